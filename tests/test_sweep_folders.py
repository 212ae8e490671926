"""Multirun job folders (brdfgan.sweep_folders): short and safe whatever the number of overrides,
named by what the run is, usable as ``evaluate.py ckpt=<path>`` unquoted."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from hydra import compose, initialize_config_dir
from hydra.core.override_parser.overrides_parser import OverridesParser

from brdfgan.sweep_folders import JOB_FOLDER_MAX_LENGTH, job_folder_name
from tests.conftest import CONF, run_python

ROOT = Path(__file__).resolve().parents[1]


def test_names_keep_what_the_run_is_and_drop_budgets_and_paths() -> None:
    name = job_folder_name(
        3,
        [
            "loss=no_adv",
            "seed=1",
            "data=tiny",
            "trainer.max_epochs=2",
            "paths.log_dir=/tmp/x",
            "+trainer.limit_val_batches=1",
        ],
    )
    assert name == "3_loss-no_adv_seed-1_data-tiny"
    assert job_folder_name(0, []) == "0"


def test_long_override_lists_are_cut_with_a_hash_and_stay_distinct() -> None:
    many = [f"loss.weight_{i}=0.{i}" for i in range(20)]
    first = job_folder_name(0, [*many, "model.width=16"])
    second = job_folder_name(0, [*many, "model.width=32"])
    assert len(first) <= JOB_FOLDER_MAX_LENGTH and len(second) <= JOB_FOLDER_MAX_LENGTH
    assert first != second
    odd = job_folder_name(1, ["loss.weights=[1,2]", "model.generator.name='a b'"])
    assert set(odd) <= set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-")


@pytest.mark.integration
def test_a_multirun_with_a_dozen_overrides_gets_short_folders_that_evaluate_accepts(tmp_path: Path) -> None:
    # A real Hydra multirun (nothing trained: train=false test=false): 2 jobs, 14 overrides each.
    overrides = [
        "seed=0,1", "loss=full", "data=tiny", "model.generator.width=8", "trainer.max_epochs=1",
        "trainer.limit_val_batches=1", "data.batch_size=2", "loss.switches.feature=false",
        "loss.compile=false", "loss.metallic_loss=bce", "loss.normal_tilt_weight=0.5",
        "model.generator.residual_blocks=2",
        "train=false", "test=false",
    ]  # fmt: skip
    result = run_python("train.py", "-m", *overrides, cwd=tmp_path, project_root=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    jobs = sorted(p for p in (tmp_path / "logs" / "train" / "multiruns").glob("*/*") if p.is_dir())
    assert [job.name.split("_")[0] for job in jobs] == ["0", "1"]
    for job in jobs:
        assert len(job.name) <= JOB_FOLDER_MAX_LENGTH and "=" not in job.name and "," not in job.name
        assert "max_epochs" not in job.name and "limit_val" not in job.name  # budgets left out
        recorded = yaml.safe_load((job / ".hydra" / "overrides.yaml").read_text())
        assert len(recorded) == len(overrides) and "trainer.max_epochs=1" in recorded
    assert "seed-1" in jobs[1].name
    # The path is a plain override value: it parses and composes unquoted.
    ckpt = jobs[1] / "checkpoints" / "last.ckpt"
    OverridesParser.create().parse_overrides([f"ckpt={ckpt}"])
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=[f"ckpt={ckpt}"])
    assert cfg.ckpt == str(ckpt)
