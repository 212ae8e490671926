"""Distribution statistics of material maps: how much of what a dataset covers.

    brdfgan dataset-stats DATA_DIR [--split train] [--scanned DIR]

For a dataset split (from its shards) and, for comparison, a folder of scanned sets (the
out-of-distribution benchmark: measuring its statistics is fine, training on it is not), one
table row each: samples, the share of metallic texels (metallic > 0.5), the base colour's HSV
spread (saturation and value as 10th/50th/90th percentiles, the share of coloured texels —
saturation > 0.2 — and how evenly they spread over six hue sectors, as the normalised entropy:
1 = all hues equally common, 0 = one hue), roughness percentiles and the relief (mean angle of
the normals from +Z, in degrees). Statistics are over a fixed-stride subsample of texels.
Also the sample count per family (a mixed material counts under its own family).
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import kornia.color
import torch
from torch import Tensor

from brdfgan.core.svbrdf import split_maps
from brdfgan.data.scanned import read_scanned_material, scanned_material_folders
from brdfgan.data.shards import iter_shard, list_shards
from brdfgan.errors import UserError

HUE_SECTORS = 6
COLOURED_SATURATION = 0.2
_STRIDE = 4  # every 4th texel along each axis


@dataclass
class MapStatistics:
    """Accumulates subsampled texels of map sets; :meth:`row` summarises them."""

    name: str
    samples: int = 0
    families: Counter[str] = field(default_factory=Counter)
    mixed: int = 0
    _texels: list[Tensor] = field(default_factory=list)

    def add(self, maps: Tensor, family: str | None = None, mixed: bool = False) -> None:
        """Shape: maps ``(8, H, W)``."""
        self.samples += 1
        if family is not None:
            self.families[family] += 1
        self.mixed += int(mixed)
        self._texels.append(maps[:, ::_STRIDE, ::_STRIDE].reshape(8, -1))

    def row(self) -> dict[str, float]:
        """The summary figures (see the module docstring)."""
        if not self._texels:
            raise UserError(f"{self.name}: no samples")
        texels = torch.cat(self._texels, dim=1)
        parts = split_maps(texels.view(8, 1, -1))
        hsv = kornia.color.rgb_to_hsv(parts.basecolor.clamp(0.0, 1.0)[None])[0].view(3, -1)
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


def dataset_statistics(data_dir: str | os.PathLike[str], split: str = "train") -> MapStatistics:
    """Statistics of the maps of every sample of a dataset split."""
    shards = list_shards(data_dir, split)
    if not shards:
        raise UserError(f"{data_dir}: no {split} shards")
    stats = MapStatistics(f"{Path(data_dir).name}/{split}")
    for shard in shards:
        for sample in iter_shard(shard):
            stats.add(sample.maps, str(sample.meta.get("family", "?")), "mix" in sample.meta)
    return stats


def scanned_statistics(folder: str | os.PathLike[str], resolution: int = 512) -> MapStatistics:
    """Statistics of the whole maps of every scanned set in ``folder`` (at ``resolution``²)."""
    stats = MapStatistics(Path(folder).name)
    for material in scanned_material_folders(folder, key="--scanned"):
        stats.add(read_scanned_material(material, resolution), f"scanned/{material.name}")
    return stats


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


def statistics_table(stats: Iterable[MapStatistics]) -> str:
    """A markdown table, one row per statistics object, then the family counts of each."""
    stats = list(stats)
    lines = [
        "| data | " + " | ".join(label for _, label, _ in COLUMNS) + " |",
        "|---|" + "---|" * len(COLUMNS),
    ]
    for s in stats:
        row = s.row()
        lines.append(f"| {s.name} | " + " | ".join(fmt.format(row[key]) for key, _, fmt in COLUMNS) + " |")
    for s in stats:
        if s.families:
            counts = ", ".join(f"{name} {count}" for name, count in sorted(s.families.items()))
            mixed = f"; mixed materials: {s.mixed}" if s.mixed else ""
            lines.append(f"\n{s.name} samples per family: {counts}{mixed}")
    return "\n".join(lines) + "\n"


__all__ = ["MapStatistics", "dataset_statistics", "scanned_statistics", "statistics_table"]
