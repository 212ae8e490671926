"""The world of a feature-registered view set: the reference's crop is the texture square.

Feature matches give only image → image homographies, so the world is anchored on the reference
photo, as :func:`~brdfgan.inference.refine.refine_maps` models a single photo: the reference's
preprocessed crop is the texture square ``[-1, 1]²`` of the plane z = 0 (row 0 at +Y), its camera
looks straight down from above the flash hotspot at the height its crop's field of view gives
(:func:`~brdfgan.core.render.capture_camera_height`), the flash at the lens. Every other view's
camera follows from its homography to that square and its own intrinsics (IPPE,
:func:`~brdfgan.core.homography.pose_from_plane_points`), its flash at its lens.
"""

from __future__ import annotations

import numpy as np
from torch import Tensor

from brdfgan.core.flash_geometry import check_flash_frame, field_of_view, hotspot_position
from brdfgan.core.homography import apply_homography, pose_from_plane_points, texel_to_plane
from brdfgan.core.render import CameraPose, capture_camera_height
from brdfgan.inference.intake.preprocess import Crop

# The reference's texture square is [-s, s]² with this s (refine_maps' capture model).
PLANE_HALF_SIZE = 1.0
# Points per side of the texture grid the pose is solved on.
POSE_GRID_POINTS = 11


def texture_to_photo(crop: Crop, side: int) -> np.ndarray:
    """Reference texture pixels (the ``side × side`` preprocessed crop) → reference photo pixels,
    both in the project's convention.

    Shape:
        - output: ``(3, 3)`` float64 (an affine map)
    """
    if side < 1:
        raise ValueError(f"side must be positive, got {side}")
    step = crop.size / side
    return np.array([[step, 0.0, float(crop.x)], [0.0, step, float(crop.y)], [0.0, 0.0, 1.0]])


def reference_camera(flash_frame: Tensor, side: int) -> CameraPose:
    """The reference camera as :func:`~brdfgan.inference.refine.refine_maps` places it: above the
    hotspot of the crop's flash frame, looking straight down, at the height that frames the texture
    square with the crop's field of view (the pose's ``fov_deg`` is the crop's).

    Shape:
        - flash_frame: ``(1, 3)`` of the ``side × side`` crop
    """
    frame = flash_frame.detach().float().reshape(1, -1).cpu()
    check_flash_frame(frame, 1)
    fov_deg = field_of_view(float(frame[0, 2]), side)
    height = capture_camera_height(fov_deg, PLANE_HALF_SIZE)
    x, y = (float(v) for v in hotspot_position(frame, side, side, PLANE_HALF_SIZE)[0])
    return CameraPose((x, y, height), (x, y, 0.0), (0.0, 1.0, 0.0), fov_deg)


def view_camera(
    view_from_texture: np.ndarray, camera_matrix: np.ndarray, side: int
) -> tuple[CameraPose, float, bool]:
    """A view's camera in the reference's world, from its homography to the texture square: a
    grid over the texture lifted to the plane and mapped into the view, solved by
    :func:`~brdfgan.core.homography.pose_from_plane_points`. The reprojection error measures how
    far the homography is from any camera with these intrinsics.

    Args:
        view_from_texture: reference texture pixels → view pixels.
        camera_matrix: the view's :func:`~brdfgan.core.homography.intrinsics` (whole photo).
        side: the reference texture's side in pixels.

    Returns:
        the pose (world units of the texture square), its RMS reprojection error in view pixels,
        and whether IPPE's two solutions were close (``ambiguous``).

    Raises:
        ValueError: fewer than 4 grid points in front of the view, or no pose above the plane.

    Shape:
        - view_from_texture, camera_matrix: ``(3, 3)``
    """
    ticks = np.linspace(0.0, float(side), POSE_GRID_POINTS)
    texels = np.stack(np.meshgrid(ticks, ticks), axis=-1).reshape(-1, 2)
    homography = np.asarray(view_from_texture, dtype=np.float64)
    w = np.concatenate([texels, np.ones((len(texels), 1))], axis=1) @ homography[2]
    # The overall sign of a homography is arbitrary: the side most points lie on is the front.
    in_front = w > 0 if (w > 0).sum() >= (w < 0).sum() else w < 0
    plane_xy = apply_homography(texel_to_plane(PLANE_HALF_SIZE, side), texels[in_front])
    return pose_from_plane_points(plane_xy, apply_homography(homography, texels[in_front]), camera_matrix)
