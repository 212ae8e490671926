"""Renderer forward+backward benchmark: the rendering-loss workload of one training step.

Modes: ``direct`` is the renderer before issue 16 (full ``(B, V, 3, H, W)`` vector fields, kept in
``tests/core/render_reference.py``), ``eager`` the library's factored renderer, ``compiled`` the same
through ``torch.compile``.

Each case runs in a fresh subprocess so its peak resident memory is its own (CPU); on CUDA the
peak comes from the allocator. Prints a Markdown table; ratios are relative to the direct row of the
same size.

    python -m benchmarks.bench_renderer [--device cpu|cuda] [--repeats N]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from functools import partial
from typing import Any

import torch

MODES = ("direct", "eager", "compiled")
# (resolution, batch, configurations, mode index)
CASES: list[tuple[int, int, int, int]] = [(r, 8, 10, m) for r in (256, 512) for m in range(len(MODES))]


def _measure(
    resolution: int, batch: int, configs: int, mode: int, device: str, repeats: int
) -> dict[str, float]:
    from tests.conftest import random_maps
    from tests.core.render_reference import render_point_lights_direct

    from brdfgan.core.render import PointLightRenderer
    from brdfgan.core.sampling import RenderingLossSampling, log_transform, sample_rendering_loss_configs

    torch.manual_seed(0)
    maps = random_maps(resolution, resolution, batch=(batch,)).to(device)
    target = random_maps(resolution, resolution, batch=(batch,), seed=1).to(device)
    sampling = RenderingLossSampling(random_configs=configs // 2, specular_configs=configs - configs // 2)
    scene = sample_rendering_loss_configs(
        batch, sampling, generator=torch.Generator().manual_seed(0), device=device
    )

    renderer: Any = PointLightRenderer(compile=MODES[mode] == "compiled")
    if MODES[mode] == "direct":
        renderer = partial(render_point_lights_direct, plane_half_size=1.0)

    def sync() -> None:
        if device == "cuda":
            torch.cuda.synchronize()

    def step(backward: bool) -> float:
        prediction = maps.clone().requires_grad_(backward)
        sync()
        start = time.perf_counter()
        with torch.set_grad_enabled(backward):
            rendered = log_transform(renderer(prediction, scene.camera_position, scene.lights))
            with torch.no_grad():
                reference = log_transform(renderer(target, scene.camera_position, scene.lights))
            loss = (rendered - reference).abs().mean()
            if backward:
                loss.backward()
        sync()
        return time.perf_counter() - start

    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    warmup = time.perf_counter()
    step(True)  # warm-up (and compilation)
    warmup = time.perf_counter() - warmup
    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    forward = min(step(False) for _ in range(repeats))
    both = min(step(True) for _ in range(repeats))
    if device == "cuda":
        peak = torch.cuda.max_memory_allocated() / 2**30
    else:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20 - rss_before
    return {"forward_s": forward, "forward_backward_s": both, "peak_gib": peak, "first_step_s": warmup}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--case", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        print(json.dumps(_measure(*map(int, args.case.split(",")), args.device, args.repeats)))
        return

    rows = []
    for case in CASES:
        command = [sys.executable, "-m", "benchmarks.bench_renderer", "--device", args.device]
        command += ["--repeats", str(args.repeats), "--case", ",".join(map(str, case))]
        out = subprocess.run(command, check=True, capture_output=True, text=True)
        rows.append((case, json.loads(out.stdout.strip().splitlines()[-1])))

    print(
        f"\nRenderer forward+backward (rendering loss: prediction + no-grad target), device={args.device}, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, best of {args.repeats}; "
        "ratios against the direct (before) row of the same size\n"
    )
    header = "resolution batch configs mode first-step-s forward-s fwd+bwd-s peak-GiB speed-up memory"
    header += " Mpix-renders/s"
    print("| " + " | ".join(header.split()) + " |")
    print("|" + "---|" * len(header.split()))
    direct = {case[0]: m for case, m in rows if MODES[case[3]] == "direct"}
    for (resolution, batch, configs, mode), m in rows:
        base = direct[resolution]
        mpix = resolution * resolution * batch * configs / 1e6
        cells = [
            f"{resolution}²", str(batch), str(configs), MODES[mode],
            f"{m['first_step_s']:.1f}", f"{m['forward_s']:.3f}", f"{m['forward_backward_s']:.3f}",
            f"{m['peak_gib']:.2f}", f"{base['forward_backward_s'] / m['forward_backward_s']:.2f}×",
            f"{m['peak_gib'] / base['peak_gib']:.2f}×", f"{mpix / m['forward_backward_s']:.1f}",
        ]  # fmt: skip
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
