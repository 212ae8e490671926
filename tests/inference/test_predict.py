"""`brdfgan predict`: the files it writes, their encodings, batch behaviour and weights safety."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from brdfgan.cli import PARTIAL_FAILURE_EXIT_CODE, main
from brdfgan.core.svbrdf import decode_normal, diffuse_albedo, linear_to_srgb, specular_albedo, srgb_to_linear
from brdfgan.errors import USER_ERROR_EXIT_CODE
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.outputs.export import ExportError, ExportOptions, texture_set, write_material
from brdfgan.inference.outputs.gltf import PNG_SIGNATURE
from brdfgan.inference.pipeline import PredictOptions, Predictor, input_clipped, output_names, predict_photo
from brdfgan.io.images import read_image
from brdfgan.models.anchored import AnchoredUNet
from brdfgan.models.generator import Generator
from brdfgan.runs import WeightsError, save_weights
from tests.conftest import random_maps

TEXTURES = ("basecolor", "normal", "roughness", "metallic", "metallicRoughness", "diffuse", "specular")
TEXTURES += ("height", "ao")


@pytest.fixture(scope="module")
def weights(tmp_path_factory: pytest.TempPathFactory) -> Path:
    torch.manual_seed(0)
    generator = Generator(width=4, residual_blocks=1)
    path = tmp_path_factory.mktemp("weights") / "tiny.safetensors"
    save_weights(path, generator, target="brdfgan.models.generator.Generator", config=generator.config(),
                 model_id="tiny-test", extra={"resolution": 64})  # fmt: skip
    return path


def flash_photo(path: Path, size: tuple[int, int] = (96, 128), centre: tuple[int, int] = (95, 30)) -> Path:
    """An 8-bit sRGB JPEG/PNG of a textured surface with a flash highlight at ``centre`` (x, y)."""
    height, width = size
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[0:height, 0:width]
    texture = 0.25 + 0.1 * rng.random((height, width, 1)) * np.array([1.0, 0.8, 0.6])
    flash = 0.6 * np.exp(-((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2) / (2 * 15.0**2))[..., None]
    linear = np.clip(texture + flash, 0, 1)
    srgb = linear_to_srgb(torch.from_numpy(linear)).numpy()
    cv2.imwrite(str(path), np.rint(srgb * 255).astype(np.uint8)[..., ::-1])
    return path


def read_rgb(path: Path) -> np.ndarray:
    return read_image(path).astype(np.float64)


@pytest.mark.parametrize(("fmt", "bit_depth", "tolerance"), [("png", 8, 0.5 / 255), ("png", 16, 0.5 / 65535),
                                                              ("exr", 8, 2e-3)])  # fmt: skip
def test_every_texture_is_written_with_its_documented_encoding(
    tmp_path: Path, fmt: str, bit_depth: int, tolerance: float
) -> None:
    maps = random_maps(24, 20, seed=3).double()
    options = ExportOptions(format=fmt, bit_depth=bit_depth)  # type: ignore[arg-type]
    out = write_material(tmp_path / "m", maps.float(), options, {"name": "m"})
    basecolor, normal = maps[0:3], maps[3:6]
    roughness, metallic = maps[6:7], maps[7:8]
    linear = srgb_to_linear(basecolor)
    expected_colour = {
        "basecolor": linear,
        "diffuse": diffuse_albedo(linear, metallic),
        "specular": specular_albedo(linear, metallic),
    }
    chw = {name: torch.from_numpy(read_rgb(out / f"{name}.{fmt}")).permute(2, 0, 1) for name in TEXTURES}
    for name, value in expected_colour.items():
        # PNG colour textures are sRGB-encoded; EXR stores linear values.
        stored = value if fmt == "exr" else linear_to_srgb(value)
        assert torch.allclose(chw[name], stored, atol=tolerance), name
    assert torch.allclose(chw["normal"], (normal + 1) / 2, atol=tolerance)
    assert torch.allclose(decode_normal(chw["normal"]), normal, atol=10 * tolerance + 1e-3)
    assert torch.allclose(chw["roughness"][:1], roughness, atol=tolerance)
    assert torch.allclose(chw["metallic"][:1], metallic, atol=tolerance)
    packed = chw["metallicRoughness"]
    # R: the ambient occlusion of the normals' relief, the same values as ao.<fmt>.
    occlusion = torch.from_numpy(read_rgb(out / f"ao.{fmt}")).permute(2, 0, 1)[:1]
    assert (
        torch.allclose(packed[0:1], occlusion, atol=tolerance)
        and occlusion.min() >= 0
        and occlusion.max() <= 1
    )
    assert torch.allclose(packed[1:2], roughness, atol=tolerance) and torch.allclose(
        packed[2:3], metallic, atol=tolerance
    )
    document = json.loads((out / "material.json").read_text())
    assert document["files"][f"basecolor.{fmt}"]["colorspace"] == ("linear" if fmt == "exr" else "srgb")
    assert document["files"][f"normal.{fmt}"]["convention"] == "opengl"
    assert (out / "material.glb").read_bytes()[:4] == b"glTF"
    if fmt == "png":
        assert cv2.imread(str(out / "basecolor.png"), cv2.IMREAD_UNCHANGED).dtype == (
            np.uint8 if bit_depth == 8 else np.uint16
        )
        assert cv2.imread(str(out / "height.png"), cv2.IMREAD_UNCHANGED).dtype == np.uint16  # always 16-bit
    # height: value = 0.5 + scale · h (PNG) or h itself (EXR), h the relief of the normals.
    relief = document["relief"]
    from brdfgan.core.height import height_from_normals

    height = height_from_normals(normal.float()).double()
    stored = chw["height"][0]
    expected_height = height if fmt == "exr" else 0.5 + relief["height_scale"] * height
    assert torch.allclose(stored, expected_height, atol=max(tolerance, 1e-4))
    if fmt == "png":  # by default the scale fills the range
        assert stored.max() == pytest.approx(1.0, abs=1e-3) or stored.min() == pytest.approx(0.0, abs=1e-3)


def test_directx_convention_flips_only_green(tmp_path: Path) -> None:
    maps = random_maps(16, 16, seed=4)
    opengl = texture_set(maps, ExportOptions())["normal"].values
    directx = texture_set(maps, ExportOptions(normal_convention="directx"))["normal"].values
    assert np.allclose(directx[..., 0], opengl[..., 0]) and np.allclose(directx[..., 2], opengl[..., 2])
    assert np.allclose(directx[..., 1], 1.0 - opengl[..., 1])
    # The glTF file keeps OpenGL normals whatever the loose files use: same bytes either way.
    a = write_material(tmp_path / "gl", maps, ExportOptions(), {})
    b = write_material(tmp_path / "dx", maps, ExportOptions(normal_convention="directx"), {})
    glb = (a / "material.glb").read_bytes(), (b / "material.glb").read_bytes()
    assert glb[0].count(PNG_SIGNATURE) == 3
    assert glb[0].split(b"BIN\x00", 1)[1] == glb[1].split(b"BIN\x00", 1)[1]


def test_normal_strength_is_baked_into_the_loose_map_and_a_scale_in_the_glb(tmp_path: Path) -> None:
    from brdfgan.core.svbrdf import scale_normal_strength
    from tests.inference.outputs.test_gltf import Glb

    maps = random_maps(16, 16, seed=4)
    out = write_material(tmp_path / "m", maps, ExportOptions(normal_strength=2.0, height_scale=10.0), {})
    stored = decode_normal(torch.from_numpy(read_rgb(out / "normal.png")).permute(2, 0, 1))
    assert torch.allclose(stored, scale_normal_strength(maps[3:6], 2.0).double(), atol=1e-2)
    document = json.loads((out / "material.json").read_text())
    assert document["files"]["normal.png"]["strength"] == 2.0 and document["relief"]["height_scale"] == 10.0
    gltf = Glb((out / "material.glb").read_bytes()).json
    material = gltf["materials"][0]
    assert material["normalTexture"]["scale"] == 2.0
    # The ORM texture is also the occlusion texture; the glb's normals are strength 1 (scaled there).
    assert (
        material["occlusionTexture"]["index"]
        == material["pbrMetallicRoughness"]["metallicRoughnessTexture"]["index"]
    )
    plain = write_material(tmp_path / "p", maps, ExportOptions(), {})
    glb = Glb((plain / "material.glb").read_bytes())
    strong = Glb((out / "material.glb").read_bytes())
    normal_png = strong.json["materials"][0]["normalTexture"]["index"]
    assert strong.view(strong.json["images"][normal_png]["bufferView"]) == glb.view(
        glb.json["images"][normal_png]["bufferView"]
    )


def test_output_directory_is_replaced_atomically(tmp_path: Path) -> None:
    maps = random_maps(8, 8, seed=5)
    out = write_material(tmp_path / "m", maps, ExportOptions(), {"run": 1})

    def broken(path: Path) -> None:
        raise OSError(5, "Input/output error")  # a full disk is its own error: test_predict_faults.py

    with pytest.raises(ExportError, match="Input/output error"):
        write_material(
            out, random_maps(8, 8, seed=6), ExportOptions(), {"run": 2}, extra_files={"x.png": broken}
        )
    assert json.loads((out / "material.json").read_text())["run"] == 1  # the old result is intact
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"]  # no temporary directory left
    write_material(out, maps, ExportOptions(format="exr"), {"run": 3})
    assert not (out / "basecolor.png").exists() and (out / "basecolor.exr").exists()  # no stale files


def test_predict_photo_writes_everything(tmp_path: Path, weights: Path) -> None:
    photo = flash_photo(tmp_path / "wood.jpg")
    model = load_model(weights)
    predictor = Predictor.create(model, PredictOptions(animate="gif"))
    result = predict_photo(photo, tmp_path / "out" / "wood", predictor)
    names = {p.name for p in result.output.iterdir()}
    assert names == {f"{t}.png" for t in TEXTURES} | {
        "material.glb",
        "material.json",
        "preview.png",
        "preview.gif",
        "index.html",
    }
    document = json.loads((result.output / "material.json").read_text())
    assert document["files"]["index.html"]["channels"] == "HTML page, self-contained"
    assert document["model"]["id"] == "tiny-test" and document["resolution"] == 64
    assert document["crop"]["chosen"] == "flash hotspot"
    hotspot = document["crop"]["hotspot"]
    assert abs(hotspot[0] - 95) < 3 and abs(hotspot[1] - 30) < 3
    assert read_image(result.output / "basecolor.png").shape == (64, 64, 3)


def test_the_default_resolution_is_the_crops_size_within_the_model_size_and_the_cap(
    tmp_path: Path, weights: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A 160-pixel crop (the photo's short side, hotspot at the centre) gives 160² maps: the
    # photo's pixels, neither thrown away nor invented; a 61-pixel crop gives the model's 64²;
    # above the cap the cap.
    model = load_model(weights)
    sides = {}
    for name, size, centre in [("whole", (160, 200), (100, 80)), ("corner", (96, 128), (95, 30))]:
        result = predict_photo(
            flash_photo(tmp_path / f"{name}.png", size, centre),
            tmp_path / "out" / name,
            Predictor.create(model, PredictOptions(preview=False)),
        )
        document = json.loads((result.output / "material.json").read_text())
        assert document["resolution"] == read_image(result.output / "basecolor.png").shape[0]
        sides[name] = (document["crop"]["size"], document["resolution"])
    assert sides == {"whole": (160, 160), "corner": (61, 64)}
    monkeypatch.setattr("brdfgan.inference.pipeline.MAX_DEFAULT_RESOLUTION", 128)
    capped = Predictor.create(model, PredictOptions(preview=False))
    assert capped.largest_resolution == 128
    result = predict_photo(tmp_path / "whole.png", tmp_path / "out" / "capped", capped)
    assert json.loads((result.output / "material.json").read_text())["resolution"] == 128
    fixed = Predictor.create(model, PredictOptions(preview=False, resolution=96))
    result = predict_photo(tmp_path / "whole.png", tmp_path / "out" / "fixed", fixed)
    assert json.loads((result.output / "material.json").read_text())["resolution"] == 96


def test_load_model_accepts_safetensors_only(tmp_path: Path, weights: Path) -> None:
    state = {"weight": torch.zeros(2)}
    pickled = tmp_path / "evil.safetensors"
    with pickled.open("wb") as handle:
        pickle.dump(state, handle)  # what torch.save writes: a pickle that could run code on load
    with pytest.raises(WeightsError) as error:
        load_model(pickled)
    assert str(pickled) in str(error.value) and "\n" not in str(error.value)
    checkpoint = tmp_path / "run.ckpt"
    torch.save(state, checkpoint)
    with pytest.raises(WeightsError, match=r"\.safetensors weights only"):
        load_model(checkpoint)
    assert load_model(weights).model_id == "tiny-test"


def test_output_names_are_unique_and_safe() -> None:
    names = output_names([Path("a/x.jpg"), Path("b/x.png"), Path("c/x y!.jpg"), Path("x.jpg")])
    assert names == ["x", "x-2", "x_y", "x-3"]


def test_cli_batch_continues_past_bad_files_and_exits_non_zero(
    tmp_path: Path, weights: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    photos = tmp_path / "photos"
    photos.mkdir()
    flash_photo(photos / "good.jpg")
    flash_photo(photos / "zgood.png", centre=(40, 50))
    (photos / "notes.jpg").write_text("not an image")
    full = (photos / "good.jpg").read_bytes()
    (photos / "truncated.jpg").write_bytes(full[: len(full) // 2])
    cv2.imwrite(str(photos / "tiny.png"), np.full((8, 8, 3), 128, np.uint8))
    cv2.imwrite(str(photos / "gray.png"), np.full((64, 64), 128, np.uint8))
    (photos / "ignored.txt").write_text("not a photo extension: skipped")
    out = tmp_path / "out"
    code = main(["predict", str(photos), str(tmp_path / "missing.jpg"), "--out", str(out),
                 "--weights", str(weights), "--quiet"])  # fmt: skip
    captured = capsys.readouterr()
    assert code == PARTIAL_FAILURE_EXIT_CODE
    assert sorted(p.name for p in out.iterdir()) == ["good", "zgood"]  # nothing for the failures
    summary = captured.err.split("photo(s) failed:")[1].strip().splitlines()
    failed = {Path(line.strip().split(":")[0]).name for line in summary}
    assert failed == {"notes.jpg", "truncated.jpg", "tiny.png", "gray.png", "missing.jpg"}
    assert all("Traceback" not in line for line in captured.err.splitlines())
    assert captured.out.split() == [str(out / "good"), str(out / "zgood")]


def test_cli_options_reach_the_files(tmp_path: Path, weights: Path) -> None:
    photo = flash_photo(tmp_path / "p.png", size=(80, 80))
    code = main(["predict", str(photo), "--out", str(tmp_path / "o"), "--weights", str(weights), "--quiet",
                 "--crop", "8,8,64", "--resolution", "32", "--normal-convention", "directx",
                 "--bit-depth", "16", "--no-preview", "--input-colorspace", "linear"])  # fmt: skip
    assert code == 0
    out = tmp_path / "o" / "p"
    document = json.loads((out / "material.json").read_text())
    assert document["crop"] == {"x": 8, "y": 8, "size": 64, "chosen": "user", "hotspot": None}
    assert document["input"]["colorspace"] == "linear" and document["resolution"] == 32
    assert document["files"]["normal.png"]["convention"] == "directx"
    assert cv2.imread(str(out / "normal.png"), cv2.IMREAD_UNCHANGED).dtype == np.uint16
    assert not (out / "preview.png").exists()


def test_cli_artist_options_quiet_verbose_prefix_and_device(
    tmp_path: Path, weights: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    photo = flash_photo(tmp_path / "oak.png", size=(80, 80))
    common = ["predict", str(photo), "--weights", str(weights), "--no-preview", "--device", "cpu"]
    assert main([*common, "--out", str(tmp_path / "q"), "--quiet", "--tileable", "--normal-strength", "1.5",
                 "--height-scale", "20"]) == 0  # fmt: skip
    quiet = capsys.readouterr()
    assert quiet.err == ""  # errors only, and there were none; stdout lists the result
    assert quiet.out.split() == [str(tmp_path / "q" / "oak")]
    document = json.loads((tmp_path / "q" / "oak" / "material.json").read_text())
    assert document["files"]["normal.png"]["strength"] == 1.5 and document["relief"]["height_scale"] == 20.0
    tiling = document["tileable"]
    assert max(max(pair) for pair in tiling["wrap_ratio_after"].values()) < 1.2
    assert min(tiling["copied_fraction"].values()) > 0.85
    assert main([*common, "--out", str(tmp_path / "v"), "--verbose", "--prefix"]) == 0
    verbose = capsys.readouterr()
    assert "oak.png: read " in verbose.err and " network " in verbose.err and " export " in verbose.err
    names = {p.name for p in (tmp_path / "v" / "oak").iterdir()}
    assert {"oak_basecolor.png", "oak_height.png", "oak_ao.png", "material.glb", "material.json"} <= names
    assert "basecolor.png" not in names


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--weights", "nowhere.safetensors"], "weights file not found"),
        (["--crop", "1,2"], "--crop"),
        (["--resolution", "0"], "--resolution"),
        (["--normal-strength", "-1"], "--normal-strength: expected a number >= 0"),
        (["--height-scale", "0"], "--height-scale: expected a number > 0"),
        (["--quiet", "--verbose"], "not allowed with argument"),
    ],
)
def test_cli_usage_errors_are_one_line(
    tmp_path: Path, arguments: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    photo = flash_photo(tmp_path / "p.jpg")
    with pytest.raises(SystemExit) as exit_info:
        code = main(["predict", str(photo), "--out", str(tmp_path / "o"), *arguments])
        raise SystemExit(code)
    assert exit_info.value.code == USER_ERROR_EXIT_CODE
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and "Traceback" not in "".join(err)
    assert not (tmp_path / "o").exists()


def test_help_has_examples(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["predict", "--help"])
    assert "examples:" in capsys.readouterr().out


def test_high_resolution_runs_tiled_and_matches_the_untiled_prediction(tmp_path: Path, weights: Path) -> None:
    photo = flash_photo(tmp_path / "p.png", size=(200, 200), centre=(100, 100))
    common = ["predict", str(photo), "--weights", str(weights), "--quiet", "--no-preview", "--format", "exr",
              "--resolution", "192"]  # fmt: skip
    assert main([*common, "--out", str(tmp_path / "direct")]) == 0
    assert main([*common, "--out", str(tmp_path / "tiled"), "--tile", "128"]) == 0
    direct = json.loads((tmp_path / "direct" / "p" / "material.json").read_text())
    tiled = json.loads((tmp_path / "tiled" / "p" / "material.json").read_text())
    assert direct["inference"]["tiled"] is False and tiled["inference"]["tiled"] is True
    for name in ("basecolor", "roughness", "metallic", "normal"):
        a = read_rgb(tmp_path / "direct" / "p" / f"{name}.exr")
        b = read_rgb(tmp_path / "tiled" / "p" / f"{name}.exr")
        # Frozen statistics + discarded tile margins: only residual padding effects remain
        # (measured: max 8e-3, mean 4e-5 for this random tiny network).
        assert np.abs(a - b).max() < 2e-2 and np.abs(a - b).mean() < 5e-4, name


def test_a_flash_aware_model_gets_the_detected_hotspot_and_the_field_of_view(tmp_path: Path) -> None:
    from brdfgan.core.clipped_fill import remove_flash
    from brdfgan.core.flash_geometry import DEFAULT_FOV_DEG, centred_flash_frame, pixel_scale
    from brdfgan.inference.intake.photo import read_photo
    from brdfgan.inference.intake.preprocess import Crop, preprocess
    from brdfgan.inference.model.tiling import predict_direct

    torch.manual_seed(0)
    generator = AnchoredUNet(width=4, depth=2)  # reads the flash frame
    with torch.no_grad():  # untrained, its roughness is 0.5 everywhere: make it read its features
        generator.surface.head.weight.normal_(0.0, 0.5)
    target = "brdfgan.models.anchored.AnchoredUNet"
    path = save_weights(tmp_path / "aware.safetensors", generator, target=target,
                        config=generator.config(), model_id="aware", extra={"resolution": 64})  # fmt: skip
    # A user crop with the highlight at its right edge: the frame must say so.
    photo_path = flash_photo(tmp_path / "edge.png")
    crop = Crop(0, 0, 96)
    options = PredictOptions(preview=False, crop=crop, resolution=64)
    result = predict_photo(photo_path, tmp_path / "out" / "edge", Predictor.create(load_model(path), options))
    document = json.loads((result.output / "material.json").read_text())
    assert document["field_of_view"] == {"degrees": DEFAULT_FOV_DEG, "source": "training default"}

    prepared = preprocess(read_photo(photo_path), 64, crop)
    frame = prepared.flash_frame(DEFAULT_FOV_DEG)
    x, _, s = frame[0].tolist()
    assert x == pytest.approx((document["input_statistics"]["hotspot_x"] + 0.5) * 64 / 96)
    assert x > 60 and s == pytest.approx(pixel_scale(DEFAULT_FOV_DEG, 64))
    loaded = load_model(path).generator
    expected = predict_direct(loaded, prepared.photo[None], frame)[0]
    # … with the flash taken out as predict takes it (the clipped hotspot's roughness filled).
    clipped = input_clipped(read_photo(photo_path), prepared)
    removed, _ = remove_flash(expected, prepared.photo, frame, clipped=clipped)
    written = torch.from_numpy(read_rgb(result.output / "roughness.png")[..., 0]).float()
    torch.testing.assert_close(written, removed[6], atol=0.6 / 255, rtol=0)
    centred = predict_direct(loaded, prepared.photo[None], centred_flash_frame(1, 64, 64))[0]
    assert (centred[6] - expected[6]).abs().max() > 2 / 255  # the frame matters: the check can tell


def test_refine_fits_the_maps_to_the_photo_and_records_it(tmp_path: Path, weights: Path) -> None:
    photo = flash_photo(tmp_path / "p.png", size=(80, 80), centre=(40, 40))
    plain, refined = tmp_path / "plain", tmp_path / "refined"
    common = [str(photo), "--weights", str(weights), "--quiet", "--resolution", "32"]
    assert main(["predict", *common, "--out", str(plain)]) == 0
    assert main(["predict", *common, "--out", str(refined), "--refine", "30"]) == 0
    document = json.loads((refined / "p" / "material.json").read_text())
    record = document["refinement"]
    assert record["steps"] == 30 and "steps" not in record["settings"]  # recorded once
    assert record["field_of_view"] == {"degrees": pytest.approx(57.5), "source": "training default"}
    assert len(record["gain"]) == 3 and all(g > 0 for g in record["gain"])
    # The fit reproduces the photo better than the network's maps did.
    assert record["photo_rmse_end"] < record["photo_rmse_start"]
    assert json.loads((plain / "p" / "material.json").read_text())["refinement"] is None
    before, after = (read_rgb(folder / "p" / "basecolor.png") for folder in (plain, refined))
    assert not np.array_equal(before, after)
    assert (refined / "p" / "preview.png").exists()


def test_refine_given_bare_uses_the_default_step_count(tmp_path: Path, weights: Path) -> None:
    from brdfgan.cli import build_parser
    from brdfgan.inference import DEFAULT_REFINE_STEPS

    args = build_parser().parse_args(["predict", "x.jpg", "--out", str(tmp_path), "--refine"])
    assert args.refine == DEFAULT_REFINE_STEPS
    assert build_parser().parse_args(["predict", "x.jpg", "--out", str(tmp_path)]).refine is None
