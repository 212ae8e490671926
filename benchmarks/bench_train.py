"""Training-step benchmark: where the time of one GAN step goes, before and after issue 16.

Each case builds the real module from the Hydra configs (``conf/train.yaml`` + overrides) and runs
the real ``SVBRDFGAN.training_step`` through a Lightning ``Trainer`` on synthetic batches (random
valid maps, their flash photos from the project's renderer) in a fresh subprocess. It reports:

- the median step time (no profiler), samples/s;
- a component table from ``torch.profiler`` over a few later steps, using the step's
  ``brdfgan/…`` labels (:mod:`brdfgan.training.module`); "other" is Lightning's own work;
- the rendering loss's forward+backward alone at the step's shape, and its share of the step
  and of the generator's forward+backward (timed alone, same shape).

Variants: ``before`` is the step as it was (the direct vector-field renderer of
``tests/core/render_reference.py``, eager, Adam's default loop); ``eager`` the factored renderer without
compilation; ``after`` the training configs' defaults (the compiled loss, fused Adam), and rows
with one option changed each (Adam not fused, ``channels_last``) so each option's effect is
measured in the same run. Recipes: the default GAN step, v3's supervised step, v4's two stages
(the photo-anchored U-Net of ``experiment=anchored`` on 128² windows, then
``experiment=anchored_fixres`` on whole 256² photos; the rendering-loss share against the 10 %
goal), the paper's width. Last, the shard loader's samples/s per worker at 512² for both formats.

    python -m benchmarks.bench_train [--steps N] [--quick] [--only v4] [--no-loader]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import torch

ROOT = Path(__file__).resolve().parents[1]
LABEL_PREFIX = "brdfgan/"


@dataclass(frozen=True)
class Case:
    recipe: str  # a row group of the table
    variant: str  # a key of VARIANT_OVERRIDES, or an ablation's label (its overrides in the case's)
    overrides: tuple[str, ...]
    crop: int
    batch: int


# The GAN step (full loss) at the default model's size: width 16, 4 blocks, 128² crops, batch 4.
DEFAULT_RECIPE = ("experiment=procedural", "loss=full")
# The step v3 was trained with: the same without discriminators (loss=supervised).
V3_RECIPE = ("experiment=procedural",)
# v4's step: the photo-anchored two-decoder U-Net (model=anchored), supervised, same crops and batch.
V4_RECIPE = ("experiment=anchored",)
# The same without the surface decoder's shading image (issue 32's ablation: it bought no normals).
V4_NO_SHADING_RECIPE = (*V4_RECIPE, "model.generator.shading=none")
# v4's second stage: the same networks fine-tuned on whole 256² photos, two a batch (init_from is
# the warm start's file, not read by a benchmark).
V4_STAGE2_RECIPE = ("experiment=anchored_fixres", "init_from=null")
PAPER_WIDTH = ("experiment=procedural", "loss=full", "model=paper")  # the paper's networks (45.6 M + 2 D)

VARIANT_OVERRIDES: dict[str, tuple[str, ...]] = {
    "before": ("loss.compile=false", "model.optimizer.fused=false"),
    "eager": ("loss.compile=false", "model.optimizer.fused=false"),
    "after (defaults)": (),
    "after, Adam not fused": ("model.optimizer.fused=false",),
    "after + channels_last": ("model.channels_last=true",),
}


def _cases(quick: bool) -> list[Case]:
    gan = "default recipe, GAN (128², batch 4)"
    default = [Case(gan, v, DEFAULT_RECIPE, 128, 4) for v in VARIANT_OVERRIDES]
    supervised = "v3 recipe, supervised (128², batch 4)"
    v3 = [Case(supervised, v, V3_RECIPE, 128, 4) for v in ("before", "after (defaults)")]
    anchored = "v4 recipe, anchored U-Net, supervised (128², batch 4)"
    v4 = [Case(anchored, v, V4_RECIPE, 128, 4) for v in ("before", "after (defaults)")]
    v4 += [Case(anchored, "after, no shading image", V4_NO_SHADING_RECIPE, 128, 4)]
    whole = "v4 recipe stage 2, whole photos (256², batch 2)"
    v4 += [Case(whole, v, V4_STAGE2_RECIPE, 256, 2) for v in ("before", "after (defaults)")]
    paper_variants = ("before", "after (defaults)") if quick else ("before", "eager", "after (defaults)")
    paper = [Case("paper width (256², batch 2)", v, PAPER_WIDTH, 256, 2) for v in paper_variants]
    return default + v3 + v4 + paper


def _synthetic_batches(count: int, batch: int, size: int) -> list[dict[str, torch.Tensor]]:
    from tests.conftest import random_maps

    from brdfgan.core.render import render_flash

    batches = []
    for i in range(count):
        maps = random_maps(size, size, batch=(batch,), seed=i)
        photo = render_flash(maps).clamp(0.0, 1.0)
        batches.append({"photo": photo, "maps": maps})
    return batches


def _compose(overrides: list[str]) -> Any:
    from hydra import compose, initialize_config_dir

    from brdfgan.training.config import register_configs

    register_configs()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return compose(config_name="train", overrides=overrides)


def median_seconds(fn: Any, repeats: int) -> float:
    """The median wall time of ``repeats`` calls of ``fn`` after one warm-up call."""
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _direct_rendering_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    configs: Any,
    plane_half_size: float = 1.0,
    *,
    render: Any,
    **_: Any,
) -> torch.Tensor:
    """The rendering loss before issue 16: both map sets through the direct renderer."""
    from brdfgan.core.sampling import log_transform

    configs = configs.to(pred.device, torch.float32)
    image = render(pred.float(), configs.camera_position, configs.lights, plane_half_size)
    with torch.no_grad():
        reference = render(target.float(), configs.camera_position, configs.lights, plane_half_size)
    return (log_transform(image) - log_transform(reference)).abs().mean()


def _step_timer(warmup: int, steps: int, profiled: int) -> Any:
    """A Lightning callback that times the ``steps`` training steps after ``warmup`` ones
    (``step_times``, seconds) and profiles the ``profiled`` steps after those (``components``:
    seconds per step, by the loss's ``record_function`` labels, and the profiled step itself)."""
    import lightning as L
    from torch.profiler import ProfilerActivity, profile

    class StepTimer(L.Callback):
        def __init__(self) -> None:
            self.start = 0.0
            self.profiler: profile | None = None
            self.step_times: list[float] = []
            self.components: dict[str, float] = {}

        def on_train_batch_start(self, trainer: Any, pl_module: Any, batch: Any, batch_idx: int) -> None:
            if batch_idx == warmup + steps:
                self.profiler = profile(activities=[ProfilerActivity.CPU])
                self.profiler.__enter__()
            self.start = time.perf_counter()

        def on_train_batch_end(
            self, trainer: Any, pl_module: Any, outputs: Any, batch: Any, batch_idx: int
        ) -> None:
            elapsed = time.perf_counter() - self.start
            components = self.components
            if warmup <= batch_idx < warmup + steps:
                self.step_times.append(elapsed)
            if batch_idx >= warmup + steps:
                components["step (profiled)"] = components.get("step (profiled)", 0.0) + elapsed / profiled
            if batch_idx == warmup + steps + profiled - 1 and self.profiler is not None:
                self.profiler.__exit__(None, None, None)
                for event in self.profiler.key_averages():
                    if event.key.startswith(LABEL_PREFIX):
                        components[event.key[len(LABEL_PREFIX) :]] = event.cpu_time_total / 1e6 / profiled

    return StepTimer()


def _measure(case: Case, steps: int) -> dict[str, Any]:
    import hydra
    import lightning as L
    from tests.core.render_reference import render_point_lights_direct
    from torch.utils.data import DataLoader

    import brdfgan.losses.rendering as rendering_module

    torch.manual_seed(0)
    # An ablation's variant is a label: its overrides are in the case's.
    cfg = _compose([*case.overrides, *VARIANT_OVERRIDES.get(case.variant, ())])
    loss = hydra.utils.instantiate(cfg.loss, _convert_="all")
    module = hydra.utils.instantiate(cfg.model, loss=loss, total_steps=10_000, metrics=None, _convert_="all")
    if case.variant == "before":  # the loss as it was: full (B, V, 3, H, W) vector fields, eager
        rendering_module.rendering_loss = partial(_direct_rendering_loss, render=render_point_lights_direct)

    warmup, profiled = 3, 3
    batches = _synthetic_batches(4, case.batch, case.crop)
    stream = [batches[i % len(batches)] for i in range(warmup + steps + profiled)]
    timer = _step_timer(warmup, steps, profiled)
    step_times, components = timer.step_times, timer.components
    trainer = L.Trainer(
        accelerator="cpu",
        devices=1,
        max_epochs=1,
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        limit_val_batches=0,
        num_sanity_val_steps=0,
        callbacks=[timer],
    )
    first = time.perf_counter()
    trainer.fit(module, train_dataloaders=DataLoader(stream, batch_size=None))
    total = time.perf_counter() - first

    # The rendering loss alone and the generator alone, at the step's shape.
    photo, maps = batches[0]["photo"], batches[0]["maps"]
    render_loss = module.loss.rendering_loss

    def render_step() -> None:
        pred = batches[1]["maps"].clone().requires_grad_(True)
        render_loss(pred, maps).backward()

    def generator_step() -> None:
        module.generator.zero_grad(set_to_none=True)
        module.generator(photo).square().mean().backward()

    render_s = median_seconds(render_step, 3) if render_loss is not None else 0.0
    generator_s = median_seconds(generator_step, 3)
    step_s = statistics.median(step_times)
    return {
        "step_s": step_s,
        "samples_per_s": case.batch / step_s,
        "first_steps_s": total - sum(step_times) - components.get("step (profiled)", 0.0) * profiled,
        "render_s": render_s,
        "generator_s": generator_s,
        "components": components,
    }


COMPONENT_ORDER = (
    "generator_forward",
    "discriminator_forward",
    "discriminator_backward",
    "discriminator_optimizer",
    "generator_adversarial_forward",
    "parameter_loss_forward",
    "rendering_loss_forward",
    "generator_backward",
    "generator_optimizer",
    "schedule_and_logging",
)


def _print_components(rows: list[tuple[Case, dict[str, Any]]]) -> None:
    for recipe in dict.fromkeys(case.recipe for case, _ in rows):
        group = [
            (case, m)
            for case, m in rows
            if case.recipe == recipe and case.variant in ("before", "after (defaults)")
        ]
        if len(group) < 2:
            continue
        print(f"\nOne training step, {recipe}: component | ms | share (torch.profiler over 3 steps)\n")
        names = [name for name, _ in group]
        print("| component | " + " | ".join(f"{c.variant} ms | {c.variant} share" for c in names) + " |")
        print("|---|" + "---|---|" * len(group))
        for component in (*COMPONENT_ORDER, "other (Lightning, toggling, zero_grad)", "step (profiled)"):
            cells = []
            for _, m in group:
                parts = m["components"]
                step = parts.get("step (profiled)", 0.0)
                if component.startswith("other"):
                    value = step - sum(parts.get(c, 0.0) for c in COMPONENT_ORDER)
                else:
                    value = parts.get(component, 0.0)
                cells += [f"{1000 * value:.0f}", f"{100 * value / step:.0f} %" if step else "–"]
            print(f"| {component} | " + " | ".join(cells) + " |")


def _print_loader(size: int = 512, samples: int = 16, batches: int = 6) -> None:
    """The shard loader's samples/s per worker at ``size``² (the measurement of
    ``benchmarks.bench_datamodule``, for both shard formats, on the same samples)."""
    import tempfile

    from benchmarks.bench_datamodule import (
        FORMATS,
        _decode_time,
        _make_datasets,
        _single_thread_stream,
        _throughput,
    )

    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        _make_datasets(root, size, samples)
        rates = {
            shard_format: (
                1.0 / _decode_time(size, shard_format),
                _single_thread_stream(root / shard_format, batches)["samples_per_s"],
                _throughput(root / shard_format, 1, batches)["samples_per_s"],
            )
            for shard_format in FORMATS
        }
    print(f"\nShard loader at {size}², samples/s per worker (one torch thread)\n")
    print("| format | decode_sample | train loader in-process | one DataLoader worker |")
    print("|---|---|---|---|")
    for shard_format, (decode, stream, worker) in rates.items():
        print(f"| {shard_format} | {decode:.1f} | {stream:.1f} | {worker:.1f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=8, help="timed steps per case (after 3 warm-up steps)")
    parser.add_argument("--quick", action="store_true", help="fewer paper-width variants")
    parser.add_argument("--no-loader", action="store_true", help="skip the shard loader table")
    parser.add_argument("--only", metavar="TEXT", help="only the recipes whose name contains TEXT (e.g. v4)")
    parser.add_argument("--case", help=argparse.SUPPRESS)
    args = parser.parse_args()
    cases = _cases(args.quick)
    if args.case is not None:
        print(json.dumps(_measure(cases[int(args.case)], args.steps)))
        return

    rows = []
    for index, case in enumerate(cases):
        if args.only is not None and args.only not in case.recipe:
            continue
        command = [
            sys.executable,
            "-m",
            "benchmarks.bench_train",
            "--steps",
            str(args.steps),
            "--case",
            str(index),
        ]
        if args.quick:
            command.append("--quick")
        out = subprocess.run(command, check=True, capture_output=True, text=True, cwd=ROOT)
        rows.append((case, json.loads(out.stdout.strip().splitlines()[-1])))
        print(f"measured {case.recipe} {case.variant}", file=sys.stderr)

    print(
        f"\nTraining step (SVBRDFGAN.training_step through Lightning, synthetic batches), CPU, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, median of {args.steps} steps; "
        "speed-up against the 'before' row of the same recipe\n"
    )
    header = ["recipe", "variant", "step s", "samples/s", "speed-up", "first 3 steps s (incl. compile)",
              "render fwd+bwd s", "render / step", "G fwd+bwd s", "render / G fwd+bwd"]  # fmt: skip
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    before = {case.recipe: m for case, m in rows if case.variant == "before"}
    for case, m in rows:
        cells = [
            case.recipe, case.variant, f"{m['step_s']:.3f}", f"{m['samples_per_s']:.1f}",
            f"{before[case.recipe]['step_s'] / m['step_s']:.2f}×", f"{m['first_steps_s']:.1f}",
            f"{m['render_s']:.3f}", f"{100 * m['render_s'] / m['step_s']:.0f} %",
            f"{m['generator_s']:.3f}", f"{100 * m['render_s'] / m['generator_s']:.0f} %",
        ]  # fmt: skip
        print("| " + " | ".join(cells) + " |")
    _print_components(rows)
    if not args.no_loader:
        _print_loader()


if __name__ == "__main__":
    main()
