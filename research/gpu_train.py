"""v5 trained at GPU scale on photos rendered on the fly (issue 46), time-boxed for a lent GPU.

The normals-only runs on the 2-core machine plateau at a slope cosine of ~0.15–0.2, from 1 000
to 8 000 batches of 4 crops and after a plain-albedo start alike
(research/notes/2026-12-v5-candidate.md). This
asks whether a larger network moves them: two ``train.py`` stages under one wall-time budget, on
``data=rendered`` (the photos rendered on the GPU every batch, the material bank painted by
the plan's CPU processes):

1. ``experiment=anchored_rendered_normals``: the normals alone, half the relief inverted, half the
   base colours faded (the shading-first stage);
2. ``experiment=anchored_rendered`` from stage 1's last weights: the full recipe.

Both with the plan's generator width (``--width``; twice v5's by default), photos a batch
(``--batch``) and loader processes, ``trainer=gpu`` (bf16-mixed), validation and checkpoints
off. :class:`TimedSnapshots` saves the weights at evenly spaced times of each stage's share, so
the two stages give learning curves; each snapshot is exported (fp16, ``brdfgan
export-weights``) to ``OUT/<stage>_<k>.safetensors``, to be scored on the CPU machine
(``evaluate.py "ckpt={…}"``). ``OUT/gpu_train.json`` holds the plan, the steps and photos of
every snapshot and the stages' step times
(:class:`research.gpu_check.StepTimer`); ``OUT/gpu_train.log`` the tails of the runs' logs.

The device machine has no Mitsuba and no ``../shared``, and a call carries at most 64 MiB, so
:func:`stage` first fills ``.device/`` here (git-ignored; ``carry: [".device", ".whl"]``):

- ``.device/scans/``: the training scan sets at 512² (their 1024² files do not fit; the bank reads
  them back at the spec's 1024², so a quarter-scan crop is half as sharp as on the CPU machine),
  each map in its own format (JPEG q95, PNG); the six held-out sets as 16² stand-ins, which only
  keep the split by name identical and are never read;
- ``.device/environments.npz``: the training environments tabulated here (the sun and sky need
  Mitsuba), which :meth:`MaterialBank.build` keeps instead of tabulating them again.

  python -m research.gpu_train stage                                  # here, once
  python -m research.gpu_train run --budget 420                       # there ($OUT set)
  python -m research.gpu_train run --device cpu --tiny --budget 200 --out /tmp/gt  # CPU smoke, ~2 min
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from hydra.utils import instantiate
from lightning.pytorch import LightningModule, Trainer
from lightning.pytorch.callbacks import Callback

from brdfgan.errors import UserError, run_reporting_errors
from brdfgan.io.atomic import atomic_replace, write_text_atomic
from research.gpu_check import TINY_PLAN as CHECK_PLAN
from research.gpu_check import StepTimer, last_error_line, make_data, run_train_py, step_stats

ROOT = Path(__file__).resolve().parents[1]
STAGED = ROOT / ".device"
STAGED_SCANS = STAGED / "scans"
STAGED_ENVIRONMENTS = STAGED / "environments.npz"
STAGED_SCAN_SIDE = 512
STAND_IN_SIDE = 16
STAGES = (("shading", "experiment=anchored_rendered_normals"), ("full", "experiment=anchored_rendered"))
MIN_STAGE_S = 5.0  # less training than this is not worth a stage's start
STEP_WARMUP = 10  # batches a stage's step times leave out (the loaders starting, the first steps)
LOG_TAIL_BYTES = 60_000  # of each stage's log, in OUT/gpu_train.log
STARTUP_ALLOWANCE_S = (
    45.0  # a stage's imports, bank check and setup before its clock starts at on_train_start
)
EXPORT_RESERVE_S = 60.0  # the exports after both stages (a process each, ~5 s)
EXPORT_TIMEOUT_S = 60.0
MAX_EXPORT_BYTES = 16 * 2**20  # the most one file under OUT may hold to come back


# --------------------------------------------------------------------------------------------
# The snapshot callback (runs inside train.py)


class TimedSnapshots(Callback):
    """Saves the weights (``trainer.save_checkpoint(weights_only=True)``) at ``count`` evenly spaced
    times of ``seconds`` from the start of training, as ``dirpath/snapshot<k>.ckpt``, and stops
    training at the last; each snapshot's step, photos and time go to ``dirpath/snapshots.json``.

    Args:
        dirpath: the folder of the snapshots.
        seconds: the training time the last snapshot is taken at.
        count: how many snapshots.
    """

    def __init__(self, dirpath: str, seconds: float, count: int) -> None:
        super().__init__()
        if seconds <= 0 or count < 1:
            raise ValueError(f"TimedSnapshots: seconds={seconds} and count={count} must be positive")
        self.dirpath = Path(dirpath)
        self.seconds = seconds
        self.count = count
        self.taken: list[dict[str, Any]] = []
        self._start = 0.0
        self._photos = 0

    def on_train_start(self, trainer: Trainer, pl_module: LightningModule) -> None:
        self.dirpath.mkdir(parents=True, exist_ok=True)
        self._start = time.monotonic()

    def on_train_batch_end(
        self, trainer: Trainer, pl_module: LightningModule, outputs: Any, batch: Any, batch_idx: int
    ) -> None:
        self._photos += int(batch["photo"].shape[0]) * trainer.world_size
        elapsed = time.monotonic() - self._start
        k = len(self.taken) + 1
        if elapsed < self.seconds * k / self.count:
            return
        path = self.dirpath / f"snapshot{k}.ckpt"
        trainer.save_checkpoint(path, weights_only=True)
        self.taken.append({"snapshot": k, "path": str(path), "step": trainer.global_step,
                           "photos": self._photos, "seconds": round(elapsed, 2)})  # fmt: skip
        if trainer.is_global_zero:
            write_text_atomic(self.dirpath / "snapshots.json", json.dumps(self.taken, indent=1) + "\n")
        if k == self.count:
            trainer.should_stop = True


# --------------------------------------------------------------------------------------------
# Staging (here)


def stage(scans: Path, to: Path = STAGED) -> None:
    """Fill ``to`` (``.device/``) from the scan sets in ``scans`` (module docstring); print its size."""
    import cv2

    from brdfgan.data.materials.scanned import SCANNED_EXTENSIONS, scanned_material_folders
    from brdfgan.data.spec.dataset_spec import split_scan_sets

    work = Path(tempfile.mkdtemp(prefix="gpu_train-"))
    overrides = [*_bank_overrides(work, 1), f"data.bank.spec.scans.folder={scans}"]
    bank = instantiate(_compose(overrides).data.bank, _convert_="all")
    folders = scanned_material_folders(str(scans), key="--scans")
    splits = split_scan_sets(bank.spec)
    held_out = {folders[i].name for split in ("val", "test") for i in splits[split]}
    temp = to.with_name(to.name + ".partial")
    shutil.rmtree(temp, ignore_errors=True)
    for folder in folders:
        side = STAND_IN_SIDE if folder.name in held_out else STAGED_SCAN_SIDE
        (temp / "scans" / folder.name).mkdir(parents=True)
        for source in sorted(folder.iterdir()):
            if source.suffix.lower() not in SCANNED_EXTENSIONS:
                continue
            image = cv2.imread(str(source), cv2.IMREAD_UNCHANGED)
            if image is None:
                raise UserError(f"{source}: not a readable image")
            small = cv2.resize(image, (side, side), interpolation=cv2.INTER_AREA)
            quality = [cv2.IMWRITE_JPEG_QUALITY, 95] if source.suffix.lower() != ".png" else []
            if not cv2.imwrite(str(temp / "scans" / folder.name / source.name), small, quality):
                raise UserError(f"{temp / 'scans' / folder.name / source.name}: could not be written")
    bank.tabulate_environments(temp / STAGED_ENVIRONMENTS.name)
    shutil.rmtree(to, ignore_errors=True)
    temp.rename(to)
    size = sum(path.stat().st_size for path in to.rglob("*") if path.is_file())
    print(f"{to}: {size / 2**20:.1f} MiB ({len(folders)} scan sets)")


# --------------------------------------------------------------------------------------------
# The run (there)


@dataclass(frozen=True)
class Plan:
    """Sizes of a run: the generator's width, photos a batch, loader processes, painting
    processes, snapshots a stage, stage 1's share of the training time, the device and
    precision; ``overrides`` on top."""

    device: str
    width: int
    batch: int
    workers: int
    paint_workers: int
    snapshots: int
    shading_share: float
    precision: str
    overrides: tuple[str, ...] = ()


def _compose(overrides: Sequence[str]) -> Any:
    from research.relief_tables import compose_config

    return compose_config(overrides)


def _bank_overrides(work: Path, paint_workers: int) -> list[str]:
    """What decides the bank (its spec, folder and painting), shared by :func:`stage`, the run's
    own bank build and both stages, so all three find the same bank (with the same
    ``BRDFGAN_SCANS_DIR``)."""
    return [
        "experiment=anchored_rendered",
        "data.prepare=null",
        "+dataset_spec@data.bank.spec=procedural_and_scans",
        f"data.bank.folder={work / 'banks'}",
        f"data.bank.paint_workers={paint_workers}",
    ]


def stage_overrides(plan: Plan, work: Path, name: str, seconds: float, init_from: Path | None) -> list[str]:
    """The ``train.py`` overrides of stage ``name`` under ``seconds`` of training."""
    cuda = plan.device == "cuda"
    experiment = dict(STAGES)[name]
    run_dir = work / "runs" / name
    return [
        *_bank_overrides(work, plan.paint_workers),
        experiment,
        f"trainer={'gpu' if cuda else 'cpu'}",
        f"trainer.precision={plan.precision}",
        f"model.generator.width={plan.width}",
        f"data.batch_size={plan.batch}",
        f"data.num_workers={plan.workers}",
        f"data.pin_memory={str(cuda).lower()}",
        f"data.data_dir={work / 'data'}",
        "data.epoch_samples=100000000",  # one epoch that the snapshots end
        "data.compile_renderer=false",  # eager is milliseconds on a GPU; compiling costs each stage
        "++loss.compile=false",
        "trainer.max_epochs=1",
        "trainer.max_steps=-1",
        "trainer.num_sanity_val_steps=0",
        "++trainer.limit_val_batches=0",
        "++trainer.enable_checkpointing=false",
        "trainer.enable_progress_bar=false",
        "trainer.log_every_n_steps=50",
        "test=false",
        "callbacks=none",
        "+callbacks.snapshots._target_=research.gpu_train.TimedSnapshots",
        f"+callbacks.snapshots.dirpath={run_dir / 'snapshots'}",
        f"+callbacks.snapshots.seconds={seconds:.0f}",
        f"+callbacks.snapshots.count={plan.snapshots}",
        f"+callbacks.step_timer._target_={StepTimer.__module__}.{StepTimer.__name__}",
        f"+callbacks.step_timer.out={run_dir / 'step_timer.json'}",
        f"hydra.run.dir={run_dir}",
        *([f"init_from={init_from}"] if init_from is not None else []),
        *plan.overrides,
    ]


def build_bank(plan: Plan, work: Path) -> dict[str, Any]:
    """Paint the bank the stages train on (``paint_workers`` processes), with the staged
    environment table; its folder and time."""
    start = time.perf_counter()
    config = _compose([*_bank_overrides(work, plan.paint_workers), *plan.overrides])
    bank = instantiate(config.data.bank, _convert_="all")
    if STAGED_ENVIRONMENTS.exists():
        bank.root.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(STAGED_ENVIRONMENTS, bank.root / STAGED_ENVIRONMENTS.name)
    bank.build(progress=False)
    seconds = round(time.perf_counter() - start, 1)
    return {"folder": str(bank.root), "procedural": bank.procedural_count,
            "scan_sets": len(bank.scan_folders), "seconds": seconds}  # fmt: skip


def run_stage(
    plan: Plan,
    work: Path,
    env: dict[str, str],
    name: str,
    seconds: float,
    init_from: Path | None,
    kill_after: float,
) -> dict[str, Any]:
    """One ``train.py`` stage of ``seconds`` of training, killed after ``kill_after`` seconds (and
    on any exception here, an interrupt included: it runs in a process group of its own)."""
    run_dir = work / "runs" / name
    log = work / f"train_{name}.log"
    overrides = stage_overrides(plan, work, name, seconds, init_from)
    start = time.perf_counter()
    code = run_train_py(overrides, log, env, kill_after)
    error = "timed out" if code is None else f"exit {code}" if code != 0 else None
    result: dict[str, Any] = {
        "stage": name,
        "overrides": overrides,
        "wall_s": round(time.perf_counter() - start, 1),
    }
    snapshots = run_dir / "snapshots" / "snapshots.json"
    result["snapshots"] = json.loads(snapshots.read_text()) if snapshots.exists() else []
    timer = run_dir / "step_timer.json"
    if timer.exists():
        result["step_timer"] = _step_summary(json.loads(timer.read_text()))
    if error is not None:
        result["error"] = f"{error}: {last_error_line(log)}"
    return result


def _step_summary(timer: dict[str, Any]) -> dict[str, Any]:
    """The batches a stage trained, their shape and peak memory, and :func:`step_stats`' medians
    past the first ten (the loaders starting, the first steps)."""
    compute = timer.get("compute_s", [])
    summary = {
        "batches": len(compute),
        "batch_shape": timer.get("batch_shape"),
        "peak_bytes": timer.get("peak_bytes"),
    }
    return {**summary, **(step_stats(timer, STEP_WARMUP) if len(compute) > STEP_WARMUP else {})}


def export(
    work: Path, env: dict[str, str], name: str, snapshot: dict[str, Any], out: Path, hardware: str
) -> str:
    """``brdfgan export-weights`` of one snapshot into ``out``; the file's name, or the error."""
    target = out / f"{name}_{snapshot['snapshot']}.safetensors"
    command = [sys.executable, "-m", "brdfgan.cli", "export-weights", str(work / "runs" / name),
               "--checkpoint", snapshot["path"], "--out", str(target), "--hardware", hardware]  # fmt: skip
    try:
        done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, check=False,
                              timeout=EXPORT_TIMEOUT_S)  # fmt: skip
    except subprocess.TimeoutExpired:
        return f"export failed: timed out after {EXPORT_TIMEOUT_S:.0f} s"
    if done.returncode != 0:
        lines = done.stderr.strip().splitlines()
        return f"export failed: {lines[-1] if lines else f'exit {done.returncode}'}"
    target.with_suffix(".json").unlink(missing_ok=True)  # OUT takes 8 files; the summary holds it
    if target.stat().st_size > MAX_EXPORT_BYTES:  # it would not come back: say so instead
        target.unlink()
        return f"export failed: {target.name} over {MAX_EXPORT_BYTES // 2**20} MiB (a narrower --width)"
    return target.name


def run(plan: Plan, budget: float, out: Path) -> int:
    """Bank, both stages and the exports inside ``budget`` seconds; the summary in ``out``."""
    deadline = time.monotonic() + budget
    out.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="gpu_train-"))
    # The runs validate nothing (the CPU machine scores the snapshots), but a datamodule reads its
    # validation split's manifest: gpu_check's toy shards, photographed by the torch renderer.
    make_data(work / "data", CHECK_PLAN)
    scans = STAGED_SCANS if STAGED_SCANS.exists() else None
    if scans is not None:
        os.environ["BRDFGAN_SCANS_DIR"] = str(scans)
    env = {
        **os.environ,
        "PROJECT_ROOT": str(work),
        "TORCHINDUCTOR_CACHE_DIR": str(work / "inductor"),
        "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), str(ROOT), os.environ.get("PYTHONPATH", "")]),
        "PYTHONUNBUFFERED": "1",
    }
    hardware = torch.cuda.get_device_name(0) if plan.device == "cuda" else "CPU"
    summary: dict[str, Any] = {"plan": asdict(plan), "budget_s": budget, "hardware": hardware, "stages": []}
    status = 0
    try:
        summary["bank"] = build_bank(plan, work)
        print(f"bank: {summary['bank']}", flush=True)
        init_from: Path | None = None
        for name, _ in STAGES:
            left = deadline - time.monotonic() - EXPORT_RESERVE_S  # for this stage and any after it
            seconds = stage_seconds(left, name, plan.shading_share)
            if seconds is None:
                summary["stages"].append(
                    {"stage": name, "error": f"skipped: {left:.0f} s of the budget left"}
                )
                status = 1
                break
            result = run_stage(plan, work, env, name, seconds, init_from, kill_after=max(left, 1.0)
                               if name == "full" else seconds + STARTUP_ALLOWANCE_S * 2)  # fmt: skip
            summary["stages"].append(result)
            print(f"{name}: {json.dumps({k: v for k, v in result.items() if k != 'overrides'})}", flush=True)
            result["exported"] = [export(work, env, name, s, out, hardware) for s in result["snapshots"]]
            _write_summary(out, summary, work)
            if (
                "error" in result
                or not result["snapshots"]
                or any(entry.startswith("export failed") for entry in result["exported"])
            ):
                status = 1
                break
            init_from = Path(result["snapshots"][-1]["path"])
    finally:
        _write_summary(out, summary, work)
        shutil.rmtree(work, ignore_errors=True)
    return status


def stage_seconds(left: float, name: str, shading_share: float) -> float | None:
    """The training time of stage ``name`` when ``left`` seconds remain for it and those after it
    (each pays ``STARTUP_ALLOWANCE_S`` before its clock starts): stage 1 its share of what both
    can train, stage 2 the rest; ``None`` when under ``MIN_STAGE_S`` would be left to train.

    >>> stage_seconds(300.0, "shading", 0.5), stage_seconds(200.0, "full", 0.5)
    (105.0, 155.0)
    >>> stage_seconds(40.0, "full", 0.5) is None
    True
    """
    if name == "shading":
        seconds = shading_share * (left - 2 * STARTUP_ALLOWANCE_S)
    else:
        seconds = left - STARTUP_ALLOWANCE_S
    return seconds if seconds >= MIN_STAGE_S else None


def _write_summary(out: Path, summary: dict[str, Any], work: Path) -> None:
    """``OUT/gpu_train.json`` and the tails of the stages' logs in ``OUT/gpu_train.log``, each
    replaced whole (a call killed at its limit still brings back the last complete ones)."""
    write_text_atomic(out / "gpu_train.json", json.dumps(summary, indent=1, default=str) + "\n")
    tails = b"".join(
        f"==> {log.name} <==\n".encode() + log.read_bytes()[-LOG_TAIL_BYTES:]
        for log in sorted(work.glob("train_*.log"))
    )
    with atomic_replace(out / "gpu_train.log") as temp:
        temp.write_bytes(tails)


# One GPU: v5's generator at twice its width (4x the weights: the normals alone plateau from
# 4 000 to 8 000 batches at v5's width on the CPU machine, so more photos alone do not lift them;
# research/notes/2026-12-v5-candidate.md, "More photos"), 32 photos a batch. Two snapshots a stage: four fp16
# exports of ~15 MB fit OUT's 64 MiB.
GPU_PLAN = Plan(device="cuda", width=32, batch=32, workers=14, paint_workers=16,
                snapshots=2, shading_share=0.45, precision="bf16-mixed")  # fmt: skip
# Minutes on a CPU: the same path at toy sizes (a 24-material procedural bank at 128², no scans,
# 64² photos, a narrow network).
TINY_PLAN = Plan(
    device="cpu", width=8, batch=2, workers=0, paint_workers=2, snapshots=2,
    shading_share=0.5, precision="32-true",
    overrides=(
        "data.bank.spec.materials=24",
        "data.bank.spec.scans.fraction=0",
        "data.bank.spec.scans.folder=null",
        "data.bank.spec.material_resolution=128",
        "data.bank.spec.resolution=64",
        "data.train_crop=32",
    ),
)  # fmt: skip


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    staging = commands.add_parser("stage", help="fill .device/ here")
    scans = Path(os.environ.get("BRDFGAN_SCANS_DIR", ROOT.parent / "shared" / "scans"))
    staging.add_argument("--scans", type=Path, default=scans, help=f"the scan sets (default {scans})")
    staging.add_argument("--to", type=Path, default=STAGED, help=f"the staging folder (default {STAGED})")
    running = commands.add_parser("run", help="train both stages (on the GPU machine)")
    running.add_argument("--budget", type=float, default=420.0, help="seconds for everything (default 420)")
    running.add_argument("--device", choices=("cuda", "cpu"), default="cuda")
    running.add_argument("--tiny", action="store_true", help="toy sizes (the CPU smoke mode)")
    running.add_argument("--batch", type=int, help="photos a batch (default: the plan's)")
    running.add_argument("--width", type=int, help="the generator's width (default: the plan's; v5's is 16)")
    running.add_argument("--out", type=Path, default=Path(os.environ.get("OUT", "gpu_train_out")))
    args = parser.parse_args(argv)
    for name in ("budget", "batch", "width"):
        value = getattr(args, name, None)
        if value is not None and value <= 0:
            raise UserError(f"--{name}={value}: must be positive")
    if args.command == "stage":
        stage(args.scans, args.to)
        return 0
    if args.device == "cuda" and not torch.cuda.is_available():
        print(
            "gpu_train: no CUDA device; for the CPU smoke mode run with --device cpu --tiny", file=sys.stderr
        )
        return 2
    plan = TINY_PLAN if args.tiny else GPU_PLAN
    chosen = {"batch": args.batch, "width": args.width}
    plan = Plan(
        **{**asdict(plan), "device": args.device, **{k: v for k, v in chosen.items() if v is not None}}
    )
    return run(plan, args.budget, args.out)


if __name__ == "__main__":
    # A user error (a missing scans folder, a bad key) is one line and exit 2, not a traceback.
    sys.exit(run_reporting_errors(main, interrupted="interrupted: OUT holds what was exported so far"))
