"""Photo → engine-ready material: the stages chained, per photo and per batch (``brdfgan predict``).

For each photo::

    read_photo (linear RGB, EXIF orientation, colour-space checks)       intake
      → preprocess (square crop on the flash hotspot, linear resize, the training auto exposure)
      → the generator, tiled with frozen normalisation statistics when large          model
      [→ refine_maps: the maps fitted to the photo with the differentiable renderer (--refine)]
      → remove_flash: clipped pixels filled, the hotspot's disc levelled, no metal on thin dark
        features (core.clipped_fill)
      [→ make_tileable: whole lattice cells, or the maps rolled and cut into a tile that wraps
         (--tileable)]
      → write_material (textures, material.glb, material.json, preview.png [, preview.gif/mp4],
                        index.html: the material viewer)                                   outputs

This is the single-photo capture's pipeline, and the write-out every kind of capture ends in
(:func:`write_prediction`). A batch of captures of any kind, each by its kind's pipeline, is
:func:`brdfgan.inference.dispatch.predict_batch`.
"""

from __future__ import annotations

import logging
import math
import os
import re
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import torch
from torch import Tensor, nn

from brdfgan.core.clipped_fill import FlashRemoval, clipped_mask, remove_flash
from brdfgan.core.flash_geometry import centred_flash_frame, resize_flash_frame
from brdfgan.core.flash_mark import FlashMark, repair_flash_mark
from brdfgan.core.lattice import (
    ALL_FEATURES,
    MAX_STRETCH,
    MAX_TURN_DEG,
    MIN_CELL_MATCH,
    PROMINENCE_THRESHOLD,
    CellTiling,
    Lattice,
    Perspective,
    Vector,
    cell_match,
    central_lattice,
    choose_cells,
    find_lattice,
    find_perspective,
    rectify,
    refine_perspective,
    tile_whole_cells,
)
from brdfgan.core.seamless import (
    MAP_NAMES,
    MIN_SIDE,
    TilingMeasures,
    file_units,
    make_seamless,
    tiling_measures,
    wrap_ratios,
)
from brdfgan.core.stripes import Stripes, choose_stripe_cells, find_stripe_perspective, find_stripes
from brdfgan.core.svbrdf import NUM_CHANNELS
from brdfgan.inference.intake.lens import FieldOfView, crop_field_of_view
from brdfgan.inference.intake.photo import PHOTO_EXTENSIONS, Colorspace, Photo, read_photo
from brdfgan.inference.intake.preprocess import Crop, CropSized, Preprocessed, clipped_in_crop, preprocess
from brdfgan.inference.model.guided import (
    DEFAULT_NETWORK_CAP,
    MapsAndCorrections,
    anchored_network,
    carry_up,
    shrink_photo,
    upsampling_record,
)
from brdfgan.inference.model.tiling import TilingConfig, predict_direct, predict_tiled
from brdfgan.inference.model.weights import Model, PredictError
from brdfgan.inference.outputs.export import ExportOptions, recover_outputs, write_material
from brdfgan.inference.outputs.preview import write_animation, write_preview
from brdfgan.inference.outputs.viewer import write_viewer
from brdfgan.inference.refine import RefineConfig, refine_maps

log = logging.getLogger(__name__)

# The default output side is the crop's side in the photo, capped here: 2K textures are what
# artists' tools export by default, and a 2048² run stays within the memory of 1024² tiles.
MAX_DEFAULT_RESOLUTION = 2048

BRDF_DESCRIPTION = (
    "Cook-Torrance GGX (Smith, Schlick) + Burley diffuse, metallic workflow, alpha = roughness^2"
)


@dataclass(frozen=True)
class PredictOptions:
    """Everything ``brdfgan predict`` lets the user choose besides inputs and weights."""

    resolution: int | None = None  # None: each photo's crop size (CropSized, MAX_DEFAULT_RESOLUTION)
    crop: Crop | None = None  # None: a square centred on the detected flash hotspot
    colorspace: Colorspace | None = None  # None: the file format's default (sRGB for JPEG/PNG)
    export: ExportOptions = field(default_factory=ExportOptions)
    tiling: TilingConfig = field(default_factory=TilingConfig)
    preview: bool = True
    animate: Literal["gif", "mp4"] | None = None
    refine: RefineConfig | None = None  # None: the network's maps as they are
    tileable: bool = False  # cut the maps into a seamless tile (make_tileable)
    # --align-pattern: with --tileable, a periodic material's lattice turned onto the tile's axes.
    align_pattern: bool = False
    prefix_files: bool = False  # texture files named <material>_<map>.<ext> for engines' importers
    field_of_view: FieldOfView = field(default_factory=FieldOfView)  # --fov / --focal-length-35mm
    # The largest side an anchored network runs at for the default (crop-sized) output; larger
    # outputs are carried up guided by the photo (inference/model/guided.py). None: never.
    network_cap: int | None = DEFAULT_NETWORK_CAP
    # --exposure-ratio: a flash + no-flash pair's exposure ratio, instead of the photos' EXIF
    # (brdfgan.inference.pair.intake.exposure_ratio). None: from the EXIF.
    exposure_ratio: float | None = None

    def __post_init__(self) -> None:
        if self.network_cap is not None and self.network_cap < 1:
            raise ValueError(f"network_cap must be positive or None, got {self.network_cap}")
        if self.exposure_ratio is not None and not (
            math.isfinite(self.exposure_ratio) and self.exposure_ratio > 0
        ):
            raise ValueError(f"exposure_ratio must be positive and finite, got {self.exposure_ratio}")


@dataclass(frozen=True)
class Predictor:
    """A model with the options of one run: the output side fixed (``--resolution``) or, by
    default, each photo's crop side clamped to [the model's resolution, MAX_DEFAULT_RESOLUTION].

    The network runs at the output side, except by default with a photo-anchored network above
    ``options.network_cap``: it then runs at the cap and its outputs are carried up guided by the
    photo (:mod:`~brdfgan.inference.model.guided`). A fixed ``--resolution`` is always exact."""

    model: Model
    options: PredictOptions
    resolution: int | CropSized

    @classmethod
    def create(cls, model: Model, options: PredictOptions) -> Predictor:
        resolution = options.resolution or CropSized(
            model.resolution, max(model.resolution, MAX_DEFAULT_RESOLUTION)
        )
        return cls(model, options, resolution)

    @property
    def largest_resolution(self) -> int:
        """The largest output side a photo of this run can get (what the memory check sizes)."""
        return self.resolution if isinstance(self.resolution, int) else self.resolution.maximum

    def describe_resolution(self) -> str:
        if isinstance(self.resolution, int):
            return f"{self.resolution}²"
        return f"the crop's size ({self.resolution.minimum}²–{self.resolution.maximum}²)"

    def network_side(self, side: int) -> int:
        """The side the network runs at for maps of ``side``² (module and class docstrings)."""
        cap = self.options.network_cap
        if isinstance(self.resolution, int) or cap is None or anchored_network(self.model.generator) is None:
            return side
        return min(side, cap)

    def tiled(self, side: int) -> bool:
        """Whether the network runs tiled for maps of ``side``²."""
        network_side = self.network_side(side)
        return self.options.tiling.runs_tiled(network_side, network_side)

    def inference_record(self, side: int) -> dict[str, Any]:
        """``material.json``'s ``inference``: tiling, the network's and the output's side, upsampling."""
        network_side = self.network_side(side)
        return {**self.options.tiling.to_json(self.tiled(side)), **upsampling_record(network_side, side)}

    def network(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        """The network's outputs for one prepared photo with its flash frame (default: centred):
        its maps at the photo's side, or on the guided fast path its maps and corrections at the
        capped side (:meth:`upsample` takes either to the maps).

        Shape: ``(3, N, N)`` and ``(1, 3)`` → ``(8, N, N)`` or ``(OUTPUT_CHANNELS, n, n)``."""
        side = photo.shape[-1]
        network_side = self.network_side(side)
        generator: nn.Module = self.model.generator
        if network_side != side:
            network = anchored_network(generator)
            assert network is not None  # network_side caps anchored networks only
            generator = MapsAndCorrections(network)
            frame = centred_flash_frame(1, side, side) if flash is None else flash
            photo = shrink_photo(photo[None], network_side)[0]
            flash = resize_flash_frame(frame, network_side / side)
        if self.tiled(side):
            return predict_tiled(generator, photo[None], self.options.tiling, flash=flash)[0]
        return predict_direct(generator, photo[None], flash)[0]

    def upsample(self, outputs: Tensor, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        """The maps at the photo's side from :meth:`network`'s ``outputs`` for it: the outputs
        themselves on the exact path, carried up guided by the photo on the fast path.

        Shape: ``(C, n, n)``, ``(3, N, N)`` and ``(1, 3)`` → ``(8, N, N)``."""
        side = photo.shape[-1]
        if outputs.shape[-1] == side:
            return outputs[:NUM_CHANNELS]
        network = anchored_network(self.model.generator)
        assert network is not None  # the fast path's outputs come from an anchored network
        frame = centred_flash_frame(1, side, side) if flash is None else flash
        with torch.inference_mode():
            return carry_up(network, outputs[None], photo[None], frame)[0]

    def maps(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        """The maps of one prepared photo with its flash frame (default: centred):
        :meth:`upsample` of :meth:`network`.

        Shape: ``(3, N, N)`` and ``(1, 3)`` → ``(8, N, N)``."""
        return self.upsample(self.network(photo, flash), photo, flash)


@dataclass(frozen=True)
class PhotoResult:
    photo: Path
    output: Path
    warnings: tuple[str, ...]
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage (--verbose)


@dataclass(frozen=True)
class PhotoFailure:
    photo: Path
    message: str  # one line, naming the photo


@dataclass(frozen=True)
class BatchResult:
    succeeded: list[PhotoResult]
    failed: list[PhotoFailure]
    stopped: str | None = None  # why the batch ended before its last photo (a full disk)


def collect_photos(inputs: Sequence[str | os.PathLike[str]]) -> list[Path]:
    """Photos named on the command line; a directory contributes its photo files (sorted, not
    recursive). A missing path is kept, so that it is reported as a failure of its own."""
    photos: list[Path] = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in PHOTO_EXTENSIONS)
            if not found:
                log.warning(
                    "%s: no photo files (%s) in this directory", path, ", ".join(sorted(PHOTO_EXTENSIONS))
                )
            photos += found
        else:
            photos.append(path)
    return photos


def output_names(photos: Sequence[Path]) -> list[str]:
    """One output folder name per photo: the file stem, made unique within the batch."""
    return unique_names(
        re.sub(r"[^A-Za-z0-9._-]+", "_", photo.stem).strip("._") or "photo" for photo in photos
    )


def unique_names(names: Iterable[str]) -> list[str]:
    """The names in order, a repeated one numbered ``name-2``, ``name-3``, …"""
    unique: list[str] = []
    taken: set[str] = set()
    for base in names:
        name, counter = base, 2
        while name in taken:
            name, counter = f"{base}-{counter}", counter + 1
        taken.add(name)
        unique.append(name)
    return unique


@dataclass(frozen=True)
class TileableRecord:
    """What ``--tileable`` did to a photo's maps (``material.json``'s ``tileable``): the flash mark
    found and repaired, the four copies the tile is cut from (:class:`~brdfgan.core.seamless.SeamlessTile`'s
    ``shifts``), each map's wrap ratio before (the network's maps) and, with the copied fractions,
    after (measured against the repaired maps, which the tile is cut from).

    A periodic material (``lattice``, :func:`~brdfgan.core.lattice.find_lattice`) is instead tiled
    by whole lattice cells (``cells``, :class:`~brdfgan.core.lattice.CellTiling`): ``shifts`` are
    then the whole periods ``(H or 0, W or 0)`` by which the resampled maps' copies differ, and the
    copied fractions are measured against the resampled maps. ``lattice`` is ``None`` unless one
    was found (kept with ``cells`` ``None`` where no whole number of its cells fits: the cut's path).
    ``note``: one line where the lattice was ambiguous or could not be used, saying which path was
    taken. A 1-D pattern (``stripes``, :func:`~brdfgan.core.stripes.find_stripes`: planks, courses,
    rows) with no 2-D lattice to use is tiled by whole periods across its stripes (``cells`` on
    :meth:`~brdfgan.core.stripes.Stripes.cell_vectors`)."""

    flash_mark: FlashMark
    shifts: tuple[tuple[int, int], ...]
    wrap_ratio_before: dict[str, tuple[float, float]]
    after: TilingMeasures
    lattice: Lattice | None = None
    cells: CellTiling | None = None
    note: str | None = None
    perspective: Perspective | None = None
    stripes: Stripes | None = None

    def to_json(self) -> dict[str, Any]:
        measures = self.after.to_json()
        lattice = None
        if self.lattice is not None:
            lattice = {
                **self.lattice.to_json(),
                "cells": None if self.stripes is not None or self.cells is None else self.cells.to_json(),
                "perspective": None
                if self.perspective is None or self.stripes is not None
                else self.perspective.to_json(),
            }
        stripes = None
        if self.stripes is not None:
            stripes = {
                **self.stripes.to_json(),
                "cells": None if self.cells is None else self.cells.to_json(),
                "perspective": None if self.perspective is None else self.perspective.to_json(),
            }
        rectified = " (the perspective rectified first)" if self.perspective is not None else ""
        # Cells that fill the maps take the seam's margin from the nearest cells inside them.
        fills = self.cells is not None and self.cells.margin_fetched
        fetched = " (its margin fetched a cell in)" if fills else ""
        if self.cells is None:
            method = "flash mark repaired, then rolled and cut along minimum-error paths"
        elif self.stripes is not None:
            method = (
                f"flash mark repaired, then resampled to whole periods across its stripes{rectified}"
                f" and each wrap cut along a minimum-error path between copies whole periods apart{fetched}"
            )
        else:
            method = (
                f"flash mark repaired, then resampled to whole lattice cells{rectified}"
                f" and each wrap cut along a minimum-error path between copies one period apart{fetched}"
            )
        return {
            "method": method,
            "flash_mark": self.flash_mark.to_json(),
            "lattice": lattice,
            "stripes": stripes,
            "note": self.note,
            "shifts": [list(shift) for shift in self.shifts],
            "wrap_ratio_before": {name: list(pair) for name, pair in self.wrap_ratio_before.items()},
            "wrap_ratio_after": measures["wrap_ratio"],
            "copied_fraction": measures["copied_fraction"],
        }

    @classmethod
    def from_json(cls, record: dict[str, Any]) -> TileableRecord:
        before = record["wrap_ratio_before"]
        lattice = record.get("lattice")
        stripes = record.get("stripes")
        cells = (lattice or {}).get("cells") if stripes is None else stripes.get("cells")
        perspective = (lattice or {}).get("perspective") if stripes is None else stripes.get("perspective")
        note = record.get("note")
        return cls(
            flash_mark=FlashMark.from_json(record["flash_mark"]),
            shifts=tuple((int(dy), int(dx)) for dy, dx in record["shifts"]),
            wrap_ratio_before={str(name): (float(pair[0]), float(pair[1])) for name, pair in before.items()},
            after=TilingMeasures.from_json(
                {"wrap_ratio": record["wrap_ratio_after"], "copied_fraction": record["copied_fraction"]}
            ),
            lattice=None if lattice is None else Lattice.from_json(lattice),
            cells=None if cells is None else CellTiling.from_json(cells),
            note=None if note is None else str(note),
            perspective=None if perspective is None else Perspective.from_json(perspective),
            stripes=None if stripes is None else Stripes.from_json(stripes),
        )


@dataclass(frozen=True)
class TilePattern:
    """The pattern a tile keeps, found on the maps before the flash is taken out of them (so that
    the hotspot's disc is filled from it): their ``lattice``, and where it is not periodic their
    ``stripes`` (``None``: none found; not looked for beside a periodic lattice)."""

    lattice: Lattice
    stripes: Stripes | None

    @property
    def stripes_searched(self) -> bool:
        return not self.lattice.periodic

    def flash_twins(self) -> tuple[tuple[Vector, Vector] | None, Vector | None]:
        """:func:`~brdfgan.core.clipped_fill.remove_flash`'s ``lattice`` and ``stripes`` arguments:
        the lattice's vectors where it is periodic, else the stripes' direction, else neither."""
        if self.lattice.periodic and self.lattice.vectors is not None:
            return self.lattice.vectors, None
        return None, self.stripes.along if self.stripes is not None else None


def tile_pattern(maps: Tensor) -> TilePattern:
    """The maps' :class:`TilePattern`. Shape: ``(8, H, W)``."""
    lattice = find_lattice(maps)
    return TilePattern(lattice, None if lattice.periodic else find_stripes(maps))


def make_tileable(
    maps: Tensor,
    hotspot: tuple[float, float],
    *,
    align_pattern: bool = False,
    flash_mark: FlashMark | None = None,
    pattern: TilePattern | None = None,
) -> tuple[Tensor, TileableRecord]:
    """``--tileable``: the flash mark repaired where it leaked into the maps (:mod:`brdfgan.core.flash_mark`,
    ``hotspot`` ``(x, y)`` in the maps' pixels), so that no tile repeats it; then, for a material
    that repeats on a 2-D lattice (:func:`~brdfgan.core.lattice.find_lattice`), the maps resampled
    to a whole number of its cells and the wraps' residual seams cut
    (:func:`~brdfgan.core.lattice.tile_whole_cells`; ``align_pattern``: turned so that the lattice's
    own direction nearest an axis becomes it, ``--align-pattern``); for any other material, or a
    lattice whose cells do not fit, rolled and cut into a tile
    (:func:`~brdfgan.core.seamless.make_seamless`, unchanged), with the record of all.
    ``flash_mark``: the repair already made (``brdfgan predict``'s
    :func:`~brdfgan.core.clipped_fill.remove_flash`): the maps are taken as repaired; ``pattern``:
    the maps' lattice and stripes found before that repair (else found here).

    Shape: ``(8, H, W)`` → ``(8, H, W)``.
    """
    height, width = maps.shape[-2:]
    if min(height, width) < MIN_SIDE:
        raise PredictError(f"--tileable needs maps of at least {MIN_SIDE}×{MIN_SIDE}, got {height}×{width}")
    repaired, mark = repair_flash_mark(maps, hotspot) if flash_mark is None else (maps, flash_mark)
    before = {name: wrap_ratios(image) for name, image in zip(MAP_NAMES, file_units(maps), strict=True)}
    lattice = find_lattice(repaired) if pattern is None else pattern.lattice
    cells = None
    if lattice.periodic and lattice.vectors is not None:
        cells = choose_cells(lattice.vectors, height, width, align=align_pattern)
    # Perspective can smear a lattice past finding over the whole maps; their centre, where the
    # scale varies half as much, may still show it: a seed only, the rectified maps decide.
    seed = lattice if lattice.periodic or lattice.ambiguous else central_lattice(repaired)
    unrectified = repaired
    perspective = find_perspective(repaired, seed)
    if perspective is not None:
        # Mild perspective: the cells are taken from the rectified maps, where they all match
        # (kept only where whole cells fit there; the cut runs on the maps as they are).
        perspective, rectified, straight = refine_perspective(repaired, perspective)
        straight_cells = None
        if straight.periodic and straight.vectors is not None:
            straight_cells = choose_cells(straight.vectors, height, width, align=align_pattern)
        if straight_cells is not None:
            repaired, lattice, cells = rectified, straight, straight_cells
        else:
            perspective = None
    note = _lattice_note(lattice, cells, align_pattern, (height, width))
    stripes = None
    # Cells that do not match each other (setts whose joints wander along their rows) keep nothing
    # whole; where the maps have stripes, their rows are the pattern to keep.
    match = (
        None
        if cells is None or lattice.vectors is None
        else cell_match(repaired, lattice.vectors, lattice.features)
    )
    if cells is None or (match is not None and match < MIN_CELL_MATCH):
        # No 2-D lattice to tile by: a 1-D pattern still tiles by whole periods across its stripes.
        searched = pattern is not None and pattern.stripes_searched
        found = pattern.stripes if pattern is not None and searched else find_stripes(unrectified)
        stripe_tiling = None if found is None else _stripe_tiling(unrectified, found, align_pattern)
        if stripe_tiling is not None:
            repaired, stripes, cells, perspective = stripe_tiling
            note = _stripes_note(lattice, stripes, match)
    if cells is not None:
        # A lattice read from one feature group alone closes its cells on that group.
        whole = tile_whole_cells(repaired, cells, lattice.features if stripes is None else ALL_FEATURES)
        shifts = ((height, width), (height, 0), (0, width), (0, 0))
        record = TileableRecord(
            mark,
            shifts,
            before,
            whole.measures,
            lattice if lattice.periodic or lattice.ambiguous else None,
            whole.tiling,
            note,
            perspective,
            stripes,
        )
        return whole.maps, record
    tile = make_seamless(repaired)
    after = tiling_measures(tile.maps, repaired, tile.shifts)
    return tile.maps, TileableRecord(
        mark, tile.shifts, before, after, lattice if lattice.periodic else None, None, note
    )


def _stripe_tiling(
    maps: Tensor, found: Stripes, align_pattern: bool
) -> tuple[Tensor, Stripes, CellTiling, Perspective | None] | None:
    """``make_tileable``'s stripes path (:mod:`brdfgan.core.stripes`): the maps' stripes (``found``
    on them) and their whole-period cells, after taking out a mild perspective where the rectified
    maps show stripes whose cells fit (else on the maps as they are), with the maps the cells are
    cut from and the perspective; ``None`` where no cells fit.

    Shape: ``(8, H, W)`` → ``(8, H, W)`` and the rest.
    """
    height, width = maps.shape[-2:]
    perspective = find_stripe_perspective(maps, found)
    if perspective is not None:
        rectified = rectify(maps, perspective)
        straight = find_stripes(rectified)
        if straight is not None:
            cells = choose_stripe_cells(straight, height, width, align=align_pattern)
            if cells is not None:
                return rectified, straight, cells, perspective
    cells = choose_stripe_cells(found, height, width, align=align_pattern)
    return None if cells is None else (maps, found, cells, None)


def _stripes_note(lattice: Lattice, stripes: Stripes, match: float | None = None) -> str | None:
    """The one line where a 1-D pattern was tiled by although the maps showed a lattice (one whose
    cells do not fit or do not match each other, ``match`` (:func:`~brdfgan.core.lattice.cell_match`),
    or an ambiguous one); ``None`` otherwise."""
    score = f"score {lattice.score:.3f}, threshold {PROMINENCE_THRESHOLD}"
    path = (
        f"tiled by whole periods across its stripes ({stripes.period:.1f} px at {stripes.direction_deg:.1f}°)"
    )
    if lattice.periodic and match is not None:
        return (
            f"a lattice was found ({score}) but its cells match each other at only {match:.2f} "
            f"(below {MIN_CELL_MATCH}): {path}"
        )
    if lattice.periodic:
        return f"a lattice was found ({score}) but no whole number of its cells fits: {path}"
    if lattice.ambiguous:
        return f"the pattern is ambiguously periodic ({score}): {path}"
    return None


def _lattice_note(
    lattice: Lattice, cells: CellTiling | None, align_pattern: bool, size: tuple[int, int]
) -> str | None:
    """The one line ``material.json`` (and the run's warnings) get where the lattice decision is worth a
    look: an ambiguous score, a lattice whose cells do not fit (with, where they would fit turned
    onto the pattern's own axes, the flag that does it), ``--align-pattern`` with nothing to align.
    ``None`` otherwise. ``size``: the maps' ``(H, W)``."""
    score = f"score {lattice.score:.3f}, threshold {PROMINENCE_THRESHOLD}"
    if lattice.periodic and cells is None:
        note = (
            f"a lattice was found ({score}) but no whole number of its cells fits the maps within "
            f"{MAX_TURN_DEG:g}° of their axes and a stretch of at most {MAX_STRETCH}: tiled by the "
            "minimum-error cut"
        )
        # A pattern whose cells all lie about 15° or more off the axes (a diagonal grid turned by
        # a phone) fits once turned onto its own axes, which only the user may ask for.
        aligned = (
            None
            if align_pattern or lattice.vectors is None
            else choose_cells(lattice.vectors, *size, align=True)
        )
        if aligned is not None:
            note += (
                f"; --align-pattern turns the pattern onto its own axes, where {aligned.cells} "
                "whole cell(s) fit"
            )
        return note
    if lattice.ambiguous:
        path = "by whole lattice cells" if cells is not None else "by the minimum-error cut"
        return f"the pattern is ambiguously periodic ({score}): tiled {path}"
    if align_pattern and cells is None:
        return (
            "--align-pattern: no 2-D lattice in the maps, so nothing to align: tiled by the minimum-error cut"
        )
    return None


RefineProgress = Callable[[Path, int, int], None]  # (photo, step, of steps)


@dataclass
class StageClock:
    """Wall-clock seconds per pipeline stage, added into ``timings`` (``--verbose`` prints them)."""

    timings: dict[str, float]

    @contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.timings[stage] = self.timings.get(stage, 0.0) + time.perf_counter() - start

    def timed(self, stage: str, write: Callable[[Path], Any]) -> Callable[[Path], Any]:
        """``write`` with its time counted under ``stage``."""

        def run(target: Path) -> Any:
            with self(stage):
                return write(target)

        return run


def predict_photo(
    path: Path, out_dir: Path, predictor: Predictor, on_refine_step: RefineProgress | None = None
) -> PhotoResult:
    """Run the whole pipeline on one photo and write ``out_dir`` (replaced atomically)."""
    timings: dict[str, float] = {}
    clock = StageClock(timings)
    with clock("read"):
        photo = read_photo(path, predictor.options.colorspace)
    reference = predict_reference(photo, predictor, clock)
    return refine_and_write(reference, out_dir, predictor, clock, on_refine_step)


def refine_and_write(
    reference: ReferencePrediction,
    out_dir: Path,
    predictor: Predictor,
    clock: StageClock,
    on_refine_step: RefineProgress | None = None,
    *,
    warnings: tuple[str, ...] | None = None,
) -> PhotoResult:
    """The single-photo path after the network: ``--refine`` when asked, then the write-out.
    ``warnings``: the result's warnings instead of the photo's and its preprocessing's own."""
    options = predictor.options
    maps = reference.maps
    refinement: dict[str, Any] | None = None
    if options.refine is not None:
        steps = options.refine.steps
        path = reference.photo.path
        progress = None if on_refine_step is None else lambda step, _loss: on_refine_step(path, step, steps)
        with clock("refine"):
            refined = refine_maps(
                reference.prepared.photo, maps, reference.flash_frame, options.refine, on_step=progress
            )
        maps = refined.maps
        refinement = {
            **refined.to_json(),
            "field_of_view": {"degrees": reference.fov_deg, "source": reference.fov_source},
            "settings": {k: v for k, v in options.refine.to_json().items() if k != "steps"},
        }
    return write_prediction(
        reference,
        maps,
        out_dir,
        predictor,
        clock,
        # The test-time fit (brdfgan.inference.refine), None without --refine.
        records={"refinement": refinement},
        warnings=reference.warnings if warnings is None else warnings,
    )


@dataclass(frozen=True)
class ReferencePrediction:
    """One read photo through preprocessing and the network: what the write-out and the fits
    (``--refine``, ``--views``) start from."""

    photo: Photo
    prepared: Preprocessed
    fov_deg: float  # horizontal field of view across the crop
    fov_source: str
    flash_frame: Tensor  # (1, 3) of prepared.photo
    maps: Tensor  # (8, N, N), the network's (carried up on the fast path)

    @property
    def side(self) -> int:
        return int(self.prepared.photo.shape[-1])

    @property
    def warnings(self) -> tuple[str, ...]:
        return self.photo.warnings + self.prepared.warnings


def predict_reference(photo: Photo, predictor: Predictor, clock: StageClock) -> ReferencePrediction:
    """Preprocess a read photo, find its crop's field of view and flash frame, and run the network."""
    options = predictor.options
    with clock("preprocess"):
        prepared = preprocess(photo, predictor.resolution, options.crop)
    fov_deg, fov_source = crop_field_of_view(
        photo.lens, photo.width, photo.height, prepared.crop.size, options.field_of_view
    )
    flash_frame = prepared.flash_frame(fov_deg)
    return network_reference(photo, prepared, fov_deg, fov_source, flash_frame, predictor, clock)


def network_reference(
    photo: Photo,
    prepared: Preprocessed,
    fov_deg: float,
    fov_source: str,
    flash_frame: Tensor,
    predictor: Predictor,
    clock: StageClock,
) -> ReferencePrediction:
    """The network's maps of a prepared crop with its flash frame (carried up on the fast path),
    each stage timed: the second half of :func:`predict_reference`, and what a capture whose
    network input is not the photo itself (a pair's flash-only image) runs on its own crop."""
    side = prepared.photo.shape[-1]
    with clock("network"):
        outputs = predictor.network(prepared.photo, flash_frame)
    with clock("upsample") if predictor.network_side(side) != side else nullcontext():  # fast path only
        maps = predictor.upsample(outputs, prepared.photo, flash_frame)
    return ReferencePrediction(photo, prepared, fov_deg, fov_source, flash_frame, maps)


def input_clipped(photo: Photo, prepared: Preprocessed) -> Tensor:
    """The network input's pixels that say nothing of the surface but that it was bright: clipped
    in the input itself, or under a clipped pixel of the photo (the exposure may have scaled a
    saturated source below the clipping level; not for EXR, which has none).

    Shape: → ``(N, N)`` bool, the input's size."""
    clipped = clipped_mask(prepared.photo)
    if photo.source != "exr":
        clipped |= clipped_in_crop(photo.linear, prepared.crop, int(prepared.photo.shape[-1]))[0]
    return clipped


def finish_maps(
    maps: Tensor,
    reference: ReferencePrediction,
    *,
    tileable: bool,
    align_pattern: bool = False,
    clock: StageClock | None = None,
) -> tuple[Tensor, FlashRemoval, TileableRecord | None]:
    """What every prediction's maps go through before they are written: the flash taken out
    (:func:`~brdfgan.core.clipped_fill.remove_flash`, with the clipped pixels of
    :func:`input_clipped`), then with ``tileable`` the tile (:func:`make_tileable`). A tile's
    lattice is found first, so that a periodic material's hotspot disc is filled from its cells, and
    a clipped disc that lost its texture gets a patch of it (a smooth disc would repeat).

    Shape: ``(8, N, N)`` → ``(8, N, N)``."""
    clock = clock or StageClock({})
    prepared, frame = reference.prepared, reference.flash_frame
    with clock("flash"):
        pattern = tile_pattern(maps) if tileable else None
        lattice, stripes = pattern.flash_twins() if pattern is not None else (None, None)
        maps, removal = remove_flash(
            maps,
            prepared.photo,
            frame,
            clipped=input_clipped(reference.photo, prepared),
            lattice=lattice,
            stripes=stripes,
            restore_texture=tileable,
        )
    if pattern is None:
        return maps, removal, None
    with clock("tileable"):
        hotspot = (float(frame[0, 0]), float(frame[0, 1]))
        maps, tiling = make_tileable(
            maps,
            hotspot,
            align_pattern=align_pattern,
            flash_mark=removal.mark,
            pattern=pattern,
        )
    return maps, removal, tiling


def write_prediction(
    reference: ReferencePrediction,
    maps: Tensor,
    out_dir: Path,
    predictor: Predictor,
    clock: StageClock,
    *,
    records: dict[str, Any],
    warnings: tuple[str, ...],
) -> PhotoResult:
    """The write-out of a prediction: :func:`finish_maps`, ``material.json``'s metadata (with
    ``records``, the fits' entries), the previews, the viewer, and :func:`write_material`, which
    replaces ``out_dir`` atomically (nothing is left half-written on an error).

    Shape: maps ``(8, N, N)``."""
    options = predictor.options
    prepared = reference.prepared
    maps, flash_removal, tiling = finish_maps(
        maps, reference, tileable=options.tileable, align_pattern=options.align_pattern, clock=clock
    )
    if tiling is not None and tiling.note is not None:
        warnings = (*warnings, tiling.note)
    metadata = {
        "name": out_dir.name,
        "model": predictor.model.to_json(),
        "input": reference.photo.to_json(),
        **prepared.to_json(),
        # The crop's horizontal field of view: what a flash-aware network is told about the
        # geometry (brdfgan.core.flash_geometry), and the capture model of a refinement.
        "field_of_view": {"degrees": reference.fov_deg, "source": reference.fov_source},
        # Which path ran: tiling, the network's side, the output's, the guided upsampling.
        "inference": predictor.inference_record(reference.side),
        **records,
        # The flash taken out of the maps: clipped pixels filled, the hotspot's disc levelled,
        # metal lowered on thin dark features (brdfgan.core.clipped_fill.remove_flash).
        "flash_removal": flash_removal.to_json(),
        # --tileable: the flash mark's repair, the cut's copies, wrap ratios and copied fractions.
        "tileable": tiling.to_json() if tiling is not None else None,
        "input_statistics": prepared.stats,
        "brdf": BRDF_DESCRIPTION,
        "warnings": list(warnings),
    }
    extra_files: dict[str, Callable[[Path], Any]] = {}
    if options.preview:
        extra_files["preview.png"] = clock.timed(
            "preview", lambda target: write_preview(target, prepared.photo, maps)
        )
    if options.animate is not None:
        extra_files[f"preview.{options.animate}"] = clock.timed(
            "animation", lambda target: write_animation(target, maps)
        )
    # Tileable maps get a periodic height and occlusion (ExportOptions.periodic follows --tileable).
    prefix = f"{out_dir.name}_" if options.prefix_files else ""
    export = replace(options.export, periodic=options.tileable, file_prefix=prefix)
    # The material viewer page (index.html) last: it embeds the textures written before it.
    extra_files["index.html"] = clock.timed(
        "viewer", lambda target: write_viewer(target, metadata=metadata, options=export)
    )
    timings = clock.timings
    with clock("export"):  # textures, height and occlusion, material.glb (previews timed on their own)
        write_material(out_dir, maps, export, metadata, extra_files=extra_files)
    timings["export"] -= sum(timings.get(stage, 0.0) for stage in ("preview", "animation", "viewer"))
    return PhotoResult(photo=reference.photo.path, output=out_dir, warnings=warnings, timings=timings)


def clean_up_outputs(out_root: Path) -> None:
    """:func:`~brdfgan.inference.outputs.export.recover_outputs` before a run writes into
    ``out_root``; a failure is a warning (the run's own folders may still be writable)."""
    try:
        recover_outputs(out_root)
    except OSError as error:
        log.warning("%s: cannot clean up after earlier runs (%s)", out_root, error.strerror or error)
