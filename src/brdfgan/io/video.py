"""Short looping animations: ``.gif`` (Pillow) or ``.mp4`` (OpenCV, ``mp4v``), written atomically."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from brdfgan.io.atomic import atomic_replace

VIDEO_SUFFIXES = frozenset({".gif", ".mp4"})


def write_video(path: str | os.PathLike[str], frames: Iterable[np.ndarray], *, fps: float, size: int) -> Path:
    """Write ``frames`` (each ``(size, size, 3)`` uint8 RGB) as a looping animation at ``fps``.

    Raises:
        ValueError: another suffix, ``fps <= 0``, or no mp4v writer in this OpenCV build.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(f"{path}: animation must be one of {sorted(VIDEO_SUFFIXES)}, got {suffix!r}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    # The temporary name keeps the suffix: both writers choose the container from it.
    with atomic_replace(path, keep_suffix=True) as temp:
        if suffix == ".gif":
            _write_gif(temp, frames, fps)
        else:
            _write_mp4(path, temp, frames, fps, size)
    return path


def _write_gif(temp: Path, frames: Iterable[np.ndarray], fps: float) -> None:
    images = [Image.fromarray(frame) for frame in frames]
    # GIF delays are in centiseconds; Pillow rounds the millisecond duration. Pillow merges
    # consecutive identical frames, which only happens for maps no light changes (e.g. all black).
    images[0].save(
        temp, format="GIF", save_all=True, append_images=images[1:], duration=round(1000.0 / fps), loop=0
    )


def _write_mp4(path: Path, temp: Path, frames: Iterable[np.ndarray], fps: float, size: int) -> None:
    # cv2.VideoWriter_fourcc exists at run time but is missing from OpenCV's type stubs.
    fourcc = cv2.VideoWriter_fourcc(*"mp4v")  # type: ignore[attr-defined]
    writer = cv2.VideoWriter(str(temp), fourcc, float(fps), (size, size))
    try:
        if not writer.isOpened():
            raise ValueError(f"{path}: cannot open an mp4v video writer (OpenCV built without FFmpeg?)")
        for frame in frames:
            writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    finally:
        writer.release()
