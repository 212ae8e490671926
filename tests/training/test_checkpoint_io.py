"""Checkpoints are complete or absent on any filesystem; a full disk or an interrupt during
training or evaluation is one line, with nothing half-written left behind."""

from __future__ import annotations

import errno
import os
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import lightning as L
import pytest
import torch

from brdfgan.errors import DiskFullError, exit_on_user_error
from brdfgan.evaluation.evaluator import write_results
from brdfgan.io.atomic import stale_temp_files
from brdfgan.training.checkpoint_io import AtomicCheckpointIO
from brdfgan.training.run import _remove_stale_checkpoint_temps, build, train
from tests.conftest import ROOT, compose_train

# Checkpoint 1 is written; checkpoint 2 is killed (SIGKILL) after half its bytes reached the
# file — the moment a kill left a truncated last.ckpt before.
KILL_MID_WRITE = textwrap.dedent(
    """
    import os, pathlib, signal, sys
    import torch
    from brdfgan.training.checkpoint_io import AtomicCheckpointIO

    path = sys.argv[1]
    writer = AtomicCheckpointIO()
    writer.save_checkpoint({"state_dict": {"w": torch.zeros(1000)}, "global_step": 1}, path)

    def write_half_then_die(self, data):
        with self.open("wb") as handle:
            handle.write(bytes(data)[: len(data) // 2])
            handle.flush()
        os.kill(os.getpid(), signal.SIGKILL)

    pathlib.Path.write_bytes = write_half_then_die
    writer.save_checkpoint({"state_dict": {"w": torch.ones(1000)}, "global_step": 2}, path)
    """
)


def test_a_kill_mid_write_leaves_the_previous_checkpoint_whole(tmp_path: Path) -> None:
    checkpoints, scratch = tmp_path / "checkpoints", tmp_path / "tmpdir"
    scratch.mkdir()
    last = checkpoints / "last.ckpt"
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "TMPDIR": str(scratch)}
    result = subprocess.run([sys.executable, "-c", KILL_MID_WRITE, str(last)], env=env, capture_output=True,
                            text=True, timeout=120)  # fmt: skip
    assert result.returncode == -9, result.stderr[-2000:]
    # The previous checkpoint is intact; the half-written one is a hidden temp beside it, not
    # a file in $TMPDIR (Lightning's default staged it there and copied it across filesystems).
    state = torch.load(last, weights_only=True)
    assert state["global_step"] == 1 and torch.equal(state["state_dict"]["w"], torch.zeros(1000))
    stale = stale_temp_files(last)
    assert len(stale) == 1 and stale[0].stat().st_size > 0
    assert list(scratch.iterdir()) == []
    _remove_stale_checkpoint_temps(last)  # what a resume from this folder does
    assert stale_temp_files(last) == [] and sorted(p.name for p in checkpoints.iterdir()) == ["last.ckpt"]


@pytest.mark.integration
def test_the_trainer_writes_checkpoints_through_the_atomic_plugin_and_loads_safely(tmp_path: Path) -> None:
    _, _, trainer = build(compose_train(["debug=default"], tmp_path))
    assert isinstance(trainer.strategy.checkpoint_io, AtomicCheckpointIO)
    target = tmp_path / "x.ckpt"
    torch.save({"payload": object.__new__(L.Callback)}, target)  # needs unpickling of a class
    with pytest.raises(pickle.UnpicklingError, match="Weights only load failed"):
        AtomicCheckpointIO().load_checkpoint(target, weights_only=False)


@pytest.mark.integration
@pytest.mark.mitsuba
def test_a_full_disk_while_training_names_the_checkpoint_and_leaves_only_whole_files(
    tiny_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real_write_bytes = Path.write_bytes
    checkpoint_writes = []

    def write_until_full(self: Path, data: bytes) -> int:
        if not self.name.startswith(".last.ckpt."):
            return real_write_bytes(self, data)
        checkpoint_writes.append(self)
        if len(checkpoint_writes) < 3:
            return real_write_bytes(self, data)
        real_write_bytes(self, bytes(data)[:1000])  # some bytes made it before the disk filled
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", write_until_full)
    overrides = ["debug=default", "test=false", "callbacks.mid_epoch_checkpoint.every_n_train_steps=2"]
    cfg = compose_train(overrides, tiny_data)
    cfg.paths.output_dir = str(tmp_path / "run")
    with pytest.raises(DiskFullError) as error:
        train(cfg)
    checkpoints = tmp_path / "run" / "checkpoints"
    assert str(error.value) == f"{checkpoints / 'last.ckpt'}: no space left on device"
    assert [p.name for p in checkpoints.iterdir()] == ["last.ckpt"]  # no hidden temp, no partial file
    assert torch.load(checkpoints / "last.ckpt", weights_only=True)["global_step"] == 4


@pytest.mark.integration
@pytest.mark.mitsuba
def test_an_interrupted_fit_says_where_to_resume(tiny_data: Path, tmp_path: Path) -> None:
    cfg = compose_train(["debug=default", "callbacks.mid_epoch_checkpoint.every_n_train_steps=2"], tiny_data)
    cfg.paths.output_dir = str(tmp_path / "run")
    cfg.callbacks.ctrl_c = {"_target_": f"{__name__}.CtrlCAtStep4"}
    with pytest.raises(KeyboardInterrupt) as error:
        train(cfg)
    assert (
        str(error.value)
        == f"interrupted: resume with ckpt_path={tmp_path / 'run' / 'checkpoints' / 'last.ckpt'}"
    )


class CtrlCAtStep4(L.Callback):
    """A Ctrl-C arriving during the third batch (after two checkpoints at steps 2 and 4)."""

    def on_train_batch_start(self, trainer: L.Trainer, *args: object) -> None:
        if trainer.global_step >= 4:
            raise KeyboardInterrupt


def test_evaluation_tables_on_a_full_disk_leave_nothing_half_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def fsync_full(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    results = {"model": {"rmse/diffuse": 0.1}}
    write_results(results, tmp_path / "before")
    monkeypatch.setattr("brdfgan.io.atomic.os.fsync", fsync_full)
    with pytest.raises(DiskFullError, match=r"metrics\.json: no space left on device"):
        write_results(results, tmp_path / "out")
    assert list((tmp_path / "out").iterdir()) == []


def test_a_full_disk_is_one_line_and_exit_1(capsys: pytest.CaptureFixture[str]) -> None:
    @exit_on_user_error
    def command() -> None:
        try:
            raise DiskFullError("/data/run/checkpoints/last.ckpt")
        except DiskFullError as error:  # libraries often wrap it; the chain still says why
            raise RuntimeError("saving failed") from error

    with pytest.raises(SystemExit) as exit_:
        command()
    assert exit_.value.code == 1
    assert capsys.readouterr().err == "error: /data/run/checkpoints/last.ckpt: no space left on device\n"

    @exit_on_user_error
    def bug() -> None:
        raise RuntimeError("a bug keeps its traceback")

    with pytest.raises(RuntimeError, match="a bug keeps its traceback"):
        bug()
