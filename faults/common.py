"""What the fault scenarios share: running a command, killing it at a point, a tiny disk."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PYTHON = sys.executable
BRDFGAN = str(Path(PYTHON).with_name("brdfgan"))


class ScenarioFailed(AssertionError):
    """The command did not behave as the scenario expects; the message says what happened."""


@dataclass(frozen=True)
class Scenario:
    """One fault and the behaviour it must produce.

    ``run(workdir)`` raises :class:`ScenarioFailed` (or any exception) when the behaviour is
    wrong and returns a short description of what it saw otherwise.
    """

    name: str
    expected: str
    run: Callable[[Path], str]


def command_env(**extra: str) -> dict[str, str]:
    """The environment of a scenario's command: this one, unbuffered, with ``extra``."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env.update(extra)
    return env


def run(
    args: Sequence[str], *, cwd: Path = REPO, timeout: float = 600, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """Run ``args`` to completion, capturing text output."""
    return subprocess.run(
        list(args), cwd=cwd, env=env or command_env(), capture_output=True, text=True, timeout=timeout
    )


def run_until(
    args: Sequence[str],
    condition: Callable[[], bool],
    *,
    sig: int = signal.SIGKILL,
    cwd: Path = REPO,
    timeout: float = 600,
    env: dict[str, str] | None = None,
    poll: float = 0.02,
) -> subprocess.CompletedProcess[str]:
    """Start ``args``, send ``sig`` as soon as ``condition()`` holds, wait for the end.

    Raises :class:`ScenarioFailed` when the command ends before the condition was met.
    """
    process = subprocess.Popen(
        list(args), cwd=cwd, env=env or command_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, start_new_session=True,
    )  # fmt: skip
    deadline = time.monotonic() + timeout
    try:
        while not condition():
            if process.poll() is not None:
                out, err = process.communicate()
                raise ScenarioFailed(f"ended (exit {process.returncode}) before the kill point: {tail(err)}")
            if time.monotonic() > deadline:
                raise ScenarioFailed("the kill point was not reached in time")
            time.sleep(poll)
        process.send_signal(sig)
        out, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    return subprocess.CompletedProcess(list(args), process.returncode, out, err)


def tail(text: str, lines: int = 3) -> str:
    """The last lines of ``text`` joined with `` / `` (for a result cell)."""
    kept = [line for line in text.strip().splitlines() if line.strip()][-lines:]
    return " / ".join(kept)


def expect_one_line_error(
    result: subprocess.CompletedProcess[str], *, exit_code: int, contains: str = "", prefix: str = "error:"
) -> str:
    """The command exited with ``exit_code`` and printed one ``prefix`` line (``error: …`` by
    default, ``interrupted: …`` for a signal) containing ``contains``, and no traceback."""
    lines = [line for line in result.stderr.splitlines() if line.startswith(prefix)]
    if "Traceback" in result.stderr or "Traceback" in result.stdout:
        raise ScenarioFailed(f"traceback (exit {result.returncode}): {tail(result.stderr)}")
    if result.returncode != exit_code:
        raise ScenarioFailed(f"exit {result.returncode}, expected {exit_code}: {tail(result.stderr)}")
    if len(lines) != 1 or contains not in lines[0]:
        raise ScenarioFailed(f"expected one '{prefix} …{contains}…' line, got: {tail(result.stderr)}")
    return lines[0]


def expect_interrupted(result: subprocess.CompletedProcess[str], message: str) -> str:
    """The command ended on a signal the way it should: exit 130, no traceback, and ``message``
    as its last line. Returns that line."""
    if "Traceback" in result.stderr or result.returncode != 130:
        raise ScenarioFailed(f"exit {result.returncode}: {tail(result.stderr)}")
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    if lines[-1:] != [message]:
        raise ScenarioFailed(f"last line is not the interrupt message: {tail(result.stderr)}")
    return lines[-1]


def hidden_leftovers(folder: Path) -> list[Path]:
    """Temporary files and folders (``.NAME.<hex>.tmp`` and the like) anywhere under ``folder``."""
    return sorted(p for p in folder.rglob(".*") if p.name.endswith((".tmp", ".old", ".partial")))


@contextlib.contextmanager
def small_disk(mountpoint: Path, size: str) -> Iterator[Path]:
    """A tmpfs of ``size`` (e.g. ``"2m"``) at ``mountpoint``; needs root."""
    mountpoint.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mountpoint)], check=True)
    try:
        yield mountpoint
    finally:
        subprocess.run(["umount", "-l", str(mountpoint)], check=False)


def fill_disk(mountpoint: Path, leave_bytes: int = 0) -> Path:
    """Fill the filesystem at ``mountpoint`` up to ``leave_bytes`` free; returns the filler file."""
    filler = mountpoint / "filler.bin"
    free = os.statvfs(mountpoint).f_bavail * os.statvfs(mountpoint).f_frsize
    with filler.open("wb") as handle:
        remaining = max(0, free - leave_bytes)
        chunk = b"\0" * (1 << 16)
        with contextlib.suppress(OSError):
            while remaining > 0:
                handle.write(chunk[: min(len(chunk), remaining)])
                remaining -= min(len(chunk), remaining)
            handle.flush()
    return filler
