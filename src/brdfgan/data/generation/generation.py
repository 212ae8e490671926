"""Synthetic dataset generation (paper §5): procedural materials → crops → Mitsuba captures → shards.

The protocol, and where each step lives:

1. ``materials`` material seeds are drawn from the dataset seed and **split before anything else**
   (paper: 80:20 on the materials, never on their crops): a seeded permutation puts
   ``test_fraction`` of the material indices in ``test``, ``val_fraction`` in ``val`` and the rest
   in ``train``. A material index, its seed and all its crops belong to exactly one split —
   :mod:`brdfgan.data.spec.dataset_spec`.
2. Each material is one family of the registry (round-robin over the configured families, so
   small datasets stay balanced) with every parameter drawn from its clipped normal, painted at
   ``material_resolution`` (paper: 2048²) — :mod:`brdfgan.data.materials`, as
   :func:`~brdfgan.data.spec.dataset_spec.paint_material` says.
3. ``crops_per_material`` random crops, rotated and scaled to ``resolution`` (paper: 7 at 512²) —
   :mod:`brdfgan.data.materials.augment`.
4. Every crop is photographed ``train_renders`` times in ``train`` (paper: 3) and
   ``eval_renders`` times in ``val``/``test`` (paper: 1): a random environment of the split's
   pool (``test`` uses the disjoint test pool; ``val`` holds out materials, not lighting, so it
   uses the training pool), randomly rotated, balanced against a random flash, through a capture
   geometry and exposure error drawn per photo (off by default: today's fixed camera) — rendered
   with Mitsuba and auto-exposed to linear LDR — :mod:`brdfgan.data.phone.environments`,
   :mod:`brdfgan.data.phone.conditions`, :mod:`brdfgan.mitsuba_render.photos`, :mod:`brdfgan.core.exposure`.
   With ``pairs``, each photo also gets its no-flash twin: the same render with the flash off,
   auto-exposed on its own off by an exposure error of its own — :mod:`brdfgan.data.phone.pairs`.
5. Materials are grouped ``materials_per_shard`` at a time into WebDataset shards
   ``<split>/<split>-NNNNNN.tar``, their samples stored in ``shard_format`` —
   :mod:`brdfgan.data.storage.shards`. A shard is the unit of work
   and a pure function of (spec, split, shard index): re-running skips complete shards, so a
   killed run resumes without duplicates, and any subset of shards can run in another process or
   on another machine (``generate.py shard=…``). Each shard's SHA-256 is recorded the moment it
   is complete (beside it, then in the split's manifest); a rerun checks complete shards against
   it and rewrites, byte for byte, any that were corrupted since, naming them.

Every random draw comes from a generator seeded by a hash of (dataset seed, material index), so
the bytes of a shard do not depend on which process made it, or in which order
(:mod:`brdfgan.data.spec.determinism`).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import subprocess
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import torch
from torch import Tensor

import brdfgan
from brdfgan import __version__
from brdfgan.core.render import FlashCapture
from brdfgan.core.svbrdf import InvalidMapsError, validate_maps
from brdfgan.data.materials.augment import random_crops
from brdfgan.data.phone.conditions import CaptureDraw
from brdfgan.data.phone.environments import (
    EnvironmentPools,
    LightingDraw,
    build_environment_pools,
    draw_lighting,
    flash_centre_irradiance,
    realize_lighting,
)
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.phone.pairs import draw_exposure_ev, pair_meta
from brdfgan.data.spec.dataset_spec import SPLITS, DatasetSpec, paint_material, split_materials
from brdfgan.data.spec.determinism import derive_seed, material_seed, single_torch_thread
from brdfgan.data.storage.shards import (
    LEGACY_SHARD_FORMAT,
    SHARD_FORMATS,
    Sample,
    ShardError,
    ShardInfo,
    list_shards,
    read_digest,
    read_manifest,
    sha256_file,
    shard_path,
    verify_shard,
    write_digest,
    write_manifest,
    write_shard,
)
from brdfgan.data.storage.spec_checks import DatasetConfigError
from brdfgan.errors import DiskFullError, is_disk_full
from brdfgan.io.atomic import write_text_atomic

log = logging.getLogger(__name__)

SPEC_FILE = "dataset.json"


@dataclass(frozen=True)
class ShardJob:
    """One unit of work: the materials of shard ``index`` of ``split``."""

    split: str
    index: int
    materials: tuple[int, ...]

    def sample_count(self, spec: DatasetSpec) -> int:
        return len(self.materials) * spec.crops_per_material * spec.renders_per_crop(self.split)


def plan_shards(spec: DatasetSpec) -> list[ShardJob]:
    """All shard jobs of the dataset in a fixed order (train, val, test; by index)."""
    jobs: list[ShardJob] = []
    for split, materials in split_materials(spec).items():
        step = spec.materials_per_shard
        for index, start in enumerate(range(0, len(materials), step)):
            jobs.append(ShardJob(split, index, materials[start : start + step]))
    return jobs


class PhotographFn(Protocol):
    """(maps (8, R, R), lighting, flash radiant intensity W/sr, flash temperature K, capture
    geometry and exposure error, render seed) -> (linear LDR photo (3, R, R), exposure scale
    applied). ``flash=False`` takes the photo's no-flash twin: the same room light, balanced
    against the same flash, with the flash off (only asked of it for ``dataset_spec.pairs``)."""

    def __call__(
        self,
        maps: Tensor,
        lighting: LightingDraw,
        flash_intensity: float,
        temperature_k: float,
        capture: CaptureDraw,
        seed: int,
        /,
        *,
        flash: bool = True,
    ) -> tuple[Tensor, float]: ...


class MitsubaPhotographer:
    """The capture simulation: flash colour from its temperature, the drawn environment rotated
    and balanced against the flash (its irradiance at the sample centre from where the drawn
    capture puts it), a Mitsuba render through the drawn camera, auto exposure to linear LDR
    off by the drawn exposure error.

    Keeps one :class:`~brdfgan.mitsuba_render.photos.CaptureRenderer` (scene reuse) and adds up
    the time spent inside ``mi.render`` (``mitsuba_seconds``) for the benchmark.
    """

    def __init__(self, spec: DatasetSpec) -> None:
        from brdfgan.mitsuba_render.photos import CaptureRenderer

        self.capture = FlashCapture()  # the sample size; each photo brings its own camera
        self.environment_resolution = spec.lighting.resolution
        self.renderer = CaptureRenderer(spec.resolution, spec.spp, self.capture, spec.lighting.resolution)
        self.mitsuba_seconds = 0.0

    def __call__(
        self,
        maps: Tensor,
        lighting: LightingDraw,
        flash_intensity: float,
        temperature_k: float,
        capture: CaptureDraw,
        seed: int,
        /,
        *,
        flash: bool = True,
    ) -> tuple[Tensor, float]:
        from brdfgan.mitsuba_render.photos import render_capture

        r, g, b = blackbody_rgb(temperature_k)
        flash_rgb = (flash_intensity * r, flash_intensity * g, flash_intensity * b)
        position = capture.flash_position
        # The room light is balanced against the flash whether or not it fires: a twin shows the
        # room of its flash photo.
        centre_irradiance = flash_centre_irradiance(flash_rgb, position)
        environment = realize_lighting(lighting, centre_irradiance, self.environment_resolution)
        result = render_capture(
            self.renderer,
            maps,
            environment,
            flash_rgb if flash else (0.0, 0.0, 0.0),
            seed=seed,
            camera=capture.camera,
            flash_position=position,
            exposure_ev=capture.exposure_ev,
        )
        if self.renderer.last_timing is not None:
            self.mitsuba_seconds += self.renderer.last_timing.mi_render_s
        return result.ldr, result.exposure_scale


def material_samples(
    spec: DatasetSpec,
    split: str,
    material_index: int,
    pools: EnvironmentPools,
    photograph: PhotographFn,
) -> Iterator[Sample]:
    """The samples of one material: its crops, each photographed ``renders_per_crop(split)`` times.

    Keys are ``<split>-m<material>-c<crop>-r<render>``; metadata records everything needed to
    reproduce or filter a sample (family, parameters, seeds, crop transform, environment id,
    rotation and balance ratio, flash intensity and temperature, capture geometry with the
    flash hotspot's pixel, exposure scale; with ``spec.pairs`` the twin's in ``pair``:
    :func:`~brdfgan.data.phone.pairs.pair_meta`, its ``no_flash`` holding the twin's exposure
    scale, exposure error and render seed).
    """
    seed = material_seed(spec.seed, material_index)
    generator = torch.Generator().manual_seed(seed)
    material = paint_material(spec, split, material_index, generator)
    maps = material.maps
    try:
        validate_maps(maps)
    except InvalidMapsError as error:  # a family bug, not a user error: keep the traceback
        where = f"material {material_index} ({material.family}, {material.parameters}, {material.extra})"
        raise RuntimeError(f"{where}: {error}") from error
    crop_sampling = material.crop or spec.crop
    crops, transforms = random_crops(maps, spec.crops_per_material, spec.resolution, generator, crop_sampling)
    pool = pools.test if split == "test" else pools.train
    for c, (crop, transform) in enumerate(zip(crops, transforms, strict=True)):
        for r in range(spec.renders_per_crop(split)):
            lighting = draw_lighting(pool, spec.lighting, generator)
            flash_intensity, temperature = spec.flash.sample(generator)
            render_seed = derive_seed(seed, "render", c, r) & 0xFFFFFFFF
            # Its own stream per photo: drawing it from ``generator`` would shift every later
            # lighting and flash draw, so turning the randomisation on would change those too.
            capture_generator = torch.Generator().manual_seed(derive_seed(seed, "capture", c, r))
            capture = spec.capture.sample(capture_generator)
            scene = (crop, lighting, flash_intensity, temperature)
            photo, exposure = photograph(*scene, capture, render_seed)
            no_flash, pair = None, {}
            if spec.pairs:
                no_flash, pair["pair"] = _no_flash_twin(
                    spec, photograph, scene, capture, exposure, (seed, c, r)
                )
            yield Sample(
                key=f"{split}-m{material_index:06d}-c{c}-r{r}",
                photo=photo,
                maps=crop,
                no_flash=no_flash,
                meta={
                    "split": split,
                    "material_index": material_index,
                    "material_seed": seed,
                    "family": material.family,
                    "parameters": material.parameters,
                    **material.extra,
                    "crop": {"index": c, **transform.to_json()},
                    "render": {"index": r, "seed": render_seed, "spp": spec.spp},
                    "lighting": lighting.to_json(),
                    "flash": {"intensity_w_sr": flash_intensity, "temperature_k": temperature},
                    "capture": capture.to_json(spec.resolution),
                    "exposure_scale": exposure,
                    **pair,
                },
            )


def _no_flash_twin(
    spec: DatasetSpec,
    photograph: PhotographFn,
    scene: tuple[Tensor, LightingDraw, float, float],
    capture: CaptureDraw,
    flash_exposure: float,
    photo_id: tuple[int, int, int],
) -> tuple[Tensor, dict[str, Any]]:
    """The no-flash twin of the photo of ``scene`` (maps, lighting, flash intensity and
    temperature) taken as ``capture`` with exposure scale ``flash_exposure``, and the sample's
    ``meta["pair"]``. ``photo_id`` is (material seed, crop, render): the twin's exposure error and
    render seed come from streams of their own, drawn only for pairs, so a spec without them keeps
    its bytes."""
    material, crop, render = photo_id
    stream = torch.Generator().manual_seed(derive_seed(material, "no-flash", crop, render))
    exposure_ev = draw_exposure_ev(spec.capture, float(torch.rand((), generator=stream, dtype=torch.float64)))
    seed = derive_seed(material, "render-no-flash", crop, render) & 0xFFFFFFFF
    twin_capture = dataclasses.replace(capture, exposure_ev=exposure_ev)
    no_flash, exposure = photograph(*scene, twin_capture, seed, flash=False)
    twin = {"exposure_scale": exposure, "exposure_ev": exposure_ev, "seed": seed}
    return no_flash, pair_meta(flash_exposure, twin)


@dataclass
class GenerationSummary:
    """What a run did: shards written and skipped (already complete), samples, wall time."""

    out_dir: Path
    written: list[Path] = field(default_factory=list)
    skipped: list[Path] = field(default_factory=list)
    samples: int = 0
    seconds: float = 0.0
    manifests: list[Path] = field(default_factory=list)
    # Shards that existed but were corrupt, truncated or no longer matched their recorded SHA-256
    # (all rewritten; they are in ``written`` too).
    repaired: list[Path] = field(default_factory=list)

    def describe(self) -> str:
        rate = self.samples / self.seconds * 3600.0 if self.seconds > 0 and self.samples else 0.0
        return (
            f"{len(self.written)} shard(s) written, {len(self.skipped)} already complete, "
            f"{self.samples} samples in {self.seconds:.1f} s ({rate:.0f} samples/h) -> {self.out_dir}"
            + (f"; rewrote damaged: {', '.join(p.name for p in self.repaired)}" if self.repaired else "")
            + (f"; manifests: {', '.join(p.parent.name for p in self.manifests)}" if self.manifests else "")
        )


def code_version() -> dict[str, str]:
    """Package version and, from a source checkout, the git commit (recorded in manifests)."""
    version = {"brdfgan": __version__, "torch": torch.__version__}
    checkout = Path(brdfgan.__file__).resolve().parents[2]  # <checkout>/src/brdfgan/__init__.py
    if (checkout / ".git").exists():  # a directory, or a file in a worktree or submodule
        # git itself resolves worktrees, packed refs and detached heads.
        try:
            result = subprocess.run(
                ["git", "-C", str(checkout), "rev-parse", "HEAD"], capture_output=True, text=True, check=False
            )
        except OSError:  # no git on this machine
            return version
        if result.returncode == 0:
            version["git_commit"] = result.stdout.strip()
    return version


def prepare_output_dir(spec: DatasetSpec, out_dir: str | os.PathLike[str]) -> Path:
    """Create ``out_dir`` (and the split folders), check it is writable, and record the spec.

    A directory that already holds a dataset made from a different spec is refused, naming the
    first differing key: mixing shards of two specs would silently corrupt both. The shard format
    is no such difference (see :func:`_in_recorded_format`).
    """
    root = Path(out_dir)
    if root.exists() and not root.is_dir():
        raise DatasetConfigError(f"{root}: output path exists and is not a directory")
    try:
        for split in SPLITS:
            (root / split).mkdir(parents=True, exist_ok=True)
        probe = root / f".write-probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as error:
        if is_disk_full(error):  # not a permission problem: one line, exit 1, like any full disk
            raise DiskFullError(root) from error
        raise DatasetConfigError(
            f"{root}: output directory is not writable ({error.strerror or error})"
        ) from None
    wanted = spec.to_json()
    spec_file = root / SPEC_FILE
    if spec_file.exists():
        try:
            existing = json.loads(spec_file.read_text())
        except (OSError, ValueError) as error:
            raise DatasetConfigError(f"{spec_file}: unreadable dataset spec ({error})") from None
        if _identity(existing) != _identity(wanted):
            key = _first_difference(_identity(existing), _identity(wanted))
            raise DatasetConfigError(
                f"{root} holds a dataset made with a different config ({key} differs); "
                "use another output directory or delete this one"
            )
    else:
        _write_json_atomic(spec_file, wanted)
    return root


def _identity(description: Any) -> Any:
    """A recorded spec less its ``shard_format``: the formats store the same values, so a dataset
    in one is the dataset of the same spec in the other."""
    if not isinstance(description, dict):
        return description
    return {key: value for key, value in description.items() if key != "shard_format"}


def _in_recorded_format(spec: DatasetSpec, root: Path) -> DatasetSpec:
    """``spec`` with the shard format that the dataset in ``root`` records (``dataset.json``;
    none recorded: PNG, the only format before u16z), so that an existing dataset is finished and
    repaired in its own format, byte for byte as its recorded SHA-256s say."""
    spec_file = root / SPEC_FILE
    try:
        recorded = json.loads(spec_file.read_text()).get("shard_format", LEGACY_SHARD_FORMAT)
    except (OSError, ValueError, AttributeError) as error:
        raise DatasetConfigError(f"{spec_file}: unreadable dataset spec ({error})") from None
    if recorded not in SHARD_FORMATS:
        raise DatasetConfigError(
            f"{spec_file}: shard_format={recorded!r} is not one of {', '.join(SHARD_FORMATS)}"
        )
    if recorded == spec.shard_format:
        return spec
    log.warning(
        "%s holds %s shards: continuing in %s (dataset_spec.shard_format=%s applies to new datasets)",
        root, recorded, recorded, spec.shard_format,
    )  # fmt: skip
    return dataclasses.replace(spec, shard_format=recorded)


def _first_difference(a: Any, b: Any, prefix: str = "dataset_spec") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if a.get(key) != b.get(key):
                return _first_difference(a.get(key), b.get(key), f"{prefix}.{key}")
    return prefix


def _write_json_atomic(path: Path, content: Mapping[str, Any]) -> None:
    write_text_atomic(path, json.dumps(content, indent=2, sort_keys=True) + "\n")


def recorded_digests(root: Path, split: str) -> dict[str, str]:
    """Shard name -> SHA-256 as the split's manifest records it (empty without a readable
    manifest, or for one written before digests were recorded)."""
    try:
        manifest = read_manifest(root, split)
    except ShardError:
        return {}  # none yet, or unreadable: finalize_manifests rewrites it
    entries = manifest.get("shards")
    return {
        entry["name"]: entry["sha256"]
        for entry in (entries if isinstance(entries, list) else [])
        if isinstance(entry, dict) and all(isinstance(entry.get(k), str) for k in ("name", "sha256"))
    }


def _recorded(path: Path, manifest_sha256: str | None) -> set[str]:
    """The SHA-256 values recorded for a shard: beside it and in its split's manifest."""
    return {digest for digest in (read_digest(path), manifest_sha256) if digest is not None}


def shard_problem(path: Path, expected: int, manifest_sha256: str | None) -> str | None:
    """Why the existing shard at ``path`` must be rewritten, or ``None`` when it is complete:
    readable tar headers with ``expected`` samples, and bytes whose SHA-256 is the one recorded
    beside it and in the manifest (``manifest_sha256``). A complete shard with no record at all
    (made before digests were kept, or the process died between the shard and its record)
    passed every check that existed then: its digest is recorded now and it is kept, rather
    than regenerating a whole old dataset."""
    try:
        count = verify_shard(path)
        if count != expected:
            return f"{path}: holds {count} samples, expected {expected}"
        recorded = _recorded(path, manifest_sha256)
    except ShardError as error:
        return str(error)
    actual = sha256_file(path)
    if not recorded:
        write_digest(path, actual)
        log.info("%s: no recorded SHA-256 (made before they were recorded); recorded it", path)
        return None
    if recorded != {actual}:
        return f"{path}: SHA-256 differs from the recorded one (the file was modified or corrupted)"
    return None


def select_jobs(jobs: Sequence[ShardJob], shards: int | Sequence[int] | None) -> list[ShardJob]:
    """The jobs with the given positions in :func:`plan_shards`'s order (all for ``None``)."""
    if shards is None:
        return list(jobs)
    wanted = [shards] if isinstance(shards, int) else list(shards)
    bad = [s for s in wanted if not 0 <= s < len(jobs)]
    if bad:
        raise DatasetConfigError(f"shard {bad[0]} out of range: this dataset has shards 0..{len(jobs) - 1}")
    return [jobs[s] for s in sorted(set(wanted))]


def run_generation(
    spec: DatasetSpec,
    out_dir: str | os.PathLike[str],
    *,
    shards: int | Sequence[int] | None = None,
    progress: bool = True,
    photographer: Callable[[DatasetSpec], PhotographFn] | None = None,
) -> GenerationSummary:
    """Generate (or finish) the dataset, or the given subset of its shards; write the manifest of
    every split whose shards are all present. Torch runs on one thread meanwhile
    (:func:`single_torch_thread`)."""
    with single_torch_thread():
        return _run_generation(spec, out_dir, shards=shards, progress=progress, photographer=photographer)


def _run_generation(
    spec: DatasetSpec,
    out_dir: str | os.PathLike[str],
    *,
    shards: int | Sequence[int] | None,
    progress: bool,
    photographer: Callable[[DatasetSpec], PhotographFn] | None,
) -> GenerationSummary:
    from tqdm import tqdm

    start = time.perf_counter()
    # Environment sources are checked before anything is written (an empty folder is an error).
    pools = build_environment_pools(spec.lighting, derive_seed(spec.seed, "lighting"))
    root = prepare_output_dir(spec, out_dir)
    spec = _in_recorded_format(spec, root)
    jobs = plan_shards(spec)
    summary = GenerationSummary(out_dir=root)
    manifest_digests = {split: recorded_digests(root, split) for split in SPLITS}
    todo = []
    for job in select_jobs(jobs, shards):
        path = shard_path(root, job.split, job.index)
        if not path.exists():
            todo.append(job)
            continue
        problem = shard_problem(path, job.sample_count(spec), manifest_digests[job.split].get(path.name))
        if problem is None:
            summary.skipped.append(path)
            continue
        log.warning("%s; it will be rewritten", problem)
        summary.repaired.append(path)
        todo.append(job)
    if todo:
        photograph = (photographer or MitsubaPhotographer)(spec)
        with tqdm(
            total=sum(job.sample_count(spec) for job in todo), unit="sample", disable=not progress
        ) as bar:
            for job in todo:
                path = shard_path(root, job.split, job.index)
                bar.set_description(path.name)

                def samples(job: ShardJob = job) -> Iterator[Sample]:
                    for material in job.materials:
                        for sample in material_samples(spec, job.split, material, pools, photograph):
                            bar.update(1)
                            yield sample

                for stale in path.parent.glob(f".{path.name}.*.tmp"):
                    stale.unlink(missing_ok=True)  # left by a killed run (the shard's or its record's)
                try:
                    before = _recorded(path, manifest_digests[job.split].get(path.name))
                except ShardError:
                    before = set()  # a malformed record: replaced below
                info: ShardInfo = write_shard(path, samples(), shard_format=spec.shard_format)
                # Recorded at once: from here on a rerun can tell this shard's bytes from corruption.
                write_digest(info.path, info.sha256)
                if before and before != {info.sha256}:
                    log.warning(
                        "%s: the rewritten shard's SHA-256 differs from the one recorded before "
                        "(other library versions than the run that made it?); recorded the new one",
                        path,
                    )
                summary.written.append(info.path)
                summary.samples += job.sample_count(spec)
    summary.manifests = finalize_manifests(spec, root, jobs)
    summary.seconds = time.perf_counter() - start
    return summary


def finalize_manifests(spec: DatasetSpec, root: Path, jobs: Sequence[ShardJob]) -> list[Path]:
    """Write ``<split>/manifest.json`` for each split whose shards all exist (idempotent)."""
    written = []
    for split in SPLITS:
        split_jobs = [job for job in jobs if job.split == split]
        paths = [shard_path(root, split, job.index) for job in split_jobs]
        if not all(p.exists() for p in paths):
            continue
        extra = sorted(set(list_shards(root, split)) - set(paths))
        if extra:
            raise DatasetConfigError(f"{extra[0]}: shard does not belong to this dataset's plan")
        manifest = {
            "split": split,
            "samples": sum(job.sample_count(spec) for job in split_jobs),
            "materials": sum(len(job.materials) for job in split_jobs),
            "renders_per_crop": spec.renders_per_crop(split),
            "shards": [
                {
                    "name": p.name,
                    "samples": job.sample_count(spec),
                    "bytes": p.stat().st_size,
                    "sha256": _shard_digest(p),
                }
                for p, job in zip(paths, split_jobs, strict=True)
            ],
            "material_indices": [m for job in split_jobs for m in job.materials],
            "spec": spec.to_json(),
            "code_version": code_version(),
        }
        written.append(write_manifest(root, split, manifest))
    return written


def _shard_digest(path: Path) -> str:
    """The recorded SHA-256 of a shard; one not made by this run (another process, an old
    version) and lacking a valid record gets it computed and recorded now."""
    try:
        digest = read_digest(path)
    except ShardError:
        digest = None
    if digest is None:
        digest = sha256_file(path)
        write_digest(path, digest)
    return digest


def dataset_ready(spec: DatasetSpec, out_dir: str | os.PathLike[str], splits: Sequence[str] = SPLITS) -> bool:
    """Whether ``out_dir`` holds the complete dataset of ``spec`` (spec file and all manifests),
    or those of its ``splits``."""
    root = Path(out_dir)
    spec_file = root / SPEC_FILE
    if not spec_file.exists() or not all((root / s / "manifest.json").exists() for s in splits):
        return False
    try:
        return bool(_identity(json.loads(spec_file.read_text())) == _identity(spec.to_json()))
    except (OSError, ValueError):
        return False


def ensure_dataset(
    spec: DatasetSpec,
    out_dir: str | os.PathLike[str],
    *,
    generate: bool = True,
    generate_under: str | os.PathLike[str] | None = None,
    progress: bool = True,
    splits: Sequence[str] = SPLITS,
    check_only: bool = False,
) -> Path:
    """Generate the dataset into ``out_dir`` unless it is already complete (used to create the
    embedded default dataset on a fresh clone's first ``train.py``/``evaluate.py``).

    A missing or incomplete dataset is generated only when ``generate`` is true or ``out_dir``
    lies inside ``generate_under``. The data configs pass ``generate: false`` and
    ``generate_under: ${paths.data_dir}``: the project's own data folder fills itself on first
    use, while a mistyped ``data.data_dir`` anywhere else is a :class:`DatasetConfigError` naming
    it, raised before anything is written. A complete dataset is used wherever it is.

    ``splits`` limits all of this to those splits' shards (a model trained on photos rendered on
    the fly, :mod:`brdfgan.data.loading.rendered`, needs only the validation and test shards).
    ``check_only``: raise what a call would raise about the path, but generate nothing (a run
    checks its data path before building anything; generation waits for ``prepare_data``, which
    Lightning calls on one process per machine).
    """
    unknown = sorted(set(splits) - set(SPLITS))
    if unknown:
        raise DatasetConfigError(f"unknown split {unknown[0]!r}: expected some of {', '.join(SPLITS)}")
    if dataset_ready(spec, out_dir, splits):
        return Path(out_dir)
    if not generate and not (generate_under is not None and _inside(out_dir, generate_under)):
        home = f" (only paths.data_dir={generate_under} fills itself on first use)" if generate_under else ""
        raise DatasetConfigError(f"data.data_dir={out_dir}: {_not_ready(spec, Path(out_dir))}{home}")
    if check_only:
        return Path(out_dir)
    log.info("dataset %s is missing or incomplete: generating %s", out_dir, "/".join(splits))
    positions = [k for k, job in enumerate(plan_shards(spec)) if job.split in splits]
    log.info("%s", run_generation(spec, out_dir, shards=positions, progress=progress).describe())
    return Path(out_dir)


def _inside(path: str | os.PathLike[str], root: str | os.PathLike[str]) -> bool:
    """Whether ``path`` lies strictly inside ``root``: as written (made absolute, ``..`` folded)
    or with every symlink resolved on both sides. So a relative and an absolute spelling agree, a
    data folder that is a link to another disk counts, and so does a dataset folder linked from
    inside it."""
    pairs = (
        (Path(os.path.abspath(path)), Path(os.path.abspath(root))),
        (Path(path).resolve(), Path(root).resolve()),
    )
    return any(inner != outer and inner.is_relative_to(outer) for inner, outer in pairs)


def _not_ready(spec: DatasetSpec, root: Path) -> str:
    """Why ``root`` does not hold the complete dataset of ``spec``, and what to do about it."""
    try:
        recorded = _identity(json.loads((root / SPEC_FILE).read_text()))
    except (OSError, ValueError):
        recorded = None
    if recorded is None:
        return "no dataset there; correct the path, or pass data.prepare.generate=true to generate one there"
    wanted = _identity(spec.to_json())
    if recorded != wanted:
        return (
            f"holds a dataset made with a different config ({_first_difference(recorded, wanted)} differs); "
            "choose the data config it was made with, or data.prepare=null to read it as it is"
        )
    return "the dataset there is incomplete; pass data.prepare.generate=true to finish it"
