"""Real multi-view captures as an evaluation input (brdfgan.evaluation.real_captures, ``eval-captures``),
on synthetic captures rendered with our own renderer in both of MaterialGAN's layouts."""

from __future__ import annotations

import json
import logging
import math
import shutil
from collections.abc import Sequence
from pathlib import Path

import pytest
import torch
from torch import Tensor

from brdfgan.cli import build_parser, main
from brdfgan.core.delit import flat_flash_falloff
from brdfgan.core.render import PointLights, plane_positions, render_point_lights
from brdfgan.core.svbrdf import flat_maps, linear_to_srgb, srgb_to_linear
from brdfgan.errors import USER_ERROR_EXIT_CODE
from brdfgan.evaluation.real_captures import (
    CaptureError,
    CaptureModel,
    capture_flash_frame,
    capture_models,
    csv_table,
    evaluate_captures,
    find_captures,
    fit_gain,
    markdown_table,
    read_capture,
)
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.views.config import ViewFitConfig
from brdfgan.io.images import write_image
from brdfgan.models.reference import DeLitPhoto, PhotoAsBasecolor
from brdfgan.runs import save_weights
from tests.conftest import random_maps

SIDE = 64
IMAGE_SIZE = 20.0  # cm
POWER = (2500.0, 2400.0, 2300.0)
# Nine cameras a few cm off-centre, 30–50 cm above the sample; the flash 1.2 cm right of each lens.
CAMERAS = (
    (1.5, -2.0, 40.0), (6.0, 4.0, 35.0), (-5.0, 3.0, 45.0), (-4.0, -6.0, 38.0), (7.0, -3.0, 42.0),
    (0.0, 7.0, 33.0), (-7.0, 0.0, 48.0), (3.0, 5.0, 30.0), (-2.0, -7.0, 50.0),
)  # fmt: skip
FLASH_OFFSET = (1.2, 0.4, 0.0)


def _lights() -> list[tuple[float, float, float]]:
    return [(x + FLASH_OFFSET[0], y + FLASH_OFFSET[1], z + FLASH_OFFSET[2]) for x, y, z in CAMERAS]


def _render_views(maps: Tensor) -> Tensor:
    """The nine linear views of ``maps`` ``(8, SIDE, SIDE)``: ``(9, 3, SIDE, SIDE)``."""
    views = len(CAMERAS)
    lights = PointLights(
        position=torch.tensor(_lights(), dtype=torch.float64).view(1, views, 1, 3),
        intensity=torch.ones(1, views, 1, dtype=torch.float64),
        color=torch.tensor(POWER, dtype=torch.float64).expand(1, views, 1, 3),
    )
    camera = torch.tensor(CAMERAS, dtype=torch.float64).view(1, views, 3)
    return render_point_lights(maps[None].double(), camera, lights, IMAGE_SIZE / 2)[0]


def write_capture(folder: Path, maps: Tensor, layout: str = "json") -> Path:
    """A capture of ``maps``: nine 8-bit sRGB views and the calibration in ``layout``."""
    folder.mkdir(parents=True)
    for index, view in enumerate(_render_views(maps)):
        srgb = linear_to_srgb(view.clamp(0.0, 1.0)).permute(1, 2, 0).numpy()
        write_image(folder / f"{index:02d}.png", srgb)
    if layout == "json":
        parameters = {
            "_comment": "in cm uint",
            "image_size": IMAGE_SIZE,
            "idx": list(range(len(CAMERAS))),
            "camera_pos": [list(c) for c in CAMERAS],
            "light_pos": [list(c) for c in _lights()],
            "light_pow": list(POWER),
        }
        (folder / "parameters.json").write_text(json.dumps(parameters, indent=2))
    else:  # MaterialGAN's text files: commas (np.savetxt) for the camera, spaces for the light
        (folder / "camera_pos.txt").write_text("".join(f"{x:.4f},{y:.4f},{z:.4f}\n" for x, y, z in CAMERAS))
        (folder / "light_pos.txt").write_text("".join(f"{x} {y} {z}\n" for x, y, z in _lights()))
        (folder / "image_size.txt").write_text(f"{IMAGE_SIZE:.4f}\n")
        (folder / "light_power.txt").write_text(",".join(f"{p:.4f}" for p in POWER) + "\n")
    return folder


def truth_model(maps: Tensor) -> CaptureModel:
    """A predictor that returns the true maps whatever it is shown."""
    return CaptureModel("truth", lambda photo, frame: maps.float().clone(), resolution=None)


def matte_maps() -> Tensor:
    """A matte, relief-free dielectric: a smooth, asymmetric, low-contrast base colour."""
    rows = torch.linspace(0.0, 1.0, SIDE).view(SIDE, 1)
    columns = torch.linspace(0.0, 1.0, SIDE).view(1, SIDE)
    pattern = 0.5 + 0.5 * torch.sin(5.0 * columns + 2.0 * rows) * torch.cos(3.0 * rows)
    maps = flat_maps(SIDE, SIDE, roughness=0.9)
    maps[0] = 0.45 + 0.2 * pattern
    maps[1] = 0.40 + 0.15 * pattern.flip(0)
    maps[2] = 0.35 + 0.1 * pattern.flip(1)
    return maps


def write_references(
    folder: Path, only: Sequence[str] = ("photo_basecolor", "de_lit"), roughness: float = 0.5
) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    modules: dict[str, PhotoAsBasecolor | DeLitPhoto] = {
        "photo_basecolor": PhotoAsBasecolor(),
        "de_lit": DeLitPhoto(),
    }
    for name in only:
        module = modules[name]
        module.roughness.fill_(roughness)
        target = f"brdfgan.models.reference.{type(module).__name__}"
        save_weights(folder / f"{name}.safetensors", module, target=target, config={}, model_id=name)
    return folder


# --- reading --------------------------------------------------------------------------------------


def test_both_layouts_read_the_same(tmp_path: Path) -> None:
    maps = random_maps(SIDE, SIDE, seed=3)
    new = read_capture(write_capture(tmp_path / "new", maps, "json"))
    old = read_capture(write_capture(tmp_path / "old", maps, "txt"))
    assert (new.layout, old.layout) == ("json", "txt")
    assert new.side == old.side == SIDE and new.view_ids == old.view_ids == tuple(range(9))
    assert torch.allclose(new.camera_pos, old.camera_pos) and torch.allclose(new.light_pos, old.light_pos)
    assert new.light_pow == old.light_pow == POWER and new.image_size == old.image_size == IMAGE_SIZE
    results = evaluate_captures([new, old], [truth_model(maps)])
    for a, b in zip(
        [v for v in results.views if v.capture == "new"],
        [v for v in results.views if v.capture == "old"],
        strict=True,
    ):
        assert a.rmse_fitted == pytest.approx(b.rmse_fitted, abs=1e-6) and a.gain == pytest.approx(
            b.gain, rel=1e-6
        )


def test_old_layout_without_light_file_has_the_flash_at_the_camera(tmp_path: Path) -> None:
    folder = write_capture(tmp_path / "old", random_maps(SIDE, SIDE), "txt")
    (folder / "light_pos.txt").unlink()
    (folder / "light_power.txt").write_text("1500\n")
    capture = read_capture(folder)
    assert torch.equal(capture.light_pos, capture.camera_pos) and capture.light_pow == (1500.0,) * 3


def test_views_in_svbrdf_diff_renderers_images_folder(tmp_path: Path) -> None:
    folder = write_capture(tmp_path / "card", random_maps(SIDE, SIDE), "json")
    where = folder / "images" / "reference" / str(SIDE)
    where.mkdir(parents=True)
    (folder / "images" / "reference" / "1024").mkdir()  # empty: skipped
    for view in sorted(folder.glob("*.png")):
        shutil.move(view, where / view.name)
    parameters = json.loads((folder / "parameters.json").read_text())
    parameters.update(images_dir="images", idx=[0, 2, 4])
    (folder / "parameters.json").write_text(json.dumps(parameters))
    capture = read_capture(folder)
    assert capture.views == tuple(where / f"{i:02d}.png" for i in (0, 2, 4))
    assert torch.equal(capture.camera_pos, torch.tensor(CAMERAS, dtype=torch.float64)[[0, 2, 4]])


def test_a_folder_of_captures(tmp_path: Path) -> None:
    maps = random_maps(SIDE, SIDE)
    write_capture(tmp_path / "set" / "b", maps, "txt")
    write_capture(tmp_path / "set" / "a", maps, "json")
    (tmp_path / "set" / "notes").mkdir()  # no capture: ignored
    captures = find_captures([tmp_path / "set", tmp_path / "set" / "a"])  # "a" twice: once
    assert [c.name for c in captures] == ["a", "b"]


# --- geometry and scores --------------------------------------------------------------------------


def test_the_flash_frame_is_the_calibrated_flash(tmp_path: Path) -> None:
    """The frame's flat-surface falloff is the flash's cos θ / r² on the plane, relative to its
    foot: the hotspot (row 0 = +y) and the scale (in flash heights) are right."""
    capture = read_capture(write_capture(tmp_path / "c", random_maps(SIDE, SIDE)))
    for view in (0, 4):
        light = capture.light_pos[view]
        points = plane_positions(SIDE, SIDE, IMAGE_SIZE / 2, dtype=torch.float64)
        offset = light.view(3, 1, 1) - points
        irradiance = offset[2] / offset.square().sum(dim=0) ** 1.5  # cos θ / r²
        expected = irradiance * float(light[2]) ** 2  # 1 at the foot of the flash
        frame = capture_flash_frame(capture, view).double()
        assert torch.allclose(flat_flash_falloff(frame, SIDE, SIDE)[0, 0], expected, rtol=1e-5)


def test_fit_gain_is_least_squares_over_unsaturated_pixels() -> None:
    render = torch.rand(3, 8, 8, dtype=torch.float64) + 0.1
    photo = 0.7 * render
    photo[:, 0, 0] = 1.0  # saturated: left out
    assert fit_gain(render, photo) == pytest.approx(0.7)
    assert fit_gain(torch.zeros(3, 4, 4), torch.rand(3, 4, 4)) == 1.0


def test_fit_gain_leaves_out_a_highlight_the_photo_tone_mapped() -> None:
    # A glossy sample's highlight: the render is 4× too bright for the photo there, which a phone's
    # tone curve rolled off just under saturation; left in, it pulls the gain to ~0.5.
    render = torch.rand(3, 16, 16, dtype=torch.float64) * 0.5 + 0.1
    photo = 0.7 * render
    render[:, :3, :3] = 6.0
    photo[:, :3, :3] = 0.97
    assert fit_gain(render, photo) == pytest.approx(0.7)
    photo[:, :3, :3] = 1.0  # clipped in the photo: left out on the first pass already
    assert fit_gain(render, photo) == pytest.approx(0.7)


def test_the_true_maps_relight_every_view(tmp_path: Path) -> None:
    maps = random_maps(SIDE, SIDE, seed=1)
    capture = read_capture(write_capture(tmp_path / "c", maps))
    results = evaluate_captures([capture], [truth_model(maps)])
    relit = [v for v in results.views if v.role == "relit"]
    assert len(relit) == 8 and [v.view for v in results.views if v.role == "input"] == [0]
    assert all(v.rmse_fitted < 0.01 and v.rmse_calibrated < 0.01 for v in results.views)  # 8-bit only
    assert relit[0].gain == pytest.approx(1.0, abs=0.01)
    assert results.mean("truth") == pytest.approx(sum(v.rmse_fitted for v in relit) / 8)


def test_a_wrong_albedo_scale_is_removed_by_the_fitted_gain(tmp_path: Path) -> None:
    maps = random_maps(SIDE, SIDE, seed=2)
    dark = maps.clone()
    dark[0:3] = linear_to_srgb(srgb_to_linear(maps[0:3]) * 0.5)  # half the albedo (linear)
    capture = read_capture(write_capture(tmp_path / "c", maps))
    results = evaluate_captures([capture], [CaptureModel("dark", lambda photo, frame: dark.clone())])
    assert results.views[0].gain > 1.3
    assert results.mean("dark") < 0.5 * results.mean("dark", "rmse_calibrated")


def test_de_lit_beats_photo_as_base_colour_on_a_matte_flat_material(tmp_path: Path) -> None:
    capture = read_capture(write_capture(tmp_path / "matte", matte_maps()))
    # The references with the material's roughness: they differ in the base colour alone.
    refs = write_references(tmp_path / "refs", roughness=0.9)
    models = capture_models(refs / "photo_basecolor.safetensors", refs)  # --weights is a reference too
    assert [m.name for m in models] == ["photo_basecolor", "de_lit"]
    results = evaluate_captures([capture], [*models, truth_model(matte_maps())])
    photo, delit, truth = (results.mean(name) for name in ("photo_basecolor", "de_lit", "truth"))
    # Measured: 0.0011 < 0.0035 < 0.0078 (the photo keeps the input view's falloff in its albedo).
    assert truth < delit < 0.6 * photo, (truth, delit, photo)


# --- errors ---------------------------------------------------------------------------------------


def _edit_json(folder: Path, **changes: object) -> None:
    parameters = json.loads((folder / "parameters.json").read_text())
    for key, value in changes.items():
        if value is None:
            del parameters[key]
        else:
            parameters[key] = value
    (folder / "parameters.json").write_text(json.dumps(parameters))


BAD_CAPTURES = {
    "missing view": (
        lambda f: (f / "05.png").unlink(),
        r"05\.png: missing view 05 \(parameters\.json lists 9",
    ),
    "missing key": (
        lambda f: _edit_json(f, image_size=None),
        r"parameters\.json: key 'image_size' is missing",
    ),
    "short position": (
        lambda f: _edit_json(
            f, camera_pos=[list(c) for c in CAMERAS[:3]] + [[1.0, 2.0]] + [list(c) for c in CAMERAS[4:]]
        ),
        r"parameters\.json: camera_pos\[3\]: expected \[x, y, z\]",
    ),
    "below the sample": (
        lambda f: _edit_json(f, light_pos=[[0.0, 0.0, -3.0]] * 9),
        r"parameters\.json: light_pos\[0\]: z = -3",
    ),
    "bad power": (
        lambda f: _edit_json(f, light_pow=[1, 2]),
        r"parameters\.json: light_pow: expected one number",
    ),
    "bad idx": (lambda f: _edit_json(f, idx=[0, 12]), r"parameters\.json: camera_pos: no entry for view 12"),
    "not json": (
        lambda f: (f / "parameters.json").write_text("{camera_pos"),
        r"parameters\.json: not valid JSON",
    ),
    "wrong size": (
        lambda f: write_image(f / "03.png", torch.rand(32, 32, 3).numpy()),
        r"03\.png: 32×32 pixels, but 00\.png is 64×64",
    ),
    "not square": (
        lambda f: write_image(f / "00.png", torch.rand(64, 48, 3).numpy()),
        r"00\.png: 48×64 pixels; .* square",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_CAPTURES))
def test_bad_captures_name_the_file_and_key(tmp_path: Path, case: str) -> None:
    folder = write_capture(tmp_path / "c", random_maps(SIDE, SIDE), "json")
    spoil, message = BAD_CAPTURES[case]
    spoil(folder)
    with pytest.raises(CaptureError, match=message):
        find_captures([folder])


BAD_TEXT_FILES = {
    "image_size.txt": ("abc\n", r"image_size\.txt: line 1: expected numbers"),
    "light_power.txt": (None, r"light_power\.txt: not found"),
    "camera_pos.txt": ("1,2,30\n4,5\n", r"camera_pos\.txt\[1\]: expected \[x, y, z\]"),
    "light_pos.txt": ("1 2 30\n", r"light_pos\.txt: 1 positions, but camera_pos\.txt has 9"),
}


@pytest.mark.parametrize("name", sorted(BAD_TEXT_FILES))
def test_bad_text_files_are_named(tmp_path: Path, name: str) -> None:
    folder = write_capture(tmp_path / "c", random_maps(SIDE, SIDE), "txt")
    text, message = BAD_TEXT_FILES[name]
    if text is None:
        (folder / name).unlink()
    else:
        (folder / name).write_text(text)
    with pytest.raises(CaptureError, match=message):
        read_capture(folder)


def test_a_folder_without_captures_is_an_error(tmp_path: Path) -> None:
    (tmp_path / "empty" / "sub").mkdir(parents=True)
    with pytest.raises(CaptureError, match="neither a capture folder"):
        find_captures([tmp_path / "empty"])
    with pytest.raises(CaptureError, match="no such folder"):
        find_captures([tmp_path / "missing"])


# --- the command ------------------------------------------------------------------------------------


def test_cli_writes_the_table_and_the_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_capture(tmp_path / "set" / "tiles", matte_maps(), "json")
    write_capture(tmp_path / "set" / "cards", random_maps(SIDE, SIDE, seed=5), "txt")
    refs = write_references(tmp_path / "refs")
    out = tmp_path / "out"
    args = ["eval-captures", str(tmp_path / "set"), "--references", str(refs), "--out", str(out),
            "--refine", "2", "--resolution", "64"]  # fmt: skip
    assert main(args) == 0
    printed = capsys.readouterr().out
    markdown = (out / "captures.md").read_text()
    assert printed == markdown
    header = next(line for line in markdown.splitlines() if line.startswith("| model"))
    assert header == "| model | relit (fitted gain) | relit (calibrated power) | cards | tiles |"
    rows = [line.split(" | ")[0].lstrip("| ") for line in markdown.splitlines() if line.startswith("| ")][1:]
    shipped = load_model().model_id  # the default weights: eval-captures' first model
    assert rows == [shipped, f"{shipped}+refine2", "photo_basecolor", "de_lit"]
    lines = (out / "captures.csv").read_text().splitlines()
    assert lines[0] == "model,capture,view,role,gain,rmse_fitted_gain,rmse_calibrated_power"
    assert len(lines) == 1 + 4 * 2 * 9  # models × captures × views
    for line in lines[1:]:
        value = float(line.split(",")[5])
        assert math.isfinite(value) and 0.0 <= value < 1.0


def test_cli_warns_about_a_missing_reference(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    # An earlier `predict --quiet` in this process raised the package logger's level: set it here.
    caplog.set_level(logging.WARNING, logger="brdfgan")
    write_capture(tmp_path / "tiles", matte_maps(), "json")
    refs = write_references(tmp_path / "refs", only=("photo_basecolor",))
    args = ["eval-captures", str(tmp_path / "tiles"), "--references", str(refs)]  # each model's resolution
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "de_lit.safetensors: no such reference weights file" in caplog.text  # stderr outside pytest
    assert "| de_lit |" not in captured.out and "| photo_basecolor |" in captured.out
    assert (tmp_path / "tiles" / "captures.md").is_file()  # default --out: the first DIR


def test_cli_bad_capture_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = write_capture(tmp_path / "c", random_maps(SIDE, SIDE), "txt")
    (folder / "image_size.txt").write_text("-3\n")
    assert main(["eval-captures", str(folder), "--out", str(tmp_path / "out")]) == USER_ERROR_EXIT_CODE
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "image_size.txt" in err, err
    assert not (tmp_path / "out").exists()


def test_cli_help_and_interrupt_message(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["eval-captures", "--help"])
    assert info.value.code == 0 and capsys.readouterr().out.startswith("usage: brdfgan eval-captures ")
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "    eval-captures" in capsys.readouterr().out
    assert build_parser().parse_args(["eval-captures", "DIR"]).interrupted.startswith("interrupted")


# --- --fit-views ------------------------------------------------------------------------------------

# A cheap fit for 64² views (tests/inference/views/test_views_fit.py's FAST): a few seconds single-threaded.
FAST_FIT = ViewFitConfig(levels=(32, 64), steps=(40, 40))


def five_view_capture(folder: Path, maps: Tensor) -> Path:
    """A capture of ``maps`` that lists its first five views."""
    write_capture(folder, maps, "json")
    _edit_json(folder, idx=list(range(5)))
    return folder


def grey_model() -> CaptureModel:
    """A deliberately wrong predictor: flat grey whatever it is shown."""
    return CaptureModel("grey", lambda photo, frame: flat_maps(photo.shape[-2], photo.shape[-1]))


def test_fit_views_one_is_todays_protocol(tmp_path: Path) -> None:
    capture = read_capture(write_capture(tmp_path / "c", random_maps(SIDE, SIDE, seed=4)))
    models = [truth_model(random_maps(SIDE, SIDE, seed=4)), grey_model()]
    today = evaluate_captures([capture], models)
    one = evaluate_captures([capture], models, fit_views=1)
    assert one == today and one.models == ("truth", "grey")
    assert markdown_table(one) == markdown_table(today) and csv_table(one) == csv_table(today)


def test_fitting_three_views_scores_the_others_and_beats_one_view(tmp_path: Path) -> None:
    capture = read_capture(five_view_capture(tmp_path / "c", random_maps(SIDE, SIDE, seed=6)))
    single = evaluate_captures([capture], [grey_model()])
    fitted = evaluate_captures([capture], [grey_model()], fit_views=3, fit_config=FAST_FIT)
    assert fitted.models == ("grey+fit3",) and fitted.fit_views == 3
    assert [v.role for v in fitted.views] == ["input", "fitted", "fitted", "relit", "relit"]
    relit = [v.rmse_fitted for v in fitted.views if v.role == "relit"]
    assert fitted.mean("grey+fit3") == pytest.approx(sum(relit) / 2)
    assert len({v.gain for v in fitted.views}) == 1  # one gain, fitted on the input view
    rows = csv_table(fitted).splitlines()[1:]
    assert [row.split(",")[3] for row in rows] == ["input", "fitted", "fitted", "relit", "relit"]
    assert "fitted to the first 3 views" in markdown_table(fitted)
    assert "| grey+fit3 |" in markdown_table(fitted)
    # The same views (03, 04) without the fit: the fit moved the flat grey toward the true maps
    # (measured: 0.28 against 0.48, summed). Not toward their overall tint: the fit gives each view
    # an RGB gain (white balance), the score one grey gain.
    before = [v.rmse_fitted for v in single.views if v.view >= 3]
    assert sum(relit) < 0.75 * sum(before), (relit, before)


def test_fit_views_needs_a_view_left_to_relight(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    big = read_capture(write_capture(tmp_path / "big", random_maps(SIDE, SIDE)))
    small = read_capture(five_view_capture(tmp_path / "small", random_maps(SIDE, SIDE)))

    def never(photo: Tensor, frame: Tensor) -> Tensor:
        raise AssertionError("a model ran before the captures were checked")

    with pytest.raises(
        CaptureError, match=r"small: 5 views, but fitting to the first 5 needs at least 6"
    ) as info:
        evaluate_captures([big, small], [CaptureModel("never", never)], fit_views=5)
    assert "\n" not in str(info.value)
    out = tmp_path / "out"
    args = [
        "eval-captures",
        str(tmp_path / "big"),
        str(tmp_path / "small"),
        "--fit-views",
        "5",
        "--out",
        str(out),
    ]
    assert main(args) == USER_ERROR_EXIT_CODE
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "small" in err and "first 5" in err, err
    assert not out.exists()
    with pytest.raises(SystemExit):
        main(["eval-captures", "DIR", "--fit-views", "0"])
    assert build_parser().parse_args(["eval-captures", "DIR"]).fit_views == 1


def test_cli_fit_views_names_the_rows(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    five_view_capture(tmp_path / "tiles", matte_maps())
    refs = write_references(tmp_path / "refs", only=("photo_basecolor",))
    out = tmp_path / "out"
    args = ["eval-captures", str(tmp_path / "tiles"), "--references", str(refs), "--out", str(out),
            "--refine", "2", "--resolution", "64", "--fit-views", "2"]  # fmt: skip
    assert main(args) == 0
    markdown = (out / "captures.md").read_text()
    assert capsys.readouterr().out == markdown and "fitted to the first 2 views" in markdown
    rows = [line.split(" | ")[0].lstrip("| ") for line in markdown.splitlines() if line.startswith("| ")][1:]
    shipped = load_model().model_id
    assert rows == [f"{shipped}+fit2", f"{shipped}+refine2+fit2", "photo_basecolor+fit2"]
    roles = [line.split(",")[3] for line in (out / "captures.csv").read_text().splitlines()[1:]]
    assert roles == ["input", "fitted", "relit", "relit", "relit"] * 3
