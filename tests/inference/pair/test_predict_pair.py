"""`brdfgan predict FLASH --no-flash NOFLASH`: a flash + no-flash pair → one material (issue 59).

The photos are synthetic pairs (tests/inference/pair/scene.py) saved as JPEGs with the EXIF a
phone writes; a tiny generator runs at 128². The pair fit runs with a few steps (its default
settings only in a slow test; the fit itself is tested on its own).
"""

from __future__ import annotations

import errno
import functools
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import torch
from torch import Tensor

from brdfgan.capture import PAIR
from brdfgan.cli import PARTIAL_FAILURE_EXIT_CODE, main
from brdfgan.errors import USER_ERROR_EXIT_CODE, UserError
from brdfgan.inference.dispatch import Capture, pair_by_name
from brdfgan.inference.intake.photo import read_photo
from brdfgan.inference.intake.preprocess import preprocess
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.outputs import export
from brdfgan.inference.pair import pipeline
from brdfgan.inference.pair.pipeline import predict_pair
from brdfgan.inference.pair.relief_fit import PairFitConfig, PairFitResult, fit_pair
from brdfgan.inference.pipeline import PredictOptions, Predictor, ReferencePrediction, network_reference
from tests.inference import test_predict
from tests.inference.pair import scene

QUICK_FIT = functools.partial(fit_pair, config=PairFitConfig(levels=(16,), steps=(4,)))


weights = test_predict.weights  # the tiny generator's weights file (module-scoped fixture)


@pytest.fixture(scope="module")
def shots(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A pair with EXIF, the same pair without, and a no-flash photo of another surface."""
    folder = tmp_path_factory.mktemp("pair")
    pair = scene.make_pair()
    return {
        "flash": scene.save_jpeg(pair.flash, folder / "wood.jpg", scene.FLASH_SETTINGS),
        "no_flash": scene.save_jpeg(pair.no_flash, folder / "wood_off.jpg", scene.NO_FLASH_SETTINGS),
        "bare_flash": scene.save_jpeg(pair.flash, folder / "bare.jpg", None),
        "bare_no_flash": scene.save_jpeg(pair.no_flash, folder / "bare_off.jpg", None),
        "other": scene.save_jpeg(
            scene.make_pair(no_flash_seed=1).no_flash, folder / "other.jpg", scene.NO_FLASH_SETTINGS
        ),
    }


@pytest.fixture
def quick_fit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pipeline, "fit_pair", QUICK_FIT)


def run(weights: Path, out: Path, *arguments: str | Path) -> int:
    options = ["--weights", str(weights), "--resolution", "128", "--fov", str(scene.FOV_DEG), "--no-preview"]
    return main(["predict", *map(str, arguments), "--out", str(out), *options])


def material(out: Path, name: str) -> dict[str, Any]:
    document: dict[str, Any] = json.loads((out / name / "material.json").read_text())
    return document


def warning_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("warning:")]


def hidden_entries(folder: Path) -> list[str]:
    return [entry.name for entry in folder.iterdir() if entry.name.startswith(".")] if folder.exists() else []


def test_the_cli_writes_the_pairs_material_with_its_record(
    weights: Path, shots: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], quick_fit: None
) -> None:
    check_the_pairs_material(weights, shots, tmp_path, capsys)


@pytest.mark.slow
def test_the_cli_with_the_default_fit_writes_the_pairs_material(
    weights: Path, shots: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """As above with the fit's default settings (about a minute on 2 busy cores at 128²)."""
    check_the_pairs_material(weights, shots, tmp_path, capsys)


def check_the_pairs_material(
    weights: Path, shots: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    code = run(weights, out, shots["flash"], "--no-flash", shots["no_flash"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert captured.out.strip() == str(out / "wood") and [p.name for p in out.iterdir()] == ["wood"]
    document = material(out, "wood")
    pair = document["pair"]
    assert pair["used"] is True and pair["fallback"] is None
    assert pair["flash"]["file"] == str(shots["flash"]) and pair["no_flash"]["file"] == str(shots["no_flash"])
    assert pair["flash"]["exposure"]["iso"] == 100.0 and pair["no_flash"]["exposure"]["iso"] == 320.0
    assert pair["exposure_ratio"] == {"value": pytest.approx(scene.RATIO), "source": "exif"}
    registration = pair["registration"]
    assert registration["method"] == "sift" and registration["inliers"] >= 40
    assert registration["reprojection_px"] < 0.5 and len(registration["homography"]) == 3
    # Through JPEG (4:2:0, quality 95, compressed in gamma space) a few per cent; 0.5 % without.
    assert pair["white_balance"]["gains"] == pytest.approx(list(scene.true_gains()), rel=0.05)
    assert pair["flash_to_room"] > 1.0 and pair["valid_fraction"] > 0.9
    # The fit ran and recorded itself; no --refine with a pair.
    assert document["pair_fit"]["kept"] in ("fit", "prediction", "flat") and document["refinement"] is None
    assert document["input"]["file"] == str(shots["flash"])
    assert all(
        str(shots["flash"]) in line or str(shots["no_flash"]) in line for line in warning_lines(captured.err)
    )
    assert hidden_entries(out) == []


def test_a_folder_run_pairs_each_photo_with_its_noflash_photo(
    weights: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], quick_fit: None
) -> None:
    pair = scene.make_pair()
    folder = tmp_path / "shots"
    folder.mkdir()
    scene.save_jpeg(pair.flash, folder / "wood.jpg", scene.FLASH_SETTINGS)
    scene.save_jpeg(pair.no_flash, folder / "wood_noflash.JPG", scene.NO_FLASH_SETTINGS)
    scene.save_jpeg(pair.flash, folder / "tiles.jpg", scene.FLASH_SETTINGS)  # no no-flash photo
    out = tmp_path / "out"
    code = run(weights, out, folder, "--no-flash")
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert sorted(p.name for p in out.iterdir()) == ["tiles", "wood"]
    assert material(out, "wood")["pair"]["no_flash"]["file"] == str(folder / "wood_noflash.JPG")
    assert material(out, "tiles")["pair"] is None
    assert any(
        line.startswith(f"warning: {folder / 'tiles.jpg'}: no no-flash photo (tiles_noflash.*)")
        for line in warning_lines(captured.err)
    )
    assert "2 material(s)" in captured.err


def test_only_no_flash_photos_are_a_one_line_error(
    weights: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lone = scene.save_jpeg(scene.make_pair().no_flash, tmp_path / "wood_noflash.jpg", None)
    assert run(weights, tmp_path / "out", lone, "--no-flash") == USER_ERROR_EXIT_CODE
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert errors == ["error: no flash photos to process"] and not (tmp_path / "out").exists()


def test_photos_pair_by_name_in_a_folder_or_beside_the_flash_photo(tmp_path: Path) -> None:
    for name in (
        "a.jpg",
        "a_noflash.png",
        "a_noflash.jpg",
        "b.dng",
        "c_NoFlash.heic",
        "d.jpg",
        "d_noflash.jpg",
    ):
        (tmp_path / name).touch()
    inputs = [
        tmp_path / name for name in ("a.jpg", "a_noflash.png", "a_noflash.jpg", "b.dng", "c_NoFlash.heic")
    ]
    captures = pair_by_name(PAIR, [*inputs, tmp_path / "d.jpg"])
    assert captures == [
        Capture(PAIR, (tmp_path / "a.jpg", tmp_path / "a_noflash.jpg"), "a"),  # the same format first
        Capture(PAIR, (tmp_path / "b.dng",), "b"),
        # Not among the inputs, but beside the flash photo.
        Capture(PAIR, (tmp_path / "d.jpg", tmp_path / "d_noflash.jpg"), "d"),
    ]


def test_two_different_surfaces_fall_back_to_the_single_photo_with_one_line(
    weights: Path, shots: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], quick_fit: None
) -> None:
    out = tmp_path / "out"
    code = run(weights, out, shots["flash"], "--no-flash", shots["other"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    fallbacks = [line for line in warning_lines(captured.err) if "single-photo" in line]
    assert len(fallbacks) == 1
    assert fallbacks[0].startswith(
        f"warning: {shots['flash']}: its no-flash photo {shots['other']} cannot serve (it does not register "
    )
    document = material(out, "wood")
    assert document["pair"]["used"] is False and "does not register" in document["pair"]["fallback"]
    assert document["pair"]["registration"] is None and document["pair_fit"] is None


def test_without_exif_the_option_gives_the_ratio_and_without_it_a_warning(
    weights: Path, shots: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], quick_fit: None
) -> None:
    out = tmp_path / "out"
    assert run(weights, out, shots["bare_flash"], "--no-flash", shots["bare_no_flash"]) == 0
    captured = capsys.readouterr()
    (fallback,) = [line for line in warning_lines(captured.err) if "single-photo" in line]
    assert "does not state its exposure" in fallback and "--exposure-ratio R" in fallback
    assert material(out, "bare")["pair"]["exposure_ratio"] is None
    code = run(
        weights, out, shots["bare_flash"], "--no-flash", shots["bare_no_flash"], "--exposure-ratio", "0.3125"
    )
    assert code == 0, capsys.readouterr().err
    pair = material(out, "bare")["pair"]
    assert pair["used"] is True and pair["exposure_ratio"] == {"value": 0.3125, "source": "option"}


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (
            ("flash", "--exposure-ratio", "0.5"),
            "error: --exposure-ratio applies to a flash + no-flash pair (--no-flash)",
        ),
        (
            ("flash", "bare_flash", "--no-flash", "no_flash"),
            "error: --no-flash NOFLASH goes with one photo, got 2;",
        ),
        (
            ("flash", "--no-flash", "no_flash", "--refine"),
            "error: --refine cannot be combined with --no-flash",
        ),
        (
            ("flash", "--no-flash", "no_flash", "--views"),
            "error: choose one kind of capture: --views or --no-flash",
        ),
    ],
)
def test_misused_options_are_one_line_usage_errors(
    weights: Path,
    shots: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    arguments: tuple[str, ...],
    message: str,
) -> None:
    out = tmp_path / "out"
    code = run(weights, out, *(str(shots.get(argument, argument)) for argument in arguments))
    captured = capsys.readouterr()
    assert code == USER_ERROR_EXIT_CODE
    assert len(captured.err.strip().splitlines()) == 1 and captured.err.startswith(message), captured.err
    assert not out.exists()


def test_an_unreadable_no_flash_photo_is_one_line_naming_it_and_writes_nothing(
    weights: Path, shots: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    broken = tmp_path / "broken_noflash.jpg"
    broken.write_bytes(b"not a photo")
    out = tmp_path / "out"
    code = run(weights, out, shots["flash"], "--no-flash", broken)
    captured = capsys.readouterr()
    assert code == PARTIAL_FAILURE_EXIT_CODE
    (error,) = [line for line in captured.err.splitlines() if line.startswith("error:")]
    assert error.startswith(f"error: {shots['flash']}: its no-flash photo {broken}: not an image file")
    assert not out.exists() or list(out.iterdir()) == []


def test_the_fit_reads_the_flash_only_image_and_writes_into_the_flash_photos_maps(
    weights: Path, shots: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    readings: list[tuple[Tensor, Tensor]] = []  # (the network's input, its maps)

    def recording_reference(*args: Any) -> ReferencePrediction:
        reference = network_reference(*args)
        readings.append((reference.prepared.photo, reference.maps))
        return reference

    calls: list[dict[str, Tensor]] = []

    def recording_fit(*args: Any, written: Tensor | None = None, **kwargs: Any) -> PairFitResult:
        assert written is not None
        calls.append({"maps": args[3], "written": written})  # (flash_only, room, valid, maps, frame)
        return QUICK_FIT(*args, written=written, **kwargs)

    monkeypatch.setattr(pipeline, "network_reference", recording_reference)
    predictor = Predictor.create(load_model(weights), PredictOptions(resolution=128, preview=False))
    predict_pair([shots["flash"], shots["no_flash"]], tmp_path / "wood", predictor, fit=recording_fit)
    flash_photo = preprocess(read_photo(shots["flash"]), 128).photo
    ((photo_input, photo_maps),) = [reading for reading in readings if torch.equal(reading[0], flash_photo)]
    ((flash_only_input, flash_only_maps),) = [reading for reading in readings if reading[1] is not photo_maps]
    assert torch.equal(photo_input, flash_photo) and not torch.allclose(flash_only_input, flash_photo)
    (call,) = calls
    assert call["maps"] is flash_only_maps and call["written"] is photo_maps


def failing_fit(*_: Any, **__: Any) -> PairFitResult:
    raise UserError("the fit failed half-way")


@pytest.mark.parametrize("fit", [failing_fit, None])
def test_a_failure_at_any_stage_leaves_nothing_half_written(
    weights: Path,
    shots: dict[str, Path],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    fit: Callable[..., PairFitResult] | None,
) -> None:
    """The fit fails, or the write-out does after some files: the output folder is never left
    half-written (an earlier material there stays whole)."""
    predictor = Predictor.create(load_model(weights), PredictOptions(resolution=128, preview=False))
    out_dir = tmp_path / "out" / "wood"
    out_dir.mkdir(parents=True)
    (out_dir / "material.json").write_text("{}")  # an earlier run's
    if fit is None:  # the glb is written after the textures

        def full_disk(path: Path, **kwargs: object) -> None:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

        monkeypatch.setattr(export, "write_glb", full_disk)
        fit = QUICK_FIT
    with pytest.raises((UserError, OSError)):
        predict_pair([shots["flash"], shots["no_flash"]], out_dir, predictor, fit=fit)
    assert [p.name for p in out_dir.iterdir()] == ["material.json"]
    assert (out_dir / "material.json").read_text() == "{}"
    assert hidden_entries(out_dir.parent) == []
