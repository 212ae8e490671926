"""Engine-ready texture files for one predicted map set, written as one directory atomically.

Files and their encodings (also recorded per file in ``material.json``):

===================== ======== ====================================================================
file                  channels encoding
===================== ======== ====================================================================
basecolor             RGB      PNG: sRGB-encoded (like every albedo texture); EXR: linear
normal                RGB      ``(n + 1) / 2`` tangent space, +Z out; OpenGL (+Y up, default) or
                               DirectX (``--normal-convention directx``: green = 1 − green)
roughness             gray     perceptual roughness r (GGX α = r²), linear value
metallic              gray     linear value
metallicRoughness     RGB      glTF packing: R = 1 (no occlusion, so it doubles as an ORM texture),
                               G = roughness, B = metallic; linear
diffuse               RGB      diffuse albedo b·(1 − m) (paper §3); PNG sRGB-encoded, EXR linear
specular              RGB      specular F0 0.04·(1 − m) + b·m; PNG sRGB-encoded, EXR linear
===================== ======== ====================================================================

``material.glb`` always embeds 8-bit PNG base colour, OpenGL normal and metallicRoughness textures
(what glTF 2.0 prescribes), whatever the format options of the loose files.

Atomicity: everything is written into a hidden temporary directory beside the target, which then
replaces ``OUT/<name>`` with two renames; a failure at any point leaves the previous result (if
any) untouched and removes the temporary directory.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import torch
from torch import Tensor

from brdfgan.core.svbrdf import (
    diffuse_albedo,
    encode_normal,
    linear_to_srgb,
    specular_albedo,
    split_maps,
    srgb_to_linear,
    validate_maps,
)
from brdfgan.inference.gltf import write_glb
from brdfgan.io.images import write_image

NormalConvention = Literal["opengl", "directx"]
TextureFormat = Literal["png", "exr"]
NORMAL_CONVENTIONS: tuple[str, ...] = ("opengl", "directx")
TEXTURE_FORMATS: tuple[str, ...] = ("png", "exr")
MATERIAL_JSON_FORMAT = "brdfgan-material/1"


class ExportError(ValueError):
    """The outputs cannot be written; the message names the path or option."""


@dataclass(frozen=True)
class ExportOptions:
    """How the loose texture files are stored (``material.glb`` is always glTF's PNG set)."""

    format: TextureFormat = "png"
    bit_depth: Literal[8, 16] = 8
    normal_convention: NormalConvention = "opengl"
    exr_precision: Literal["half", "float"] = "half"

    def __post_init__(self) -> None:
        if self.format not in TEXTURE_FORMATS:
            raise ExportError(f"format: expected one of {TEXTURE_FORMATS}, got {self.format!r}")
        if self.bit_depth not in (8, 16):
            raise ExportError(f"bit depth: expected 8 or 16, got {self.bit_depth!r}")
        if self.normal_convention not in NORMAL_CONVENTIONS:
            raise ExportError(
                f"normal convention: expected one of {NORMAL_CONVENTIONS}, got {self.normal_convention!r}"
            )


# What glTF 2.0 prescribes for material.glb: sRGB base colour, OpenGL normals, 8-bit PNG.
GLTF_TEXTURES = ExportOptions()


@dataclass(frozen=True)
class Texture:
    """One texture file's content and how to read it back.

    Shape:
        - values: ``(H, W, C)`` float32 in ``[0, 1]`` (C = 1 or 3), the stored values
    """

    values: np.ndarray
    colorspace: str  # "srgb" | "linear": the transfer function of the stored values
    channels: str  # what each channel holds
    encoding: str  # how to turn stored values into the quantity


def texture_set(maps: Tensor, options: ExportOptions) -> dict[str, Texture]:
    """The stored values of every loose texture file, keyed by map name (no extension).

    Shape:
        - maps: ``(8, H, W)``, layout of :mod:`brdfgan.core.svbrdf`
    """
    if maps.ndim != 3:
        raise ExportError(f"expected one map set of shape (8, H, W), got {tuple(maps.shape)}")
    validate_maps(maps)
    # float32 is exact enough for 16-bit PNG and half EXR, and half the memory of float64 at 4096².
    parts = split_maps(maps.detach().to("cpu", torch.float32))
    basecolor_linear = srgb_to_linear(parts.basecolor)
    diffuse = diffuse_albedo(basecolor_linear, parts.metallic)
    specular = specular_albedo(basecolor_linear, parts.metallic)
    normal = encode_normal(parts.normal)
    if options.normal_convention == "directx":
        normal = torch.cat([normal[0:1], 1.0 - normal[1:2], normal[2:3]])
    packed = torch.cat([torch.ones_like(parts.roughness), parts.roughness, parts.metallic])
    exr = options.format == "exr"

    def colour(linear: Tensor, what: str) -> Texture:
        stored = linear if exr else linear_to_srgb(linear)
        return Texture(_hwc(stored), "linear" if exr else "srgb", "RGB", what)

    convention = "OpenGL (+Y up)" if options.normal_convention == "opengl" else "DirectX (+Y down)"
    return {
        "basecolor": colour(basecolor_linear, "base color"),
        "normal": Texture(
            _hwc(normal), "linear", "RGB = XYZ", f"tangent-space normal (n + 1) / 2, {convention}"
        ),
        "roughness": Texture(
            _hwc(parts.roughness), "linear", "gray", "perceptual roughness (GGX alpha = r^2)"
        ),
        "metallic": Texture(_hwc(parts.metallic), "linear", "gray", "metalness"),
        "metallicRoughness": Texture(
            _hwc(packed), "linear", "R = 1 (occlusion), G = roughness, B = metallic", "glTF metallicRoughness"
        ),
        "diffuse": colour(diffuse, "diffuse albedo b(1 - m)"),
        "specular": colour(specular, "specular F0 0.04(1 - m) + b m"),
    }


def png_bytes(values: np.ndarray) -> bytes:
    """8-bit PNG of ``(H, W, C)`` values in [0, 1], RGB order (OpenCV wants BGR: converted here)."""
    image = np.clip(np.rint(values * 255.0), 0, 255).astype(np.uint8)
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise ExportError("cannot encode a PNG texture")
    return encoded.tobytes()


def write_material(
    out_dir: str | os.PathLike[str],
    maps: Tensor,
    options: ExportOptions,
    metadata: Mapping[str, Any],
    *,
    extra_files: Mapping[str, Callable[[Path], Any]] | None = None,
) -> Path:
    """Write every texture, ``material.glb``, ``material.json`` (and ``extra_files``) into ``out_dir``.

    ``extra_files`` maps a file name to a function that writes it at the given path (used for
    the preview and the animation), so that they are part of the same atomic directory swap.
    ``metadata`` goes into ``material.json`` beside the per-file table.

    Shape:
        - maps: ``(8, H, W)``
    Returns:
        ``out_dir``
    """
    target = Path(out_dir)
    textures = texture_set(maps, options)
    # The bit depth changes no value; another format or normal convention (EXR, DirectX) does, and
    # then the glTF set is computed for itself.
    same_values = (options.format, options.normal_convention) == (
        GLTF_TEXTURES.format,
        GLTF_TEXTURES.normal_convention,
    )
    gltf_textures = textures if same_values else texture_set(maps, GLTF_TEXTURES)
    parent = target.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ExportError(
            f"{parent}: cannot create the output directory ({error.strerror or error})"
        ) from None
    if target.exists() and not target.is_dir():
        raise ExportError(f"{target}: exists and is not a directory")
    staging = parent / f".{target.name}.{uuid.uuid4().hex[:12]}.tmp"
    try:
        staging.mkdir()
        files = _write_files(staging, target.name, textures, gltf_textures, options, extra_files or {})
        document = {"format": MATERIAL_JSON_FORMAT, **metadata, "files": files}
        (staging / "material.json").write_text(json.dumps(document, indent=2, sort_keys=False) + "\n")
        _swap_directory(staging, target)
    except OSError as error:
        raise ExportError(f"{target}: cannot write the outputs ({error.strerror or error})") from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


def _write_files(
    directory: Path,
    name: str,
    textures: Mapping[str, Texture],
    gltf_textures: Mapping[str, Texture],
    options: ExportOptions,
    extra_files: Mapping[str, Callable[[Path], Any]],
) -> dict[str, dict[str, Any]]:
    files: dict[str, dict[str, Any]] = {}
    for map_name, texture in textures.items():
        path = directory / f"{map_name}.{options.format}"
        write_image(path, texture.values, bit_depth=options.bit_depth, exr_precision=options.exr_precision)
        depth = options.bit_depth if options.format == "png" else options.exr_precision
        files[path.name] = {
            "map": map_name,
            "colorspace": texture.colorspace,
            "channels": texture.channels,
            "encoding": texture.encoding,
            "bit_depth" if options.format == "png" else "precision": depth,
        }
        if map_name == "normal":
            files[path.name]["convention"] = options.normal_convention
    write_glb(
        directory / "material.glb",
        basecolor_png=png_bytes(gltf_textures["basecolor"].values),
        normal_png=png_bytes(gltf_textures["normal"].values),
        metallic_roughness_png=png_bytes(gltf_textures["metallicRoughness"].values),
        name=name,
    )
    files["material.glb"] = {
        "map": "glTF 2.0 binary: a 1 m square floor plane (+Y up) with this material",
        "colorspace": "baseColor sRGB; normal and metallicRoughness linear",
        "channels": "embedded 8-bit PNGs",
        "encoding": "glTF metallic-roughness PBR; normal texture OpenGL convention",
    }
    for file_name, write in extra_files.items():
        write(directory / file_name)
        files[file_name] = {
            "map": "preview",
            "colorspace": "srgb",
            "channels": "RGB",
            "encoding": "sRGB image",
        }
    return files


def _swap_directory(staging: Path, target: Path) -> None:
    """Replace ``target`` by ``staging`` with renames; the old result survives any failure."""
    if not target.exists():
        os.replace(staging, target)
        return
    retired = target.parent / f".{target.name}.{uuid.uuid4().hex[:12]}.old"
    os.replace(target, retired)
    try:
        os.replace(staging, target)
    except OSError:
        os.replace(retired, target)
        raise
    shutil.rmtree(retired, ignore_errors=True)


def _hwc(chw: Tensor) -> np.ndarray:
    return chw.permute(1, 2, 0).clamp(0.0, 1.0).numpy()
