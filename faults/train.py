"""Fault scenarios for ``train.py`` and ``evaluate.py``: kills and signals mid-epoch and in the
middle of a checkpoint write, full disks, unusable checkpoints, crafted run folders and bad
values — each against the real command on the tiny dataset (``debug=default``: 2 epochs of 6
batches, a checkpoint after every batch).

A resumed run must end with the weights of a straight run, bit for bit. The unit-level versions
are in ``tests/training/test_resume.py``, ``tests/training/test_checkpoint_io.py``, ``tests/test_runs.py`` and
``tests/test_config_check.py``.
"""

from __future__ import annotations

import atexit
import functools
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

import torch
import yaml

from faults.common import (
    PYTHON,
    Scenario,
    ScenarioFailed,
    command_env,
    expect_one_line_error,
    hidden_leftovers,
    run,
    run_until,
    small_disk,
    tail,
)

STEPS = 24  # 2 epochs × 6 batches × 2 optimizer steps (discriminator and generator)
STEPS_PER_EPOCH = 12
SMOKE = [
    "debug=default",
    "trainer.max_epochs=2",
    "test=false",
    "callbacks.mid_epoch_checkpoint.every_n_train_steps=2",
]

# train.py with the checkpoint file write patched so that checkpoint number argv[1] gets half its
# bytes, then the process sleeps (to be killed there); the rest of argv is train.py's command line.
SLOW_CHECKPOINT_WRITE = """
import pathlib, runpy, sys, time

target_write, real_write_bytes, writes = int(sys.argv[1]), pathlib.Path.write_bytes, []

def write_halfway(self, data):
    if not self.name.startswith(".last.ckpt."):
        return real_write_bytes(self, data)
    writes.append(self)
    if len(writes) != target_write:
        return real_write_bytes(self, data)
    with self.open("wb") as handle:
        handle.write(bytes(data)[: len(data) // 2])
        handle.flush()
    time.sleep(600)

pathlib.Path.write_bytes = write_halfway
sys.argv = ["train.py", *sys.argv[2:]]
runpy.run_path("train.py", run_name="__main__")
"""


@functools.cache
def project() -> Path:
    """A project root holding the tiny dataset (made once, by the first training run)."""
    root = Path(tempfile.mkdtemp(prefix="faults-train-project-"))
    atexit.register(shutil.rmtree, root, ignore_errors=True)
    return root


def env() -> dict[str, str]:
    return command_env(PROJECT_ROOT=str(project()))


def train(run_dir: Path, *overrides: str) -> list[str]:
    return [PYTHON, "train.py", *SMOKE, f"hydra.run.dir={run_dir}", *overrides]


def last_checkpoint(run_dir: Path) -> Path:
    return run_dir / "checkpoints" / "last.ckpt"


def step_of(checkpoint: Path) -> int | None:
    """The optimizer step a checkpoint holds, or None while it does not exist (yet)."""
    try:
        return int(torch.load(checkpoint, map_location="cpu", weights_only=True)["global_step"])
    except (OSError, RuntimeError, EOFError, KeyError):
        return None


def weights(checkpoint: Path) -> dict[str, torch.Tensor]:
    return torch.load(checkpoint, map_location="cpu", weights_only=True)["state_dict"]


@functools.cache
def reference() -> dict[str, torch.Tensor]:
    """The final weights of a straight, uninterrupted run."""
    run_dir = project() / "reference"
    result = run(train(run_dir), env=env())
    if result.returncode != 0:
        raise ScenarioFailed(f"the straight run failed (exit {result.returncode}): {tail(result.stderr)}")
    return weights(last_checkpoint(run_dir))


def resume_and_compare(run_dir: Path, *overrides: str) -> str:
    """Resume from ``last.ckpt`` to the end; the weights must be the straight run's, bit for bit."""
    checkpoint = last_checkpoint(run_dir)
    resumed_from = step_of(checkpoint)
    result = run(train(run_dir, f"ckpt_path={checkpoint}", *overrides), env=env())
    if result.returncode != 0:
        raise ScenarioFailed(f"the resumed run failed (exit {result.returncode}): {tail(result.stderr)}")
    final, expected = weights(checkpoint), reference()
    different = [name for name in expected if not torch.equal(final[name], expected[name])]
    if different or final.keys() != expected.keys():
        count = len(different)
        raise ScenarioFailed(f"resumed from step {resumed_from}: {count} tensors differ from a straight run")
    return f"resumed from step {resumed_from} of {STEPS}; all {len(expected)} tensors equal a straight run's"


def mid_epoch(run_dir: Path) -> bool:
    step = step_of(last_checkpoint(run_dir))
    return step is not None and step > STEPS_PER_EPOCH + 2


def kill_mid_epoch(workdir: Path) -> str:
    reference()
    run_dir = workdir / "run"
    result = run_until(train(run_dir), lambda: mid_epoch(run_dir), env=env())
    if result.returncode != -signal.SIGKILL:
        raise ScenarioFailed(f"expected the kill to end it, got exit {result.returncode}")
    step = step_of(last_checkpoint(run_dir))
    if step is None or step % STEPS_PER_EPOCH == 0:
        raise ScenarioFailed(f"the kill did not land inside an epoch (last.ckpt at step {step})")
    return f"killed with last.ckpt at step {step}; " + resume_and_compare(run_dir)


def interrupt_mid_epoch(sig: signal.Signals) -> Scenario:
    def scenario(workdir: Path) -> str:
        reference()
        run_dir = workdir / "run"
        result = run_until(train(run_dir), lambda: mid_epoch(run_dir), sig=sig, env=env())
        line = expect_one_line_error(result, exit_code=130, prefix="interrupted: resume with ckpt_path=")
        if str(last_checkpoint(run_dir)) not in line:
            raise ScenarioFailed(f"the message does not name {last_checkpoint(run_dir)}: {line}")
        return f"exit 130, {line[:40]}…; " + resume_and_compare(run_dir)

    return Scenario(
        f"{sig.name} mid-epoch, resume",
        "one line naming last.ckpt, exit 130; the resumed run equals a straight run bit for bit",
        scenario,
    )


def kill_mid_checkpoint_write(workdir: Path) -> str:
    reference()
    run_dir, scratch = workdir / "run", workdir / "tmpdir"
    scratch.mkdir()
    checkpoints = run_dir / "checkpoints"

    def half_written() -> bool:
        # Writes 1-6 of last.ckpt (steps 2-12) are whole once it holds step 12; the next
        # last.ckpt temp is the patched, sleeping write 7. Other checkpoints' temps don't count.
        if step_of(last_checkpoint(run_dir)) != STEPS_PER_EPOCH:
            return False
        temps = hidden_leftovers(checkpoints) if checkpoints.is_dir() else []
        for temp in (t for t in temps if t.name.startswith(".last.ckpt.")):
            try:
                if temp.stat().st_size > 0:
                    return True
            except FileNotFoundError:  # an earlier checkpoint's temp, renamed meanwhile
                continue
        return False

    command = [PYTHON, "-c", SLOW_CHECKPOINT_WRITE, "7", *train(run_dir)[2:]]
    # torch.compile's cache normally lives in $TMPDIR too; elsewhere, so only checkpoints count.
    scratch_env = command_env(
        PROJECT_ROOT=str(project()), TMPDIR=str(scratch), TORCHINDUCTOR_CACHE_DIR=str(workdir / "inductor")
    )
    result = run_until(command, half_written, env=scratch_env)
    if result.returncode != -signal.SIGKILL:
        raise ScenarioFailed(f"expected the kill to end it, got exit {result.returncode}")
    left = hidden_leftovers(checkpoints)
    step = step_of(last_checkpoint(run_dir))
    if step is None:
        raise ScenarioFailed("last.ckpt is not a whole checkpoint after the kill")
    if list(scratch.iterdir()):
        raise ScenarioFailed(f"files left in $TMPDIR: {sorted(p.name for p in scratch.iterdir())}")
    compared = resume_and_compare(run_dir)
    if hidden_leftovers(checkpoints):
        raise ScenarioFailed(f"the resume left {hidden_leftovers(checkpoints)}")
    return (
        f"killed while writing checkpoint 7: last.ckpt whole (step {step}), {len(left)} hidden temp beside "
        f"it, nothing in $TMPDIR; {compared}; the resume removed the temp"
    )


def disk_full(workdir: Path) -> str:
    reference()
    disk = workdir / "disk"
    with small_disk(disk, "3m"):  # room for one checkpoint (~2.7 MB) but not for its successor
        run_dir = disk / "run"
        result = run(train(run_dir), env=env())
        line = expect_one_line_error(result, exit_code=1, contains="no space left on device")
        left = hidden_leftovers(run_dir)
        if left:
            raise ScenarioFailed(f"partial files left: {left}")
        broken = [p.name for p in (run_dir / "checkpoints").glob("*.ckpt") if step_of(p) is None]
        if broken:
            raise ScenarioFailed(f"checkpoints that do not load: {broken}")
        subprocess.run(["mount", "-o", "remount,size=64m", str(disk)], check=True)
        compared = resume_and_compare(run_dir)
    return f"{line}; no partial file; after freeing space: {compared}"


def unusable_checkpoint(workdir: Path) -> str:
    wide = workdir / "wide"
    run(train(wide, "model.generator.width=16", "trainer.max_epochs=1"), env=env())
    truncated = workdir / "truncated.ckpt"
    truncated.write_bytes(last_checkpoint(wide).read_bytes()[:100_000])
    seen = []
    cases = ((truncated, "not a readable checkpoint"), (last_checkpoint(wide), "does not fit"))
    for checkpoint, message in cases:
        result = run(train(workdir / "run", f"ckpt_path={checkpoint}"), env=env())
        seen.append(expect_one_line_error(result, exit_code=2, contains=message)[:90])
    return " / ".join(seen)


def crafted_run_folder(workdir: Path) -> str:
    marker, victim = workdir / "pwned", workdir / "victim.txt"
    victim.write_text("precious")
    payload = workdir / "evil.ckpt"
    make_payload = (
        f"import torch\nclass P:\n    def __reduce__(self): return (open, ({str(marker)!r}, 'w'))\n"
        f"torch.save(P(), {str(payload)!r})"
    )
    run([PYTHON, "-c", make_payload])
    seen = []
    for node in (
        {"_target_": "torch.load", "f": str(payload), "weights_only": False},
        {"_target_": "builtins.open", "file": str(victim), "mode": "w"},
    ):
        run_dir = workdir / node["_target_"]
        (run_dir / ".hydra").mkdir(parents=True)
        (run_dir / "checkpoints").mkdir()
        (run_dir / ".hydra" / "config.yaml").write_text(yaml.safe_dump({"model": {"generator": node}}))
        shutil.copy(last_checkpoint(project() / "reference"), last_checkpoint(run_dir))
        for command in (
            [PYTHON, "evaluate.py", f"ckpt={last_checkpoint(run_dir)}", f"hydra.run.dir={workdir / 'eval'}"],
            [PYTHON, "-m", "brdfgan.cli", "export-weights", str(run_dir)],
        ):
            result = run(command, env=env())
            seen.append(expect_one_line_error(result, exit_code=2, contains="not a brdfgan model config"))
    if marker.exists() or victim.read_text() != "precious":
        raise ScenarioFailed("the crafted config ran code")
    return f"{len(seen)} commands refused, e.g. {seen[0].rsplit('/', 1)[-1]}; payload not run, victim intact"


def evaluate_disk_full(workdir: Path) -> str:
    reference()
    disk = workdir / "disk"
    checkpoint = last_checkpoint(project() / "reference")
    with small_disk(disk, "64k"):
        command = [PYTHON, "evaluate.py", f"ckpt={checkpoint}", "data=tiny", f"hydra.run.dir={disk / 'eval'}"]
        result = run(command, env=env())
        line = expect_one_line_error(result, exit_code=1, contains="no space left on device")
        if hidden_leftovers(disk):
            raise ScenarioFailed(f"partial files left: {hidden_leftovers(disk)}")
        subprocess.run(["mount", "-o", "remount,size=64m", str(disk)], check=True)
        again = run(command, env=env())
        if again.returncode != 0 or not (disk / "eval" / "metrics.json").is_file():
            raise ScenarioFailed(f"the rerun failed (exit {again.returncode}): {tail(again.stderr)}")
    return f"{line}; no partial file; after freeing space the rerun wrote metrics.json"


def bad_values(workdir: Path) -> str:
    seen = []
    for override, key in (("trainer.max_epochs=abc", "trainer.max_epochs='abc'"), ("seed=abc", "seed=abc"),
                          ("model.optimizer.lr=fast", "model.optimizer.lr='fast'")):  # fmt: skip
        result = run(train(workdir / "run", override), env=command_env(PROJECT_ROOT=str(workdir)))
        seen.append(expect_one_line_error(result, exit_code=2, contains=key)[:70])
    if (workdir / "data").exists() or (workdir / "run" / "checkpoints").exists():
        raise ScenarioFailed("work was done before the value was checked")
    return " / ".join(seen) + "; nothing prepared"


SCENARIOS = [
    Scenario(
        "kill -9 mid-epoch, resume",
        "the resumed run ends with the weights of a straight run, bit for bit",
        kill_mid_epoch,
    ),
    interrupt_mid_epoch(signal.SIGTERM),
    interrupt_mid_epoch(signal.SIGINT),
    Scenario(
        "kill -9 in the middle of a checkpoint write",
        "last.ckpt stays whole; nothing in $TMPDIR; the resume removes the temp and ends bit-identical",
        kill_mid_checkpoint_write,
    ),
    Scenario(
        "disk full (tmpfs run folder)",
        "one line naming the file, exit 1, no partial file; after freeing space the resume completes",
        disk_full,
    ),
    Scenario(
        "ckpt_path truncated / of another architecture",
        "one line naming the file, exit 2, before training",
        unusable_checkpoint,
    ),
    Scenario(
        "crafted run folder (torch.load pickle, builtins.open)",
        "evaluate.py and export_weights: one line, exit 2; nothing executed",
        crafted_run_folder,
    ),
    Scenario(
        "evaluate.py, disk full (tmpfs run folder)",
        "one line naming the file, exit 1, no partial file; after freeing space the rerun completes",
        evaluate_disk_full,
    ),
    Scenario(
        "bad config values",
        "one line naming the key, value and expected type, exit 2, before any work",
        bad_values,
    ),
]
