"""Distribution statistics of map sets (brdfgan.data.statistics, `brdfgan dataset-stats`)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from brdfgan.cli import main
from brdfgan.core.svbrdf import join_maps
from brdfgan.data.statistics import MapStatistics, dataset_statistics, statistics_table
from tests.conftest import tilted_plane


def _maps(colour: tuple[float, float, float], metallic: float, size: int = 16) -> torch.Tensor:
    basecolor = torch.tensor(colour).view(3, 1, 1).expand(3, size, size)
    normal = tilted_plane(size, (math.sin(math.radians(30.0)), 0.0, math.cos(math.radians(30.0))))[3:6]
    return join_maps(
        basecolor, normal, torch.full((1, size, size), 0.4), torch.full((1, size, size), metallic)
    )


def test_golden_figures_of_known_maps() -> None:
    stats = MapStatistics("toy")
    stats.add(_maps((0.8, 0.1, 0.1), 0.0), "red")  # saturated red dielectric
    stats.add(_maps((0.5, 0.5, 0.5), 1.0), "grey", mixed=True)  # grey metal
    row = stats.row()
    assert row["samples"] == 2 and row["metallic_share"] == pytest.approx(0.5)
    assert row["coloured_share"] == pytest.approx(0.5)
    assert row["hue_evenness"] == pytest.approx(0.0)  # every coloured texel is red
    assert row["roughness_p50"] == pytest.approx(0.4)
    assert row["relief_deg"] == pytest.approx(30.0, abs=1e-3)
    stats.add(_maps((0.1, 0.8, 0.1), 0.0), "green")
    stats.add(_maps((0.1, 0.1, 0.8), 0.0), "blue")
    # Three of six hue sectors equally full: entropy log 3 / log 6.
    assert stats.row()["hue_evenness"] == pytest.approx(math.log(3) / math.log(6), abs=1e-6)
    table = statistics_table([stats])
    assert (
        "| toy | 4 | 25.0% |" in table and "green 1, grey 1, red 1" in table and "mixed materials: 1" in table
    )


def test_dataset_statistics_and_cli(tiny_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tiny_data / "data" / "tiny"
    stats = dataset_statistics(data, "train")
    assert stats.samples > 0 and sum(stats.families.values()) == stats.samples
    assert main(["dataset-stats", str(data)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("| data | samples | metallic |") and f"| tiny/train | {stats.samples} |" in out
    assert main(["dataset-stats", str(data / "nowhere")]) == 2
    assert "no train shards" in capsys.readouterr().err
