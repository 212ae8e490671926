"""The dataset and data configs compose and build what they say (no data is generated)."""

from __future__ import annotations

from pathlib import Path

import hydra
import pytest
from hydra import compose, initialize_config_dir

from brdfgan.data.datamodule import ShardDataModule
from brdfgan.data.generation import DatasetSpec, plan_shards

CONF = Path(__file__).resolve().parents[1] / "conf"


def _compose(overrides: list[str]):  # type: ignore[no-untyped-def]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name="generate", overrides=overrides)


@pytest.mark.parametrize("name", ["default", "tiny", "paper"])
def test_every_dataset_config_builds_a_valid_spec(name: str) -> None:
    spec = hydra.utils.instantiate(_compose([f"dataset={name}"]).dataset, _convert_="all")
    assert isinstance(spec, DatasetSpec)
    assert plan_shards(spec)


def test_paper_dataset_follows_the_paper_protocol() -> None:
    spec = hydra.utils.instantiate(_compose(["dataset=paper"]).dataset, _convert_="all")
    assert (spec.material_resolution, spec.resolution, spec.spp) == (2048, 512, 196)
    assert (spec.crops_per_material, spec.train_renders, spec.eval_renders) == (7, 3, 1)
    assert spec.test_fraction == 0.2
    assert (spec.lighting.train_count, spec.lighting.test_count) == (20, 6)
    train_samples = sum(j.sample_count(spec) for j in plan_shards(spec) if j.split == "train")
    assert abs(train_samples - 40544) / 40544 < 0.01  # the paper's training-set size


@pytest.mark.parametrize("name", ["default", "tiny", "paper", "deschaintre"])
def test_data_configs_instantiate_a_datamodule(name: str) -> None:
    cfg = _compose([f"+data={name}"])
    module = hydra.utils.instantiate(cfg.data, _convert_="all")
    assert isinstance(module, ShardDataModule)
    if name in ("paper", "deschaintre"):
        assert module._prepare is None  # too big to make on the fly / converted, not generated
        return
    # The prepare hook generates exactly the dataset generate.py makes for the same name.
    prepare = module._prepare
    assert prepare is not None and prepare.keywords["out_dir"] == f"./data/{name}"
    generated = hydra.utils.instantiate(_compose([f"dataset={name}"]).dataset, _convert_="all")
    assert prepare.keywords["spec"] == generated
