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
metallicRoughness     RGB      glTF ORM packing: R = ambient occlusion, G = roughness, B = metallic;
                               linear
height                gray     height from the normals (Frankot-Chellappa), value = 0.5 + S·h with
                               h in units of the sample side and S the height scale (material.json);
                               PNG always 16-bit; EXR: h itself
ao                    gray     ambient occlusion of that height (horizon-based, cosine-weighted);
                               linear, 1 = unoccluded
diffuse               RGB      diffuse albedo b·(1 − m) (paper §3); PNG sRGB-encoded, EXR linear
specular              RGB      specular F0 0.04·(1 − m) + b·m; PNG sRGB-encoded, EXR linear
===================== ======== ====================================================================

``material.glb`` always embeds 8-bit PNG base colour, OpenGL normal and metallicRoughness textures
(what glTF 2.0 prescribes), whatever the format options of the loose files; the ORM texture is
also its ``occlusionTexture``. The normal strength (``--normal-strength S``) is baked into the
loose normal map, while the ``.glb`` keeps the network's normals with ``normalTexture.scale = S``
(glTF's own strength), so a viewer shows the same relief either way; height and occlusion are
those of the strengthened normals in both.

Atomicity: everything is written into a hidden staging directory beside the target,
``.<name>.<owner>.tmp``, which then takes the place of ``OUT/<name>``. On Linux the two directories
are exchanged in one ``renameat2(RENAME_EXCHANGE)``, so a complete ``OUT/<name>`` exists at every
instant; elsewhere (or on a filesystem that refuses the exchange) the old result is first renamed
to ``.<name>.<owner>.old``, leaving a moment without ``OUT/<name>``. A failure or an interrupt
leaves the previous result (if any) in place and removes the staging directory.

A kill (``kill -9``, power loss) cannot clean up, so the owner in those names, ``<pid>-<start>-<random>``
with ``<start>`` a hash of the process's start time and the boot, says whether the process that
made them is still running. :func:`recover_outputs` (run by every ``predict`` before it writes)
removes the hidden directories of processes that are gone, and puts back a ``.<name>.<owner>.old``
whose ``OUT/<name>`` is missing (a kill between the two renames of the fallback).
"""

from __future__ import annotations

import ctypes
import errno
import functools
import hashlib
import json
import logging
import math
import os
import re
import shutil
import uuid
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.height import ambient_occlusion, height_from_normals
from brdfgan.core.svbrdf import (
    diffuse_albedo,
    encode_normal,
    linear_to_srgb,
    scale_normal_strength,
    specular_albedo,
    split_maps,
    srgb_to_linear,
    validate_maps,
)
from brdfgan.errors import DiskFullError, UserError, is_disk_full
from brdfgan.inference.outputs.gltf import write_glb
from brdfgan.io.images import png_bytes, write_image

log = logging.getLogger(__name__)

NormalConvention = Literal["opengl", "directx"]
TextureFormat = Literal["png", "exr"]
NORMAL_CONVENTIONS: tuple[str, ...] = ("opengl", "directx")
TEXTURE_FORMATS: tuple[str, ...] = ("png", "exr")
MATERIAL_JSON_FORMAT = "brdfgan-material/1"

# ``.<name>.<pid>-<start token>-<random>.tmp`` (staging) or ``.old`` (a previous result being retired).
HIDDEN_OUTPUT_PATTERN = re.compile(
    r"^\.(?P<name>.+)\.(?P<pid>[0-9]+)-(?P<token>[0-9a-f]{8})-[0-9a-f]{8}\.(?P<kind>tmp|old)$"
)


class ExportError(UserError):
    """The outputs cannot be written; the message names the path or option."""


@dataclass(frozen=True)
class ExportOptions:
    """How the loose texture files are stored (``material.glb`` is always glTF's PNG set)."""

    format: TextureFormat = "png"
    bit_depth: Literal[8, 16] = 8
    normal_convention: NormalConvention = "opengl"
    exr_precision: Literal["half", "float"] = "half"
    normal_strength: float = 1.0  # tangent tilt × this (baked into the loose normal map)
    height_scale: float | None = None  # height.png value = 0.5 + scale·h; None: fill the range
    periodic: bool = False  # the maps wrap (--tileable): height and occlusion are integrated so
    file_prefix: str = ""  # texture files named <prefix><map>.<ext> (--prefix: "<material>_")

    def __post_init__(self) -> None:
        if self.format not in TEXTURE_FORMATS:
            raise ExportError(f"format: expected one of {TEXTURE_FORMATS}, got {self.format!r}")
        if self.bit_depth not in (8, 16):
            raise ExportError(f"bit depth: expected 8 or 16, got {self.bit_depth!r}")
        if self.normal_convention not in NORMAL_CONVENTIONS:
            raise ExportError(
                f"normal convention: expected one of {NORMAL_CONVENTIONS}, got {self.normal_convention!r}"
            )
        if not (math.isfinite(self.normal_strength) and self.normal_strength >= 0):
            raise ExportError(f"normal strength: expected a number >= 0, got {self.normal_strength!r}")
        if self.height_scale is not None and not (math.isfinite(self.height_scale) and self.height_scale > 0):
            raise ExportError(f"height scale: expected a number > 0, got {self.height_scale!r}")


# material.json's entry of an extra file that is not an image (images: previews, sRGB).
EXTRA_FILE_ENTRIES: dict[str, dict[str, Any]] = {
    ".html": {
        "map": "material viewer: the maps, the previews and an interactive 3D view (three.js, inlined)",
        "colorspace": "srgb",
        "channels": "HTML page, self-contained",
        "encoding": "open in a browser, from file:// too",
    },
}

# What glTF 2.0 prescribes for material.glb: sRGB base colour, OpenGL normals, 8-bit PNG (the
# normal strength goes into normalTexture.scale instead of the texture).
GLTF_TEXTURES = ExportOptions()


@dataclass(frozen=True)
class Relief:
    """The surface relief of a map set: height and ambient occlusion of its normals (at the
    chosen normal strength), shared by the loose files and the ``.glb``.

    Shape:
        - height: ``(H, W)`` in units of the sample side, mean 0
        - occlusion: ``(H, W)`` in ``[0, 1]``
    """

    height: Tensor
    occlusion: Tensor
    height_scale: float  # stored height value = 0.5 + height_scale · h

    def to_json(self) -> dict[str, Any]:
        return {
            "height_units": "sample side (the texture's width spans 1)",
            "height_encoding": "value = 0.5 + height_scale * h",
            "height_scale": self.height_scale,
            "height_range": [float(self.height.min()), float(self.height.max())],
            "occlusion": "horizon-based, cosine-weighted, 8 directions within 1/16 of the side",
            "occlusion_mean": float(self.occlusion.mean()),
        }


def surface_relief(maps: Tensor, options: ExportOptions) -> Relief:
    """Height (Frankot-Chellappa) and ambient occlusion of ``maps``' normals at
    ``options.normal_strength``; periodic when ``options.periodic``.

    Shape:
        - maps: ``(8, H, W)``
    """
    normal = scale_normal_strength(
        split_maps(maps.detach().to("cpu", torch.float32)).normal, options.normal_strength
    )
    height = height_from_normals(normal, periodic=options.periodic)
    occlusion = ambient_occlusion(height, periodic=options.periodic)
    reach = float(height.abs().max())
    scale = options.height_scale if options.height_scale is not None else (0.5 / reach if reach > 0 else 1.0)
    return Relief(height=height, occlusion=occlusion, height_scale=scale)


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
    bit_depth: Literal[8, 16] | None = None  # PNG depth when fixed (height: 16), else the option's


def texture_set(maps: Tensor, options: ExportOptions, relief: Relief | None = None) -> dict[str, Texture]:
    """The stored values of every loose texture file, keyed by map name (no extension); the
    height and occlusion from ``relief`` (default: :func:`surface_relief` of the maps).

    Shape:
        - maps: ``(8, H, W)``, layout of :mod:`brdfgan.core.svbrdf`
    """
    check_shape(maps, "8 H W", name="maps (one map set)", error=ExportError)
    validate_maps(maps)
    # float32 is exact enough for 16-bit PNG and half EXR, and half the memory of float64 at 4096².
    parts = split_maps(maps.detach().to("cpu", torch.float32))
    basecolor_linear = srgb_to_linear(parts.basecolor)
    diffuse = diffuse_albedo(basecolor_linear, parts.metallic)
    specular = specular_albedo(basecolor_linear, parts.metallic)
    relief = relief if relief is not None else surface_relief(maps, options)
    normal = encode_normal(scale_normal_strength(parts.normal, options.normal_strength))
    if options.normal_convention == "directx":
        normal = torch.cat([normal[0:1], 1.0 - normal[1:2], normal[2:3]])
    occlusion = relief.occlusion[None]
    packed = torch.cat([occlusion, parts.roughness, parts.metallic])
    exr = options.format == "exr"
    height = relief.height[None] if exr else (0.5 + relief.height_scale * relief.height[None]).clamp(0.0, 1.0)
    height_encoding = (
        "height h in units of the sample side"
        if exr
        else f"value = 0.5 + {relief.height_scale:.6g} * h, h in units of the sample side"
    )

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
            _hwc(packed),
            "linear",
            "R = occlusion, G = roughness, B = metallic",
            "glTF occlusion-roughness-metallic",
        ),
        "height": Texture(_hwc(height, clip=not exr), "linear", "gray", height_encoding, bit_depth=16),
        "ao": Texture(_hwc(occlusion), "linear", "gray", "ambient occlusion (1 = open)"),
        "diffuse": colour(diffuse, "diffuse albedo b(1 - m)"),
        "specular": colour(specular, "specular F0 0.04(1 - m) + b m"),
    }


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
    relief = surface_relief(maps, options)
    textures = texture_set(maps, options, relief)
    # The bit depth changes no value; another format, normal convention or strength (EXR, DirectX,
    # --normal-strength) does, and then the glTF set is computed for itself (same relief).
    gltf_options = replace(
        options, format="png", bit_depth=8, normal_convention="opengl", normal_strength=1.0
    )
    same_values = (options.format, options.normal_convention, options.normal_strength) == (
        "png",
        "opengl",
        1.0,
    )
    gltf_textures = textures if same_values else texture_set(maps, gltf_options, relief)
    parent = target.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ExportError(
            f"{parent}: cannot create the output directory ({error.strerror or error})"
        ) from None
    if target.exists() and not target.is_dir():
        raise ExportError(f"{target}: exists and is not a directory")
    try:
        with staged_directory(target) as staging:
            files = _write_files(staging, target.name, textures, gltf_textures, options, extra_files or {})
            document = {
                "format": MATERIAL_JSON_FORMAT,
                **metadata,
                "relief": relief.to_json(),
                "files": files,
            }
            (staging / "material.json").write_text(json.dumps(document, indent=2, sort_keys=False) + "\n")
    except OSError as error:
        if is_disk_full(error):
            # The folder is what the user asked for; the file that hit the limit is a hidden temporary.
            raise DiskFullError(target) from None
        raise ExportError(f"{target}: cannot write the outputs ({error.strerror or error})") from None
    return target


@contextmanager
def staged_directory(target: Path) -> Iterator[Path]:
    """A fresh hidden folder beside ``target`` (its parent must exist) to write a result into; when
    the block ends without error it takes ``target``'s place (:func:`_swap_directory`: the old
    result survives any failure), and whatever is left of it is removed in any case — also on
    KeyboardInterrupt (SIGINT, and SIGTERM while predict runs): nothing hidden stays."""
    owner = _owner()
    staging = target.parent / f".{target.name}.{owner}.tmp"
    try:
        staging.mkdir()
        yield staging
        _swap_directory(staging, target, owner)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def recover_outputs(out_root: str | os.PathLike[str]) -> list[str]:
    """Clean up after killed runs in ``out_root``: hidden staging and retired directories whose
    owning process is gone are removed, except a retired ``.<name>.<owner>.old`` whose
    ``<name>`` is missing, which is renamed back (the kill came between the two renames).
    Directories of running processes are left alone. Logs (a restore as a warning) and returns
    one line per action."""
    root = Path(out_root)
    if not root.is_dir():
        return []
    actions: list[str] = []
    for entry in sorted(root.iterdir()):
        match = HIDDEN_OUTPUT_PATTERN.match(entry.name)
        if match is None or entry.is_symlink() or not entry.is_dir():
            continue
        if _owner_running(int(match["pid"]), match["token"]):
            continue
        target = root / match["name"]
        if match["kind"] == "old" and not os.path.lexists(target):
            os.rename(entry, target)
            actions.append(f"{target}: restored the previous result (a run was killed while replacing it)")
            log.warning("%s", actions[-1])
        else:
            shutil.rmtree(entry, ignore_errors=True)
            actions.append(f"{entry}: removed (left by process {match['pid']}, which is no longer running)")
            log.info("%s", actions[-1])
    return actions


def _write_files(
    directory: Path,
    name: str,
    textures: Mapping[str, Texture],
    gltf_textures: Mapping[str, Texture],
    options: ExportOptions,
    extra_files: Mapping[str, Callable[[Path], Any]],
) -> dict[str, dict[str, Any]]:
    files: dict[str, dict[str, Any]] = {}
    paths = {
        map_name: directory / f"{options.file_prefix}{map_name}.{options.format}" for map_name in textures
    }
    # Twelve 2048² encodes were half of predict's export: OpenCV and OpenEXR encode without the
    # GIL, so they run on torch's intra-op threads (OMP_NUM_THREADS). Leaving the block waits for
    # every write, so an interrupt never leaves one running into the staging folder's removal.
    with ThreadPoolExecutor(max_workers=max(1, torch.get_num_threads())) as pool:
        writes = [
            pool.submit(
                write_image,
                paths[map_name],
                texture.values,
                bit_depth=texture.bit_depth or options.bit_depth,
                exr_precision=options.exr_precision,
            )
            for map_name, texture in textures.items()
        ]
        embedded = {
            slot: pool.submit(png_bytes, gltf_textures[slot].values)
            for slot in ("basecolor", "normal", "metallicRoughness")
        }
        for written in writes:
            written.result()
        pngs = {slot: future.result() for slot, future in embedded.items()}
    for map_name, texture in textures.items():
        path = paths[map_name]
        depth = (texture.bit_depth or options.bit_depth) if options.format == "png" else options.exr_precision
        files[path.name] = {
            "map": map_name,
            "colorspace": texture.colorspace,
            "channels": texture.channels,
            "encoding": texture.encoding,
            "bit_depth" if options.format == "png" else "precision": depth,
        }
        if map_name == "normal":
            files[path.name]["convention"] = options.normal_convention
            files[path.name]["strength"] = options.normal_strength
    write_glb(
        directory / "material.glb",
        basecolor_png=pngs["basecolor"],
        normal_png=pngs["normal"],
        metallic_roughness_png=pngs["metallicRoughness"],
        name=name,
        normal_scale=options.normal_strength,
    )
    files["material.glb"] = {
        "map": "glTF 2.0 binary: a 1 m square floor plane (+Y up) with this material",
        "colorspace": "baseColor sRGB; normal and metallicRoughness linear",
        "channels": "embedded 8-bit PNGs",
        "encoding": "glTF metallic-roughness PBR; occlusion in the metallicRoughness texture's R; "
        "normal texture OpenGL convention at strength 1, "
        f"normalTexture.scale {options.normal_strength:g}",
    }
    for file_name, write in extra_files.items():
        write(directory / file_name)
        files[file_name] = EXTRA_FILE_ENTRIES.get(
            Path(file_name).suffix,
            {"map": "preview", "colorspace": "srgb", "channels": "RGB", "encoding": "sRGB image"},
        )
    return files


def _swap_directory(staging: Path, target: Path, owner: str) -> None:
    """Put ``staging`` in the place of ``target``; the old result survives any failure.

    Afterwards ``staging`` holds the old result (exchange) or is gone; the caller removes it.
    """
    if not os.path.lexists(target):
        os.rename(staging, target)  # one atomic step: nothing to keep
        return
    if exchange_paths(staging, target):
        return
    # No atomic exchange here: retire the old result under a name recover_outputs knows.
    retired = target.parent / f".{target.name}.{owner}.old"
    os.rename(target, retired)
    try:
        os.rename(staging, target)
    except BaseException:  # also an interrupt between the renames: put the old result back
        os.rename(retired, target)
        raise
    shutil.rmtree(retired, ignore_errors=True)


# Linux renameat2(2): flags and the "relative to the working directory" file descriptor.
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


@functools.cache
def _renameat2() -> Callable[..., int] | None:
    try:
        function = ctypes.CDLL(None, use_errno=True).renameat2  # Linux with glibc >= 2.28
    except (AttributeError, OSError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    function.restype = ctypes.c_int
    return function


def exchange_paths(a: Path, b: Path) -> bool:
    """Swap two existing paths atomically (``renameat2(RENAME_EXCHANGE)``). ``False`` when this
    system or filesystem cannot (then nothing changed); an ``OSError`` for any other failure."""
    function = _renameat2()
    if function is None:
        return False
    if function(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):  # no kernel or filesystem support
        return False
    raise OSError(code, os.strerror(code), os.fspath(b))


# --- owners of hidden directories ---------------------------------------------------------------


def _owner() -> str:
    """``<pid>-<start token>-<random>`` for a hidden directory of this process."""
    pid = os.getpid()
    return f"{pid}-{_start_token(pid) or '00000000'}-{uuid.uuid4().hex[:8]}"


def _start_token(pid: int) -> str | None:
    """A hash of the process's start time and the boot id: a PID is reused, this pair is not.

    ``None`` when there is no such process; ``"00000000"`` for a running process when the system
    has no ``/proc`` to read start times from (the PID alone then decides).
    """
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        if Path("/proc/self/stat").exists():
            return None
        return "00000000" if _pid_exists(pid) else None
    except OSError:
        return None
    # Field 22 is the start time in clock ticks since boot; the command name (field 2) is in
    # parentheses and may itself contain spaces or parentheses, so count from the last ')'.
    start = stat.rsplit(")", 1)[1].split()[19]
    try:
        boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        boot = ""
    return hashlib.sha1(f"{boot}:{start}".encode()).hexdigest()[:8]


def _pid_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def _owner_running(pid: int, token: str) -> bool:
    return _start_token(pid) == token


def _hwc(chw: Tensor, *, clip: bool = True) -> np.ndarray:
    """``(C, H, W)`` → ``(H, W, C)`` values, clipped to ``[0, 1]`` unless raw (an EXR height)."""
    hwc = chw.permute(1, 2, 0)
    return (hwc.clamp(0.0, 1.0) if clip else hwc).numpy()
