"""Plane ↔ photo geometry for photos of one flat surface: homographies, intrinsics, poses.

The surface is the plane z = 0 of :mod:`brdfgan.core.render`; a texture of ``side × side`` texels
covers its square ``[-s, s]²`` with row 0 at +Y (docs/conventions.md#scene-and-orientation).

Pixel conventions. The project puts the centre of pixel (or texel) j at j + ½: pixel j spans
``[j, j + 1]`` (:func:`~brdfgan.core.render.project_to_image`, ``grid_sample`` with
``align_corners=False``). OpenCV puts it at j. Every point and homography here is in the project's
convention, except the camera matrix of :func:`intrinsics` and what is handed to or read from
``cv2``; the half pixel between them is crossed only through :func:`to_opencv_px`,
:func:`from_opencv_px`, :func:`to_opencv_homography` and :func:`from_opencv_homography`.

Homographies are ``(3, 3)`` float64 acting on column vectors ``(x, y, 1)``; ``A → B`` maps points
of A to points of B.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from brdfgan.core.render import CameraPose, project_to_image

# OpenCV's pixel centre j is the project's j + ½.
OPENCV_PIXEL_OFFSET = 0.5
# IPPE's two planar poses: the runner-up must reproject this many times worse than the best for
# the choice to count as clear; nearly fronto-parallel views with noisy points fall below it.
AMBIGUITY_RATIO = 1.5
# Points per side of the grid on which two homographies are compared.
ERROR_GRID_POINTS = 21


def to_opencv_px(points_px: np.ndarray) -> np.ndarray:
    """Project pixel coordinates (pixel j's centre at j + ½) → OpenCV's (centre at j).

    Shape:
        - points_px: ``(..., 2)``; output: same, float64
    """
    return np.asarray(points_px, dtype=np.float64) - OPENCV_PIXEL_OFFSET


def from_opencv_px(points_px: np.ndarray) -> np.ndarray:
    """OpenCV pixel coordinates (pixel j's centre at j) → the project's (centre at j + ½).

    Shape:
        - points_px: ``(..., 2)``; output: same, float64
    """
    return np.asarray(points_px, dtype=np.float64) + OPENCV_PIXEL_OFFSET


def _translation(dx: float, dy: float) -> np.ndarray:
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])


def to_opencv_homography(homography: np.ndarray) -> np.ndarray:
    """An image → image homography in project pixels as OpenCV needs it (``cv2.warpPerspective``).

    Shape:
        - homography: ``(3, 3)``; output: ``(3, 3)`` float64
    """
    shift = OPENCV_PIXEL_OFFSET
    return (
        _translation(-shift, -shift) @ np.asarray(homography, dtype=np.float64) @ _translation(shift, shift)
    )


def from_opencv_homography(homography: np.ndarray) -> np.ndarray:
    """An image → image homography in OpenCV pixels (``cv2.findHomography``) in project pixels.

    Shape:
        - homography: ``(3, 3)``; output: ``(3, 3)`` float64
    """
    shift = OPENCV_PIXEL_OFFSET
    return (
        _translation(shift, shift) @ np.asarray(homography, dtype=np.float64) @ _translation(-shift, -shift)
    )


def intrinsics(fov_deg: float, width: int, height: int) -> np.ndarray:
    """The pinhole camera matrix K of a ``width × height`` photo with horizontal field of view
    ``fov_deg``, square pixels, principal point at the image centre, in **OpenCV's** pixel
    convention (the centre is ``(W/2 − ½, H/2 − ½)``), for ``cv2.solvePnP`` and friends.

    Shape:
        - output: ``(3, 3)`` float64
    """
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"fov_deg must lie in (0, 180), got {fov_deg}")
    if width < 1 or height < 1:
        raise ValueError(f"need a positive image size, got {width}x{height}")
    focal = width / (2.0 * math.tan(math.radians(fov_deg) / 2.0))
    centre_x, centre_y = to_opencv_px(np.array([width / 2.0, height / 2.0]))
    return np.array([[focal, 0.0, centre_x], [0.0, focal, centre_y], [0.0, 0.0, 1.0]])


def apply_homography(homography: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points mapped through a homography (no check that they stay in front of a camera).

    Shape:
        - homography: ``(3, 3)``; points: ``(N, 2)``; output: ``(N, 2)`` float64
    """
    points = np.asarray(points, dtype=np.float64)
    mapped = np.concatenate([points, np.ones_like(points[:, :1])], axis=1) @ np.asarray(homography).T
    return mapped[:, :2] / mapped[:, 2:]


def homography_from_points(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The homography mapping ``source`` onto ``target`` in the least-squares (DLT) sense; exact
    for 4 points in general position or for exact correspondences. Both point sets are
    normalised first (Hartley), so float64 keeps it exact to rounding.

    Shape:
        - source, target: ``(N, 2)``, N ≥ 4; output: ``(3, 3)`` float64 with ``H[2, 2] = 1``
    """
    source, target = np.asarray(source, dtype=np.float64), np.asarray(target, dtype=np.float64)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 2 or len(source) < 4:
        raise ValueError(f"need two (N, 2) point sets with N >= 4, got {source.shape} and {target.shape}")
    norm_source, norm_target = _normalising(source), _normalising(target)
    a = apply_homography(norm_source, source)
    b = apply_homography(norm_target, target)
    zeros, ones = np.zeros(len(a)), np.ones(len(a))
    rows_x = np.stack(
        [a[:, 0], a[:, 1], ones, zeros, zeros, zeros, -b[:, 0] * a[:, 0], -b[:, 0] * a[:, 1], -b[:, 0]], 1
    )
    rows_y = np.stack(
        [zeros, zeros, zeros, a[:, 0], a[:, 1], ones, -b[:, 1] * a[:, 0], -b[:, 1] * a[:, 1], -b[:, 1]], 1
    )
    _, _, vt = np.linalg.svd(np.concatenate([rows_x, rows_y]))
    homography = np.linalg.inv(norm_target) @ vt[-1].reshape(3, 3) @ norm_source
    return homography / homography[2, 2]


def _normalising(points: np.ndarray) -> np.ndarray:
    """The similarity moving ``(N, 2)`` points to mean 0 and mean distance √2 (Hartley)."""
    centre = points.mean(axis=0)
    spread = np.linalg.norm(points - centre, axis=1).mean()
    scale = math.sqrt(2.0) / spread if spread > 0 else 1.0
    return np.array([[scale, 0.0, -scale * centre[0]], [0.0, scale, -scale * centre[1]], [0.0, 0.0, 1.0]])


def texel_to_plane(plane_half_size: float, side: int) -> np.ndarray:
    """Texel coordinates of a ``side × side`` texture (texel j spans ``[j, j + 1]``, row 0 at +Y)
    → world ``(x, y)`` on the square ``[-s, s]²`` it covers (:func:`~brdfgan.core.render.texel_centres`).

    Shape:
        - output: ``(3, 3)`` float64 (an affine map)
    """
    step = 2.0 * plane_half_size / side
    return np.array([[step, 0.0, -plane_half_size], [0.0, -step, plane_half_size], [0.0, 0.0, 1.0]])


def plane_homography(pose: CameraPose, width: int, height: int) -> np.ndarray:
    """World ``(x, y)`` on the plane z = 0 → pixels of the ``width × height`` photo of ``pose``,
    from :func:`~brdfgan.core.render.project_to_image` (four points: it is a homography). The
    points sit around where the camera looks, so none is behind it for any view of the plane.

    Shape:
        - output: ``(3, 3)`` float64
    """
    target = np.asarray(pose.target, dtype=np.float64)
    spread = max(1e-6, 0.1 * float(np.linalg.norm(np.asarray(pose.origin, dtype=np.float64) - target)))
    plane_xy = target[:2] + spread * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    points = np.concatenate([plane_xy, np.zeros((4, 1))], axis=1)
    return homography_from_points(plane_xy, project_to_image(points, pose, width, height))


def pose_homography(
    pose: CameraPose, width: int, height: int, plane_half_size: float, side: int
) -> np.ndarray:
    """Texel coordinates of the ``side × side`` texture on ``[-s, s]²`` → pixels of the
    ``width × height`` photo of ``pose`` (both in the project's pixel convention): the ground
    truth of a registration.

    Shape:
        - output: ``(3, 3)`` float64
    """
    return plane_homography(pose, width, height) @ texel_to_plane(plane_half_size, side)


def homography_error_px(first: np.ndarray, second: np.ndarray, width: int, height: int) -> float:
    """The largest distance, in target pixels, between where two homographies send the points of a
    grid over the source rectangle ``[0, width] × [0, height]`` (edges included).

    Shape:
        - first, second: ``(3, 3)``
    """
    xs = np.linspace(0.0, float(width), ERROR_GRID_POINTS)
    ys = np.linspace(0.0, float(height), ERROR_GRID_POINTS)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    distance = np.linalg.norm(apply_homography(first, grid) - apply_homography(second, grid), axis=1)
    return float(distance.max())


def pose_from_plane_points(
    plane_xy: np.ndarray, image_px: np.ndarray, camera_matrix: np.ndarray
) -> tuple[CameraPose, float, bool]:
    """The camera that photographed points of the plane z = 0, by IPPE (``cv2.solvePnPGeneric``).

    IPPE gives the two poses a planar target allows. The one kept reprojects best among those
    whose camera is above the plane (z > 0); ``ambiguous`` says that the other physical pose
    reprojects less than :data:`AMBIGUITY_RATIO` times worse (a nearly fronto-parallel view with
    noisy points: the tilt's direction is then uncertain). The pose aims where its optical axis
    meets the plane (one unit ahead if it never does), with the field of view of ``camera_matrix``.

    Args:
        plane_xy: world ``(x, y)`` of the points on z = 0 (any unit; the pose is in that unit).
        image_px: where the photo shows them, project pixels (pixel j's centre at j + ½).
        camera_matrix: :func:`intrinsics` of the photo (OpenCV convention).

    Returns:
        the pose, its RMS reprojection error in pixels, and ``ambiguous``.

    Raises:
        ValueError: fewer than 4 points, or every pose is below the plane (the photo is mirrored:
            a registration with a negative determinant, which ``check_registration`` refuses).

    Shape:
        - plane_xy, image_px: ``(N, 2)``; camera_matrix: ``(3, 3)``
    """
    plane_xy, image_px = np.asarray(plane_xy, dtype=np.float64), np.asarray(image_px, dtype=np.float64)
    if plane_xy.shape != image_px.shape or plane_xy.ndim != 2 or plane_xy.shape[1] != 2 or len(plane_xy) < 4:
        raise ValueError(f"need two (N, 2) point sets with N >= 4, got {plane_xy.shape} and {image_px.shape}")
    world = np.concatenate([plane_xy, np.zeros((len(plane_xy), 1))], axis=1)
    _, rotations, translations, errors = cv2.solvePnPGeneric(
        world,
        to_opencv_px(image_px),
        np.asarray(camera_matrix, dtype=np.float64),
        None,
        flags=cv2.SOLVEPNP_IPPE,
    )
    candidates = []
    for rotation_vector, translation, error in zip(rotations, translations, np.ravel(errors), strict=True):
        rotation, _ = cv2.Rodrigues(rotation_vector)
        origin = -rotation.T @ np.ravel(translation)
        if origin[2] > 0.0:
            candidates.append((float(error), rotation, origin))
    if not candidates:
        raise ValueError("no camera pose above the plane fits the points (is the photo mirrored?)")
    candidates.sort(key=lambda candidate: candidate[0])
    best_error, rotation, origin = candidates[0]
    ambiguous = len(candidates) > 1 and candidates[1][0] < AMBIGUITY_RATIO * best_error
    return _camera_pose(rotation, origin, camera_matrix), best_error, ambiguous


def _camera_pose(rotation: np.ndarray, origin: np.ndarray, camera_matrix: np.ndarray) -> CameraPose:
    """OpenCV's world → camera rotation (rows: right, down, forward) and the camera centre as a
    :class:`CameraPose`; the width comes back from the principal point of :func:`intrinsics`."""
    down, forward = rotation[1], rotation[2]
    # The forward ray meets z = 0 at origin + t·forward with t = −z / forward_z.
    distance = -origin[2] / forward[2] if forward[2] < -1e-9 else 1.0
    target = origin + distance * forward
    width = 2.0 * float(from_opencv_px(np.array([camera_matrix[0, 2]]))[0])
    fov_deg = math.degrees(2.0 * math.atan(width / (2.0 * float(camera_matrix[0, 0]))))
    return CameraPose(_vector3(origin), _vector3(target), _vector3(-down), fov_deg)


def _vector3(vector: np.ndarray) -> tuple[float, float, float]:
    return (float(vector[0]), float(vector[1]), float(vector[2]))
