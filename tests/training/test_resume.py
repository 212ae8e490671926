"""Resuming is exact: a run interrupted inside an epoch and resumed ends bit-identical to a
straight run; a checkpoint that cannot be resumed is one line, before any training."""

from __future__ import annotations

from pathlib import Path

import lightning as L
import pytest
import torch
from omegaconf import DictConfig

from brdfgan.data.loading.datamodule import _round_robin_share
from brdfgan.training.run import TrainConfigError, build, train
from tests.conftest import compose_train

# tiny: 3 train materials × 2 crops × 2 renders = 12 samples, batch 2 → 6 batches per epoch.
OVERRIDES = ["debug=default", "logger=csv", "trainer.max_epochs=2", "test=false",
             "callbacks.mid_epoch_checkpoint.every_n_train_steps=2"]  # fmt: skip


class SimulatedKill(RuntimeError):
    """Raised by :class:`KillAt` to end a fit the way a kill would: no more saving."""


class KillAt(L.Callback):
    """Stop the fit at the start of training batch number ``batch`` (0-based, over epochs)."""

    def __init__(self, batch: int) -> None:
        self.batch = batch

    def on_train_batch_start(self, trainer: L.Trainer, *args: object) -> None:
        if trainer.fit_loop.total_batch_idx == self.batch:
            raise SimulatedKill(f"killed before batch {self.batch}")


def _fit(cfg: DictConfig, ckpt_path: str | None = None, kill_at: int | None = None) -> L.LightningModule:
    L.seed_everything(cfg.seed, workers=True)
    datamodule, module, trainer = build(cfg)
    if kill_at is not None:
        trainer.callbacks.insert(0, KillAt(kill_at))
    trainer.fit(module, datamodule=datamodule, ckpt_path=ckpt_path)
    return module


def _weights(module: L.LightningModule) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


@pytest.mark.integration
@pytest.mark.mitsuba
def test_interrupted_and_resumed_runs_equal_the_straight_run_bit_for_bit(
    tiny_data: Path, tmp_path: Path
) -> None:
    straight_cfg = compose_train(OVERRIDES, tiny_data)
    straight_cfg.paths.output_dir = str(tmp_path / "straight")
    straight = _weights(_fit(straight_cfg))
    # Killed inside the second epoch (batch 9 of 12), and right at the epoch boundary (batch 6).
    for kill_at in (9, 6):
        cfg = compose_train(OVERRIDES, tiny_data)
        cfg.paths.output_dir = str(tmp_path / f"interrupted-{kill_at}")
        with pytest.raises(SimulatedKill):
            _fit(cfg, kill_at=kill_at)
        last = tmp_path / f"interrupted-{kill_at}" / "checkpoints" / "last.ckpt"
        assert torch.load(last, weights_only=True)["global_step"] == 2 * kill_at  # the batch before the kill
        resumed = _weights(_fit(cfg, ckpt_path=str(last)))
        assert straight.keys() == resumed.keys()
        different = [name for name in straight if not torch.equal(straight[name], resumed[name])]
        assert not different, (
            f"killed at batch {kill_at}: {len(different)} tensors differ, e.g. {different[0]}"
        )


def test_round_robin_share_follows_the_dataloader_order() -> None:
    assert _round_robin_share([3], 2) == [2]
    assert _round_robin_share([2, 2], 3) == [2, 1]
    # worker 1 is exhausted after one batch; the others keep taking turns
    assert _round_robin_share([3, 1, 3], 5) == [2, 1, 2]
    assert _round_robin_share([3, 1, 3], 7) == [3, 1, 3]
    assert _round_robin_share([2, 2], 0) == [0, 0]


@pytest.mark.integration
@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "not a readable checkpoint"),
        (b"PK\x03\x04 truncated zip", "not a readable checkpoint"),
    ],
    ids=["empty", "corrupt"],
)
def test_an_unreadable_checkpoint_to_resume_is_one_line(tmp_path: Path, content: bytes, message: str) -> None:
    checkpoint = tmp_path / "last.ckpt"
    checkpoint.write_bytes(content)
    cfg = compose_train(["debug=default", f"ckpt_path={checkpoint}"], tmp_path)
    with pytest.raises(TrainConfigError, match=f"ckpt_path: {checkpoint}: {message}"):
        train(cfg)


@pytest.mark.integration
def test_a_truncated_real_checkpoint_is_refused(tmp_path: Path) -> None:
    cfg = compose_train(["debug=default"], tmp_path)
    _, module, _ = build(cfg)
    whole = tmp_path / "whole.ckpt"
    torch.save({"state_dict": module.state_dict(), "global_step": 4}, whole)
    truncated = tmp_path / "truncated.ckpt"
    truncated.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
    cfg.ckpt_path = str(truncated)
    with pytest.raises(TrainConfigError, match="truncated or corrupt"):
        train(cfg)


@pytest.mark.integration
def test_another_architectures_checkpoint_is_refused_before_training(tmp_path: Path) -> None:
    wider = compose_train(["debug=default", "model.generator.width=16"], tmp_path)
    _, module, _ = build(wider)
    checkpoint = tmp_path / "wide.ckpt"
    torch.save({"state_dict": module.state_dict(), "global_step": 4}, checkpoint)
    cfg = compose_train(["debug=default", f"ckpt_path={checkpoint}"], tmp_path)
    with pytest.raises(
        TrainConfigError, match=r"the generator does not fit this run's model \(down\.0\.weight is \(16"
    ):
        train(cfg)
    # A GAN checkpoint for a run without a discriminator (another loss) is refused too.
    _, gan, _ = build(compose_train(["debug=default"], tmp_path))
    torch.save({"state_dict": gan.state_dict(), "global_step": 4}, checkpoint)
    overrides = ["debug=default", "loss=supervised", f"ckpt_path={checkpoint}"]
    cfg = compose_train(overrides, tmp_path)
    with pytest.raises(TrainConfigError, match="holds a discriminator this run's model does not have"):
        train(cfg)
