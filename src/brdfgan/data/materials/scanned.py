"""Scanned material sets as map sets: real scans in the layouts that material libraries ship.

A *material set* is a folder holding the maps of one scanned material; its layout is recognised
per folder from its file names (case-insensitive, each ``.jpg``, ``.jpeg`` or ``.png``; ``<name>``
is the material's name, ``<res>`` a resolution tag such as ``1K``/``2k``, ``[-JPG]`` ambientCG's
optional ``-JPG``/``-PNG`` tag):

========= =========== ================================================================
layout    map         file stem
========= =========== ================================================================
brdfgan   base colour ``albedo``
brdfgan   normal      ``normal`` (OpenGL)
brdfgan   roughness   ``roughness``
brdfgan   metallic    ``metallic`` (optional)
ambientcg base colour ``<name>_<res>[-JPG]_Color``
ambientcg normal      ``<name>_<res>[-JPG]_NormalGL``, or ``…_NormalDX`` (DirectX)
ambientcg roughness   ``<name>_<res>[-JPG]_Roughness``
ambientcg metallic    ``<name>_<res>[-JPG]_Metalness`` (optional)
polyhaven base colour ``<name>_diff_<res>``
polyhaven normal      ``<name>_nor_gl_<res>``, or ``<name>_nor_dx_<res>`` (DirectX)
polyhaven roughness   ``<name>_rough_<res>``, or G of ``<name>_arm_<res>``
polyhaven metallic    ``<name>_metal_<res>``, or B of ``<name>_arm_<res>`` (optional)
matsynth  base colour ``basecolor``
matsynth  normal      ``normal`` (OpenGL)
matsynth  roughness   ``roughness``
matsynth  metallic    ``metallic`` (optional)
========= =========== ================================================================

(:data:`LAYOUT_FILES` is this table in code.) ``brdfgan`` is the layout of ``../shared/scans`` and
``../shared/ood/ambientcg``; ``matsynth`` is also the layout :func:`brdfgan.io.maps.write_maps`
writes. The base colour file decides the layout; other files (displacement, AO, previews, …) are
ignored. An OpenGL normal (+Y up, our convention) is preferred when both are there; a DirectX one
has its Y flipped on read. Poly Haven's ARM texture packs AO, roughness, metallic in R, G, B and
supplies each of roughness and metallic that has no file of its own. No metallic map means 0
(a dielectric). Roughness and metallic files are grayscale (RGB with equal channels is accepted,
as :func:`brdfgan.io.maps.read_map_files` does); 8- and 16-bit files read alike. All maps of a
set must have one size, and it must be square.

A *folder of sets* (:func:`find_material_sets`) holds one set per sub-folder (one level; hidden
entries are ignored; sub-folders with no map file of any layout are not sets), sorted by folder
name, so the material index of a set is its position there. A folder that holds map files
itself (a downloaded ambientCG folder, say) is one set: the only one it yields. Problems are
:class:`DatasetConfigError` naming the folder or file: an incomplete set (e.g. a base colour but
no normal), several candidate files for one map, a corrupt file, mismatched or non-square sizes.

The sets feed datasets through :func:`read_scanned_material`, resized (linear-light base colour,
renormalised normals) to the dataset's ``material_resolution``; a dataset of scanned materials
is test only (:func:`brdfgan.data.spec.dataset_spec.split_materials`).
"""

from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from torch import Tensor

from brdfgan.core.svbrdf import NORMAL, resize_maps
from brdfgan.data.storage.spec_checks import DatasetConfigError
from brdfgan.io.maps import MapIOError, read_map_files

log = logging.getLogger(__name__)

Layout = Literal["brdfgan", "ambientcg", "polyhaven", "matsynth"]
NormalConvention = Literal["opengl", "directx"]

# Per layout, the file stem of each role as a template (tokens in _TOKENS); the extension is one
# of SCANNED_EXTENSIONS. Roles: basecolor, normal_gl, normal_dx, roughness, metallic, and arm (a
# packed texture: AO, roughness, metallic in R, G, B — see ARM_CHANNELS).
LAYOUT_FILES: dict[Layout, dict[str, str]] = {
    "brdfgan": {
        "basecolor": "albedo",
        "normal_gl": "normal",
        "roughness": "roughness",
        "metallic": "metallic",
    },
    "ambientcg": {
        "basecolor": "<name>_<res>[-JPG]_Color",
        "normal_gl": "<name>_<res>[-JPG]_NormalGL",
        "normal_dx": "<name>_<res>[-JPG]_NormalDX",
        "roughness": "<name>_<res>[-JPG]_Roughness",
        "metallic": "<name>_<res>[-JPG]_Metalness",
    },
    "polyhaven": {
        "basecolor": "<name>_diff_<res>",
        "normal_gl": "<name>_nor_gl_<res>",
        "normal_dx": "<name>_nor_dx_<res>",
        "roughness": "<name>_rough_<res>",
        "metallic": "<name>_metal_<res>",
        "arm": "<name>_arm_<res>",
    },
    "matsynth": {
        "basecolor": "basecolor",
        "normal_gl": "normal",
        "roughness": "roughness",
        "metallic": "metallic",
    },
}
_TOKENS = {"<name>": r".+", "<res>": r"\d+k", "[-JPG]": r"(?:-(?:jpg|png))?"}
SCANNED_EXTENSIONS = (".jpg", ".jpeg", ".png")
# The colour channel of an ARM texture that holds each map.
ARM_CHANNELS = {"roughness": 1, "metallic": 2}

# Kept for existing callers: the brdfgan layout, our map name → file stem.
SCANNED_FILE_STEMS = {
    "basecolor": "albedo",
    "normal": "normal",
    "roughness": "roughness",
    "metallic": "metallic",
}


def _compile(template: str) -> re.Pattern[str]:
    pattern = re.escape(template)
    for token, regex in _TOKENS.items():
        pattern = pattern.replace(re.escape(token), regex)
    extension = "|".join(re.escape(ext) for ext in SCANNED_EXTENSIONS)
    return re.compile(f"{pattern}(?:{extension})", re.IGNORECASE)


_PATTERNS = {
    layout: {role: _compile(template) for role, template in roles.items()}
    for layout, roles in LAYOUT_FILES.items()
}


@dataclass(frozen=True)
class ScanSet:
    """One material set on disk: which file holds which map.

    ``metallic`` is ``None`` for a dielectric (metallic 0). ``roughness_channel`` and
    ``metallic_channel`` name the colour channel of a packed file (Poly Haven's ARM) holding the
    map, ``None`` for a grayscale file.
    """

    folder: Path
    layout: Layout
    basecolor: Path
    normal: Path
    normal_convention: NormalConvention
    roughness: Path
    metallic: Path | None = None
    roughness_channel: int | None = None
    metallic_channel: int | None = None

    @property
    def name(self) -> str:
        """The material's name: its folder's."""
        return self.folder.name

    @property
    def files(self) -> dict[str, Path | None]:
        """``{map name: file}`` as :func:`brdfgan.io.maps.read_map_files` takes it."""
        return {
            "basecolor": self.basecolor,
            "normal": self.normal,
            "roughness": self.roughness,
            "metallic": self.metallic,
        }


def _listing(folder: Path) -> list[Path]:
    try:
        return sorted(p for p in folder.iterdir() if not p.name.startswith("."))
    except OSError as error:
        raise DatasetConfigError(f"{folder}: cannot list folder ({error.strerror or error})") from error


def _map_files(folder: Path) -> dict[Layout, dict[str, list[Path]]]:
    """The files of ``folder`` named as a layout names a role: layout → role → files (sorted)."""
    found: dict[Layout, dict[str, list[Path]]] = {}
    for path in _listing(folder):
        if not path.is_file():
            continue
        for layout, roles in _PATTERNS.items():
            for role, pattern in roles.items():
                if pattern.fullmatch(path.name):
                    found.setdefault(layout, {}).setdefault(role, []).append(path)
    return found


def _hint(layout: Layout, *roles: str) -> str:
    """The accepted file names of ``roles`` in ``layout``, for messages."""
    return " or ".join(
        f"{LAYOUT_FILES[layout][role]}.jpg|png" for role in roles if role in LAYOUT_FILES[layout]
    )


def detect_material_set(folder: str | os.PathLike[str]) -> ScanSet | None:
    """The material set stored in ``folder``, or ``None`` when it holds no map file of any layout.

    Only file names are looked at (no file is opened). :class:`DatasetConfigError` names the
    folder when the set is incomplete (no base colour, normal or roughness) or ambiguous (base
    colour files of two layouts, several files for one map).
    """
    folder = Path(folder)
    found = _map_files(folder)
    if not found:
        return None
    layouts = [layout for layout, roles in found.items() if "basecolor" in roles]
    if not layouts:
        present = ", ".join(sorted({p.name for roles in found.values() for ps in roles.values() for p in ps}))
        expected = ", ".join(f"{layout}: {_hint(layout, 'basecolor')}" for layout in LAYOUT_FILES)
        raise DatasetConfigError(
            f"{folder}: incomplete material set: no base colour map ({expected}) next to {present}"
        )
    if len(layouts) > 1:
        names = ", ".join(p.name for layout in layouts for p in found[layout]["basecolor"])
        raise DatasetConfigError(
            f"{folder}: base colour files of several layouts ({names}); keep one set per folder"
        )
    layout = layouts[0]
    roles = found[layout]

    def single(role: str) -> Path | None:
        paths = roles.get(role, [])
        if len(paths) > 1:
            names = ", ".join(p.name for p in paths)
            raise DatasetConfigError(f"{folder}: several {role} files ({names}); keep one set per folder")
        return paths[0] if paths else None

    basecolor = single("basecolor")
    assert basecolor is not None
    normal = single("normal_gl")
    convention: NormalConvention = "opengl"
    if normal is None:
        normal, convention = single("normal_dx"), "directx"
    arm = single("arm")
    roughness, roughness_channel = single("roughness"), None
    if roughness is None and arm is not None:
        roughness, roughness_channel = arm, ARM_CHANNELS["roughness"]
    metallic, metallic_channel = single("metallic"), None
    if metallic is None and arm is not None:
        metallic, metallic_channel = arm, ARM_CHANNELS["metallic"]

    missing = []
    if normal is None:
        missing.append(f"no normal map ({_hint(layout, 'normal_gl', 'normal_dx')})")
    if roughness is None:
        missing.append(f"no roughness map ({_hint(layout, 'roughness', 'arm')})")
    if normal is None or roughness is None:
        raise DatasetConfigError(
            f"{folder}: incomplete {layout} material set (base colour {basecolor.name}): {'; '.join(missing)}"
        )
    return ScanSet(
        folder=folder,
        layout=layout,
        basecolor=basecolor,
        normal=normal,
        normal_convention=convention,
        roughness=roughness,
        metallic=metallic,
        roughness_channel=roughness_channel,
        metallic_channel=metallic_channel,
    )


def find_material_sets(
    root: str | os.PathLike[str], *, key: str = "dataset_spec.scanned", skip_incomplete: bool = False
) -> tuple[list[ScanSet], list[tuple[Path, str]]]:
    """The material sets under ``root`` (one per sub-folder, sorted by name; or ``root`` itself
    when it holds map files), and the unusable ones skipped.

    With ``skip_incomplete=False`` an incomplete or ambiguous set raises
    :class:`DatasetConfigError` (the first one's message, with the count of the others); with
    ``True`` it is skipped and listed as ``(folder, message)``. Files are not opened here, so a
    corrupt file is found by :func:`read_material_set`. ``key`` names the setting in errors.
    It is an error if ``root`` is missing or holds no usable set.
    """
    folder = Path(root)
    if not folder.is_dir():
        raise DatasetConfigError(f"{key}={str(root)!r}: folder of scanned materials not found")
    candidates = sorted((p for p in _listing(folder) if p.is_dir()), key=lambda p: p.name)
    if _map_files(folder):
        nested = [p.name for p in candidates if _map_files(p)]
        if nested:
            raise DatasetConfigError(
                f"{key}={str(root)!r}: holds map files itself and material sets in sub-folders "
                f"({', '.join(nested)}); point at one set or at a folder of sets"
            )
        candidates = [folder]
    sets: list[ScanSet] = []
    skipped: list[tuple[Path, str]] = []
    for candidate in candidates:
        try:
            scan = detect_material_set(candidate)
        except DatasetConfigError as error:
            skipped.append((candidate, str(error)))
            continue
        if scan is not None:
            sets.append(scan)
    if skipped and not skip_incomplete:
        others = f" (and {len(skipped) - 1} more incomplete or ambiguous sets)" if len(skipped) > 1 else ""
        raise DatasetConfigError(skipped[0][1] + others)
    if not sets:
        also = f"; {len(skipped)} incomplete skipped" if skipped else ""
        raise DatasetConfigError(
            f"{key}={str(root)!r}: no material sets (sub-folders with {', '.join(LAYOUT_FILES)} "
            f"map files, e.g. albedo.jpg/png){also}"
        )
    return sets, skipped


def read_material_set(scan: ScanSet, resolution: int | None = None) -> Tensor:
    """The map set of ``scan``, OpenGL normals, at ``resolution``² (``None``: the files' size).

    :class:`DatasetConfigError` names the file that is unreadable, corrupt, out of range, of
    another size than the base colour, or not square.

    Shape:
        - output: ``(8, R, R)``, ``R`` = ``resolution`` or the files' side
    """
    channels = {
        name: channel
        for name, channel in (("roughness", scan.roughness_channel), ("metallic", scan.metallic_channel))
        if channel is not None
    }
    try:
        maps = read_map_files(scan.files, where=scan.folder, channels=channels)
    except MapIOError as error:
        raise DatasetConfigError(str(error)) from error
    if maps.shape[-1] != maps.shape[-2]:
        raise DatasetConfigError(
            f"{scan.basecolor}: maps are {maps.shape[-1]}x{maps.shape[-2]} (WxH), expected square"
        )
    if scan.normal_convention == "directx":
        maps[NORMAL][1].neg_()  # DirectX: +Y down
    return maps if resolution is None else resize_maps(maps, resolution)


def scanned_material_folders(
    root: str | os.PathLike[str], key: str = "dataset_spec.scanned", skip_incomplete: bool = False
) -> tuple[Path, ...]:
    """The folders of the material sets under ``root`` (:func:`find_material_sets`), sorted by
    name (the material index of a set is its position here); skipped sets are logged."""
    sets, skipped = find_material_sets(root, key=key, skip_incomplete=skip_incomplete)
    for _, reason in skipped:
        log.warning("skipping %s", reason)
    return tuple(scan.folder for scan in sets)


def read_scanned_material(folder: Path, resolution: int) -> Tensor:
    """The map set of one scanned folder, in any layout, at ``resolution``². A missing metallic
    file means 0.

    Shape:
        - output: ``(8, resolution, resolution)``
    """
    scan = detect_material_set(folder)
    if scan is None:
        raise DatasetConfigError(f"{folder}: no map files of a known layout ({', '.join(LAYOUT_FILES)})")
    return read_material_set(scan, resolution)


__all__ = [
    "ARM_CHANNELS",
    "LAYOUT_FILES",
    "SCANNED_EXTENSIONS",
    "SCANNED_FILE_STEMS",
    "Layout",
    "NormalConvention",
    "ScanSet",
    "detect_material_set",
    "find_material_sets",
    "read_material_set",
    "read_scanned_material",
    "scanned_material_folders",
]
