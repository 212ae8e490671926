"""Several flash photos of one flat surface → one material (``brdfgan predict --views``).

::

    read_photo each view (an unreadable one: a warning naming it, left out)
      → the first readable view is the reference: preprocess + network, as predict_photo
      → each other view registered to the reference photo — by MaterialGAN's marker board where
        both photos show it, else by features (highlight masked) — and checked (check_registration:
        a view that fails is left out with a warning naming it)
      → its camera in the reference's world (views.geometry), its photo warped into the
        reference's texture frame (views.warp)
      → fit_views: the maps and each view's gain fitted to every view (views.fit)
      → the single-photo write-out (pipeline.write_prediction: atomic, nothing half-written),
        material.json with ``views`` (one entry per input, in order) and ``view_fit``

With fewer than two usable views the reference gets the single-photo path's output, with a
warning saying so.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from brdfgan.core.exposure import luminance
from brdfgan.core.homography import apply_homography, intrinsics
from brdfgan.core.render import CameraPose
from brdfgan.errors import UserError, one_line
from brdfgan.inference.intake.lens import crop_field_of_view
from brdfgan.inference.intake.photo import Colorspace, Photo, read_photo
from brdfgan.inference.pipeline import (
    PhotoResult,
    Predictor,
    ReferencePrediction,
    StageClock,
    predict_reference,
    refine_and_write,
    write_prediction,
)
from brdfgan.inference.views.config import ViewFitConfig
from brdfgan.inference.views.fit import ViewFitResult, fit_views, working_levels
from brdfgan.inference.views.geometry import (
    PLANE_HALF_SIZE,
    reference_camera,
    texture_to_photo,
    view_camera,
)
from brdfgan.inference.views.register import (
    MIN_MARKER_CORNERS,
    Registration,
    check_registration,
    detect_features,
    highlight_mask,
    homography_to_view,
    marker_homography,
)
from brdfgan.inference.views.warp import warp_to_reference

FitProgress = Callable[[int, int], None]  # (step, of steps)


@dataclass(frozen=True)
class RegisteredView:
    """A view that registered: its geometry and its photo in the reference's texture frame."""

    index: int  # position among the inputs
    photo: Photo
    registration: Registration
    camera: CameraPose
    pose_reprojection_px: float
    ambiguous: bool
    fov_deg: float  # horizontal, whole photo
    fov_source: str
    image: Tensor  # (3, N, N) linear, warped
    seen: Tensor  # (1, N, N)


def _vector(values: Sequence[float]) -> list[float]:
    return [float(v) for v in values]


def _finite_or_none(value: Any) -> Any:
    """JSON has no NaN or infinity: a view that sees nothing, a failed fit, record ``null``."""
    return None if isinstance(value, float) and not math.isfinite(value) else value


# The board's printed size: only the ratio of two views' board homographies is used, in which it
# cancels, so any value gives the same registration.
BOARD_SIZE_CM = 1.0


def grey_of(photo: Photo) -> np.ndarray:
    """The photo's linear luminance, what the board and the features are found on. Shape: ``(H, W)``."""
    return luminance(photo.linear)[0].numpy()


def find_board(grey: np.ndarray) -> Registration | None:
    """The marker board's homography (board plane → the photo's pixels) when the photo (its
    :func:`grey_of`) shows enough of its tags (:data:`MIN_MARKER_CORNERS` corners), else ``None``."""
    board = marker_homography(grey, BOARD_SIZE_CM)
    return board if board is not None and board.inliers >= MIN_MARKER_CORNERS else None


def reference_features(reference: ReferencePrediction, grey: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference photo's keypoints and descriptors (on its :func:`grey_of`), away from its
    flash highlight (found once for every view registered to it)."""
    return detect_features(grey, highlight_mask(reference.photo.linear))


def register_view(
    index: int,
    photo: Photo,
    reference: ReferencePrediction,
    features: tuple[np.ndarray, np.ndarray],
    board: Registration | None,
    predictor: Predictor,
) -> RegisteredView | str:
    """One view registered to the reference (whose :func:`reference_features` are ``features``
    and :func:`find_board` is ``board``), checked, posed and warped; or the one-line reason it is
    left out. Where both photos show the marker board it registers them (tag corners are exact
    where features may be few); a view without it falls back to the features."""
    side = reference.side
    photo_from_texture = texture_to_photo(reference.prepared.crop, side)
    corners = np.array([[0.0, 0.0], [side, 0.0], [side, side], [0.0, side]])
    square = apply_homography(photo_from_texture, corners)  # the reference square, reference pixels
    grey = grey_of(photo)
    view_board = find_board(grey) if board is not None else None
    if board is not None and view_board is not None:
        # Checked in the board's frame, where check_registration knows a marker view's orientation.
        reason = check_registration(
            view_board, apply_homography(np.linalg.inv(board.homography), square), photo.width, photo.height
        )
        registration = replace(view_board, homography=view_board.homography @ np.linalg.inv(board.homography))
    else:
        found = homography_to_view(features, grey, highlight_mask(photo.linear))
        if found is None:
            return "too few features match the reference photo's to fit a homography"
        registration = found
        reason = check_registration(
            registration,
            square,
            photo.width,
            photo.height,
            reference_size=(reference.photo.width, reference.photo.height),
        )
    if reason is not None:
        return reason
    view_from_texture = registration.homography @ photo_from_texture
    fov_deg, fov_source = crop_field_of_view(
        photo.lens, photo.width, photo.height, photo.width, predictor.options.field_of_view
    )
    try:
        camera, pose_error, ambiguous = view_camera(
            view_from_texture, intrinsics(fov_deg, photo.width, photo.height), side
        )
    except ValueError as error:
        return f"no camera pose fits its registration ({one_line(error)})"
    image, seen = warp_to_reference(photo.linear, view_from_texture, side)
    return RegisteredView(
        index, photo, registration, camera, pose_error, ambiguous, fov_deg, fov_source, image, seen
    )


def predict_views(
    paths: Sequence[Path],
    out_dir: Path,
    predictor: Predictor,
    on_fit_step: FitProgress | None = None,
    config: ViewFitConfig | None = None,
) -> PhotoResult:
    """Fit one material to every usable photo of ``paths`` (views of one flat surface, the first
    readable one the reference) and write it to ``out_dir`` (replaced atomically; module docstring),
    with the fit's settings ``config`` (default: ``ViewFitConfig()``).

    The result's warnings are one line each and name their file.

    Raises:
        UserError: no photo can be read, or the reference cannot be used (its one-line reason).
    """
    clock = StageClock({})
    log = _ViewLog.start(paths)
    with clock("read"):
        photos = _read_views(paths, predictor.options.colorspace, log)
    if not photos:  # the first one's reason, for a line that says what to fix
        first = log.warnings[0].replace(": left out: ", ": ", 1)
        raise UserError(f"none of the {len(paths)} views can be read ({first})")
    reference_index, *others = sorted(photos)
    reference = predict_reference(photos[reference_index], predictor, clock)
    log.entries[reference_index]["role"] = "reference"
    reference_path = paths[reference_index]
    log.warnings[:0] = [f"{reference_path}: {warning}" for warning in reference.warnings]
    with clock("register"):
        registered = _register_views(others, photos, reference, predictor, log)
    if not registered:
        log.warnings.append(
            f"{reference_path}: no other view is usable: the material is this photo's single-photo prediction"
        )
        return refine_and_write(reference, out_dir, predictor, clock, warnings=tuple(log.warnings))

    if len(registered) == 1:  # measured on synthetic captures: docs/views.md
        log.warnings.append(
            f"{reference_path}: only two usable photos: a fit to two can come out worse than one "
            "photo (glossy surfaces); 3-5 photos are what it needs"
        )
    camera = reference_camera(reference.flash_frame, reference.side)
    config = config or ViewFitConfig()
    fitted = _fit_registered(reference, camera, registered, config, clock, on_fit_step)
    _record_fit(log, reference_index, reference, camera, registered, fitted)
    records = {
        "refinement": None,
        # One entry per input view, in order: role reference/fitted/left_out and why, registration,
        # camera (world units of the reference's texture square [-1, 1]², flash at the lens), fit.
        "views": [{key: _finite_or_none(value) for key, value in entry.items()} for entry in log.entries],
        # The multi-view fit (brdfgan.inference.views.fit) and its settings.
        "view_fit": _fit_entry(fitted, config.to_json()),
    }
    return write_prediction(
        reference, fitted.maps, out_dir, predictor, clock, records=records, warnings=tuple(log.warnings)
    )


@dataclass(frozen=True)
class _ViewLog:
    """What :func:`predict_views` reports about its inputs: one material.json ``views`` entry per
    input (in order) and the result's warnings, a left-out view's naming its file."""

    paths: Sequence[Path]
    entries: list[dict[str, Any]]
    warnings: list[str]

    @classmethod
    def start(cls, paths: Sequence[Path]) -> _ViewLog:
        """Every input left out until it is read, registered and fitted."""
        return cls(paths, [{"file": str(path), "role": "left_out", "reason": None} for path in paths], [])

    def leave_out(self, index: int, reason: str) -> None:
        self.entries[index]["reason"] = reason
        self.warnings.append(f"{self.paths[index]}: left out: {reason}")


def _read_views(paths: Sequence[Path], colorspace: Colorspace | None, log: _ViewLog) -> dict[int, Photo]:
    """The photos that can be read, by input position; the others are left out."""
    photos: dict[int, Photo] = {}
    for index, path in enumerate(paths):
        try:
            photos[index] = read_photo(path, colorspace)
        except (UserError, OSError) as error:
            message = one_line(error)
            prefix = f"{path}: "
            log.leave_out(index, message[len(prefix) :] if message.startswith(prefix) else message)
    return photos


def _register_views(
    others: list[int],
    photos: dict[int, Photo],
    reference: ReferencePrediction,
    predictor: Predictor,
    log: _ViewLog,
) -> list[RegisteredView]:
    """The views ``others`` that register to the reference; the others are left out."""
    if not others:
        return []
    # The reference's features and board, found once for all views.
    grey = grey_of(reference.photo)
    features, board = reference_features(reference, grey), find_board(grey)
    registered: list[RegisteredView] = []
    for index in others:
        outcome = register_view(index, photos[index], reference, features, board, predictor)
        if isinstance(outcome, str):
            log.leave_out(index, outcome)
        else:
            registered.append(outcome)
    return registered


def _fit_registered(
    reference: ReferencePrediction,
    camera: CameraPose,
    registered: list[RegisteredView],
    config: ViewFitConfig,
    clock: StageClock,
    on_fit_step: FitProgress | None,
) -> ViewFitResult:
    """The reference's maps fitted to the reference (``camera``, seen whole) and the registered
    views, each with the flash at its lens."""
    cameras = [camera, *(view.camera for view in registered)]
    positions = torch.tensor([list(pose.origin) for pose in cameras], dtype=torch.float32)
    total_steps = sum(steps for _, steps in working_levels(config, reference.side))
    progress = None if on_fit_step is None else lambda step, _loss: on_fit_step(step, total_steps)
    with clock("fit"):
        return fit_views(
            torch.stack([reference.prepared.photo, *(view.image for view in registered)]),
            torch.stack([torch.ones_like(reference.prepared.photo[:1]), *(view.seen for view in registered)]),
            positions,
            positions,  # the flash at each lens
            reference.maps,
            PLANE_HALF_SIZE,
            config,
            on_step=progress,
        )


def _record_fit(
    log: _ViewLog,
    reference_index: int,
    reference: ReferencePrediction,
    camera: CameraPose,
    registered: list[RegisteredView],
    fitted: ViewFitResult,
) -> None:
    """Each fitted view's registration, camera and fit into its entry; a view the fit dropped
    is left out (the reference keeps its role)."""
    log.entries[reference_index].update(_camera_entry(camera, reference.fov_deg, reference.fov_source))
    for view in registered:
        log.entries[view.index].update(
            role="fitted",
            method=view.registration.method,
            inliers=view.registration.inliers,
            inlier_ratio=view.registration.inlier_ratio,
            reprojection_px=view.registration.reprojection_px,
            pose_reprojection_px=view.pose_reprojection_px,
            pose_ambiguous=view.ambiguous,
            **_camera_entry(view.camera, view.fov_deg, view.fov_source),
        )
    for index, record in zip(
        [reference_index, *(view.index for view in registered)], fitted.views, strict=True
    ):
        log.entries[index].update(
            coverage=record.coverage,
            gain=list(record.gain),
            residual_before=record.residual_before,
            residual_after=record.residual_after,
        )
        if record.dropped is not None:
            if index != reference_index:
                log.entries[index]["role"] = "left_out"
            log.leave_out(index, record.dropped)


def _camera_entry(pose: CameraPose, fov_deg: float, fov_source: str) -> dict[str, Any]:
    return {
        "camera_position": _vector(pose.origin),
        "camera_target": _vector(pose.target),
        "field_of_view": {"degrees": fov_deg, "source": fov_source},
    }


def _fit_entry(result: ViewFitResult, settings: dict[str, Any]) -> dict[str, Any]:
    return {**result.to_json(), "settings": settings}
