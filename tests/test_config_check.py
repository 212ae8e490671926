"""Config type errors are one line naming the full key, the value and the expected type, before
anything is built (brdfgan.config_check), for train.py, evaluate.py and their groups."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from brdfgan.config_check import ConfigValueError, check_config, describe, fits
from brdfgan.training.run import CHECKED_GROUPS, train
from tests.conftest import compose_train, run_python

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.integration
@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("trainer.max_epochs=abc", "trainer.max_epochs='abc': expected int | None (lightning."),
        (
            "model.optimizer.lr=fast",
            "model.optimizer.lr='fast': expected float | Tensor (torch.optim.adam.Adam)",
        ),
        (
            "data.batch_size=two",
            "data.batch_size='two': expected int (brdfgan.data.loading.datamodule.ShardDataModule)",
        ),
        ("model.generator.width=abc", "model.generator.width='abc': expected int (brdfgan.models.generator."),
        ("model.generator.width=1e6", "model.generator.width=1000000.0: expected int"),
        (
            "model.optimizer.betas=[0.5]",
            "model.optimizer.betas=[0.5]: expected tuple[float | Tensor, float | Tensor]",
        ),
        ("loss.switches.feature=maybe", "loss.switches.feature='maybe': expected bool"),
        (
            "callbacks.model_checkpoint.save_top_k=x",
            "callbacks.model_checkpoint.save_top_k='x': expected int",
        ),
        ("trainer.precision=33", "trainer.precision=33: expected 64 | 32 | 16"),
        ("data.prepare.spec.spp=lots", "data.prepare.spec.spp='lots': expected int"),
        (
            "+data.batchsize=3",
            "data.batchsize: not a parameter of brdfgan.data.loading.datamodule.ShardDataModule",
        ),
    ],
)
def test_a_wrong_value_names_the_key_before_anything_is_built(
    tmp_path: Path, override: str, message: str
) -> None:
    cfg = compose_train(["debug=default", override], tmp_path)
    with pytest.raises(ConfigValueError) as error:
        train(cfg)
    assert message in str(error.value)
    assert "\n" not in str(error.value)
    assert not (tmp_path / "data").exists() and not (tmp_path / "run").exists()  # nothing prepared or written


@pytest.mark.integration
@pytest.mark.parametrize(
    "overrides",
    [[], ["debug=default"], ["debug=fdr"], ["debug=overfit"], ["debug=limit"],
     ["experiment=paper", "debug=default"], ["experiment=paper"], ["experiment=procedural_finetune"],
     ["model=deschaintre2018"], ["model=anchored"], ["loss=no_adv"], ["loss=supervised"], ["trainer=gpu"],
     ["trainer=ddp"], ["logger=many"], ["data=deschaintre"], ["callbacks=none"], ["data=rendered"],
     ["experiment=anchored_rendered"], ["experiment=anchored_rendered_fixres", "init_from=x"],
     ["experiment=anchored_rendered_normals"], ["experiment=procedural"], ["experiment=anchored"],
     ["experiment=anchored_fixres", "init_from=x"], ["experiment=cpu"]],
)  # fmt: skip
def test_every_shipped_config_passes_the_check(tmp_path: Path, overrides: list[str]) -> None:
    check_config(compose_train(overrides, tmp_path), CHECKED_GROUPS)


@pytest.mark.integration
def test_an_interpolated_target_node_is_checked_where_it_is_defined(tmp_path: Path) -> None:
    # data=rendered's bank takes ${data.prepare.spec}: a wrong value there names the defining key.
    cfg = compose_train(["data=rendered", "data.prepare.spec.spp=lots"], tmp_path)
    with pytest.raises(ConfigValueError, match=r"^data\.prepare\.spec\.spp='lots': expected int"):
        check_config(cfg, CHECKED_GROUPS)


def test_fits_and_describe_on_the_annotation_kinds() -> None:
    assert fits(3, int) and fits(3, float) and fits(True, bool) and not fits(True, int)
    assert fits(None, int | None) and fits("a", "int") is None  # an unresolved annotation: not judged
    assert fits([1, 2.0], tuple[float, float]) and fits([1, 2.0], tuple[float, float]) is True
    assert fits([1], tuple[float, float]) is False and fits("ab", list[str]) is False
    assert fits({"a": 1}, dict[str, int]) and not fits({"a": "x"}, dict[str, int])
    assert fits("32-true", int | str) and fits("x", Path) and not fits(3, Path)
    assert describe(int | None) == "int | None" and describe(tuple[float, ...]) == "tuple[float, ...]"
    node = OmegaConf.create({"x": {"_target_": "builtins.no_such_thing"}})
    with pytest.raises(ConfigValueError, match=r"x\._target_=builtins\.no_such_thing: cannot import it"):
        check_config(node, ["x"])


@pytest.mark.integration
def test_train_and_evaluate_print_one_line_and_exit_2(tmp_path: Path) -> None:
    cases = [
        (
            "train.py",
            ["debug=default", "trainer.max_epochs=abc"],
            "error: trainer.max_epochs='abc': expected",
        ),
        ("evaluate.py", ["ckpt=x.ckpt", "data=tiny", "data.batch_size=two"], "error: data.batch_size='two'"),
        (
            "evaluate.py",
            ["ckpt=x.ckpt", "grid_samples=abc"],
            "error: Error merging override grid_samples=abc: Value 'abc' of type 'str' could not be",
        ),
        (
            "train.py",
            ["seed=abc"],
            "error: Error merging override seed=abc: Value 'abc' of type 'str' could not be",
        ),
    ]
    for script, args, message in cases:
        began = time.monotonic()
        result = run_python(script, *args, cwd=tmp_path)
        assert result.returncode == 2, result.stderr[-2000:]
        assert "Traceback" not in result.stderr
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith(message), result.stderr[-2000:]
        assert time.monotonic() - began < 60
    assert not (tmp_path / "data").exists()


@pytest.mark.integration
def test_a_renamed_preset_is_refused_in_one_line_that_names_the_new_one(tmp_path: Path) -> None:
    cases = [
        ("train.py", ["experiment=v5"], "error: experiment=v5 was renamed experiment=anchored_rendered"),
        (
            "evaluate.py",
            ["ckpt=x.ckpt", "data=default_model"],
            "error: data=default_model was renamed data=procedural",
        ),
        (
            "train.py",
            ["experiment=no_such_preset"],
            "error: In 'train': Could not find 'experiment/no_such_preset'",
        ),
    ]
    for script, args, message in cases:
        result = run_python(script, *args, cwd=tmp_path)
        assert result.returncode == 2, result.stderr[-2000:]
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith(message), result.stderr[-2000:]
    # An unknown name lists the group's options, the new names among them.
    assert "(options: anchored, anchored_fixres, anchored_rendered," in lines[0]
    assert not (tmp_path / "data").exists() and not (tmp_path / "logs").exists()


def test_every_renamed_preset_names_a_preset_that_exists_in_place_of_the_old_one() -> None:
    from hydra.errors import MissingConfigException

    from brdfgan.errors import RENAMED_PRESETS, missing_config_message

    for old, new in RENAMED_PRESETS.items():
        group, _, name = old.rpartition("/")
        assert (ROOT / "conf" / group / f"{new}.yaml").is_file(), f"{old} -> {new}: no such preset"
        assert not (ROOT / "conf" / f"{old}.yaml").exists(), f"{old} is still a preset"
        error = MissingConfigException(f"Could not find '{old}'\n\nAvailable options", old, [new])
        assert missing_config_message(error) == f"{group}={name} was renamed {group}={new}"


@pytest.mark.integration
@pytest.mark.parametrize(
    "renamed", ["experiment=anchored_rendered", "experiment=procedural", "data=procedural"]
)
def test_a_new_name_composes(tmp_path: Path, renamed: str) -> None:
    cfg = compose_train([renamed], tmp_path)
    assert cfg.data.data_dir.endswith(("/procedural", "/procedural_and_scans"))
