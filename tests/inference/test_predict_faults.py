"""`brdfgan predict` under faults: kills and interrupts mid-batch and mid-swap, a full disk, inputs
that cannot give a material, resolutions that cannot fit in memory.

The kills are real signals sent by the process to itself at an exact point (a patched function in
a child process), so nothing here depends on timing. The same faults against the unpatched command
line are in ``faults/predict.py`` (``make faults``).
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from brdfgan.cli import main
from brdfgan.errors import DISK_FULL_EXIT_CODE, INTERRUPTED_EXIT_CODE, USER_ERROR_EXIT_CODE, interrupts_raise
from brdfgan.inference.model.memory import check_memory
from brdfgan.inference.model.tiling import TilingConfig
from brdfgan.inference.model.weights import Model, PredictError, load_model
from brdfgan.inference.outputs import export
from brdfgan.inference.outputs.export import ExportOptions, recover_outputs, write_material
from brdfgan.io.images import write_image
from brdfgan.models.generator import Generator
from tests.conftest import ROOT, random_maps
from tests.inference import test_predict
from tests.inference.test_predict import flash_photo

REPO = ROOT
weights = test_predict.weights  # the tiny generator's weights file (module-scoped fixture)


def hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def run_child(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", script, *args], cwd=REPO, capture_output=True, text=True, timeout=300
    )


def material_run(folder: Path) -> int:
    return json.loads((folder / "material.json").read_text())["run"]


# --- the result swap ---------------------------------------------------------------------------

SWAP_CHILD = """
import os, signal, sys
from pathlib import Path
import torch
from brdfgan.core.svbrdf import join_maps
from brdfgan.inference.outputs import export

out, mode = Path(sys.argv[1]), sys.argv[2]
flat = torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1).expand(3, 8, 8)
maps = join_maps(torch.full((3, 8, 8), 0.5), flat, torch.full((1, 8, 8), 0.5), torch.zeros(1, 8, 8))

def die():
    os.kill(os.getpid(), signal.SIGKILL)  # no finally block, no cleanup: like kill -9 or a power cut

if mode == "exchange":
    real_exchange = export.exchange_paths
    def exchange_then_die(a, b):
        assert real_exchange(a, b)
        die()
    export.exchange_paths = exchange_then_die
else:  # a system without renameat2: the old result is renamed away first
    export.exchange_paths = lambda a, b: False
    for name in ("rename", "replace"):
        def rename_then_die(src, dst, real=getattr(os, name)):
            real(src, dst)
            if str(dst).endswith(".old"):
                die()
        setattr(os, name, rename_then_die)
export.write_material(out, maps, export.ExportOptions(), {"run": 2})
"""


def test_kill_right_after_the_exchange_leaves_the_new_result_in_place(tmp_path: Path) -> None:
    out = write_material(tmp_path / "m", random_maps(8, 8), ExportOptions(), {"run": 1})
    child = run_child(SWAP_CHILD, str(out), "exchange")
    assert child.returncode == -signal.SIGKILL, child.stderr
    # The exchange is one atomic step: OUT/m is the complete new result, the old one is hidden.
    assert material_run(out) == 2
    [stale] = hidden(tmp_path)
    assert stale.startswith(".m.") and stale.endswith(".tmp") and material_run(tmp_path / stale) == 1
    # The next run into the folder removes what the killed process left.
    assert len(recover_outputs(tmp_path)) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"] and material_run(out) == 2


def test_kill_between_the_fallback_renames_is_restored_by_the_next_run(tmp_path: Path) -> None:
    out = write_material(tmp_path / "m", random_maps(8, 8), ExportOptions(), {"run": 1})
    child = run_child(SWAP_CHILD, str(out), "fallback")
    assert child.returncode == -signal.SIGKILL, child.stderr
    assert not out.exists()  # the moment the fallback cannot avoid
    assert [name.rsplit(".", 1)[1] for name in hidden(tmp_path)] == ["old", "tmp"]
    actions = recover_outputs(tmp_path)
    assert any("restored the previous result" in action for action in actions), actions
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"] and material_run(out) == 1


def test_fallback_swap_replaces_the_result_when_no_exchange_is_possible(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(export, "exchange_paths", lambda a, b: False)
    out = write_material(tmp_path / "m", random_maps(8, 8), ExportOptions(), {"run": 1})
    write_material(out, random_maps(8, 8, seed=1), ExportOptions(), {"run": 2})
    assert material_run(out) == 2 and hidden(tmp_path) == []


def test_recover_outputs_removes_only_folders_of_processes_that_are_gone(tmp_path: Path) -> None:
    (tmp_path / "kept").mkdir()
    mine = tmp_path / f".a.{export._owner()}.tmp"  # this process is running: its folder stays
    pid, token, _ = export._owner().split("-")
    reused_pid = tmp_path / f".b.{pid}-{'0' * 8 if token != '0' * 8 else 'f' * 8}-0123abcd.tmp"
    gone = tmp_path / f".c.{2**22 + 1}-0123abcd-0123abcd.tmp"  # above Linux's largest PID
    retired = tmp_path / f".kept.{2**22 + 1}-0123abcd-0123abcd.old"  # its result exists: removed
    lost = tmp_path / f".lost.{2**22 + 1}-0123abcd-0123abcd.old"  # its result is missing: restored
    for folder in (mine, reused_pid, gone, retired, lost):
        folder.mkdir()
        (folder / "material.json").write_text("{}")
    (tmp_path / ".notes.tmp").mkdir()  # not ours (no owner in the name): never touched

    recover_outputs(tmp_path)

    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([mine.name, ".notes.tmp", "kept", "lost"])
    assert (tmp_path / "lost" / "material.json").exists()
    assert recover_outputs(tmp_path / "missing") == []


# --- interrupts and kills mid-batch -------------------------------------------------------------

BATCH_CHILD = """
import os, signal, sys
from brdfgan.inference.outputs import export

sig, args = int(sys.argv[1]), sys.argv[2:]
real_write_glb = export.write_glb
calls = []

def write_glb_then_signal(path, **kwargs):
    calls.append(path)
    real_write_glb(path, **kwargs)
    if len(calls) == 2:  # inside the second photo's staging folder
        os.kill(os.getpid(), sig)

export.write_glb = write_glb_then_signal
from brdfgan.cli import main
sys.exit(main(args))
"""


def batch_args(tmp_path: Path, out: Path, weights: Path) -> list[str]:
    """``brdfgan predict`` on three small flash photos into ``out``, quiet and without previews."""
    photos = [flash_photo(tmp_path / f"p{k}.png") for k in range(3)]
    return [
        "predict",
        *map(str, photos),
        "--out",
        str(out),
        "--weights",
        str(weights),
        "--quiet",
        "--no-preview",
    ]


@pytest.mark.integration
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_signal_mid_batch_leaves_no_staging_folder(
    tmp_path: Path, weights: Path, sig: signal.Signals
) -> None:
    out = tmp_path / "out"
    args = batch_args(tmp_path, out, weights)
    child = run_child(BATCH_CHILD, str(int(sig)), *args)
    if sig == signal.SIGKILL:
        # Nothing can clean up after kill -9: the second photo's staging folder stays ...
        assert child.returncode == -signal.SIGKILL
        [stale] = hidden(out)
        assert stale.startswith(".p1.") and stale.endswith(".tmp")
        # ... until the next run into the same folder, which removes it and completes.
        assert main(args) == 0
    else:
        assert child.returncode == INTERRUPTED_EXIT_CODE, child.stderr
        assert "Traceback" not in child.stderr
        assert child.stderr.strip().splitlines()[-1].startswith("interrupted: ")
        assert sorted(p.name for p in out.iterdir()) == ["p0"]  # finished photo kept, nothing hidden
        assert is_complete(out / "p0")
        assert main(args) == 0
    assert sorted(p.name for p in out.iterdir()) == ["p0", "p1", "p2"]


def is_complete(folder: Path) -> bool:
    """A complete material folder: its material.json lists files that all exist."""
    document = json.loads((folder / "material.json").read_text())
    return all((folder / name).is_file() for name in document["files"])


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_interrupts_raise_makes_signals_a_keyboard_interrupt_that_cleans_up(
    tmp_path: Path, sig: signal.Signals
) -> None:
    def terminated(path: Path) -> None:
        os.kill(os.getpid(), sig)  # lands while the staging folder is being filled
        raise AssertionError(f"{sig.name} did not interrupt")

    # A shell starts background jobs with SIGINT ignored, and interrupts_raise leaves an ignored
    # signal ignored (its docstring): start from the default a terminal gives the process.
    outside = signal.signal(sig, signal.default_int_handler if sig == signal.SIGINT else signal.SIG_DFL)
    try:
        before = signal.getsignal(sig)
        with pytest.raises(KeyboardInterrupt), interrupts_raise():
            write_material(
                tmp_path / "m", random_maps(8, 8), ExportOptions(), {}, extra_files={"x.png": terminated}
            )
        assert list(tmp_path.iterdir()) == []  # no staging folder, no result
        assert signal.getsignal(sig) is before  # the previous handler is back
    finally:
        signal.signal(sig, outside)


# --- a full disk ------------------------------------------------------------------------------


def test_full_disk_stops_the_batch_with_one_line_naming_the_folder(
    tmp_path: Path, weights: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    args = batch_args(tmp_path, out, weights)
    calls: list[Path] = []

    def full_disk(path: Path, **kwargs: object) -> None:
        calls.append(path)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(export, "write_glb", full_disk)
    assert main(args) == DISK_FULL_EXIT_CODE
    captured = capfd.readouterr()
    errors = [line for line in captured.err.splitlines() if line.startswith("error:")]
    assert errors == [f"error: {out / 'p0'}: no space left on device"]
    assert len(calls) == 1  # the later photos were not attempted: they would fail the same way
    assert captured.out == "" and list(out.iterdir()) == []  # no partial or hidden folder
    monkeypatch.undo()  # space freed
    assert main(args) == 0
    assert sorted(p.name for p in out.iterdir()) == ["p0", "p1", "p2"]


# --- inputs that cannot give a material ----------------------------------------------------------


def test_black_and_corrupt_photos_fail_with_one_line_and_stdout_lists_only_results(
    tmp_path: Path, weights: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    good = flash_photo(tmp_path / "good.png")
    black = tmp_path / "black.jpg"
    Image.fromarray(np.zeros((64, 64, 3), np.uint8)).save(black)
    negative = write_image(tmp_path / "negative.exr", np.full((64, 64, 3), -1.0), exr_precision="float")
    full = write_image(
        tmp_path / "full.exr", np.random.default_rng(0).random((64, 64, 3)), exr_precision="float"
    )
    corrupt = tmp_path / "corrupt.exr"
    corrupt.write_bytes(full.read_bytes()[: full.stat().st_size * 2 // 3])
    out = tmp_path / "out"
    capfd.readouterr()
    code = main(["predict", str(good), str(black), str(negative), str(corrupt), "--out", str(out),
                 "--weights", str(weights), "--quiet", "--no-preview"])  # fmt: skip
    captured = capfd.readouterr()
    assert code == 1
    # stdout is the list of output folders, nothing else (OpenEXR's warning used to land here).
    assert captured.out.splitlines() == [str(out / "good")]
    errors = [line for line in captured.err.splitlines() if line.startswith("error:")]
    assert len(errors) == 3 and not any("nan" in line.lower() for line in captured.err.splitlines())
    assert f"error: {black}: is black (every pixel is 0)" in errors[0]
    assert f"error: {negative}: is black (every value is zero or negative)" in errors[1]
    assert errors[2].startswith(f"error: {corrupt}: corrupt or unreadable EXR file: ")
    assert sorted(p.name for p in out.iterdir()) == ["good"]


# --- memory ------------------------------------------------------------------------------------


def test_absurd_resolution_is_refused_up_front_with_the_memory_it_needs(
    tmp_path: Path, weights: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("brdfgan.inference.model.memory.available_memory", lambda: 8 * 2**30)
    photo = flash_photo(tmp_path / "p.png")
    code = main(["predict", str(photo), "--out", str(tmp_path / "out"), "--weights", str(weights),
                 "--quiet", "--resolution", "100000"])  # fmt: skip
    err = capfd.readouterr().err.strip().splitlines()
    assert code == USER_ERROR_EXIT_CODE and "Traceback" not in "".join(err)
    # 1e10 pixels at 320 B each (the maps, the texture arrays being encoded): ~2980 GiB.
    assert err[-1].startswith("error: --resolution 100000 needs ~2981 GiB of memory, 8.0 GiB are available")
    assert "use a smaller --resolution (at most about 5120)" in err[-1]
    assert not (tmp_path / "out").exists()


def test_check_memory_advises_tiles_when_the_untiled_pass_is_what_does_not_fit(tmp_path: Path) -> None:
    # A wide network: its activations (2 x 2 x 64 float32 per pixel) dwarf the export's 320 B.
    wide = Generator(width=64, downsamplings=1, residual_blocks=0)
    model = Model(wide, "wide", "Generator", wide.config(), {"resolution": 2048}, tmp_path / "w.safetensors")
    untiled = TilingConfig(tile=2048, max_direct_pixels=2048 * 2048)
    with pytest.raises(
        PredictError, match=r"needs ~4\.\d GiB of memory, 2\.0 GiB are available; use --tile 1024"
    ):
        check_memory(model, 2048, untiled, available=2 * 2**30)
    check_memory(model, 2048, TilingConfig(), available=2 * 2**30)  # the default tiles fit
    check_memory(model, 2048, untiled, available=5 * 2**30)


def test_the_estimate_does_not_refuse_ordinary_runs() -> None:
    model = load_model()  # the shipped weights: a run at 1024² peaked at 0.75 GB resident
    check_memory(model, 1024, TilingConfig(), available=2**30)
    with pytest.raises(PredictError, match=r"--resolution 4096 needs ~5\.0 GiB"):
        check_memory(model, 4096, TilingConfig(), available=2**30)
