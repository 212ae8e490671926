"""Scanned material sets as map sets: the source of the out-of-distribution benchmark.

A folder of scanned PBR sets (``../shared/ood/ambientcg``: one sub-folder per material, ambientCG
file names) becomes the materials of a dataset that is **test only**
(:func:`brdfgan.data.generation.split_materials` puts every scanned material in ``test``), so
real scans can never become training data. The files of a set:

================ =========================================================================
``albedo``       base colour, sRGB (as our base colour maps are stored)
``normal``       tangent-space normal ``(n + 1)/2``, OpenGL (+Y up: our convention)
``roughness``    perceptual roughness, linear gray
``metallic``     metalness, linear gray; absent for dielectrics (metallic 0)
================ =========================================================================

each ``.jpg`` or ``.png``, all one size; the set is resized (linear-light base colour, renormalised
normals) to the dataset's ``material_resolution``.
"""

from __future__ import annotations

import os
from pathlib import Path

from torch import Tensor

from brdfgan.core.svbrdf import resize_maps
from brdfgan.data.spec_checks import DatasetConfigError
from brdfgan.io.maps import read_map_files

# Our map name → the file stem of a scanned set (ambientCG's names).
SCANNED_FILE_STEMS = {
    "basecolor": "albedo",
    "normal": "normal",
    "roughness": "roughness",
    "metallic": "metallic",
}
SCANNED_EXTENSIONS = (".jpg", ".jpeg", ".png")


def _find(folder: Path, stem: str) -> Path | None:
    found = [folder / f"{stem}{ext}" for ext in SCANNED_EXTENSIONS if (folder / f"{stem}{ext}").is_file()]
    if len(found) > 1:
        raise DatasetConfigError(f"{folder}: several {stem} files ({', '.join(p.name for p in found)})")
    return found[0] if found else None


def scanned_material_folders(
    root: str | os.PathLike[str], key: str = "dataset_spec.scanned"
) -> tuple[Path, ...]:
    """The material sets under ``root``: its sub-folders holding an albedo file, sorted by name
    (the material index of a set is its position here). ``key`` names the setting in errors."""
    folder = Path(root)
    if not folder.is_dir():
        raise DatasetConfigError(f"{key}={str(root)!r}: folder of scanned materials not found")
    sets = tuple(sorted(p for p in folder.iterdir() if p.is_dir() and _find(p, "albedo") is not None))
    if not sets:
        raise DatasetConfigError(f"{key}={str(root)!r}: no material sets (sub-folders with albedo.jpg/png)")
    return sets


def read_scanned_material(folder: Path, resolution: int) -> Tensor:
    """The map set of one scanned folder at ``resolution``². A missing metallic file means 0.

    Shape: output ``(8, resolution, resolution)``.
    """
    paths = {name: _find(folder, stem) for name, stem in SCANNED_FILE_STEMS.items()}
    maps = read_map_files(paths, where=folder)
    if maps.shape[-1] != maps.shape[-2]:
        raise DatasetConfigError(f"{folder}: maps are {maps.shape[-1]}x{maps.shape[-2]}, expected square")
    return resize_maps(maps, resolution)


__all__ = ["SCANNED_FILE_STEMS", "read_scanned_material", "scanned_material_folders"]
