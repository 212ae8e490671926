"""Range checks of the dataset spec, each naming the key as it is typed on the command line.

The spec dataclasses (:class:`~brdfgan.data.spec.dataset_spec.DatasetSpec` and the flash, crop and
lighting specs nested in it) call these from ``__post_init__``, so a bad value fails when the
config is composed, before ``generate.py`` writes ``dataset.json`` or starts Mitsuba; the
corrected command then runs in the same output directory. Messages read
``dataset_spec.flash.intensity_min=-3: must be > 0``. Values of the wrong type are reported too
(``must be a number, got 'abc'``) instead of failing inside a comparison.
"""

from __future__ import annotations

import math
from typing import Any

from brdfgan.errors import UserError


class DatasetConfigError(UserError):
    """A dataset spec or output directory is unusable; the message names the key or path."""


def _show(value: Any) -> str:
    # As the user typed it: 9000 rather than 9000.0; strings quoted so 'abc' reads as text.
    if isinstance(value, float):
        return f"{value:g}"
    return repr(value) if isinstance(value, str) else str(value)


def number(key: str, value: Any) -> float:
    """``value`` as a float; :class:`DatasetConfigError` unless it is a finite real number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise DatasetConfigError(f"{key}={_show(value)}: must be a number")
    if not math.isfinite(value):
        raise DatasetConfigError(f"{key}={_show(value)}: must be a finite number")
    return float(value)


def integer(key: str, value: Any, *, minimum: int) -> int:
    """``value`` as an int, at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise DatasetConfigError(f"{key}={_show(value)}: must be an integer >= {minimum}")
    if value < minimum:
        raise DatasetConfigError(f"{key}={_show(value)}: must be an integer >= {minimum}")
    return value


def in_range(
    key: str,
    value: Any,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """``value`` as a float inside ``low``..``high`` (either bound optional, each closed unless
    ``*_open``)."""
    x = number(key, value)
    too_low = low is not None and (x <= low if low_open else x < low)
    too_high = high is not None and (x >= high if high_open else x > high)
    if too_low or too_high:
        raise DatasetConfigError(f"{key}={_show(value)}: must be {_describe(low, high, low_open, high_open)}")
    return x


def _describe(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    if low is not None and high is not None:
        return f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if low is not None:
        return f"{'>' if low_open else '>='} {low:g}"
    assert high is not None
    return f"{'<' if high_open else '<='} {high:g}"


def ordered(key: str, spec: object, low_name: str, high_name: str) -> None:
    """The fields ``low_name``/``high_name`` of ``spec`` (configured under ``key``) are numbers
    and not inverted (equal is allowed: a constant)."""
    low_key, high_key = f"{key}.{low_name}", f"{key}.{high_name}"
    low = number(low_key, getattr(spec, low_name))
    high = number(high_key, getattr(spec, high_name))
    if low > high:
        raise DatasetConfigError(
            f"{low_key}={_show(low)} > {high_key}={_show(high)}: the minimum must not exceed the maximum"
        )
