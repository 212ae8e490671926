"""Fault scenarios for ``brdfgan predict``: signals and kills mid-batch and mid-swap, a full disk,
photos that cannot give a material, a resolution that cannot fit in memory.

Every row runs the installed console script (or, for the two kills inside the result swap, the
same ``main`` with one function patched to SIGKILL the process at that exact point) on the sample
photos at 128², outputs in the scenario's workdir. The unit-level versions are in
``tests/inference/test_predict_faults.py``.
"""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path

import numpy as np

from faults.common import (
    BRDFGAN,
    PYTHON,
    REPO,
    Scenario,
    ScenarioFailed,
    expect_interrupted,
    expect_one_line_error,
    fill_disk,
    hidden_leftovers,
    run,
    run_until,
    small_disk,
    tail,
)

SAMPLES = REPO / "src" / "brdfgan" / "samples"
PHOTOS = [SAMPLES / "bricks.jpg", SAMPLES / "wood_planks.jpg"]
NAMES = ["bricks", "wood_planks"]
INTERRUPTED = "interrupted: finished photos are complete; the one in progress was not written"

# The console script's main with one step of the result swap patched to kill the process right
# after it: argv[1] says which step ("exchange": the atomic renameat2 exchange; "fallback": the
# first of the two renames used where there is no exchange), the rest is brdfgan's command line.
KILL_IN_SWAP = """
import os, signal, sys
from brdfgan.inference.outputs import export

def die():
    os.kill(os.getpid(), signal.SIGKILL)

if sys.argv[1] == "exchange":
    real_exchange = export.exchange_paths
    def exchange_then_die(a, b):
        if not real_exchange(a, b):
            sys.exit("this filesystem refuses renameat2(RENAME_EXCHANGE)")
        die()
    export.exchange_paths = exchange_then_die
else:
    export.exchange_paths = lambda a, b: False
    real_rename = os.rename
    def rename_then_die(src, dst):
        real_rename(src, dst)
        if str(dst).endswith(".old"):
            die()
    os.rename = rename_then_die

from brdfgan.cli import main
sys.exit(main(sys.argv[2:]))
"""


def predict(out: Path, *extra: str, photos: list[Path] = PHOTOS, quiet: bool = True) -> list[str]:
    return [
        BRDFGAN,
        "predict",
        *map(str, photos),
        "--out",
        str(out),
        "--resolution",
        "128",
        *(["--quiet"] if quiet else []),
        *extra,
    ]


def staging_with_files(out: Path) -> bool:
    """A photo's hidden staging folder exists and holds some of its files (mid-write)."""
    try:
        return any(folder.is_dir() and any(folder.iterdir()) for folder in out.glob(".*.tmp"))
    except OSError:  # the folder went away while looking: not the moment
        return False


def complete(folder: Path) -> bool:
    """A material folder whose material.json lists only files that exist."""
    try:
        document = json.loads((folder / "material.json").read_text())
    except (OSError, ValueError):
        return False
    return all((folder / name).is_file() for name in document["files"])


def finish(out: Path, *extra: str, quiet: bool = True) -> str:
    """Rerun into the same folder: exit 0, every result complete, nothing hidden left."""
    result = run(predict(out, *extra, quiet=quiet))
    if result.returncode != 0:
        raise ScenarioFailed(f"rerun failed (exit {result.returncode}): {tail(result.stderr)}")
    leftovers = hidden_leftovers(out)
    if leftovers:
        raise ScenarioFailed(f"the rerun left {leftovers[0].name}")
    if result.stdout.split() != [str(out / name) for name in NAMES]:
        raise ScenarioFailed(f"stdout is not the list of results: {tail(result.stdout)}")
    if not all(complete(out / name) for name in NAMES):
        raise ScenarioFailed("a result is incomplete after the rerun")
    return result.stderr


def interrupt_mid_batch(sig: signal.Signals) -> Scenario:
    def scenario(workdir: Path) -> str:
        out = workdir / "out"

        def in_second_photo() -> bool:  # so that the first photo's result must survive the signal
            return (out / NAMES[0]).exists() and staging_with_files(out)

        result = run_until(predict(out), in_second_photo, sig=sig)
        line = expect_interrupted(result, INTERRUPTED)
        leftovers = hidden_leftovers(out)
        if leftovers:
            raise ScenarioFailed(f"left {leftovers[0].name}")
        kept = sorted(p.name for p in out.iterdir())
        if kept != NAMES[:1] or not complete(out / NAMES[0]):
            raise ScenarioFailed(f"expected the complete first result only, found {kept}")
        return f"exit 130, '{line[:40]}…'; kept {kept}, no hidden folder"

    return Scenario(
        f"{sig.name} mid-batch",
        "one line, exit 130; finished results kept, the staging folder of the photo in progress removed",
        scenario,
    )


def kill_mid_batch(workdir: Path) -> str:
    out = workdir / "out"
    run_until(predict(out), lambda: staging_with_files(out), sig=signal.SIGKILL)
    left = [p.name for p in hidden_leftovers(out)]
    if not left:
        raise ScenarioFailed("the kill left no staging folder to clean up (it landed outside one)")
    finish(out)
    return f"kill -9 left {left[0]}; the rerun removed it and wrote {', '.join(NAMES)}"


def first_result(out: Path) -> None:
    """A complete earlier result in ``out`` for the swap scenarios to replace."""
    first = run(predict(out, "--no-preview"))
    if first.returncode != 0:
        raise ScenarioFailed(f"first run failed: {tail(first.stderr)}")


def killed_in_swap(out: Path, step: str) -> None:
    """Rerun into ``out`` with the process killed at ``step`` of the result swap (KILL_IN_SWAP)."""
    killed = run([PYTHON, "-c", KILL_IN_SWAP, step, *predict(out, "--no-preview")[1:]])
    if killed.returncode != -signal.SIGKILL:
        raise ScenarioFailed(f"exit {killed.returncode}, expected the injected kill: {tail(killed.stderr)}")


def kill_after_exchange(workdir: Path) -> str:
    out = workdir / "out"
    first_result(out)
    before = (out / NAMES[0] / "material.json").stat().st_mtime_ns
    killed_in_swap(out, "exchange")
    target = out / NAMES[0]
    if not complete(target) or (target / "material.json").stat().st_mtime_ns == before:
        raise ScenarioFailed(f"{target} is not the complete new result right after the kill")
    left = [p.name for p in hidden_leftovers(out)]
    if not left:
        raise ScenarioFailed("no hidden old copy: the kill did not land right after the exchange")
    finish(out, "--no-preview")
    return f"{NAMES[0]}/ was the new result at once; the old copy ({left[0]}) removed by the rerun"


def kill_between_renames(workdir: Path) -> str:
    out = workdir / "out"
    first_result(out)
    killed_in_swap(out, "fallback")
    if (out / NAMES[0]).exists():
        raise ScenarioFailed("the kill did not land between the renames")
    retired = [p.name for p in out.glob(f".{NAMES[0]}.*.old")]
    # Not --quiet: the restore is a warning, and --quiet leaves errors only.
    stderr = finish(out, "--no-preview", quiet=False)
    restored = [line for line in stderr.splitlines() if "restored the previous result" in line]
    if not retired or not restored:
        raise ScenarioFailed(f"no restore reported (retired: {retired}): {tail(stderr)}")
    return f"{NAMES[0]}/ missing, {retired[0]} kept; the rerun restored it (warning), then completed"


def disk_bytes(folder: Path) -> int:
    """Space a folder takes on a filesystem with 4 KiB blocks."""
    return sum(-(-p.stat().st_size // 4096) * 4096 + 4096 for p in folder.rglob("*") if p.is_file())


def disk_full(workdir: Path) -> str:
    reference = workdir / "reference"
    if run(predict(reference, "--no-preview")).returncode != 0:
        raise ScenarioFailed("the reference run failed")
    with small_disk(workdir / "disk", "4m") as disk:
        out = disk / "out"
        # Room for the first result (and its folder), not for the second.
        filler = fill_disk(disk, leave_bytes=disk_bytes(reference / NAMES[0]) + 64 * 1024)
        result = run(predict(out, "--no-preview"))
        line = expect_one_line_error(result, exit_code=1, contains=": no space left on device")
        named = Path(line.removeprefix("error: ").removesuffix(": no space left on device"))
        if named.parent != out:
            raise ScenarioFailed(f"the error names no output folder: {line}")
        partial = [named] if named.exists() else hidden_leftovers(out)
        if partial:
            raise ScenarioFailed(f"a partial folder is left: {partial[0]}")
        kept = sorted(p.name for p in out.iterdir()) if out.exists() else []
        if not all(complete(out / name) for name in kept):
            raise ScenarioFailed(f"an incomplete result is visible: {kept}")
        filler.unlink()  # space freed
        finish(out, "--no-preview")
    return f"{line}; kept {kept}, no partial folder; after freeing space the rerun completed"


def black_photo(workdir: Path) -> str:
    from PIL import Image

    photo = workdir / "lens_cap.jpg"
    Image.fromarray(np.zeros((256, 256, 3), np.uint8)).save(photo)
    out = workdir / "out"
    result = run(predict(out, photos=[photo]))
    line = expect_one_line_error(result, exit_code=1, contains=f"{photo}: is black")
    if out.exists() and any(out.iterdir()):
        raise ScenarioFailed(f"wrote {sorted(p.name for p in out.iterdir())}")
    return f"{line}; nothing written"


def corrupt_exr(workdir: Path) -> str:
    from brdfgan.io.images import write_image

    full = write_image(
        workdir / "full.exr", np.random.default_rng(0).random((256, 256, 3)), exr_precision="float"
    )
    corrupt = workdir / "interrupted_copy.exr"
    corrupt.write_bytes(full.read_bytes()[: full.stat().st_size * 2 // 3])
    out = workdir / "out"
    result = run(predict(out, "--no-preview", photos=[PHOTOS[0], corrupt]))
    line = expect_one_line_error(result, exit_code=1, contains=f"{corrupt}: corrupt or unreadable EXR file")
    if result.stdout.splitlines() != [str(out / NAMES[0])]:
        raise ScenarioFailed(f"stdout holds more than the output folders: {tail(result.stdout)}")
    return f"stdout only {NAMES[0]}'s folder; {line[:100]}…"


def mostly_black_photo(workdir: Path) -> str:
    from PIL import Image

    # A lit spot near a corner of a black frame: the median luminance is 0.
    yy, xx = np.mgrid[0:256, 0:320]
    spot = 255 * np.exp(-((xx - 40) ** 2 + (yy - 40) ** 2) / (2 * 12.0**2))
    spot = np.where(spot < 10, 0, spot)
    photo = workdir / "spot.png"
    Image.fromarray((spot[..., None] * np.array([1.0, 0.9, 0.8])).astype(np.uint8)).save(photo)
    out = workdir / "out"
    result = run(predict(out, "--no-preview", photos=[photo]))
    text = result.stdout + result.stderr
    if "nan" in text.lower():
        raise ScenarioFailed(
            f"NaN in a message: {next(line for line in text.splitlines() if 'nan' in line.lower())}"
        )
    if result.returncode != 0:
        raise ScenarioFailed(f"exit {result.returncode}: {tail(result.stderr)}")
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning:")]
    return f"written; {len(warnings)} warning(s), none with NaN" + (
        f": {warnings[0][:80]}…" if warnings else ""
    )


def huge_resolution(workdir: Path) -> str:
    out = workdir / "out"
    began = time.monotonic()
    result = run([BRDFGAN, "predict", str(PHOTOS[0]), "--out", str(out), "--resolution", "100000", "--quiet"])
    seconds = time.monotonic() - began
    line = expect_one_line_error(result, exit_code=2, contains="--resolution 100000 needs ~")
    if "GiB" not in line or out.exists():
        raise ScenarioFailed(f"no estimate, or something was written: {line}")
    return f"{line} ({seconds:.0f} s, nothing written)"


SCENARIOS = [
    interrupt_mid_batch(signal.SIGTERM),
    interrupt_mid_batch(signal.SIGINT),
    Scenario(
        "kill -9 mid-batch, rerun",
        "the rerun into the same --out removes the dead run's staging folder and completes",
        kill_mid_batch,
    ),
    Scenario(
        "kill -9 right after the result swap (renameat2 exchange)",
        "OUT/NAME is the complete new result at once (never missing); the rerun removes the old copy",
        kill_after_exchange,
    ),
    Scenario(
        "kill -9 between the two renames (no renameat2)",
        "the rerun restores OUT/NAME from .NAME.*.old with a warning, then completes",
        kill_between_renames,
    ),
    Scenario(
        "disk full (tmpfs --out)",
        "one line naming the folder, exit 1, no partial folder; after freeing space the rerun completes",
        disk_full,
    ),
    Scenario("black photo", "one line naming the photo (is black), exit 1, nothing written", black_photo),
    Scenario(
        "corrupt .exr input",
        "one line naming the file; stdout holds only the output folders, no OpenEXR warning",
        corrupt_exr,
    ),
    Scenario("photo lit only near a corner", "written; no NaN in any message", mostly_black_photo),
    Scenario(
        "--resolution 100000",
        "one line with the memory estimate in GiB, exit 2, before anything is allocated or written",
        huge_resolution,
    ),
]
