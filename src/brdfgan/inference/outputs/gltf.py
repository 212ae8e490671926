"""Export predicted maps as ``material.glb``: a glTF 2.0 binary with one textured square plane.

Pure Python (``struct`` + ``json``): the file is small and fully specified, so no glTF library is
needed. Layout, following the glTF 2.0 specification (section 4.4, GLB):

- a 12-byte header (magic ``glTF``, version 2, total length), a JSON chunk padded with spaces and a
  BIN chunk padded with zeros, each to 4 bytes;
- one scene → one node → one mesh with one indexed triangle primitive (two triangles);
- one metallic-roughness material with base colour, metallic-roughness and normal textures, the
  three PNGs stored byte for byte in the BIN chunk (bufferView + ``image/png``).

Geometry (documented because viewers, the normal map and the tangents all depend on it)
----------------------------------------------------------------------------------------
glTF is +Y up, so the plane lies on the floor: the X-Z plane at y = 0, centred at the origin,
``size`` × ``size``, facing +Y (single-sided, as the material is). Seen from above with −Z "away"
(the default glTF camera looks down −Z), the image reads upright::

      image top-left  (u, v) = (0, 0)  at (−s/2, 0, −s/2)      image top-right    (1, 0) at (+s/2, 0, −s/2)
      image bottom-left      (0, 1)    at (−s/2, 0, +s/2)      image bottom-right (1, 1) at (+s/2, 0, +s/2)

i.e. image +X (columns, +u) → world +X and image "up" (towards row 0, −v; glTF's UV origin is the
top-left corner) → world −Z.

Tangent frame: TANGENT = (1, 0, 0, +1). glTF defines the bitangent as ``cross(normal, tangent.xyz)
* tangent.w`` = cross(+Y, +X) = −Z, which is image "up". The normal texture is OpenGL convention
(as the project's maps are, and as glTF requires): red = +X = image right = tangent, green = +Y =
image up = bitangent, blue = +Z = the surface normal. w = +1 is also what Blender writes for an
unmirrored UV layout, so viewers that regenerate tangents (MikkTSpace) agree.

Texture semantics (glTF): base colour is sRGB; metallic-roughness is linear with G = roughness and
B = metallic and R = ambient occlusion (the same texture is the ``occlusionTexture``: glTF's ORM
packing); the normal texture is linear,
encoded ``(n + 1) / 2``. Beware that ``cv2.imencode`` expects BGR: encode an RGB array with
``cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)`` first, or metallic ends up in R.
"""

from __future__ import annotations

import json
import math
import os
import struct
from pathlib import Path
from typing import Any

from brdfgan.io.atomic import atomic_replace

GLB_MAGIC = 0x46546C67  # b"glTF" read as a little-endian uint32
GLB_VERSION = 2
CHUNK_JSON = 0x4E4F534A  # b"JSON"
CHUNK_BIN = 0x004E4942  # b"BIN\0"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

# glTF / WebGL enums.
FLOAT = 5126
UNSIGNED_SHORT = 5123
ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963
TRIANGLES = 4
LINEAR = 9729
LINEAR_MIPMAP_LINEAR = 9987
REPEAT = 10497

# Plane corners in units of the half size, with their UVs (see the module docstring).
CORNERS: tuple[tuple[float, float, float], ...] = ((-1, 0, 1), (1, 0, 1), (1, 0, -1), (-1, 0, -1))
UVS: tuple[tuple[float, float], ...] = ((0.0, 1.0), (1.0, 1.0), (1.0, 0.0), (0.0, 0.0))
NORMAL: tuple[float, float, float] = (0.0, 1.0, 0.0)
TANGENT: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 1.0)
# Counter-clockwise seen from +Y (the front side): (v1 − v0) × (v2 − v0) points along +Y.
INDICES: tuple[int, ...] = (0, 1, 2, 0, 2, 3)


def _pad(data: bytes, fill: bytes) -> bytes:
    """``data`` followed by ``fill`` up to the next multiple of 4 bytes (GLB chunk/bufferView alignment)."""
    return data + fill * (-len(data) % 4)


def _f32(value: float) -> float:
    """``value`` rounded to float32, so POSITION min/max equal the stored values exactly (the validator
    compares them bit for bit)."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


def _check_png(label: str, data: bytes) -> bytes:
    if not isinstance(data, bytes | bytearray | memoryview):
        raise TypeError(f"{label}: expected PNG bytes, got {type(data).__name__}")
    data = bytes(data)
    if not data.startswith(PNG_SIGNATURE):
        raise ValueError(f"{label}: not PNG data (missing the PNG signature)")
    return data


class _Buffer:
    """The BIN chunk under construction: appends 4-byte-aligned bufferViews and records them."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict[str, Any]] = []

    def add(self, payload: bytes, *, target: int | None = None) -> int:
        """Append ``payload`` as a new bufferView (4-byte aligned start); return its index."""
        self.data += b"\0" * (-len(self.data) % 4)
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(payload)}
        if target is not None:
            view["target"] = target
        self.data += payload
        self.views.append(view)
        return len(self.views) - 1


# The longest function of the package on purpose: the glTF document is one literal whose parts
# (buffers, views, accessors, images, textures, material, mesh, node) reference each other by
# index, so it reads best whole, beside the binary chunk those indices point into.
def build_glb(
    *,
    basecolor_png: bytes,
    normal_png: bytes,
    metallic_roughness_png: bytes,
    name: str = "material",
    size: float = 1.0,
    generator: str = "brdfgan",
    normal_scale: float = 1.0,
    occlusion: bool = True,
) -> bytes:
    """The GLB bytes of a ``size`` × ``size`` plane (X-Z, facing +Y) textured with the three PNGs.

    ``basecolor_png`` is sRGB RGB(A); ``metallic_roughness_png`` linear with G = roughness and
    B = metallic, and with ``occlusion`` R = ambient occlusion (then also the material's
    ``occlusionTexture``, glTF's ORM packing); ``normal_png`` linear, tangent space, OpenGL
    convention (+Y = image up), ``(n + 1) / 2``, its strength ``normal_scale``
    (``normalTexture.scale``). The PNG bytes are embedded unchanged. Pure: no file is touched.
    """
    try:
        side = float(size)  # also accepts numpy scalars
    except (TypeError, ValueError):
        raise ValueError(f"size must be a positive finite number, got {size!r}") from None
    if not (math.isfinite(side) and side > 0):
        raise ValueError(f"size must be a positive finite number, got {size!r}")
    if not (math.isfinite(normal_scale) and normal_scale >= 0):
        raise ValueError(f"normal_scale must be a finite number >= 0, got {normal_scale!r}")
    images = {
        "basecolor": _check_png("basecolor_png", basecolor_png),
        "normal": _check_png("normal_png", normal_png),
        "metallic_roughness": _check_png("metallic_roughness_png", metallic_roughness_png),
    }

    half = side / 2.0
    positions = [tuple(_f32(c * half) for c in corner) for corner in CORNERS]
    buffer = _Buffer()

    def accessor(values: list[tuple[float, ...]], kind: str, **extra: Any) -> dict[str, Any]:
        payload = b"".join(struct.pack(f"<{len(v)}f", *v) for v in values)
        view = buffer.add(payload, target=ARRAY_BUFFER)
        return {"bufferView": view, "componentType": FLOAT, "count": len(values), "type": kind, **extra}

    accessors = [
        accessor(
            positions,
            "VEC3",
            # Required for POSITION (bounding box); computed from the float32 values actually stored.
            min=[min(p[i] for p in positions) for i in range(3)],
            max=[max(p[i] for p in positions) for i in range(3)],
        ),
        accessor([NORMAL] * len(CORNERS), "VEC3"),
        accessor([TANGENT] * len(CORNERS), "VEC4"),
        accessor(list(UVS), "VEC2"),
    ]
    index_view = buffer.add(struct.pack(f"<{len(INDICES)}H", *INDICES), target=ELEMENT_ARRAY_BUFFER)
    accessors.append(
        {"bufferView": index_view, "componentType": UNSIGNED_SHORT, "count": len(INDICES), "type": "SCALAR"}
    )
    # Image views carry no target: they are not vertex or index data.
    image_entries = [
        {"name": f"{name}_{key}", "bufferView": buffer.add(data), "mimeType": "image/png"}
        for key, data in images.items()
    ]
    texture_index = {key: i for i, key in enumerate(images)}

    document: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": generator},
        "scene": 0,
        "scenes": [{"name": name, "nodes": [0]}],
        "nodes": [{"name": name, "mesh": 0}],
        "meshes": [
            {
                "name": name,
                "primitives": [
                    {
                        "attributes": {"POSITION": 0, "NORMAL": 1, "TANGENT": 2, "TEXCOORD_0": 3},
                        "indices": 4,
                        "material": 0,
                        "mode": TRIANGLES,
                    }
                ],
            }
        ],
        "materials": [
            {
                "name": name,
                "pbrMetallicRoughness": {
                    "baseColorTexture": {"index": texture_index["basecolor"]},
                    "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                    "metallicRoughnessTexture": {"index": texture_index["metallic_roughness"]},
                    "metallicFactor": 1.0,
                    "roughnessFactor": 1.0,
                },
                "normalTexture": {"index": texture_index["normal"], "scale": _f32(normal_scale)},
                **(
                    {"occlusionTexture": {"index": texture_index["metallic_roughness"], "strength": 1.0}}
                    if occlusion
                    else {}
                ),
                "doubleSided": False,
            }
        ],
        # Mipmapped trilinear filtering and REPEAT: the maps are meant to tile.
        "samplers": [
            {"magFilter": LINEAR, "minFilter": LINEAR_MIPMAP_LINEAR, "wrapS": REPEAT, "wrapT": REPEAT}
        ],
        "textures": [{"sampler": 0, "source": i} for i in range(len(image_entries))],
        "images": image_entries,
        "accessors": accessors,
        "bufferViews": buffer.views,
        # byteLength is the data length; the BIN chunk may be up to 3 padding bytes longer (spec 4.4.3.3).
        "buffers": [{"byteLength": len(buffer.data)}],
    }

    json_chunk = _pad(json.dumps(document, separators=(",", ":")).encode("utf-8"), b" ")
    bin_chunk = _pad(bytes(buffer.data), b"\0")
    length = 12 + 8 + len(json_chunk) + 8 + len(bin_chunk)
    return b"".join(
        [
            struct.pack("<III", GLB_MAGIC, GLB_VERSION, length),
            struct.pack("<II", len(json_chunk), CHUNK_JSON),
            json_chunk,
            struct.pack("<II", len(bin_chunk), CHUNK_BIN),
            bin_chunk,
        ]
    )


def write_glb(
    path: str | os.PathLike[str],
    *,
    basecolor_png: bytes,
    normal_png: bytes,
    metallic_roughness_png: bytes,
    name: str = "material",
    size: float = 1.0,
    generator: str = "brdfgan",
    normal_scale: float = 1.0,
    occlusion: bool = True,
) -> Path:
    """Write :func:`build_glb`'s bytes to ``path`` atomically (the parent directory must exist).

    Returns:
        The path written.
    """
    data = build_glb(
        basecolor_png=basecolor_png,
        normal_png=normal_png,
        metallic_roughness_png=metallic_roughness_png,
        name=name,
        size=size,
        generator=generator,
        normal_scale=normal_scale,
        occlusion=occlusion,
    )
    path = Path(path)
    with atomic_replace(path) as temp:
        temp.write_bytes(data)
    return path
