"""The pair fit reads relief from the ratio of the room light to the flash (inference.pair.relief_fit)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
import torch
import torch.nn.functional as F

from brdfgan.core.delit import flash_render
from brdfgan.core.flash_geometry import centred_flash_frame
from brdfgan.core.svbrdf import join_maps, linear_to_srgb
from brdfgan.inference.pair.relief_fit import (
    SH_TERMS,
    PairFitConfig,
    fit_pair,
    flash_shading,
    normals_of_height,
    sh_basis,
    turned_light,
    usable_ratio_mask,
    with_relief,
)

SIZE = 64
# The model's own reach: the default's shrinkage toward flat is chosen on rendered validation pairs.
FAST = PairFitConfig(levels=(32, 64), steps=(150, 100), flat_prior=0.02)


def mean_angle(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(torch.rad2deg(torch.acos((a * b).sum(0).clamp(-1, 1))).mean())


def pair_of(
    height_px: torch.Tensor, *, metal: float = 0.0, albedo: torch.Tensor | None = None, sheen: float = 0.0
) -> tuple[torch.Tensor, ...]:
    """A diffuse surface with a blocky albedo (or ``albedo``, ``(1, 3, SIZE, SIZE)``), its
    flash-only image and its room light's share (a side-lit order-2 irradiance) — the model the fit
    assumes, rendered by the project's flash — plus ``sheen``, an even reflection of the room that
    the model lacks."""
    normal = normals_of_height(height_px)
    if albedo is None:
        generator = torch.Generator().manual_seed(0)
        blocks = 0.3 + 0.4 * torch.rand(1, 3, SIZE // 8, SIZE // 8, generator=generator)
        albedo = blocks.repeat_interleave(8, 2).repeat_interleave(8, 3)
    frame = centred_flash_frame(1, SIZE, SIZE, fov_deg=50.0)
    roughness, metallic = torch.full((1, 1, SIZE, SIZE), 0.8), torch.full((1, 1, SIZE, SIZE), metal)
    flash_only = flash_render(albedo, normal, roughness, metallic, frame)[0]
    light = torch.zeros(3, SH_TERMS)
    light[:, 0], light[:, 3], light[:, 1] = 1.0, 0.6, 0.3  # constant, from +x, from +y
    room = 0.2 * albedo[0] * torch.einsum("ck,bkhw->bchw", light, sh_basis(normal))[0].clamp_min(0) + sheen
    flat = torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1).expand(3, SIZE, SIZE)
    maps = join_maps(linear_to_srgb(albedo[0]), flat, roughness[0], metallic[0])
    return flash_only, room, maps, frame, normal[0]


def test_the_fit_reads_relief_the_flash_alone_leaves_ambiguous() -> None:
    y, x = torch.meshgrid(torch.linspace(0, 1, SIZE), torch.linspace(0, 1, SIZE), indexing="ij")
    height = (2.0 * torch.sin(2 * math.pi * 2 * x) * torch.sin(2 * math.pi * 1.5 * y))[None, None]
    flash_only, room, maps, frame, truth = pair_of(height)
    result = fit_pair(flash_only, room, torch.ones(1, SIZE, SIZE), maps, frame, FAST)
    flat = maps[3:6]
    assert result.kept == "fit" and result.residual_fit < 0.5 * result.residual_flat
    assert mean_angle(result.maps[3:6], truth) < 0.6 * mean_angle(flat, truth)
    fitted, true = (-n[:2] / n[2:] for n in (result.maps[3:6], truth))
    assert float((fitted * true).sum() / (fitted.norm() * true.norm())) > 0.8  # slope cosine
    # The base colour loses the relief's flash shading: closer to the albedo than the network's.
    record = result.to_json()
    assert record["kept"] == "fit" and len(record["room_light"]) == 3 and record["levels"] == [32, 64]


def bumps(amplitude: float) -> torch.Tensor:
    y, x = torch.meshgrid(torch.linspace(0, 1, SIZE), torch.linspace(0, 1, SIZE), indexing="ij")
    return (amplitude * torch.sin(2 * math.pi * 2 * x) * torch.sin(2 * math.pi * 1.5 * y))[None, None]


def test_a_flat_surface_gets_flat_normals_whatever_the_network_drew() -> None:
    flash_only, room, maps, frame, _ = pair_of(torch.zeros(1, 1, SIZE, SIZE))
    noise = torch.Generator().manual_seed(1)
    room = room * (1 + 0.01 * torch.randn(room.shape, generator=noise))
    invented = maps.clone()
    invented[3:6] = normals_of_height(bumps(2.0))[0]  # relief the photos refute
    result = fit_pair(flash_only, room, torch.ones(1, SIZE, SIZE), invented, frame, FAST)
    assert result.kept == "flat" and result.residual_prediction > result.residual_flat
    assert torch.equal(result.maps[3:6], maps[3:6]) and torch.equal(result.maps[:3], invented[:3])


def test_the_networks_relief_stays_where_the_photos_bear_it_out() -> None:
    flash_only, room, maps, frame, truth = pair_of(bumps(2.0))
    network = maps.clone()
    network[3:6] = truth  # the network read the relief; a fit of a few steps does not
    quick = PairFitConfig(levels=(32, 64), steps=(2, 2), flat_prior=0.02)
    result = fit_pair(flash_only, room, torch.ones(1, SIZE, SIZE), network, frame, quick)
    assert result.kept == "prediction" and torch.equal(result.maps, network)
    assert result.residual_prediction < 0.5 * min(result.residual_flat, result.residual_fit)


def test_the_kept_relief_is_written_into_maps_the_fit_does_not_read() -> None:
    # predict --no-flash reads the relief with the flash-only image's maps and writes it into the
    # flash photo's: what is fitted and kept is the same; only the maps it goes into change.
    flash_only, room, maps, frame, truth = pair_of(bumps(2.0))
    valid = torch.ones(1, SIZE, SIZE)
    written = maps.clone()
    written[:3] = linear_to_srgb(torch.tensor([0.5, 0.3, 0.2]).view(3, 1, 1).expand(3, SIZE, SIZE))
    written[3:6] = normals_of_height(bumps(-2.0))[0]  # never written: the fit's reading decides
    written[6], written[7] = 0.35, 0.1
    plain = fit_pair(flash_only, room, valid, maps, frame, FAST)
    into = fit_pair(flash_only, room, valid, maps, frame, FAST, written=written)
    assert plain.kept == into.kept == "fit" and torch.equal(into.height, plain.height)
    assert torch.equal(into.maps[3:6], plain.maps[3:6])
    assert torch.equal(into.maps, with_relief(written, into.height, frame))
    assert torch.equal(into.maps[6:], written[6:])
    # The network's normals, when they are what the photos bear out, are the fit's maps' normals.
    network = maps.clone()
    network[3:6] = truth
    quick = PairFitConfig(levels=(32, 64), steps=(2, 2), flat_prior=0.02)
    kept = fit_pair(flash_only, room, valid, network, frame, quick, written=written)
    assert kept.kept == "prediction"
    assert torch.equal(kept.maps[3:6], truth) and torch.equal(
        kept.maps[[0, 1, 2, 6, 7]], written[[0, 1, 2, 6, 7]]
    )
    with pytest.raises(ValueError, match="written"):
        fit_pair(flash_only, room, valid, maps, frame, quick, written=written[:, :32])


def test_a_ratio_that_follows_the_material_is_no_relief() -> None:
    # A flat surface whose albedo varies smoothly, and an even sheen of the room's reflection in the
    # no-flash photo: the ratio is brighter where the surface is darker, which a smooth relief can
    # imitate. Scored against a flat surface alone, the fit's 10°+ of invented relief is kept; given
    # the material's own terms, every relief is turned away.
    y, x = torch.meshgrid(torch.linspace(0, 1, SIZE), torch.linspace(0, 1, SIZE), indexing="ij")
    albedo = 0.35 + 0.25 * torch.sin(2 * math.pi * x) * torch.cos(1.5 * math.pi * y)
    flat_height = torch.zeros(1, 1, SIZE, SIZE)
    flash_only, room, maps, frame, truth = pair_of(
        flat_height, albedo=albedo.expand(1, 3, SIZE, SIZE).clone(), sheen=0.01
    )
    valid = torch.ones(1, SIZE, SIZE)
    plain = fit_pair(flash_only, room, valid, maps, frame, replace(FAST, guard_with_maps=False))
    drawn = normals_of_height(F.interpolate(plain.height, size=(SIZE, SIZE), mode="bilinear"))[0]
    assert plain.kept == "fit" and mean_angle(drawn, truth) > 10.0
    guarded = fit_pair(flash_only, room, valid, maps, frame, FAST)
    assert guarded.kept == "flat" and torch.equal(guarded.maps, maps)
    assert guarded.residual_flat < 0.5 * min(guarded.residual_fit, plain.residual_flat)


def test_nothing_held_out_gives_flat_normals() -> None:
    flash_only, room, maps, frame, _ = pair_of(torch.zeros(1, 1, SIZE, SIZE))
    network = maps.clone()
    network[3:6] = normals_of_height(bumps(2.0))[0]
    result = fit_pair(flash_only, room, torch.zeros(1, SIZE, SIZE), network, frame, FAST)
    assert result.kept == "flat" and result.residual_flat == 0 and torch.equal(result.maps[3:6], maps[3:6])


def test_metal_glints_and_invalid_pixels_are_not_read() -> None:
    flash_only, room, maps, frame, _ = pair_of(torch.zeros(1, 1, SIZE, SIZE), metal=1.0)
    valid = torch.ones(1, SIZE, SIZE)
    assert not usable_ratio_mask(flash_only, room, valid, maps, frame, FAST).any()
    flash_only, room, maps, frame, _ = pair_of(torch.zeros(1, 1, SIZE, SIZE))
    valid[:, :, : SIZE // 2] = 0
    usable = usable_ratio_mask(flash_only, room, valid, maps, frame, FAST)
    assert not usable[:, :, : SIZE // 2].any() and usable[:, :, SIZE // 2 :].all()


def test_a_relief_turned_over_is_lit_alike_by_the_turned_light() -> None:
    # The room light's harmonics cannot tell a relief from its mirror image under the light turned
    # 180° about the normal: only the flash's shading can, which is why the guard scores both.
    light = torch.randn(3, SH_TERMS, generator=torch.Generator().manual_seed(2))
    height = bumps(2.0)
    lit, turned = (
        torch.einsum("ck,bkhw->bchw", light_, sh_basis(normals_of_height(height_)))
        for light_, height_ in ((light, height), (turned_light(light), -height))
    )
    assert torch.allclose(lit, turned, atol=1e-5)
    frame = centred_flash_frame(1, SIZE, SIZE, fov_deg=50.0)
    assert not torch.allclose(*(flash_shading(normals_of_height(h), frame) for h in (height, -height)))


def test_the_fit_is_kept_only_where_its_sign_is_read() -> None:
    flash_only, room, maps, frame, truth = pair_of(bumps(2.0))
    result = fit_pair(flash_only, room, torch.ones(1, SIZE, SIZE), maps, frame, FAST)
    assert result.kept == "fit" and result.residual_turned > 1.2 * result.residual_fit
    turned = normals_of_height(-result.height)[0]  # the relief the flash tells apart: far from the truth
    assert mean_angle(result.maps[3:6], truth) < 0.5 * mean_angle(turned, truth)
    # A margin no relief here clears: the fit is not kept, though it lowers the residual most.
    strict = replace(FAST, min_sign_margin=float(result.residual_turned / result.residual_fit))
    refused = fit_pair(flash_only, room, torch.ones(1, SIZE, SIZE), maps, frame, strict)
    assert refused.kept == "flat" and torch.equal(refused.maps[3:6], maps[3:6])
