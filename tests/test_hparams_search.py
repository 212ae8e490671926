"""The Optuna search (conf/hparams_search/svbrdf_optuna.yaml): its keys are real arguments of the
composed config, and a two-trial multirun on the tiny dataset records the best parameters."""

from __future__ import annotations

import csv
import inspect
import math
from pathlib import Path

import pytest
import yaml
from hydra import compose, initialize_config_dir
from hydra.utils import get_object
from hydra_plugins.hydra_optuna_sweeper._impl import create_params_from_overrides
from omegaconf import DictConfig, OmegaConf
from optuna.distributions import CategoricalDistribution

from brdfgan.sweep_folders import JOB_FOLDER_MAX_LENGTH
from tests.conftest import CONF, run_python

ROOT = Path(__file__).resolve().parents[1]
OPTUNA_SWEEPER = "hydra_plugins.hydra_optuna_sweeper.optuna_sweeper.OptunaSweeper"
MISSING = object()

pytestmark = pytest.mark.integration


def _compose(overrides: list[str]) -> DictConfig:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name="train", overrides=overrides, return_hydra_config=True)


def _accepts(target: str, name: str) -> bool:
    """Whether ``name`` is an argument of the ``_target_`` callable ``target``."""
    parameters = inspect.signature(get_object(target)).parameters
    return name in parameters or any(p.kind is p.VAR_KEYWORD for p in parameters.values())


@pytest.mark.parametrize(
    "chosen", [[], ["debug=default"], ["experiment=paper"], ["model=deschaintre2018", "loss=supervised"]]
)
def test_search_space_keys_are_arguments_of_the_composed_config(chosen: list[str]) -> None:
    cfg = _compose(["hparams_search=svbrdf_optuna", *chosen])
    sweeper = cfg.hydra.sweeper
    assert sweeper._target_ == OPTUNA_SWEEPER
    assert sweeper.sampler._target_ == "optuna.samplers.TPESampler" and sweeper.sampler.seed == cfg.seed
    assert sweeper.direction == "minimize" and sweeper.n_jobs == 1 and sweeper.storage is None
    assert cfg.monitor == "val/loss"  # what train.py returns to the sweeper
    params = dict(sweeper.params)
    assert {"model.optimizer.lr", "model.generator.width"} <= set(params)
    assert sum(key.startswith("loss.") for key in params) >= 2
    distributions, fixed = create_params_from_overrides([f"{key}={value}" for key, value in params.items()])
    assert set(distributions) == set(params) and not fixed  # every entry is searched, none is fixed
    for key, distribution in distributions.items():
        # A renamed key fails here: it must exist in the composed config and be an argument of
        # the object its node builds (so a trial's override reaches a constructor).
        parent_key, _, name = key.rpartition(".")
        assert OmegaConf.select(cfg, key, default=MISSING) is not MISSING, f"{key}: not in the train config"
        assert _accepts(OmegaConf.select(cfg, parent_key)._target_, name), f"{key}: not an argument"
        if not chosen:  # the project's defaults lie inside the search space
            default = OmegaConf.select(cfg, key)
            if isinstance(distribution, CategoricalDistribution):
                assert default in distribution.choices, key
            else:
                assert distribution.low <= default <= distribution.high, key


def test_search_is_off_unless_chosen() -> None:
    cfg = _compose([])
    assert cfg.hydra.sweeper._target_ != OPTUNA_SWEEPER
    assert "feature_weight" not in cfg.loss  # the search's explicit default stays out of plain runs


def _val_loss(job: Path) -> float:
    with next((job / "csv").glob("*/metrics.csv")).open() as file:
        values = [float(row["val/loss"]) for row in csv.DictReader(file) if row.get("val/loss")]
    return values[-1]


@pytest.mark.mitsuba
@pytest.mark.slow  # 13-18 s: kept out of make test's 6 minutes (make test-slow runs it)
def test_two_trials_on_the_tiny_data_record_the_best_parameters(tiny_data: Path, tmp_path: Path) -> None:
    sweep = tmp_path / "sweep"
    overrides = [
        "hparams_search=svbrdf_optuna", "debug=default", "hydra.sweeper.n_trials=2",
        "trainer.max_epochs=1", "trainer.limit_train_batches=2", "trainer.limit_val_batches=1",
        "test=false", "logger=csv", f"hydra.sweep.dir={sweep}",
    ]  # fmt: skip
    result = run_python("train.py", "-m", *overrides, cwd=tmp_path, project_root=tiny_data)
    assert result.returncode == 0, result.stderr[-3000:]

    searched = set(_compose(["hparams_search=svbrdf_optuna"]).hydra.sweeper.params)
    jobs = sorted(p for p in sweep.iterdir() if p.is_dir())
    assert [job.name.split("_")[0] for job in jobs] == ["0", "1"]
    for job in jobs:
        assert len(job.name) <= JOB_FOLDER_MAX_LENGTH and "=" not in job.name and "," not in job.name
        recorded = yaml.safe_load((job / ".hydra" / "overrides.yaml").read_text())
        sampled = {k: yaml.safe_load(v) for k, _, v in (o.partition("=") for o in recorded) if k in searched}
        assert set(sampled) == searched
        config = OmegaConf.load(job / ".hydra" / "config.yaml")
        for key, value in sampled.items():  # the trial's values win over debug=default's widths
            assert OmegaConf.select(config, key) == value, key

    results = yaml.safe_load((sweep / "optimization_results.yaml").read_text())
    assert set(results["best_params"]) == searched
    assert math.isfinite(results["best_value"])
    # The value Optuna minimised is the trials' monitored metric.
    assert results["best_value"] == pytest.approx(min(_val_loss(job) for job in jobs), rel=1e-6)
