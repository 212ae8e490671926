"""The "before" tables of issue 46, item 1 (a)–(c): the relief of the training data and what a
photo shows of it (definitions in :mod:`research.relief`; the tables in
research/notes/2026-12-relief-investigation.md).

(a) **Realism**: per procedural family (a few training materials each, painted at the spec's
material resolution as the bank paints them, cut into training crops as the bank cuts them) and
for the training scan sets (crops as the spec's scan sampling cuts them): the flat map's angle
(mean tilt), the flat texels, the nearly flat windows, the angle on steep texels and the slope
power by octave of spatial frequency; and whether the base colour's dark lines are the relief's
grooves or its ridges, per family and per training scan set.

(b, c) **Observability and the sensor**: training photos drawn as ``data=rendered`` draws them
(:func:`~brdfgan.data.loading.rendered.draw_scene`: a bank material and crop, the capture, flash and
environment draws, the torch renderer), delivered by no sensor, the evaluation sensor
(conf/sensor/phone_eval.yaml), the training sensor (conf/data/procedural_and_scans.yaml) and the
training sensor without its noise and/or JPEG, plus a phone-calibrated proposal; for each the
relief share (all photos, and split by environment-to-flash ratio) and the observable angle.

    python -m research.relief_tables                            # paints what it needs (~4 min, 1 thread)
    python -m research.relief_tables --bank data/banks          # photos from a built bank (data=rendered)
    python -m research.relief_tables data.relief.bump_probability=0.5   # Hydra overrides of data=rendered

Every draw is seeded (``--seed``); the output is markdown on stdout, progress on stderr. Only the
training split is read: the held-out scans and ``../shared/ood`` are never touched.
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import hydra
import torch
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig
from torch import Tensor

from brdfgan.core.lighting import Environment
from brdfgan.core.svbrdf import NORMAL
from brdfgan.data.loading.rendered import (
    MaterialBank,
    ReliefSampling,
    collate_scenes,
    draw_scene,
    photograph_scenes,
    sample_relief,
    scene_tensors,
)
from brdfgan.data.materials.augment import random_crops
from brdfgan.data.materials.families import resolve_families
from brdfgan.data.materials.source import PaintedMaterial
from brdfgan.data.phone.environments import EnvironmentSpec, load_environment
from brdfgan.data.phone.sensor import SensorEffects
from brdfgan.data.spec.dataset_spec import DatasetSpec, paint_material, scan_materials, split_materials
from brdfgan.data.spec.determinism import derive_seed, material_seed, single_torch_thread
from brdfgan.training.config import register_configs
from research.relief import (
    FLAT_DEG,
    FLAT_WINDOW,
    FLAT_WINDOW_DEG,
    SLOPE_BANDS,
    STEEP_DEG,
    dark_is_low_cosine,
    delivered_noise_log,
    flat_share,
    flat_window_share,
    observable_angle,
    observable_mask,
    relief_share,
    scene_relief_shading,
    slope_band_energy,
    srgb8_rounding_log,
    steep_angle_share,
    tilt_deg,
)

CONF = Path(__file__).resolve().parents[1] / "conf"
# The OOD benchmark's scans, where conf/dataset_spec/ood.yaml's ``scanned`` finds them: the held-out
# tables report on them (never trained or tuned on).
OOD_SCANS = Path(os.environ.get("BRDFGAN_OOD_DIR", CONF.parent.parent / "shared" / "ood" / "ambientcg"))
ENVIRONMENT_SPLIT = 0.5  # environment-to-flash irradiance ratio splitting the photos in two


def band_label(low: float, high: float) -> str:
    """A band of spatial frequency (cycles per pixel) as the periods it spans: ``"8–16 px"``."""
    if low == 0:
        return f"> {1 / high:g} px"
    return f"< {1 / low:g} px" if high == float("inf") else f"{1 / high:g}–{1 / low:g} px"


BAND_LABELS = tuple(band_label(low, high) for low, high in itertools.pairwise(SLOPE_BANDS))


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def compose_config(overrides: Sequence[str] = ()) -> DictConfig:
    """``conf/train.yaml`` with ``data=rendered`` (the procedural_and_scans spec and sensors, the
    bank's and the relief sampling's settings) and ``overrides``, its paths relative to the working
    directory as a run's are."""
    register_configs()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name="train", overrides=["data=rendered", *overrides])


# ----------------------------------------------------------------------------- materials


class HandfulBank(MaterialBank):
    """The training bank of a spec with its procedural part reduced to ``materials`` (painted by
    the caller, held in memory) and its environments loaded directly: what :func:`draw_scene`
    needs, without painting and tabulating the whole bank on disk. :meth:`MaterialBank.draw`
    chooses among the scan sets and ``materials``."""

    def __init__(
        self, spec: DatasetSpec, materials: Sequence[PaintedMaterial], environment_resolution: int
    ) -> None:
        super().__init__(spec, tempfile.gettempdir(), environment_resolution)  # the folder is never used
        self.materials = tuple(materials)
        self._loaded: dict[str, Environment] = {}

    @property
    def procedural_count(self) -> int:
        return len(self.materials)

    def procedural_material(self, position: int) -> PaintedMaterial:
        return self.materials[position]

    def scan(self, which: int) -> Tensor:
        """Training scan set ``which`` as the bank reads it (not recoloured), kept for its draws.

        Shape: output ``(8, S, S)``, S the spec's ``scans.resolution``."""
        return self.scan_material(which, 1.0, torch.Generator()).maps  # a draw of 1: never recoloured

    def environment(self, spec: EnvironmentSpec) -> Environment:
        if spec.env_id not in self._loaded:  # as MaterialBank.build tabulates it
            self._loaded[spec.env_id] = load_environment(spec, self.environment_resolution)
        return self._loaded[spec.env_id]


# ----------------------------------------------------------------------------- (a) realism


@dataclass
class ReliefRow:
    """Per-crop relief statistics of one group of crops, summarised by :meth:`cells`."""

    name: str
    materials: int = 0
    tilt: list[float] = field(default_factory=list)
    flat: list[float] = field(default_factory=list)
    flat_windows: list[float] = field(default_factory=list)
    steep: list[float] = field(default_factory=list)
    bands: list[Tensor] = field(default_factory=list)

    def add(self, crops: Tensor) -> None:
        """Shape: crops ``(N, 8, R, R)``."""
        normal = crops[:, NORMAL]
        self.materials += 1
        self.tilt += tilt_deg(normal).mean(dim=(-2, -1)).tolist()
        self.flat += flat_share(normal).tolist()
        self.flat_windows += flat_window_share(normal).tolist()
        self.steep += steep_angle_share(normal).tolist()
        self.bands += list(slope_band_energy(normal))

    def extend(self, other: ReliefRow) -> None:
        self.materials += other.materials
        self.tilt += other.tilt
        self.flat += other.flat
        self.flat_windows += other.flat_windows
        self.steep += other.steep
        self.bands += other.bands

    def cells(self) -> list[str]:
        """Materials, crops, mean tilt (°), flat texel share, flat window share, the steep share of
        the angle (pooled over the crops: Σ share·tilt / Σ tilt) and the mean band shares."""
        tilt = torch.tensor(self.tilt, dtype=torch.float64)
        steep = float(
            (torch.tensor(self.steep, dtype=torch.float64) * tilt).sum() / tilt.sum().clamp_min(1e-12)
        )
        bands = torch.stack(self.bands).double().mean(dim=0).tolist()
        return [
            str(self.materials),
            str(len(self.tilt)),
            f"{tilt.mean().item():.1f}",
            f"{_mean(self.flat):.0%}",
            f"{_mean(self.flat_windows):.0%}",
            f"{steep:.0%}",
            *(f"{share:.2f}" for share in bands),
        ]


def _mean(values: Sequence[float]) -> float:
    return sum(values) / len(values) if values else float("nan")


def family_indices(spec: DatasetSpec, per_family: int) -> dict[str, list[int]]:
    """The first ``per_family`` procedural training materials of each family, by family name (the
    bank's materials: the training split less its scans; a material's family is the registry's
    round-robin over its index)."""
    families = resolve_families(spec.families)
    scans = scan_materials(spec)
    chosen: dict[str, list[int]] = {family.name: [] for family in families}
    for index in (i for i in split_materials(spec)["train"] if i not in scans):
        indices = chosen[families[index % len(families)].name]
        if len(indices) < per_family:
            indices.append(index)
    return chosen


def paint(spec: DatasetSpec, index: int) -> PaintedMaterial:
    """Training material ``index`` exactly as :meth:`MaterialBank.build` paints it."""
    return paint_material(
        spec, "train", index, torch.Generator().manual_seed(material_seed(spec.seed, index))
    )


def realism_rows(
    bank: HandfulBank,
    materials: dict[str, list[PaintedMaterial]],
    crops: int,
    scan_crops: int,
    seed: int,
    relief: ReliefSampling,
) -> list[ReliefRow]:
    """A row per family, all procedural families together, and the training scans: ``crops``
    crops of each material and ``scan_crops`` of each scan set, cut as :func:`draw_scene` cuts
    them (the spec's crop sampling, the scans' own); with ``relief`` sampling on, two more rows:
    the same crops through it (what the training photos show)."""
    spec = bank.spec
    sampling = relief != ReliefSampling()
    rows = []
    procedural = ReliefRow("procedural, all families")
    scans = ReliefRow(f"training scans ({len(bank.scan_folders)} sets)")
    relieved = {
        "procedural": ReliefRow("procedural, with data.relief"),
        "scans": ReliefRow("scans, with data.relief"),
    }

    def add(row: ReliefRow, group: str, cut: Tensor, generator: torch.Generator) -> None:
        row.add(cut)
        if sampling:
            relieved[group].add(
                torch.stack([sample_relief(bank, crop, relief, generator)[0] for crop in cut])
            )

    for family, painted in materials.items():
        row = ReliefRow(family)
        for number, material in enumerate(painted):
            generator = torch.Generator().manual_seed(derive_seed(seed, "relief crops", family, number))
            add(
                row,
                "procedural",
                random_crops(material.maps, crops, spec.resolution, generator, spec.crop)[0],
                generator,
            )
        rows.append(row)
        procedural.extend(row)
    for which, folder in enumerate(bank.scan_folders):
        generator = torch.Generator().manual_seed(derive_seed(seed, "relief crops", folder.name))
        cut = random_crops(bank.scan(which), scan_crops, spec.resolution, generator, spec.scans.crop)[0]
        add(scans, "scans", cut, generator)
    return [*rows, procedural, scans, *(relieved.values() if sampling else ())]


def realism_table(rows: Sequence[ReliefRow]) -> str:
    header = (
        "| family | materials | crops | flat map's angle ° | flat texels (< "
        f"{FLAT_DEG:g}°) | flat {FLAT_WINDOW}² windows (< {FLAT_WINDOW_DEG:g}°) | angle on steep texels (> "
        f"{STEEP_DEG:g}°) | " + " | ".join(f"slope power {label}" for label in BAND_LABELS) + " |"
    )
    lines = [header, "|---|" + "---|" * (5 + len(BAND_LABELS) + 1)]
    lines += [f"| {row.name} | " + " | ".join(row.cells()) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def dark_is_low_table(bank: HandfulBank, materials: dict[str, list[PaintedMaterial]]) -> str:
    """Per procedural family (its painted materials, whole) and per training scan set (whole, as
    the bank reads it): :func:`~research.relief.dark_is_low_cosine`, x / y, with the
    flat map's angle beside it; the scans sorted by the cosine."""
    lines = ["| material | dark is low, cosine x / y | flat map's angle ° |", "|---|---|---|"]

    def row(name: str, maps: Tensor) -> tuple[float, str]:
        cosine = dark_is_low_cosine(maps).mean(dim=0).tolist()
        angle = float(tilt_deg(maps[:, NORMAL]).mean())
        return sum(cosine) / 2, f"| {name} | {cosine[0]:+.2f} / {cosine[1]:+.2f} | {angle:.1f} |"

    for family, painted in materials.items():
        lines.append(row(f"{family} (procedural)", torch.stack([m.maps for m in painted]))[1])
    scans = sorted(row(folder.name, bank.scan(which)[None]) for which, folder in enumerate(bank.scan_folders))
    lines += [line for _, line in scans]
    cosines = torch.tensor([cosine for cosine, _ in scans])
    lines.append(
        f"| **training scans: {int((cosines > 0.1).sum())} of {len(scans)} above +0.1, "
        f"{int((cosines < -0.1).sum())} under −0.1** | median {float(cosines.median()):+.2f} | |"
    )
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- (b, c) photos


def sensor_variants(cfg: DictConfig) -> list[tuple[str, SensorEffects | None]]:
    """The deliveries compared: none, the evaluation sensor, v4's training sensor
    (``data=procedural_and_scans``) with and without its noise and JPEG, and ``data=rendered``'s
    sensor (the phone's noise and JPEG calibrated to a downscaled photo; why:
    research/notes/2026-12-relief-investigation.md)."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        v4 = compose(config_name="train", overrides=["data=procedural_and_scans"])
    training: SensorEffects = hydra.utils.instantiate(v4.data.sensor)
    evaluation: SensorEffects = hydra.utils.instantiate(cfg.data.eval_sensor)
    rendered: SensorEffects = hydra.utils.instantiate(cfg.data.sensor)
    return [
        ("no sensor (the render)", None),
        ("evaluation sensor (phone_eval)", evaluation),
        ("v4's training sensor", training),
        ("v4's training sensor, no noise", replace(training, noise_probability=0.0)),
        ("v4's training sensor, no JPEG", replace(training, jpeg_probability=0.0)),
        ("v4's training sensor, neither", replace(training, noise_probability=0.0, jpeg_probability=0.0)),
        ("data=rendered's sensor (noise ÷ 30–3000, JPEG 85–95)", rendered),
    ]


@dataclass
class PhotoRow:
    """Per-photo measures under one delivery: the relief share against the photo's relief shading
    and against the flash's alone, the flat map's angle and its observable part, the median noise σ,
    and the photo's environment-to-flash ratio."""

    name: str
    share: list[float] = field(default_factory=list)
    flash_share: list[float] = field(default_factory=list)
    environment: list[float] = field(default_factory=list)
    total: list[float] = field(default_factory=list)
    observable: list[float] = field(default_factory=list)
    noise: list[float] = field(default_factory=list)

    def _groups(self) -> list[Tensor]:
        """Masks of all photos, those with the environment below the split and the others."""
        room = torch.tensor(self.environment, dtype=torch.float64) >= ENVIRONMENT_SPLIT
        return [torch.ones_like(room), ~room, room]

    def share_cells(self) -> list[str]:
        """Mean relief share of all photos and by lighting, then against the flash's shading alone."""
        share = torch.tensor(self.share, dtype=torch.float64)
        flash = torch.tensor(self.flash_share, dtype=torch.float64)
        groups = self._groups()
        return [_mean_cell(share[group]) for group in groups] + [
            _mean_cell(flash[group]) for group in groups[1:]
        ]

    def angle_cells(self) -> list[str]:
        """The observable angle (mean over the photos), its share of the flat map's angle (pooled:
        Σ observable / Σ total) of all photos and by lighting, and the median noise σ."""
        total = torch.tensor(self.total, dtype=torch.float64)
        observable = torch.tensor(self.observable, dtype=torch.float64)
        shares = [
            f"{observable[group].sum() / total[group].sum():.0%}" if total[group].sum() > 0 else "–"
            for group in self._groups()
        ]
        return [f"{observable.mean():.2f}", *shares, f"{torch.tensor(self.noise).median():.3f}"]


def _mean_cell(values: Tensor) -> str:
    return f"{values.mean():.2f}" if values.numel() else "–"


def deliver(
    sensor: SensorEffects | None, photo: Tensor, seed: int, illuminant: tuple[float, float, float] | None
) -> tuple[Tensor, Tensor]:
    """The delivered photo and its noise σ in log luminance per pixel: the noise and JPEG error
    (:func:`delivered_noise_log` against the same delivery with both off, every other draw equal)
    and, for an 8-bit file, the rounding to its codes (:func:`srgb8_rounding_log`), in quadrature.
    Without a sensor: the render itself, its noise σ the 8-bit rounding alone (any file of it has
    that much).

    Shape:
        - photo: ``(3, R, R)`` linear; output: ``(1, 3, R, R)``, ``(1, 1, R, R)``
    """
    if sensor is None:
        return photo[None], srgb8_rounding_log(photo[None])
    generator_seed = derive_seed(seed, "sensor") & 0x7FFFFFFFFFFFFFFF
    delivered, record = sensor.apply(
        photo, torch.Generator().manual_seed(generator_seed), illuminant_rgb=illuminant
    )
    quiet = replace(sensor, noise_probability=0.0, jpeg_probability=0.0)
    reference, _ = quiet.apply(
        photo, torch.Generator().manual_seed(generator_seed), illuminant_rgb=illuminant
    )
    noise = delivered_noise_log(delivered[None], reference[None])
    if not record["raw"]:
        scale = record["exposure_scale"] or 1.0  # the file's values, before predict's re-exposure
        noise = (noise.square() + srgb8_rounding_log(delivered[None] / scale).square()).sqrt()
    return delivered[None], noise


def photo_rows(
    bank: MaterialBank,
    variants: Sequence[tuple[str, SensorEffects | None]],
    count: int,
    batch: int,
    environment_lights: int,
    relief: ReliefSampling,
    seed: int,
    k: float,
) -> tuple[list[PhotoRow], dict[str, int]]:
    """Relief share and angles of ``count`` training photos under each delivery (their crops'
    relief sampled as ``relief`` says), and how many photos there are of scans and of procedural
    materials, by lighting."""
    rows = [PhotoRow(name) for name, _ in variants]
    counts = {"scans": 0, "procedural": 0, "room": 0}
    for start in range(0, count, batch):
        seeds = [
            derive_seed(seed, "relief photos", i) & 0x7FFFFFFFFFFFFFFF
            for i in range(start, min(start + batch, count))
        ]
        scenes = [draw_scene(bank, f"relief-{s}", s, environment_lights, relief) for s in seeds]
        scene_batch = collate_scenes(scenes)
        inputs = scene_tensors(scene_batch)
        photos, maps, _ = photograph_scenes(*inputs)
        ratio = scene_relief_shading(*inputs)
        # The flash's relief shading alone (light 0 is the flash): what a model that reads relief
        # as flash shading looks for.
        flash_inputs = (*inputs[:2], inputs[2][:, :1], inputs[3][:, :1], *inputs[4:])
        flash_ratio = scene_relief_shading(*flash_inputs)
        for index, scene in enumerate(scenes):
            environment = float(scene.meta["lighting"]["env_to_flash_ratio"])
            counts["scans" if scene.meta["family"].startswith("scanned/") else "procedural"] += 1
            counts["room"] += environment >= ENVIRONMENT_SPLIT
            normal = maps[index : index + 1, NORMAL]
            shading = ratio[index : index + 1]
            illuminant = SensorEffects.flash_illuminant(scene.meta)
            deliveries = [deliver(sensor, photos[index], seeds[index], illuminant) for _, sensor in variants]
            delivered = torch.cat([photo for photo, _ in deliveries])  # one batch, one high-pass
            shares = relief_share(delivered, shading).tolist()
            flash_shares = relief_share(delivered, flash_ratio[index : index + 1]).tolist()
            total = float(tilt_deg(normal).mean())
            for row, share, flash_share, (_, noise) in zip(
                rows, shares, flash_shares, deliveries, strict=True
            ):
                row.share.append(share)
                row.flash_share.append(flash_share)
                row.environment.append(environment)
                row.total.append(total)
                row.observable.append(
                    float(observable_angle(normal, observable_mask(shading, noise, k)[:, 0]))
                )
                row.noise.append(float(noise.median()))
        log(f"photos {min(start + batch, count)}/{count}")
    return rows, counts


def share_table(rows: Sequence[PhotoRow]) -> str:
    split = f"{ENVIRONMENT_SPLIT:g}"
    lines = [
        f"| delivered by | relief share | env < {split} flash | env ≥ {split} flash | "
        f"flash shading only: env < {split} | env ≥ {split} |",
        "|---|---|---|---|---|---|",
    ]
    lines += [f"| {row.name} | " + " | ".join(row.share_cells()) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def angle_table(rows: Sequence[PhotoRow], total: float) -> str:
    split = f"{ENVIRONMENT_SPLIT:g}"
    lines = [
        f"| delivered by | observable angle ° (of {total:.2f}) | share of the angle | env < {split} flash | "
        f"env ≥ {split} flash | median noise σ (log) |",
        "|---|---|---|---|---|---|",
    ]
    lines += [f"| {row.name} | " + " | ".join(row.angle_cells()) + " |" for row in rows]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- main


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--per-family", type=int, default=4, help="training materials painted per family")
    parser.add_argument("--crops", type=int, default=2, help="crops per procedural material")
    parser.add_argument("--scan-crops", type=int, default=3, help="crops per training scan set")
    parser.add_argument("--photos", type=int, default=200, help="training photos drawn for (b) and (c)")
    parser.add_argument("--batch", type=int, default=8, help="photos rendered together")
    parser.add_argument("--k", type=float, default=1.0, help="observable: relief shading > k × noise σ")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--bank",
        type=Path,
        default=None,
        help="folder of built material banks (data.bank.folder); its photos are drawn from the whole "
        "bank when it holds this spec's, else from the painted materials",
    )
    parser.add_argument(
        "overrides",
        nargs="*",
        help="Hydra overrides of the training config with data=rendered, e.g. "
        "data.relief.bump_probability=0.5 or data.sensor.shot_noise_max=4e-4 (the 'after' tables)",
    )
    args = parser.parse_args(argv)
    for name in ("per_family", "crops", "scan_crops", "photos", "batch"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1")
    started = time.time()
    cfg = compose_config(args.overrides)
    spec: DatasetSpec = hydra.utils.instantiate(cfg.data.prepare.spec, _convert_="all")
    environment_resolution = int(cfg.data.bank.environment_resolution)
    with single_torch_thread():
        chosen = family_indices(spec, args.per_family)
        materials = {family: [paint(spec, index) for index in indices] for family, indices in chosen.items()}
        log(f"painted {sum(map(len, materials.values()))} materials ({time.time() - started:.0f} s)")
        handful = HandfulBank(
            spec, [material for painted in materials.values() for material in painted], environment_resolution
        )
        relief: ReliefSampling = hydra.utils.instantiate(cfg.data.relief)
        rows = realism_rows(handful, materials, args.crops, args.scan_crops, args.seed, relief)
        log(f"realism done ({time.time() - started:.0f} s)")
        bank: MaterialBank = handful
        if args.bank is not None:
            built = MaterialBank(spec, args.bank, environment_resolution)
            if built.ready():
                bank = built
            else:
                log(f"{args.bank}: no complete bank of this spec; drawing from the painted materials")
        variants = sensor_variants(cfg)
        photos, counts = photo_rows(
            bank,
            variants,
            args.photos,
            args.batch,
            int(cfg.data.environment_lights),
            relief,
            args.seed,
            args.k,
        )
    print(
        f"### (a) Relief of the training materials ({args.per_family} per family, {args.crops} crops of "
        f"{spec.resolution}² each; {args.scan_crops} crops per scan set)\n"
    )
    print(realism_table(rows))
    print("Is dark low? The base colour's log luminance as a height against the relief (+1: dark lines")
    print("are grooves, −1: ridges; each family's painted materials and each training scan set, whole):\n")
    print(dark_is_low_table(handful, materials))
    source = "the painted materials" if bank is handful else "the whole bank"
    print(
        f"### (b, c) What the training photos show of it ({args.photos} photos drawn from {source} and "
        f"the training scans: {counts['procedural']} procedural, {counts['scans']} scans, "
        f"{counts['room']} with the environment ≥ {ENVIRONMENT_SPLIT:g} × the flash; observable: "
        f"relief shading > {args.k:g} σ)\n"
    )
    print("Relief share (mean over the photos):\n")
    print(share_table(photos))
    print("Observable angle (the flat map's angle of the maps as photographed, and the part of it on texels")
    print("whose relief shading exceeds the delivered photo's noise):\n")
    print(angle_table(photos, _mean(photos[0].total)))
    log(f"done in {time.time() - started:.0f} s")


if __name__ == "__main__":
    main()
