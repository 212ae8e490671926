"""The dataset spec (:class:`DatasetSpec`, everything that determines the bytes of a dataset, and
its Hydra node), the split of its materials and scanned sets (paper: 80:20 on the materials,
never on their crops), and the maps of each material as the spec paints them
(:func:`paint_material`).

A seeded permutation puts ``test_fraction`` of the material indices in ``test``, ``val_fraction``
in ``val`` and the rest in ``train``: a material index, its seed and all its crops belong to
exactly one split. Shard generation (:mod:`brdfgan.data.generation.generation`) and the
materials of on-the-fly rendered training (:mod:`brdfgan.data.loading.rendered`) both come from
here, so the two paint every material alike.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from typing import Any

import torch

from brdfgan.data.materials.augment import CropSampling
from brdfgan.data.materials.families import resolve_families
from brdfgan.data.materials.mixing import MixingConfig
from brdfgan.data.materials.recolor import RecolorConfig
from brdfgan.data.materials.scanned import scanned_material_folders
from brdfgan.data.materials.source import PaintedMaterial, ScanSampling, paint_procedural, paint_scanned
from brdfgan.data.phone.conditions import CaptureSampling
from brdfgan.data.phone.environments import LightingConfig
from brdfgan.data.phone.flash import FlashSampling
from brdfgan.data.spec.determinism import derive_seed, material_seed
from brdfgan.data.storage.shards import LEGACY_SHARD_FORMAT, SHARD_FORMATS
from brdfgan.data.storage.spec_checks import DatasetConfigError, in_range, integer

SPLITS = ("train", "val", "test")


@dataclass(frozen=True)
class DatasetSpec:
    """Everything that determines the bytes of a dataset. Defaults: a small CPU-sized set; the
    paper's protocol is ``material_resolution=2048, resolution=512, spp=196`` with the default
    crop, render and split counts (``conf/dataset_spec/paper.yaml``)."""

    seed: int = 0
    materials: int = 40
    families: tuple[str, ...] = ()
    material_resolution: int = 1024
    resolution: int = 256
    crops_per_material: int = 7
    train_renders: int = 3
    eval_renders: int = 1
    test_fraction: float = 0.2
    val_fraction: float = 0.05
    materials_per_shard: int = 4
    spp: int = 64
    crop: CropSampling = field(default_factory=CropSampling)
    flash: FlashSampling = field(default_factory=FlashSampling)
    lighting: LightingConfig = field(default_factory=LightingConfig)
    capture: CaptureSampling = field(default_factory=CaptureSampling)
    mixing: MixingConfig = field(default_factory=MixingConfig)
    recolor: RecolorConfig = field(default_factory=RecolorConfig)
    # A folder of scanned material sets (brdfgan.data.materials.scanned) instead of the procedural
    # families: such a dataset is test only, so real scans never become training data.
    scanned: str | None = None
    # Scanned sets as a share of every split's materials, beside the families (split by set).
    scans: ScanSampling = field(default_factory=ScanSampling)
    # How samples are stored (brdfgan.data.storage.shards): "u16z" or "png", the same 16-bit values either
    # way. "png" here because a spec without the key (every dataset.json made before it) describes
    # PNG shards; conf/dataset_spec/default.yaml makes new datasets "u16z". Not part of a dataset's
    # identity: an existing dataset is finished and repaired in the format it records.
    shard_format: str = LEGACY_SHARD_FORMAT
    # Every photo with its no-flash twin (the flash off, the room light alone, exposed on its own;
    # brdfgan.data.phone.pairs): a flash + no-flash pair. Twice the renders.
    pairs: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "families", tuple(self.families))
        if not isinstance(self.pairs, bool):
            raise DatasetConfigError(f"dataset_spec.pairs={self.pairs!r}: must be true or false")
        if self.shard_format not in SHARD_FORMATS:
            raise DatasetConfigError(
                f"dataset_spec.shard_format={self.shard_format!r}: must be one of {', '.join(SHARD_FORMATS)}"
            )
        for key in (
            "materials",
            "material_resolution",
            "resolution",
            "crops_per_material",
            "train_renders",
            "eval_renders",
            "materials_per_shard",
            "spp",
        ):
            integer(f"dataset_spec.{key}", getattr(self, key), minimum=1)
        if math.isqrt(self.spp) ** 2 != self.spp:
            raise DatasetConfigError(
                f"dataset_spec.spp={self.spp}: must be a perfect square "
                "(stratified sampler; paper: 196 = 14²)"
            )
        if self.resolution > self.material_resolution:
            raise DatasetConfigError(
                f"dataset_spec.resolution={self.resolution} > dataset_spec.material_resolution="
                f"{self.material_resolution}: crops are cut from the material maps"
            )
        if self.scanned is not None:
            self._check_scanned()
            return
        if self.scans.enabled:
            self._check_scans()
        test = in_range("dataset_spec.test_fraction", self.test_fraction, 0.0, 1.0, high_open=True)
        val = in_range("dataset_spec.val_fraction", self.val_fraction, 0.0, 1.0, high_open=True)
        if test + val >= 1.0:
            raise DatasetConfigError(
                f"dataset_spec.test_fraction={test:g} + dataset_spec.val_fraction={val:g}: must be below 1"
            )
        counts = held_out_counts(self.materials, test, val)
        if counts["test"] + counts["val"] >= self.materials:
            raise DatasetConfigError(
                f"dataset_spec.materials={self.materials} leaves no training material after the "
                f"{counts['test']} test and {counts['val']} validation ones"
            )
        resolve_families(self.families)  # unknown names fail here, before any work

    def _check_scanned(self) -> None:
        found = len(scanned_material_folders(str(self.scanned)))
        if self.materials != found:
            raise DatasetConfigError(
                f"dataset_spec.materials={self.materials}: dataset_spec.scanned={self.scanned!r} "
                f"holds {found} sets"
            )
        if self.mixing.fraction > 0 or self.recolor.probability > 0:
            raise DatasetConfigError(
                "dataset_spec.scanned: scanned materials are a benchmark and stay as scanned; "
                "set dataset_spec.mixing.fraction=0 and dataset_spec.recolor.probability=0"
            )

    def _check_scans(self) -> None:
        found = len(scanned_material_folders(str(self.scans.folder), key="dataset_spec.scans.folder"))
        held_out = self.scans.held_out_count("val_sets") + self.scans.held_out_count("test_sets")
        if held_out >= found:
            raise DatasetConfigError(
                f"dataset_spec.scans: {held_out} validation and test sets leave none of the {found} "
                f"sets in {self.scans.folder!r} to train on"
            )
        split_scan_sets(self)  # unknown set names fail here

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready description (recorded in ``dataset.json`` and the manifests). An empty
        family list is recorded resolved, as the registry's names: a dataset made before a family
        joined the registry then differs from today's, and is not taken for it. Options added
        since (scans, mirrored crops, crops inside the source, pairs) are recorded only when used, so
        a dataset made before them keeps its identity."""
        description = json.loads(json.dumps(dataclasses.asdict(self)))
        if self.scanned is None:
            description["families"] = [family.name for family in resolve_families(self.families)]
        if not self.scans.enabled:
            del description["scans"]
        for option in ("mirror", "inside"):
            if not description["crop"][option]:
                del description["crop"][option]
        if not self.pairs:
            del description["pairs"]
        return description

    def renders_per_crop(self, split: str) -> int:
        return self.train_renders if split == "train" else self.eval_renders


def spec_from_config(config: Any) -> DatasetSpec:
    """The spec of a Hydra ``dataset_spec`` node (``conf/dataset_spec/*.yaml``). A value rejected
    by one of the spec classes is re-raised as that class's own one-line error
    (``dataset_spec.flash.… must be …``) instead of Hydra's multi-line wrapper around it."""
    import hydra
    from hydra.errors import InstantiationException

    try:
        spec = hydra.utils.instantiate(config, _convert_="all")
    except InstantiationException as error:
        if isinstance(error.__cause__, ValueError):
            raise error.__cause__ from None
        raise
    if not isinstance(spec, DatasetSpec):
        raise DatasetConfigError(f"dataset_spec: builds a {type(spec).__name__}, expected a DatasetSpec")
    return spec


def held_out_counts(materials: int, test_fraction: float, val_fraction: float) -> dict[str, int]:
    """Materials of the ``test`` and ``val`` splits: at least one for a non-zero fraction."""
    return {
        name: (max(1, round(materials * fraction)) if fraction > 0 else 0)
        for name, fraction in (("test", test_fraction), ("val", val_fraction))
    }


def split_materials(spec: DatasetSpec) -> dict[str, tuple[int, ...]]:
    """Material indices per split, each sorted. Disjoint and covering ``range(materials)``.
    Scanned materials are all ``test``."""
    if spec.scanned is not None:
        return {"train": (), "val": (), "test": tuple(range(spec.materials))}
    order = torch.randperm(
        spec.materials, generator=torch.Generator().manual_seed(derive_seed(spec.seed, "split"))
    )
    counts = held_out_counts(spec.materials, spec.test_fraction, spec.val_fraction)
    test = order[: counts["test"]]
    val = order[counts["test"] : counts["test"] + counts["val"]]
    train = order[counts["test"] + counts["val"] :]
    return {name: tuple(sorted(t.tolist())) for name, t in (("train", train), ("val", val), ("test", test))}


def split_scan_sets(spec: DatasetSpec) -> dict[str, tuple[int, ...]]:
    """Indices of the scanned sets (in :func:`~brdfgan.data.materials.scanned.scanned_material_folders`'
    order) per split, each sorted: the sets ``test_sets`` and ``val_sets`` name, or as many as
    they say from a seeded permutation, held out; the rest ``train``. Empty without scans."""
    if not spec.scans.enabled:
        return {split: () for split in SPLITS}
    key = "dataset_spec.scans"
    folders = scanned_material_folders(str(spec.scans.folder), key=f"{key}.folder")
    names = [folder.name for folder in folders]
    held: dict[str, list[int]] = {}
    for split, which in (("test", "test_sets"), ("val", "val_sets")):
        for name in spec.scans.named_sets(which):
            if name not in names:
                raise DatasetConfigError(f"{key}.{which}: no set {name!r} in {spec.scans.folder!r}")
        held[split] = [names.index(name) for name in spec.scans.named_sets(which)]
    seeded = torch.Generator().manual_seed(derive_seed(spec.seed, "scan-split"))
    free = [
        int(i)
        for i in torch.randperm(len(names), generator=seeded)
        if int(i) not in held["test"] + held["val"]
    ]
    for split, which in (("test", "test_sets"), ("val", "val_sets")):
        if not spec.scans.named_sets(which):  # a number: the next sets of the permutation
            count = spec.scans.held_out_count(which)
            held[split], free = free[:count], free[count:]
    train = [index for index in range(len(names)) if index not in held["test"] + held["val"]]
    return {"train": tuple(train), "val": tuple(sorted(held["val"])), "test": tuple(sorted(held["test"]))}


def scan_materials(spec: DatasetSpec) -> dict[int, int]:
    """Material index → scanned set index, for the indices painted from a scan. Each index is a
    scan with probability ``scans.fraction`` (a draw of its own: the others stay procedural and
    unchanged); a split's scan materials take its sets in turn, starting at a seeded offset, so
    every set of the split is used about equally."""
    if not spec.scans.enabled:
        return {}
    sets = split_scan_sets(spec)
    chosen: dict[int, int] = {}
    for split, indices in split_materials(spec).items():
        pool = sets[split]
        scans = [i for i in indices if _unit_draw(spec.seed, "scan", i) < spec.scans.fraction]
        if not pool or not scans:
            continue
        start = int(_unit_draw(spec.seed, "scan-offset", split) * len(pool))
        chosen.update({index: pool[(start + rank) % len(pool)] for rank, index in enumerate(scans)})
    return chosen


def _unit_draw(*parts: int | str) -> float:
    """A uniform number in [0, 1) from a hash of ``parts`` (:func:`derive_seed`)."""
    return derive_seed(*parts) / 2**63


def paint_material(
    spec: DatasetSpec, split: str, material_index: int, generator: torch.Generator
) -> PaintedMaterial:
    """The maps of material ``material_index`` of ``split`` (:mod:`brdfgan.data.materials.source`):
    a scanned set (a test-only scanned dataset's, or one of the split's sets where
    :func:`scan_materials` says so), or a family draw from ``generator`` (mixed with a partner
    of the same split and recoloured as the spec says)."""
    if spec.scanned is not None:
        return paint_scanned(scanned_material_folders(spec.scanned)[material_index], spec.material_resolution)
    scans = scan_materials(spec)
    scan = scans.get(material_index)
    if scan is not None:
        folder = scanned_material_folders(str(spec.scans.folder), key="dataset_spec.scans.folder")[scan]
        recolor = dataclasses.replace(spec.recolor, probability=spec.scans.recolor_probability)
        return paint_scanned(
            folder, spec.scans.resolution, crop=spec.scans.crop, recolor=recolor,
            choice_seed=derive_seed(spec.seed, "mix", material_index),
        )  # fmt: skip
    return paint_procedural(
        resolve_families(spec.families),
        material_index,
        spec.material_resolution,
        generator,
        choice_seed=derive_seed(spec.seed, "mix", material_index),
        partner_seed=lambda index: material_seed(spec.seed, index),
        # A partner is painted as it is on its own: procedural, so not a scan's index.
        split_indices=[index for index in split_materials(spec)[split] if index not in scans],
        mixing=spec.mixing,
        recolor=spec.recolor,
    )
