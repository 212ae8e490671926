"""Fault scenarios for ``generate.py``: kills mid-shard, a full disk, a shard corrupted in place,
bad values and a corrupt environment file, each against the real command on the tiny dataset.

The unit-level versions (injected ENOSPC, in-process corruption) are in
``tests/data/generation/test_generation.py`` and ``tests/data/generation/test_generation_faults.py``.
"""

from __future__ import annotations

import atexit
import functools
import shutil
import signal
import tarfile
import tempfile
from pathlib import Path

from faults.common import (
    PYTHON,
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

# dataset_spec=tiny with small environment pools: 4 shards (train 0-1, val 0, test 0), seconds to make.
DATASET = [
    "dataset_spec=tiny",
    "dataset_spec.lighting.train_count=2",
    "dataset_spec.lighting.test_count=1",
    "dataset_spec.lighting.resolution=16",
]
INTERRUPTED = "interrupted: complete shards are kept; re-run the same command to finish"


def generate(workdir: Path, out: Path, *overrides: str) -> list[str]:
    """The command line; Hydra's run folder goes into the scenario's workdir, not the checkout."""
    return [
        PYTHON,
        "generate.py",
        *DATASET,
        f"out_dir={out}",
        "progress=false",
        "contact_sheet=0",
        f"hydra.run.dir={workdir / 'hydra'}",
        *overrides,
    ]


def shard_bytes(out: Path) -> dict[str, bytes]:
    """Every shard and checksum record of a dataset, by relative path."""
    return {
        str(p.relative_to(out)): p.read_bytes()
        for pattern in ("*/*.tar", "*/*.tar.sha256")
        for p in sorted(out.glob(pattern))
    }


@functools.cache
def reference() -> Path:
    """A straight, uninterrupted run (made once, shared by the scenarios that compare bytes)."""
    workdir = Path(tempfile.mkdtemp(prefix="faults-generate-reference-"))
    atexit.register(shutil.rmtree, workdir, ignore_errors=True)
    out = workdir / "out"
    result = run(generate(workdir, out))
    if result.returncode != 0:
        raise ScenarioFailed(f"the reference run failed (exit {result.returncode}): {tail(result.stderr)}")
    return out


def same_as_reference(out: Path) -> None:
    """The same shards as a straight run: byte-identical, or (Mitsuba's rare one-code pixels,
    docs/data.md) the same samples with photos within the generation's tolerance."""
    from brdfgan.data.storage.shards import shard_differences

    expected, found = shard_bytes(reference()), shard_bytes(out)
    if found.keys() != expected.keys():
        raise ScenarioFailed(f"files differ from a straight run: {sorted(found)} vs {sorted(expected)}")
    differing = [name for name in expected if found[name] != expected[name] and name.endswith(".tar")]
    beyond = [line for name in differing for line in shard_differences(reference() / name, out / name)]
    if beyond:
        raise ScenarioFailed(f"not the same shards as a straight run: {'; '.join(beyond[:3])}")


def finish(workdir: Path, out: Path) -> None:
    """Rerun the same command: it must succeed, leave no temporary file, match a straight run."""
    result = run(generate(workdir, out))
    if result.returncode != 0:
        raise ScenarioFailed(f"rerun failed (exit {result.returncode}): {tail(result.stderr)}")
    leftovers = hidden_leftovers(out)
    if leftovers:
        raise ScenarioFailed(f"temporary files left: {leftovers[0]}")
    same_as_reference(out)


def mid_shard(out: Path) -> bool:
    """Shard train-000001 is being written (so train-000000 is complete)."""
    return any((out / "train").glob(".train-000001.tar.*.tmp"))


def kill_mid_shard(workdir: Path) -> str:
    out = workdir / "out"
    reference()
    run_until(generate(workdir, out), lambda: mid_shard(out), sig=signal.SIGKILL)
    if not (out / "train" / "train-000000.tar").exists() or (out / "train" / "train-000001.tar").exists():
        raise ScenarioFailed("the kill did not land in shard train-000001")
    finish(workdir, out)
    return (
        "killed in train-000001; the rerun made the rest, every shard the same as a straight run "
        "(photos within one code)"
    )


def interrupt_mid_shard(sig: signal.Signals) -> Scenario:
    def scenario(workdir: Path) -> str:
        out = workdir / "out"
        result = run_until(generate(workdir, out), lambda: mid_shard(out), sig=sig)
        line = expect_interrupted(result, INTERRUPTED)
        if not (out / "train" / "train-000000.tar").exists() or hidden_leftovers(out):
            raise ScenarioFailed("the complete shard is gone or a temporary file is left")
        expected = shard_bytes(reference())
        kept = shard_bytes(out)
        if any(kept[name] != expected[name] for name in kept) or "train/train-000000.tar.sha256" not in kept:
            raise ScenarioFailed(f"kept files differ from a straight run: {sorted(kept)}")
        return f"exit 130, '{line[:40]}…'; kept {', '.join(sorted(kept))}, no temporary file"

    return Scenario(
        f"{sig.name} mid-shard",
        "one line, exit 130; complete shards (and their records) kept, the partial one removed",
        scenario,
    )


def disk_full(workdir: Path) -> str:
    reference_shard = reference() / "train" / "train-000000.tar"
    with small_disk(workdir / "disk", "8m") as disk:
        out = disk / "out"
        # Room for dataset.json, train-000000.tar and its record, not for train-000001.tar.
        filler = fill_disk(disk, leave_bytes=reference_shard.stat().st_size + 32 * 1024)
        result = run(generate(workdir, out))
        line = expect_one_line_error(result, exit_code=1, contains=": no space left on device")
        named = Path(line.removeprefix("error: ").removesuffix(": no space left on device"))
        if out not in named.parents:
            raise ScenarioFailed(f"the error names no file of the dataset: {line}")
        partial = [named] if named.exists() else hidden_leftovers(out)
        if partial:
            raise ScenarioFailed(f"a partial file is left: {partial[0]}")
        kept = sorted(p.name for p in out.glob("*/*.tar"))
        filler.unlink()  # space freed
        finish(workdir, out)
    return f"{line}; kept {kept}, no partial file; after freeing space the rerun matches a straight run"


def corrupted_in_place(workdir: Path) -> str:
    out = workdir / "out"
    shutil.copytree(reference(), out)
    shard = out / "train" / "train-000000.tar"
    with tarfile.open(shard) as tar:
        # The first image member of either shard format (dataset_spec.shard_format).
        member = next(info for info in tar if info.name.endswith((".basecolor.png", ".maps.u16z")))
    with shard.open("r+b") as handle:  # flip bytes inside the image data, headers untouched
        handle.seek(member.offset_data + member.size // 2)
        chunk = handle.read(32)
        handle.seek(member.offset_data + member.size // 2)
        handle.write(bytes(b ^ 0x5A for b in chunk))
    result = run(generate(workdir, out))
    if result.returncode != 0:
        raise ScenarioFailed(f"rerun failed (exit {result.returncode}): {tail(result.stderr)}")
    output = result.stdout + result.stderr
    reports = [line for line in output.splitlines() if str(shard) in line and "SHA-256" in line]
    if not reports or "rewrote damaged: train-000000.tar" not in output:
        raise ScenarioFailed(f"the corruption was not reported: {tail(output)}")
    same_as_reference(out)
    return (
        f"reported ({reports[0].split('] - ')[-1][:90]}…), rewritten as the original (photos within one code)"
    )


def bad_value(workdir: Path) -> str:
    out = workdir / "out"
    seen = []
    for overrides, key in (
        (["dataset_spec.flash.intensity_min=-3"], "dataset_spec.flash.intensity_min=-3"),
        (
            ["dataset_spec.flash.temperature_min_k=9000", "dataset_spec.flash.temperature_max_k=1000"],
            "dataset_spec.flash.temperature_min_k=9000 > dataset_spec.flash.temperature_max_k=1000",
        ),
    ):
        result = run(generate(workdir, out, *overrides))
        seen.append(expect_one_line_error(result, exit_code=2, contains=key))
        if out.exists():
            raise ScenarioFailed(f"{' '.join(overrides)} wrote {sorted(out.rglob('*'))[:3]}")
    finish(workdir, out)  # the corrected command, in the same output folder
    return f"{' / '.join(seen)}; nothing written; the corrected command then ran"


def corrupt_environment(workdir: Path) -> str:
    import numpy as np

    from brdfgan.io.images import write_image

    envs = workdir / "envs"
    envs.mkdir()
    for k in range(2):
        sky = np.full((16, 32, 3), 0.5 + k, np.float32)
        write_image(envs / f"studio{k}.exr", sky, exr_precision="float")
    good = (envs / "studio0.exr").read_bytes()
    bad = envs / "attic.exr"
    bad.write_bytes(good[: len(good) // 2])  # an interrupted copy
    out = workdir / "out"
    result = run(generate(workdir, out, f"dataset_spec.lighting.folder={envs}"))
    line = expect_one_line_error(result, exit_code=2, contains=str(bad.resolve()))
    if out.exists():
        raise ScenarioFailed(f"wrote {sorted(out.rglob('*'))[:3]} before the check")
    return f"{line[:110]}; nothing written"


SCENARIOS = [
    Scenario(
        "kill -9 mid-shard, rerun",
        "rerun finishes; every shard the same as a straight run (photos within one code); no temporary file",
        kill_mid_shard,
    ),
    interrupt_mid_shard(signal.SIGTERM),
    interrupt_mid_shard(signal.SIGINT),
    Scenario(
        "disk full (tmpfs)",
        "one line naming the file, exit 1, no partial file; after freeing space the rerun completes",
        disk_full,
    ),
    Scenario(
        "an image member corrupted in place in a complete shard",
        "rerun reports the shard (SHA-256 mismatch) and rewrites it as the original (photos within one code)",
        corrupted_in_place,
    ),
    Scenario(
        "bad range value",
        "one line naming the key, exit 2, nothing written; the corrected command then runs",
        bad_value,
    ),
    Scenario(
        "corrupt .exr in dataset_spec.lighting.folder",
        "one line naming the file, exit 2, before anything is written",
        corrupt_environment,
    ),
]
