"""Trivial reference predictors and the fixed grid sample list."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from brdfgan.core.svbrdf import linear_to_srgb, validate_maps
from brdfgan.data.storage.shards import Sample, shard_path, write_shard
from brdfgan.errors import UserError
from brdfgan.evaluation.evaluator import fixed_samples
from brdfgan.models.reference import ConstantMaps, PhotoAsBasecolor, mean_maps, reference_models
from brdfgan.runs import load_weights, save_weights
from tests.conftest import random_maps


def test_mean_maps_is_the_pixel_mean_with_a_unit_normal() -> None:
    a, b = random_maps(4, 6, seed=1), random_maps(4, 6, seed=2)
    batches = [{"maps": a[None]}, {"maps": torch.stack([b, b])}]
    mean = mean_maps(batches)
    expected = (a.double().mean(dim=(1, 2)) + 2 * b.double().mean(dim=(1, 2))) / 3
    assert torch.allclose(mean[[0, 1, 2, 6, 7]].double(), expected[[0, 1, 2, 6, 7]], atol=1e-6)
    assert torch.isclose(mean[3:6].norm(), torch.tensor(1.0))
    assert torch.allclose(mean[3:6].double(), expected[3:6] / expected[3:6].norm(), atol=1e-6)
    with pytest.raises(UserError, match="no training samples"):
        mean_maps([])


def test_references_predict_what_they_claim_and_survive_a_weights_round_trip(tmp_path: Path) -> None:
    mean = torch.tensor([0.6, 0.5, 0.4, 0.0, 0.0, 1.0, 0.7, 0.2])
    models = reference_models(mean)
    photo = torch.rand(2, 3, 5, 7)
    for name, model in models.items():
        path = save_weights(tmp_path / f"{name}.safetensors", model, target=f"brdfgan.models.reference."
                            f"{type(model).__name__}", config={}, model_id=name)  # fmt: skip
        loaded, meta = load_weights(path)
        assert meta["model_id"] == name
        assert torch.equal(loaded(photo), model(photo))
        validate_maps(loaded(photo))
    constant = models["mean_maps"](photo)
    assert isinstance(models["mean_maps"], ConstantMaps)
    assert torch.equal(constant, mean.view(1, 8, 1, 1).expand(2, 8, 5, 7))
    from_photo = models["photo_basecolor"](photo)
    assert isinstance(models["photo_basecolor"], PhotoAsBasecolor)
    assert torch.allclose(from_photo[:, 0:3], linear_to_srgb(photo))
    assert torch.all(from_photo[:, 5] == 1.0) and torch.all(from_photo[:, 3:5] == 0.0)
    assert torch.allclose(from_photo[:, 6], torch.tensor(0.7)) and torch.allclose(
        from_photo[:, 7], torch.tensor(0.2)
    )


def test_fixed_samples_takes_a_key_list_in_its_order(tmp_path: Path) -> None:
    samples = [Sample(f"test-{i}", torch.rand(3, 4, 4), random_maps(4, 4, seed=i), {}) for i in range(5)]
    write_shard(shard_path(tmp_path, "test", 0), samples[:3])
    write_shard(shard_path(tmp_path, "test", 1), samples[3:])
    assert [s.key for s in fixed_samples(tmp_path, "test", 2)] == ["test-0", "test-1"]
    chosen = fixed_samples(tmp_path, "test", 2, ["test-4", "test-0"])
    assert [s.key for s in chosen] == ["test-4", "test-0"]
    with pytest.raises(ValueError, match="grid_keys: no sample 'test-9'"):
        fixed_samples(tmp_path, "test", 2, ["test-9"])
