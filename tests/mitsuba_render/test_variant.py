from __future__ import annotations

import logging

import pytest

from brdfgan.mitsuba_render import variant as variant_module
from brdfgan.mitsuba_render.variant import MitsubaUnavailableError, find_libllvm, select_variant


def test_find_libllvm_ignores_versions_that_crash_mitsuba(monkeypatch: pytest.MonkeyPatch) -> None:
    files = {
        "/usr/lib/x86_64-linux-gnu/libLLVM-14.so",
        "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1",
        "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
        "/usr/lib/llvm-18/lib/libLLVM.so",
    }
    monkeypatch.setattr(
        variant_module.glob,
        "glob",
        lambda pattern: sorted(f for f in files if f.startswith(pattern.split("*")[0])),
    )
    assert find_libllvm() == "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"
    files.discard("/usr/lib/x86_64-linux-gnu/libLLVM-19.so")
    assert find_libllvm() == "/usr/lib/llvm-18/lib/libLLVM.so"
    files.discard("/usr/lib/llvm-18/lib/libLLVM.so")
    assert find_libllvm() is None


def test_select_variant_picks_and_logs_one(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="brdfgan.mitsuba_render.variant"):
        chosen = select_variant()
    assert chosen in variant_module.VARIANT_PREFERENCE
    assert chosen in caplog.text


def test_unknown_variant_is_a_clear_error() -> None:
    with pytest.raises(MitsubaUnavailableError, match="no_such_variant unavailable"):
        select_variant("no_such_variant")
    select_variant()  # leave the default active for other tests
