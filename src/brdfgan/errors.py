"""User errors: what a command reports as one line and a non-zero exit instead of a traceback.

Every project error class derives from :class:`UserError` and names the offending file or key;
entry points wrap their work in :func:`exit_on_user_error` (or :func:`run_reporting_errors`) so
those, and Hydra's and OmegaConf's configuration errors, become ``error: <message>`` on stderr,
exit 2. Any other exception, a plain ``ValueError`` included, is a bug and keeps its traceback.
A full disk is not the user's mistake in the command but needs no traceback either: it becomes
``error: <path>: no space left on device``, exit 1 (:class:`DiskFullError`, raised by the atomic
writers of :mod:`brdfgan.io.atomic`, or any ``OSError`` with ``ENOSPC``/``EDQUOT``).
"""

from __future__ import annotations

import errno
import functools
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import ParamSpec, TypeVar

P = ParamSpec("P")
R = TypeVar("R")

USER_ERROR_EXIT_CODE = 2
DISK_FULL_EXIT_CODE = 1
INTERRUPTED_EXIT_CODE = 130

# errno values that mean "the filesystem has no room for this write".
DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})


class UserError(ValueError):
    """Something the user can fix (a file, a key, a value); the message names it."""


class DiskFullError(OSError):
    """A write failed because the filesystem is full; ``filename`` is the file being written.

    Raised after the partial file was removed, so nothing half-written is left behind.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        super().__init__(errno.ENOSPC, "no space left on device", os.fspath(path))

    def __str__(self) -> str:
        return f"{self.filename}: no space left on device"


def _disk_full_errors(error: BaseException) -> Iterator[OSError]:
    """The full-filesystem ``OSError``s among ``error`` and the errors it was raised from."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, OSError) and current.errno in DISK_FULL_ERRNOS:
            yield current
        current = current.__cause__ or current.__context__


def wrapped_interrupt(error: BaseException) -> KeyboardInterrupt | None:
    """The ``KeyboardInterrupt`` that ``error`` was raised from, if any.

    A signal that lands while native code calls back into Python (Mitsuba's ``mi.render`` runs
    its integrator through ``drjit.custom``) raises the interrupt in the callback, and the library
    re-raises it as its own ``RuntimeError`` *from* the interrupt: that is still the user's
    interrupt, not a bug. Only explicit causes count (``raise ... from``); an error raised while
    handling an interrupt (its ``__context__``) is a bug in the cleanup and keeps its traceback.
    """
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, KeyboardInterrupt):
            return current
        current = current.__cause__
    return None


def is_disk_full(error: BaseException) -> bool:
    """Whether ``error`` (or an error it was raised from) is a full filesystem."""
    return next(_disk_full_errors(error), None) is not None


def disk_full_message(error: BaseException) -> str:
    """``<path>: no space left on device`` for a disk-full error (the outermost path known)."""
    path = next((e.filename for e in _disk_full_errors(error) if e.filename), None)
    return f"{path}: no space left on device" if path else "no space left on device"


def one_line(error: BaseException) -> str:
    """The error's message folded to one line (Hydra's instantiation errors span several)."""
    return " ".join(str(error).split()) or type(error).__name__


def report_error(error: BaseException) -> int | None:
    """Print the one line for an error a command reports without a traceback and return its exit
    status; ``None`` for anything else (a bug), which the caller re-raises."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    if is_disk_full(error):
        print(f"error: {disk_full_message(error)}", file=sys.stderr)
        return DISK_FULL_EXIT_CODE
    if isinstance(error, UserError | HydraException | OmegaConfBaseException):
        print(f"error: {one_line(error)}", file=sys.stderr)
        return USER_ERROR_EXIT_CODE
    return None


def run_reporting_errors(function: Callable[[], int], *, interrupted: str = "interrupted") -> int:
    """``function()``'s exit status; a user error, a full disk or an interrupt print one line and
    return their exit status instead (:func:`report_error`). ``interrupted``: what an interrupt
    prints unless the ``KeyboardInterrupt`` carries a message of its own."""
    try:
        return function()
    except KeyboardInterrupt as error:
        # A command that knows more (where to resume from) raises it with a message.
        print(str(error) or interrupted, file=sys.stderr)
        return INTERRUPTED_EXIT_CODE
    except Exception as error:
        interrupt = wrapped_interrupt(error)
        if interrupt is not None:
            print(str(interrupt) or interrupted, file=sys.stderr)
            return INTERRUPTED_EXIT_CODE
        code = report_error(error)
        if code is None:
            raise
        return code


def exit_on_user_error(
    function: Callable[P, R] | None = None, *, interrupted: str = "interrupted"
) -> Callable[P, R] | Callable[[Callable[P, R]], Callable[P, R]]:
    """Run ``function``; a :class:`UserError`, Hydra's instantiation/config errors, a full disk or
    a ``KeyboardInterrupt`` end the process with one line (:func:`report_error`). ``interrupted``:
    what an interrupt prints (each command says what it kept)."""

    def decorate(inner: Callable[P, R]) -> Callable[P, R]:
        @functools.wraps(inner)
        def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
            try:
                return inner(*args, **kwargs)
            except KeyboardInterrupt as error:
                print(str(error) or interrupted, file=sys.stderr)
                raise SystemExit(INTERRUPTED_EXIT_CODE) from None
            except BaseException as error:
                interrupt = wrapped_interrupt(error)
                if interrupt is not None:
                    print(str(interrupt) or interrupted, file=sys.stderr)
                    raise SystemExit(INTERRUPTED_EXIT_CODE) from None
                code = report_error(error)
                if code is None:
                    raise
                raise SystemExit(code) from None

        return wrapper

    return decorate if function is None else decorate(function)


def single_console_logging() -> None:
    """Print each log line once in a Hydra app that uses Lightning.

    Importing ``lightning`` gives its package logger a stderr handler of its own, and its records
    also propagate to the root logger, which Hydra's job logging sends to stdout and the run's log
    file: every Lightning line (and the model summary) appeared twice. Its own handler goes; the
    root's handlers keep each line once, in the console and in the log file. Lightning's tips
    (an advertisement for its cloud logger) are dropped."""
    import logging

    import lightning  # noqa: F401  (the import adds the handler removed here)

    package_logger = logging.getLogger("lightning")
    for handler in list(package_logger.handlers):
        package_logger.removeHandler(handler)
    # Lightning's Trainer also advertises a cloud logger ("💡 Tip: … litlogger …") on every run.
    for name in LIGHTNING_TIP_LOGGERS:
        tip_logger = logging.getLogger(name)
        if not any(isinstance(f, LightningTipFilter) for f in tip_logger.filters):
            tip_logger.addFilter(LightningTipFilter())


# The loggers Lightning's rank-zero messages (its tips among them) are written to.
LIGHTNING_TIP_LOGGERS = ("lightning.pytorch.utilities.rank_zero", "lightning.fabric.utilities.rank_zero")


class LightningTipFilter:
    """Drops Lightning's advertising tips (messages starting with "💡 Tip"), keeps the rest."""

    def filter(self, record: object) -> bool:
        message = getattr(record, "msg", "")
        return not (isinstance(message, str) and message.lstrip().startswith("💡"))


# Config presets renamed, ``"<group>/<old name>": "<new name>"``: a command that asks for an old
# name is refused in one line that names the new one (:func:`missing_config_message`). Experiments
# and data are named by what they are, not by the model version that first used them.
RENAMED_PRESETS: dict[str, str] = {
    "experiment/default_model": "procedural",
    "experiment/default_model_finetune": "procedural_finetune",
    "experiment/v5": "anchored_rendered",
    "experiment/v5_fixres": "anchored_rendered_fixres",
    "experiment/v5_shading": "anchored_rendered_normals",
    "data/default_model": "procedural",
    "dataset_spec/default_model": "procedural",
}


def missing_config_message(error: BaseException) -> str:
    """The one line for Hydra's "Could not find '<group>/<name>'": a renamed preset
    (:data:`RENAMED_PRESETS`) names its new name, any other the group's options."""
    missing = getattr(error, "missing_cfg_file", None) or ""
    group, _, name = missing.rpartition("/")
    if missing in RENAMED_PRESETS:
        return f"{group}={name} was renamed {group}={RENAMED_PRESETS[missing]}"
    first = str(error).split("\n", 1)[0].strip() or type(error).__name__
    options = getattr(error, "options", None)
    return f"{first} (options: {', '.join(options)})" if group and options else first


def run_hydra_app(app: Callable[[], object]) -> None:
    """Run a ``@hydra.main`` entry point so that composition errors are one line too.

    Hydra reports a bad override (``seed=abc``, an unknown key) itself, over several lines,
    before the task function — and so before :func:`exit_on_user_error` — runs. With
    ``HYDRA_FULL_ERROR=1`` it re-raises instead, and the error becomes ``error: <message>``,
    exit 2, here. Errors inside the task are the task wrapper's business; a bug's traceback
    is never swallowed.
    """
    import logging

    from hydra.errors import HydraException, MissingConfigException
    from omegaconf.errors import OmegaConfBaseException

    os.environ["HYDRA_FULL_ERROR"] = "1"
    # A log file on a full disk must not print a "--- Logging error ---" traceback per record;
    # the write that matters fails on its own and is reported below as one line.
    logging.raiseExceptions = False
    try:
        app()
    except (OSError, HydraException, OmegaConfBaseException) as error:
        # An OSError here is Hydra writing the run folder's .hydra/ files on a full disk.
        if is_disk_full(error):
            print(f"error: {disk_full_message(error)}", file=sys.stderr)
            raise SystemExit(DISK_FULL_EXIT_CODE) from None
        # Hydra's missing config is an OSError too (an IOError subclass): a user's typo, not I/O.
        if isinstance(error, MissingConfigException):
            print(f"error: {missing_config_message(error)}", file=sys.stderr)
            raise SystemExit(USER_ERROR_EXIT_CODE) from None
        if isinstance(error, OSError):
            raise
        # "Error merging override seed=abc" says where; its cause says what is wrong.
        cause = f": {one_line(error.__cause__)}" if error.__cause__ is not None else ""
        print(f"error: {one_line(error)}{cause}", file=sys.stderr)
        raise SystemExit(USER_ERROR_EXIT_CODE) from None


@contextmanager
def interrupts_raise() -> Iterator[None]:
    """Inside the block SIGTERM, like SIGINT, raises ``KeyboardInterrupt``, once.

    A terminated process runs no ``finally`` blocks; an exception does, so partial outputs (the
    staging folder of a photo, the shard being written) are removed. Signals after the first
    are ignored until the block ends, so that cleanup is not cut short. Only default handlers
    are replaced (one a launcher or an embedding program installed is its own business, an
    ignored signal stays ignored), and the previous ones are restored afterwards. Outside the
    main thread, where Python cannot set handlers, nothing changes.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    interrupted = False

    def handler(_signum: int, _frame: FrameType | None) -> None:
        nonlocal interrupted
        if interrupted:
            return
        interrupted = True
        raise KeyboardInterrupt

    defaults: dict[signal.Signals, Callable[[int, FrameType | None], object] | int] = {
        signal.SIGINT: signal.default_int_handler,
        signal.SIGTERM: signal.SIG_DFL,
    }
    replaced = [number for number, default in defaults.items() if signal.getsignal(number) is default]
    for number in replaced:
        signal.signal(number, handler)
    try:
        yield
    finally:
        for number in replaced:
            signal.signal(number, defaults[number])
