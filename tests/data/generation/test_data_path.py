"""A missing dataset is generated on first use only inside paths.data_dir, or when asked
(data.prepare.generate=true): a mistyped data.data_dir is one error line, not a new dataset."""

from __future__ import annotations

import os
from functools import partial
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import hydra
import pytest
import torch

from brdfgan.data.generation import generation
from brdfgan.data.generation.generation import SPEC_FILE, ensure_dataset, run_generation
from brdfgan.data.loading.datamodule import ShardDataModule
from brdfgan.data.storage.spec_checks import DatasetConfigError
from brdfgan.models.generator import Generator
from brdfgan.runs import save_weights
from tests.conftest import compose_train, run_python
from tests.data.generation.test_generation import tiny_spec, torch_photographer


@pytest.fixture
def generated(monkeypatch: pytest.MonkeyPatch) -> list[Path]:
    """The folders ensure_dataset generates into (recorded; nothing is rendered or written)."""
    calls: list[Path] = []

    def record(spec: Any, out_dir: str | os.PathLike[str], **_: Any) -> SimpleNamespace:
        calls.append(Path(out_dir))
        return SimpleNamespace(describe=lambda: "recorded")

    monkeypatch.setattr(generation, "run_generation", record)
    return calls


def _prepare(overrides: list[str], root: Path) -> ShardDataModule:
    """prepare_data of the tiny data config, its project root at ``root``."""
    cfg = compose_train(["debug=default", *overrides], root)
    module = hydra.utils.instantiate(cfg.data, _convert_="all")
    module.prepare_data()
    return module


@pytest.mark.integration
def test_the_projects_own_data_folder_generates_on_first_use(tmp_path: Path, generated: list[Path]) -> None:
    _prepare([], tmp_path)
    store = tmp_path / "elsewhere" / "store"
    _prepare([f"paths.data_dir={store}"], tmp_path)  # an overridden data folder is the project's own
    assert generated == [tmp_path / "data" / "tiny", store / "tiny"]


@pytest.mark.integration
def test_a_mistyped_data_dir_is_an_error_naming_it(tmp_path: Path, generated: list[Path]) -> None:
    missing = tmp_path / "nonexistent"
    message = (
        f"data.data_dir={missing}: no dataset there; correct the path, or pass data.prepare.generate=true"
    )
    with pytest.raises(DatasetConfigError, match=message):
        _prepare([f"data.data_dir={missing}"], tmp_path)
    assert generated == [] and list(tmp_path.iterdir()) == []


@pytest.mark.integration
def test_generate_true_generates_anywhere(tmp_path: Path, generated: list[Path]) -> None:
    elsewhere = tmp_path / "elsewhere"
    _prepare([f"data.data_dir={elsewhere}", "data.prepare.generate=true"], tmp_path)
    assert generated == [elsewhere]


def _link(link: Path, target: Path) -> None:
    target.mkdir(parents=True, exist_ok=True)
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(target, target_is_directory=True)


@pytest.mark.parametrize(
    ("out_dir", "root", "inside"),
    [
        ("data/tiny", "{tmp}/data", True),  # relative against absolute, both ways
        ("{tmp}/data/tiny", "data", True),
        ("data/sub/tiny", "data", True),
        ("data/../tiny", "data", False),
        ("data", "data", False),  # the data folder itself holds datasets, is not one
        ("database/tiny", "data", False),  # a name that merely starts like it
        ("{tmp}/disk/tiny", "linked_data", True),  # the data folder links to another disk
        ("data/linked_tiny", "data", True),  # a dataset folder linked from inside it
        ("linked_data/../disk2/tiny", "linked_data", False),
    ],
)
def test_inside_the_data_folder_compares_spellings_and_links(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    generated: list[Path],
    out_dir: str,
    root: str,
    inside: bool,
) -> None:
    monkeypatch.chdir(tmp_path)
    _link(tmp_path / "linked_data", tmp_path / "disk")
    _link(tmp_path / "data" / "linked_tiny", tmp_path / "outside" / "tiny")
    out_dir, root = out_dir.format(tmp=tmp_path), root.format(tmp=tmp_path)
    if inside:
        ensure_dataset(tiny_spec(), out_dir, generate=False, generate_under=root)
        assert generated == [Path(out_dir)]
    else:
        with pytest.raises(DatasetConfigError, match="no dataset there"):
            ensure_dataset(tiny_spec(), out_dir, generate=False, generate_under=root)
        assert generated == []


def test_a_complete_dataset_elsewhere_is_read_and_a_partial_one_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    spec, elsewhere = tiny_spec(materials=3, val_fraction=0.0), tmp_path / "elsewhere"
    run_generation(spec, elsewhere, progress=False, photographer=torch_photographer)

    def refuse(*_: Any, **__: Any) -> None:
        raise AssertionError("generated")

    monkeypatch.setattr(generation, "run_generation", refuse)
    home = tmp_path / "data"
    prepare = partial(ensure_dataset, spec, str(elsewhere), generate=False, generate_under=str(home))
    module = ShardDataModule(str(elsewhere), batch_size=2, prepare=prepare)
    module.prepare_data()
    module.setup("fit")
    assert next(iter(module.train_dataloader()))["photo"].shape[0] == 2

    with pytest.raises(
        DatasetConfigError, match=r"holds a dataset made with a different config \(dataset_spec.spp"
    ):
        ensure_dataset(
            tiny_spec(materials=3, val_fraction=0.0, spp=9), elsewhere, generate=False, generate_under=home
        )
    (elsewhere / "test" / "manifest.json").unlink()
    with pytest.raises(
        DatasetConfigError, match=f"data.data_dir={elsewhere}: the dataset there is incomplete"
    ):
        prepare()
    assert (elsewhere / SPEC_FILE).is_file() and not home.exists()


@pytest.mark.integration
@pytest.mark.parametrize("script", ["train.py", "evaluate.py"])
def test_train_and_evaluate_refuse_a_mistyped_data_dir_with_one_line(tmp_path: Path, script: str) -> None:
    missing = tmp_path / "nonexistent"
    if script == "train.py":
        args = ["debug=default"]
    else:
        config: dict[str, Any] = {"in_channels": 3, "width": 8, "downsamplings": 2, "residual_blocks": 1}
        torch.manual_seed(0)
        weights = save_weights(tmp_path / "w.safetensors", Generator(**config), model_id="t", config=config,
                               target="brdfgan.models.generator.Generator")  # fmt: skip
        args = [f"ckpt={weights}", "data=tiny"]
    result = run_python(script, *args, f"data.data_dir={missing}", cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-3000:]
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and errors[0].startswith(f"error: data.data_dir={missing}: no dataset there")
    assert "Traceback" not in result.stderr
    # Checked before the model and trainer are built: no seed, banner or tip line before it.
    printed = [line for line in (result.stdout + result.stderr).splitlines() if line.strip()]
    assert printed == errors, printed
    assert not missing.exists() and not (tmp_path / "data").exists()
