"""Synthetic flash + no-flash pairs of a flat diffuse surface with a known truth.

The surface is a textured albedo under a warm room light with a mild gradient; the flash photo
adds a white flash at the lens (the flat surface's falloff ``(1 + |o|²)^(−3/2)``). Each photo sees
the surface through a known homography (the flash photo: an integer offset into the world image;
the no-flash photo: a small handheld move), has its own white balance and its own exposure
(EXIF ExposureTime × ISO / FNumber²), and is stored as 8-bit sRGB.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from PIL import Image

from brdfgan.core.flash_geometry import pixel_scale
from brdfgan.core.svbrdf import linear_to_srgb
from brdfgan.inference.intake.exposure_settings import ExposureSettings
from brdfgan.inference.intake.lens import EXIF_IFD
from brdfgan.inference.intake.photo import Photo

WIDTH, HEIGHT = 480, 360
WORLD_WIDTH, WORLD_HEIGHT = 720, 600
OFFSET = (120, 120)  # the flash photo's top-left corner in the world image
FOV_DEG = 60.0
FLASH_CENTRE = (240.0, 180.0)  # project convention: the flash faces this point of the flash photo
FLASH_STRENGTH = 3.0  # at the hotspot, times the room's irradiance
ROOM_COLOUR = np.array([1.0, 0.82, 0.6])
# The white balance each shot's camera chose (a no-flash shot balances the warm room light).
FLASH_BALANCE = np.array([1.0, 1.0, 1.0])
NO_FLASH_BALANCE = np.array([0.75, 1.0, 1.45])
# Exposure: 1/60 s, ISO 100 and 320, f/1.8 → r = 100 / 320.
FLASH_SETTINGS = ExposureSettings(1 / 60, 100.0, 1.8)
NO_FLASH_SETTINGS = ExposureSettings(1 / 60, 320.0, 1.8)
RATIO = 100.0 / 320.0
EXPOSURE_SCALE = 0.176  # the flash photo's linear value per unit radiance


def true_gains() -> np.ndarray:
    """The white-balance gains the pair's intake should find: the ratio of the shots' balances
    (green 1 in both)."""
    return FLASH_BALANCE / NO_FLASH_BALANCE


def albedo(seed: int) -> np.ndarray:
    """A textured albedo on the world image, detail at several scales. Shape ``(H, W, 3)``."""
    rng = np.random.default_rng(seed)
    detail = np.zeros((WORLD_HEIGHT, WORLD_WIDTH), dtype=np.float32)
    for sigma in (1.5, 4.0, 12.0):
        noise = rng.standard_normal((WORLD_HEIGHT, WORLD_WIDTH)).astype(np.float32)
        detail += cv2.GaussianBlur(noise, (0, 0), sigma) * sigma
    detail = (detail - detail.mean()) / detail.std()
    value = np.clip(0.35 + 0.1 * detail, 0.08, 0.6)
    tint = np.array([1.0, 0.9, 0.8]) if seed % 2 == 0 else np.array([0.8, 0.9, 1.0])
    return value[..., None] * tint


def room_irradiance() -> np.ndarray:
    """The room light on the world image: warm, 15 % brighter on the right. Shape ``(H, W, 3)``."""
    x = np.linspace(-1.0, 1.0, WORLD_WIDTH)[None, :, None]
    return (1.0 + 0.15 * x) * ROOM_COLOUR * np.ones((WORLD_HEIGHT, 1, 1))


def flash_falloff() -> np.ndarray:
    """The flash's falloff on the flash photo, 1 at its centre. Shape ``(H, W, 1)``."""
    s = pixel_scale(FOV_DEG, WIDTH)
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH] + 0.5
    offsets = ((xs - FLASH_CENTRE[0]) * s) ** 2 + ((ys - FLASH_CENTRE[1]) * s) ** 2
    return ((1.0 + offsets) ** -1.5)[..., None]


def flash_frame(side: int, crop: tuple[int, int, int]) -> torch.Tensor:
    """The true flash frame of a ``crop`` (x, y, size) of the flash photo resized to ``side``."""
    x, y, size = crop
    factor = side / size
    s = pixel_scale(FOV_DEG, WIDTH) / factor
    return torch.tensor([[(FLASH_CENTRE[0] - x) * factor, (FLASH_CENTRE[1] - y) * factor, s]])


def moved(degrees: float = 2.0, shift: tuple[float, float] = (7.3, -4.1), scale: float = 1.02) -> np.ndarray:
    """A handheld move: no-flash photo pixels → world pixels (project convention), a rotation about
    the photo's centre, a scale and a shift, and a slight tilt."""
    angle = math.radians(degrees)
    cos, sin = math.cos(angle) * scale, math.sin(angle) * scale
    centre = np.array([WIDTH / 2, HEIGHT / 2])
    turn = np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])
    to_centre = np.array([[1.0, 0.0, -centre[0]], [0.0, 1.0, -centre[1]], [0.0, 0.0, 1.0]])
    back = np.array(
        [[1.0, 0.0, centre[0] + OFFSET[0] + shift[0]], [0.0, 1.0, centre[1] + OFFSET[1] + shift[1]]]
    )
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [2e-5, -1e-5, 1.0]])
    return np.vstack([back, [0.0, 0.0, 1.0]]) @ turn @ tilt @ to_centre


def true_homography(no_flash_to_world: np.ndarray) -> np.ndarray:
    """Flash photo pixels → no-flash photo pixels (what the registration should find)."""
    flash_to_world = np.array([[1.0, 0.0, OFFSET[0]], [0.0, 1.0, OFFSET[1]], [0.0, 0.0, 1.0]])
    homography = np.linalg.inv(no_flash_to_world) @ flash_to_world
    return homography / homography[2, 2]


def _view(world: np.ndarray, photo_to_world: np.ndarray) -> np.ndarray:
    """The world image seen through a homography (bilinear), in the photo's pixels."""
    half = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]])
    opencv = np.linalg.inv(half) @ photo_to_world @ half  # OpenCV puts pixel j's centre at j
    return cv2.warpPerspective(
        world.astype(np.float32),
        opencv,
        (WIDTH, HEIGHT),
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_REFLECT,
    ).astype(np.float64)


@dataclass(frozen=True)
class Pair:
    """Linear images ``(H, W, 3)`` of one synthetic pair, and their truth."""

    flash: np.ndarray
    no_flash: np.ndarray
    flash_only: np.ndarray  # the flash photo's flash share (its units)
    homography: np.ndarray  # flash photo pixels → no-flash photo pixels


def make_pair(
    seed: int = 0,
    no_flash_to_world: np.ndarray | None = None,
    no_flash_seed: int | None = None,
    blur: float = 0.0,
    flash_strength: float = FLASH_STRENGTH,
) -> Pair:
    """A pair of the surface of albedo ``seed`` (the no-flash photo of ``no_flash_seed``'s surface:
    a different one), the no-flash photo moved by ``no_flash_to_world`` (default :func:`moved`) and
    blurred by a Gaussian of ``blur`` px, the flash ``flash_strength`` times the room's irradiance
    at its hotspot."""
    mover = moved() if no_flash_to_world is None else no_flash_to_world
    surface = albedo(seed)
    room = surface * room_irradiance()
    flash_to_world = np.array([[1.0, 0.0, OFFSET[0]], [0.0, 1.0, OFFSET[1]], [0.0, 0.0, 1.0]])
    room_in_flash = _view(room, flash_to_world)
    flash_only = (
        EXPOSURE_SCALE * FLASH_BALANCE * _view(surface, flash_to_world) * flash_strength * flash_falloff()
    )
    flash = EXPOSURE_SCALE * FLASH_BALANCE * room_in_flash + flash_only
    other = room if no_flash_seed is None else albedo(no_flash_seed) * room_irradiance()
    no_flash = EXPOSURE_SCALE / RATIO * NO_FLASH_BALANCE * _view(other, mover)
    if blur > 0:
        no_flash = cv2.GaussianBlur(no_flash, (0, 0), blur)
    return Pair(flash, no_flash, flash_only, true_homography(mover))


def as_photo(linear: np.ndarray, path: Path, settings: ExposureSettings | None) -> Photo:
    """A :class:`Photo` of linear values as an 8-bit sRGB file would decode them (quantised)."""
    codes = np.rint(linear_to_srgb(torch.from_numpy(np.clip(linear, 0, 1))).numpy() * 255) / 255
    decoded = torch.from_numpy(codes).permute(2, 0, 1)
    from brdfgan.core.svbrdf import srgb_to_linear

    return Photo(
        path=path,
        linear=srgb_to_linear(decoded).float().contiguous(),
        source="jpeg",
        bit_depth=8,
        colorspace="srgb",
        orientation=1,
        warnings=(),
        exposure=settings,
    )


def exif_of(settings: ExposureSettings | None, focal_35mm: float | None = None) -> Image.Exif:
    """EXIF stating ``settings`` in the Exif sub-IFD, as a phone writes it."""
    exif = Image.Exif()
    ifd = exif.get_ifd(EXIF_IFD)
    if settings is not None:
        assert settings.exposure_time_s is not None and settings.f_number is not None
        ifd[0x829A] = settings.exposure_time_s  # ExposureTime
        ifd[0x8827] = int(settings.iso or 0)  # ISOSpeedRatings
        ifd[0x829D] = settings.f_number  # FNumber
    if focal_35mm is not None:
        ifd[0xA405] = int(focal_35mm)
    return exif


def save_jpeg(linear: np.ndarray, path: Path, settings: ExposureSettings | None, quality: int = 95) -> Path:
    """``linear`` as an 8-bit sRGB JPEG with EXIF stating ``settings``."""
    srgb = linear_to_srgb(torch.from_numpy(np.clip(linear, 0, 1))).numpy()
    image = Image.fromarray(np.rint(srgb * 255).astype(np.uint8))
    image.save(path, quality=quality, exif=exif_of(settings))
    return path
