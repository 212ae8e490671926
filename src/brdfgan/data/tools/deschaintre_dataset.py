"""Converter for the dataset layout of Deschaintre et al. 2018 (single-image SVBRDF capture).

Their dataset stores each sample as one PNG of five square tiles side by side::

    input | normal | diffuse | roughness | specular

(256² tiles in the test sets, 288² in the training set that their code crops to 256²). This
module turns such files into our samples (:class:`~brdfgan.data.storage.shards.Sample`, our 8-channel map
layout) and a folder of them into sharded splits with a manifest, so ``evaluate.py`` can run on that
public data. Encodings assumed, tile by tile (each choice is documented where it is made):

========= ============================================ =========================================
tile      their file                                   ours
========= ============================================ =========================================
input     flash photo, sRGB-encoded 8-bit               linear LDR (:func:`srgb_to_linear`)
normal    ``(n + 1) / 2``, +Z out                       unit normal, OpenGL (+Y up); see below
diffuse   diffuse albedo d, sRGB-encoded                } base colour b and metallic m by least
specular  specular albedo (F0) s, sRGB-encoded          } squares, :func:`albedos_to_basecolor_metallic`
roughness gray stored as RGB, raw value                 perceptual roughness, unchanged
========= ============================================ =========================================

- **Albedos.** The maps come from Substance materials converted to the specular/glossiness
  workflow, ``d = b (1 - m)`` and ``s = 0.04 (1 - m) + b m`` with b linear: exactly our derived
  albedos (docs/conventions.md#derived-albedos), so we invert that model. Their later code
  linearises albedos and photos with a pure 2.2 power; we use the exact sRGB curve like everywhere
  else here. (Their 2018 renderer additionally scales the diffuse term by ``1 - s``: a renderer
  choice, not part of the stored maps.)
- **Roughness.** Their GGX uses ``alpha = roughness²`` on the stored value, as ours does, so the
  value is our perceptual roughness. The three channels are averaged.
- **Normals.** The released code does not state the tangent frame of the normal tiles (its
  rendering-loss grid even runs x along image rows), and Substance exports either convention.
  We assume OpenGL (+Y up, our convention); ``flip_green=True`` reads DirectX (+Y down) files.
  Decoded normals are renormalised, and a z slightly below 0 (8-bit rounding) is clamped to 0.

Malformed files (not decodable, not RGB, width ≠ 5 × height, crop larger than a tile) raise
:class:`DeschaintreFormatError`, a one-line ``ValueError`` naming the file.
:func:`convert_deschaintre_folder` stops at the first one by default — before writing a manifest, so
a half-converted split is never mistaken for a complete one — or, with ``skip_malformed=True``,
skips it and lists it (file and reason) in the manifest and the returned summary.

Command: ``brdfgan convert-deschaintre SRC OUT [--split test] [--flip-green] ...``
"""

from __future__ import annotations

import itertools
import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.svbrdf import (
    DIELECTRIC_F0,
    diffuse_albedo,
    encode_normal,
    join_maps,
    linear_to_srgb,
    normalize_normal,
    specular_albedo,
    split_maps,
    srgb_to_linear,
)
from brdfgan.data.storage.shards import (
    Sample,
    ShardInfo,
    list_shards,
    shard_path,
    write_manifest,
    write_shard,
)
from brdfgan.errors import UserError
from brdfgan.io.images import ImageIOError, read_image, write_image

__all__ = [
    "TILES",
    "ConversionSummary",
    "DeschaintreDatasetError",
    "DeschaintreFormatError",
    "albedos_to_basecolor_metallic",
    "convert_deschaintre_folder",
    "maps_from_deschaintre",
    "maps_to_deschaintre",
    "read_deschaintre_sample",
    "write_deschaintre_sample",
]

TILES: tuple[str, ...] = ("input", "normal", "diffuse", "roughness", "specular")
SOURCE_FORMAT = "deschaintre2018"
DEFAULT_SAMPLES_PER_SHARD = 64
# Metallic search: a coarse grid finds the basin, golden-section search refines it to ~1e-7.
_GRID_STEPS = 32
_GOLDEN_ITERATIONS = 40
# Two fits whose squared residuals (linear albedo units) differ by less than this are a tie: about
# the residual that 8-bit rounding of d and s alone produces for dark colours.
TIE_TOLERANCE = 1e-6
_BINARY_EPS = 1e-6


class DeschaintreDatasetError(UserError):
    """The conversion cannot proceed (bad folder, existing output); the message names the path."""


class DeschaintreFormatError(DeschaintreDatasetError):
    """A file is not a sample in the Deschaintre 2018 layout; the message names the file."""


# --------------------------------------------------------------------------------------------
# Map conversion


def albedos_to_basecolor_metallic(diffuse: Tensor, specular: Tensor) -> tuple[Tensor, Tensor]:
    """Invert ``d = b (1 - m)``, ``s = 0.04 (1 - m) + b m`` per pixel by least squares over RGB.

    Derivation. Write ``u = 1 - m``. For a fixed u, the best b of channel c minimises
    ``(b u - d_c)² + (b m - (s_c - 0.04 u))²``: the squared distance from the point
    ``(d_c, s_c - 0.04 u)`` to the line through 0 along ``(u, m)``, which gives

        ``b_c = (u d_c + m (s_c - 0.04 u)) / (u² + m²)``,
        ``residual(u) = Σ_c q_c(u)² / (u² + (1 - u)²)``, ``q_c(u) = 0.04 u² - (d_c + s_c) u + d_c``.

    The residual is minimised over u ∈ [0, 1] (grid, then golden-section search); b is clamped to
    [0, 1]. Maps made by the forward formulas have residual 0 at the true u.

    Ambiguity. Averaging ``q_c(u) = 0`` over channels gives a quadratic whose two roots are the
    true u and ``25 · mean(b)``: when the base colour is dark (mean linear b < 0.04, sRGB ≈ 0.22)
    and nearly gray, a metal and a half-metal fit equally well (e.g. b = 0.02, m = 0 and
    b = 0.04, m = 0.5 give the same d and s). Of two fits within :data:`TIE_TOLERANCE` we take the
    one whose metallic is closer to 0 or 1, as real metallic maps are nearly binary, and of two
    equally binary ones the dielectric (black b = 0, m = 0 and a metal with b = 0.04 both give
    d = 0, s = 0.04; black dielectrics are common, metals that dark are not).

    Shape:
        - diffuse, specular: ``(*, 3, H, W)``, linear albedos in [0, 1]
        - output: linear base colour ``(*, 3, H, W)`` and metallic ``(*, 1, H, W)`` (input dtype)
    """
    check_shape(diffuse, "* 3 H W", name="diffuse")
    if diffuse.shape != specular.shape:
        raise ValueError(
            "diffuse and specular must both be (*, 3, H, W), "
            f"got {tuple(diffuse.shape)} and {tuple(specular.shape)}"
        )
    d, s = diffuse.double(), specular.double()
    # Σ_c q_c(u)² as a quartic in u with per-pixel coefficients: no channel axis in the search.
    a = DIELECTRIC_F0
    b, c = -(d + s), d
    coefficients = [
        torch.full_like(d[..., :1, :, :], 3 * a * a),
        2 * a * b.sum(-3, keepdim=True),
        (b * b + 2 * a * c).sum(-3, keepdim=True),
        2 * (b * c).sum(-3, keepdim=True),
        (c * c).sum(-3, keepdim=True),
    ]

    def residual(u: Tensor) -> Tensor:
        quartic = coefficients[0]
        for coefficient in coefficients[1:]:
            quartic = quartic * u + coefficient
        return quartic / (u * u + (1 - u) ** 2)

    grid = torch.linspace(0.0, 1.0, _GRID_STEPS + 1, dtype=torch.float64)
    values = torch.stack([residual(torch.full_like(coefficients[0], float(g))) for g in grid])
    best = grid[values.argmin(dim=0)]
    low, high = (best - 1.0 / _GRID_STEPS).clamp(min=0.0), (best + 1.0 / _GRID_STEPS).clamp(max=1.0)
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(_GOLDEN_ITERATIONS):
        left, right = high - ratio * (high - low), low + ratio * (high - low)
        keep_left = residual(left) <= residual(right)
        high = torch.where(keep_left, right, high)
        low = torch.where(keep_left, low, left)
    u = (low + high) / 2
    for edge in (0.0, 1.0):  # a minimum on the boundary is approached, never evaluated, by the search
        edge_u = torch.full_like(u, edge)
        u = torch.where(residual(edge_u) <= residual(u), edge_u, u)

    # The other root of the channel-averaged quadratic (roots sum to mean(d + s) / 0.04).
    other = (d + s).mean(-3, keepdim=True) / a - u
    distance, other_distance = torch.minimum(u, 1 - u), torch.minimum(other, 1 - other)
    more_binary = (other_distance < distance - _BINARY_EPS) | (
        ((other_distance - distance).abs() <= _BINARY_EPS) & (other > u)  # equally: prefer the dielectric
    )
    tie = residual(other.clamp(0, 1)) <= residual(u) + TIE_TOLERANCE
    u = torch.where((other >= 0) & (other <= 1) & tie & more_binary, other, u)

    m = 1 - u
    basecolor = ((u * d + m * (s - a * u)) / (u * u + m * m)).clamp(0.0, 1.0)
    return basecolor.to(diffuse.dtype), m.to(diffuse.dtype)


def maps_from_deschaintre(
    normal: Tensor, diffuse: Tensor, roughness: Tensor, specular: Tensor, *, flip_green: bool = False
) -> Tensor:
    """Their four map tiles, as stored in [0, 1], → our 8-channel map set.

    Shape:
        - normal, diffuse, roughness, specular: ``(*, 3, H, W)`` file values in [0, 1]
          (roughness may also be ``(*, 1, H, W)``)
        - output: ``(*, 8, H, W)``, the layout of :mod:`brdfgan.core.svbrdf`
    """
    vector = normal * 2.0 - 1.0
    if flip_green:
        vector = torch.cat([vector[..., :1, :, :], -vector[..., 1:2, :, :], vector[..., 2:, :, :]], dim=-3)
    # 8-bit rounding can push grazing normals just below the surface; clamp, then renormalise.
    vector = torch.cat([vector[..., :2, :, :], vector[..., 2:, :, :].clamp(min=0.0)], dim=-3)
    basecolor, metallic = albedos_to_basecolor_metallic(srgb_to_linear(diffuse), srgb_to_linear(specular))
    return join_maps(
        linear_to_srgb(basecolor).clamp(0.0, 1.0),
        normalize_normal(vector),
        roughness.mean(dim=-3, keepdim=True).clamp(0.0, 1.0),
        metallic,
    )


def maps_to_deschaintre(maps: Tensor, *, flip_green: bool = False) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Our map set → their four tiles (normal, diffuse, roughness, specular) as file values in [0, 1].

    The inverse of :func:`maps_from_deschaintre` up to its documented ambiguity; used to write test
    data and to export our predictions in their layout.

    Shape:
        - maps: ``(*, 8, H, W)``
        - output: four ``(*, 3, H, W)`` tensors (roughness repeated as gray RGB)
    """
    parts = split_maps(maps)
    normal = parts.normal
    if flip_green:
        normal = torch.cat([normal[..., :1, :, :], -normal[..., 1:2, :, :], normal[..., 2:, :, :]], dim=-3)
    basecolor = srgb_to_linear(parts.basecolor)
    diffuse = linear_to_srgb(diffuse_albedo(basecolor, parts.metallic))
    specular = linear_to_srgb(specular_albedo(basecolor, parts.metallic))
    roughness = parts.roughness.expand(*parts.roughness.shape[:-3], 3, *parts.roughness.shape[-2:])
    return encode_normal(normal), diffuse, roughness, specular


# --------------------------------------------------------------------------------------------
# Files


def read_deschaintre_sample(
    path: str | os.PathLike[str], *, key: str | None = None, flip_green: bool = False, crop: int | None = None
) -> Sample:
    """Read one PNG of five tiles (``input | normal | diffuse | roughness | specular``) as a sample.

    ``crop`` takes the centred ``crop × crop`` window of every tile (their 288² training tiles are
    cropped to 256² by their code). ``key`` defaults to the file name made key-safe.

    Shape:
        - output.photo: ``(3, S, S)`` linear; output.maps: ``(8, S, S)``, S the tile size or ``crop``

    Raises:
        DeschaintreFormatError: naming the file, when it is not in this layout.
    """
    path = Path(path)
    try:
        image = read_image(path)
    except ImageIOError as error:
        raise DeschaintreFormatError(str(error)) from error
    height, width, channels = image.shape
    if channels not in (3, 4):
        raise DeschaintreFormatError(f"{path}: expected an RGB image, got {channels} channel(s)")
    if width != len(TILES) * height:
        raise DeschaintreFormatError(
            f"{path}: expected {len(TILES)} square tiles side by side ({' | '.join(TILES)}), "
            f"i.e. width = {len(TILES)} × height; got {width}×{height}"
        )
    if crop is not None and not 0 < crop <= height:
        raise DeschaintreFormatError(f"{path}: crop {crop} must lie in [1, {height}] (the tile size)")
    size = crop or height
    top = (height - size) // 2
    rgb = torch.from_numpy(np.ascontiguousarray(image[top : top + size, :, :3].transpose(2, 0, 1)))
    tiles = [rgb[:, :, i * height + top : i * height + top + size] for i in range(len(TILES))]
    photo = srgb_to_linear(tiles[0]).clamp(0.0, 1.0)
    maps = maps_from_deschaintre(*tiles[1:], flip_green=flip_green)
    meta = {
        "source": SOURCE_FORMAT,
        "file": path.name,
        "tile": height,
        "crop": crop,
        "flip_green": flip_green,
    }
    return Sample(key=key or _key(path.stem), photo=photo, maps=maps, meta=meta)


def write_deschaintre_sample(
    path: str | os.PathLike[str], photo: Tensor, maps: Tensor, *, flip_green: bool = False
) -> Path:
    """Write a photo and its maps as one 8-bit PNG in their layout (the inverse of reading).

    Shape:
        - photo: ``(3, H, W)`` linear LDR in [0, 1]; maps: ``(8, H, W)``
    """
    height, width = maps.shape[-2:]
    check_shape(photo, "3 H W", name="photo (the maps' size)", dims={"H": height, "W": width})
    tiles = (linear_to_srgb(photo.clamp(0.0, 1.0)), *maps_to_deschaintre(maps, flip_green=flip_green))
    strip = torch.cat([tile.detach().cpu().float() for tile in tiles], dim=-1)
    return write_image(path, strip.permute(1, 2, 0).numpy(), bit_depth=8)


def _key(stem: str, index: int | None = None) -> str:
    # Their names contain ';' and spaces; keys allow letters, digits, '_' and '-' only. The index
    # keeps keys unique when different names sanitise alike.
    safe = re.sub(r"[^A-Za-z0-9_-]+", "_", stem).strip("_") or "sample"
    key = safe if index is None else f"{index:06d}_{safe}"
    return key[:80]


# --------------------------------------------------------------------------------------------
# Folders


@dataclass
class ConversionSummary:
    """What :func:`convert_deschaintre_folder` wrote, and the files it skipped (name, reason)."""

    manifest: Path
    samples: int
    shards: list[ShardInfo] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)

    def describe(self) -> str:
        text = f"{self.samples} sample(s) in {len(self.shards)} shard(s); manifest {self.manifest}"
        return text + (f"; skipped {len(self.skipped)} malformed file(s)" if self.skipped else "")


def convert_deschaintre_folder(
    src_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    split: str = "test",
    samples_per_shard: int = DEFAULT_SAMPLES_PER_SHARD,
    *,
    flip_green: bool = False,
    crop: int | None = None,
    skip_malformed: bool = False,
    overwrite: bool = False,
) -> ConversionSummary:
    """Convert every ``*.png`` of ``src_dir`` (sorted by name) into ``out_dir/<split>/`` shards
    and a manifest, the layout :class:`~brdfgan.data.loading.datamodule.ShardDataModule` reads.

    Shards hold ``samples_per_shard`` samples each (the last one fewer); keys are
    ``<index>_<file name>``. An existing split with shards is refused unless ``overwrite``, which
    removes its shards and manifest first (stale shards would otherwise join the split).

    Raises:
        DeschaintreFormatError: the first malformed file, unless ``skip_malformed``; no manifest is
            written then.
        DeschaintreDatasetError: a missing or empty source folder, an existing split, no valid file.
    """
    src, root = Path(src_dir), Path(out_dir)
    if samples_per_shard < 1:
        raise DeschaintreDatasetError(f"samples_per_shard must be >= 1, got {samples_per_shard}")
    if not src.is_dir():
        raise DeschaintreDatasetError(f"{src}: source folder not found")
    files = sorted(p for p in src.iterdir() if p.suffix.lower() == ".png" and p.is_file())
    if not files:
        raise DeschaintreDatasetError(f"{src}: no .png files")
    _prepare_split(root, split, overwrite)

    skipped: list[tuple[str, str]] = []

    def samples() -> Iterator[Sample]:
        for index, path in enumerate(files):
            try:
                yield read_deschaintre_sample(
                    path, key=_key(path.stem, index), flip_green=flip_green, crop=crop
                )
            except DeschaintreFormatError as error:
                if not skip_malformed:
                    raise
                skipped.append((path.name, str(error)))

    stream = samples()
    shards: list[ShardInfo] = []
    try:
        while (first := next(stream, None)) is not None:
            batch = itertools.chain([first], itertools.islice(stream, samples_per_shard - 1))
            shards.append(write_shard(shard_path(root, split, len(shards)), batch))
    except OSError as error:
        raise DeschaintreDatasetError(
            f"{root / split}: cannot write shards ({error.strerror or error})"
        ) from error
    if not shards:
        raise DeschaintreDatasetError(f"{src}: none of the {len(files)} .png files is a valid sample")

    from brdfgan.data.generation.generation import code_version  # heavy imports, needed only here

    count = sum(info.count for info in shards)
    manifest = {
        "split": split,
        "samples": count,
        "shards": [
            {"name": info.path.name, "samples": info.count, "bytes": info.bytes, "sha256": info.sha256}
            for info in shards
        ],
        "source": {"format": SOURCE_FORMAT, "dir": str(src.resolve()), "files": len(files)},
        "conversion": {
            "flip_green": flip_green,
            "crop": crop,
            "photo": "sRGB → linear",
            "albedos": "sRGB → linear; least squares of d = b(1-m), s = 0.04(1-m) + b m",
            "roughness": "perceptual (alpha = r²), unchanged",
        },
        "skipped": [{"file": name, "error": reason} for name, reason in skipped],
        "code_version": code_version(),
    }
    return ConversionSummary(write_manifest(root, split, manifest), count, shards, skipped)


def _prepare_split(root: Path, split: str, overwrite: bool) -> None:
    existing = list_shards(root, split)
    manifest = root / split / "manifest.json"
    if not (existing or manifest.exists()):
        return
    if not overwrite:
        raise DeschaintreDatasetError(
            f"{root / split}: already holds a converted split; "
            "pass overwrite=True (--overwrite) to replace it"
        )
    for path in [manifest, *existing]:
        path.unlink(missing_ok=True)
