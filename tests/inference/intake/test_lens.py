"""The field of view from EXIF (brdfgan.inference.intake.lens): golden numbers for phones'
values, the sensor-size path, the fallback, and the EXIF read from JPEG and PNG files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from brdfgan.inference.intake.lens import (
    DEFAULT_FOV_DEG,
    EXIF_IFD,
    FOCAL_LENGTH,
    FOCAL_LENGTH_35MM,
    FOCAL_PLANE_RESOLUTION_UNIT,
    FOCAL_PLANE_X_RESOLUTION,
    PIXEL_X_DIMENSION,
    Lens,
    crop_field_of_view,
)
from brdfgan.inference.intake.photo import read_photo


# (35 mm equivalent, photo size, square crop side) → horizontal FOV across the crop, computed by
# hand: the crop spans side · 43.267 / diagonal mm of a full frame; fov = 2 atan(span / 2f). The
# full 4:3 frame at 26 mm is 79.5° diagonal, 67.3° wide — the angles phone makers quote.
@pytest.mark.parametrize(
    ("phone", "f35", "size", "crop", "fov"),
    [
        ("iPhone 13 main, 4:3 full height", 26.0, (4032, 3024), 3024, 53.06),
        ("Pixel 2 (the paper's phone)", 27.0, (4032, 3024), 3024, 51.35),
        ("Galaxy S9, half-height crop", 26.0, (4032, 3024), 1512, 28.03),
        ("iPhone ultra-wide", 13.0, (4032, 3024), 3024, 89.91),
        ("portrait 3:4, full width", 26.0, (3024, 4032), 3024, 53.06),
    ],
)
def test_35mm_equivalent_focal_length_gives_the_crop_fov(
    phone: str, f35: float, size: tuple[int, int], crop: int, fov: float
) -> None:
    value, source = crop_field_of_view(Lens(focal_length_35mm=f35), *size, crop)
    assert value == pytest.approx(fov, abs=0.01), phone
    assert source == "exif 35 mm equivalent"


def test_focal_length_with_the_sensor_pitch_and_the_default() -> None:
    # A 36 mm wide full-frame sensor at 6000 px: 166.67 px/mm; 50 mm lens; a 4000 px crop spans 24 mm.
    lens = Lens(focal_length_mm=50.0, pixels_per_mm=6000 / 36.0)
    value, source = crop_field_of_view(lens, 6000, 4000, 4000)
    assert value == pytest.approx(math.degrees(2 * math.atan(12.0 / 50.0)))
    assert source == "exif focal length and sensor"
    # A focal length alone does not give an angle; nothing at all is the training default.
    default = (DEFAULT_FOV_DEG, "training default")
    assert crop_field_of_view(Lens(focal_length_mm=4.2), 4032, 3024, 3024) == default
    assert crop_field_of_view(None, 640, 480, 480) == default
    with pytest.raises(ValueError, match="does not fit"):
        crop_field_of_view(None, 640, 480, 700)


def _exif(**tags: float) -> Image.Exif:
    exif = Image.Exif()
    ifd = exif.get_ifd(EXIF_IFD)
    for tag, value in tags.items():
        ifd[{"f": FOCAL_LENGTH, "f35": FOCAL_LENGTH_35MM, "fpxr": FOCAL_PLANE_X_RESOLUTION,
             "unit": FOCAL_PLANE_RESOLUTION_UNIT, "width": PIXEL_X_DIMENSION}[tag]] = value  # fmt: skip
    return exif


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
def test_the_lens_is_read_from_jpeg_and_png_exif(tmp_path: Path, suffix: str) -> None:
    image = Image.fromarray(np.random.default_rng(0).integers(20, 235, (60, 80, 3), dtype=np.uint8))
    path = tmp_path / f"phone{suffix}"
    image.save(path, exif=_exif(f=4.25, f35=26).tobytes())
    lens = read_photo(path).lens
    assert lens == Lens(focal_length_mm=4.25, focal_length_35mm=26.0)
    assert read_photo(path).to_json()["lens"]["focal_length_35mm"] == 26.0
    # The sensor pitch, in the stored image's pixels: declared for 160 px, stored at 80 → halved;
    # unit 3 = centimetres.
    image.save(path, exif=_exif(f=50, fpxr=1000, unit=3, width=160).tobytes())
    assert read_photo(path).lens == Lens(focal_length_mm=50.0, pixels_per_mm=50.0)
    # No EXIF, or EXIF without a focal length: no lens.
    image.save(path)
    assert read_photo(path).lens is None
    image.save(path, exif=_exif(unit=2).tobytes())
    assert read_photo(path).lens is None


def test_the_user_given_field_of_view_follows_the_crop_like_the_exif() -> None:
    from brdfgan.inference.intake.lens import FieldOfView

    # 26 mm on a 4:3 phone photo: 67.3° across its width (the full frame's diagonal 43.27 mm).
    exif = crop_field_of_view(Lens(focal_length_35mm=26.0), 4032, 3024, 1512)
    given = crop_field_of_view(None, 4032, 3024, 1512, FieldOfView(focal_length_35mm=26.0))
    assert given == (exif[0], "--focal-length-35mm")
    photo_fov = math.degrees(2 * math.atan(4032 * math.hypot(36, 24) / math.hypot(4032, 3024) / 52.0))
    assert photo_fov == pytest.approx(67.30, abs=0.01)
    by_fov = crop_field_of_view(None, 4032, 3024, 1512, FieldOfView(photo_fov_deg=photo_fov))
    assert by_fov[1] == "--fov" and by_fov[0] == pytest.approx(exif[0], abs=1e-9)
    # The crop spanning the whole width has the photo's own field of view; the user wins over EXIF.
    assert crop_field_of_view(Lens(focal_length_35mm=13.0), 800, 800, 800, FieldOfView(23.0)) == (
        pytest.approx(23.0),
        "--fov",
    )
    with pytest.raises(ValueError, match="not both"):
        FieldOfView(40.0, 26.0)
    with pytest.raises(ValueError, match=r"\(0, 180\)"):
        FieldOfView(180.0)


def test_predict_records_the_field_of_view_given_on_the_command_line(tmp_path: Path) -> None:
    import json

    import torch

    from brdfgan.cli import main
    from brdfgan.models.generator import Generator
    from brdfgan.runs import save_weights

    torch.manual_seed(0)
    generator = Generator(width=4, residual_blocks=1)
    weights = save_weights(tmp_path / "w.safetensors", generator, target="brdfgan.models.generator.Generator",
                           config=generator.config(), model_id="tiny", extra={"resolution": 64})  # fmt: skip
    image = Image.fromarray(np.random.default_rng(0).integers(20, 235, (60, 80, 3), dtype=np.uint8))
    image.save(tmp_path / "exif.jpg", exif=_exif(f35=26).tobytes())
    image.save(tmp_path / "plain.png")

    def recorded(photo: str, *flags: str) -> dict:
        out = tmp_path / "out" / photo.replace(".", "_")
        args = ["predict", str(tmp_path / photo), "--out", str(out), "--weights", str(weights), "--quiet",
                "--no-preview", "--crop", "10,0,60", *flags]  # fmt: skip
        assert main(args) == 0
        return json.loads((out / Path(photo).stem / "material.json").read_text())["field_of_view"]

    from_exif = recorded("exif.jpg")
    assert from_exif["source"] == "exif 35 mm equivalent"
    from_flag = recorded("plain.png", "--focal-length-35mm", "26")
    assert from_flag == {
        "degrees": pytest.approx(from_exif["degrees"], abs=1e-9),
        "source": "--focal-length-35mm",
    }
    photo_fov = math.degrees(2 * math.atan(80 * math.hypot(36, 24) / 100.0 / 52.0))  # 80 x 60: diagonal 100
    from_fov = recorded("plain.png", "--fov", f"{photo_fov!r}")
    assert from_fov == {"degrees": pytest.approx(from_exif["degrees"], abs=1e-6), "source": "--fov"}
    assert recorded("plain.png")["source"] == "training default"
    for bad in (
        ["--fov", "180"],
        ["--fov", "-3"],
        ["--focal-length-35mm", "0"],
        ["--fov", "40", "--focal-length-35mm", "26"],
    ):
        with pytest.raises(SystemExit) as exit_info:
            main(["predict", str(tmp_path / "plain.png"), "--out", str(tmp_path / "x"), *bad])
        assert exit_info.value.code == 2
