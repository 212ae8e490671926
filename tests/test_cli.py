"""The ``brdfgan`` console: its subcommands, and which errors end a command with one line."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from brdfgan import __version__
from brdfgan.cli import build_parser, main
from brdfgan.data.storage.shards import Sample, shard_path, write_shard
from brdfgan.errors import (
    DISK_FULL_EXIT_CODE,
    INTERRUPTED_EXIT_CODE,
    USER_ERROR_EXIT_CODE,
    DiskFullError,
    UserError,
    run_reporting_errors,
)
from brdfgan.runs import load_weights
from tests.conftest import random_maps, run_python

COMMANDS = (
    "predict", "export-weights", "contact-sheet", "convert-deschaintre", "report", "references",
    "dataset-stats",
)  # fmt: skip


def test_every_subcommand_has_a_one_line_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    listing = capsys.readouterr().out
    for command in COMMANDS:
        assert f"    {command}" in listing
        with pytest.raises(SystemExit):
            main([command, "--help"])
        assert capsys.readouterr().out.startswith(f"usage: brdfgan {command} ")


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0 and capsys.readouterr().out.strip() == f"brdfgan {__version__}"


def test_every_subcommand_names_its_interrupt_message() -> None:
    parser = build_parser()
    required = {
        "export-weights": ["RUN"],
        "contact-sheet": ["DATA"],
        "convert-deschaintre": ["SRC", "OUT"],
        "report": ["RUN"],
        "references": ["DATA", "--out", "OUT"],
        "predict": ["P", "--out", "O"],
        "dataset-stats": ["DATA"],
    }
    messages = {command: parser.parse_args([command, *required[command]]).interrupted for command in COMMANDS}
    assert messages["predict"].startswith("interrupted: finished photos are complete")
    assert all(message.startswith("interrupted") for message in messages.values())


def test_user_errors_and_full_disks_are_one_line_bugs_keep_their_traceback(
    capsys: pytest.CaptureFixture[str],
) -> None:
    def fail(error: BaseException) -> int:
        raise error

    assert run_reporting_errors(lambda: fail(UserError("x.png: not a photo"))) == USER_ERROR_EXIT_CODE
    assert capsys.readouterr().err == "error: x.png: not a photo\n"
    assert run_reporting_errors(lambda: fail(DiskFullError("out/m"))) == DISK_FULL_EXIT_CODE
    assert capsys.readouterr().err == "error: out/m: no space left on device\n"
    assert run_reporting_errors(lambda: fail(KeyboardInterrupt()), interrupted="interrupted: kept") == (
        INTERRUPTED_EXIT_CODE
    )
    assert capsys.readouterr().err == "interrupted: kept\n"
    with pytest.raises(ValueError, match="a bug"):  # a plain ValueError is not the user's to fix
        run_reporting_errors(lambda: fail(ValueError("a bug")))


def test_an_interrupt_a_native_library_re_raised_is_still_an_interrupt(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A signal inside Mitsuba's render callback comes back as drjit's RuntimeError raised *from*
    the KeyboardInterrupt (seen in CI as a traceback instead of generate's one line, exit 130)."""
    import drjit as dr
    import mitsuba as mi

    from brdfgan.errors import exit_on_user_error

    mi.set_variant("scalar_rgb")

    class InterruptedOp(dr.CustomOp):  # type: ignore[misc]
        def eval(self, x: object) -> object:
            raise KeyboardInterrupt

    def render() -> int:
        dr.custom(InterruptedOp, mi.Float(1.0))
        return 0

    assert run_reporting_errors(render, interrupted="interrupted: kept") == INTERRUPTED_EXIT_CODE
    assert capsys.readouterr().err == "interrupted: kept\n"
    with pytest.raises(SystemExit) as exited:
        exit_on_user_error(render, interrupted="interrupted: kept")()
    assert exited.value.code == INTERRUPTED_EXIT_CODE
    assert capsys.readouterr().err == "interrupted: kept\n"

    def cleanup_fails() -> int:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise ValueError("a bug in the cleanup") from None  # not *from* the interrupt

    with pytest.raises(ValueError, match="a bug in the cleanup"):
        run_reporting_errors(cleanup_fails)


def test_references_writes_the_three_weight_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    maps = [random_maps(8, 8, seed=seed) for seed in range(3)]
    samples = [Sample(f"train-{i}", torch.rand(3, 8, 8), m, meta={}) for i, m in enumerate(maps)]
    write_shard(shard_path(tmp_path / "data", "train", 0), samples)
    assert main(["references", str(tmp_path / "data"), "--out", str(tmp_path / "refs")]) == 0
    written = [Path(line) for line in capsys.readouterr().out.split()]
    assert [p.name for p in written] == [
        "mean_maps.safetensors",
        "photo_basecolor.safetensors",
        "de_lit.safetensors",
    ]
    delit, meta = load_weights(written[2])
    assert delit(torch.rand(1, 3, 4, 4)).shape == (1, 8, 4, 4) and "gain" in meta["extra"]
    assert (
        main(["references", str(tmp_path / "data"), "--out", str(tmp_path / "only"), "--only", "de_lit"]) == 0
    )
    assert capsys.readouterr().out.split() == [str(tmp_path / "only" / "de_lit.safetensors")]
    assert main(["references", str(tmp_path / "data"), "--out", str(tmp_path / "x"), "--only", "median"]) != 0
    constant, _ = load_weights(written[0])
    predicted = constant(torch.rand(1, 3, 4, 4))[0, :, 0, 0].double()
    expected = torch.stack(maps).double().mean(dim=(0, 2, 3))  # base colour, roughness, metallic
    assert torch.allclose(predicted[[0, 1, 2, 6, 7]], expected[[0, 1, 2, 6, 7]], atol=1e-3)


@pytest.mark.integration
def test_a_user_error_is_one_line_from_the_console_script(tmp_path: Path) -> None:
    result = run_python("-m", "brdfgan.cli", "report", str(tmp_path), cwd=tmp_path)
    assert result.returncode == USER_ERROR_EXIT_CODE
    assert result.stderr.startswith("error: ") and result.stderr.count("\n") == 1, result.stderr
