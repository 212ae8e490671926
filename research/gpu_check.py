"""GPU readiness check: the paper configuration's training step on CUDA, unattended, in minutes.

Run ``research/gpu_check.sh`` (GPU) or ``research/gpu_check.sh --device cpu --tiny`` (a CPU smoke
run of the same path at toy sizes, seconds). Nothing is downloaded and Mitsuba is not needed:

1. Data: a small dataset (10 materials → 32 train, 2 val, 2 test samples at 512²) made by the
   real generation pipeline (:func:`brdfgan.data.generation.generation.run_generation`: procedural families,
   crops, the shard writer, manifests) with the photos rendered by the project's torch renderer
   (:func:`brdfgan.core.render.render_flash` + :func:`brdfgan.core.exposure.auto_expose`) instead
   of Mitsuba, in a temporary folder.
2. ``train.py experiment=paper trainer=gpu`` on it (paper networks, both discriminators, the full
   loss, whole 512² samples, batch 8, bf16-mixed), for a fixed number of steps, validation and
   checkpoints off; :class:`StepTimer` (a Lightning callback added through ``+callbacks``) times
   every batch with ``torch.cuda.synchronize``. The same run again in ``32-true``.
3. The rendering loss alone (the loss config's :class:`~brdfgan.losses.rendering.RenderingLoss`,
   compiled or not as configured), forward + backward on a batch of the same data, under the
   same autocast: its share of the step.
4. ``train.py experiment=anchored_rendered`` on photos rendered on the fly (``data=rendered``): a
   material bank painted by the CPU (the tiny spec's families at the plan's sizes, room
   environments only, so no Mitsuba), the photos rendered on the device in every batch's transfer
   hook; its batch interval.
5. With two or more GPUs: ``trainer=ddp trainer.devices=2`` for a few steps.

The Markdown table goes to stdout and, when ``$OUT`` is set (the GPU tool copies it back), to
``$OUT/gpu_check.md``, with the raw numbers in ``$OUT/gpu_check.json`` and each run's log. A run
that fails is a row saying so (the others still run) and the exit status is 1. Without CUDA the
default mode prints one line and exits 2; a missing package, one line and exit 3.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import os
import platform
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from lightning.pytorch import LightningModule, Trainer
from lightning.pytorch.callbacks import Callback

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"
# What the check imports beyond torch and Lightning (module name → pip name), checked first so
# that a bare machine gets one line naming them rather than a traceback minutes in.
REQUIRED_MODULES = {
    "hydra": "hydra-core",
    "omegaconf": "omegaconf",
    "webdataset": "webdataset",
    "cv2": "opencv-python-headless",
    "kornia": "kornia",
    "OpenEXR": "OpenEXR",
    "brdfgan": "brdfgan (PYTHONPATH=src or pip install -e .)",
}
NO_CUDA_EXIT = 2
MISSING_PACKAGE_EXIT = 3
LOG_TAIL_BYTES = 200_000  # of each run's log kept under $OUT
MIN_RUN_SECONDS = 20.0  # a train.py run given less would only time out
EAGER_LOSS = "++loss.compile=false"
GAVE_UP = ("timed out", "skipped")  # run errors that a retry would only repeat


# --------------------------------------------------------------------------------------------
# The timing callback (runs inside train.py)


def _synchronize(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


class StepTimer(Callback):
    """Times every training batch and writes the numbers to ``out`` (JSON) when training ends.

    ``compute_s``: from ``on_train_batch_start`` (the batch already on the device) to
    ``on_train_batch_end``, both after a device synchronise: the step alone. ``interval_s``: from
    one batch end to the next, data loading and Lightning's own work included (what sets the
    throughput). Rank 0 writes; its peak CUDA memory is ``torch.cuda.max_memory_allocated``.

    Args:
        out: the JSON file to write.
    """

    def __init__(self, out: str) -> None:
        super().__init__()
        self.out = out
        self.compute_s: list[float] = []
        self.interval_s: list[float] = []
        self.batch_shape: list[int] = []
        self._start = 0.0
        self._last_end: float | None = None

    def on_train_batch_start(
        self, trainer: Trainer, pl_module: LightningModule, batch: Any, batch_idx: int
    ) -> None:
        _synchronize(pl_module.device)
        self._start = time.perf_counter()

    def on_train_batch_end(
        self, trainer: Trainer, pl_module: LightningModule, outputs: Any, batch: Any, batch_idx: int
    ) -> None:
        _synchronize(pl_module.device)
        now = time.perf_counter()
        self.compute_s.append(now - self._start)
        if self._last_end is not None:
            self.interval_s.append(now - self._last_end)
        self._last_end = now
        self.batch_shape = list(batch["photo"].shape)

    def on_train_end(self, trainer: Trainer, pl_module: LightningModule) -> None:
        if not trainer.is_global_zero:
            return
        device = pl_module.device
        networks = {
            name: sum(p.numel() for p in network.parameters())
            for name in ("generator", "discriminator")
            if isinstance(network := getattr(pl_module, name, None), torch.nn.Module)
        }
        result = {
            "compute_s": self.compute_s,
            "interval_s": self.interval_s,
            "batch_shape": self.batch_shape,
            "world_size": trainer.world_size,
            "precision": str(trainer.precision),
            "device": str(device),
            "peak_bytes": torch.cuda.max_memory_allocated(device) if device.type == "cuda" else None,
            "parameters": networks,
        }
        Path(self.out).write_text(json.dumps(result, indent=1) + "\n")


# --------------------------------------------------------------------------------------------
# What to run


@dataclass(frozen=True)
class Plan:
    """Sizes of one check. ``warmup`` batches are run and not timed (compilation, cuDNN's
    algorithm search, the loaders filling up), then ``steps`` timed ones."""

    device: str  # "cuda" or "cpu"
    resolution: int
    material_resolution: int
    batch: int
    workers: int
    warmup: int
    steps: int
    precision: str  # the main run's
    compare_precision: str  # the comparison run's
    compare_warmup: int
    compare_steps: int
    ddp_steps: int
    render_repeats: int
    overrides: tuple[str, ...] = ()  # on top of experiment=paper


# One H200: 5 + 20 batches ≈ 1–2 min with compilation; the comparison and DDP runs are shorter.
GPU_PLAN = Plan(
    device="cuda",
    resolution=512,
    material_resolution=512,
    batch=8,
    workers=6,
    warmup=5,
    steps=20,
    precision="bf16-mixed",
    compare_precision="32-true",
    compare_warmup=3,
    compare_steps=10,
    ddp_steps=10,
    render_repeats=20,
)
# Seconds on a CPU: the same runs at toy sizes, fp32 first and bf16-mixed (CPU autocast) second,
# the rendering loss eager (compiling it would take longer than everything else).
TINY_PLAN = Plan(
    device="cpu",
    resolution=64,
    material_resolution=128,
    batch=2,
    workers=0,
    warmup=1,
    steps=2,
    precision="32-true",
    compare_precision="bf16-mixed",
    compare_warmup=0,  # one batch: bf16 convolutions are slow on CPUs without bf16 units
    compare_steps=1,
    ddp_steps=2,
    render_repeats=3,
    overrides=(
        "model.generator.width=8",
        "model.generator.residual_blocks=2",
        "model.discriminator.width=8",
        EAGER_LOSS,
        "data.shuffle_buffer=8",
    ),
)


def _timed_run_overrides(
    plan: Plan, timer_out: Path, *, precision: str, optimizer_steps: int, name: str, trainer: list[str]
) -> list[str]:
    """What every timed ``train.py`` run of the check shares: the device(s), batch and loader
    sizes, ``optimizer_steps`` steps, no validation, checkpoints or test, :class:`StepTimer`."""
    return [
        *trainer,
        f"task_name=gpu_check_{name}",
        f"data.batch_size={plan.batch}",
        f"data.num_workers={plan.workers}",
        f"data.pin_memory={str(plan.device == 'cuda').lower()}",
        f"trainer.precision={precision}",
        f"trainer.max_steps={optimizer_steps}",
        "trainer.num_sanity_val_steps=0",
        "++trainer.limit_val_batches=0",
        "++trainer.enable_checkpointing=false",
        "trainer.enable_progress_bar=false",
        "test=false",
        "callbacks=none",
        "+callbacks.gpu_check_timer._target_=research.gpu_check.StepTimer",
        f"+callbacks.gpu_check_timer.out={timer_out}",
    ]


def training_overrides(
    plan: Plan,
    data_dir: Path,
    timer_out: Path,
    *,
    precision: str,
    batches: int,
    name: str,
    ddp: bool = False,
) -> list[str]:
    """The ``train.py`` overrides of one timed run: ``experiment=paper`` on ``data_dir``, on one
    device (or two DDP processes), ``batches`` training batches, no validation, checkpoints or
    test, :class:`StepTimer` writing to ``timer_out``."""
    cuda = plan.device == "cuda"
    trainer = ["trainer=ddp", "trainer.devices=2"] if ddp else [f"trainer={'gpu' if cuda else 'cpu'}"]
    if ddp and not cuda:
        trainer.append("trainer.accelerator=cpu")
    # max_steps counts optimizer steps: a generator and a discriminator step per batch.
    timed = _timed_run_overrides(
        plan, timer_out, precision=precision, optimizer_steps=2 * batches, name=name, trainer=trainer
    )
    return ["experiment=paper", *timed, f"data.data_dir={data_dir}", *plan.overrides]


def rendered_overrides(
    plan: Plan, data_dir: Path, bank_dir: Path, timer_out: Path, *, precision: str, batches: int
) -> list[str]:
    """The ``train.py`` overrides of the on-the-fly run: ``experiment=anchored_rendered`` (photos
    rendered each step from a material bank, ``data=rendered``) on the device, the bank painted by
    the CPU from the tiny spec's families at the plan's sizes with room environments only (sun and
    sky need Mitsuba), ``data_dir``'s shards for validation (unused here: validation is off)."""
    cuda = plan.device == "cuda"
    timed = _timed_run_overrides(
        plan, timer_out, precision=precision, optimizer_steps=batches, name="rendered",
        trainer=[f"trainer={'gpu' if cuda else 'cpu'}"],
    )  # fmt: skip
    spec = "data.bank.spec"
    toy = ["model.generator.width=8", EAGER_LOSS] if plan.overrides else []
    return [
        "experiment=anchored_rendered",
        *timed,
        f"data.data_dir={data_dir}",
        "data.prepare=null",
        f"+dataset_spec@{spec}=tiny",
        f"{spec}.materials=24",
        f"{spec}.material_resolution={plan.material_resolution}",
        f"{spec}.resolution={plan.resolution}",
        f"{spec}.lighting.sunsky_fraction=0",
        f"data.bank.folder={bank_dir}",
        f"data.train_crop={plan.resolution // 2}",
        f"data.compile_renderer={str(cuda).lower()}",
        *toy,
    ]


# --------------------------------------------------------------------------------------------
# Data


def torch_photographer(spec: Any) -> Callable[..., tuple[torch.Tensor, float]]:
    """A :data:`~brdfgan.data.generation.generation.PhotographFn` without Mitsuba: the flash-only torch
    render of the drawn flash and field of view, auto-exposed with the drawn exposure error (no
    environment light; tilt, distance and flash offset are ignored — the capture randomisation
    is off by default anyway)."""
    from brdfgan.core.exposure import auto_expose
    from brdfgan.core.render import FlashCapture, render_flash
    from brdfgan.data.phone.flash import blackbody_rgb

    def photograph(
        maps: torch.Tensor, lighting: Any, intensity: float, temperature: float, draw: Any, seed: int
    ) -> tuple[torch.Tensor, float]:
        capture = FlashCapture(draw.fov_deg, intensity, blackbody_rgb(temperature))
        ldr, scale = auto_expose(render_flash(maps[None], capture)[0], draw.exposure_ev)
        return ldr, float(scale)

    return photograph


def make_data(root: Path, plan: Plan) -> tuple[Path, int]:
    """Generate the check's dataset into ``root`` (10 materials: 8 train × 2 crops × 2 photos = 32
    train samples, one material each for val and test); return it and its train sample count."""
    from brdfgan.data.generation.generation import run_generation
    from brdfgan.data.materials.augment import CropSampling
    from brdfgan.data.phone.environments import LightingConfig
    from brdfgan.data.spec.dataset_spec import DatasetSpec
    from brdfgan.data.storage.shards import read_manifest

    spec = DatasetSpec(
        seed=0,
        materials=10,
        material_resolution=plan.material_resolution,
        resolution=plan.resolution,
        crops_per_material=2,
        train_renders=2,
        eval_renders=1,
        test_fraction=0.1,
        val_fraction=0.1,
        materials_per_shard=2,
        spp=1,  # Mitsuba's; unused by the torch photographer
        crop=CropSampling(scale_min=0.5, scale_max=1.0),
        lighting=LightingConfig(train_count=2, test_count=1, resolution=8),  # unused likewise
    )
    run_generation(spec, root, progress=False, photographer=torch_photographer)
    return root, int(read_manifest(root, "train")["samples"])


def first_batch(data_dir: Path, size: int) -> dict[str, Any]:
    """The first ``size`` train samples as a batch
    (:func:`~brdfgan.data.loading.datamodule.collate_samples`)."""
    from itertools import islice

    from brdfgan.data.loading.datamodule import collate_samples
    from brdfgan.data.storage.shards import iter_shard, list_shards

    samples = (sample for shard in list_shards(data_dir, "train") for sample in iter_shard(shard))
    return collate_samples(list(islice(samples, size)))


# --------------------------------------------------------------------------------------------
# Runs


@dataclass
class RunResult:
    """One ``train.py`` run: its overrides, its timer's numbers, or why there are none."""

    name: str
    overrides: list[str]
    seconds: float
    timer: dict[str, Any] | None
    error: str | None


def run_training(
    name: str,
    plan: Plan,
    data_dir: Path,
    work: Path,
    env: dict[str, str],
    timeout: float,
    *,
    precision: str,
    batches: int,
    ddp: bool = False,
    rendered: bool = False,
) -> RunResult:
    """``train.py`` with :func:`training_overrides` (``rendered``: :func:`rendered_overrides`) in
    its own process group (DDP ranks included), killed after ``timeout`` seconds; its output goes
    to ``work/train_<name>.log``."""
    timer_out = work / f"{name}.json"
    if rendered:
        overrides = rendered_overrides(
            plan, data_dir, work / "banks", timer_out, precision=precision, batches=batches
        )
    else:
        overrides = training_overrides(
            plan, data_dir, timer_out, precision=precision, batches=batches, name=name, ddp=ddp
        )
    if timeout < MIN_RUN_SECONDS:
        return RunResult(name, overrides, 0.0, None, f"skipped: {max(0.0, timeout):.0f} s of the budget left")
    log = work / f"train_{name}.log"
    start = time.perf_counter()
    error: str | None = None
    code = run_train_py(overrides, log, env, timeout)
    if code is None:
        error = f"timed out after {timeout:.0f} s"
    elif code != 0:
        error = f"exit {code}: {last_error_line(log)}"
    seconds = time.perf_counter() - start
    timer = None
    if error is None:
        try:
            timer = json.loads(timer_out.read_text())
        except (OSError, ValueError):
            error = f"no timings written: {last_error_line(log)}"
    return RunResult(name, overrides, seconds, timer, error)


def run_train_py(overrides: Sequence[str], log: Path, env: dict[str, str], timeout: float) -> int | None:
    """``train.py overrides`` in a process group of its own, its output into ``log``; its exit
    status, or ``None`` when it was killed at ``timeout`` seconds. The whole group (DDP ranks,
    loader processes) is killed at the timeout and on any exception here, an interrupt included."""
    with log.open("w") as handle:
        process = subprocess.Popen(
            [sys.executable, str(ROOT / "train.py"), *overrides],
            cwd=ROOT,
            env=env,
            stdout=handle,
            stderr=subprocess.STDOUT,
            start_new_session=True,  # its own group, so a timeout also ends the DDP ranks it starts
        )
        try:
            return process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None
        finally:
            if process.returncode is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()


def last_error_line(log: Path) -> str:
    """The line of a log that best says why a run failed: the last ``error:`` or exception line,
    else the last non-empty one."""
    try:
        lines = [line.strip() for line in log.read_text(errors="replace").splitlines() if line.strip()]
    except OSError:
        return "(no log)"
    markers = ("error:", "Error:", "Error ", "Exception", "CUDA out of memory")
    for line in reversed(lines):
        if any(marker in line for marker in markers):
            return line[:300]
    return lines[-1][:300] if lines else "(empty log)"


@dataclass(frozen=True)
class RenderTiming:
    """The rendering loss alone: median seconds of forward + backward, whether it was compiled
    (``loss.compile``) and the dtype of the maps it was given (the generator's, see
    :func:`prediction_dtype`)."""

    seconds: float
    compiled: bool
    maps_dtype: str


def prediction_dtype(device: torch.device, precision: str) -> torch.dtype:
    """The dtype of the generator's maps in a run of ``precision``: its output head
    (:func:`~brdfgan.models.heads.maps_from_raw`) on a bf16 convolution output under the run's
    autocast. Device-dependent: CUDA's autocast runs ``softplus`` (the normal's z) in float32 and
    the concatenations promote, the CPU's keeps bf16."""
    if precision != "bf16-mixed":
        return torch.float32
    from brdfgan.models.heads import maps_from_raw

    with torch.autocast(device.type, dtype=torch.bfloat16):
        return maps_from_raw(torch.zeros(1, 8, 2, 2, device=device, dtype=torch.bfloat16)).dtype


def time_rendering_loss(
    overrides: Sequence[str], batch: dict[str, Any], device: torch.device, precision: str, repeats: int
) -> RenderTiming:
    """The configured rendering loss, forward + backward, on ``batch`` under the autocast of
    ``precision``: median of ``repeats`` after two warm-ups (compilation, the first backward).

    The loss comes from the same composed config as the training run, so it is compiled or not
    as there; the prediction is the batch's maps shifted by one sample (valid maps that are not
    the target), a leaf in the dtype the generator would hand it.
    """
    import hydra
    from hydra import compose, initialize_config_dir

    from brdfgan.losses.rendering import RenderingLoss
    from brdfgan.training.config import register_configs

    register_configs()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="train", overrides=list(overrides))
    loss = hydra.utils.instantiate(cfg.loss, _convert_="all")
    rendering = getattr(loss, "rendering_loss", None)
    if not isinstance(rendering, RenderingLoss):
        raise RuntimeError("the loss config has no rendering term (loss.switches.rendering=false?)")
    rendering = rendering.to(device)
    target = batch["maps"].to(device)
    dtype = prediction_dtype(device, precision)
    prediction = target.roll(1, dims=0).to(dtype).contiguous()
    autocast = torch.autocast(device.type, dtype=torch.bfloat16, enabled=precision == "bf16-mixed")
    times = []
    for _ in range(2 + repeats):
        pred = prediction.clone().requires_grad_()
        _synchronize(device)
        start = time.perf_counter()
        with autocast:
            value = rendering(pred, target)
        value.backward()
        _synchronize(device)
        times.append(time.perf_counter() - start)
    compiled = bool(cfg.loss.get("compile", False))
    return RenderTiming(statistics.median(times[2:]), compiled, str(dtype).removeprefix("torch."))


# --------------------------------------------------------------------------------------------
# Report


def step_stats(timer: dict[str, Any], warmup: int) -> dict[str, float]:
    """Medians after ``warmup`` batches of the step (``compute_s``) and of the batch interval
    (``interval_s``, one entry shorter: the first batch has no predecessor), and the throughput
    over all ranks from the interval (from the step when no interval was timed: one batch).

    Shape:
        - timer["compute_s"]: N floats; timer["interval_s"]: N - 1 floats
    """
    compute = timer["compute_s"][warmup:]
    if not compute:
        raise ValueError(f"no timed batch: {len(timer['compute_s'])} batches for {warmup} warm-up")
    interval = timer["interval_s"][max(0, warmup - 1) :] or compute
    samples = timer["batch_shape"][0] * timer["world_size"]
    between = statistics.median(interval)
    return {
        "step_s": statistics.median(compute),
        "interval_s": between,
        "samples_per_s": samples / between,
        "timed": len(compute),
    }


def ms(seconds: float) -> str:
    return f"{seconds * 1e3:.1f} ms"


def gib(count: float | None) -> str:
    return "n/a (CPU)" if count is None else f"{count / 2**30:.2f} GiB"


def markdown_table(rows: Sequence[tuple[str, str, str]]) -> str:
    lines = ["| check | value | note |", "| --- | --- | --- |"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in rows]
    return "\n".join(lines)


def environment_rows(device: torch.device) -> list[tuple[str, str, str]]:
    import lightning

    if device.type == "cuda":
        name = torch.cuda.get_device_name(device)
        props = torch.cuda.get_device_properties(device)
        gpu = f"{name}, {props.total_memory / 2**30:.0f} GiB, {torch.cuda.device_count()} visible"
    else:
        gpu = f"none (CPU: {platform.processor() or platform.machine()}, {os.cpu_count()} cores)"
    cudnn = torch.backends.cudnn.version() if torch.backends.cudnn.is_available() else None
    versions = f"torch {torch.__version__}, CUDA {torch.version.cuda}, cuDNN {cudnn}"
    return [
        ("device", gpu, ""),
        ("versions", versions, f"Lightning {lightning.__version__}, Python {platform.python_version()}"),
    ]


# --------------------------------------------------------------------------------------------
# Main


def missing_modules() -> list[str]:
    missing = []
    for module, package in REQUIRED_MODULES.items():
        try:
            importlib.import_module(module)
        except ImportError:
            missing.append(package)
    return missing


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--device", choices=("cuda", "cpu"), default="cuda")
    parser.add_argument("--tiny", action="store_true", help="toy sizes (the CPU smoke mode)")
    parser.add_argument("--ddp", action="store_true", help="run the 2-process DDP row even without 2 GPUs")
    parser.add_argument("--budget", type=float, default=480.0, help="seconds for everything (default 480)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary folder (data, runs)")
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    deadline = time.monotonic() + args.budget
    if args.device == "cuda" and not torch.cuda.is_available():
        print(
            f"gpu_check: no CUDA device (torch {torch.__version__}, built for CUDA {torch.version.cuda}); "
            "for the CPU smoke mode run with --device cpu --tiny",
            file=sys.stderr,
        )
        return NO_CUDA_EXIT
    missing = missing_modules()
    if missing:
        print(f"gpu_check: missing Python packages: {', '.join(missing)}", file=sys.stderr)
        return MISSING_PACKAGE_EXIT
    plan = dataclasses.replace(TINY_PLAN if args.tiny else GPU_PLAN, device=args.device)
    device = torch.device("cuda:0" if plan.device == "cuda" else "cpu")
    out = Path(os.environ["OUT"]) if os.environ.get("OUT") else None
    work = Path(tempfile.mkdtemp(prefix="gpu_check-"))
    env = {
        **os.environ,
        "PROJECT_ROOT": str(work),  # paths.root_dir: every run's folder lands under work/logs
        "TORCHINDUCTOR_CACHE_DIR": str(work / "inductor"),  # shared by the runs, removed after
        "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), str(ROOT), os.environ.get("PYTHONPATH", "")]),
        "PYTHONUNBUFFERED": "1",
    }
    os.environ["TORCHINDUCTOR_CACHE_DIR"] = env["TORCHINDUCTOR_CACHE_DIR"]
    try:
        rows, raw, failed = run_checks(plan, device, work, env, deadline, force_ddp=args.ddp)
    finally:
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            for log in sorted(work.glob("train_*.log")):
                (out / log.name).write_bytes(log.read_bytes()[-LOG_TAIL_BYTES:])
        if args.keep:
            print(f"gpu_check: kept {work}", file=sys.stderr)
        else:
            shutil.rmtree(work, ignore_errors=True)
    mode = "tiny CPU smoke mode" if args.tiny else "paper configuration"
    report = f"## gpu_check ({mode})\n\n{markdown_table(rows)}\n"
    print(report)
    if out is not None:
        (out / "gpu_check.md").write_text(report)
        (out / "gpu_check.json").write_text(json.dumps(raw, indent=1, default=str) + "\n")
    return 1 if failed else 0


Row = tuple[str, str, str]


def run_checks(
    plan: Plan, device: torch.device, work: Path, env: dict[str, str], deadline: float, *, force_ddp: bool
) -> tuple[list[Row], dict[str, Any], bool]:
    """Every check of :func:`main`; returns the table rows, the raw numbers and whether any failed."""
    rows = environment_rows(device)
    raw: dict[str, Any] = {"plan": dataclasses.asdict(plan)}
    start = time.perf_counter()
    try:
        data_dir, train_samples = make_data(work / "data", plan)
    except Exception as error:  # nothing else can run without data; still one table
        rows.append(("data", "FAILED", one_line(error)))
        return rows, raw, True
    seconds = time.perf_counter() - start
    raw["data"] = {"seconds": seconds, "train_samples": train_samples}
    samples = f"{train_samples} train samples at {plan.resolution}²"
    rows.append(("data", samples, f"made in {seconds:.1f} s (torch renderer)"))
    networks = "paper networks" if not plan.overrides else "toy sizes: " + ", ".join(plan.overrides)
    rows.append(
        ("configuration", f"experiment=paper, batch {plan.batch}, {plan.resolution}² samples", networks)
    )
    runs = _Runs(data_dir, work, env, deadline, raw)

    main_run, plan, failed = _main_run(runs, plan, rows)
    if main_run.timer is not None:
        row, render_failed = _rendering_loss_row(main_run, data_dir, device, plan, raw)
        failed |= render_failed
        rows.append(row)
        if device.type == "cuda":
            torch.cuda.empty_cache()

    compare = runs.train(
        plan,
        f"compare_{_slug(plan.compare_precision)}",
        plan.compare_precision,
        plan.compare_warmup,
        plan.compare_steps,
    )
    failed |= compare.timer is None
    rows.append(compare_row(compare, main_run, plan, raw))

    rendered = runs.train(plan, "rendered", plan.precision, plan.warmup, plan.steps, rendered=True)
    failed |= rendered.timer is None
    rows.append(rendered_row(rendered, plan, raw))

    row, ddp_failed = _ddp_row(runs, plan, device, force_ddp=force_ddp)
    rows.append(row)
    return rows, raw, failed or ddp_failed


@dataclass
class _Runs:
    """What every training run of :func:`run_checks` shares: the data, the work folder, the
    environment, the deadline and the raw numbers each run adds to."""

    data_dir: Path
    work: Path
    env: dict[str, str]
    deadline: float
    raw: dict[str, Any]

    def train(
        self,
        run_plan: Plan,
        name: str,
        precision: str,
        warmup: int,
        steps: int,
        *,
        ddp: bool = False,
        rendered: bool = False,
    ) -> RunResult:
        # The later runs leave time for the ones after them (the DDP run is last).
        reserve = 10.0 if ddp else 30.0
        result = run_training(
            name,
            run_plan,
            self.data_dir,
            self.work,
            self.env,
            self.deadline - time.monotonic() - reserve,
            precision=precision,
            batches=warmup + steps,
            ddp=ddp,
            rendered=rendered,
        )
        if result.timer is not None:
            try:
                self.raw[name] = {"stats": step_stats(result.timer, warmup)}
            except ValueError as error:  # the run stopped before its timed batches
                result.timer, result.error = None, one_line(error)
        self.raw.setdefault(name, {}).update(seconds=result.seconds, timer=result.timer, error=result.error)
        return result


def _main_run(runs: _Runs, plan: Plan, rows: list[Row]) -> tuple[RunResult, Plan, bool]:
    """The main run, once more with the loss eager when the compiled one fails; its rows are
    appended to ``rows``. Returns the run, the plan it ran and whether the first try failed."""
    main_run = runs.train(plan, f"main_{_slug(plan.precision)}", plan.precision, plan.warmup, plan.steps)
    failed = main_run.timer is None
    if (
        main_run.timer is None
        and EAGER_LOSS not in plan.overrides
        and not str(main_run.error).startswith(GAVE_UP)
    ):
        # The compiled rendering loss is the newest part of the step: without it, is the rest ready?
        rows.extend(main_rows(main_run, plan, runs.raw))
        rows.append(("retry", EAGER_LOSS, "the run above failed; the rows below run the loss eager"))
        plan = dataclasses.replace(plan, overrides=(*plan.overrides, EAGER_LOSS))
        main_run = runs.train(
            plan, f"main_{_slug(plan.precision)}_eager", plan.precision, plan.warmup, plan.steps
        )
    rows.extend(main_rows(main_run, plan, runs.raw))
    return main_run, plan, failed


def _rendering_loss_row(
    main_run: RunResult, data_dir: Path, device: torch.device, plan: Plan, raw: dict[str, Any]
) -> tuple[Row, bool]:
    """The rendering loss's forward and backward alone on the main run's first batch, as a share
    of its step; and whether it failed."""
    try:
        batch = first_batch(data_dir, plan.batch)
        render = time_rendering_loss(main_run.overrides, batch, device, plan.precision, plan.render_repeats)
        raw["rendering_loss"] = dataclasses.asdict(render)
        share = render.seconds / raw[main_run.name]["stats"]["step_s"]
        how = (
            f"same batch, {'bf16 autocast' if plan.precision == 'bf16-mixed' else 'no autocast'}, "
            f"{render.maps_dtype} maps, "
            f"{'compiled' if render.compiled else 'eager'}; median of {plan.render_repeats}"
        )
        return ("rendering loss fwd+bwd", f"{ms(render.seconds)} ({share:.0%} of the step)", how), False
    except Exception as error:  # a row, not an abort: the other numbers still count
        return ("rendering loss fwd+bwd", "FAILED", one_line(error)), True


def _ddp_row(runs: _Runs, plan: Plan, device: torch.device, *, force_ddp: bool) -> tuple[Row, bool]:
    """Two DDP processes' step time where there are two GPUs (or ``force_ddp``); and whether it failed."""
    gpus = torch.cuda.device_count() if device.type == "cuda" else 0
    if not (gpus > 1 or force_ddp):
        return ("DDP, 2 processes", "skipped", f"{gpus} GPU(s) visible"), False
    ddp = runs.train(plan, "ddp", plan.precision, plan.warmup, plan.ddp_steps, ddp=True)
    if ddp.timer is None:
        return ("DDP, 2 processes", "FAILED", str(ddp.error)), True
    stats = runs.raw["ddp"]["stats"]
    note = f"{stats['samples_per_s']:.1f} samples/s over both; median of {stats['timed']}"
    return (f"DDP step time, 2 processes, {plan.precision}", ms(stats["step_s"]), note), False


def _slug(precision: str) -> str:
    return precision.replace("-", "_")


def one_line(error: BaseException) -> str:
    return " ".join(f"{type(error).__name__}: {error}".split())[:300]


def main_rows(result: RunResult, plan: Plan, raw: dict[str, Any]) -> list[Row]:
    """Step time, throughput and peak memory of the main run (or the row saying it failed)."""
    if result.timer is None:
        return [(f"train.py, {plan.precision}", "FAILED", str(result.error))]
    stats = raw[result.name]["stats"]
    params = ", ".join(f"{name} {count / 1e6:.1f} M" for name, count in result.timer["parameters"].items())
    interval = f"batch interval {ms(stats['interval_s'])} incl. data loading ({plan.workers} workers)"
    return [
        (
            f"step time, {plan.precision}",
            ms(stats["step_s"]),
            f"median of {stats['timed']} after {plan.warmup} warm-up; {params}",
        ),
        (f"throughput, {plan.precision}", f"{stats['samples_per_s']:.1f} samples/s", interval),
        (
            f"peak GPU memory, {plan.precision}",
            gib(result.timer["peak_bytes"]),
            "torch.cuda.max_memory_allocated",
        ),
    ]


def compare_row(result: RunResult, main_run: RunResult, plan: Plan, raw: dict[str, Any]) -> Row:
    """The comparison run's step time against the main run's."""
    label = f"{plan.compare_precision} vs {plan.precision}"
    if result.timer is None:
        return (label, "FAILED", str(result.error))
    stats = raw[result.name]["stats"]
    note = f"{ms(stats['step_s'])}, median of {stats['timed']}; peak {gib(result.timer['peak_bytes'])}"
    if main_run.timer is None:
        return (label, "n/a (the main run failed)", note)
    ratio = stats["step_s"] / raw[main_run.name]["stats"]["step_s"]
    return (label, f"{ratio:.2f}× the step time", note)


def rendered_row(result: RunResult, plan: Plan, raw: dict[str, Any]) -> Row:
    """The on-the-fly run: its batch interval (the CPU's draws, the device's renders, the step)."""
    label = f"experiment=anchored_rendered on rendered photos, {plan.precision}"
    if result.timer is None:
        return (label, "FAILED", str(result.error))
    stats = raw[result.name]["stats"]
    note = (
        f"step {ms(stats['step_s'])}, {stats['samples_per_s']:.1f} samples/s; photos rendered on the "
        f"{plan.device} each batch; peak {gib(result.timer['peak_bytes'])}; median of {stats['timed']}"
    )
    return (label, f"batch interval {ms(stats['interval_s'])}", note)


if __name__ == "__main__":
    sys.exit(main())
