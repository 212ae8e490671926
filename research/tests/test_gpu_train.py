"""research/gpu_train.py: its stages' overrides compose to v5's two stages on a GPU, its snapshots
follow the clock and stop training, staging shrinks the scans and carries the environment table,
and (slow) its CPU smoke mode trains both stages and exports their snapshots."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import torch
from lightning.pytorch import LightningModule, Trainer
from tests.conftest import compose_train
from torch.utils.data import DataLoader

from brdfgan.config_check import check_config
from brdfgan.training.run import CHECKED_GROUPS
from research import gpu_train

ROOT = Path(__file__).resolve().parents[2]
HELD_OUT = ("Fabric030", "Metal012", "Tiles036", "Marble017", "Metal004", "Wood048")


@pytest.mark.integration
def test_stage_overrides_compose_to_v5s_two_stages_on_one_gpu(tmp_path: Path) -> None:
    plan = gpu_train.GPU_PLAN
    shading = compose_train(gpu_train.stage_overrides(plan, tmp_path, "shading", 120.0, None), tmp_path)
    check_config(shading, CHECKED_GROUPS)  # the callbacks' arguments fit their signatures too
    assert list(shading.loss.parameter_maps) == ["normal"] and not shading.loss.switches.rendering
    assert shading.get("init_from") is None
    first = tmp_path / "runs" / "shading" / "snapshots" / "snapshot2.ckpt"
    full = compose_train(gpu_train.stage_overrides(plan, tmp_path, "full", 200.0, first), tmp_path)
    check_config(full, CHECKED_GROUPS)
    assert full.loss.switches.rendering and full.init_from == str(first)
    for cfg, seconds in ((shading, 120), (full, 200)):
        assert cfg.data._target_ == "brdfgan.data.loading.rendered.RenderedDataModule"
        assert cfg.data.prepare is None and cfg.data.bank.spec.scans.fraction == 0.35
        assert (cfg.data.bank.folder, cfg.data.bank.paint_workers) == (str(tmp_path / "banks"), 16)
        assert (cfg.data.batch_size, cfg.data.num_workers, cfg.data.compile_renderer) == (32, 14, False)
        assert cfg.model.generator.width == 32
        trainer = cfg.trainer
        assert (trainer.accelerator, trainer.devices, trainer.precision) == ("gpu", 1, "bf16-mixed")
        assert (trainer.max_epochs, trainer.limit_val_batches, trainer.enable_checkpointing) == (1, 0, False)
        assert set(cfg.callbacks) == {"snapshots", "step_timer"} and cfg.test is False
        assert (cfg.callbacks.snapshots.seconds, cfg.callbacks.snapshots.count) == (seconds, 2)


class _SlowModel(LightningModule):
    """One weight, a training step of ~10 ms: the snapshots' clock has something to count."""

    def __init__(self) -> None:
        super().__init__()
        self.weight = torch.nn.Parameter(torch.zeros(1))

    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        time.sleep(0.01)
        return (self.weight - batch["photo"].mean()).square()

    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.SGD(self.parameters(), lr=0.1)


def test_timed_snapshots_follow_the_clock_and_stop_training(tmp_path: Path) -> None:
    snapshots = gpu_train.TimedSnapshots(str(tmp_path / "snapshots"), seconds=0.3, count=3)
    photos = [{"photo": torch.ones(2, 3, 4, 4)} for _ in range(1000)]
    trainer = Trainer(max_epochs=1, callbacks=[snapshots], logger=False, enable_checkpointing=False,
                      enable_progress_bar=False, enable_model_summary=False, accelerator="cpu")  # fmt: skip
    trainer.fit(_SlowModel(), DataLoader(photos, batch_size=None))  # type: ignore[arg-type]
    taken = json.loads((tmp_path / "snapshots" / "snapshots.json").read_text())
    assert [entry["snapshot"] for entry in taken] == [1, 2, 3]
    assert [entry["seconds"] >= round(0.1 * k, 2) for k, entry in enumerate(taken, 1)] == [True] * 3
    steps = [entry["step"] for entry in taken]
    assert steps == sorted(steps) and steps[-1] == trainer.global_step < 1000  # stopped at the last
    assert [entry["photos"] for entry in taken] == [2 * step for step in steps]
    weights = torch.load(tmp_path / "snapshots" / "snapshot3.ckpt", weights_only=True)
    assert "optimizer_states" not in weights and "weight" in weights["state_dict"]


def test_stage_seconds_split_what_is_left_and_skip_a_stage_without_time() -> None:
    allowance = gpu_train.STARTUP_ALLOWANCE_S
    assert gpu_train.stage_seconds(400.0, "shading", 0.45) == pytest.approx(0.45 * (400.0 - 2 * allowance))
    assert gpu_train.stage_seconds(200.0, "full", 0.45) == 200.0 - allowance
    assert gpu_train.stage_seconds(allowance + 1.0, "full", 0.45) is None


def test_cli_refuses_a_non_positive_budget_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from brdfgan.errors import run_reporting_errors

    assert run_reporting_errors(lambda: gpu_train.main(["run", "--budget", "0"])) == 2
    assert capsys.readouterr().err.strip() == "error: --budget=0.0: must be positive"


def test_timed_snapshots_refuse_no_time() -> None:
    with pytest.raises(ValueError, match="seconds=0"):
        gpu_train.TimedSnapshots("x", seconds=0, count=3)


def _scan_set(folder: Path, side: int, normal_suffix: str) -> None:
    folder.mkdir(parents=True)
    generator = np.random.default_rng(len(folder.name))
    cv2.imwrite(str(folder / "albedo.jpg"), generator.integers(0, 255, (side, side, 3), dtype=np.uint8))
    cv2.imwrite(str(folder / "roughness.jpg"), np.full((side, side), 128, np.uint8))
    normal = np.zeros((side, side, 3), np.uint8)
    normal[..., :] = (255, 128, 128)  # BGR of a flat (0, 0, 1) normal
    cv2.imwrite(str(folder / f"normal{normal_suffix}"), normal)


@pytest.mark.integration
def test_staging_shrinks_the_training_scans_and_carries_the_environment_table(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    scans = tmp_path / "scans"
    for name in (*HELD_OUT, "Bark012", "Rock030"):
        _scan_set(scans / name, 1024, ".png" if name == "Rock030" else ".jpg")
    monkeypatch.chdir(tmp_path)  # the bank of the composed config lands under ./data
    staged = tmp_path / "staged"
    assert gpu_train.main(["stage", "--scans", str(scans), "--to", str(staged)]) == 0
    assert sorted(p.name for p in (staged / "scans").iterdir()) == sorted((*HELD_OUT, "Bark012", "Rock030"))
    for name, side in (("Bark012", 512), ("Fabric030", 16)):
        for path in (staged / "scans" / name).iterdir():
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            assert image is not None and image.shape[:2] == (side, side), path
    assert (staged / "scans" / "Rock030" / "normal.png").exists()  # each map keeps its format
    assert not (tmp_path / "staged.partial").exists()
    with np.load(staged / "environments.npz") as table:
        radiance = [name for name in table.files if name.endswith("/radiance")]
        assert radiance and {table[name].shape[0] for name in radiance} == {64}


@pytest.mark.integration
@pytest.mark.slow
def test_cpu_smoke_mode_trains_both_stages_and_exports_their_snapshots(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": f"{ROOT / 'src'}{os.pathsep}{ROOT}", "OMP_NUM_THREADS": "2"}
    command = [sys.executable, "-m", "research.gpu_train", "run", "--device", "cpu", "--tiny",
               "--budget", "200", "--out", str(tmp_path / "out")]  # fmt: skip
    result = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr[-3000:]
    out = tmp_path / "out"
    names = {"shading_1", "shading_2", "full_1", "full_2"}
    assert {p.stem for p in out.glob("*.safetensors")} == names
    summary = json.loads((out / "gpu_train.json").read_text())
    assert [stage["stage"] for stage in summary["stages"]] == ["shading", "full"]
    assert summary["bank"]["scan_sets"] == 0 and summary["bank"]["procedural"] > 0
    for stage in summary["stages"]:
        assert "error" not in stage and len(stage["snapshots"]) == 2
        assert stage["step_timer"]["batch_shape"] == [2, 3, 32, 32]
    last = summary["stages"][0]["snapshots"][-1]["path"]
    assert f"init_from={last}" in summary["stages"][1]["overrides"]
