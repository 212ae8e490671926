"""Still preview (``preview.png``) at 256²: seconds before/after the batched renderer, and the error
of the environment tile against a reference for a few sky-light settings.

Speed: the preview's rendering as ``preview_image`` did it before (``relight``, one point light per
renderer call, then ``render_sky`` in chunks of 8, maps decoded per call) against
:func:`~brdfgan.inference.outputs.preview.render_preview_tiles` (the same 4 + 64 lights, maps decoded
once, up to 17 lights per call), the same with the renderer through ``torch.compile`` (not used:
see the first-call column), and the whole ``write_preview`` now. Steady state: median of
``--repeats`` calls, before and after interleaved so both see the same machine load. First call: a
fresh process per run, one call each (what a one-photo ``brdfgan predict`` pays: imports excluded,
first-touch memory included), median over ``--processes`` processes per side. The maps are
:func:`tests.conftest.random_maps` at 256² (the time does not depend on their values).
``--busy N …`` prints one speed table per N, with N other processes running during the timing, each
a two-thread elementwise torch loop (default 0 and 2): the shared-machine case in which a 256²
preview took 11 s (eager torch pays a thread fork-join per elementwise step, and with other jobs on
the cores each can stall for a scheduler slice). The compiled row is timed only without them.

Quality: the environment tile (auto-exposed, 8-bit sRGB, as in ``preview.png``) with 16, 32 and 64
(the default) sky lights, and with 64 lights rendered at 128² and upsampled bilinearly, against a
4×-sample reference (256 lights at 256²), on the map sets of ``tests/inference/outputs/test_preview.py``
(``quality_maps``). RMSE in 8-bit levels; the time is the whole still rendering (4 point lights + the
sky) with that setting, median of ``--repeats``.

    python -m benchmarks.bench_preview [--repeats N] [--processes N] [--busy N ...]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import torch
import torch.nn.functional as F

SIZE = 256
LIGHTS = 4
QUALITY_SETS = ("glossy_metal", "rough_dielectric", "bumpy_glossy", "mixed")
BUSY_LOOP = (
    "import torch\ntorch.set_num_threads(2)\nx = torch.rand(2_000_000)\nwhile True:\n    x.mul_(1.0)\n"
)


def _renderers(size: int = SIZE) -> dict[str, Callable[[], object]]:
    """The timed calls: the preview's rendering before and after, the same through ``torch.compile``,
    and the whole ``write_preview``."""
    from tests.conftest import random_maps

    from brdfgan.core.relight import relight, render_sky
    from brdfgan.core.render import shade_point_lights
    from brdfgan.core.sky import ProceduralSky
    from brdfgan.inference.outputs import preview
    from brdfgan.inference.outputs.preview import PREVIEW_SKY_SAMPLES, preview_lights, render_preview_tiles

    maps, photo = random_maps(size, size, seed=1), torch.rand(3, size, size)
    sky, positions = ProceduralSky(), preview_lights(LIGHTS)
    compiled_shading = torch.compile(shade_point_lights, dynamic=False)

    def before() -> object:
        with torch.no_grad():
            return torch.cat(
                [relight(maps, positions), render_sky(maps, sky, samples=PREVIEW_SKY_SAMPLES)[None]]
            )

    def after() -> object:
        with torch.no_grad():
            return render_preview_tiles(maps, positions, sky, samples=PREVIEW_SKY_SAMPLES)

    def compiled() -> object:
        eager = preview.shade_point_lights
        preview.shade_point_lights = compiled_shading  # timing only, in this throwaway process
        try:
            return after()
        finally:
            preview.shade_point_lights = eager

    def whole() -> object:
        with tempfile.TemporaryDirectory() as tmp:
            return preview.write_preview(Path(tmp) / "preview.png", photo, maps, tile=size)

    return {"before": before, "after": after, "compiled": compiled, "write_preview": whole}


def _child(name: str, repeats: int) -> dict[str, float]:
    """In a fresh process: the first call, then the median of ``repeats`` more."""
    run = _renderers()[name]
    start = time.perf_counter()
    run()
    first = time.perf_counter() - start
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        seconds.append(time.perf_counter() - start)
    return {"first": first, "steady": statistics.median(seconds) if seconds else math.nan}


def _in_fresh_process(name: str, repeats: int, env: dict[str, str] | None = None) -> dict[str, float]:
    command = [sys.executable, "-m", "benchmarks.bench_preview", "--child", name, "--repeats", str(repeats)]
    out = subprocess.run(command, check=True, capture_output=True, text=True, env=env)
    result: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def speed(repeats: int, processes: int, busy: int) -> None:
    """The speed table with ``busy`` other busy processes running; the compiled row only when idle."""
    others = [subprocess.Popen([sys.executable, "-c", BUSY_LOOP]) for _ in range(busy)]
    try:
        _speed(repeats, processes, busy)
    finally:
        for other in others:
            other.kill()
            other.wait()


def _speed(repeats: int, processes: int, busy: int) -> None:
    runs = _renderers()
    before, after = runs["before"](), runs["after"]()
    assert isinstance(before, torch.Tensor) and isinstance(after, torch.Tensor)
    difference = (after - before).abs().amax() / before.abs().amax()
    eager = ("before", "after", "write_preview")
    seconds: dict[str, list[float]] = {name: [] for name in eager}
    for _ in range(repeats):
        for name in eager:
            start = time.perf_counter()
            runs[name]()
            seconds[name].append(time.perf_counter() - start)
    first: dict[str, list[float]] = {name: [] for name in (*eager, "compiled")}
    for _ in range(processes):
        for name in eager:
            first[name].append(_in_fresh_process(name, 0)["first"])
    compiled_steady = []
    for _ in range(processes if not busy else 0):  # a cold compile each time: an empty inductor cache
        with tempfile.TemporaryDirectory() as cache:
            result = _in_fresh_process("compiled", 3, {**os.environ, "TORCHINDUCTOR_CACHE_DIR": cache})
        first["compiled"].append(result["first"])
        compiled_steady.append(result["steady"])
    print(
        f"\nStill preview rendering at {SIZE}², {LIGHTS} point + 64 sky lights, torch {torch.__version__}, "
        f"{torch.get_num_threads()} threads, {busy} busy two-thread processes beside it; steady: median of "
        f"{repeats} (interleaved; compiled: median over processes of a median of 3), first call: median of "
        f"{processes} fresh processes (compiled: cold inductor cache); "
        f"max |after − before| / max |before| = {float(difference):.1e}\n"
    )
    print("| rendering | steady s | first call s | steady speed-up | first-call speed-up |")
    print("|---|---|---|---|---|")
    steady = {name: statistics.median(seconds[name]) for name in eager}
    once = {name: statistics.median(times) for name, times in first.items() if times}
    labels = {
        "before": "before: relight + render_sky",
        "after": "after: render_preview_tiles",
        "write_preview": "write_preview (after, whole PNG)",
    }
    if compiled_steady:
        steady["compiled"] = statistics.median(compiled_steady)
        labels["compiled"] = "render_preview_tiles, torch.compile"
    for name, label in labels.items():
        cells = [
            label,
            f"{steady[name]:.2f}",
            f"{once[name]:.2f}",
            f"{steady['before'] / steady[name]:.2f}×",
            f"{once['before'] / once[name]:.2f}×",
        ]
        print("| " + " | ".join(cells) + " |")


def _environment_tile(hdr: torch.Tensor) -> torch.Tensor:
    from brdfgan.core.exposure import auto_expose
    from brdfgan.core.svbrdf import linear_to_srgb

    ldr, _ = auto_expose(hdr[None])
    return (linear_to_srgb(ldr[0]) * 255.0).round()


def quality(repeats: int) -> None:
    from tests.inference.outputs.test_preview import quality_maps

    from brdfgan.core.sky import ProceduralSky
    from brdfgan.core.svbrdf import resize_maps
    from brdfgan.inference.outputs.preview import PREVIEW_SKY_SAMPLES, preview_lights, render_preview_tiles

    sky, positions = ProceduralSky(), preview_lights(LIGHTS)
    settings: dict[str, tuple[int, int]] = {  # label: (sky lights, internal size)
        "16 lights": (16, SIZE),
        "32 lights": (32, SIZE),
        f"{PREVIEW_SKY_SAMPLES} lights (default)": (PREVIEW_SKY_SAMPLES, SIZE),
        f"{PREVIEW_SKY_SAMPLES} lights at {SIZE // 2}², upsampled": (PREVIEW_SKY_SAMPLES, SIZE // 2),
    }

    def render(maps: torch.Tensor, samples: int, size: int) -> torch.Tensor:
        with torch.no_grad():
            tiles = render_preview_tiles(resize_maps(maps, size), positions, sky, samples=samples)
            if size != SIZE:
                tiles = F.interpolate(tiles, size=(SIZE, SIZE), mode="bilinear", align_corners=False)
        return tiles

    errors: dict[str, dict[str, float]] = {label: {} for label in settings}
    for kind in QUALITY_SETS:
        maps = quality_maps(kind, SIZE)
        reference = _environment_tile(render(maps, 4 * PREVIEW_SKY_SAMPLES, SIZE)[-1])
        for label, (samples, size) in settings.items():
            tile = _environment_tile(render(maps, samples, size)[-1])
            errors[label][kind] = math.sqrt(float(((tile - reference) ** 2).mean()))
    maps = quality_maps("mixed", SIZE)
    seconds = {}
    for label, (samples, size) in settings.items():
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            render(maps, samples, size)
            times.append(time.perf_counter() - start)
        seconds[label] = statistics.median(times)
    print(
        f"\nEnvironment tile: RMSE in 8-bit sRGB levels against {4 * PREVIEW_SKY_SAMPLES} sky lights at "
        f"{SIZE}²; time: the whole still rendering, median of {repeats}; ratios against the default\n"
    )
    default = f"{PREVIEW_SKY_SAMPLES} lights (default)"
    print("| setting | " + " | ".join(QUALITY_SETS) + " | worst error ratio | s | time ratio |")
    print("|---|" + "---|" * (len(QUALITY_SETS) + 3))
    for label in settings:
        worst = max(errors[label][kind] / errors[default][kind] for kind in QUALITY_SETS)
        cells = [label, *(f"{errors[label][kind]:.2f}" for kind in QUALITY_SETS)]
        cells += [f"{worst:.2f}×", f"{seconds[label]:.2f}", f"{seconds[label] / seconds[default]:.2f}×"]
        print("| " + " | ".join(cells) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--processes", type=int, default=3)
    parser.add_argument(
        "--busy", type=int, nargs="+", default=[0, 2], help="speed tables with this many busy processes"
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(_child(args.child, args.repeats)))
        return
    for busy in args.busy:
        speed(args.repeats, args.processes, busy)
    quality(args.repeats)


if __name__ == "__main__":
    main()
