"""Test-time refinement benchmark: seconds per photo of ``brdfgan predict --refine`` on this CPU.

Times :func:`brdfgan.inference.refine.refine_maps` with the default settings (one offset per map,
``DEFAULT_REFINE_STEPS`` steps at the 256² working size) on maps of 256² and 1024² — the larger
is fitted at the working size and its correction transferred — and with the ambient light left
out (``ambient=false``). The photo is a flash render of random maps under the capture
model; the start is those maps perturbed. Median of ``--repeats`` runs after one warm-up; the
last column is the time relative to the default at 256², measured in the same run.

    python -m benchmarks.bench_refine [--repeats N]
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch


def _case(size: int, ambient: bool, repeats: int) -> float:
    from tests.conftest import random_maps

    from brdfgan.core.flash_geometry import centred_flash_frame
    from brdfgan.core.render import FlashCapture, render_flash
    from brdfgan.inference.refine import RefineConfig, refine_maps

    truth = random_maps(size, size, seed=1)
    photo = render_flash(truth[None], FlashCapture(fov_deg=57.5))[0].clamp(0, 1)
    start = truth.clone()
    start[6] = (start[6] + 0.2).clamp(0, 1)
    frame = centred_flash_frame(1, size, size, 57.5)
    config = RefineConfig(ambient=ambient)
    seconds = []
    for _ in range(repeats + 1):  # the first is a warm-up
        begin = time.perf_counter()
        refine_maps(photo, start, frame, config)
        seconds.append(time.perf_counter() - begin)
    return statistics.median(seconds[1:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    from brdfgan.inference import DEFAULT_REFINE_STEPS

    cases = [("one offset per map (default)", 256, True), ("one offset per map (default)", 1024, True),
             ("without the ambient light (ambient=false)", 256, False)]  # fmt: skip
    threads = torch.get_num_threads()
    print(f"refinement, {DEFAULT_REFINE_STEPS} steps at the 256² working size, {threads} threads")
    print("| fit | maps | s per photo | vs default 256² |")
    print("|---|---|---|---|")
    reference = None
    for label, size, ambient in cases:
        seconds = _case(size, ambient, args.repeats)
        reference = reference or seconds
        print(f"| {label} | {size}² | {seconds:.2f} | {seconds / reference:.2f}× |", flush=True)


if __name__ == "__main__":
    main()
