"""Capture renderer benchmark: reloading the Mitsuba scene per sample vs traverse-update.

Each (resolution, spp) case runs in a fresh subprocess with one renderer per mode: a warm-up
render each (kernel compilation or disk-cache load), then ``--repeats`` renders per mode,
interleaved in alternating order so other load on the machine hits both modes alike, each with
other maps, another environment (rotated, rescaled) and another flash, as dataset generation
does. Reports the median
seconds per ``render()`` call, the parts inside and outside ``mi.render``, and the speed-up of traverse-update
over reload at the same size. A second table times building the environments themselves.

    python -m benchmarks.bench_capture [--repeats N]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time

# (resolution, spp)
CASES: list[tuple[int, int]] = [(256, 64), (512, 196)]
MODES = ("reload", "traverse-update")
ENVIRONMENT_RESOLUTION = 256


def _measure(resolution: int, spp: int, repeats: int) -> dict[str, dict[str, float]]:
    from tests.conftest import random_maps

    from brdfgan.core.render import FlashCapture
    from brdfgan.data.phone.environments import LightingConfig, build_environment_pools, load_environment
    from brdfgan.mitsuba_render.photos import CaptureRenderer

    pools = build_environment_pools(LightingConfig(train_count=4, test_count=2), seed=0)
    environments = [load_environment(spec, ENVIRONMENT_RESOLUTION) for spec in pools.train]
    renderers = {
        mode: CaptureRenderer(resolution, spp, FlashCapture(), ENVIRONMENT_RESOLUTION, reuse_scene=reuse)
        for mode, reuse in zip(MODES, (False, True), strict=True)
    }

    def render(mode: str, index: int) -> tuple[float, float]:
        maps = random_maps(resolution, resolution, seed=index)
        env = environments[index % len(environments)].rotated(0.7 * index).scaled(1.0 + 0.1 * index)
        flash = (1.0 + 0.1 * index, 1.0, 0.9)
        renderer = renderers[mode]
        renderer.render(maps, env.radiance, flash, seed=index, sun=env.sun)
        timing = renderer.last_timing
        assert timing is not None
        return timing.total_s, timing.mi_render_s

    first = {}
    for mode in MODES:
        start = time.perf_counter()
        render(mode, 0)  # kernel compilation (or load from Dr.Jit's disk cache), first scene load
        first[mode] = time.perf_counter() - start
        # Every environment once more untimed, so the reuse path has loaded both emitter sets
        # (with and without sun).
        for index in range(1, len(environments)):
            render(mode, index)
    # Interleaved, alternating order: other load on the machine hits both modes alike.
    timings: dict[str, list[tuple[float, float]]] = {mode: [] for mode in MODES}
    for i in range(repeats):
        for mode in MODES if i % 2 == 0 else MODES[::-1]:
            timings[mode].append(render(mode, len(environments) + i))
    # Medians: a render that another process slowed down moves a mean, hardly a median.
    return {
        mode: {
            "first_s": first[mode],
            "total_s": statistics.median(t for t, _ in values),
            "total_min_s": min(t for t, _ in values),
            "mi_render_s": statistics.median(r for _, r in values),
            "outside_s": statistics.median(t - r for t, r in values),
        }
        for mode, values in timings.items()
    }


def _environment_times() -> list[tuple[str, float]]:
    from brdfgan.data.phone.environments import load_environment as cached
    from brdfgan.data.phone.environments import room_spec, sunsky_spec

    rows = []
    for name, spec in (("sunsky", sunsky_spec(0, 0)), ("room", room_spec(0, 0))):
        start = time.perf_counter()
        cached.__wrapped__(spec, ENVIRONMENT_RESOLUTION)
        rows.append((name, time.perf_counter() - start))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=4)
    parser.add_argument("--case", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        print(json.dumps(_measure(*map(int, args.case.split(",")), args.repeats)))
        return

    rows = []
    for case in CASES:
        command = [sys.executable, "-m", "benchmarks.bench_capture", "--repeats", str(args.repeats)]
        command += ["--case", ",".join(map(str, case))]
        out = subprocess.run(command, check=True, capture_output=True, text=True)
        rows.append((case, json.loads(out.stdout.strip().splitlines()[-1])))

    from brdfgan.mitsuba_render.variant import mitsuba

    mi = mitsuba()
    print(
        f"\nCapture renderer (plane + envmap {2 * ENVIRONMENT_RESOLUTION}×{ENVIRONMENT_RESOLUTION} + sun + "
        f"flash, direct integrator, stratified sampler), Mitsuba {mi.__version__} {mi.variant()}, "
        f"median of {args.repeats} renders after warm-up; speed-up (of the median render() time) "
        "against reload at the same size\n"
    )
    header = ["resolution", "spp", "mode", "first-render-s", "render()-s", "min-s", "mi.render-s"]
    header += ["outside-mi.render-s", "mi.render-share", "speed-up"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for (resolution, spp), modes in rows:
        for mode, m in modes.items():
            base = modes["reload"]
            cells = [
                f"{resolution}²", str(spp), mode, f"{m['first_s']:.2f}",
                f"{m['total_s']:.3f}", f"{m['total_min_s']:.3f}", f"{m['mi_render_s']:.3f}",
                f"{m['outside_s']:.3f}", f"{m['mi_render_s'] / m['total_s']:.0%}",
                f"{base['total_s'] / m['total_s']:.2f}×",
            ]  # fmt: skip
            print("| " + " | ".join(cells) + " |")

    print(f"\nBuilding one environment at {2 * ENVIRONMENT_RESOLUTION}×{ENVIRONMENT_RESOLUTION} (uncached)\n")
    print("| kind | seconds |")
    print("|---|---|")
    for name, seconds in _environment_times():
        print(f"| {name} | {seconds:.2f} |")


if __name__ == "__main__":
    main()
