"""Short looping animations, written atomically: ``.gif`` (Pillow) or ``.mp4`` (H.264, plays in browsers).

The ``.mp4`` is H.264 High profile, 4:2:0 (``yuv420p``), BT.709-tagged, with the ``moov`` atom
before the media data (``+faststart``), so browsers play it and can start before it has fully
loaded. It is encoded by the static ffmpeg build that the ``imageio-ffmpeg`` wheel ships (or the
one ``IMAGEIO_FFMPEG_EXE`` names); odd frame sizes are padded by one edge row/column because
4:2:0 needs even ones.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import tempfile
from collections.abc import Iterable, Iterator
from fractions import Fraction
from pathlib import Path
from typing import IO

import imageio_ffmpeg
import numpy as np
from PIL import Image

from brdfgan.errors import DiskFullError, UserError
from brdfgan.io.atomic import atomic_replace

VIDEO_SUFFIXES = frozenset({".gif", ".mp4"})

# libx264 constant-rate factor (0 lossless … 51 worst): ~50 dB PSNR on smooth 256² previews.
H264_CRF = 20


class VideoEncodeError(UserError):
    """ffmpeg could not be started or failed to encode the ``.mp4``; the message names the file."""


def write_video(path: str | os.PathLike[str], frames: Iterable[np.ndarray], *, fps: float, size: int) -> Path:
    """Write ``frames`` (each ``(size, size, 3)`` uint8 RGB) as a looping animation at ``fps``.

    Raises:
        ValueError: another suffix, ``fps <= 0``, no frames, or a frame of another shape or dtype.
        VideoEncodeError: ffmpeg could not be started or failed (``.mp4``).
        DiskFullError: the filesystem filled up while writing.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(f"{path}: animation must be one of {sorted(VIDEO_SUFFIXES)}, got {suffix!r}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    checked = _checked_frames(path, frames, size)
    # The temporary name keeps the suffix: Pillow chooses the format from it.
    with atomic_replace(path, keep_suffix=True) as temp:
        if suffix == ".gif":
            _write_gif(temp, checked, fps)
        else:
            _write_mp4(path, temp, checked, fps, size)
    return path


def _checked_frames(path: Path, frames: Iterable[np.ndarray], size: int) -> Iterator[np.ndarray]:
    """``frames``, each checked to be ``(size, size, 3)`` uint8; a ValueError after none at all."""
    count = 0
    for frame in frames:
        if frame.shape != (size, size, 3) or frame.dtype != np.uint8:
            raise ValueError(
                f"{path}: frame {count} must be ({size}, {size}, 3) uint8, got {frame.shape} {frame.dtype}"
            )
        count += 1
        yield frame
    if count == 0:
        raise ValueError(f"{path}: no frames to write")


def _write_gif(temp: Path, frames: Iterable[np.ndarray], fps: float) -> None:
    images = [Image.fromarray(frame) for frame in frames]
    # GIF delays are in centiseconds; Pillow rounds the millisecond duration. Pillow merges
    # consecutive identical frames, which only happens for maps no light changes (e.g. all black).
    images[0].save(
        temp, format="GIF", save_all=True, append_images=images[1:], duration=round(1000.0 / fps), loop=0
    )


def h264_command(ffmpeg: str, output: Path, *, width: int, height: int, fps: float) -> list[str]:
    """The ffmpeg command that reads raw RGB24 frames of ``width``×``height`` (both even) from stdin
    and writes a browser-playable H.264 ``.mp4`` to ``output``."""
    rate = Fraction(fps).limit_denominator(1_000_000)
    return [
        ffmpeg,
        "-hide_banner",
        "-loglevel",
        "error",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-video_size",
        f"{width}x{height}",
        "-framerate",
        f"{rate.numerator}/{rate.denominator}",
        "-i",
        "pipe:0",
        "-an",
        # RGB → limited-range BT.709 YUV (swscale's default matrix would be BT.601, untagged), then
        # 4:2:0: the only chroma layout every browser decodes; tagged BT.709 with the sRGB transfer
        # the frames are encoded with (the tags go into the H.264 VUI and the mp4 colr box).
        "-vf",
        "scale=out_color_matrix=bt709:out_range=tv,format=yuv420p,"
        "setparams=colorspace=bt709:color_primaries=bt709:color_trc=iec61966-2-1:range=tv",
        "-c:v",
        "libx264",
        "-profile:v",
        "high",
        "-preset",
        "slow",
        "-crf",
        str(H264_CRF),
        # Second pass that moves the index (moov) in front of the media data (mdat).
        "-movflags",
        "+faststart",
        "-f",
        "mp4",
        "-y",
        str(output),
    ]


def _even(frame: np.ndarray) -> np.ndarray:
    """``frame`` with its last row/column repeated once where its height/width is odd."""
    height, width = frame.shape[:2]
    if height % 2 == 0 and width % 2 == 0:
        return frame
    return np.pad(frame, ((0, height % 2), (0, width % 2), (0, 0)), mode="edge")


def _ffmpeg_exe(path: Path) -> str:
    try:
        return str(imageio_ffmpeg.get_ffmpeg_exe())
    except RuntimeError as error:  # no bundled binary for this platform and none configured
        raise VideoEncodeError(f"{path}: no ffmpeg to encode H.264 video: {error}") from error


def _ffmpeg_message(log: IO[bytes]) -> str:
    log.seek(0)
    lines = [line.strip() for line in log.read().decode("utf-8", "replace").splitlines() if line.strip()]
    return lines[-1] if lines else "no error message"


def _write_mp4(path: Path, temp: Path, frames: Iterable[np.ndarray], fps: float, size: int) -> None:
    even = size + size % 2
    command = h264_command(_ffmpeg_exe(path), temp, width=even, height=even, fps=fps)
    # ffmpeg's messages go to a file, not a pipe that nobody drains while frames are written.
    with tempfile.TemporaryFile() as log:
        try:
            process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log)
        except OSError as error:
            raise VideoEncodeError(f"{path}: cannot start ffmpeg ({command[0]}): {error}") from error
        assert process.stdin is not None
        try:
            try:
                for frame in frames:
                    process.stdin.write(np.ascontiguousarray(_even(frame)).tobytes())
            except BrokenPipeError:
                pass  # ffmpeg exited early: its exit status and message say why, below
            with contextlib.suppress(BrokenPipeError):
                process.stdin.close()  # end of input: ffmpeg finishes the file
            returncode = process.wait()
        finally:
            if process.poll() is None:  # an error in a frame or Ctrl-C: no file to finish
                process.kill()
                process.wait()
            with contextlib.suppress(OSError):  # unwritten frames left in the buffer: drop them
                process.stdin.close()
        if returncode != 0:
            message = _ffmpeg_message(log)
            if "No space left on device" in message:
                raise DiskFullError(path)
            raise VideoEncodeError(f"{path}: ffmpeg failed to encode H.264 (exit {returncode}): {message}")
