"""Atomic file replacement: write beside the target under a hidden temporary name, fsync, rename.

A reader (or a resumed job) sees either the old file or the complete new one, never a partial
one; temporary names start with ``.`` and end with ``.tmp`` so globs for real files skip them.
A full disk while writing removes the temporary file and raises
:class:`~brdfgan.errors.DiskFullError` naming the target, so the caller can report one line.
"""

from __future__ import annotations

import os
import re
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from brdfgan.errors import DiskFullError, is_disk_full

# Hex digits of the random part of a temporary name (temp_path writes it, stale_temp_files reads it).
TEMP_TOKEN_LENGTH = 12


def temp_path(path: Path, *, keep_suffix: bool = False) -> Path:
    """``.<name>.<random>.tmp`` in the target's directory (same filesystem, so rename is atomic);
    ``keep_suffix``: ``.<name>.<random>.tmp.<suffix>``, for writers that pick the format from it."""
    temp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:TEMP_TOKEN_LENGTH]}.tmp")
    return temp.with_name(temp.name + path.suffix) if keep_suffix else temp


def stale_temp_files(path: Path) -> list[Path]:
    """Temporary files of :func:`atomic_replace` for ``path`` that a killed writer left behind.

    Only call this where no other process may be writing ``path`` at the same time (a training
    run's own checkpoints): a live writer's temporary file looks the same.
    """
    pattern = re.compile(rf"^\.{re.escape(path.name)}\.[0-9a-f]{{{TEMP_TOKEN_LENGTH}}}\.tmp$")
    if not path.parent.is_dir():
        return []
    return sorted(p for p in path.parent.iterdir() if pattern.match(p.name) and p.is_file())


@contextmanager
def atomic_replace(path: str | os.PathLike[str], *, keep_suffix: bool = False) -> Iterator[Path]:
    """Yield a fresh temporary path to write; on success it is fsynced and renamed over ``path``
    (and the directory entry fsynced), on any error it is removed and ``path`` is untouched.
    ``keep_suffix``: the temporary name ends with the target's suffix (see :func:`temp_path`)."""
    path = Path(path)
    temp = temp_path(path, keep_suffix=keep_suffix)
    try:
        yield temp
        with temp.open("rb+") as handle:
            os.fsync(handle.fileno())
        # Some writers create their file 0600 (safetensors does); give the result the mode a
        # plain open() would have, so shared outputs and shipped files are readable by others.
        os.chmod(temp, _default_file_mode())
        os.replace(temp, path)
    except BaseException as error:
        temp.unlink(missing_ok=True)
        if is_disk_full(error) and not isinstance(error, DiskFullError):
            raise DiskFullError(path) from error
        raise
    fsync_directory(path.parent)


def _default_file_mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def fsync_directory(directory: Path) -> None:
    """Make a rename in ``directory`` durable (best effort: not every filesystem allows it)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Replace ``path`` with ``text`` (UTF-8) atomically."""
    with atomic_replace(path) as temp:
        temp.write_text(text, encoding="utf-8")
    return Path(path)
