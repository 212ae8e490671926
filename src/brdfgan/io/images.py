"""Low-level image file IO: PNG/JPEG through OpenCV, EXR through OpenEXR.

Arrays are ``float32`` of shape ``(H, W, C)`` with ``C`` in ``{1, 3, 4}`` and channels in RGB(A)
order. Integer formats are normalised to ``[0, 1]`` (8-bit ``/ 255``, 16-bit ``/ 65535``); EXR
values are returned as stored. No colour-space conversion happens here: what is in the file is
what you get (see :mod:`brdfgan.io.maps` for the per-map conventions).

Writes are atomic: the image is written to a hidden temporary file in the target directory and
moved over the target with :func:`os.replace`, so a reader never sees a half-written file and a
failed write leaves any existing file untouched. A full disk raises
:class:`~brdfgan.errors.DiskFullError` naming the target.

OpenEXR's C++ library prints its own messages (e.g. "Warning: Exception raised reading pixel data
..." on stdout, the chunk error on stderr) on a corrupt file. ``brdfgan predict``'s stdout is the
list of output folders, so reads capture both file descriptors: on failure the library's first
line becomes part of the one-line :class:`ImageIOError`, on success anything it said goes to stderr.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import io
import os
import sys
import tempfile
import threading
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
import OpenEXR

from brdfgan.errors import DiskFullError, UserError, is_disk_full

__all__ = [
    "EXR_EXTENSIONS",
    "PNG_EXTENSIONS",
    "READ_EXTENSIONS",
    "WRITE_EXTENSIONS",
    "ImageIOError",
    "read_image",
    "write_image",
]

PNG_EXTENSIONS = frozenset({".png"})
JPEG_EXTENSIONS = frozenset({".jpg", ".jpeg"})
EXR_EXTENSIONS = frozenset({".exr"})
READ_EXTENSIONS = PNG_EXTENSIONS | JPEG_EXTENSIONS | EXR_EXTENSIONS
WRITE_EXTENSIONS = PNG_EXTENSIONS | EXR_EXTENSIONS

BitDepth = Literal[8, 16]
ExrPrecision = Literal["half", "float"]

_INTEGER_SCALE: dict[np.dtype, float] = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}


class ImageIOError(UserError):
    """An image file cannot be read or written; the message names the file."""


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a PNG, JPEG or EXR file.

    Integer images are scaled to ``[0, 1]``; EXR values are returned raw (no clipping).
    A grayscale file gives ``C = 1``; grayscale + alpha gives ``C = 4`` (gray replicated to RGB).

    Shape:
        - output: ``(H, W, C)`` float32, ``C`` in ``{1, 3, 4}``, RGB(A) channel order
    """
    path = Path(path)
    ext = _extension(path, READ_EXTENSIONS, "read")
    if not path.exists():
        raise ImageIOError(f"{path}: file not found")
    if not path.is_file():
        raise ImageIOError(f"{path}: not a regular file")
    image = _read_exr(path) if ext in EXR_EXTENSIONS else _read_cv2(path)
    if image.shape[0] == 0 or image.shape[1] == 0:
        raise ImageIOError(f"{path}: image is empty, shape {image.shape}")
    return image


def write_image(
    path: str | os.PathLike[str],
    array: np.ndarray,
    *,
    bit_depth: BitDepth = 8,
    exr_precision: ExrPrecision = "half",
) -> Path:
    """Write ``array`` atomically as PNG (8/16-bit, clipped to ``[0, 1]``) or EXR (half/float, raw).

    ``bit_depth`` applies to PNG and ``exr_precision`` to EXR; both are validated whatever the
    format so that a typo never passes silently. The parent directory must exist.

    Shape:
        - array: ``(H, W)`` or ``(H, W, C)`` floating point, ``C`` in ``{1, 3, 4}``, RGB(A) order
    Returns:
        The path written.
    """
    path = Path(path)
    ext = _extension(path, WRITE_EXTENSIONS, "write")
    if bit_depth not in (8, 16):
        raise ImageIOError(f"{path}: unsupported bit depth {bit_depth!r}, expected 8 or 16")
    if exr_precision not in ("half", "float"):
        raise ImageIOError(f"{path}: unsupported EXR precision {exr_precision!r}, expected 'half' or 'float'")
    image = _check_array(path, array)
    if not path.parent.is_dir():
        raise ImageIOError(f"{path}: parent directory does not exist")

    # The real extension stays last so that any tool inspecting the temp file sees its format.
    temp = path.with_name(f".{path.stem}.tmp-{uuid.uuid4().hex[:12]}{path.suffix}")
    try:
        if ext in EXR_EXTENSIONS:
            _write_exr(path, temp, image, exr_precision)
        else:
            _write_png(path, temp, image, bit_depth)
        os.replace(temp, path)
    except BaseException as error:
        temp.unlink(missing_ok=True)
        if is_disk_full(error):
            raise DiskFullError(path) from error
        if isinstance(error, OSError):
            raise ImageIOError(f"{path}: cannot write file ({error.strerror or error})") from error
        raise
    return path


def _extension(path: Path, allowed: frozenset[str], action: str) -> str:
    ext = path.suffix.lower()
    if ext not in allowed:
        raise ImageIOError(
            f"{path}: unsupported extension {path.suffix or '(none)'!r} to {action}, "
            f"expected one of {', '.join(sorted(allowed))}"
        )
    return ext


def _read_cv2(path: Path) -> np.ndarray:
    # imdecode on bytes we read ourselves avoids OpenCV's silent None on missing files and its
    # trouble with non-ASCII paths on some platforms.
    try:
        data = np.fromfile(path, dtype=np.uint8)
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    except OSError as error:
        raise ImageIOError(f"{path}: cannot read file ({error.strerror or error})") from error
    except cv2.error as error:
        raise ImageIOError(f"{path}: corrupt or unreadable image") from error
    if image is None:
        raise ImageIOError(f"{path}: corrupt or unreadable image")
    scale = _INTEGER_SCALE.get(image.dtype)
    if scale is None:
        raise ImageIOError(f"{path}: unsupported sample type {image.dtype}, expected 8- or 16-bit integers")
    if image.ndim == 2:
        image = image[:, :, None]
    elif image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    elif image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA)
    else:
        raise ImageIOError(f"{path}: unsupported channel count {image.shape[2]}")
    return image.astype(np.float32) / np.float32(scale)


_CAPTURE_LOCK = threading.Lock()


@contextlib.contextmanager
def captured_native_output(lines: list[str]) -> Iterator[None]:
    """Capture what a native library prints inside the block, at both levels it can print at.

    C/C++ code writes to file descriptors 1 and 2, which Python-level redirection does not reach,
    so the descriptors themselves are pointed at a temporary file; pybind11 modules print through
    ``sys.stdout``/``sys.stderr``, which are swapped for a buffer (OpenEXR's "Warning: Exception
    raised reading pixel data" comes that way). ``lines`` receives the captured lines (stripped,
    non-empty) when the block ends, also when it raises. The descriptors and ``sys.stdout`` belong
    to the whole process, so captures are serialised (two threads restoring each other's
    descriptors would leave fd 1 on a deleted file); what another thread prints meanwhile is
    captured too.
    """
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):  # a replaced or closed stream has nothing to flush
            stream.flush()
    python_level = io.StringIO()
    with _CAPTURE_LOCK, tempfile.TemporaryFile() as sink:
        saved = os.dup(1), os.dup(2)
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            with contextlib.redirect_stdout(python_level), contextlib.redirect_stderr(python_level):
                yield
        finally:
            # C stdio (and C++ std::cout, synchronised with it) buffers output to a file: flush
            # it into the sink now, or it would surface on the real stdout later.
            _libc_fflush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            sink.seek(0)
            text = sink.read().decode("utf-8", "replace") + python_level.getvalue()
            lines += [line.strip() for line in text.splitlines() if line.strip()]


def _libc_fflush() -> None:
    with contextlib.suppress(OSError, AttributeError):  # no C library: nothing buffered there either
        ctypes.CDLL(None).fflush(None)


def _read_exr(path: Path) -> np.ndarray:
    library_output: list[str] = []
    try:
        with captured_native_output(library_output), OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: channel.pixels for name, channel in exr.channels().items()}
    except (RuntimeError, OSError, ValueError) as error:
        detail = _exr_detail(path, library_output) or " ".join(str(error).split())
        raise ImageIOError(f"{path}: corrupt or unreadable EXR file: {detail}") from error
    for line in library_output:  # a successful read that still had something to say
        print(f"OpenEXR: {line}", file=sys.stderr)
    names = set(channels)
    if {"R", "G", "B"} <= names:
        order = ["R", "G", "B", "A"] if "A" in names else ["R", "G", "B"]
    elif "Y" in names:
        order = ["Y", "Y", "Y", "A"] if "A" in names else ["Y"]
    elif len(names) == 1:
        order = list(names)
    else:
        raise ImageIOError(
            f"{path}: unsupported EXR channel set {sorted(names)}, expected RGB, RGBA, Y or one channel"
        )
    planes = [channels[name] for name in order]
    if any(plane.ndim != 2 or plane.shape != planes[0].shape for plane in planes):
        raise ImageIOError(f"{path}: EXR channels have different sizes (subsampled channels unsupported)")
    return np.stack(planes, axis=-1).astype(np.float32)


def _exr_detail(path: Path, library_output: list[str]) -> str:
    """The library's most specific line: its error (which repeats the path) rather than its warning."""
    specific = [line for line in library_output if not line.startswith("Warning:")] or library_output
    return specific[0].removeprefix(f"{path}: ").removeprefix(f"{path}:").strip() if specific else ""


def _check_array(path: Path, array: np.ndarray) -> np.ndarray:
    if not isinstance(array, np.ndarray):
        raise ImageIOError(f"{path}: expected a numpy array, got {type(array).__name__}")
    if not np.issubdtype(array.dtype, np.floating):
        # Integer input is ambiguous (0..255 or 0..1?), so the caller must normalise explicitly.
        raise ImageIOError(
            f"{path}: expected a floating-point array with values in [0, 1], got {array.dtype}"
        )
    image = array[:, :, None] if array.ndim == 2 else array
    if image.ndim != 3 or image.shape[2] not in (1, 3, 4):
        raise ImageIOError(f"{path}: expected shape (H, W) or (H, W, C) with C in 1, 3, 4, got {array.shape}")
    if image.shape[0] == 0 or image.shape[1] == 0:
        raise ImageIOError(f"{path}: cannot write an empty image of shape {array.shape}")
    if np.isnan(image).any():
        raise ImageIOError(f"{path}: refusing to write data containing NaN")
    return image


def png_bytes(image: np.ndarray, bit_depth: BitDepth = 8) -> bytes:
    """A PNG file's bytes of ``image``'s values in ``[0, 1]`` (clipped; RGB(A) order in, as PNG
    stores it), quantised to ``bit_depth``. OpenCV releases the GIL while it encodes, so several
    images encode in parallel on threads.

    Shape:
        - image: ``(H, W)`` or ``(H, W, C)``, ``C`` in ``{1, 3, 4}``
    """
    unit = np.clip(image.astype(np.float64), 0.0, 1.0)
    quantised = (np.rint(unit * 255.0).astype(np.uint8) if bit_depth == 8 else
                 np.rint(unit * 65535.0).astype(np.uint16))  # fmt: skip
    channels = quantised.shape[2] if quantised.ndim == 3 else 1
    stored: np.ndarray = quantised
    if channels == 3:
        stored = cv2.cvtColor(quantised, cv2.COLOR_RGB2BGR)
    elif channels == 4:
        stored = cv2.cvtColor(quantised, cv2.COLOR_RGBA2BGRA)
    ok, encoded = cv2.imencode(".png", stored)
    if not ok:
        raise ImageIOError("PNG encoding failed")
    return encoded.tobytes()


def _write_png(path: Path, temp: Path, image: np.ndarray, bit_depth: BitDepth) -> None:
    if not np.isfinite(image).all():
        raise ImageIOError(f"{path}: refusing to write infinite values to PNG")
    try:
        encoded = png_bytes(image, bit_depth)
    except ImageIOError:
        raise ImageIOError(f"{path}: PNG encoding failed") from None
    # O_EXCL: never clobber a file of the same name; mode 0o666 lets the umask decide permissions
    # (mkstemp would force 0o600 onto the final file).
    fd = os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    with os.fdopen(fd, "wb") as handle:
        handle.write(encoded)


def _write_exr(path: Path, temp: Path, image: np.ndarray, precision: str) -> None:
    with np.errstate(over="ignore"):  # overflow is detected and reported just below
        stored = image.astype(np.float16 if precision == "half" else np.float32)
    # Finite input that rounds to inf would silently corrupt the file.
    if (np.isfinite(image) & ~np.isfinite(stored)).any():
        raise ImageIOError(f"{path}: values exceed the {precision}-float range")
    names = {1: ["Y"], 3: ["R", "G", "B"], 4: ["R", "G", "B", "A"]}[image.shape[2]]
    channels = {name: np.ascontiguousarray(stored[:, :, i]) for i, name in enumerate(names)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    try:
        with OpenEXR.File(header, channels) as exr:
            exr.write(str(temp))
    except (RuntimeError, ValueError) as error:
        # OpenEXR reports a failed write(2) as a RuntimeError carrying only the strerror text.
        if os.strerror(errno.ENOSPC) in str(error) or os.strerror(errno.EDQUOT) in str(error):
            raise DiskFullError(path) from error
        raise ImageIOError(f"{path}: EXR write failed ({error})") from error
