"""User errors: what a command reports as one line and a non-zero exit instead of a traceback.

Every module raises a ``ValueError`` subclass naming the offending file or key; entry points wrap
their work in :func:`exit_on_user_error` so those become ``error: <message>`` on stderr, exit 2.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from typing import ParamSpec, TypeVar

P = ParamSpec("P")
R = TypeVar("R")

USER_ERROR_EXIT_CODE = 2


def one_line(error: BaseException) -> str:
    """The error's message folded to one line (Hydra's instantiation errors span several)."""
    return " ".join(str(error).split()) or type(error).__name__


def exit_on_user_error(function: Callable[P, R]) -> Callable[P, R]:
    """Run ``function``; a ``ValueError`` (our error classes derive from it), Hydra's
    instantiation/config errors or a ``KeyboardInterrupt`` end the process with one line."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    @functools.wraps(function)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            return function(*args, **kwargs)
        except (ValueError, HydraException, OmegaConfBaseException) as error:
            print(f"error: {one_line(error)}", file=sys.stderr)
            raise SystemExit(USER_ERROR_EXIT_CODE) from None
        except KeyboardInterrupt:
            print("interrupted: complete shards are kept; re-run the same command to finish", file=sys.stderr)
            raise SystemExit(130) from None

    return wrapper
