"""Atomic replacement: complete new file or untouched old one, never a partial file."""

from __future__ import annotations

from pathlib import Path

import pytest

from brdfgan.io.atomic import atomic_replace, write_text_atomic


def test_success_replaces_and_leaves_no_temp(tmp_path: Path) -> None:
    target = tmp_path / "a.json"
    target.write_text("old")
    assert write_text_atomic(target, "new") == target
    assert target.read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]


def test_failure_keeps_the_old_file_and_removes_the_temp(tmp_path: Path) -> None:
    target = tmp_path / "a.json"
    target.write_text("old")
    with pytest.raises(RuntimeError, match="boom"), atomic_replace(target) as temp:
        assert temp.name.startswith(".a.json.") and temp.suffix == ".tmp"
        temp.write_text("half")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]
