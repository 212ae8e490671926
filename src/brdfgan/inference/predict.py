"""Photo → engine-ready material: the pipeline behind ``brdfgan predict``.

For each photo::

    read_photo (linear RGB, EXIF orientation, colour-space checks)
      → preprocess (square crop on the flash hotspot, linear resize, the training auto exposure)
      → predict_maps (the generator, tiled with frozen normalisation statistics when large)
      → write_material (textures, material.glb, material.json, preview.png [, preview.gif/mp4])

A batch keeps going when one photo fails: :func:`predict_batch` returns what succeeded and, for
each failure, the one-line reason; only a full disk stops it (every later photo would fail the
same way). Before writing it cleans up after killed runs into the same folder
(:func:`~brdfgan.inference.export.recover_outputs`), and while it runs SIGTERM interrupts it like
Ctrl-C, so that the staging folder of the photo in progress is removed
(:func:`brdfgan.errors.interrupts_raise`).
:func:`check_memory` refuses a resolution whose estimated memory exceeds what is available.
"""

from __future__ import annotations

import logging
import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import torch
from torch import nn

from brdfgan.errors import disk_full_message, is_disk_full, one_line
from brdfgan.inference.export import ExportOptions, recover_outputs, write_material
from brdfgan.inference.photo import PHOTO_EXTENSIONS, Colorspace, read_photo
from brdfgan.inference.preprocess import Crop, preprocess
from brdfgan.inference.preview import write_animation, write_preview
from brdfgan.inference.tiling import TilingConfig, activation_bytes_per_pixel, predict_maps, predict_memory
from brdfgan.runs import WeightsError, load_weights

log = logging.getLogger(__name__)

DEFAULT_WEIGHTS = "default.safetensors"
# The resolution a weights file was trained at, when its metadata does not say.
FALLBACK_RESOLUTION = 256
# Peak memory per output pixel outside the network: the resized photo, the maps and the texture
# arrays being encoded. Measured as the growth of peak resident memory per pixel of tiled runs
# (1024² → 2048², --tile 512, shipped weights): 207 B/px writing PNG, 296 B/px writing EXR.
EXPORT_BYTES_PER_PIXEL = 320
# The generator's input, (3, N, N) float32, stays alive while the network runs.
INPUT_BYTES_PER_PIXEL = 12


class PredictError(ValueError):
    """A predict request cannot run at all (no weights, no inputs); one line."""


@dataclass(frozen=True)
class PredictOptions:
    """Everything ``brdfgan predict`` lets the user choose besides inputs and weights."""

    resolution: int | None = None  # None: the resolution the model was trained at
    crop: Crop | None = None  # None: a square centred on the detected flash hotspot
    colorspace: Colorspace | None = None  # None: the file format's default (sRGB for JPEG/PNG)
    export: ExportOptions = field(default_factory=ExportOptions)
    tiling: TilingConfig = field(default_factory=TilingConfig)
    preview: bool = True
    animate: Literal["gif", "mp4"] | None = None


@dataclass(frozen=True)
class Model:
    """A generator ready for inference and what is known about it."""

    generator: nn.Module
    model_id: str
    target: str
    config: dict[str, Any]
    extra: dict[str, Any]
    path: Path

    @property
    def resolution(self) -> int:
        return int(self.extra.get("resolution", FALLBACK_RESOLUTION))


@dataclass(frozen=True)
class PhotoResult:
    photo: Path
    output: Path
    warnings: tuple[str, ...]


@dataclass(frozen=True)
class BatchResult:
    succeeded: list[PhotoResult]
    failed: list[tuple[Path, str]]
    stopped: str | None = None  # why the batch ended before its last photo (a full disk)


def default_weights_path() -> Path:
    """The weights shipped inside the package (``brdfgan/weights/default.safetensors``)."""
    return Path(str(resources.files("brdfgan") / "weights" / DEFAULT_WEIGHTS))


def load_model(path: str | os.PathLike[str] | None = None) -> Model:
    """Load a ``.safetensors`` weights file (default: the shipped one); never unpickles anything."""
    path = Path(path) if path is not None else default_weights_path()
    if path.suffix.lower() != ".safetensors":
        raise WeightsError(
            f"{path}: predict loads .safetensors weights only (a pickle-based file could run code); "
            "convert a training checkpoint with: python -m brdfgan.inference.export_weights RUN_DIR"
        )
    if not path.is_file() and path == default_weights_path():
        raise PredictError(f"{path}: no default weights are installed with this package; pass --weights")
    generator, meta = load_weights(path)
    return Model(
        generator=generator.eval(),
        model_id=str(meta.get("model_id", path.stem)),
        target=str(meta.get("target", "")),
        config=dict(meta.get("config", {})),
        extra=dict(meta.get("extra", {})),
        path=path,
    )


def collect_photos(inputs: Sequence[str | os.PathLike[str]]) -> list[Path]:
    """Photos named on the command line; a directory contributes its photo files (sorted, not
    recursive). A missing path is kept, so that it is reported as a failure of its own."""
    photos: list[Path] = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in PHOTO_EXTENSIONS)
            if not found:
                log.warning(
                    "%s: no photo files (%s) in this directory", path, ", ".join(sorted(PHOTO_EXTENSIONS))
                )
            photos += found
        else:
            photos.append(path)
    return photos


def output_names(photos: Sequence[Path]) -> list[str]:
    """One output folder name per photo: the file stem, made unique within the batch."""
    names: list[str] = []
    taken: set[str] = set()
    for photo in photos:
        base = re.sub(r"[^A-Za-z0-9._-]+", "_", photo.stem).strip("._") or "photo"
        name, counter = base, 2
        while name in taken:
            name, counter = f"{base}-{counter}", counter + 1
        taken.add(name)
        names.append(name)
    return names


def estimate_memory(
    model: Model, resolution: int, tiling: TilingConfig, activation_bytes: float | None = None
) -> int:
    """Peak bytes one photo at ``resolution``² needs beyond what the process holds already: the
    larger of the network phase (input photo plus :func:`~brdfgan.inference.tiling.predict_memory`)
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


def check_memory(model: Model, options: PredictOptions, available: int | None = None) -> None:
    """Raise a one-line :class:`PredictError` when the photos' resolution needs more memory than
    ``available`` (default: :func:`available_memory`), before anything large is allocated.

    The message gives the estimate and a way out: ``--tile`` when the network's untiled pass is
    what does not fit, a smaller ``--resolution`` (the largest that fits) when the full-size maps
    themselves do not.
    """
    available = available_memory() if available is None else available
    if available is None:
        return
    resolution = options.resolution or model.resolution
    activation = activation_bytes_per_pixel(model.generator)
    needed = estimate_memory(model, resolution, options.tiling, activation)
    if needed <= available:
        return
    default = TilingConfig()
    if estimate_memory(model, resolution, default, activation) <= available:
        advice = f"use --tile {default.tile} (tiles keep the network's memory at one {default.tile}² pass)"
    else:
        low, high = 0, resolution  # the largest resolution that fits, by bisection
        while high - low > 1:
            middle = (low + high) // 2
            if estimate_memory(model, middle, options.tiling, activation) <= available:
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


def predict_photo(
    path: Path,
    out_dir: Path,
    model: Model,
    options: PredictOptions,
    *,
    tile_progress: Callable[[int, int], None] | None = None,
) -> PhotoResult:
    """Run the whole pipeline on one photo and write ``out_dir`` (replaced atomically)."""
    photo = read_photo(path, options.colorspace)
    resolution = options.resolution or model.resolution
    prepared = preprocess(photo, resolution, options.crop)
    with torch.inference_mode():
        maps = predict_maps(model.generator, prepared.photo[None], options.tiling, progress=tile_progress)[0]
    tiled = options.tiling.runs_tiled(resolution, resolution)
    warnings = photo.warnings + prepared.warnings
    metadata = {
        "name": out_dir.name,
        "model": {
            "id": model.model_id,
            "class": model.target,
            "config": model.config,
            "weights": model.path.name,
        },
        "input": {
            "file": str(path),
            "source": photo.source,
            "bit_depth": photo.bit_depth,
            "colorspace": photo.colorspace,
            "exif_orientation": photo.orientation,
            "size": [photo.width, photo.height],
        },
        "crop": {
            "x": prepared.crop.x,
            "y": prepared.crop.y,
            "size": prepared.crop.size,
            "chosen": "user" if options.crop is not None else "flash hotspot",
            "hotspot": list(prepared.hotspot) if prepared.hotspot is not None else None,
        },
        "resolution": resolution,
        "resized_from": prepared.resized_from,
        "exposure_scale": prepared.exposure_scale,
        "inference": {
            "tiled": tiled,
            "tile": options.tiling.tile if tiled else None,
            "overlap": options.tiling.overlap if tiled else None,
        },
        "input_statistics": prepared.stats,
        "brdf": "Cook-Torrance GGX (Smith, Schlick) + Burley diffuse, metallic workflow, alpha = roughness^2",
        "warnings": list(warnings),
    }
    extra_files: dict[str, Callable[[Path], Any]] = {}
    if options.preview:
        extra_files["preview.png"] = lambda target: write_preview(target, prepared.photo, maps)
    if options.animate is not None:
        extra_files[f"preview.{options.animate}"] = lambda target: write_animation(target, maps)
    write_material(out_dir, maps, options.export, metadata, extra_files=extra_files)
    return PhotoResult(photo=path, output=out_dir, warnings=warnings)


def predict_batch(
    photos: Sequence[Path],
    out_root: Path,
    model: Model,
    options: PredictOptions,
    *,
    on_result: Callable[[PhotoResult | tuple[Path, str]], None] | None = None,
) -> BatchResult:
    """Predict every photo into ``out_root/<name>/``; a failure is recorded and the batch goes on.

    User errors (unreadable or unsupported files, bad crops, unwritable outputs) are reported
    with their one-line message; anything else with its exception type, so a bug in one photo
    never loses the rest of the batch. A full disk ends the batch: the result then says so in
    ``stopped`` (``<path>: no space left on device``). Hidden folders left by killed runs in
    ``out_root`` are cleaned up first. Interrupts (``KeyboardInterrupt``) propagate; run inside
    :func:`brdfgan.errors.interrupts_raise` to get the same for SIGTERM.
    """
    succeeded: list[PhotoResult] = []
    failed: list[tuple[Path, str]] = []
    names = output_names(photos)
    try:
        recover_outputs(out_root)
    except OSError as error:  # not fatal: the photos may still be writable
        log.warning("%s: cannot clean up after earlier runs (%s)", out_root, error.strerror or error)
    for photo, name in zip(photos, names, strict=True):
        try:
            result: PhotoResult | tuple[Path, str] = predict_photo(photo, out_root / name, model, options)
            succeeded.append(result)
        except (ValueError, OSError) as error:
            if is_disk_full(error):
                message = disk_full_message(error)
                failed.append((photo, message))
                if on_result is not None:
                    on_result((photo, message))
                return BatchResult(succeeded=succeeded, failed=failed, stopped=message)
            message = one_line(error)
            if str(photo) not in message:
                message = f"{photo}: {message}"
            result = (photo, message)
            failed.append(result)
        except Exception as error:  # keep the batch alive and report the bug
            log.debug("internal error on %s", photo, exc_info=True)
            result = (photo, f"{photo}: internal error {type(error).__name__}: {one_line(error)}")
            failed.append(result)
        if on_result is not None:
            on_result(result)
    return BatchResult(succeeded=succeeded, failed=failed)
