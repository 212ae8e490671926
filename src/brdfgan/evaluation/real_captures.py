"""Real multi-view flash captures as an evaluation input (``brdfgan eval-captures``).

The community's protocol for real photos without ground-truth maps (MaterialGAN, Guo et al. 2020;
Look-Ahead, Zhou & Kalantari 2022): several rectified flash photos of one planar sample with
calibrated camera and flash positions; predict the maps from one photo
(:func:`evaluate_captures`), re-render them at the other views' calibrated camera and flash, and
compare with those photos (sRGB RMSE, also after one gain fitted on the input view). The capture
folder's two layouts (``parameters.json``, MaterialGAN's text files), the facts of the format
this module relies on (units, axes, the light's power, the stored gamma) and the evaluation's
steps: ``docs/ood.md`` ("The capture folder format", "The evaluation, step by step").
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import torch
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.exposure import SATURATION_LEVEL
from brdfgan.core.flash_geometry import check_flash_frame, resize_flash_frame
from brdfgan.core.svbrdf import check_map_shape, linear_to_srgb, resize_maps
from brdfgan.errors import UserError
from brdfgan.inference.intake.photo import Photo, read_photo
from brdfgan.inference.intake.preprocess import Crop, preprocess
from brdfgan.inference.pipeline import unique_names
from brdfgan.inference.refine import RefineConfig, refine_maps
from brdfgan.inference.views.config import ViewFitConfig
from brdfgan.inference.views.fit import fit_views as fit_maps_to_views
from brdfgan.inference.views.fit import render_views
from brdfgan.io.atomic import write_text_atomic

log = logging.getLogger(__name__)

# fit_gain's refits of the gain and of the pixels it is fitted over (it settles in 2-3 on glossy captures).
GAIN_PASSES = 5

__all__ = [
    "REFERENCE_FILES",
    "CalibratedCapture",
    "CaptureError",
    "CaptureModel",
    "CaptureResults",
    "ViewScore",
    "capture_flash_frame",
    "capture_models",
    "check_fit_views",
    "evaluate_captures",
    "find_captures",
    "fit_capture_maps",
    "fit_gain",
    "markdown_table",
    "read_capture",
    "relight",
    "srgb_rmse",
    "write_capture_results",
]

PARAMETERS_FILE = "parameters.json"
CAMERA_FILE, LIGHT_FILE, SIZE_FILE, POWER_FILE = (
    "camera_pos.txt",
    "light_pos.txt",
    "image_size.txt",
    "light_power.txt",
)
VIEW_EXTENSIONS = (".png", ".jpg", ".jpeg")
# The resolution folder of svbrdf-diff-renderer's images/reference/<N>/ preferred: the protocol's.
PREFERRED_VIEW_RESOLUTION = 256
# The reference predictors compared with the model, by weights file in the references folder.
REFERENCE_FILES = ("photo_basecolor", "de_lit")

# (photo (3, N, N) linear auto-exposed, flash frame (1, 3)) → maps (8, N, N)
MapPredictor = Callable[[Tensor, Tensor], Tensor]


class CaptureError(UserError):
    """A capture folder cannot be evaluated; one line naming the file (and key)."""


# --- reading -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class CalibratedCapture:
    """One capture folder: its views and calibration (centimetres, sample centre at the origin).
    The views are a :data:`~brdfgan.capture.VIEWS` capture, the input view its flash reference;
    ``--fit-views K`` fits the first K of them as ``predict --views`` does.

    Attributes:
        name: how tables name it (the folder's name, made unique within a run).
        folder: the capture folder.
        views: the view files, the input view first.
        view_ids: their numbers (``NN`` of ``NN.png``).
        camera_pos, light_pos: ``(V, 3)`` float64, one row per view.
        light_pow: the flash's RGB radiant intensity (``light_pow`` / ``light_power.txt``).
        image_size: the side of the sample square the views show.
        layout: ``"json"`` (``parameters.json``) or ``"txt"`` (MaterialGAN's text files).
    """

    name: str
    folder: Path
    views: tuple[Path, ...]
    view_ids: tuple[int, ...]
    camera_pos: Tensor
    light_pos: Tensor
    light_pow: tuple[float, float, float]
    image_size: float
    layout: Literal["json", "txt"]
    side: int = 0  # pixels of every view (checked when read); 0 until then

    @property
    def plane_half_size(self) -> float:
        return self.image_size / 2.0


def is_capture_folder(folder: Path) -> bool:
    """Whether ``folder`` is meant as one capture (its calibration or its first view is there)."""
    return any((folder / name).is_file() for name in (PARAMETERS_FILE, CAMERA_FILE, "00.png"))


def find_captures(paths: Sequence[str | os.PathLike[str]]) -> list[CalibratedCapture]:
    """The captures named on the command line, read and checked (module docstring: a folder is a
    capture or a folder of captures). Raises :class:`CaptureError` for the first bad one."""
    folders: list[Path] = []
    for item in paths:
        path = Path(item)
        if not path.exists():
            raise CaptureError(f"{path}: no such folder")
        if not path.is_dir():
            raise CaptureError(f"{path}: not a folder (a capture folder or a folder of them)")
        if is_capture_folder(path):
            folders.append(path)
            continue
        found = sorted(sub for sub in path.iterdir() if sub.is_dir() and is_capture_folder(sub))
        if not found:
            raise CaptureError(
                f"{path}: neither a capture folder ({PARAMETERS_FILE} or {CAMERA_FILE} with 00.png, "
                "01.png, …) nor a folder of capture folders"
            )
        folders += found
    unique: list[Path] = []
    for folder in folders:
        if folder.resolve() not in {f.resolve() for f in unique}:
            unique.append(folder)
    return [read_capture(folder, name) for folder, name in zip(unique, _capture_names(unique), strict=True)]


def _capture_names(folders: Sequence[Path]) -> list[str]:
    """The folders' names, with the parent's name added where two are alike, then numbered."""
    names = [folder.resolve().name or "capture" for folder in folders]
    counts = {name: names.count(name) for name in names}
    return unique_names(
        f"{folder.resolve().parent.name}/{name}" if counts[name] > 1 else name
        for folder, name in zip(folders, names, strict=True)
    )


def read_capture(folder: str | os.PathLike[str], name: str | None = None) -> CalibratedCapture:
    """Read and check one capture folder (either layout; ``parameters.json`` first).

    Raises:
        CaptureError: a missing or invalid parameter (naming the file and key), a missing view,
            views that are not square or not all of one size.
    """
    folder = Path(folder)
    if (folder / PARAMETERS_FILE).is_file():
        capture = _read_json_layout(folder, name or folder.resolve().name)
    elif (folder / CAMERA_FILE).is_file():
        capture = _read_text_layout(folder, name or folder.resolve().name)
    else:
        raise CaptureError(
            f"{folder / PARAMETERS_FILE}: not found (nor the older {CAMERA_FILE}, {SIZE_FILE}, "
            f"{POWER_FILE}): the capture's calibration is missing"
        )
    return _check_views(capture)


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise CaptureError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _positions(rows: Any, where: str) -> Tensor:
    """``(V, 3)`` from a list of ``[x, y, z]``, every z above the sample (> 0)."""
    if not isinstance(rows, list) or not rows:
        raise CaptureError(f"{where}: expected a list of [x, y, z] per view, got {_short(rows)}")
    values: list[list[float]] = []
    for index, row in enumerate(rows):
        if not isinstance(row, list | tuple) or len(row) != 3:
            raise CaptureError(f"{where}[{index}]: expected [x, y, z], got {_short(row)}")
        values.append([_number(v, f"{where}[{index}]") for v in row])
        if not values[-1][2] > 0:
            raise CaptureError(f"{where}[{index}]: z = {values[-1][2]:g} is not above the sample (z > 0)")
    return torch.tensor(values, dtype=torch.float64)


def _power(value: Any, where: str) -> tuple[float, float, float]:
    """A positive number or three, as RGB."""
    values = value if isinstance(value, list | tuple) else [value]
    if len(values) not in (1, 3):
        raise CaptureError(f"{where}: expected one number or three (RGB), got {_short(value)}")
    numbers = [_number(v, where) for v in values]
    if not all(v > 0 for v in numbers):
        raise CaptureError(f"{where}: the flash power must be positive, got {_short(value)}")
    r, g, b = numbers * 3 if len(numbers) == 1 else numbers
    return (r, g, b)


def _size(value: Any, where: str) -> float:
    size = _number(value, where)
    if not size > 0:
        raise CaptureError(f"{where}: the sample's side must be positive, got {size:g}")
    return size


def _short(value: Any, limit: int = 60) -> str:
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _read_json_layout(folder: Path, name: str) -> CalibratedCapture:
    path = folder / PARAMETERS_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as error:
        raise CaptureError(f"{path}: cannot read ({getattr(error, 'strerror', None) or error})") from None
    except json.JSONDecodeError as error:
        raise CaptureError(f"{path}: not valid JSON (line {error.lineno}: {error.msg})") from None
    if not isinstance(data, dict):
        raise CaptureError(
            f"{path}: expected a JSON object with image_size, camera_pos, light_pos, light_pow"
        )
    for key in ("image_size", "camera_pos", "light_pow"):
        if key not in data:
            raise CaptureError(f"{path}: key {key!r} is missing")
    image_size = _size(data["image_size"], f"{path}: image_size")
    camera = _positions(data["camera_pos"], f"{path}: camera_pos")
    light = _positions(data["light_pos"], f"{path}: light_pos") if "light_pos" in data else camera.clone()
    power = _power(data["light_pow"], f"{path}: light_pow")
    ids = data.get("idx", list(range(camera.shape[0])))
    if (
        not isinstance(ids, list)
        or not all(isinstance(i, int) and not isinstance(i, bool) for i in ids)
        or len(set(ids)) != len(ids)
    ):
        raise CaptureError(f"{path}: idx: expected a list of distinct view numbers, got {_short(ids)}")
    for key, positions in (("camera_pos", camera), ("light_pos", light)):
        bad = [i for i in ids if not 0 <= i < positions.shape[0]]
        if bad:
            raise CaptureError(f"{path}: {key}: no entry for view {bad[0]} ({positions.shape[0]} entries)")
    if len(ids) < 2:
        raise CaptureError(f"{path}: idx: needs at least two views (one to predict from, one to relight)")
    images_dir = data.get("images_dir")
    if images_dir is not None and not isinstance(images_dir, str):
        raise CaptureError(f"{path}: images_dir: expected a folder name, got {_short(images_dir)}")
    views = _view_files(folder, ids, images_dir, PARAMETERS_FILE)
    index = torch.tensor(ids)
    return CalibratedCapture(
        name, folder, views, tuple(ids), camera[index], light[index], power, image_size, "json"
    )


def _text_numbers(path: Path) -> list[list[float]]:
    """The rows of numbers of a MaterialGAN text file (commas and/or spaces; blank lines and
    ``#`` comments skipped)."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise CaptureError(f"{path}: cannot read ({getattr(error, 'strerror', None) or error})") from None
    rows: list[list[float]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        try:
            values = [float(v) for v in re.split(r"[,\s]+", line.strip(", \t")) if v]
        except ValueError:
            raise CaptureError(f"{path}: line {number}: expected numbers, got {_short(line)}") from None
        if not all(math.isfinite(v) for v in values):
            raise CaptureError(f"{path}: line {number}: expected finite numbers, got {_short(line)}")
        rows.append(values)
    if not rows:
        raise CaptureError(f"{path}: empty (no numbers)")
    return rows


def _read_text_layout(folder: Path, name: str) -> CalibratedCapture:
    for required in (SIZE_FILE, POWER_FILE):
        if not (folder / required).is_file():
            raise CaptureError(f"{folder / required}: not found (the capture's {CAMERA_FILE} needs it)")
    camera = _positions(_text_numbers(folder / CAMERA_FILE), str(folder / CAMERA_FILE))
    light = camera.clone()
    if (folder / LIGHT_FILE).is_file():
        light = _positions(_text_numbers(folder / LIGHT_FILE), str(folder / LIGHT_FILE))
        if light.shape[0] != camera.shape[0]:
            raise CaptureError(
                f"{folder / LIGHT_FILE}: {light.shape[0]} positions, but {CAMERA_FILE} has {camera.shape[0]}"
            )
    size_rows = [v for row in _text_numbers(folder / SIZE_FILE) for v in row]
    if len(size_rows) != 1:
        raise CaptureError(
            f"{folder / SIZE_FILE}: expected one number (the sample's side), got {len(size_rows)}"
        )
    image_size = _size(size_rows[0], str(folder / SIZE_FILE))
    power = _power([v for row in _text_numbers(folder / POWER_FILE) for v in row], str(folder / POWER_FILE))
    if camera.shape[0] < 2:
        raise CaptureError(
            f"{folder / CAMERA_FILE}: needs at least two views (one to predict from, one to relight)"
        )
    ids = list(range(camera.shape[0]))
    views = _view_files(folder, ids, None, CAMERA_FILE)
    return CalibratedCapture(name, folder, views, tuple(ids), camera, light, power, image_size, "txt")


def _view_file(folder: Path, view: int) -> Path | None:
    for extension in VIEW_EXTENSIONS:
        path = folder / f"{view:02d}{extension}"
        if path.is_file():
            return path
    return None


def _view_files(folder: Path, ids: Sequence[int], images_dir: str | None, source: str) -> tuple[Path, ...]:
    """The view files: beside the calibration, else in ``<images_dir>/reference/<N>/``."""
    where = folder
    if _view_file(folder, ids[0]) is None and images_dir is not None:
        reference = folder / images_dir / "reference"
        sizes = (
            sorted(
                (int(d.name) for d in reference.iterdir() if d.is_dir() and d.name.isdigit()), reverse=True
            )
            if reference.is_dir()
            else []
        )
        if PREFERRED_VIEW_RESOLUTION in sizes:
            sizes.remove(PREFERRED_VIEW_RESOLUTION)
            sizes.insert(0, PREFERRED_VIEW_RESOLUTION)
        where = next((reference / str(n) for n in sizes if _view_file(reference / str(n), ids[0])), folder)
    views: list[Path] = []
    for view in ids:
        path = _view_file(where, view)
        if path is None:
            raise CaptureError(
                f"{where / f'{view:02d}.png'}: missing view {view:02d} ({source} lists {len(ids)} views)"
            )
        views.append(path)
    return tuple(views)


def _check_views(capture: CalibratedCapture) -> CalibratedCapture:
    """Every view square and of the first one's size (image headers only)."""
    from PIL import Image, UnidentifiedImageError

    first: tuple[int, int] | None = None
    for path in capture.views:
        try:
            with Image.open(path) as image:
                width, height = image.size
        except (UnidentifiedImageError, OSError) as error:
            raise CaptureError(
                f"{path}: not a readable image ({getattr(error, 'strerror', None) or error})"
            ) from None
        if width != height:
            raise CaptureError(
                f"{path}: {width}×{height} pixels; a rectified capture view is square (the whole sample)"
            )
        if first is None:
            first = (width, height)
        elif (width, height) != first:
            raise CaptureError(
                f"{path}: {width}×{height} pixels, but {capture.views[0].name} is {first[0]}×{first[1]}"
            )
    assert first is not None
    return replace(capture, side=first[0])


def read_views(capture: CalibratedCapture) -> list[Photo]:
    """Every view decoded like ``brdfgan predict`` decodes a photo (sRGB → linear)."""
    photos = [read_photo(path, "srgb") for path in capture.views]
    for photo in photos:
        if (photo.height, photo.width) != (capture.side, capture.side):  # EXIF rotation aside, never
            raise CaptureError(f"{photo.path}: {photo.width}×{photo.height} pixels, expected {capture.side}²")
    return photos


# --- geometry, relighting, scores ---------------------------------------------------------------


def capture_flash_frame(capture: CalibratedCapture, view: int = 0, side: int | None = None) -> Tensor:
    """The :mod:`flash frame <brdfgan.core.flash_geometry>` of view ``view`` (index into
    ``capture.views``) at ``side`` pixels (default: the capture's): the hotspot where the flash is
    above the plane, ``s = (image_size / side) / light_z`` (module docstring).

    Shape: output ``(1, 3)`` float32.
    """
    side = side or capture.side
    if side < 1:
        raise ValueError(f"need a positive side, got {side}")
    lx, ly, lz = (float(v) for v in capture.light_pos[view])
    size = capture.image_size
    x = (lx / size + 0.5) * side
    y = (0.5 - ly / size) * side
    frame = torch.tensor([[x, y, size / side / lz]], dtype=torch.float32)
    check_flash_frame(frame, 1)
    return frame


@torch.no_grad()
def relight(capture: CalibratedCapture, maps: Tensor) -> Tensor:
    """Every view re-rendered from ``maps`` at its calibrated camera and flash, radiance ×
    ``light_pow`` (linear, unclipped), one view at a time (bounded memory at 1024²+).

    Shape:
        - maps: ``(8, side, side)``
        - output: ``(V, 3, side, side)`` in the maps' dtype
    """
    check_map_shape(maps)
    power = torch.tensor(capture.light_pow, dtype=maps.dtype).view(3, 1, 1)
    renders = [
        render_views(
            maps[None], capture.camera_pos[v : v + 1], capture.light_pos[v : v + 1], capture.plane_half_size
        )[0]
        for v in range(len(capture.views))
    ]
    return torch.stack(renders) * power


def fit_gain(render: Tensor, photo: Tensor, saturation: float = SATURATION_LEVEL) -> float:
    """The gain ``g`` minimising ``Σ (g·render − photo)²`` (linear) over the pixels whose photo is
    not saturated and whose scaled render ``g·render`` is not either (every channel below
    ``saturation``; all pixels when none is left). A black render gets 1 (any gain fits it as
    badly).

    The second condition matters on glossy samples: next to a clipped highlight a phone's tone
    curve leaves the photo just under 1 where the render is several times brighter, and those few
    pixels would pull a least-squares gain down by a third. ``g`` and the pixel set are refitted
    together until the set settles (at most :data:`GAIN_PASSES` passes).

    Shape: render, photo ``(3, H, W)`` linear.
    """
    r_all, p_all = render.double(), photo.double()
    unsaturated = (p_all < saturation).all(dim=0, keepdim=True)
    if not unsaturated.any():
        unsaturated = torch.ones_like(unsaturated)
    pixels, gain = unsaturated, 1.0
    for _ in range(GAIN_PASSES):
        chosen = pixels.expand_as(p_all)
        r, p = r_all[chosen], p_all[chosen]
        energy = float((r * r).sum())
        if not energy > 0:
            return 1.0
        gain = float((r * p).sum()) / energy
        settled = unsaturated & (gain * r_all < saturation).all(dim=0, keepdim=True)
        if not settled.any() or torch.equal(settled, pixels):
            break
        pixels = settled
    return gain


def srgb_rmse(render: Tensor, photo: Tensor) -> float:
    """RMSE of the two linear images clipped to [0, 1] and sRGB-encoded, over pixels and channels."""
    a = linear_to_srgb(render.double().clamp(0.0, 1.0))
    b = linear_to_srgb(photo.double().clamp(0.0, 1.0))
    return float((a - b).square().mean().sqrt())


# --- models ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CaptureModel:
    """A predictor to score: ``predict(photo (3, N, N), frame (1, 3)) → maps (8, N, N)`` fed the
    auto-exposed input view at ``resolution`` (``None``: the capture's own), optionally followed
    by ``refine_maps`` with ``refine``."""

    name: str
    predict: MapPredictor
    resolution: int | None = None
    refine: RefineConfig | None = None


def shipped_references_dir() -> Path:
    """``brdfgan/weights/references`` inside the package."""
    return Path(str(resources.files("brdfgan") / "weights" / "references"))


def model_predictor(
    path: str | os.PathLike[str] | None, resolution: int | None = None
) -> tuple[str, CaptureModel]:
    """A weights file (default: the shipped one) as a :class:`CaptureModel` run like ``brdfgan
    predict`` runs it (direct or tiled); its name is the model id."""
    from brdfgan.inference.model.weights import load_model
    from brdfgan.inference.pipeline import PredictOptions, Predictor

    model = load_model(path)
    side = resolution or model.resolution
    predictor = Predictor(model, PredictOptions(), side)
    return str(model.path), CaptureModel(model.model_id, predictor.maps, side)


def capture_models(
    weights: str | os.PathLike[str] | None = None,
    references: str | os.PathLike[str] | None = None,
    *,
    refine: RefineConfig | None = None,
    resolution: int | None = None,
) -> list[CaptureModel]:
    """The models of one ``eval-captures`` run: the weights (default: the shipped ones), with
    ``refine`` the same followed by the refinement (``<name>+refine<steps>``), then the references
    of :data:`REFERENCE_FILES` found in ``references`` (default: the shipped folder); a missing
    reference file is a warning, and that row is left out. ``resolution``: every model's input
    side (default: each model's training resolution)."""
    path, main = model_predictor(weights, resolution)
    models = [main]
    if refine is not None:
        models.append(
            CaptureModel(f"{main.name}+refine{refine.steps}", main.predict, main.resolution, refine)
        )
    folder = Path(references) if references is not None else shipped_references_dir()
    for reference in REFERENCE_FILES:
        file = folder / f"{reference}.safetensors"
        if not file.is_file():
            log.warning("%s: no such reference weights file; the %s row is left out", file, reference)
            continue
        if file.resolve() == Path(path).resolve():
            continue  # --weights is this reference: its row is there already
        _, model = model_predictor(file, resolution)
        models.append(CaptureModel(reference, model.predict, model.resolution))
    names = [m.name for m in models]
    return [
        m
        if names.count(m.name) == 1
        else CaptureModel(f"{m.name} ({i + 1})", m.predict, m.resolution, m.refine)
        for i, m in enumerate(models)
    ]


def predict_capture_maps(capture: CalibratedCapture, photo: Photo, model: CaptureModel) -> Tensor:
    """``model``'s maps of the input view ``photo``, at the capture's resolution (module docstring).

    Shape: output ``(8, side, side)`` float32.
    """
    side = capture.side
    resolution = model.resolution or side
    prepared = preprocess(photo, resolution, Crop(0, 0, side))
    for warning in prepared.warnings:
        log.debug("%s: %s", photo.path, warning)
    frame = resize_flash_frame(capture_flash_frame(capture, 0, side), resolution / side)
    with torch.no_grad():
        maps = model.predict(prepared.photo, frame)
    check_map_shape(maps)
    check_shape(maps, "8 R R", name=f"{model.name}'s maps", dims={"R": resolution})
    if model.refine is not None:
        maps = refine_maps(prepared.photo, maps, frame, model.refine).maps
    return resize_maps(maps.detach().float().cpu(), side)


def check_fit_views(captures: Sequence[CalibratedCapture], fit_views: int) -> None:
    """Raise :class:`CaptureError` for the first capture with no view left to relight after
    fitting to its first ``fit_views`` views (``fit_views`` ≥ 1)."""
    if fit_views < 1:
        raise UserError(f"fit_views={fit_views}: expected a positive number of views")
    for capture in captures:
        if len(capture.views) <= fit_views:
            raise CaptureError(
                f"{capture.folder}: {len(capture.views)} views, but fitting to the first {fit_views} "
                f"needs at least {fit_views + 1} (one left to relight)"
            )


def fit_capture_maps(
    capture: CalibratedCapture,
    photos: Sequence[Photo],
    maps: Tensor,
    fit_views: int,
    config: ViewFitConfig | None = None,
) -> Tensor:
    """``maps`` fitted to the first ``fit_views`` views of ``capture`` (module docstring): the
    views are rectified onto the sample square already, so each is seen whole, in the maps' frame.

    Shape: maps ``(8, side, side)`` → ``(8, side, side)``.
    """
    stacked = torch.stack([photo.linear for photo in photos[:fit_views]])
    result = fit_maps_to_views(
        stacked,
        torch.ones_like(stacked[:, :1]),
        capture.camera_pos[:fit_views],
        capture.light_pos[:fit_views],
        maps,
        capture.plane_half_size,
        config,
    )
    dropped = [f"{record.index:02d}" for record in result.views if record.dropped is not None]
    log.debug(
        "%s: fit to %d views kept the %s (loss %.4g → %.4g; dropped views: %s)",
        capture.name,
        fit_views,
        result.kept,
        result.loss_start,
        result.loss_end,
        ", ".join(dropped) or "none",
    )
    return result.maps


# --- results -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class ViewScore:
    """One view's sRGB RMSE for one model: with the gain fitted on the input view, and with the
    calibrated flash power; ``role`` is ``"input"`` for the view the maps came from, ``"fitted"``
    for the other views the maps were fitted to, ``"relit"`` for the views scored."""

    model: str
    capture: str
    view: int
    role: Literal["input", "fitted", "relit"]
    gain: float
    rmse_fitted: float
    rmse_calibrated: float


@dataclass(frozen=True)
class CaptureResults:
    """Every view's scores, with the order of models and captures; ``fit_views``: the number of
    views the maps were fitted to (1: the input view alone)."""

    models: tuple[str, ...]
    captures: tuple[str, ...]
    views: tuple[ViewScore, ...] = field(default_factory=tuple)
    fit_views: int = 1

    def capture_mean(self, model: str, capture: str, key: str = "rmse_fitted") -> float:
        """Mean over the relit views of one capture."""
        values = [
            getattr(v, key)
            for v in self.views
            if v.model == model and v.capture == capture and v.role == "relit"
        ]
        return sum(values) / len(values) if values else math.nan

    def mean(self, model: str, key: str = "rmse_fitted") -> float:
        """Mean of the capture means (each material weighs the same)."""
        means = [self.capture_mean(model, capture, key) for capture in self.captures]
        return sum(means) / len(means) if means else math.nan


def score_capture(
    capture: CalibratedCapture, photos: Sequence[Photo], maps: Tensor, model: str, fit_views: int = 1
) -> list[ViewScore]:
    """Relight ``maps`` at every view of ``capture`` and score them against ``photos``; the first
    ``fit_views`` views are the input and the fitted ones (in no mean)."""
    renders = relight(capture, maps)
    gain = fit_gain(renders[0], photos[0].linear)
    return [
        ViewScore(
            model=model,
            capture=capture.name,
            view=view_id,
            role="input" if index == 0 else "fitted" if index < fit_views else "relit",
            gain=gain,
            rmse_fitted=srgb_rmse(gain * render, photo.linear),
            rmse_calibrated=srgb_rmse(render, photo.linear),
        )
        for index, (view_id, render, photo) in enumerate(zip(capture.view_ids, renders, photos, strict=True))
    ]


def evaluate_captures(
    captures: Sequence[CalibratedCapture],
    models: Sequence[CaptureModel],
    on_capture: Callable[[CalibratedCapture], None] | None = None,
    fit_views: int = 1,
    fit_config: ViewFitConfig | None = None,
) -> CaptureResults:
    """Every model on every capture (module docstring); ``on_capture`` is called after each
    capture (progress). ``fit_views`` > 1: the maps are fitted to the first ``fit_views`` views
    with ``fit_config`` (default: ``ViewFitConfig()``) and each row is ``<model>+fit<K>``.

    Raises:
        CaptureError: a capture with ``fit_views`` views or fewer, before any model runs.
    """
    if not captures or not models:
        raise UserError("nothing to evaluate: no captures or no models")
    check_fit_views(captures, fit_views)
    names = [m.name if fit_views == 1 else f"{m.name}+fit{fit_views}" for m in models]
    views: list[ViewScore] = []
    for capture in captures:
        photos = read_views(capture)
        for model, name in zip(models, names, strict=True):
            maps = predict_capture_maps(capture, photos[0], model)
            if fit_views > 1:
                maps = fit_capture_maps(capture, photos, maps, fit_views, fit_config)
            views += score_capture(capture, photos, maps, name, fit_views)
        if on_capture is not None:
            on_capture(capture)
    return CaptureResults(tuple(names), tuple(c.name for c in captures), tuple(views), fit_views)


def markdown_table(results: CaptureResults) -> str:
    """One row per model: the mean relit-view RMSE with the fitted gain (the headline) and with
    the calibrated power, then each capture's mean with the fitted gain."""
    relit = sorted({v.view for v in results.views if v.role == "relit"})
    source = "maps predicted from the first view"
    if results.fit_views > 1:
        source += f" and fitted to the first {results.fit_views} views (not scored)"
    lines = [
        f"Relit views of {len(results.captures)} capture(s), {source}; "
        f"sRGB RMSE, lower is better (views {', '.join(f'{v:02d}' for v in relit)}). Fitted gain: one "
        "gain per model and capture fitted on the input view; calibrated: the capture's flash power as is.",
        "",
        "| model | relit (fitted gain) | relit (calibrated power) | "
        + " | ".join(_cell_text(c) for c in results.captures)
        + " |",
        "|---|---|---|" + "---|" * len(results.captures),
    ]
    for model in results.models:
        cells = [results.mean(model), results.mean(model, "rmse_calibrated")]
        cells += [results.capture_mean(model, capture) for capture in results.captures]
        lines.append(f"| {_cell_text(model)} | " + " | ".join(f"{v:.4f}" for v in cells) + " |")
    return "\n".join(lines) + "\n"


def _cell_text(text: str) -> str:
    return text.replace("|", "\\|")


def csv_table(results: CaptureResults) -> str:
    """One row per model, capture and view (the input and fitted views too, ``role`` = ``input``,
    ``fitted``)."""
    table = io.StringIO(newline="")
    writer = csv.writer(table)
    writer.writerow(["model", "capture", "view", "role", "gain", "rmse_fitted_gain", "rmse_calibrated_power"])
    for v in results.views:
        writer.writerow(
            [
                v.model,
                v.capture,
                f"{v.view:02d}",
                v.role,
                f"{v.gain:.6g}",
                f"{v.rmse_fitted:.6f}",
                f"{v.rmse_calibrated:.6f}",
            ]
        )
    return table.getvalue()


def write_capture_results(results: CaptureResults, out: str | os.PathLike[str]) -> list[Path]:
    """``out/captures.md`` and ``out/captures.csv``, each written atomically."""
    folder = Path(out)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UserError(f"{folder}: cannot create the output folder ({error.strerror or error})") from None
    return [
        write_text_atomic(folder / "captures.md", markdown_table(results)),
        write_text_atomic(folder / "captures.csv", csv_table(results)),
    ]
