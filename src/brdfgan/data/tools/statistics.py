"""Distribution statistics of material maps and captures: how much of what a dataset covers.

    brdfgan dataset-stats DATA_DIR [--split train [val test]] [--scanned DIR]

**Maps.** For each dataset split (from its shards) and, for comparison, a folder of scanned sets
(the out-of-distribution benchmark: measuring its statistics is fine, training on it is not), one
table row each: samples, the share of metallic texels (metallic > 0.5), the base colour's HSV
spread (saturation and value as 10th/50th/90th percentiles, the share of coloured texels —
saturation > 0.2 — and how evenly they spread over six hue sectors, as the normalised entropy:
1 = all hues equally common, 0 = one hue), roughness percentiles and the relief (mean angle of
the normals from +Z, in degrees). Statistics are over a fixed-stride subsample of texels.
A split that mixes real scanned sets (family ``scanned/<set>``) with procedural materials gets
two more rows, ``<split> (procedural)`` and ``<split> (scans)``, so that the scans can be set
beside the procedural families and the benchmark. Then the sample count per family (a mixed
material counts under its own family; scanned sets are counted together, with the number of
distinct sets).

**Captures.** A second table, one row per split (and its procedural and scanned parts), from
each sample's metadata (:meth:`brdfgan.data.phone.conditions.CaptureDraw.to_json`, the flash draw, the
crop transform, the recolour and mix records of :mod:`brdfgan.data.materials.source`): field of
view (°), flash offset (a fraction of the camera distance), tilt (°), exposure error (EV), flash
colour temperature (K) and crop scale, each as min / 10th / 50th / 90th percentile / max, and the
shares of mirrored, recoloured and mixed samples. A quantity no sample records (a dataset made
before it existed) shows "–"; the percentiles are over the samples that record it.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from brdfgan.core.svbrdf import split_maps
from brdfgan.data.materials.scanned import read_scanned_material, scanned_material_folders
from brdfgan.data.materials.source import SCANNED_PREFIX, is_scanned
from brdfgan.data.storage.shards import iter_shard, list_shards
from brdfgan.errors import UserError
from brdfgan.metrics.svbrdf_metrics import basecolor_hsv

HUE_SECTORS = 6
COLOURED_SATURATION = 0.2
MISSING = "–"
_STRIDE = 4  # every 4th texel along each axis
GROUPS = ("procedural", "scans")  # the parts of a split, by family


@dataclass
class MapStatistics:
    """Accumulates subsampled texels of map sets; :meth:`row` summarises them.
    ``list_families``: whether :func:`statistics_table` lists its families (not for the parts of
    a split, whose families the split's row lists)."""

    name: str
    samples: int = 0
    families: Counter[str] = field(default_factory=Counter)
    mixed: int = 0
    _texels: list[Tensor] = field(default_factory=list)
    list_families: bool = True

    def add(self, maps: Tensor, family: str | None = None, mixed: bool = False) -> None:
        """Shape: maps ``(8, H, W)``."""
        self.samples += 1
        if family is not None:
            self.families[family] += 1
        self.mixed += int(mixed)
        self._texels.append(maps[:, ::_STRIDE, ::_STRIDE].reshape(8, -1))

    @classmethod
    def merged(cls, name: str, parts: Iterable[MapStatistics]) -> MapStatistics:
        """The statistics of all of ``parts`` together (sharing their texels, not copying them)."""
        whole = cls(name)
        for part in parts:
            whole.samples += part.samples
            whole.families.update(part.families)
            whole.mixed += part.mixed
            whole._texels.extend(part._texels)
        return whole

    @property
    def scanned_sets(self) -> int:
        """The number of distinct scanned sets among the families."""
        return sum(1 for family in self.families if is_scanned(family))

    def row(self) -> dict[str, float]:
        """The summary figures (see the module docstring)."""
        if not self._texels:
            raise UserError(f"{self.name}: no samples")
        texels = torch.cat(self._texels, dim=1)
        parts = split_maps(texels.view(8, 1, -1))
        hsv = basecolor_hsv(texels.view(8, 1, -1)).view(3, -1)  # the evaluator's hue and saturation
        hue, saturation, value = hsv[0], hsv[1], hsv[2]
        coloured = saturation > COLOURED_SATURATION
        sectors = torch.floor(hue[coloured] / (2 * math.pi) * HUE_SECTORS).clamp(0, HUE_SECTORS - 1)
        counts = torch.bincount(sectors.long(), minlength=HUE_SECTORS).double()
        share = counts / counts.sum().clamp(min=1.0)
        entropy = -(share[share > 0] * share[share > 0].log()).sum() / math.log(HUE_SECTORS)
        q = torch.tensor([0.1, 0.5, 0.9])
        s10, s50, s90 = torch.quantile(saturation, q).tolist()
        v10, v50, v90 = torch.quantile(value, q).tolist()
        r10, r50, r90 = torch.quantile(parts.roughness.flatten(), q).tolist()
        relief = torch.rad2deg(torch.acos(parts.normal[2].flatten().clamp(-1.0, 1.0))).mean().item()
        return {
            "samples": float(self.samples),
            "metallic_share": float((parts.metallic > 0.5).float().mean()),
            "saturation_p10": s10, "saturation_p50": s50, "saturation_p90": s90,
            "value_p10": v10, "value_p50": v50, "value_p90": v90,
            "coloured_share": float(coloured.float().mean()),
            "hue_evenness": float(entropy),
            "roughness_p10": r10, "roughness_p50": r50, "roughness_p90": r90,
            "relief_deg": relief,
        }  # fmt: skip


# ----------------------------------------------------------------------------- captures

# (key, column label, path in a sample's meta, number format)
CAPTURE_QUANTITIES: tuple[tuple[str, str, tuple[str, ...], str], ...] = (
    ("fov_deg", "field of view °", ("capture", "fov_deg"), "{:.1f}"),
    ("flash_offset", "flash offset", ("capture", "flash_offset"), "{:.3f}"),
    ("tilt_deg", "tilt °", ("capture", "tilt_deg"), "{:.1f}"),
    ("exposure_ev", "exposure EV", ("capture", "exposure_ev"), "{:+.2f}"),
    ("temperature_k", "flash K", ("flash", "temperature_k"), "{:.0f}"),
    ("crop_scale", "crop scale", ("crop", "scale"), "{:.3f}"),
)
PERCENTILES = (0.0, 0.1, 0.5, 0.9, 1.0)  # min, p10, p50, p90, max
# (key, column label): shares of the samples
CAPTURE_SHARES = (("mirrored", "mirrored"), ("recoloured", "recoloured"), ("mixed", "mixed"))


def meta_number(meta: Mapping[str, Any], path: Sequence[str]) -> float | None:
    """The number at ``path`` in ``meta`` (``("capture", "fov_deg")``), or None where a key is
    missing or the value is not a number."""
    value: Any = meta
    for key in path:
        if not isinstance(value, Mapping) or key not in value:
            return None
        value = value[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value)


def percentiles(values: Sequence[float]) -> tuple[float, ...] | None:
    """Min, 10th, 50th, 90th percentile and max of ``values`` (linearly interpolated, as
    :func:`torch.quantile` and NumPy's default), or None for no values."""
    if not values:
        return None
    q = torch.tensor(PERCENTILES, dtype=torch.float64)
    return tuple(torch.quantile(torch.tensor(values, dtype=torch.float64), q).tolist())


@dataclass
class CaptureStatistics:
    """Accumulates the capture records of samples' metadata; :meth:`row` summarises them."""

    name: str
    samples: int = 0
    values: dict[str, list[float]] = field(
        default_factory=lambda: {key: [] for key, *_ in CAPTURE_QUANTITIES}
    )
    cropped: int = 0  # samples with a crop record (the denominator of the mirrored share)
    mirrored: int = 0
    recoloured: int = 0
    mixed: int = 0

    def add(self, meta: Mapping[str, Any]) -> None:
        self.samples += 1
        for key, _, path, _ in CAPTURE_QUANTITIES:
            value = meta_number(meta, path)
            if value is not None:
                self.values[key].append(value)
        crop = meta.get("crop")
        if isinstance(crop, Mapping):
            self.cropped += 1
            self.mirrored += int(bool(crop.get("mirror", False)))
        # Recorded only when drawn: absent is "not recoloured / not mixed", in older datasets too.
        self.recoloured += int("recolor" in meta)
        self.mixed += int("mix" in meta)

    @classmethod
    def merged(cls, name: str, parts: Iterable[CaptureStatistics]) -> CaptureStatistics:
        whole = cls(name)
        for part in parts:
            whole.samples += part.samples
            for key, values in part.values.items():
                whole.values[key].extend(values)
            whole.cropped += part.cropped
            whole.mirrored += part.mirrored
            whole.recoloured += part.recoloured
            whole.mixed += part.mixed
        return whole

    def row(self) -> dict[str, Any]:
        """``samples``; per quantity of :data:`CAPTURE_QUANTITIES` its :func:`percentiles`
        (None: no sample records it); per share of :data:`CAPTURE_SHARES` a fraction (None:
        unknown)."""
        if not self.samples:
            raise UserError(f"{self.name}: no samples")
        row: dict[str, Any] = {"samples": self.samples}
        row |= {key: percentiles(self.values[key]) for key, *_ in CAPTURE_QUANTITIES}
        row["mirrored"] = self.mirrored / self.cropped if self.cropped else None
        row["recoloured"] = self.recoloured / self.samples
        row["mixed"] = self.mixed / self.samples
        return row


# ----------------------------------------------------------------------------- splits


@dataclass
class SplitStatistics:
    """The map and capture statistics of one dataset split, kept by part (:data:`GROUPS`:
    procedural materials and scanned sets)."""

    name: str
    maps: dict[str, MapStatistics]
    captures: dict[str, CaptureStatistics]

    @classmethod
    def empty(cls, name: str) -> SplitStatistics:
        return cls(
            name,
            {group: MapStatistics(f"{name} ({group})", list_families=False) for group in GROUPS},
            {group: CaptureStatistics(f"{name} ({group})") for group in GROUPS},
        )

    def add(self, maps: Tensor, meta: Mapping[str, Any]) -> None:
        family = str(meta.get("family", "?"))
        group = "scans" if is_scanned(family) else "procedural"
        self.maps[group].add(maps, family, "mix" in meta)
        self.captures[group].add(meta)

    @property
    def mixes_scans(self) -> bool:
        """Whether the split holds both procedural materials and scans (then its parts get rows)."""
        return all(stats.samples for stats in self.maps.values())

    @property
    def whole(self) -> MapStatistics:
        return MapStatistics.merged(self.name, self.maps.values())

    def map_rows(self) -> list[MapStatistics]:
        """The whole split's statistics, then its parts' where it mixes scans in."""
        return [self.whole, *self.maps.values()] if self.mixes_scans else [self.whole]

    def capture_rows(self) -> list[CaptureStatistics]:
        whole = CaptureStatistics.merged(self.name, self.captures.values())
        return [whole, *self.captures.values()] if self.mixes_scans else [whole]


def split_shards(data_dir: str | os.PathLike[str], split: str) -> list[Path]:
    """The shards of a split; a one-line :class:`UserError` naming the path where there are none."""
    shards = list_shards(data_dir, split)
    if shards:
        return shards
    root = Path(data_dir)
    if not root.is_dir():
        raise UserError(f"{data_dir}: no {split} shards (no such directory)")
    present = sorted(p.name for p in root.iterdir() if p.is_dir() and list_shards(root, p.name))
    having = f" (shards found for: {', '.join(present)})" if present else ""
    raise UserError(f"{data_dir}: no {split} shards{having}")


def _split_name(data_dir: str | os.PathLike[str], split: str) -> str:
    root = Path(data_dir)
    return f"{root.name or root.resolve().name}/{split}"


def split_statistics(
    data_dir: str | os.PathLike[str], split: str = "train", shards: Sequence[Path] | None = None
) -> SplitStatistics:
    """Map and capture statistics of every sample of a dataset split (of ``shards``, by default
    all of the split's)."""
    stats = SplitStatistics.empty(_split_name(data_dir, split))
    for shard in split_shards(data_dir, split) if shards is None else shards:
        for sample in iter_shard(shard):
            stats.add(sample.maps, sample.meta)
    return stats


def dataset_statistics(data_dir: str | os.PathLike[str], split: str = "train") -> MapStatistics:
    """Statistics of the maps of every sample of a dataset split."""
    return split_statistics(data_dir, split).whole


def scanned_statistics(folder: str | os.PathLike[str], resolution: int = 512) -> MapStatistics:
    """Statistics of the whole maps of every scanned set in ``folder`` (at ``resolution``²)."""
    stats = MapStatistics(Path(folder).name)
    for material in scanned_material_folders(folder, key="--scanned"):
        stats.add(read_scanned_material(material, resolution), f"{SCANNED_PREFIX}{material.name}")
    return stats


# ----------------------------------------------------------------------------- tables

COLUMNS = (
    ("samples", "samples", "{:.0f}"),
    ("metallic_share", "metallic", "{:.1%}"),
    ("coloured_share", "coloured", "{:.1%}"),
    ("hue_evenness", "hue evenness", "{:.2f}"),
    ("saturation_p10", "sat p10", "{:.2f}"),
    ("saturation_p50", "sat p50", "{:.2f}"),
    ("saturation_p90", "sat p90", "{:.2f}"),
    ("value_p10", "val p10", "{:.2f}"),
    ("value_p50", "val p50", "{:.2f}"),
    ("value_p90", "val p90", "{:.2f}"),
    ("roughness_p10", "rough p10", "{:.2f}"),
    ("roughness_p50", "rough p50", "{:.2f}"),
    ("roughness_p90", "rough p90", "{:.2f}"),
    ("relief_deg", "relief °", "{:.1f}"),
)


def _family_counts(stats: MapStatistics) -> str:
    """``bricks 4, wood 2; scanned: 3 sets, 5 samples`` (scanned sets counted together)."""
    procedural = [f"{name} {count}" for name, count in sorted(stats.families.items()) if not is_scanned(name)]
    scanned = sum(count for name, count in stats.families.items() if is_scanned(name))
    if scanned:
        sets = stats.scanned_sets
        counts = (
            f"scanned: {sets} set{'s' if sets != 1 else ''}, {scanned} sample{'s' if scanned != 1 else ''}"
        )
        return "; ".join(part for part in (", ".join(procedural), counts) if part)
    return ", ".join(procedural)


def statistics_table(stats: Iterable[MapStatistics]) -> str:
    """A markdown table, one row per statistics object, then the family counts of each (of those
    with ``list_families``)."""
    stats = list(stats)
    lines = [
        "| data | " + " | ".join(label for _, label, _ in COLUMNS) + " |",
        "|---|" + "---|" * len(COLUMNS),
    ]
    for s in stats:
        row = s.row()
        lines.append(f"| {s.name} | " + " | ".join(fmt.format(row[key]) for key, _, fmt in COLUMNS) + " |")
    for s in stats:
        if s.families and s.list_families:
            mixed = f"; mixed materials: {s.mixed}" if s.mixed else ""
            lines.append(f"\n{s.name} samples per family: {_family_counts(s)}{mixed}")
    return "\n".join(lines) + "\n"


def capture_table(stats: Iterable[CaptureStatistics]) -> str:
    """A markdown table of the capture distributions, one row per statistics object: each
    quantity as ``min / p10 / p50 / p90 / max``, each share as a percentage, "–" where unknown."""
    lines = [
        "| capture | samples | " + " | ".join(label for _, label, _, _ in CAPTURE_QUANTITIES) + " | "
        + " | ".join(label for _, label in CAPTURE_SHARES) + " |",
        "|---|" + "---|" * (1 + len(CAPTURE_QUANTITIES) + len(CAPTURE_SHARES)),
    ]  # fmt: skip
    for s in stats:
        row = s.row()
        cells = [str(row["samples"])]
        for key, _, _, fmt in CAPTURE_QUANTITIES:
            cells.append(MISSING if row[key] is None else " / ".join(fmt.format(v) for v in row[key]))
        cells += [MISSING if row[key] is None else f"{row[key]:.1%}" for key, _ in CAPTURE_SHARES]
        lines.append(f"| {s.name} | " + " | ".join(cells) + " |")
    lines.append(
        "\nquantities: min / p10 / p50 / p90 / max; flash offset as a fraction of the camera "
        f"distance; {MISSING}: not recorded in the samples' metadata"
    )
    return "\n".join(lines) + "\n"


def dataset_report(
    data_dir: str | os.PathLike[str],
    splits: Sequence[str] = ("train",),
    scanned: str | os.PathLike[str] | None = None,
) -> str:
    """The text of ``brdfgan dataset-stats``: the map table (each split's rows, then the scanned
    folder's), then the capture table. Every split is checked to have shards before any is read."""
    splits = list(dict.fromkeys(splits))  # once each, in order
    shards = {split: split_shards(data_dir, split) for split in splits}
    ood = scanned_statistics(scanned) if scanned is not None else None
    per_split = [split_statistics(data_dir, split, shards[split]) for split in splits]
    map_rows = [row for stats in per_split for row in stats.map_rows()]
    return (
        statistics_table(map_rows + ([ood] if ood is not None else []))
        + "\n"
        + capture_table(row for stats in per_split for row in stats.capture_rows())
    )


__all__ = [
    "CAPTURE_QUANTITIES",
    "CaptureStatistics",
    "MapStatistics",
    "SplitStatistics",
    "capture_table",
    "dataset_report",
    "dataset_statistics",
    "is_scanned",
    "meta_number",
    "percentiles",
    "scanned_statistics",
    "split_shards",
    "split_statistics",
    "statistics_table",
]
