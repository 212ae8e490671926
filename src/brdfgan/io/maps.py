"""Map sets on disk: a directory holding ``basecolor``, ``normal``, ``roughness`` and ``metallic``.

All four files share one extension, ``.png`` or ``.exr``, and one size. In memory a map set is the
8-channel tensor of :mod:`brdfgan.core.svbrdf`; on disk each map is stored as follows.

========== ============================================ ==========================================
map        PNG (8- or 16-bit)                           EXR (half or float)
========== ============================================ ==========================================
basecolor  RGB, sRGB-encoded, as texture files are      RGB, **linear** (EXR is a linear format)
normal     RGB, ``(n + 1) / 2`` (OpenGL, +Y up)         RGB, ``(n + 1) / 2``, same as PNG
roughness  grayscale, raw value                         one channel ``Y``, raw value
metallic   grayscale, raw value                         one channel ``Y``, raw value
========== ============================================ ==========================================

So the sRGB curve is applied only at the EXR boundary (:func:`srgb_to_linear` on write,
:func:`linear_to_srgb` on read), and normals are renormalised on read (:func:`decode_normal`)
because quantisation breaks unit length.

Reading is lenient where real texture packs are: grayscale maps saved as RGB(A) files are accepted
when their colour channels agree, an alpha channel is ignored, a grayscale base color is expanded
to RGB, and tiny excursions outside ``[0, 1]`` (filtering, rounding) are clipped. Genuinely
out-of-range data raises :class:`MapIOError` naming the file.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Literal

import numpy as np
import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.svbrdf import (
    MAP_NAMES,
    InvalidMapsError,
    decode_normal,
    encode_normal,
    join_maps,
    linear_to_srgb,
    normalize_normal,
    split_maps,
    srgb_to_linear,
    validate_maps,
)
from brdfgan.io.images import BitDepth, ExrPrecision, ImageIOError, read_image, write_image

__all__ = ["MAP_FORMATS", "MapFormat", "MapIOError", "map_paths", "read_map_files", "read_maps", "write_maps"]

MapFormat = Literal["png", "exr"]
MAP_FORMATS: tuple[str, ...] = ("png", "exr")

# Stored values this far outside [0, 1] are treated as rounding/filtering noise and clipped;
# anything beyond is a wrong file (e.g. an HDR image or a [-1, 1] normal map) and is rejected.
RANGE_TOLERANCE = 1e-3
# Decoded normals may dip this far below z = 0 through quantisation of grazing normals.
NORMAL_Z_TOLERANCE = 1e-2
# Colour channels of a grayscale map saved as RGB may differ by this much (lossy re-encoding);
# beyond it the file is probably a packed texture (e.g. ORM), and channel 0 would be wrong.
GRAYSCALE_TOLERANCE = 2.0 / 255.0


class MapIOError(ImageIOError):
    """A map set cannot be read or written; the message names the file or map."""


def map_paths(directory: str | os.PathLike[str], format: MapFormat) -> dict[str, Path]:
    """The file path of each map of a set stored in ``directory`` with extension ``format``."""
    _check_format(format)
    return {name: Path(directory) / f"{name}.{format}" for name in MAP_NAMES}


def write_maps(
    directory: str | os.PathLike[str],
    maps: Tensor,
    *,
    format: MapFormat = "png",
    bit_depth: BitDepth = 8,
    exr_precision: ExrPrecision = "half",
) -> dict[str, Path]:
    """Write a map set as four files in ``directory`` (created if needed), each atomically.

    The maps are validated first (:class:`InvalidMapsError` if invalid), so nothing is written for
    bad input. Map files of the other format left in ``directory`` by an earlier write are removed
    afterwards, so that the directory holds exactly one map set.

    Shape:
        - maps: ``(8, H, W)`` in the layout of :mod:`brdfgan.core.svbrdf`
    Returns:
        ``{map name: path written}``
    """
    _check_format(format)
    directory = Path(directory)
    check_shape(maps, "8 H W", name="write_maps maps (one map set)", error=InvalidMapsError)
    validate_maps(maps)
    if directory.exists() and not directory.is_dir():
        raise MapIOError(f"{directory}: exists and is not a directory")
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise MapIOError(f"{directory}: cannot create directory ({error.strerror or error})") from error

    # float64 keeps the sRGB round trip through a float EXR within float32 rounding.
    parts = split_maps(maps.detach().to(device="cpu", dtype=torch.float64))
    basecolor = srgb_to_linear(parts.basecolor) if format == "exr" else parts.basecolor
    stored = {
        "basecolor": basecolor,
        "normal": encode_normal(parts.normal),
        "roughness": parts.roughness,
        "metallic": parts.metallic,
    }
    paths = map_paths(directory, format)
    for name, values in stored.items():
        array = values.permute(1, 2, 0).numpy()
        try:
            write_image(paths[name], array, bit_depth=bit_depth, exr_precision=exr_precision)
        except ImageIOError as error:
            raise MapIOError(str(error)) from error

    other: MapFormat = "exr" if format == "png" else "png"
    for stale in map_paths(directory, other).values():
        stale.unlink(missing_ok=True)
    return paths


def read_maps(directory: str | os.PathLike[str], *, format: MapFormat | None = None) -> Tensor:
    """Read a map set written by :func:`write_maps` (or a compatible texture pack).

    ``format=None`` detects the format from the files present; it is an error if map files of
    both formats, or of neither, are there.

    Shape:
        - output: ``(8, H, W)`` float32, passes :func:`validate_maps`
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise MapIOError(f"{directory}: map directory not found")
    if format is None:
        format = _detect_format(directory)
    _check_format(format)
    return read_map_files(map_paths(directory, format), linear_basecolor=format == "exr", where=directory)


def read_map_files(
    paths: Mapping[str, Path | None],
    *,
    linear_basecolor: bool = False,
    where: str | os.PathLike[str],
    channels: Mapping[str, int] | None = None,
) -> Tensor:
    """Read the map set stored in the files ``paths`` (keys ``basecolor``, ``normal``,
    ``roughness``, ``metallic``) under this module's encodings — for texture packs that name
    their files otherwise. A ``None`` metallic path means a dielectric (metallic 0);
    ``linear_basecolor`` says the base colour file is linear (EXR). ``where`` names the set in
    messages. ``channels`` maps ``roughness``/``metallic`` to the colour channel that holds it in
    a packed RGB file (e.g. an ARM texture: roughness 1, metallic 2); the others are grayscale.

    Shape:
        - output: ``(8, H, W)`` float32, passes :func:`validate_maps`
    """
    for name in MAP_NAMES:
        path = paths.get(name)
        if path is None and name != "metallic":
            raise MapIOError(f"{where}: no {name} map given")
        if path is not None and not path.is_file():
            raise MapIOError(f"{path}: map file missing")

    images: dict[str, np.ndarray] = {}
    files = {name: path for name, path in paths.items() if path is not None}
    for name, path in files.items():
        try:
            images[name] = read_image(path)
        except ImageIOError as error:
            raise MapIOError(str(error)) from error
    size = images["basecolor"].shape[:2]
    for name, image in images.items():
        if image.shape[:2] != size:
            raise MapIOError(
                f"{files[name]}: size {image.shape[1]}x{image.shape[0]} (WxH) differs from "
                f"basecolor's {size[1]}x{size[0]}"
            )

    stored = _in_unit_range(files["basecolor"], _colour(images["basecolor"]))
    basecolor = torch.from_numpy(stored).permute(2, 0, 1).double()
    if linear_basecolor:
        basecolor = linear_to_srgb(basecolor)
    encoded = _in_unit_range(files["normal"], _normal_channels(files["normal"], images["normal"]))
    normal = _decode_normal(files["normal"], torch.from_numpy(encoded).permute(2, 0, 1).double())
    packed = dict(channels or {})
    scalars = [
        torch.from_numpy(_in_unit_range(files[name], _scalar(files[name], images[name], packed.get(name))))
        .permute(2, 0, 1)
        .double()
        if name in files
        else torch.zeros(1, *size, dtype=torch.float64)
        for name in ("roughness", "metallic")
    ]
    # The clamp absorbs the last ulp the sRGB curve can add at the ends of [0, 1].
    maps = join_maps(basecolor.clamp(0.0, 1.0), normal, *scalars).float()
    try:
        validate_maps(maps)
    except InvalidMapsError as error:
        raise MapIOError(f"{where}: {error}") from error
    return maps


def _check_format(format: str) -> None:
    if format not in MAP_FORMATS:
        raise MapIOError(f"unsupported map format {format!r}, expected one of {', '.join(MAP_FORMATS)}")


def _detect_format(directory: Path) -> MapFormat:
    present = {
        fmt: [p.name for p in map_paths(directory, fmt).values() if p.is_file()] for fmt in ("png", "exr")
    }
    if present["png"] and present["exr"]:
        raise MapIOError(
            f"{directory}: both PNG ({', '.join(present['png'])}) and EXR ({', '.join(present['exr'])}) "
            "map files present; pass format='png' or format='exr'"
        )
    if present["exr"]:
        return "exr"
    if present["png"]:
        return "png"
    expected = ", ".join(f"{name}.png|exr" for name in MAP_NAMES)
    raise MapIOError(f"{directory}: no map files found, expected {expected}")


def _colour(image: np.ndarray) -> np.ndarray:
    """RGB(A) or grayscale → ``(H, W, 3)``; alpha is not part of the representation."""
    return np.repeat(image, 3, axis=2) if image.shape[2] == 1 else image[:, :, :3]


def _normal_channels(path: Path, image: np.ndarray) -> np.ndarray:
    if image.shape[2] == 1:
        raise MapIOError(f"{path}: normal map has a single channel (a height map?), expected RGB")
    return image[:, :, :3]


def _grayscale(path: Path, image: np.ndarray) -> np.ndarray:
    """Grayscale, or RGB(A) with equal colour channels → ``(H, W, 1)``."""
    if image.shape[2] == 1:
        return image
    colour = image[:, :, :3]
    spread = float((colour.max(axis=2) - colour.min(axis=2)).max())
    if spread > GRAYSCALE_TOLERANCE:
        raise MapIOError(
            f"{path}: colour channels differ by up to {spread:.3g}; expected a grayscale map "
            "(packed textures such as ORM are not supported)"
        )
    return image[:, :, :1]


def _scalar(path: Path, image: np.ndarray, channel: int | None) -> np.ndarray:
    """Channel ``channel`` of a packed RGB(A) file, or the grayscale map (``None``) → ``(H, W, 1)``."""
    if channel is None:
        return _grayscale(path, image)
    if image.shape[2] < 3:
        raise MapIOError(f"{path}: a packed texture must be RGB, this file has {image.shape[2]} channel(s)")
    return image[:, :, channel : channel + 1]


def _in_unit_range(path: Path, values: np.ndarray) -> np.ndarray:
    low, high = float(values.min()), float(values.max())
    if not (np.isfinite(low) and np.isfinite(high)):
        raise MapIOError(f"{path}: contains NaN or infinite values")
    if low < -RANGE_TOLERANCE or high > 1.0 + RANGE_TOLERANCE:
        raise MapIOError(f"{path}: stored values must lie in [0, 1], found [{low:.4g}, {high:.4g}]")
    return np.clip(values, 0.0, 1.0)


def _decode_normal(path: Path, encoded: Tensor) -> Tensor:
    """``(3, H, W)`` file encoding → unit normals with ``z >= 0``."""
    normal = decode_normal(encoded)
    worst = float(normal[2].min())
    if worst < -NORMAL_Z_TOLERANCE:
        raise MapIOError(
            f"{path}: normals point into the surface (z down to {worst:.3g}); "
            "expected an OpenGL tangent-space map encoded as (n + 1) / 2"
        )
    if worst < 0.0:
        normal = normalize_normal(torch.cat([normal[:2], normal[2:].clamp(min=0.0)]))
    return normal
