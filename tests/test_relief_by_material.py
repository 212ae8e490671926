"""scripts/relief_by_material: the slope cosine and RMS ratio it reports, and its table."""

from __future__ import annotations

import pytest
import torch
from scripts.relief_by_material import FLAT, SlopeSums, markdown

from brdfgan.core.svbrdf import NORMAL, flat_maps
from brdfgan.data.materials.base import height_to_normal
from brdfgan.data.materials.noise import fbm


def bumpy(scale: float) -> torch.Tensor:
    maps = flat_maps(32, 32, batch=(1,))
    maps[0, NORMAL] = height_to_normal(scale * fbm(32, 4, torch.Generator().manual_seed(0), octaves=3)[None])
    return maps


def test_the_right_relief_scores_one_inside_out_minus_one_and_half_as_steep_half() -> None:
    truth = bumpy(2.0)
    for pred, cosine, ratio in ((truth, 1.0, 1.0), (bumpy(-2.0), -1.0, 1.0), (bumpy(1.0), 1.0, 0.5)):
        sums = SlopeSums()
        sums.add(pred, truth)
        assert sums.cosine() == pytest.approx(cosine, abs=1e-6)
        assert sums.rms_ratio() == pytest.approx(ratio, rel=2e-2)  # slopes of a halved height, renormalised
    flat = SlopeSums()
    flat.add(flat_maps(32, 32, batch=(1,)), truth)
    assert flat.cosine() == 0.0 and flat.rms_ratio() == 0.0


def test_the_table_puts_each_model_beside_the_flat_map() -> None:
    table = markdown({"Wood048": {FLAT: (3.0, 0.0, 0.0, 4), "v5": (4.5, -0.8, 0.4, 4)}})
    assert "| Wood048 | 4 | 3.000 | 4.500 (1.50), -0.80, 0.40 |" in table
