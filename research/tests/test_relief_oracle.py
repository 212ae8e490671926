"""research.relief_oracle: shape from shading with the rest of the surface known, scored as the
evaluator scores a model's normals, on the tiny Mitsuba dataset."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import torch

from brdfgan.core.svbrdf import NORMAL, flat_maps
from research.relief_oracle import main, radial_scores, radial_sums


def test_radial_scores_are_one_for_the_truth_and_zero_without_relief() -> None:
    maps = flat_maps(16, 16, batch=(1,))
    tilt = 0.2 * torch.randn(2, 16, 16, generator=torch.Generator().manual_seed(0))
    maps[0, NORMAL] = torch.nn.functional.normalize(torch.cat([tilt, torch.ones(1, 16, 16)]), dim=0)
    frame = torch.tensor([[8.0, 8.0, 0.05]])
    scores = radial_scores(radial_sums(maps[:, NORMAL], maps[:, NORMAL], frame))
    assert scores["radial_cosine"] == pytest.approx(1.0)
    assert 0.2 < scores["radial_share"] < 0.8  # isotropic noise: about half of it along the light
    flat = flat_maps(16, 16, batch=(1,))[:, NORMAL]
    assert radial_scores(radial_sums(flat, maps[:, NORMAL], frame))["radial_cosine"] == 0.0


def test_the_oracle_reads_the_tiny_sets_relief_from_its_own_shading(tiny_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "oracle"
    main(["data=tiny", f"data.data_dir={tiny_data / 'data' / 'tiny'}",
          "--out", str(out), "--limit", "2", "--steps", "60", "--ridge", "0", "1000"])  # fmt: skip
    results = json.loads(out.with_suffix(".json").read_text())["results"]
    assert set(results) == {"shading/ridge=0", "shading/ridge=1000", "photo/ridge=0", "photo/ridge=1000"}
    exact, flattened = results["shading/ridge=0"], results["shading/ridge=1000"]
    assert exact["photos"] == 2
    # The tiny set's relief is faint (0.24° from flat): from its own, noise-free shading the fit
    # draws some of it the right way round; a ridge this strong pulls it nearly flat.
    assert exact["normal_slope_cosine"] > 0.0 and exact["radial_cosine"] > 0.0
    assert flattened["normal_slope_ratio"] < exact["normal_slope_ratio"]
    assert exact["misfit_share"] < flattened["misfit_share"] <= 1.0 + 1e-9
    assert exact["shading_correlation"] == pytest.approx(1.0)  # the observation is the true shading
    assert flattened["angle_deg"] == pytest.approx(flattened["flat_angle_deg"], rel=0.05)
    # Without a ridge the photo's noise is fitted as relief.
    assert (
        results["photo/ridge=0"]["normal_slope_ratio"]
        > 10 * results["photo/ridge=1000"]["normal_slope_ratio"]
    )
    for row in results.values():
        assert 0.0 <= row["radial_share"] <= 1.0 and all(math.isfinite(v) for v in row.values())


def test_no_steps_scores_the_flat_start_and_the_observations_correlation(
    tiny_data: Path, tmp_path: Path
) -> None:
    data = ["data=tiny", f"data.data_dir={tiny_data / 'data' / 'tiny'}", "--limit", "2", "--ridge", "1"]
    main([*data, "--out", str(tmp_path / "none"), "--steps", "0", "--observations", "photo"])
    main([*data, "--out", str(tmp_path / "fit"), "--steps", "20", "--observations", "photo"])
    none, fit = (
        json.loads((tmp_path / name).with_suffix(".json").read_text())["results"]["photo/ridge=1"]
        for name in ("none", "fit")
    )
    # No iteration: the flat start, which leaves all of the observation's variation unexplained.
    assert none["angle_deg"] == pytest.approx(none["flat_angle_deg"])
    assert none["misfit_share"] == pytest.approx(1.0)
    assert fit["misfit_share"] < 1.0
    # The correlation is the observation's, whatever the fit.
    assert none["shading_correlation"] == pytest.approx(fit["shading_correlation"])
    assert 0.0 < abs(none["shading_correlation"]) < 1.0
