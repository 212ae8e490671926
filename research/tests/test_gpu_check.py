"""research/gpu_check.py: the overrides it gives train.py compose to the paper configuration, its
statistics, its no-CUDA exit, and (slow) its CPU smoke mode end to end."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest
import torch
from tests.conftest import compose_train

from brdfgan.config_check import check_config
from brdfgan.training.run import CHECKED_GROUPS
from research import gpu_check

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.integration
def test_gpu_overrides_compose_to_the_paper_configuration_on_one_gpu(tmp_path: Path) -> None:
    overrides = gpu_check.training_overrides(
        gpu_check.GPU_PLAN,
        tmp_path / "data",
        tmp_path / "t.json",
        precision="bf16-mixed",
        batches=25,
        name="x",
    )
    cfg = compose_train(overrides, tmp_path)
    check_config(cfg, CHECKED_GROUPS)  # every value fits the signature it is passed to, the timer's too
    assert (cfg.model.generator.width, cfg.model.generator.residual_blocks) == (64, 9)
    assert (cfg.model.discriminator.width, cfg.model.discriminator.scales) == (64, 2)
    assert all(cfg.loss.switches[term] for term in ("adversarial", "feature", "parameter", "rendering"))
    assert (cfg.data.batch_size, cfg.data.data_dir, cfg.data.get("train_crop")) == (
        8,
        str(tmp_path / "data"),
        None,
    )
    trainer = cfg.trainer
    assert (trainer.accelerator, trainer.devices, trainer.precision) == ("gpu", 1, "bf16-mixed")
    assert "strategy" not in trainer  # trainer=gpu replaced the experiment's ddp preset
    assert (trainer.max_steps, trainer.limit_val_batches, trainer.enable_checkpointing) == (50, 0, False)
    assert list(cfg.callbacks) == ["gpu_check_timer"] and cfg.test is False


@pytest.mark.integration
def test_ddp_overrides_compose_to_two_processes(tmp_path: Path) -> None:
    overrides = gpu_check.training_overrides(
        gpu_check.GPU_PLAN,
        tmp_path,
        tmp_path / "t.json",
        precision="bf16-mixed",
        batches=3,
        name="d",
        ddp=True,
    )
    trainer = compose_train(overrides, tmp_path).trainer
    assert (trainer.strategy, trainer.devices, trainer.accelerator) == (
        "ddp_find_unused_parameters_true",
        2,
        "gpu",
    )
    tiny = gpu_check.training_overrides(
        gpu_check.TINY_PLAN, tmp_path, tmp_path / "t.json", precision="32-true", batches=3, name="d", ddp=True
    )
    assert compose_train(tiny, tmp_path).trainer.accelerator == "cpu"


@pytest.mark.integration
def test_rendered_overrides_compose_to_v5_on_a_bank_without_mitsuba(tmp_path: Path) -> None:
    overrides = gpu_check.rendered_overrides(
        gpu_check.GPU_PLAN, tmp_path / "data", tmp_path / "banks", tmp_path / "t.json",
        precision="bf16-mixed", batches=25,
    )  # fmt: skip
    cfg = compose_train(overrides, tmp_path)
    check_config(cfg, CHECKED_GROUPS)
    assert (
        cfg.data._target_ == "brdfgan.data.loading.rendered.RenderedDataModule" and cfg.data.prepare is None
    )
    spec = cfg.data.bank.spec
    assert (spec.resolution, spec.material_resolution, spec.lighting.sunsky_fraction) == (512, 512, 0)
    assert spec.scans.folder is None  # the device has no scans: procedural families only
    assert (cfg.data.compile_renderer, cfg.data.train_crop, cfg.data.batch_size) == (True, 256, 8)
    assert (cfg.trainer.accelerator, cfg.trainer.max_steps, cfg.test) == ("gpu", 25, False)


def test_step_stats_are_medians_after_the_warm_up() -> None:
    timer = {
        "compute_s": [9.0, 1.0, 3.0, 2.0],  # the warm-up batch is the slow one
        "interval_s": [9.5, 4.0, 2.0],  # batch 1→2, 2→3, 3→4
        "batch_shape": [8, 3, 512, 512],
        "world_size": 2,
    }
    stats = gpu_check.step_stats(timer, warmup=1)
    assert stats == {"step_s": 2.0, "interval_s": 4.0, "samples_per_s": 16 / 4.0, "timed": 3}
    one_batch = {**timer, "compute_s": [0.5], "interval_s": [], "world_size": 1}
    assert gpu_check.step_stats(one_batch, warmup=0)["samples_per_s"] == 8 / 0.5
    with pytest.raises(ValueError, match="no timed batch"):
        gpu_check.step_stats(timer, warmup=4)


def test_gpu_mode_without_cuda_is_one_line_and_exit_2(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert gpu_check.main([]) == gpu_check.NO_CUDA_EXIT
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and captured.err.startswith("gpu_check: no CUDA device")


@pytest.mark.integration
@pytest.mark.slow
def test_cpu_smoke_mode_prints_the_table_and_writes_out(tmp_path: Path) -> None:
    env = {**os.environ, "OUT": str(tmp_path / "out")}
    result = subprocess.run(
        ["bash", str(ROOT / "research" / "gpu_check.sh"), "--device", "cpu", "--tiny"],
        env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr[-3000:]
    rows = {line.split("|")[1].strip(): line for line in result.stdout.splitlines() if line.startswith("| ")}
    for check in (
        "step time, 32-true",
        "throughput, 32-true",
        "peak GPU memory, 32-true",
        "rendering loss fwd+bwd",
        "bf16-mixed vs 32-true",
        "experiment=anchored_rendered on rendered photos, 32-true",
        "DDP, 2 processes",
    ):
        assert check in rows, result.stdout
        assert "FAILED" not in rows[check]
    assert "32 train samples at 64²" in rows["data"] and "× the step time" in rows["bf16-mixed vs 32-true"]
    assert "skipped" in rows["DDP, 2 processes"]
    out = tmp_path / "out"
    assert (out / "gpu_check.md").read_text().strip() == result.stdout.strip()
    assert {p.name for p in out.glob("train_*.log")} == {
        "train_main_32_true.log",
        "train_compare_bf16_mixed.log",
        "train_rendered.log",
    }


def test_a_failed_compiled_run_is_retried_with_the_loss_eager(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    calls: list[tuple[str, tuple[str, ...]]] = []

    def fake_run(
        name: str, plan: gpu_check.Plan, *args: object, batches: int, **kwargs: object
    ) -> gpu_check.RunResult:
        calls.append((name, plan.overrides))
        if not calls[1:]:  # the first (compiled) run fails
            return gpu_check.RunResult(name, [], 1.0, None, "exit 1: RuntimeError: inductor")
        seconds = 0.5 if "32_true" in name else 1.0
        timer = {
            "compute_s": [9.0] + [seconds] * (batches - 1),
            "interval_s": [seconds] * (batches - 1),
            "batch_shape": [8, 3, 512, 512],
            "world_size": 1,
            "peak_bytes": 3 * 2**30,
            "parameters": {"generator": 45_600_000},
        }
        return gpu_check.RunResult(name, [], 1.0, timer, None)

    monkeypatch.setattr(gpu_check, "make_data", lambda root, plan: (root, 32))
    monkeypatch.setattr(gpu_check, "run_training", fake_run)
    monkeypatch.setattr(gpu_check, "first_batch", lambda data_dir, size: {})
    timing = gpu_check.RenderTiming(0.25, compiled=False, maps_dtype="float32")
    monkeypatch.setattr(gpu_check, "time_rendering_loss", lambda *args: timing)
    rows, raw, failed = gpu_check.run_checks(
        gpu_check.GPU_PLAN, torch.device("cpu"), tmp_path, {}, deadline=1e12, force_ddp=False
    )
    assert failed  # the compiled run's failure still fails the check
    assert [name for name, _ in calls] == [
        "main_bf16_mixed",
        "main_bf16_mixed_eager",
        "compare_32_true",
        "rendered",
    ]
    assert [gpu_check.EAGER_LOSS in overrides for _, overrides in calls] == [False, True, True, True]
    table = {check: (value, note) for check, value, note in rows}
    assert table["train.py, bf16-mixed"][0] == "FAILED" and "retry" in table
    assert table["step time, bf16-mixed"][0] == "1000.0 ms"
    assert table["throughput, bf16-mixed"][0] == "8.0 samples/s"
    assert table["peak GPU memory, bf16-mixed"][0] == "3.00 GiB"
    assert table["rendering loss fwd+bwd"][0] == "250.0 ms (25% of the step)"
    assert table["32-true vs bf16-mixed"][0] == "0.50× the step time"
    rendered = table["experiment=anchored_rendered on rendered photos, bf16-mixed"]
    assert rendered[0] == "batch interval 1000.0 ms"
    assert table["DDP, 2 processes"][0] == "skipped"
    assert raw["main_bf16_mixed_eager"]["stats"]["timed"] == 20
