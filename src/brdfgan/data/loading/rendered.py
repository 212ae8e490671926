"""Training photos rendered on the fly: a bank of material maps, fresh capture conditions for every
draw, the project's torch renderer.

Shards (:mod:`brdfgan.data.generation.generation`) photograph each training material once or a few times,
under one light each, and cost every fresh machine the whole generation before its first step.
Here a training sample is drawn anew every time:

1. **A material from the bank** (:class:`MaterialBank`): the training materials of a dataset spec
   — the procedural families (mixed and recoloured as the spec says) painted once and cached on
   disk, plus the spec's training scan sets read from their folder — one of them drawn at random,
   a scan with the spec's ``scans.fraction``; a scan is recoloured afresh with its
   ``recolor_probability``.
2. **A crop** of it, as generation cuts one (the material's or the spec's crop sampling).
3. **Capture conditions** from the spec: the camera (field of view, tilt, distance), the flash
   (offset, intensity, colour temperature), the exposure error, and an environment of the training
   pool rotated and balanced against the flash, turned into distant lights
   (:func:`~brdfgan.core.lighting.environment_lights`).
4. **The photo**: :func:`photograph_scenes` renders the flash and the distant lights with
   :func:`~brdfgan.core.render.render_point_lights` (the BRDF of the rendering loss and of the
   Mitsuba-checked conventions) in texture space, resamples it into the photo's pixels through the
   camera (:func:`~brdfgan.core.render.view_grid`, the warp that aligns maps to shard photos) and
   auto-exposes it off by the drawn error. This runs in
   :meth:`RenderedDataModule.on_after_batch_transfer`, on the device the model trains on: the
   CPU workers draw and crop, a GPU renders.
5. **The phone** (``sensor``, :class:`~brdfgan.data.phone.sensor.SensorEffects`) and the train crop, as
   for shard photos.

With ``pairs`` (:class:`~brdfgan.data.phone.pairs.PairSampling`, off by default) every draw is a
flash + no-flash pair (:func:`photograph_pairs`): the same scene with the flash and the room light,
and with the room light alone, each shot auto-exposed off by its own drawn error and
white-balanced on its own, the no-flash shot moved a little as a handheld phone moves it, and
each through the phone on its own. Its draws come from a stream of their own, so the flash
photo's scene is the one drawn without pairs.

Validation and test stay Mitsuba shards (only those splits are generated), so no model is graded
by the renderer it trained on. Every draw is a pure function of ``(seed, epoch, rank, batch,
position)``: a resumed run sees the same photos as an uninterrupted one.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import multiprocessing
import random
import zipfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import DataLoader

from brdfgan.capture import NO_FLASH_PHOTO, TRAINING_CAPTURE
from brdfgan.core.exposure import auto_exposure_scale
from brdfgan.core.lighting import Environment, SunLight, environment_lights
from brdfgan.core.relight import SKY_LIGHT_DISTANCE
from brdfgan.core.render import PointLights, render_point_lights, view_grid, warp_maps_to_view, warp_to_view
from brdfgan.core.sampling import log_uniform
from brdfgan.core.svbrdf import BASECOLOR, NORMAL, normalize_normal
from brdfgan.data.loading.datamodule import (
    EpochStream,
    ShardDataModule,
    collate_samples,
    random_crop,
    sensed_sample,
)
from brdfgan.data.materials.augment import random_crops
from brdfgan.data.materials.base import height_to_normal
from brdfgan.data.materials.noise import fbm
from brdfgan.data.materials.scanned import read_scanned_material, scanned_material_folders
from brdfgan.data.materials.source import PaintedMaterial, recolor_scan
from brdfgan.data.phone.conditions import CaptureDraw
from brdfgan.data.phone.environments import (
    EnvironmentSpec,
    balance_environment,
    build_environment_pools,
    draw_lighting,
    flash_centre_irradiance,
    load_environment,
)
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.phone.pairs import PAIR_BATCH_KEYS, PairDraw, PairSampling, misregister, pair_meta
from brdfgan.data.spec.dataset_spec import (
    DatasetSpec,
    paint_material,
    scan_materials,
    split_materials,
    split_scan_sets,
)
from brdfgan.data.spec.determinism import derive_seed, material_seed, single_torch_thread
from brdfgan.data.storage.shards import Sample, ShardError, decode_maps, encode_maps
from brdfgan.data.storage.spec_checks import DatasetConfigError, in_range, integer, ordered
from brdfgan.io.atomic import atomic_replace, write_text_atomic

__all__ = [
    "MaterialBank",
    "PhotoScene",
    "ReliefSampling",
    "RenderedDataModule",
    "RenderedStream",
    "capture_scene",
    "draw_scene",
    "pair_tensors",
    "photograph_pairs",
    "photograph_scenes",
    "render_scenes",
    "scene_tensors",
]

log = logging.getLogger(__name__)

# Pairs off: every draw a single flash photo (the default).
SINGLE_PHOTOS = PairSampling()

BANK_VERSION = 1
INDEX_FILE = "bank.json"
ENVIRONMENTS_IDENTITY = "identity"  # environments.npz's entry naming what it tabulates
# What of a dataset spec decides its training materials (the rest — crops, capture, lighting,
# flash — is drawn per photo here); a bank is identified by these alone.
_MATERIAL_KEYS = (
    "seed",
    "materials",
    "families",
    "material_resolution",
    "test_fraction",
    "val_fraction",
    "mixing",
    "recolor",
    "scans",
)


def bank_identity(spec: DatasetSpec) -> dict[str, Any]:
    """The parts of ``spec`` that decide its training materials, with the bank format version."""
    description = spec.to_json()
    return {"bank_version": BANK_VERSION, **{key: description.get(key) for key in _MATERIAL_KEYS}}


class MaterialBank:
    """The training materials of ``spec``, painted once into ``folder/<identity digest>/``.

    :meth:`build` paints every procedural training material (each exactly as generation paints
    it: same seed, family, partner, recolour) into ``m<index>.u16z`` (the maps' 16-bit shard
    encoding), tabulates the training environments into ``environments.npz`` (so rendering needs
    no Mitsuba) and writes ``bank.json`` last; a killed build resumes with the files it finished.
    The training scan sets are read from ``spec.scans.folder`` when first drawn and kept in memory.
    """

    def __init__(
        self,
        spec: DatasetSpec,
        folder: str | Path,
        environment_resolution: int = 64,
        paint_workers: int = 1,
    ) -> None:
        if paint_workers < 1:
            raise DatasetConfigError(f"data.bank.paint_workers={paint_workers}: must be >= 1")
        if spec.scanned is not None:
            raise DatasetConfigError(
                "dataset_spec.scanned: a scanned dataset is test only; it has no training materials to bank"
            )
        if environment_resolution < 4:
            raise DatasetConfigError(
                f"data.bank.environment_resolution={environment_resolution}: must be >= 4"
            )
        self.spec = spec
        identity = bank_identity(spec)
        digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:16]
        self.root = Path(folder) / digest
        self.identity = identity
        self.environment_resolution = environment_resolution
        self.paint_workers = paint_workers
        scans = scan_materials(spec)
        self.procedural = tuple(i for i in split_materials(spec)["train"] if i not in scans)
        if spec.scans.enabled:
            folders = scanned_material_folders(str(spec.scans.folder), key="dataset_spec.scans.folder")
            self.scan_folders = tuple(folders[i] for i in split_scan_sets(spec)["train"])
        else:
            self.scan_folders = ()
        if not self.procedural and not self.scan_folders:
            raise DatasetConfigError("dataset_spec: no training material to bank")
        pools = build_environment_pools(spec.lighting, derive_seed(spec.seed, "lighting"))
        self.environments = pools.train
        self._scans: dict[int, Tensor] = {}
        self._environments: dict[str, Environment] = {}
        self._meta: dict[int, dict[str, Any]] = {}

    # -- building -------------------------------------------------------------------------

    def ready(self) -> bool:
        """Whether the bank is complete (its ``bank.json`` written for this identity)."""
        index = self.root / INDEX_FILE
        if not index.exists():
            return False
        try:
            return bool(json.loads(index.read_text())["identity"] == self.identity)
        except (OSError, ValueError, KeyError):
            return False

    def material_path(self, index: int) -> Path:
        return self.root / f"m{index:06d}.u16z"

    def build(self, progress: bool = True) -> Path:
        """Paint what is missing and write ``bank.json``; a complete bank is left as it is.

        ``paint_workers`` processes paint at once; each material's bytes depend on its index
        alone (its own seed, one torch thread), so the bank is the same for any worker count.
        """
        from tqdm import tqdm

        if self.ready():
            return self.root
        self.root.mkdir(parents=True, exist_ok=True)
        materials: dict[str, Any] = {}
        for index in self.procedural:  # painted by a build that was killed later: kept
            meta_path = self.material_path(index).with_suffix(".json")
            if self.material_path(index).exists() and meta_path.exists():
                materials[str(index)] = json.loads(meta_path.read_text())
        missing = [index for index in self.procedural if str(index) not in materials]
        paths = [self.material_path(index) for index in missing]
        bar = tqdm(total=len(self.procedural), initial=len(materials),
                   desc="material bank", unit="material", disable=not progress)  # fmt: skip
        with bar, contextlib.ExitStack() as stack:
            painted: Iterator[dict[str, Any]]
            if self.paint_workers == 1 or len(missing) <= 1:
                painted = map(paint_bank_material, [self.spec] * len(missing), missing, paths)
            else:
                # spawn, not fork: the parent's torch thread pool may already be running.
                context = multiprocessing.get_context("spawn")
                workers = min(self.paint_workers, len(missing))
                pool = stack.enter_context(ProcessPoolExecutor(workers, mp_context=context))
                painted = pool.map(paint_bank_material, [self.spec] * len(missing), missing, paths)
            for index, meta in zip(missing, painted, strict=True):
                materials[str(index)] = meta
                bar.update()
        self.tabulate_environments()
        index_text = json.dumps(
            {
                "identity": self.identity,
                "materials": materials,
                "scan_sets": [folder.name for folder in self.scan_folders],
                "environments": [spec.env_id for spec in self.environments],
                "environment_resolution": self.environment_resolution,
            },
            sort_keys=True,
        )
        write_text_atomic(self.root / INDEX_FILE, index_text)
        return self.root

    def tabulate_environments(self, path: Path | None = None) -> Path:
        """Tabulate the training environments into ``path`` (default: the bank's
        ``environments.npz``), unless the table there is of these very environments at this
        resolution (its ``identity`` entry: every environment's spec and the resolution): a killed
        build's, or one tabulated elsewhere and carried to a machine without Mitsuba, which the
        sun-and-sky environments need. A table of other lighting settings is tabulated again."""
        path = path or self.root / "environments.npz"
        identity = self._environments_identity()
        if path.exists() and self._environments_table_identity(path) == identity:
            return path
        arrays: dict[str, np.ndarray] = {ENVIRONMENTS_IDENTITY: np.frombuffer(identity, dtype=np.uint8)}
        for spec in self.environments:
            environment = load_environment(spec, self.environment_resolution)
            arrays[f"{spec.env_id}/radiance"] = environment.radiance
            if environment.sun is not None:
                arrays[f"{spec.env_id}/sun"] = np.asarray(
                    [*environment.sun.direction, *environment.sun.irradiance], dtype=np.float64
                )
        with atomic_replace(path, keep_suffix=True) as temp:
            np.savez(temp, allow_pickle=False, **arrays)
        return path

    def _environments_identity(self) -> bytes:
        specs = [spec.to_json() for spec in self.environments]
        return json.dumps(
            {"environments": specs, "resolution": self.environment_resolution}, sort_keys=True
        ).encode()

    @staticmethod
    def _environments_table_identity(path: Path) -> bytes | None:
        """The ``identity`` a table at ``path`` was written with (``None``: none, or unreadable)."""
        try:
            with np.load(path) as data:
                return bytes(data[ENVIRONMENTS_IDENTITY]) if ENVIRONMENTS_IDENTITY in data.files else None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile):  # unreadable: tabulated again
            return None

    # -- drawing --------------------------------------------------------------------------

    def environment(self, spec: EnvironmentSpec) -> Environment:
        """A training environment as tabulated in the bank."""
        if not self._environments:
            with np.load(self.root / "environments.npz") as data:
                for env in self.environments:
                    sun = data.get(f"{env.env_id}/sun")
                    self._environments[env.env_id] = Environment(
                        np.asarray(data[f"{env.env_id}/radiance"], dtype=np.float32),
                        None if sun is None else SunLight(_triple(sun[:3]), _triple(sun[3:])),
                    )
        return self._environments[spec.env_id]

    def draw(self, generator: torch.Generator) -> PaintedMaterial:
        """A material at random: a training scan set with probability ``scans.fraction`` (freshly
        recoloured with ``scans.recolor_probability``), else a banked procedural material."""
        u = torch.rand(3, generator=generator, dtype=torch.float64).tolist()
        count = self.procedural_count
        if self.scan_folders and (not count or u[0] < self.spec.scans.fraction):
            which = min(int(u[1] * len(self.scan_folders)), len(self.scan_folders) - 1)
            return self.scan_material(which, u[2], generator)
        return self.procedural_material(min(int(u[1] * count), count - 1))

    @property
    def procedural_count(self) -> int:
        """How many procedural materials :meth:`draw` chooses among."""
        return len(self.procedural)

    def procedural_material(self, position: int) -> PaintedMaterial:
        """The ``position``-th banked procedural material, decoded from its file."""
        index = self.procedural[position]
        path = self.material_path(index)
        try:
            maps = decode_maps(path.read_bytes(), str(path))
        except OSError as error:
            raise ShardError(
                f"{path}: cannot read the banked material ({error}); delete {self.root}"
            ) from error
        meta = self._material_meta(index)
        return PaintedMaterial(maps, meta["family"], meta["parameters"], meta["extra"])

    def _material_meta(self, index: int) -> dict[str, Any]:
        if not self._meta:
            recorded = json.loads((self.root / INDEX_FILE).read_text())["materials"]
            self._meta = {int(key): value for key, value in recorded.items()}
        return self._meta[index]

    def scan_material(self, which: int, recolor_draw: float, generator: torch.Generator) -> PaintedMaterial:
        """Training scan set ``which`` (read once, then kept), recoloured when ``recolor_draw`` is
        below ``scans.recolor_probability`` with a draw from ``generator``."""
        folder = self.scan_folders[which]
        if which not in self._scans:
            self._scans[which] = read_scanned_material(folder, self.spec.scans.resolution)
        maps = self._scans[which]
        extra: dict[str, Any] = {}
        recolor = replace(self.spec.recolor, probability=self.spec.scans.recolor_probability)
        if recolor.probability > 0 and recolor_draw < recolor.probability:
            maps, extra["recolor"] = recolor_scan(maps, recolor, generator)
        return PaintedMaterial(maps, f"scanned/{folder.name}", {}, extra, self.spec.scans.crop)


def paint_bank_material(spec: DatasetSpec, index: int, path: Path) -> dict[str, Any]:
    """Paint training material ``index`` of ``spec`` as generation paints it into ``path`` (a
    bank's ``m<index>.u16z``), its family, parameters and extras into the ``.json`` beside it
    first, each written atomically: a maps file on disk always has its metadata beside it. On one
    torch thread, so the bytes do not depend on the core count. Returns the metadata."""
    with single_torch_thread():
        generator = torch.Generator().manual_seed(material_seed(spec.seed, index))
        material = paint_material(spec, "train", index, generator)
    meta = _material_meta(material)
    write_text_atomic(path.with_suffix(".json"), json.dumps(meta, sort_keys=True))
    with atomic_replace(path) as temp:
        temp.write_bytes(encode_maps(material.maps))
    return meta


def _material_meta(material: PaintedMaterial) -> dict[str, Any]:
    return {"family": material.family, "parameters": material.parameters, "extra": material.extra}


def _triple(values: np.ndarray) -> tuple[float, float, float]:
    return (float(values[0]), float(values[1]), float(values[2]))


# ----------------------------------------------------------------------------- relief


@dataclass(frozen=True)
class ReliefSampling:
    """Relief laid over a drawn material's crop, so a share of the photos shows relief that its
    base colour does not outline (off by default: every material as painted).

    A painted material's relief and albedo come from one height field — grout is both a dark line
    and a groove — so a network can read either from the other; in a share of the photos here they
    are independent:

    - ``swap_probability``: the crop takes the normals of another bank material's crop;
    - ``bump_probability``: smooth relief is added to the normals (broad bumps and dents to fine
      grain): an fbm height of ``cells`` base cells across the crop (log-uniform in
      ``[bump_cells_min, bump_cells_max]``, four octaves), scaled to an RMS slope log-uniform in
      ``[bump_slope_min, bump_slope_max]``, its slopes added to the crop's;
    - ``plain_albedo_probability``: the base colour's texture is faded toward its mean (per
      channel, contrast uniform in ``[0, 1)``), so the photo's variation is mostly the relief's
      shading. Relief under a uniform albedo is what a network learns from fastest
      (research/notes/2026-12-relief-investigation.md); the faded crops teach what relief shading
      looks like, the others to tell it from a texture;
    - ``flat_probability``: the crop's own relief is removed (its normals set flat) unless swapped,
      so the base colour's texture appears over a flat surface — wood grain, marble veins, print:
      the near-flat held-out scans on which every model drew relief from the texture
      (research/notes/2026-12-v5-candidate.md). Bumps, when drawn, are added after it;
    - ``invert_probability``: the crop's relief (its own, swapped or flat) is turned inside out,
      its slopes negated, so grooves become ridges under the same base colour. Whether a dark line
      is low or high is then not in the base colour — the training scans disagree on it
      (research/notes/2026-12-relief-investigation.md) — and only the photo's shading tells. Bumps
      are added after it.

    Checked on construction, naming the keys under ``data.relief``.
    """

    swap_probability: float = 0.0
    bump_probability: float = 0.0
    bump_slope_min: float = 0.02
    bump_slope_max: float = 0.25
    bump_cells_min: int = 2
    bump_cells_max: int = 32
    plain_albedo_probability: float = 0.0
    flat_probability: float = 0.0
    invert_probability: float = 0.0

    def __post_init__(self) -> None:
        key = "data.relief"
        in_range(f"{key}.swap_probability", self.swap_probability, 0.0, 1.0)
        in_range(f"{key}.bump_probability", self.bump_probability, 0.0, 1.0)
        in_range(f"{key}.plain_albedo_probability", self.plain_albedo_probability, 0.0, 1.0)
        in_range(f"{key}.flat_probability", self.flat_probability, 0.0, 1.0)
        in_range(f"{key}.invert_probability", self.invert_probability, 0.0, 1.0)
        in_range(f"{key}.bump_slope_min", self.bump_slope_min, 0.0, 2.0, low_open=True)
        in_range(f"{key}.bump_slope_max", self.bump_slope_max, 0.0, 2.0, low_open=True)
        ordered(key, self, "bump_slope_min", "bump_slope_max")
        integer(f"{key}.bump_cells_min", self.bump_cells_min, minimum=1)
        integer(f"{key}.bump_cells_max", self.bump_cells_max, minimum=1)
        ordered(key, self, "bump_cells_min", "bump_cells_max")


def add_relief(normal: Tensor, height: Tensor, rms_slope: float) -> Tensor:
    """``normal`` with the slopes of ``height`` (scaled to an RMS slope of ``rms_slope``) added to
    its own: slopes ``(−n_x/n_z, −n_y/n_z)`` add where heights add.

    Shape:
        - normal: ``(3, H, W)`` unit; height: ``(1, H, W)`` any scale
        - output: ``(3, H, W)`` unit

    Example:
        A flat map plus a periodic ripple scaled to an RMS slope of 0.1: the result's slopes
        have that RMS, and they point down the ripple (normals lean away from rising height):

        >>> x = torch.arange(16.0)
        >>> ripple = torch.sin(2 * torch.pi * x / 16).expand(1, 16, 16).clone()
        >>> flat = torch.tensor([0.0, 0.0, 1.0]).view(3, 1, 1).expand(3, 16, 16)
        >>> bumped = add_relief(flat, ripple, 0.1)
        >>> slopes = -bumped[:2] / bumped[2:]
        >>> round(float(slopes.square().sum(0).mean().sqrt()), 4), bool(bumped[0, 0, 0] < 0)
        (0.1, True)
    """
    bump = height_to_normal(height)
    bump_slopes = -bump[:2] / bump[2:]
    rms = float(bump_slopes.square().sum(0).mean().sqrt())
    slopes = -normal[:2] / normal[2:].clamp_min(1e-6)
    if rms > 0.0:
        slopes = slopes + bump_slopes * (rms_slope / rms)
    return normalize_normal(torch.cat([-slopes, torch.ones_like(height)]), dim=0)


def _happens(probability: float, generator: torch.Generator) -> bool:
    """One draw from ``generator`` below ``probability``; no draw at all when it is 0, so an option
    switched off leaves every later draw as it was before the option existed."""
    return probability > 0.0 and float(torch.rand(1, generator=generator, dtype=torch.float64)) < probability


def sample_relief(
    bank: MaterialBank, maps: Tensor, sampling: ReliefSampling, generator: torch.Generator
) -> tuple[Tensor, dict[str, Any]]:
    """The crop ``maps`` with :class:`ReliefSampling`'s relief (swapped or flattened, inverted,
    then bumped, then the base colour faded, as drawn from ``generator``; for one ``sampling`` the
    same number of draws whatever happens) and what was drawn.

    Shape:
        - maps: ``(8, R, R)``; output: ``(8, R, R)``
    """
    u = torch.rand(4, generator=generator, dtype=torch.float64).tolist()
    record: dict[str, Any] = {}
    own = normal = maps[NORMAL]
    if u[0] < sampling.swap_probability:
        partner = bank.draw(generator)
        crops, _ = random_crops(partner.maps, 1, maps.shape[-1], generator, partner.crop or bank.spec.crop)
        normal = crops[0][NORMAL]
        record["swap"] = {"family": partner.family}
    bump: Tensor | None = None
    if u[1] < sampling.bump_probability:
        slope = log_uniform(u[2], sampling.bump_slope_min, sampling.bump_slope_max)
        cells = round(log_uniform(u[3], sampling.bump_cells_min, sampling.bump_cells_max))
        bump = fbm(maps.shape[-1], cells, generator, octaves=4)[None]
        record["bumps"] = {"rms_slope": slope, "cells": cells}
    # The fade, then the flattening and the inversion, drawn after the rest (the last two only when
    # on), so that switching any of them on leaves every earlier draw as it was.
    fade = torch.rand(2, generator=generator, dtype=torch.float64).tolist()
    if _happens(sampling.flat_probability, generator) and "swap" not in record:
        normal = torch.tensor([0.0, 0.0, 1.0], dtype=maps.dtype).view(3, 1, 1).expand_as(normal)
        record["flat"] = True
    if _happens(sampling.invert_probability, generator):
        normal = normal * torch.tensor([-1.0, -1.0, 1.0], dtype=maps.dtype).view(3, 1, 1)
        record["inverted"] = True
    if bump is not None:
        normal = add_relief(normal, bump, record["bumps"]["rms_slope"])
    out = maps
    if normal is not own:
        out = maps.clone()
        out[NORMAL] = normal
    if fade[0] < sampling.plain_albedo_probability:
        out = out.clone() if out is maps else out
        mean = out[BASECOLOR].mean(dim=(1, 2), keepdim=True)
        out[BASECOLOR] = mean + fade[1] * (out[BASECOLOR] - mean)
        record["plain_albedo"] = {"contrast": fade[1]}
    return out, record


# ----------------------------------------------------------------------------- one photo's scene


@dataclass(frozen=True)
class PhotoScene:
    """Everything one training photo is rendered from (and its no-flash twin, with ``pair``).

    Shape:
        - maps: ``(8, R, R)`` texture space; camera_position: ``(3,)``
        - light_position, light_rgb: ``(K, 3)`` world units and W/sr (the flash first)
        - grid: ``(R, R, 2)`` the photo's :func:`~brdfgan.core.render.view_grid`
    """

    key: str
    maps: Tensor
    camera_position: Tensor
    light_position: Tensor
    light_rgb: Tensor
    grid: Tensor
    exposure_ev: float
    meta: dict[str, Any]
    pair: PairDraw | None = None


def draw_scene(
    bank: MaterialBank,
    key: str,
    seed: int,
    environment_lights_count: int,
    relief: ReliefSampling = ReliefSampling(),
    pairs: PairSampling = SINGLE_PHOTOS,
) -> PhotoScene:
    """One training photo's scene, a pure function of ``seed``: a bank material and a crop of it,
    the capture, flash and lighting draws of the spec (as
    :func:`~brdfgan.data.generation.generation.material_samples` draws them for a Mitsuba render)
    with the environment as ``environment_lights_count`` distant lights plus its sun; with
    ``pairs`` enabled, the no-flash twin's draw (from a stream of its own: the rest is the scene
    drawn without pairs)."""
    spec = bank.spec
    generator = torch.Generator().manual_seed(seed)
    material = bank.draw(generator)
    crops, transforms = random_crops(material.maps, 1, spec.resolution, generator, material.crop or spec.crop)
    lighting = draw_lighting(bank.environments, spec.lighting, generator)
    flash_intensity, temperature = spec.flash.sample(generator)
    capture = spec.capture.sample(generator)
    red, green, blue = blackbody_rgb(temperature)
    flash_rgb = (flash_intensity * red, flash_intensity * green, flash_intensity * blue)
    environment = balance_environment(
        bank.environment(lighting.spec), lighting, flash_centre_irradiance(flash_rgb, capture.flash_position)
    )
    meta = {
        "split": "train",
        "family": material.family,
        "parameters": material.parameters,
        **material.extra,
        "crop": transforms[0].to_json(),
        "lighting": lighting.to_json(),
        "flash": {"intensity_w_sr": flash_intensity, "temperature_k": temperature},
        "capture": capture.to_json(spec.resolution),
        "render": {"renderer": "torch", "seed": seed, "environment_lights": environment_lights_count},
        "maps_view": "photo",
    }
    lights = environment_lights(environment, environment_lights_count, generator)
    # Drawn last: switching the relief sampling on leaves every other draw of the photo as it was.
    maps, relief_record = sample_relief(bank, crops[0], relief, generator)
    if relief_record:
        meta["relief"] = relief_record
    scene = capture_scene(key, maps, capture, flash_rgb, lights, meta)
    if not pairs.enabled:
        return scene
    pair = pairs.sample(torch.Generator().manual_seed(_mix(seed, "pair")), spec.capture)
    return replace(scene, pair=pair)


def capture_scene(
    key: str,
    maps: Tensor,
    capture: CaptureDraw,
    flash_rgb: tuple[float, float, float],
    distant_lights: tuple[np.ndarray, np.ndarray],
    meta: dict[str, Any],
) -> PhotoScene:
    """The scene of a photo of ``maps`` taken as ``capture`` says, lit by the flash (RGB radiant
    intensity, W/sr) and ``distant_lights`` (:func:`~brdfgan.core.lighting.environment_lights`:
    directions and irradiance), the latter placed as point lights far away (the placement of
    :func:`~brdfgan.core.relight.render_sky`).

    Shape:
        - maps: ``(8, R, R)``; distant_lights: ``(L, 3)``, ``(L, 3)``
    """
    directions, irradiance = distant_lights
    positions = np.concatenate([np.asarray([capture.flash_position]), directions * SKY_LIGHT_DISTANCE])
    rgb = np.concatenate([np.asarray([flash_rgb]), irradiance * SKY_LIGHT_DISTANCE**2])
    resolution = maps.shape[-1]
    return PhotoScene(
        key=key,
        maps=maps,
        camera_position=torch.tensor(capture.camera.origin, dtype=torch.float32),
        light_position=torch.from_numpy(positions).float(),
        light_rgb=torch.from_numpy(rgb).float(),
        grid=view_grid(capture.camera, resolution, resolution, capture.plane_half_size).float(),
        exposure_ev=capture.exposure_ev,
        meta=meta,
    )


def render_scenes(
    maps: Tensor,
    camera_position: Tensor,
    light_position: Tensor,
    light_rgb: Tensor,
    grids: Tensor,
    render: Callable[..., Tensor] = render_point_lights,
) -> Tensor:
    """The linear HDR photos of a batch of scenes, before exposure: the point-light render from
    each camera in texture space, resampled into the photo's pixels. ``render`` is
    :func:`~brdfgan.core.render.render_point_lights` or a compiled copy of it.

    Shape:
        - maps: ``(B, 8, R, R)``; camera_position: ``(B, 3)``
        - light_position, light_rgb: ``(B, K, 3)``; grids: ``(B, R, R, 2)``
        - output: ``(B, 3, R, R)``
    """
    batch, count = light_position.shape[:2]
    lights = PointLights(
        position=light_position.unsqueeze(1),
        intensity=light_rgb.new_ones(batch, 1, count),
        color=light_rgb.unsqueeze(1),
    )
    hdr = render(maps, camera_position.unsqueeze(1), lights)[:, 0]
    return warp_to_view(hdr, grids).clamp_min(0.0)


def photograph_pairs(
    maps: Tensor,
    camera_position: Tensor,
    light_position: Tensor,
    light_rgb: Tensor,
    grids: Tensor,
    exposure_ev: Tensor,
    no_flash_ev: Tensor,
    white_balance: Tensor,
    misregistration: Tensor,
    render: Callable[..., Tensor] = render_point_lights,
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Flash + no-flash pairs of a batch of scenes: the flash (light 0) and the room light (the
    others) rendered apart (:func:`render_scenes`, as many lights as one photo), the flash shot
    their sum and the no-flash shot the room light alone; each auto-exposed off by its own error
    (``exposure_ev``, ``no_flash_ev``), times its white-balance gains and clipped
    (``clip(hdr · scale · 2^ev · g, 0, 1)``); the no-flash shot then moved by
    :func:`~brdfgan.data.phone.pairs.misregister`.

    Returns:
        ``(photos, no_flash, maps_in_view, exposure_scale)``: the flash photos, the no-flash
        photos, the maps as the flash photos show them, the scales applied (flash shot, no-flash
        shot; a black shot's is 0).

    Shape:
        - maps: ``(B, 8, R, R)``; camera_position: ``(B, 3)``
        - light_position, light_rgb: ``(B, K, 3)``; grids: ``(B, R, R, 2)``
        - exposure_ev, no_flash_ev: ``(B,)``; white_balance: ``(B, 2, 3)``; misregistration: ``(B, 3)``
        - output: ``(B, 3, R, R)``, ``(B, 3, R, R)``, ``(B, 8, R, R)``, ``(B, 2)``
    """
    flash = render_scenes(maps, camera_position, light_position[:, :1], light_rgb[:, :1], grids, render)
    room = render_scenes(maps, camera_position, light_position[:, 1:], light_rgb[:, 1:], grids, render)
    hdr = torch.stack([flash + room, room], dim=1)
    stops = torch.stack([exposure_ev, no_flash_ev], dim=1).to(hdr)
    scale = auto_exposure_scale(hdr) * torch.pow(2.0, stops)
    shots = (hdr * scale[..., None, None, None] * white_balance.to(hdr)[..., None, None]).clamp(0.0, 1.0)
    no_flash = misregister(shots[:, 1], misregistration.to(hdr))
    return shots[:, 0], no_flash, warp_maps_to_view(maps, grids), scale


def photograph_scenes(
    maps: Tensor,
    camera_position: Tensor,
    light_position: Tensor,
    light_rgb: Tensor,
    grids: Tensor,
    exposure_ev: Tensor,
    render: Callable[..., Tensor] = render_point_lights,
) -> tuple[Tensor, Tensor, Tensor]:
    """Photos of a batch of scenes: :func:`render_scenes` auto-exposed off by the drawn error
    (``clip(hdr · scale · 2^ev, 0, 1)`` as :func:`~brdfgan.core.exposure.auto_expose`), with the
    maps resampled into the photos' pixels alike.

    Returns:
        ``(photos, maps_in_view, exposure_scale)``: linear LDR photos, the maps as the photos show
        them, the scales applied.

    Shape:
        - maps: ``(B, 8, R, R)``; camera_position: ``(B, 3)``
        - light_position, light_rgb: ``(B, K, 3)``; grids: ``(B, R, R, 2)``; exposure_ev: ``(B,)``
        - output: ``(B, 3, R, R)``, ``(B, 8, R, R)``, ``(B,)``
    """
    hdr = render_scenes(maps, camera_position, light_position, light_rgb, grids, render)
    scale = auto_exposure_scale(hdr) * torch.pow(2.0, exposure_ev.to(hdr))
    photos = (hdr * scale[:, None, None, None]).clamp(0.0, 1.0)
    return photos, warp_maps_to_view(maps, grids), scale


# ----------------------------------------------------------------------------- streaming


def _mix(*parts: int | str) -> int:
    return derive_seed(*parts) & 0x7FFFFFFFFFFFFFFF


def scene_tensors(batch: Mapping[str, Any]) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor]:
    """A :func:`collate_scenes` batch's tensors in the order :func:`photograph_scenes` takes them
    (the first five: :func:`render_scenes`): maps, camera position, light positions and colours,
    view grids, exposure errors."""
    return (
        batch["scene_maps"],
        batch["camera_position"],
        batch["light_position"],
        batch["light_rgb"],
        batch["grid"],
        batch["exposure_ev"],
    )


def pair_tensors(batch: Mapping[str, Any]) -> tuple[Tensor, Tensor, Tensor]:
    """A :func:`collate_scenes` batch of pairs' twin draws, in the order :func:`photograph_pairs`
    takes them after :func:`scene_tensors`: no-flash exposure errors, white-balance gains,
    misregistrations."""
    return batch["no_flash_ev"], batch["white_balance"], batch["misregistration"]


def collate_scenes(scenes: Sequence[PhotoScene]) -> dict[str, Any]:
    """A batch of scenes (what :class:`RenderedStream` yields, before rendering); scenes of pairs
    add their twins' draws (:func:`pair_tensors`).

    Shape:
        - output["scene_maps"]: ``(B, 8, R, R)``; output["camera_position"]: ``(B, 3)``
        - output["light_position"], output["light_rgb"]: ``(B, K, 3)``
        - output["grid"]: ``(B, R, R, 2)``; output["exposure_ev"]: ``(B,)``
        - output["key"]: list of B str; output["meta"]: list of B dict
        - pairs: output["no_flash_ev"]: ``(B,)``; output["white_balance"]: ``(B, 2, 3)``;
          output["misregistration"]: ``(B, 3)``
    """
    batch = {
        "scene_maps": torch.stack([scene.maps for scene in scenes]).float(),
        "camera_position": torch.stack([scene.camera_position for scene in scenes]),
        "light_position": torch.stack([scene.light_position for scene in scenes]),
        "light_rgb": torch.stack([scene.light_rgb for scene in scenes]),
        "grid": torch.stack([scene.grid for scene in scenes]),
        "exposure_ev": torch.tensor([scene.exposure_ev for scene in scenes], dtype=torch.float32),
        "key": [scene.key for scene in scenes],
        "meta": [scene.meta for scene in scenes],
    }
    pairs = [scene.pair for scene in scenes if scene.pair is not None]
    if not pairs:
        return batch
    if len(pairs) != len(scenes):
        raise ValueError("a batch of scenes mixes pairs and single photos")
    batch["no_flash_ev"] = torch.tensor([pair.exposure_ev for pair in pairs], dtype=torch.float32)
    batch["white_balance"] = torch.tensor([pair.white_balance for pair in pairs], dtype=torch.float32)
    batch["misregistration"] = torch.tensor([pair.misregistration() for pair in pairs], dtype=torch.float32)
    return batch


class RenderedStream(EpochStream):
    """Batches of training scenes, ``batches_per_epoch`` an epoch, for one rank.

    Batch ``b`` of epoch ``e`` is a pure function of ``(seed, e, rank, b)``; DataLoader workers
    take every ``num_workers``-th batch, which is the order the DataLoader yields them in, so
    skipping the first ``skip_batches`` batches reproduces a resumed run's position exactly.
    """

    def __init__(
        self,
        bank: MaterialBank,
        *,
        batch_size: int,
        batches_per_epoch: int,
        seed: int,
        rank: int = 0,
        environment_lights: int = 16,
        relief: ReliefSampling = ReliefSampling(),
        pairs: PairSampling = SINGLE_PHOTOS,
    ) -> None:
        super().__init__()
        self.bank = bank
        self.relief = relief
        self.pairs = pairs
        self.batch_size = batch_size
        self.batches_per_epoch = batches_per_epoch
        self.seed = seed
        self.rank = rank
        self.environment_lights = environment_lights

    def __len__(self) -> int:
        return self.batches_per_epoch

    def __iter__(self) -> Iterator[dict[str, Any]]:
        worker, num_workers, epoch, skip = self._begin_epoch()
        return self._batches(epoch, range(skip, self.batches_per_epoch)[worker::num_workers])

    def _batches(self, epoch: int, batches: Sequence[int]) -> Iterator[dict[str, Any]]:
        for batch in batches:
            scenes = []
            for position in range(self.batch_size):
                key = f"train-e{epoch}-r{self.rank}-b{batch}-{position}"
                seed = _mix(self.seed, "rendered", epoch, self.rank, batch, position)
                scenes.append(
                    draw_scene(self.bank, key, seed, self.environment_lights, self.relief, self.pairs)
                )
            yield collate_scenes(scenes)


class RenderedDataModule(ShardDataModule):
    """:class:`~brdfgan.data.loading.datamodule.ShardDataModule` whose training photos are rendered on
    the fly from ``bank`` (module docstring); validation and test read Mitsuba shards from
    ``data_dir``, and :meth:`prepare_data` generates only the splits the run needs.

    Args:
        bank: the training materials (its spec is the one the validation and test shards are
            generated with).
        environment_lights: distant lights each photo's environment becomes.
        relief: relief laid over the drawn materials (:class:`ReliefSampling`; default: none).
        pairs: flash + no-flash pairs (:class:`~brdfgan.data.phone.pairs.PairSampling`; default:
            single flash photos).
        compile_renderer: render through ``torch.compile`` (training photos have one shape, so
            it compiles once; worth it for runs of more than a few hundred steps).
        epoch_samples: training photos an epoch (there is no split to count).
        **kwargs: as :class:`~brdfgan.data.loading.datamodule.ShardDataModule` (``train_split`` is unused).
    """

    def __init__(
        self,
        data_dir: str,
        bank: MaterialBank,
        *,
        epoch_samples: int,
        environment_lights: int = 16,
        relief: ReliefSampling | None = None,
        pairs: PairSampling | None = None,
        compile_renderer: bool = False,
        **kwargs: Any,
    ) -> None:
        if environment_lights < 1:
            raise DatasetConfigError(f"data.environment_lights={environment_lights}: must be >= 1")
        super().__init__(data_dir, epoch_samples=epoch_samples, train_split=None, **kwargs)
        self.relief = relief or ReliefSampling()
        self.hparams.pop("bank", None)  # checkpoints hold plain values only
        self.hparams["relief"] = asdict(self.relief)
        self.pairs = pairs or PairSampling()
        self.hparams["pairs"] = asdict(self.pairs)
        self.bank = bank
        self.environment_lights = environment_lights
        self._render = (
            torch.compile(render_point_lights, dynamic=False) if compile_renderer else render_point_lights
        )

    def prepare_data(self) -> None:
        self.bank.build()
        super().prepare_data()

    def _prepare_arguments(self, stage: str | None) -> dict[str, Any]:
        return {"splits": self._shard_splits(stage)}

    def _shard_splits(self, stage: str | None = None) -> tuple[str, ...]:
        """The shard splits ``stage`` reads (``None``: the trainer's stage): validation when
        fitting or validating, test when testing (all without a stage)."""
        if stage is None and self.trainer is not None and self.trainer.state.fn is not None:
            stage = str(self.trainer.state.fn.value)
        wanted = {"fit": ("val",), "validate": ("val",), "test": ("test",), "predict": ("test",)}
        splits = wanted.get(stage or "", ("val", "test"))
        return tuple(split for split in splits if self.splits[split] is not None)

    def num_samples(self, kind: str = "train") -> int:
        if kind == "train":
            assert self.epoch_samples is not None
            return self.epoch_samples
        return super().num_samples(kind)

    def train_dataloader(self) -> DataLoader:
        stream = RenderedStream(
            self.bank,
            batch_size=self.batch_size,
            batches_per_epoch=self.train_batches_per_epoch,
            seed=self.seed,
            rank=self._rank,
            environment_lights=self.environment_lights,
            relief=self.relief,
            pairs=self.pairs,
        )
        stream.epoch, stream.skip_batches = self._train_position()
        self.teardown("fit")
        self._train_loader = self._loader(stream, persistent=self.num_workers > 0)
        return self._train_loader

    def on_after_batch_transfer(self, batch: Any, dataloader_idx: int) -> Any:
        """Render the photos of a batch of scenes where the batch now is (a shard batch passes)."""
        if not isinstance(batch, Mapping) or "scene_maps" not in batch:
            return batch
        return self.photograph(batch)

    def photograph(self, batch: Mapping[str, Any]) -> dict[str, Any]:
        """A batch of scenes as the training batch of
        :func:`~brdfgan.data.loading.datamodule.collate_samples`: rendered
        (:func:`photograph_scenes`, on the batch's device), through ``sensor`` and the train crop
        on the CPU, back on the batch's device. Scenes of pairs are rendered as pairs
        (:func:`photograph_pairs`): each sample holds its twin and ``meta["pair"]``, and the batch
        the pair's keys."""
        device = batch["scene_maps"].device
        pairs = "no_flash_ev" in batch
        twins: Sequence[Tensor | None]
        records: Sequence[dict[str, Any] | None]
        with torch.no_grad():
            if pairs:
                photos, twin_photos, maps, scales = photograph_pairs(
                    *scene_tensors(batch), *pair_tensors(batch), self._render
                )
                flash_scales, twins = scales[:, 0].tolist(), list(twin_photos.cpu())
                records = _pair_records(batch, scales.cpu())
            else:
                photos, maps, scales = photograph_scenes(*scene_tensors(batch), self._render)
                flash_scales = scales.tolist()
                twins, records = [None] * len(flash_scales), [None] * len(flash_scales)
        samples = []
        for key, photo, aligned, scale, meta, twin, record in zip(
            batch["key"], photos.cpu(), maps.cpu(), flash_scales, batch["meta"], twins, records, strict=True
        ):
            exposed = {**meta, "exposure_scale": scale} | ({} if record is None else {"pair": record})
            sample = Sample(key, photo, aligned, exposed, check=False, no_flash=twin)
            seed = int(meta["render"]["seed"])
            if self.sensor is not None and self.sensor.enabled:
                sample = sensed_sample(sample, self.sensor, _mix(seed, "sensor"))
            if self.train_crop is not None:
                sample = random_crop(sample, self.train_crop, random.Random(_mix(seed, "crop")))
            samples.append(sample)
        collated = collate_samples(samples)
        tensors = (*(photo.batch_key for photo in TRAINING_CAPTURE.photos), "maps", "flash")
        for name in (*tensors, *((NO_FLASH_PHOTO.batch_key, *PAIR_BATCH_KEYS) if pairs else ())):
            collated[name] = collated[name].to(device)
        return collated


def _pair_records(batch: Mapping[str, Any], scales: Tensor) -> list[dict[str, Any]]:
    """The ``meta["pair"]`` of every pair of a :func:`collate_scenes` batch rendered with exposure
    ``scales`` (:func:`photograph_pairs`'): what was drawn for the twin, as applied.

    Shape:
        - scales: ``(B, 2)``
    """
    records = []
    for (flash_scale, twin_scale), stops, gains, (dx, dy, angle) in zip(
        scales.tolist(),
        batch["no_flash_ev"].tolist(),
        batch["white_balance"].tolist(),
        batch["misregistration"].tolist(),
        strict=True,
    ):
        twin = {
            "exposure_scale": twin_scale,
            "exposure_ev": stops,
            "shift_px": [dx, dy],
            "rotation_deg": angle,
        }
        records.append(pair_meta(flash_scale, twin, gains))
    return records
