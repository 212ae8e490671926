"""Environment pools and per-render lighting draws for synthetic captures: sun/sky, procedural
rooms and user HDR files.

Every environment becomes a :class:`brdfgan.core.lighting.Environment` (equirect radiance in the
layout described there, plus an optional sun), so one scene renders every kind by swapping data.

Kinds:

- ``sunsky``: Mitsuba's Hosek–Wilkie sky with the sun kept apart as a directional light
  (:func:`brdfgan.mitsuba_render.environment.sunsky_environment`; Mitsuba is imported on use).
- ``room``: a box room around the sample with painted walls, ceiling light panels and/or a
  window onto an overcast sky, radiance computed analytically per texel direction (numpy).
- ``file``: ``.hdr``/``.exr`` lat-long files from a folder, area-resized to the resolution.

Radiometric balance (paper: photos "predominantly flash lit" with other lights present): each
render scales its environment so the irradiance it puts on the upward-facing sample
(:func:`~brdfgan.core.lighting.upper_hemisphere_irradiance`, sun included) equals
``ratio · E_flash`` with ``E_flash = I / d²`` the flash irradiance at the sample centre
(:func:`~brdfgan.core.lighting.flash_irradiance`) and ``ratio`` log-uniform in
``[env_to_flash_min, env_to_flash_max]``. Each render also turns its environment by a uniform
random angle about the up axis.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from brdfgan.core.lighting import Environment, equirect_directions, flash_irradiance, normalize_environment
from brdfgan.core.sampling import log_uniform
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.storage.spec_checks import DatasetConfigError, in_range, integer, ordered
from brdfgan.errors import UserError
from brdfgan.mitsuba_render.environment import sunsky_environment

EnvironmentKind = Literal["sunsky", "room", "file"]
ParamValue = float | str

ENVIRONMENT_EXTENSIONS = frozenset({".exr", ".hdr"})
# Texel supersampling (per axis) of the analytic room: antialiases panel and window edges.
ROOM_SUPERSAMPLE = 3


class LightingError(UserError):
    """An environment source cannot be used; the one-line message names the path."""


@dataclass(frozen=True)
class EnvironmentSpec:
    """One environment of a pool: a stable id, its kind and the parameters that rebuild it.

    ``params`` are sorted ``(name, value)`` pairs, so specs are hashable and
    :func:`load_environment` is a pure (and cached) function of ``(spec, resolution)``.
    """

    env_id: str
    kind: EnvironmentKind
    params: tuple[tuple[str, ParamValue], ...]

    def param(self, name: str) -> ParamValue:
        return dict(self.params)[name]

    def to_json(self) -> dict[str, Any]:
        """JSON-ready form for per-sample metadata."""
        return {"env_id": self.env_id, "kind": self.kind, "params": dict(self.params)}


def make_spec(env_id: str, kind: EnvironmentKind, params: Mapping[str, ParamValue]) -> EnvironmentSpec:
    """Spec with its parameters sorted (floats as Python floats, so JSON and hashing are stable)."""
    clean = {k: (v if isinstance(v, str) else float(v)) for k, v in params.items()}
    return EnvironmentSpec(env_id, kind, tuple(sorted(clean.items())))


def _sunsky_environment(spec: EnvironmentSpec, resolution: int) -> Environment:
    return sunsky_environment(
        float(spec.param("elevation_deg")),
        float(spec.param("azimuth_deg")),
        float(spec.param("turbidity")),
        float(spec.param("ground_albedo")),
        resolution,
    )


# ----------------------------------------------------------------------------- rooms

# Plausible interior paints and floors as linear RGB albedo (light reflectance values of real
# paints span ~0.1 for charcoal to ~0.85 for bright white).
_WALL_PAINTS = (
    (0.85, 0.85, 0.83),  # white
    (0.83, 0.78, 0.68),  # warm white
    (0.55, 0.56, 0.57),  # light grey
    (0.62, 0.53, 0.40),  # beige
    (0.50, 0.60, 0.68),  # pale blue
    (0.40, 0.46, 0.36),  # sage green
    (0.45, 0.22, 0.14),  # terracotta
    (0.12, 0.12, 0.13),  # charcoal
)
_FLOORS = (
    (0.35, 0.22, 0.12),  # oak
    (0.12, 0.07, 0.04),  # dark wood
    (0.20, 0.20, 0.20),  # grey carpet
    (0.60, 0.58, 0.55),  # light tiles
    (0.30, 0.30, 0.28),  # concrete
)
_WALLS = ("+x", "-x", "+y", "-y")


def _jitter_colour(rng: np.random.Generator, base: Sequence[float]) -> np.ndarray:
    return np.clip(np.asarray(base) * rng.uniform(0.85, 1.1), 0.02, 0.9)


def _sample_room_params(rng: np.random.Generator) -> dict[str, ParamValue]:
    p: dict[str, ParamValue] = {}
    p["size_x"], p["size_y"] = rng.uniform(3.0, 8.0), rng.uniform(3.0, 8.0)
    p["height"] = rng.uniform(2.4, 3.5)
    # The sample lies on the floor or on a table/desk, away from the walls.
    p["sample_x"] = float(p["size_x"]) * rng.uniform(0.2, 0.8)
    p["sample_y"] = float(p["size_y"]) * rng.uniform(0.2, 0.8)
    p["sample_height"] = 0.0 if rng.random() < 0.3 else rng.uniform(0.45, 1.0)
    for name, palette in (("wall", _WALL_PAINTS), ("floor", _FLOORS)):
        colour = _jitter_colour(rng, palette[rng.integers(len(palette))])
        p.update({f"{name}_r": colour[0], f"{name}_g": colour[1], f"{name}_b": colour[2]})
    ceiling = rng.uniform(0.75, 0.88)
    p.update({"ceiling_r": ceiling, "ceiling_g": ceiling, "ceiling_b": ceiling * rng.uniform(0.95, 1.0)})

    has_window = rng.random() < 0.6
    panels = int(rng.integers(0, 4)) if has_window else int(rng.integers(1, 5))
    p["panel_count"] = float(panels)
    p["panel_temperature_k"] = rng.uniform(2700.0, 6500.0)
    for k in range(panels):
        w, d = rng.uniform(0.3, 1.2), rng.uniform(0.3, 1.2)
        p[f"panel{k}_w"], p[f"panel{k}_d"] = w, d
        p[f"panel{k}_x"] = rng.uniform(w / 2, float(p["size_x"]) - w / 2)
        p[f"panel{k}_y"] = rng.uniform(d / 2, float(p["size_y"]) - d / 2)
    p["window_wall"] = _WALLS[rng.integers(4)] if has_window else "none"
    if has_window:
        wall_length = float(p["size_x"] if p["window_wall"] in ("+y", "-y") else p["size_y"])
        width = min(rng.uniform(0.8, 2.5), wall_length - 0.4)
        p["window_width"] = width
        p["window_center"] = rng.uniform(width / 2 + 0.2, wall_length - width / 2 - 0.2)
        p["window_sill"] = rng.uniform(0.5, 1.0)
        p["window_height"] = min(rng.uniform(0.8, 1.6), float(p["height"]) - float(p["window_sill"]) - 0.1)
        # Zenith radiance of the overcast sky outside, relative to the panels' radiance of 1.
        p["window_radiance"] = log_uniform(rng.random(), 0.5, 5.0)
        p["window_temperature_k"] = rng.uniform(5500.0, 9000.0)
        p["outside_ground_albedo"] = rng.uniform(0.1, 0.3)
    return p


def _rgb(spec: EnvironmentSpec, name: str) -> np.ndarray:
    return np.array([float(spec.param(f"{name}_{c}")) for c in "rgb"])


def room_radiance(spec: EnvironmentSpec, directions: np.ndarray) -> np.ndarray:
    """Radiance arriving at the sample from ``directions`` in a box room (analytic, no loops
    over pixels).

    The sample sits at the origin; the room spans ``[−sample_x, size_x − sample_x]`` ×
    ``[−sample_y, size_y − sample_y]`` × ``[−sample_height, height − sample_height]``. Each
    direction hits the nearest box face. Light panels on the ceiling have radiance 1 (times the
    black-body colour of their temperature); a window shows a CIE overcast sky,
    ``L(θ) = L_z (1 + 2 cosθ)/3``, above the horizon and a Lambertian ground below. Walls, floor
    and ceiling reflect a constant bounce term from the integrating-sphere approximation:
    total irradiance ``E = Φ / (A (1 − ρ̄))`` (emitted flux Φ, room area A, mean albedo ρ̄);
    the ceiling, which sees no direct light from its own panels, gets only the indirect part
    ``ρ̄ E``. Radiance of a diffuse surface is ``ρ E / π``.

    Shape:
        - directions: ``(*, 3)`` unit vectors, world frame (+Z up)
        - output: ``(*, 3)``
    """
    p = dict(spec.params)
    sx, sy, height = float(p["size_x"]), float(p["size_y"]), float(p["height"])
    ox, oy, oz = float(p["sample_x"]), float(p["sample_y"]), float(p["sample_height"])
    lo = np.array([-ox, -oy, -oz])
    hi = np.array([sx - ox, sy - oy, height - oz])
    d = directions
    with np.errstate(divide="ignore", invalid="ignore"):
        t_axis = np.where(d > 0, hi / d, np.where(d < 0, lo / d, np.inf))
    axis = np.argmin(t_axis, axis=-1)
    t = np.take_along_axis(t_axis, axis[..., None], axis=-1)
    hit = d * t  # (*, 3) hit point relative to the sample
    room_x, room_y, room_z = hit[..., 0] + ox, hit[..., 1] + oy, hit[..., 2] + oz
    ceiling_hit = (axis == 2) & (d[..., 2] > 0)
    floor_hit = (axis == 2) & (d[..., 2] <= 0)

    wall, ceiling, floor = _rgb(spec, "wall"), _rgb(spec, "ceiling"), _rgb(spec, "floor")
    panel_colour = np.array(blackbody_rgb(float(p["panel_temperature_k"])))
    panels = int(float(p["panel_count"]))
    in_panel = np.zeros(d.shape[:-1], dtype=bool)
    panel_area = 0.0
    for k in range(panels):
        cx, cy = float(p[f"panel{k}_x"]), float(p[f"panel{k}_y"])
        hw, hd = float(p[f"panel{k}_w"]) / 2, float(p[f"panel{k}_d"]) / 2
        in_panel |= ceiling_hit & (np.abs(room_x - cx) <= hw) & (np.abs(room_y - cy) <= hd)
        panel_area += 4 * hw * hd
    flux = math.pi * panel_area * panel_colour  # Lambertian panels of radiance 1·colour

    in_window = np.zeros(d.shape[:-1], dtype=bool)
    outside = np.zeros((*d.shape[:-1], 3))
    window_wall = str(p["window_wall"])
    if window_wall != "none":
        wall_axis = 0 if window_wall in ("+x", "-x") else 1
        sign = 1.0 if window_wall.startswith("+") else -1.0
        along = room_y if wall_axis == 0 else room_x
        centre, half_width = float(p["window_center"]), float(p["window_width"]) / 2
        sill, win_h = float(p["window_sill"]), float(p["window_height"])
        in_window = (
            (axis == wall_axis)
            & (np.sign(d[..., wall_axis]) == sign)
            & (np.abs(along - centre) <= half_width)
            & (room_z >= sill)
            & (room_z <= sill + win_h)
        )
        sky_colour = np.array(blackbody_rgb(float(p["window_temperature_k"]))) * float(p["window_radiance"])
        up = np.clip(d[..., 2], 0.0, 1.0)[..., None]
        sky = sky_colour * (1.0 + 2.0 * up) / 3.0
        # Overcast sky irradiance on the horizontal ground: ∫ L_z (1+2cosθ)/3 cosθ dω = 7π/9 L_z.
        ground = float(p["outside_ground_albedo"]) * (7.0 / 9.0) * sky_colour
        outside = np.where(d[..., 2:3] >= 0.0, sky, ground)
        # Flux through the window: π × area × the mean radiance of the half sky + ground it shows
        # (sky at the horizon L_z/3 up to the zenith; ground dimmer), an approximation.
        mean_outside = 0.5 * (sky_colour * (1.0 / 3.0 + 2.0 / 3.0 * 0.5) + ground)
        flux = flux + math.pi * 2 * half_width * win_h * mean_outside

    area_floor = sx * sy
    area_walls = 2 * height * (sx + sy)
    area = 2 * area_floor + area_walls
    mean_albedo = (area_floor * (floor + ceiling) + area_walls * wall) / area
    total_e = flux / (area * (1.0 - mean_albedo))
    surface = (
        np.where(
            ceiling_hit[..., None],
            ceiling * mean_albedo * total_e,
            np.where(floor_hit[..., None], floor * total_e, wall * total_e),
        )
        / math.pi
    )
    radiance = np.where(in_panel[..., None], panel_colour, surface)
    radiance = np.where(in_window[..., None], outside, radiance)
    return radiance


def _room_environment(spec: EnvironmentSpec, resolution: int) -> Environment:
    directions = equirect_directions(resolution, supersample=ROOM_SUPERSAMPLE)
    radiance = room_radiance(spec, directions).mean(axis=-2)
    return Environment(radiance.astype(np.float32), None)


# ----------------------------------------------------------------------------- files


def scan_environment_folder(path: str | Path) -> list[Path]:
    """The ``.exr``/``.hdr`` files directly in ``path``, sorted by name.

    Raises:
        LightingError: the folder is missing, not a folder or holds no such file.
    """
    folder = Path(path)
    if not folder.exists():
        raise LightingError(f"{folder}: environment folder not found")
    if not folder.is_dir():
        raise LightingError(f"{folder}: not a folder")
    files = sorted(
        (f for f in folder.iterdir() if f.is_file() and f.suffix.lower() in ENVIRONMENT_EXTENSIONS),
        key=lambda f: f.name,
    )
    if not files:
        raise LightingError(f"{folder}: no .exr or .hdr environment maps in this folder")
    return files


def read_environment_file(path: str | Path, resolution: int) -> np.ndarray:
    """Load a lat-long HDR file and area-resize it to ``(resolution, 2·resolution, 3)``.

    Raises:
        LightingError: unreadable file, not about 2:1, or non-finite values.
    """
    import cv2

    from brdfgan.io.images import ImageIOError, read_image

    file = Path(path)
    if file.suffix.lower() == ".hdr":
        if not file.is_file():
            raise LightingError(f"{file}: file not found")
        image = cv2.imread(str(file), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR)
        if image is None:
            raise LightingError(f"{file}: corrupt or unreadable .hdr file")
        image = cv2.cvtColor(image.astype(np.float32), cv2.COLOR_BGR2RGB)
    elif file.suffix.lower() == ".exr":
        try:
            image = read_image(file)
        except ImageIOError as error:
            raise LightingError(str(error)) from error
        image = np.repeat(image, 3, axis=2) if image.shape[2] == 1 else image[:, :, :3]
    else:
        raise LightingError(f"{file}: unsupported environment format, expected .exr or .hdr")
    height, width = image.shape[:2]
    if abs(width / height - 2.0) > 0.02:
        raise LightingError(f"{file}: a lat-long map must be 2:1, got {width}x{height}")
    if not np.isfinite(image).all():
        raise LightingError(f"{file}: contains NaN or infinite values")
    resized = cv2.resize(
        np.ascontiguousarray(image, dtype=np.float32),
        (2 * resolution, resolution),
        interpolation=cv2.INTER_AREA,
    )
    return np.maximum(resized, 0.0).astype(np.float32)


# ----------------------------------------------------------------------------- specs and pools


@dataclass(frozen=True)
class LightingConfig:
    """Environment pools and per-render balance.

    Attributes:
        train_count: procedural environments in the training pool (paper: 20).
        test_count: procedural environments in the disjoint test pool (paper: 6).
        sunsky_fraction: share of sun/sky environments among the procedural ones ...
        room_fraction: ... and of indoor rooms (relative weights, normalised; both 0 means
            user files only).
        folder: user ``.exr``/``.hdr`` lat-long maps; they are added to the pools, shuffled by
            the seed and split disjointly (``file_test_fraction`` of them, at least one, to
            test; at least one to train), so the folder needs at least 2 files.
        file_test_fraction: share of user files that go to the test pool.
        resolution: equirect height (width is twice that).
        env_to_flash_min / env_to_flash_max: range of the log-uniform ratio of environment to
            flash irradiance on the sample. At ≤ 1 the flash stays the main light, as in the
            paper's "predominantly flash lit" photos; at 0.05 the environment is a faint fill
            (a phone flash at ~50 cm typically outshines room light by 1–20× for the short
            exposure it forces). Log-uniform covers each factor of ten equally.
    """

    train_count: int = 20
    test_count: int = 6
    sunsky_fraction: float = 0.5
    room_fraction: float = 0.5
    folder: str | None = None
    file_test_fraction: float = 0.25
    resolution: int = 256
    env_to_flash_min: float = 0.05
    env_to_flash_max: float = 1.0

    def __post_init__(self) -> None:
        key = "dataset_spec.lighting"  # where a lighting spec is configured; messages name the key
        # Without a folder the procedural pools are all there is, and neither may be empty.
        least = 0 if self.folder is not None else 1
        integer(f"{key}.train_count", self.train_count, minimum=least)
        integer(f"{key}.test_count", self.test_count, minimum=least)
        sunsky = in_range(f"{key}.sunsky_fraction", self.sunsky_fraction, 0.0)
        room = in_range(f"{key}.room_fraction", self.room_fraction, 0.0)
        if sunsky + room == 0 and self.folder is None:
            raise DatasetConfigError(
                f"no environment source: {key}.sunsky_fraction and {key}.room_fraction are both 0 "
                f"and no {key}.folder is given"
            )
        fraction = self.file_test_fraction
        in_range(f"{key}.file_test_fraction", fraction, 0.0, 1.0, low_open=True, high_open=True)
        integer(f"{key}.resolution", self.resolution, minimum=4)
        ordered(key, self, "env_to_flash_min", "env_to_flash_max")
        in_range(f"{key}.env_to_flash_min", self.env_to_flash_min, 0.0, low_open=True)  # log-uniform


@dataclass(frozen=True)
class EnvironmentPools:
    """Disjoint training and test environments."""

    train: tuple[EnvironmentSpec, ...]
    test: tuple[EnvironmentSpec, ...]


_KIND_CODES: dict[str, int] = {"sunsky": 1, "room": 2, "file": 3}


def _kind_rng(seed: int, kind: str, index: int) -> np.random.Generator:
    # One independent stream per (seed, kind, index): adding environments of one kind never
    # changes the others.
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, _KIND_CODES[kind], index])


def sunsky_spec(index: int, seed: int) -> EnvironmentSpec:
    """The ``index``-th random sun/sky environment of ``seed``."""
    rng = _kind_rng(seed, "sunsky", index)
    params = {
        "elevation_deg": rng.uniform(10.0, 80.0),
        "azimuth_deg": rng.uniform(0.0, 360.0),
        "turbidity": rng.uniform(2.0, 8.0),
        "ground_albedo": rng.uniform(0.1, 0.4),
    }
    return make_spec(f"sunsky-{index:04d}", "sunsky", params)


def room_spec(index: int, seed: int) -> EnvironmentSpec:
    """The ``index``-th random room of ``seed``."""
    return make_spec(f"room-{index:04d}", "room", _sample_room_params(_kind_rng(seed, "room", index)))


def file_specs(folder: str | Path) -> list[EnvironmentSpec]:
    """One spec per file of :func:`scan_environment_folder` (id ``file-<stem>``, or
    ``file-<name>`` when two files share a stem)."""
    files = scan_environment_folder(folder)
    stems = [f.stem for f in files]
    return [
        make_spec(
            f"file-{f.stem if stems.count(f.stem) == 1 else f.name}", "file", {"path": str(f.resolve())}
        )
        for f in files
    ]


def _split_counts(count: int, config: LightingConfig) -> tuple[int, int]:
    total = config.sunsky_fraction + config.room_fraction
    sunsky = round(count * config.sunsky_fraction / total) if total > 0 else 0
    return sunsky, (count - sunsky if total > 0 else 0)


def build_environment_pools(config: LightingConfig, seed: int) -> EnvironmentPools:
    """Training and test pools, deterministic in ``seed``, with disjoint ids.

    Procedural environments are numbered per kind across both pools (training first), so a test
    environment is never a training one. User files are shuffled by the seed and split.

    Every user file is read and checked here (:func:`check_environment_file`), so a corrupt one
    fails before any work instead of when a render first draws it, possibly hours in.

    Raises:
        LightingError: the folder is unusable, holds fewer than 2 files or a file is unusable.
    """
    train: list[EnvironmentSpec] = []
    test: list[EnvironmentSpec] = []
    counters = {"sunsky": 0, "room": 0}
    for pool, count in ((train, config.train_count), (test, config.test_count)):
        n_sunsky, n_room = _split_counts(count, config)
        for kind, n, make in (("sunsky", n_sunsky, sunsky_spec), ("room", n_room, room_spec)):
            for _ in range(n):
                pool.append(make(counters[kind], seed))
                counters[kind] += 1
    if config.folder is not None:
        files = file_specs(config.folder)
        if len(files) < 2:
            raise LightingError(
                f"{config.folder}: needs at least 2 environment maps to split into train and test, "
                f"found {len(files)}"
            )
        for spec in files:
            check_environment_file(spec, config.resolution)
        order = _kind_rng(seed, "file", 0).permutation(len(files))
        n_test = min(max(1, round(len(files) * config.file_test_fraction)), len(files) - 1)
        test += [files[i] for i in order[:n_test]]
        train += [files[i] for i in order[n_test:]]
    if not train or not test:
        raise ValueError(f"empty environment pool: {len(train)} train, {len(test)} test")
    return EnvironmentPools(tuple(train), tuple(test))


def check_environment_file(spec: EnvironmentSpec, resolution: int) -> None:
    """Decode a ``file`` environment as the renders will (through the :func:`load_environment`
    cache, so the first renders reuse it) and check that it lights the sample.

    Raises:
        LightingError: naming the file: unreadable, corrupt, not 2:1, non-finite, or black above
            the horizon (it could not be balanced against the flash).
    """
    environment = load_environment(spec, resolution)
    if not environment.plane_irradiance() > 0.0:
        raise LightingError(f"{spec.param('path')}: puts no light on the sample (black above the horizon)")


@lru_cache(maxsize=32)
def load_environment(spec: EnvironmentSpec, resolution: int) -> Environment:
    """Build the environment of a spec at equirect height ``resolution`` (cached; the array is
    read-only, :meth:`Environment.rotated`/:meth:`Environment.scaled` return new ones).

    Sun/sky needs Mitsuba (imported lazily); rooms and files do not.
    """
    if spec.kind == "sunsky":
        environment = _sunsky_environment(spec, resolution)
    elif spec.kind == "room":
        environment = _room_environment(spec, resolution)
    elif spec.kind == "file":
        environment = Environment(read_environment_file(str(spec.param("path")), resolution), None)
    else:
        raise ValueError(f"unknown environment kind {spec.kind!r}")
    environment.radiance.setflags(write=False)
    return environment


def environment_map(spec: EnvironmentSpec, resolution: int) -> np.ndarray:
    """The equirect radiance array of a spec (sun not included; see :func:`load_environment`).

    Shape:
        - output: ``(resolution, 2·resolution, 3)`` float32, read-only
    """
    return load_environment(spec, resolution).radiance


# ----------------------------------------------------------------------------- per-render draws


@dataclass(frozen=True)
class LightingDraw:
    """The random lighting of one render: which environment, its rotation about the up axis and
    the environment-to-flash irradiance ratio."""

    spec: EnvironmentSpec
    rotation_rad: float
    env_to_flash_ratio: float

    def to_json(self) -> dict[str, Any]:
        return {
            "environment": self.spec.to_json(),
            "rotation_deg": math.degrees(self.rotation_rad),
            "env_to_flash_ratio": self.env_to_flash_ratio,
        }


def sample_env_to_flash_ratio(config: LightingConfig, generator: torch.Generator) -> float:
    """Log-uniform ratio in ``[env_to_flash_min, env_to_flash_max]``."""
    u = float(torch.rand((), generator=generator, dtype=torch.float64))
    return log_uniform(u, config.env_to_flash_min, config.env_to_flash_max)


def draw_lighting(
    pool: Sequence[EnvironmentSpec], config: LightingConfig, generator: torch.Generator
) -> LightingDraw:
    """Pick an environment uniformly from ``pool``, a uniform rotation and a balance ratio."""
    if not pool:
        raise ValueError("empty environment pool")
    index = int(torch.randint(len(pool), (), generator=generator))
    angle = float(torch.rand((), generator=generator, dtype=torch.float64)) * 2.0 * math.pi
    return LightingDraw(pool[index], angle, sample_env_to_flash_ratio(config, generator))


def realize_lighting(draw: LightingDraw, flash_irradiance_value: float, resolution: int) -> Environment:
    """The drawn environment, rotated and scaled so its plane irradiance is
    ``ratio · flash_irradiance_value``."""
    return balance_environment(load_environment(draw.spec, resolution), draw, flash_irradiance_value)


def balance_environment(
    environment: Environment, draw: LightingDraw, flash_irradiance_value: float
) -> Environment:
    """``environment`` (the draw's, however it was loaded) rotated by the draw and scaled so its
    plane irradiance is ``ratio · flash_irradiance_value``."""
    rotated = environment.rotated(draw.rotation_rad)
    return normalize_environment(rotated, draw.env_to_flash_ratio * flash_irradiance_value)


def flash_centre_irradiance(flash_rgb: Sequence[float], position: Sequence[float]) -> float:
    """Luminance of the irradiance a flash of RGB radiant intensity ``flash_rgb`` (W/sr) at
    ``position`` puts on the sample centre: ``I · cos θ / d²`` (cos θ = 1 straight above it)."""
    distance = math.hypot(*position)
    return flash_irradiance(flash_rgb, distance) * (position[2] / distance)
