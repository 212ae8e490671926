"""brdfgan.io.video: the ``.mp4`` is browser-playable H.264 (High, yuv420p, BT.709, faststart)."""

from __future__ import annotations

import struct
import subprocess
from collections.abc import Iterator
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest

from brdfgan.errors import DiskFullError, UserError
from brdfgan.io import video
from brdfgan.io.video import VideoEncodeError, write_video

BACKGROUND = (40, 90, 160)
SQUARE = (250, 240, 30)


def moving_square(frames: int, size: int) -> list[np.ndarray]:
    """A bright square crossing a flat background, one step per frame."""
    side = max(size // 4, 2)
    out = []
    for k in range(frames):
        frame = np.empty((size, size, 3), np.uint8)
        frame[:] = BACKGROUND
        x = round(k * (size - side) / max(frames - 1, 1))
        frame[size // 2 - side // 2 : size // 2 + side // 2, x : x + side] = SQUARE
        out.append(frame)
    return out


def probe(path: Path) -> str:
    """ffmpeg's description of the file (what ffprobe would print), from ``ffmpeg -i``."""
    result = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    return result.stderr


def decode(path: Path) -> tuple[dict[str, object], list[np.ndarray]]:
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    width, height = meta["size"]
    return meta, [np.frombuffer(data, np.uint8).reshape(height, width, 3) for data in reader]


def top_level_boxes(path: Path) -> list[bytes]:
    """The types of the mp4's top-level boxes, in file order."""
    data = path.read_bytes()
    types, offset = [], 0
    while offset + 8 <= len(data):
        size, kind = struct.unpack(">I4s", data[offset : offset + 8])
        if size == 1:  # 64-bit size follows the type
            size = struct.unpack(">Q", data[offset + 8 : offset + 16])[0]
        elif size == 0:  # box runs to the end of the file
            size = len(data) - offset
        assert size >= 8, f"corrupt box {kind!r} at {offset}"
        types.append(kind)
        offset += size
    assert offset == len(data)
    return types


def fake_ffmpeg(directory: Path, message: str) -> Path:
    """An "ffmpeg" that reads nothing, prints ``message`` to stderr and exits 1."""
    directory.mkdir()
    script = directory / "ffmpeg"
    script.write_text(f"#!/bin/sh\necho '{message}' >&2\nexit 1\n")
    script.chmod(0o755)
    return script


def test_mp4_is_browser_playable_h264(tmp_path: Path) -> None:
    frames = moving_square(12, 64)
    path = write_video(tmp_path / "turn.mp4", iter(frames), fps=12, size=64)
    assert path == tmp_path / "turn.mp4"
    assert [p.name for p in tmp_path.iterdir()] == ["turn.mp4"]  # no temporary file left

    info = probe(path)
    assert "Video: h264 (High)" in info, info
    assert "yuv420p(tv, bt709/bt709/iec61966-2-1" in info, info
    assert "64x64" in info, info

    boxes = top_level_boxes(path)
    assert boxes.index(b"moov") < boxes.index(b"mdat"), boxes  # +faststart: index before data
    assert imageio_ffmpeg.count_frames_and_secs(str(path)) == (12, 1.0)

    meta, decoded = decode(path)
    assert meta["codec"] == "h264"
    assert len(decoded) == 12
    for written, read in zip(frames, decoded, strict=True):
        assert read.shape == written.shape
        error = np.abs(read.astype(np.int16) - written)
        assert error.mean() < 3.0  # lossy, and 4:2:0 blurs colour at the square's edges
        # Away from edges the colours survive the RGB → BT.709 YUV → RGB round trip.
        assert np.abs(read[2, 2].astype(np.int16) - BACKGROUND).max() <= 4
    centre = decoded[0][32, 8].astype(np.int16)
    assert np.abs(centre - SQUARE).max() <= 6


@pytest.mark.parametrize("size", [33, 1])
def test_mp4_odd_size_is_padded_to_even(tmp_path: Path, size: int) -> None:
    frames = moving_square(5, size)
    path = write_video(tmp_path / "odd.mp4", iter(frames), fps=10, size=size)
    even = size + 1
    assert f"{even}x{even}" in probe(path)
    _, decoded = decode(path)
    assert len(decoded) == 5
    for written, read in zip(frames, decoded, strict=True):
        assert read.shape == (even, even, 3)
        assert np.abs(read[:size, :size].astype(np.int16) - written).mean() < 4.0
        # The extra row and column repeat the edge, not a black bar.
        assert np.abs(read[size, :size].astype(np.int16) - written[size - 1]).mean() < 6.0
        assert np.abs(read[:size, size].astype(np.int16) - written[:, size - 1]).mean() < 6.0


def test_mp4_frame_rate_is_kept(tmp_path: Path) -> None:
    path = write_video(tmp_path / "slow.mp4", iter(moving_square(15, 16)), fps=7.5, size=16)
    assert imageio_ffmpeg.count_frames_and_secs(str(path)) == (15, 2.0)


def test_mp4_ffmpeg_failure_is_one_line_user_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fake = fake_ffmpeg(tmp_path / "bin", "Unknown encoder libx264")
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(fake))
    out = tmp_path / "out"
    out.mkdir()
    # Bigger than a pipe buffer: the writer meets the closed pipe and still reports ffmpeg's error.
    frames = moving_square(20, 128)
    with pytest.raises(VideoEncodeError) as caught:
        write_video(out / "turn.mp4", iter(frames), fps=12, size=128)
    assert isinstance(caught.value, UserError)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"{out / 'turn.mp4'}: ffmpeg failed to encode H.264 (exit 1)")
    assert message.endswith("Unknown encoder libx264")
    assert list(out.iterdir()) == []


def test_mp4_without_ffmpeg_is_user_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(tmp_path / "missing" / "ffmpeg"))
    with pytest.raises(VideoEncodeError, match=r"turn\.mp4: cannot start ffmpeg"):
        write_video(tmp_path / "turn.mp4", iter(moving_square(2, 8)), fps=12, size=8)

    def no_binary() -> str:
        raise RuntimeError("No ffmpeg exe could be found.")

    monkeypatch.setattr(video.imageio_ffmpeg, "get_ffmpeg_exe", no_binary)
    with pytest.raises(VideoEncodeError, match=r"turn\.mp4: no ffmpeg to encode H\.264 video"):
        write_video(tmp_path / "turn.mp4", iter(moving_square(2, 8)), fps=12, size=8)
    assert list(tmp_path.iterdir()) == []


def test_mp4_full_disk_is_disk_full_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fake = fake_ffmpeg(tmp_path / "bin", "Error writing trailer: No space left on device")
    monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(fake))
    target = tmp_path / "turn.mp4"
    with pytest.raises(DiskFullError, match=r"turn\.mp4: no space left on device"):
        write_video(target, iter(moving_square(2, 8)), fps=12, size=8)
    assert not target.exists()


def test_mp4_bug_in_frames_keeps_its_traceback_and_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "turn.mp4"
    target.write_bytes(b"old")

    def broken() -> Iterator[np.ndarray]:
        yield from moving_square(2, 16)
        raise RuntimeError("bug while rendering frame 2")

    with pytest.raises(RuntimeError, match="bug while rendering frame 2"):
        write_video(target, broken(), fps=12, size=16)
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["turn.mp4"]


@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_bad_frames_are_rejected(tmp_path: Path, suffix: str) -> None:
    with pytest.raises(ValueError, match=r"frame 1 must be \(8, 8, 3\) uint8, got \(8, 9, 3\) uint8"):
        write_video(
            tmp_path / f"turn{suffix}",
            iter([np.zeros((8, 8, 3), np.uint8), np.zeros((8, 9, 3), np.uint8)]),
            fps=12,
            size=8,
        )
    with pytest.raises(ValueError, match=r"frame 0 must be .* float32"):
        write_video(tmp_path / f"turn{suffix}", iter([np.zeros((8, 8, 3), np.float32)]), fps=12, size=8)
    with pytest.raises(ValueError, match="no frames to write"):
        write_video(tmp_path / f"turn{suffix}", iter([]), fps=12, size=8)
    assert list(tmp_path.iterdir()) == []


def test_gif_is_still_written(tmp_path: Path) -> None:
    from PIL import Image

    path = write_video(tmp_path / "turn.gif", iter(moving_square(4, 16)), fps=10, size=16)
    with Image.open(path) as image:
        assert image.format == "GIF"
        assert image.n_frames == 4
        assert image.info["duration"] == 100
