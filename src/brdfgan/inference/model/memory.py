"""How much memory one photo needs, checked before any photo is read or anything large allocated."""

from __future__ import annotations

import math
import os
from pathlib import Path

from brdfgan.inference.model.tiling import TilingConfig, activation_bytes_per_pixel, predict_memory
from brdfgan.inference.model.weights import Model, PredictError

# Peak memory per output pixel outside the network: the resized photo, the maps and the texture
# arrays being encoded. Measured as the growth of peak resident memory per pixel of tiled runs
# (1024² → 2048², --tile 512, shipped weights): 207 B/px writing PNG, 296 B/px writing EXR.
EXPORT_BYTES_PER_PIXEL = 320
# The generator's input, (3, N, N) float32, stays alive while the network runs.
INPUT_BYTES_PER_PIXEL = 12


def estimate_memory(
    model: Model, resolution: int, tiling: TilingConfig, activation_bytes: float | None = None
) -> int:
    """Peak bytes one photo at ``resolution``² needs beyond what the process holds already: the
    larger of the network phase (input photo plus :func:`~brdfgan.inference.model.tiling.predict_memory`)
    and the export phase (:data:`EXPORT_BYTES_PER_PIXEL`). The photo file's own decoded size is
    not counted: it does not depend on ``resolution``."""
    if activation_bytes is None:
        activation_bytes = activation_bytes_per_pixel(model.generator)
    pixels = resolution * resolution
    network = INPUT_BYTES_PER_PIXEL * pixels + predict_memory(
        model.generator, resolution, resolution, tiling, activation_bytes
    )
    return max(EXPORT_BYTES_PER_PIXEL * pixels, network)


def available_memory() -> int | None:
    """Bytes this process can still allocate: ``MemAvailable`` (or the free pages where there is
    no ``/proc/meminfo``), capped by a cgroup v2 memory limit. ``None`` when unknown."""
    available: int | None = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                available = int(line.split()[1]) * 1024  # the file says kB and means KiB
    except (OSError, ValueError, IndexError):
        pass
    if available is None:
        try:
            available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            return None
    try:  # a container's limit, which /proc/meminfo does not show
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = Path("/sys/fs/cgroup/memory.current").read_text().strip()
        if limit != "max":
            available = min(available, int(limit) - int(used))
    except (OSError, ValueError):
        pass
    return available


def check_memory(model: Model, resolution: int, tiling: TilingConfig, available: int | None = None) -> None:
    """Raise a one-line :class:`~brdfgan.inference.model.weights.PredictError` when photos at
    ``resolution``² need more memory than ``available`` (default: :func:`available_memory`).

    The message gives the estimate and a way out: ``--tile`` when the network's untiled pass is
    what does not fit, a smaller ``--resolution`` (the largest that fits) when the full-size maps
    themselves do not.
    """
    available = available_memory() if available is None else available
    if available is None:
        return
    activation = activation_bytes_per_pixel(model.generator)
    needed = estimate_memory(model, resolution, tiling, activation)
    if needed <= available:
        return
    default = TilingConfig()
    if estimate_memory(model, resolution, default, activation) <= available:
        advice = f"use --tile {default.tile} (tiles keep the network's memory at one {default.tile}² pass)"
    else:
        low, high = 0, resolution  # the largest resolution that fits, by bisection
        while high - low > 1:
            middle = (low + high) // 2
            if estimate_memory(model, middle, tiling, activation) <= available:
                low = middle
            else:
                high = middle
        fits = low // 64 * 64 if low >= 64 else low
        advice = f"use a smaller --resolution (at most about {fits})" if fits else "not enough memory"
    raise PredictError(
        f"--resolution {resolution} needs ~{_gib(needed)} GiB of memory, {_gib(available)} GiB are "
        f"available; {advice}"
    )


def _gib(size: int) -> str:
    gib = size / 2**30
    return f"{gib:.1f}" if gib < 10 else f"{math.ceil(gib)}"
