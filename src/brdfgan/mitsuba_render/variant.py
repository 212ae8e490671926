"""Choosing and activating a Mitsuba variant: cuda_ad_rgb → llvm_ad_rgb → scalar_rgb.

Dr.Jit's LLVM backend loads ``libLLVM`` at import time. With Debian's default LLVM 14–16 the
``llvm_ad_rgb`` variant aborts the process ("Cannot select … fminimum",
docs/conventions.md#mitsuba-variant), so unless the user already set ``DRJIT_LIBLLVM_PATH`` we look
for LLVM ≥ 17 and fall back to ``scalar_rgb`` when there is none rather than risk a hard crash.
"""

from __future__ import annotations

import glob
import logging
import os
import re
import sys
from types import ModuleType

log = logging.getLogger(__name__)

VARIANT_PREFERENCE: tuple[str, ...] = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")
MIN_LLVM_MAJOR = 17
_LLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM-*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM-*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM-*.so*",
)


class MitsubaUnavailableError(RuntimeError):
    """No requested Mitsuba variant can run on this machine."""


def find_libllvm(min_major: int = MIN_LLVM_MAJOR) -> str | None:
    """Path of the newest installed ``libLLVM`` with major version ≥ ``min_major``, or None."""
    best: tuple[int, str] | None = None
    for pattern in _LLVM_GLOBS:
        for path in glob.glob(pattern):
            match = re.search(r"(?:libLLVM-|llvm-)(\d+)", path)
            if match and int(match.group(1)) >= min_major and (best is None or int(match.group(1)) > best[0]):
                best = (int(match.group(1)), path)
    return best[1] if best else None


def configure_llvm_path() -> str | None:
    """Set ``DRJIT_LIBLLVM_PATH`` to a usable LLVM unless already set; return the path in use."""
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return os.environ["DRJIT_LIBLLVM_PATH"]
    if "drjit" in sys.modules:
        return None  # too late to influence which library Dr.Jit loaded
    path = find_libllvm()
    if path is not None:
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    return path


def _variant_runs(variant: str, llvm_path: str | None) -> bool:
    import drjit as dr

    if variant.startswith("cuda"):
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    if variant.startswith("llvm"):
        return llvm_path is not None and bool(dr.has_backend(dr.JitBackend.LLVM))
    return True


def select_variant(preferred: str | None = None) -> str:
    """Activate and return the first Mitsuba variant that runs here.

    Args:
        preferred: a variant name to use, or ``None``/"auto" for cuda_ad_rgb → llvm_ad_rgb →
            scalar_rgb.

    Raises:
        MitsubaUnavailableError: the preferred variant (or every fallback) cannot run.
    """
    llvm_path = configure_llvm_path()
    import mitsuba as mi

    candidates = VARIANT_PREFERENCE if preferred in (None, "auto") else (preferred,)
    for variant in candidates:
        if variant in mi.variants() and _variant_runs(variant, llvm_path):
            if mi.variant() != variant:
                mi.set_variant(variant)
            log.info("Mitsuba %s uses variant %s (libLLVM: %s)", mi.__version__, variant, llvm_path)
            return variant
    raise MitsubaUnavailableError(
        f"Mitsuba variant(s) {', '.join(candidates)} unavailable here "
        f"(compiled: {', '.join(mi.variants())}; libLLVM >= {MIN_LLVM_MAJOR}: {llvm_path or 'not found'}; "
        "install Debian's libllvm19 or set DRJIT_LIBLLVM_PATH)"
    )


def mitsuba() -> ModuleType:
    """The ``mitsuba`` module with a variant selected (selecting the default one if needed)."""
    configure_llvm_path()
    import mitsuba as mi

    if mi.variant() is None:
        select_variant()
    return mi
