"""The no-flash twin of a generated photo (``dataset_spec.pairs``) is Mitsuba's render of the same
scene with the flash off: the room light balanced against the flash that did not fire, at the
twin's own exposure."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from brdfgan.core.render import FlashCapture
from brdfgan.data.generation.generation import plan_shards, run_generation
from brdfgan.data.phone.conditions import CaptureDraw, CaptureSampling
from brdfgan.data.phone.environments import (
    LightingConfig,
    LightingDraw,
    flash_centre_irradiance,
    make_spec,
    realize_lighting,
)
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.storage.shards import iter_shard, shard_path
from tests.data.generation.test_generation import tiny_spec

pytestmark = [pytest.mark.mitsuba, pytest.mark.integration]

CAPTURE_FIELDS = (
    "fov_deg", "tilt_deg", "tilt_axis_deg", "distance_drawn", "distance_factor", "flash_offset",
    "flash_offset_angle_deg", "exposure_ev",
)  # fmt: skip


def test_the_twin_of_a_generated_photo_is_its_flash_off_render(tmp_path: Path) -> None:
    from brdfgan.mitsuba_render.photos import CaptureRenderer, render_capture

    capture_sampling = CaptureSampling(
        fov_min_deg=40.0, fov_max_deg=60.0, flash_offset_max=0.05, tilt_max_deg=3.0, exposure_ev_min=-1.5,
        exposure_ev_max=-0.5,
    )  # fmt: skip
    spec = tiny_spec(
        pairs=True,
        spp=64,
        capture=capture_sampling,
        lighting=LightingConfig(train_count=3, test_count=2, resolution=16),
    )
    jobs = plan_shards(spec)
    run_generation(spec, tmp_path, shards=len(jobs) - 1, progress=False)  # the test shard alone
    samples = list(iter_shard(shard_path(tmp_path, "test", jobs[-1].index)))
    renderer = CaptureRenderer(spec.resolution, spec.spp, FlashCapture(), spec.lighting.resolution)
    for sample in samples:
        meta, twin = sample.meta, sample.meta["pair"]["no_flash"]
        assert sample.no_flash is not None
        recorded = meta["lighting"]
        environment = recorded["environment"]
        lighting = LightingDraw(
            make_spec(environment["env_id"], environment["kind"], environment["params"]),
            math.radians(recorded["rotation_deg"]),
            recorded["env_to_flash_ratio"],
        )
        capture = CaptureDraw(**{name: meta["capture"][name] for name in CAPTURE_FIELDS})
        intensity = meta["flash"]["intensity_w_sr"]
        flash = tuple(intensity * c for c in blackbody_rgb(meta["flash"]["temperature_k"]))
        room = realize_lighting(
            lighting, flash_centre_irradiance(flash, capture.flash_position), spec.lighting.resolution
        )
        shot = {"camera": capture.camera, "flash_position": capture.flash_position}
        # The flash off, at the twin's exposure error and render seed (from the stored maps: their
        # 16-bit quantisation aside, the maps it was rendered from).
        off = render_capture(
            renderer,
            sample.maps,
            room,
            (0.0, 0.0, 0.0),
            twin["seed"],
            exposure_ev=twin["exposure_ev"],
            **shot,
        )
        assert off.exposure_scale == pytest.approx(twin["exposure_scale"], rel=1e-3)
        assert float((off.ldr - sample.no_flash).abs().max()) < 1e-4  # measured: 2e-5 (about a code)
        assert twin["exposure_ev"] != meta["capture"]["exposure_ev"] and -1.5 <= twin["exposure_ev"] <= -0.5
        # Flash photo minus the ratio times the twin: the flash alone (Mitsuba's noise aside).
        alone = render_capture(renderer, sample.maps, None, flash, 0, **shot).hdr * meta["exposure_scale"]
        ratio = meta["pair"]["exposure_ratio"]
        assert ratio == pytest.approx(meta["exposure_scale"] / twin["exposure_scale"])
        recovered = sample.photo - ratio * sample.no_flash
        unclipped = (sample.photo < 0.99).all(0) & (sample.no_flash < 0.99).all(0)
        assert unclipped.float().mean() > 0.8
        mean_error = float((recovered - alone)[:, unclipped].mean() / alone[:, unclipped].mean())
        assert abs(mean_error) < 0.01, mean_error  # measured: 0.15 % at most
        assert not torch.allclose(sample.no_flash * ratio, sample.photo, atol=0.05)  # the flash shows
