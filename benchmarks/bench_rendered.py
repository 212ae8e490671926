"""On-the-fly training photos (``data=rendered``): where a training step's time goes.

One run, the real pieces: the material bank of ``conf/data/rendered.yaml`` (built first if missing:
minutes), batches of the v4 recipe (4 photos of 256², 128² windows), and per batch

- **draw**: the CPU side (a bank material decoded, cropped, capture and lighting drawn), the scan
  sets already in memory as they are after a run's first minutes;
- **render**: :func:`~brdfgan.data.loading.rendered.photograph_scenes`, eager and compiled;
- **phone + crop**: the sensor and the train crop;
- **v4 step**: the generator's forward, the supervised loss (parameter + rendering) and backward
  and Adam (``experiment=anchored``'s model and loss, its rendering loss compiled);

then the whole step (draw + compiled render + phone + v4 step) and the rendering's share of it,
beside the v4 step alone (what a shard batch costs on top of decoding). Last, what a fresh clone
pays before its first step: painting a bank (the same spec with ``--paint-materials`` materials,
into temporary folders) by one process and by ``--paint-workers`` (``data.bank.paint_workers``).

    python -m benchmarks.bench_rendered [--batches 8] [--paint-materials 120] [--paint-workers 2]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import hydra
import torch

from benchmarks.bench_train import median_seconds
from brdfgan.core.render import render_point_lights
from brdfgan.data.loading.rendered import MaterialBank, RenderedStream, photograph_scenes, scene_tensors
from brdfgan.training.config import register_configs

CONF = Path(__file__).resolve().parents[1] / "conf"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--batches", type=int, default=8)
    parser.add_argument("--paint-materials", type=int, default=120, help="the painting rows' spec size")
    parser.add_argument("--paint-workers", type=int, default=2, help="the parallel painting row's processes")
    args = parser.parse_args()
    register_configs()
    with hydra.initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = hydra.compose(config_name="train", overrides=["experiment=anchored", "data=rendered"])
    module = hydra.utils.instantiate(cfg.data, _convert_="all")
    module.bank.build()
    for which in range(len(module.bank.scan_folders)):  # steady state: a run reads each scan set once
        module.bank.scan_material(which, 1.0, torch.Generator())
    stream = RenderedStream(
        module.bank, batch_size=module.batch_size, batches_per_epoch=args.batches + 2, seed=0,
        environment_lights=module.environment_lights, relief=module.relief,
    )  # fmt: skip
    draws, scenes = [], []
    iterator = iter(stream)
    for _ in range(args.batches + 2):
        start = time.perf_counter()
        scenes.append(next(iterator))
        draws.append(time.perf_counter() - start)
    draw = statistics.median(draws[2:])

    compiled = torch.compile(render_point_lights, dynamic=False)
    with torch.no_grad():
        eager = median_seconds(lambda: photograph_scenes(*scene_tensors(scenes[0])), 3)
        start = time.perf_counter()
        photograph_scenes(*scene_tensors(scenes[0]), compiled)
        compile_seconds = time.perf_counter() - start
        fast = median_seconds(lambda: photograph_scenes(*scene_tensors(scenes[1]), compiled), 5)
    phone = median_seconds(lambda: module.photograph(scenes[2]), 3) - eager  # photograph renders eagerly
    batches = [module.photograph(batch) for batch in scenes[2:]]

    model = hydra.utils.instantiate(
        cfg.model, loss=hydra.utils.instantiate(cfg.loss, _convert_="all"), _convert_="all"
    )
    generator, loss = model.generator, model.loss
    optimizer = torch.optim.Adam(generator.parameters(), lr=2e-4, betas=(0.5, 0.999))

    def step(batch: dict[str, Any]) -> None:
        fake = generator(batch["photo"], batch["flash"])
        total = loss.generator_terms(fake, batch["maps"], None, None)["g_total"]
        optimizer.zero_grad(set_to_none=True)
        total.backward()
        optimizer.step()

    step(batches[0])  # compiles the rendering loss
    steps = []
    for batch in batches[1:]:
        start = time.perf_counter()
        step(batch)
        steps.append(time.perf_counter() - start)
    v4_step = statistics.median(steps)
    whole = draw + fast + phone + v4_step
    rows = [
        ("draw (CPU: bank, crop, capture, lights)", draw),
        ("render, eager", eager),
        (f"render, compiled (compiles once: {compile_seconds:.0f} s)", fast),
        ("phone + train crop", phone),
        ("v4 step (forward, supervised loss, backward, Adam)", v4_step),
        ("whole on-the-fly step (compiled render)", whole),
    ]
    lights = f"windows {module.train_crop}², {module.environment_lights} environment lights + sun + flash"
    print(f"threads {torch.get_num_threads()}, batch {module.batch_size}, {lights}")
    print("| part | ms per batch | share of the whole step |\n| --- | --- | --- |")
    for name, seconds in rows:
        print(f"| {name} | {seconds * 1000:.0f} | {seconds / whole:.0%} |")
    print(f"rendering's share of the whole step: {fast / whole:.0%}; the step against a shard batch's "
          f"v4 step alone: {whole / v4_step:.2f}×")  # fmt: skip
    paint_table(module.bank, args.paint_materials, args.paint_workers)


def paint_table(bank: MaterialBank, materials: int, workers: int) -> None:
    """Time a whole bank build (painting and the environment table) of ``bank``'s spec cut to
    ``materials`` materials, by one process and by ``workers``; one Markdown table."""
    spec = dataclasses.replace(bank.spec, materials=materials)
    seconds = {}
    for count in (1, workers):
        with tempfile.TemporaryDirectory(prefix="bench_bank-") as folder:
            fresh = MaterialBank(spec, folder, bank.environment_resolution, paint_workers=count)
            start = time.perf_counter()
            fresh.build(progress=False)
            seconds[count] = time.perf_counter() - start
    painted = fresh.procedural_count
    print(
        f"\nbank build, {painted} procedural materials at {spec.material_resolution}², the environment table"
    )
    print("| processes | s | materials/s | time ratio |\n| --- | --- | --- | --- |")
    for count, took in seconds.items():
        print(f"| {count} | {took:.1f} | {painted / took:.1f} | {took / seconds[1]:.2f}× |")


if __name__ == "__main__":
    main()
