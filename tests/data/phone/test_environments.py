"""Environment lighting: specs and pools, room/sunsky/file maps, irradiance, rotation, balance."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from brdfgan.core.lighting import (
    Environment,
    SunLight,
    equirect_directions,
    flash_irradiance,
    normalize_environment,
    rotate_environment,
    upper_hemisphere_irradiance,
    upper_hemisphere_irradiance_rgb,
)
from brdfgan.data.phone.environments import (
    LightingConfig,
    LightingDraw,
    LightingError,
    build_environment_pools,
    draw_lighting,
    environment_map,
    load_environment,
    read_environment_file,
    realize_lighting,
    room_spec,
    scan_environment_folder,
    sunsky_spec,
)
from brdfgan.io.images import write_image
from brdfgan.mitsuba_render.environment import ENVMAP_TO_WORLD

RES = 16


def _lat_long(height: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 4.0, (height, 2 * height, 3)).astype(np.float32)


def _write_hdr(path: Path, array: np.ndarray) -> None:
    assert cv2.imwrite(str(path), cv2.cvtColor(array, cv2.COLOR_RGB2BGR))


# ----------------------------------------------------------------------------- specs and pools


def test_pools_are_deterministic_disjoint_and_sized() -> None:
    config = LightingConfig()
    pools = build_environment_pools(config, seed=5)
    assert pools == build_environment_pools(config, seed=5)
    assert pools != build_environment_pools(config, seed=6)
    assert len(pools.train) == 20 and len(pools.test) == 6
    train_ids = {s.env_id for s in pools.train}
    test_ids = {s.env_id for s in pools.test}
    assert len(train_ids) == 20 and len(test_ids) == 6 and not train_ids & test_ids
    assert not {s.params for s in pools.train} & {s.params for s in pools.test}
    kinds = [s.kind for s in pools.train]
    assert kinds.count("sunsky") == 10 and kinds.count("room") == 10
    assert {s.kind for s in pools.test} == {"sunsky", "room"}


def test_kind_mix_and_spec_json() -> None:
    pools = build_environment_pools(LightingConfig(train_count=4, test_count=2, sunsky_fraction=0.0), 1)
    assert {s.kind for s in pools.train + pools.test} == {"room"}
    spec = pools.train[0]
    assert spec.env_id == "room-0000"
    assert list(dict(spec.params)) == sorted(dict(spec.params))
    assert json.loads(json.dumps(spec.to_json())) == spec.to_json()
    assert hash(spec) == hash(room_spec(0, 1))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            {"env_to_flash_min": 1.0, "env_to_flash_max": 0.5},
            "dataset_spec.lighting.env_to_flash_min=1 > dataset_spec.lighting.env_to_flash_max=0.5",
        ),
        ({"env_to_flash_min": 0.0}, "dataset_spec.lighting.env_to_flash_min=0: must be > 0"),
        ({"sunsky_fraction": 0.0, "room_fraction": 0.0}, "no environment source"),
        ({"sunsky_fraction": -0.5}, "dataset_spec.lighting.sunsky_fraction=-0.5: must be >= 0"),
        ({"resolution": 2}, "dataset_spec.lighting.resolution=2: must be an integer >= 4"),
        ({"test_count": 0}, "dataset_spec.lighting.test_count=0: must be an integer >= 1"),
        ({"file_test_fraction": 1.0}, r"dataset_spec.lighting.file_test_fraction=1: must be in \(0, 1\)"),
        ({"train_count": "abc"}, "dataset_spec.lighting.train_count='abc'"),
    ],
)
def test_config_rejects_bad_values_naming_the_key(change: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        LightingConfig(**change)  # type: ignore[arg-type]


def test_a_folder_may_stand_in_for_the_procedural_pools(tmp_path: Path) -> None:
    for k in range(2):
        write_image(tmp_path / f"env{k}.exr", _lat_long(8, k), exr_precision="float")
    config = LightingConfig(train_count=0, test_count=0, folder=str(tmp_path), resolution=8)
    pools = build_environment_pools(config, seed=0)
    assert len(pools.train) == len(pools.test) == 1


def test_user_files_are_split_disjointly(tmp_path: Path) -> None:
    for k in range(5):
        write_image(tmp_path / f"env{k}.exr", _lat_long(8, k), exr_precision="float")
    config = LightingConfig(train_count=2, test_count=1, folder=str(tmp_path))
    pools = build_environment_pools(config, seed=3)
    assert pools == build_environment_pools(config, seed=3)
    train_files = {s.env_id for s in pools.train if s.kind == "file"}
    test_files = {s.env_id for s in pools.test if s.kind == "file"}
    assert len(test_files) == 1 and len(train_files) == 4 and not train_files & test_files
    assert train_files | test_files == {f"file-env{k}" for k in range(5)}
    only_files = LightingConfig(sunsky_fraction=0.0, room_fraction=0.0, folder=str(tmp_path))
    pools = build_environment_pools(only_files, seed=0)
    assert {s.kind for s in pools.train + pools.test} == {"file"}


def test_folder_with_one_file_cannot_be_split(tmp_path: Path) -> None:
    write_image(tmp_path / "only.exr", _lat_long(8))
    with pytest.raises(LightingError, match="at least 2"):
        build_environment_pools(LightingConfig(folder=str(tmp_path)), seed=0)


@pytest.mark.parametrize("damage", ["truncated", "garbage", "black sky"])
def test_every_user_file_is_decoded_when_the_pools_are_built(tmp_path: Path, damage: str) -> None:
    for k in range(3):
        write_image(tmp_path / f"env{k}.exr", _lat_long(8, k), exr_precision="float")
    bad = tmp_path / "env1.exr"
    if damage == "truncated":  # an interrupted copy: the header is intact, the pixels are not
        bad.write_bytes(bad.read_bytes()[:-200])
    elif damage == "garbage":
        bad.write_bytes(b"\x76\x2f\x31\x01" + bytes(300))  # EXR magic, nothing valid after it
    else:  # lights nothing above the horizon: it could never be balanced against the flash
        sky = _lat_long(8)
        sky[:5] = 0.0  # rows 0-4 are the ones whose interpolation reaches above the horizon
        write_image(bad, sky, exr_precision="float")
    config = LightingConfig(train_count=1, test_count=1, folder=str(tmp_path), resolution=8)
    with pytest.raises(LightingError, match=re.escape(str(bad.resolve()))):
        build_environment_pools(config, seed=0)


def test_empty_and_missing_folders_raise(tmp_path: Path) -> None:
    with pytest.raises(LightingError, match=r"no \.exr or \.hdr"):
        scan_environment_folder(tmp_path)
    with pytest.raises(LightingError, match="not found"):
        scan_environment_folder(tmp_path / "missing")
    (tmp_path / "notes.txt").write_text("not an environment")
    with pytest.raises(LightingError, match=re.escape(str(tmp_path))):
        scan_environment_folder(tmp_path)


# ----------------------------------------------------------------------------- maps


def test_equirect_directions_follow_mitsubas_envmap_convention() -> None:
    # Mitsuba's envmap: local d = (sinφ sinθ, cosθ, −cosφ sinθ), θ_i = iπ/(H−1), φ_j = 2π(j+½)/W.
    height = 6
    theta = np.arange(height)[:, None] * math.pi / (height - 1)
    phi = (np.arange(2 * height)[None, :] + 0.5) * 2 * math.pi / (2 * height)
    local = np.stack(
        np.broadcast_arrays(np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)), -1
    )
    world = local @ np.array(ENVMAP_TO_WORLD)[:3, :3].T
    np.testing.assert_allclose(equirect_directions(height), world, atol=1e-12)
    assert np.allclose(equirect_directions(height)[0], [0.0, 0.0, 1.0])  # row 0 is the zenith
    sub = equirect_directions(height, supersample=3)
    assert sub.shape == (height, 2 * height, 9, 3)
    np.testing.assert_allclose(np.linalg.norm(sub, axis=-1), 1.0)


def test_room_maps_are_valid_and_deterministic() -> None:
    for index in range(6):
        spec = room_spec(index, seed=2)
        array = environment_map(spec, RES)
        assert array.shape == (RES, 2 * RES, 3) and array.dtype == np.float32
        assert np.isfinite(array).all() and (array >= 0).all()
        assert upper_hemisphere_irradiance(array) > 0
        assert load_environment(spec, RES).sun is None
        fresh = load_environment.__wrapped__(spec, RES).radiance
        np.testing.assert_array_equal(array, fresh)
    assert not np.array_equal(environment_map(room_spec(0, 2), RES), environment_map(room_spec(0, 3), RES))


def test_room_lights_are_brighter_than_the_paint() -> None:
    # A room lit by ceiling panels only: the panels outshine the bounce light of the paint by a
    # wide margin, and they are overhead.
    rooms = (room_spec(i, 0) for i in range(50))
    spec = next(s for s in rooms if s.param("window_wall") == "none")
    array = environment_map(spec, 64).sum(-1)
    assert array.max() > 20 * np.median(array)
    peak = np.unravel_index(np.argmax(array), array.shape)
    assert equirect_directions(64)[peak][2] > 0.3


def test_environment_files_round_trip(tmp_path: Path) -> None:
    source = _lat_long(RES * 2, seed=4)
    write_image(tmp_path / "a.exr", source, exr_precision="float")
    _write_hdr(tmp_path / "b.hdr", source)
    assert [p.name for p in scan_environment_folder(tmp_path)] == ["a.exr", "b.hdr"]
    exr = read_environment_file(tmp_path / "a.exr", RES)
    hdr = read_environment_file(tmp_path / "b.hdr", RES)
    expected = source.reshape(RES, 2, 2 * RES, 2, 3).mean(axis=(1, 3))  # 2×2 area filter
    assert exr.shape == hdr.shape == (RES, 2 * RES, 3)
    np.testing.assert_allclose(exr, expected, rtol=1e-5)
    np.testing.assert_allclose(hdr, expected, rtol=0.02)  # RGBE keeps ~8 bits of mantissa


def test_environment_file_errors(tmp_path: Path) -> None:
    (tmp_path / "broken.hdr").write_bytes(b"not an image")
    with pytest.raises(LightingError, match=r"broken\.hdr"):
        read_environment_file(tmp_path / "broken.hdr", RES)
    (tmp_path / "broken.exr").write_bytes(b"not an image")
    with pytest.raises(LightingError, match=r"broken\.exr"):
        read_environment_file(tmp_path / "broken.exr", RES)
    write_image(tmp_path / "square.exr", np.ones((8, 8, 3), np.float32))
    with pytest.raises(LightingError, match="2:1"):
        read_environment_file(tmp_path / "square.exr", RES)


@pytest.mark.integration
@pytest.mark.mitsuba
def test_sunsky_maps_have_sky_above_and_a_separate_sun() -> None:
    spec = sunsky_spec(3, seed=0)
    environment = load_environment(spec, RES)
    array = environment.radiance
    assert array.shape == (RES, 2 * RES, 3) and np.isfinite(array).all() and (array >= 0).all()
    np.testing.assert_array_equal(array, load_environment.__wrapped__(spec, RES).radiance)
    directions = equirect_directions(RES)
    up, down = directions[..., 2] > 0.05, directions[..., 2] < -0.05
    # A blue sky above; below, a Lambertian ground of the model's albedo lit by sky and sun.
    assert array[up].min() > 0 and array[up][:, 2].mean() > array[up][:, 0].mean()
    sun = environment.sun
    assert sun is not None
    ground_e = upper_hemisphere_irradiance_rgb(array) + np.array(sun.irradiance) * sun.direction[2]
    expected_ground = float(spec.param("ground_albedo")) * ground_e / math.pi
    np.testing.assert_allclose(array[down], np.broadcast_to(expected_ground, array[down].shape), rtol=1e-3)
    elevation = math.radians(float(spec.param("elevation_deg")))
    assert sun.direction[2] == pytest.approx(math.sin(elevation))
    assert min(sun.irradiance) > 0
    # The sun is far brighter than any sky texel's share: it is a separate light, not in the map.
    assert sun.plane_irradiance() > 0.2 * upper_hemisphere_irradiance(array)


# ----------------------------------------------------------------------------- irradiance


@pytest.mark.parametrize("height", [3, 8, 16, 64])
def test_constant_environment_irradiance_is_pi_l(height: int) -> None:
    radiance = np.full((height, 2 * height, 3), 0.7, np.float32)
    assert upper_hemisphere_irradiance(radiance) == pytest.approx(math.pi * 0.7, rel=1e-4)
    rgb = upper_hemisphere_irradiance_rgb(radiance * np.array([1.0, 2.0, 3.0], np.float32))
    np.testing.assert_allclose(rgb, math.pi * 0.7 * np.array([1.0, 2.0, 3.0]), rtol=1e-4)


def test_lower_hemisphere_does_not_count() -> None:
    radiance = np.zeros((RES, 2 * RES, 3), np.float32)
    below = equirect_directions(RES)[..., 2] < -0.2
    radiance[below] = 5.0
    assert upper_hemisphere_irradiance(radiance) == 0.0


def test_cosine_weighting() -> None:
    # L = cosθ above the horizon: E = ∫ cos²θ dω = 2π/3.
    z = equirect_directions(64)[..., 2].clip(min=0.0)
    radiance = np.repeat(z[..., None], 3, axis=-1).astype(np.float32)
    assert upper_hemisphere_irradiance(radiance) == pytest.approx(2 * math.pi / 3, rel=2e-3)


def test_normalisation_hits_the_target_ratio_sun_included() -> None:
    sun = SunLight((0.6, 0.0, 0.8), (2.0, 2.0, 2.0))
    environment = Environment(_lat_long(RES), sun)
    e_flash = flash_irradiance((3.0, 3.0, 3.0), 2.0)
    assert e_flash == pytest.approx(0.75)
    scaled = normalize_environment(environment, 0.3 * e_flash)
    assert scaled.plane_irradiance() == pytest.approx(0.3 * e_flash, rel=1e-6)
    assert scaled.sun is not None
    # Radiance and sun scale together.
    factor = scaled.sun.irradiance[0] / 2.0
    np.testing.assert_allclose(scaled.radiance, environment.radiance * factor, rtol=1e-6)
    with pytest.raises(ValueError, match="no light"):
        normalize_environment(Environment(np.zeros((RES, 2 * RES, 3), np.float32)), 1.0)


def test_draws_are_deterministic_and_balanced() -> None:
    config = LightingConfig(train_count=2, test_count=1, sunsky_fraction=0.0)
    pool = build_environment_pools(config, seed=0).train
    draws = [draw_lighting(pool, config, torch.Generator().manual_seed(k)) for k in range(40)]
    again = [draw_lighting(pool, config, torch.Generator().manual_seed(k)) for k in range(40)]
    assert draws == again
    ratios = np.array([d.env_to_flash_ratio for d in draws])
    assert ratios.min() >= config.env_to_flash_min and ratios.max() <= config.env_to_flash_max
    assert ratios.min() < 0.15 and ratios.max() > 0.4  # log-uniform spread
    assert {d.spec.env_id for d in draws} == {s.env_id for s in pool}
    assert all(0.0 <= d.rotation_rad < 2 * math.pi for d in draws)
    draw = LightingDraw(pool[0], 1.0, 0.25)
    environment = realize_lighting(draw, flash_irradiance((4.0, 4.0, 4.0), 2.0), RES)
    assert environment.plane_irradiance() == pytest.approx(0.25, rel=1e-5)
    assert json.loads(json.dumps(draw.to_json()))["env_to_flash_ratio"] == 0.25


# ----------------------------------------------------------------------------- rotation


def test_rotation_is_a_column_shift() -> None:
    array = _lat_long(RES)
    width = 2 * RES
    step = 2 * math.pi / width
    np.testing.assert_array_equal(rotate_environment(array, 3 * step), np.roll(array, -3, axis=1))
    np.testing.assert_allclose(rotate_environment(array, 2 * math.pi), array, atol=1e-6)
    np.testing.assert_allclose(rotate_environment(array, -step), np.roll(array, 1, axis=1), atol=1e-6)
    half = rotate_environment(array, 0.5 * step)
    np.testing.assert_allclose(half, 0.5 * (array + np.roll(array, -1, axis=1)), rtol=1e-6)
    assert upper_hemisphere_irradiance(rotate_environment(array, 1.234)) == pytest.approx(
        upper_hemisphere_irradiance(array), rel=1e-5
    )


def test_sun_and_map_rotate_together() -> None:
    # A bright texel marks the sun's direction; after any rotation it still does.
    directions = equirect_directions(RES)
    row, col = 4, 5
    array = np.zeros((RES, 2 * RES, 3), np.float32)
    array[row, col] = 1.0
    environment = Environment(array, SunLight(tuple(directions[row, col]), (1.0, 1.0, 1.0)))
    step = 2 * math.pi / (2 * RES)
    for k in (1, 7, -3, 20):
        turned = environment.rotated(k * step)
        assert turned.sun is not None
        peak = np.unravel_index(np.argmax(turned.radiance[..., 0]), turned.radiance.shape[:2])
        np.testing.assert_allclose(directions[peak], turned.sun.direction, atol=1e-9)
    quarter = SunLight((1.0, 0.0, 0.0), (1.0, 1.0, 1.0)).rotated(math.pi / 2)
    np.testing.assert_allclose(quarter.direction, (0.0, 1.0, 0.0), atol=1e-12)  # +X → +Y


@pytest.mark.integration
@pytest.mark.mitsuba
def test_sunsky_scalar_variant_fallback_agrees() -> None:
    # Without a JIT variant, the emitter is evaluated one direction at a time; same numbers.
    code = (
        "import json\n"
        "from brdfgan.mitsuba_render.variant import select_variant; select_variant('scalar_rgb')\n"
        "from brdfgan.data.phone.environments import load_environment, sunsky_spec\n"
        "e = load_environment(sunsky_spec(0, 0), 8)\n"
        "print(json.dumps([float(e.radiance.sum()), list(e.sun.irradiance)]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    total, irradiance = json.loads(out.stdout.strip().splitlines()[-1])
    environment = load_environment(sunsky_spec(0, 0), 8)
    assert total == pytest.approx(float(environment.radiance.sum()), rel=1e-5)
    assert environment.sun is not None
    np.testing.assert_allclose(irradiance, environment.sun.irradiance, rtol=1e-5)
