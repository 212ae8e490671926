"""Synthetic handheld captures: a known material photographed several times by a phone held by hand.

The ground truth of the multi-view path (``brdfgan predict --views``, ``brdfgan eval-captures
--fit-views``; docs/views.md). For a map set it draws handheld cameras (:func:`handheld_cameras`),
renders each photo with Mitsuba (:func:`~research.handheld.render_handheld`), delivers
it through a phone (:class:`~brdfgan.data.phone.sensor.SensorEffects`, the same draws for every view: one
phone, its exposure and white balance locked as a capture protocol asks) and writes one folder:

- ``NN.png``, ``parameters.json``: the capture as ``brdfgan eval-captures`` reads it
  (:mod:`brdfgan.evaluation.real_captures`): each photo rectified onto the sample square by its true
  homography, the calibrated camera and flash positions in cm, the flash power at the photos'
  exposure.
- ``handheld/NN.png``: the photos themselves, as ``brdfgan predict --views`` takes them (8-bit
  sRGB, no EXIF: the field of view is in ``truth.json``).
- ``truth/``: the material (``brdfgan.io.maps`` PNGs) and ``truth.json``: each view's camera,
  flash, true homography (the sample texture's pixels → the photo's, project convention) and the
  phone's draws.

Units are centimetres, the sample square ``[-s, s]²`` of z = 0 with row 0 at +y, as the capture
format has it.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from omegaconf import OmegaConf
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.exposure import luminance
from brdfgan.core.homography import apply_homography, pose_homography, texel_to_plane
from brdfgan.core.render import CameraPose, Vector3, camera_frame, capture_camera_height, project_to_image
from brdfgan.core.svbrdf import validate_maps
from brdfgan.data.phone.conditions import tilted_camera
from brdfgan.data.phone.sensor import SensorEffects, encode_srgb8
from brdfgan.inference.outputs.export import staged_directory
from brdfgan.inference.views.register import MATERIALGAN_BOARD, MarkerBoard
from brdfgan.inference.views.warp import warp_to_reference
from brdfgan.io.images import write_image
from brdfgan.io.maps import write_maps
from research.handheld import SURROUND_TILES, render_handheld, surrounded_maps

TRUTH_FILE = "truth.json"


@dataclass(frozen=True)
class HandheldSettings:
    """How the synthetic photos are taken.

    Attributes:
        views: photos per capture (MaterialGAN's captures have 9).
        width, height: the photos' size in pixels (a phone's 4:3).
        fov_deg: the lens's horizontal field of view (a phone's main camera: 65–70°).
        sample_cm: the side of the sample square.
        fill: the sample's side over the photo's height for a straight-on view at the nominal
            distance.
        reference_tilt_max_deg: the first photo (the reference) is nearly straight on.
        tilt_min_deg, tilt_max_deg: the other photos' tilt from straight on, uniform (at 15° the
            flash's highlight reaches the sample's edge: steeper views miss it).
        roll_max_deg: rotation about the view axis, uniform in ``±`` this.
        distance_jitter: the camera's distance, uniform in ``1 ± jitter`` of the nominal one.
        target_jitter: where the camera aims, uniform in ``±`` this fraction of ``s`` from the centre.
        flash_offset_cm: the flash beside the lens, along the image's right and up (a phone's
            flash sits ~1 cm from its lens; 0 puts it at the lens, as ``predict --views`` assumes).
        flash_intensity: radiant intensity of the white flash (W/sr in cm units; the exposure is
            metered, so only the ratio to the surface matters).
        metering_grey: the exposure puts the first photo's median luminance here (a phone's
            metering aims at 18 % grey and lets a small highlight clip) ...
        max_clipped: ... unless more than this share of its pixels would clip.
        spp: Mitsuba samples per pixel.
        side: the rectified views' side (the capture's resolution).
        max_draws: camera draws tried per view before giving up on framing the sample.
    """

    views: int = 9
    width: int = 640
    height: int = 480
    fov_deg: float = 65.0
    sample_cm: float = 10.0
    fill: float = 0.6
    reference_tilt_max_deg: float = 3.0
    tilt_min_deg: float = 5.0
    tilt_max_deg: float = 15.0
    roll_max_deg: float = 20.0
    distance_jitter: float = 0.15
    target_jitter: float = 0.1
    flash_offset_cm: tuple[float, float] = (0.0, 0.0)
    flash_intensity: float = 1000.0
    metering_grey: float = 0.18
    max_clipped: float = 0.05
    spp: int = 64
    side: int = 256
    max_draws: int = 100

    def __post_init__(self) -> None:
        if self.views < 1:
            raise ValueError(f"views must be >= 1, got {self.views}")
        if not 0.0 < self.fill < 1.0:
            raise ValueError(f"fill must lie in (0, 1), got {self.fill}")
        if not 0.0 <= self.tilt_min_deg <= self.tilt_max_deg < 80.0:
            raise ValueError(
                f"need 0 <= tilt_min_deg <= tilt_max_deg < 80, got {self.tilt_min_deg}, {self.tilt_max_deg}"
            )

    @property
    def plane_half_size(self) -> float:
        return self.sample_cm / 2.0


def locked_phone(config: str | os.PathLike[str]) -> SensorEffects:
    """The phone of a sensor config file (``conf/sensor/*.yaml``: the evaluation photos' phone is
    ``phone_eval.yaml``) writing its files as they come: no auto exposure, the capture's exposure
    is locked."""
    settings = OmegaConf.to_container(OmegaConf.load(Path(config)))
    if not isinstance(settings, dict):
        raise ValueError(f"{config}: not a sensor config")
    settings.pop("_target_", None)
    return SensorEffects(**{**{str(key): value for key, value in settings.items()}, "auto_exposure": False})


def _rotated_up(camera: CameraPose, roll_deg: float) -> Vector3:
    right, up, _ = camera_frame(camera)
    angle = math.radians(roll_deg)
    rolled = up * math.cos(angle) + right * math.sin(angle)
    return (float(rolled[0]), float(rolled[1]), float(rolled[2]))


def sample_corners(plane_half_size: float) -> np.ndarray:
    """The sample square's corners on z = 0. Shape: ``(4, 3)``."""
    s = plane_half_size
    return np.array([[-s, s, 0.0], [s, s, 0.0], [s, -s, 0.0], [-s, -s, 0.0]])


def _frames_sample(camera: CameraPose, settings: HandheldSettings, margin_px: float) -> bool:
    corners = project_to_image(
        sample_corners(settings.plane_half_size), camera, settings.width, settings.height
    )
    x, y = corners[:, 0], corners[:, 1]
    return bool(
        (x >= margin_px).all()
        and (x <= settings.width - margin_px).all()
        and (y >= margin_px).all()
        and (y <= settings.height - margin_px).all()
    )


def handheld_cameras(settings: HandheldSettings, generator: torch.Generator) -> list[CameraPose]:
    """``settings.views`` cameras: the first nearly straight on, the others tilted towards
    azimuths spread around the sample (each view from another side, as one walks around it),
    rolled, nearer or farther and aimed off centre; every one sees the whole sample square with a
    margin of 2 % of the photo's height.

    Raises:
        ValueError: no draw frames the sample in ``settings.max_draws`` tries (the settings ask
            for too steep or too near a view).
    """
    vertical_half = math.atan(
        math.tan(math.radians(settings.fov_deg) / 2.0) * settings.height / settings.width
    )
    # The distance at which the sample's side is `fill` of the photo's height, straight on.
    nominal = settings.plane_half_size / (settings.fill * math.tan(vertical_half))
    framing = capture_camera_height(settings.fov_deg, settings.plane_half_size)
    margin = 0.02 * settings.height
    start = float(torch.rand((), generator=generator, dtype=torch.float64)) * 360.0
    cameras: list[CameraPose] = []
    for view in range(settings.views):
        for _ in range(settings.max_draws):
            u = torch.rand(5, generator=generator, dtype=torch.float64).tolist()
            if view == 0:
                tilt = u[0] * settings.reference_tilt_max_deg
                azimuth = u[1] * 360.0
            else:
                tilt = settings.tilt_min_deg + u[0] * (settings.tilt_max_deg - settings.tilt_min_deg)
                spread = 360.0 / max(1, settings.views - 1)
                azimuth = start + (view - 1) * spread + (u[1] - 0.5) * 0.5 * spread
            distance = nominal * (1.0 + (2.0 * u[2] - 1.0) * settings.distance_jitter)
            orbit = tilted_camera(
                settings.fov_deg, tilt, azimuth, distance / framing, settings.plane_half_size
            )
            shift = (np.array(u[3:5]) * 2.0 - 1.0) * settings.target_jitter * settings.plane_half_size
            origin = (orbit.origin[0] + shift[0], orbit.origin[1] + shift[1], orbit.origin[2])
            target = (float(shift[0]), float(shift[1]), 0.0)
            aimed = CameraPose(origin, target, orbit.up, settings.fov_deg)
            roll = (
                float(torch.rand((), generator=generator, dtype=torch.float64)) * 2.0 - 1.0
            ) * settings.roll_max_deg
            camera = CameraPose(origin, target, _rotated_up(aimed, roll), settings.fov_deg)
            if _frames_sample(camera, settings, margin):
                cameras.append(camera)
                break
        else:
            raise ValueError(f"no camera of view {view} framed the sample in {settings.max_draws} draws")
    return cameras


def flash_position(camera: CameraPose, offset_cm: tuple[float, float]) -> Vector3:
    """The flash at the lens, moved by ``offset_cm`` along the image's right and up."""
    right, up, _ = camera_frame(camera)
    position = np.asarray(camera.origin, dtype=np.float64) + offset_cm[0] * right + offset_cm[1] * up
    return (float(position[0]), float(position[1]), float(position[2]))


@dataclass(frozen=True, eq=False)
class SyntheticCapture:
    """The photos of one synthetic capture and everything known about them.

    Shape:
        - photos: ``(V, 3, height, width)`` linear, as the phone delivered them (8-bit sRGB decoded)
        - rectified: ``(V, 3, side, side)``, seen ``(V, 1, side, side)``
        - homographies: ``(V, 3, 3)`` the sample texture's pixels (``side``) → the photo's
    """

    settings: HandheldSettings
    cameras: tuple[CameraPose, ...]
    flash_positions: tuple[Vector3, ...]
    photos: Tensor
    rectified: Tensor
    seen: Tensor
    homographies: np.ndarray
    exposure_scale: float
    phone: dict[str, Any]


def render_synthetic_capture(
    maps: Tensor,
    settings: HandheldSettings,
    sensor: SensorEffects,
    seed: int = 0,
    *,
    surround: Tensor | None = None,
) -> SyntheticCapture:
    """Photograph ``maps`` (the sample square) as ``settings`` says: cameras drawn from ``seed``,
    Mitsuba renders of the sample inside ``surround`` (the surface around it, three times its side
    with ``maps`` in the centre; default: ``maps`` repeated, which a photo's features can match to
    the wrong copy) at one exposure (metered on the first photo, :func:`metered_exposure`), each
    photo through ``sensor`` with the same draws (one phone, locked), rectified by its true
    homography.

    Shape:
        - maps: ``(8, R, R)``
    """
    validate_maps(maps)
    dims = check_shape(maps, "8 R R", name="maps")
    if surround is None:
        surround = surrounded_maps(maps)
    check_shape(surround, "8 S S", name="surround", dims={"S": SURROUND_TILES * dims["R"]})
    generator = torch.Generator().manual_seed(seed)
    cameras = handheld_cameras(settings, generator)
    flashes = [flash_position(camera, settings.flash_offset_cm) for camera in cameras]
    intensity = (settings.flash_intensity,) * 3
    hdr = render_handheld(
        surround,
        cameras,
        flashes,
        intensity,
        settings.width,
        settings.height,
        plane_half_size=SURROUND_TILES * settings.plane_half_size,
        spp=settings.spp,
        seed=seed,
    )
    exposure = metered_exposure(hdr[0], settings.metering_grey, settings.max_clipped)
    photos, rectified, seen, homographies = [], [], [], []
    phone: dict[str, Any] = {}
    for camera, image in zip(cameras, hdr, strict=True):
        delivered, phone = sensor.apply(
            (image * exposure).clamp(0.0, 1.0),
            torch.Generator().manual_seed(seed),  # the same draws for every view: one phone, locked
            illuminant_rgb=(1.0, 1.0, 1.0),
        )
        homography = pose_homography(
            camera, settings.width, settings.height, settings.plane_half_size, settings.side
        )
        view, view_seen = warp_to_reference(delivered, homography, settings.side)
        photos.append(delivered)
        rectified.append(view)
        seen.append(view_seen)
        homographies.append(homography)
    return SyntheticCapture(
        settings,
        tuple(cameras),
        tuple(flashes),
        torch.stack(photos),
        torch.stack(rectified),
        torch.stack(seen),
        np.stack(homographies),
        exposure,
        phone,
    )


def metered_exposure(hdr: Tensor, grey: float, max_clipped: float) -> float:
    """The multiplier that puts the photo's median luminance at ``grey``, or lower where more than
    ``max_clipped`` of its pixels would then exceed 1 (the flash's highlight clips, as on a phone,
    but does not take over the frame).

    Shape:
        - hdr: ``(3, H, W)`` linear
    """
    values = luminance(hdr).flatten()
    metered = grey / max(float(values.median()), 1e-12)
    highlight = float(torch.quantile(values.double(), 1.0 - max_clipped))
    return min(metered, 1.0 / max(highlight, 1e-12))


# The printed board's paper and ink as base colour (sRGB), and its matte finish.
BOARD_PAPER, BOARD_INK, BOARD_ROUGHNESS = 0.8, 0.04, 0.8
# White paper around each tag, in board units: the detector needs a quiet zone around the black border.
BOARD_MARGIN_UNITS = 0.3


def with_marker_board(
    surround: Tensor, sample_cm: float, board_cm: float, board: MarkerBoard = MATERIALGAN_BOARD
) -> Tensor:
    """``surround`` (the surface around the sample, :func:`render_synthetic_capture`) with the
    marker board's tags printed on it, centred on the sample: matte paper and ink, flat. The
    board must leave the sample square free (its tags' inner edges outside ``±sample_cm / 2``).

    Shape:
        - surround: ``(8, S, S)`` over ``SURROUND_TILES · sample_cm``; output the same
    """
    check_shape(surround, "8 S S", name="surround")
    side = surround.shape[-1]
    unit = board_cm / board.units_across
    # The tags' nearest edge to the centre, along either axis.
    inner = min(max(abs(x), abs(y)) for x, y in board.centres) - board.half_side
    if inner * unit <= sample_cm / 2.0:
        raise ValueError(f"a {board_cm} cm board covers the {sample_cm} cm sample: make it larger")
    to_texels = np.linalg.inv(texel_to_plane(SURROUND_TILES * sample_cm / 2.0, side))
    dictionary = cv2.aruco.getPredefinedDictionary(board.dictionary)
    printed = surround.clone()
    margin = BOARD_MARGIN_UNITS * unit
    for tag, corners in board.corners_cm(board_cm).items():
        padded = corners + margin * np.sign(corners - corners.mean(axis=0))
        (left, top), _, (right, bottom), _ = np.rint(apply_homography(to_texels, padded)).astype(int)
        (inner_left, inner_top), _, (inner_right, _), _ = np.rint(
            apply_homography(to_texels, corners)
        ).astype(int)
        printed[:3, top:bottom, left:right] = BOARD_PAPER
        printed[3:6, top:bottom, left:right] = torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1)
        printed[6, top:bottom, left:right] = BOARD_ROUGHNESS
        printed[7, top:bottom, left:right] = 0.0
        size = inner_right - inner_left
        ink = cv2.aruco.generateImageMarker(dictionary, tag, size, borderBits=1).astype(np.float32) / 255.0
        printed[:3, inner_top : inner_top + size, inner_left : inner_left + size] = torch.from_numpy(
            BOARD_INK + (BOARD_PAPER - BOARD_INK) * ink
        )
    return printed


def _vector(values: Sequence[float]) -> list[float]:
    return [float(v) for v in values]


def write_synthetic_capture(
    capture: SyntheticCapture, maps: Tensor, folder: str | os.PathLike[str], name: str | None = None
) -> Path:
    """Write ``capture`` of ``maps`` to ``folder`` (module docstring), replaced atomically.

    Returns:
        The folder.
    """
    folder = Path(folder)
    settings = capture.settings
    folder.parent.mkdir(parents=True, exist_ok=True)
    with staged_directory(folder) as staging:
        (staging / "handheld").mkdir()
        for index in range(settings.views):
            rectified = encode_srgb8(capture.rectified[index]).permute(1, 2, 0).numpy() / 255.0
            write_image(staging / f"{index:02d}.png", rectified)
            photo = encode_srgb8(capture.photos[index]).permute(1, 2, 0).numpy() / 255.0
            write_image(staging / "handheld" / f"{index:02d}.png", photo)
        power = settings.flash_intensity * capture.exposure_scale
        parameters = {
            "_comment": "in cm unit; a synthetic handheld capture (research.synthetic_captures)",
            "image_size": settings.sample_cm,
            "camera_pos": [_vector(camera.origin) for camera in capture.cameras],
            "light_pos": [_vector(flash) for flash in capture.flash_positions],
            "light_pow": power,
        }
        (staging / "parameters.json").write_text(json.dumps(parameters, indent=2) + "\n", encoding="utf-8")
        write_maps(staging / "truth", maps)
        truth = {
            "name": name or folder.name,
            "settings": asdict(settings),
            "exposure_scale": capture.exposure_scale,
            "phone": capture.phone,
            "views": [
                {
                    "file": f"handheld/{index:02d}.png",
                    "camera_position": _vector(camera.origin),
                    "camera_target": _vector(camera.target),
                    "camera_up": _vector(camera.up),
                    "field_of_view_deg": camera.fov_deg,
                    "flash_position": _vector(flash),
                    # The sample texture's pixels (side × side) → the photo's, project convention.
                    "homography": capture.homographies[index].tolist(),
                }
                for index, (camera, flash) in enumerate(
                    zip(capture.cameras, capture.flash_positions, strict=True)
                )
            ],
        }
        (staging / "truth" / TRUTH_FILE).write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return folder
