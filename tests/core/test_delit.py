"""The de-lit photo (core.delit) and the de-lit reference predictor."""

from __future__ import annotations

import math

import pytest
import torch

from brdfgan.core.delit import clip_hotspot, delit_photo, flat_flash_falloff
from brdfgan.core.flash_geometry import centred_flash_frame, crop_flash_frame, pixel_scale
from brdfgan.core.render import FlashCapture, render_flash
from brdfgan.core.svbrdf import flat_maps, linear_to_srgb, srgb_to_linear, validate_maps
from brdfgan.errors import UserError
from brdfgan.models.reference import DeLitPhoto, fit_delit_reference


def _diffuse_render(basecolor: float, fov_deg: float, size: int) -> torch.Tensor:
    """The diffuse part of a flash photo of a uniform dielectric: the render minus that of the same
    material with a black base colour (the specular lobe alone). Roughness 0.25 makes Burley's
    F_D90 = 0.5 + 2 · 0.25 · (h·l)² exactly 1 with the flash at the lens (h·l = 1): Lambert."""
    capture = FlashCapture(fov_deg=fov_deg)
    maps = flat_maps(size, size, (basecolor,) * 3, roughness=0.25, batch=(1,), dtype=torch.float64)
    black = flat_maps(size, size, (0.0,) * 3, roughness=0.25, batch=(1,), dtype=torch.float64)
    return render_flash(maps, capture) - render_flash(black, capture)


@pytest.mark.parametrize("fov_deg", [20.0, 45.0, 75.0])
def test_the_delit_render_of_a_uniform_material_is_uniform(fov_deg: float) -> None:
    size = 48
    photo = _diffuse_render(0.6, fov_deg, size)
    raw_spread = photo.max() / photo.min()
    delit = delit_photo(photo, centred_flash_frame(1, size, size, fov_deg, dtype=torch.float64), clip=False)
    assert float(delit.max() / delit.min()) - 1.0 < 0.01  # uniform within 1 %
    assert raw_spread > 1.05  # while the photo itself was not (at 20°: 1.07, at 75°: 2.6)
    # The level is the Lambertian radiance at the hotspot: ρ/π · I / h².
    height = FlashCapture(fov_deg=fov_deg).camera_height
    expected = float(srgb_to_linear(torch.tensor(0.6))) / math.pi / height**2
    assert torch.allclose(delit, torch.full_like(delit, expected), rtol=0.01)


def test_a_wrong_field_of_view_leaves_the_falloff_in() -> None:
    size = 48
    photo = _diffuse_render(0.6, 60.0, size)
    delit = delit_photo(photo, centred_flash_frame(1, size, size, 20.0, dtype=torch.float64), clip=False)
    assert float(delit.max() / delit.min()) > 1.5


def test_falloff_follows_the_hotspot_through_a_crop() -> None:
    frame = centred_flash_frame(1, 64, 64, 60.0, dtype=torch.float64)
    whole = flat_flash_falloff(frame, 64, 64)
    window = flat_flash_falloff(crop_flash_frame(frame, 40.0, 8.0), 16, 16)
    assert torch.allclose(window, whole[..., 8:24, 40:56])
    assert float(whole.max()) <= 1.0
    # At a corner pixel centre: (1 + |o|²)^-1.5 with |o| in camera distances.
    s = pixel_scale(60.0, 64)
    o_squared = 2 * (31.5 * s) ** 2
    assert math.isclose(float(whole[0, 0, 0, 0]), (1.0 + o_squared) ** -1.5, rel_tol=1e-9)


def test_clip_hotspot_caps_luminance_and_keeps_the_hue() -> None:
    image = torch.full((1, 3, 8, 8), 0.2, dtype=torch.float64)
    image[:, 0] = 0.3  # reddish
    image[:, :, 3:5, 3:5] *= 10.0  # the highlight: 4 pixels
    clipped = clip_hotspot(image)
    assert torch.equal(clipped[:, :, 0, 0], image[:, :, 0, 0])  # below the cap: untouched
    hot = clipped[:, :, 4, 4]
    assert torch.allclose(hot / hot[:, 1:2], image[:, :, 0, 0] / image[:, 1:2, 0, 0])  # same chromaticity
    luminance_cap = 1.5 * (0.2126 * 0.3 + 0.7152 * 0.2 + 0.0722 * 0.2)
    assert math.isclose(float((clipped[0, :, 4, 4] * clipped.new_tensor([0.2126, 0.7152, 0.0722])).sum()),
                        luminance_cap, rel_tol=1e-6)  # fmt: skip
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        clip_hotspot(image[0])
    with pytest.raises(ValueError, match="flash frame for 2 photos"):
        delit_photo(image, centred_flash_frame(2, 8, 8))


def test_the_delit_reference_fits_the_exposure_gain_and_medians() -> None:
    size, fov = 32, 50.0
    frame = centred_flash_frame(1, size, size, fov)
    falloff = flat_flash_falloff(frame, size, size)
    batches = []
    generator = torch.Generator().manual_seed(0)
    for roughness in (0.2, 0.4, 0.9):
        albedo = 0.1 + 0.6 * torch.rand(1, 3, size, size, generator=generator)
        maps = torch.cat(
            [linear_to_srgb(albedo), flat_maps(size, size, roughness=roughness, batch=(1,))[:, 3:]], dim=1
        )
        # A matte photo at exposure 0.5: the de-lit photo is half the albedo.
        batches.append({"photo": 0.5 * albedo * falloff, "maps": maps, "flash": frame})
    model = fit_delit_reference(batches)
    assert math.isclose(float(model.gain), 2.0, rel_tol=1e-4)
    assert math.isclose(float(model.roughness), 0.4, rel_tol=1e-6)
    assert float(model.metallic) == 0.0
    maps = model(batches[0]["photo"], frame)
    validate_maps(maps)
    assert torch.allclose(maps[:, :3], batches[0]["maps"][:, :3], atol=1e-4)  # the albedo recovered
    assert torch.all(maps[:, 5] == 1.0) and torch.all(maps[:, 6] == model.roughness)
    # Without a frame: centred on the hotspot with the default field of view.
    assert model(batches[0]["photo"]).shape == (1, 8, size, size)
    with pytest.raises(UserError, match="no training samples"):
        fit_delit_reference([])


def test_the_delit_reference_is_a_weights_file(tmp_path) -> None:
    from brdfgan.runs import load_weights, save_weights

    model = DeLitPhoto()
    model.gain.fill_(1.7)
    model.roughness.fill_(0.45)
    path = save_weights(tmp_path / "de_lit.safetensors", model, target="brdfgan.models.reference.DeLitPhoto",
                        config={}, model_id="de_lit")  # fmt: skip
    loaded, _ = load_weights(path)
    photo = torch.rand(2, 3, 16, 16)
    assert torch.equal(loaded(photo), model(photo))
