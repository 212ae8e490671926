"""Generation on a full disk (ENOSPC injected into the writes): every file generate.py writes is
replaced atomically, so a full disk leaves no partial or hidden file, the error names the file,
and a rerun after freeing space finishes with the bytes of an uninterrupted run.

The same on a real tmpfs, and kills of the real command, are ``python -m faults generate``.
"""

from __future__ import annotations

import errno
import pathlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from brdfgan.data.generation.generation import SPEC_FILE, dataset_ready, run_generation
from brdfgan.data.storage.shards import digest_path, shard_path
from brdfgan.errors import DiskFullError
from tests.data.generation.test_generation import shard_hashes, tiny_spec, torch_photographer


class FullAfter:
    """A file object that accepts ``budget`` bytes and then fails like a full disk."""

    def __init__(self, handle: Any, budget: int) -> None:
        self._handle = handle
        self._budget = budget

    def write(self, data: Any) -> int:
        if len(data) > self._budget:
            self._handle.write(data[: self._budget])  # what fitted
            self._budget = 0
            raise OSError(errno.ENOSPC, "No space left on device")
        self._budget -= len(data)
        return self._handle.write(data)

    def __enter__(self) -> FullAfter:
        return self

    def __exit__(self, *exc: object) -> None:
        self._handle.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._handle, name)


def fill_disk_at(monkeypatch: pytest.MonkeyPatch, matches: Callable[[Path], bool], budget: int) -> None:
    """From now on, files whose path ``matches`` may take ``budget`` bytes (0 at open: no room
    for a new file at all, raised on opening)."""
    real_open = pathlib.Path.open

    def open_(self: Path, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        if not matches(self) or not set(mode) & set("wxa+"):
            return real_open(self, mode, *args, **kwargs)
        if budget == 0:
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return FullAfter(real_open(self, mode, *args, **kwargs), budget)

    monkeypatch.setattr(pathlib.Path, "open", open_)


def temp_of(target: Path) -> Callable[[Path], bool]:
    """The hidden temporary file an atomic write of ``target`` goes through."""
    return lambda p: (
        p.parent == target.parent and p.name.startswith(f".{target.name}.") and p.name.endswith(".tmp")
    )


def hidden_files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob(".*") if p.is_file())


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    root = tmp_path_factory.mktemp("clean")
    run_generation(tiny_spec(), root, progress=False, photographer=torch_photographer)
    return shard_hashes(root)


@pytest.mark.parametrize(
    ("target", "budget"),
    [
        (SPEC_FILE, 10),
        ("train/train-000001.tar", 20_000),  # mid-shard, after shard 0 is complete
        ("train/train-000001.tar.sha256", 10),  # the shard is in place, its record is not
        ("val/manifest.json", 100),
        ("test/manifest.json", 0),  # not even room for a new file
    ],
)
def test_a_full_disk_names_the_file_leaves_nothing_partial_and_a_rerun_finishes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, clean: dict[str, str], target: str, budget: int
) -> None:
    spec = tiny_spec()
    with monkeypatch.context() as patch:
        fill_disk_at(patch, temp_of(tmp_path / target), budget)
        with pytest.raises(DiskFullError) as raised:
            run_generation(spec, tmp_path, progress=False, photographer=torch_photographer)
    assert str(raised.value) == f"{tmp_path / target}: no space left on device"
    assert not hidden_files(tmp_path)  # the partial temporary file is gone
    assert not (tmp_path / target).exists()
    if target != SPEC_FILE:
        assert shard_path(tmp_path, "train", 0).exists()  # complete shards stay
    # Space freed: the same command finishes, with the bytes of a run that never failed.
    run_generation(spec, tmp_path, progress=False, photographer=torch_photographer)
    assert shard_hashes(tmp_path) == clean
    assert all(digest_path(tmp_path / name).exists() for name in clean)
    assert dataset_ready(spec, tmp_path) and not hidden_files(tmp_path)


def test_a_disk_too_full_for_the_write_probe_is_a_full_disk_not_a_permission_problem(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out"
    with monkeypatch.context() as patch:
        fill_disk_at(patch, lambda p: p.name.startswith(".write-probe-"), 0)
        with pytest.raises(DiskFullError, match=f"^{out}: no space left on device$"):
            run_generation(tiny_spec(), out, progress=False, photographer=torch_photographer)
    assert not (out / SPEC_FILE).exists()
