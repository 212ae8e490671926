"""A homography from each handheld flash photo of a flat surface to a common frame (OpenCV).

Two paths, each giving a :class:`Registration` (or ``None`` when nothing can be estimated):

- **Features** (:func:`feature_homography`): SIFT (default) or ORB keypoints matched between the
  reference photo and a view, then a robust homography (MAGSAC++). Keypoints are detected on the
  log luminance high-passed so that the flash's falloff, vignetting and exposure do not dominate
  (:func:`detection_image`), away from the flash highlight, which moves with the camera
  (:func:`highlight_mask`). Detection runs at most :data:`WORKING_LONG_SIDE` pixels on the long
  side; points and homographies are in full-resolution pixels.
- **Marker board** (:func:`marker_homography`): MaterialGAN's AprilTag 36h11 frame
  (:data:`MATERIALGAN_BOARD`); the homography maps the board plane, in cm and centred, to the view.

:func:`check_registration` gives the one-line reason to leave a registered view out. Nothing here
raises for a bad photo: the caller warns with the file's name and goes on without it. Points and
homographies use the project's pixel convention (pixel j's centre at j + ½, :mod:`brdfgan.core.homography`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import cv2
import numpy as np
import torch
from torch import Tensor

from brdfgan.core.exposure import SATURATION_LEVEL
from brdfgan.core.homography import apply_homography, from_opencv_px
from brdfgan.inference.intake.preprocess import (
    CLIP_DISC_FRACTION,
    CLIP_DISC_MIN_RADIUS,
    find_hotspot,
    flash_centre,
)

Detector = Literal["sift", "orb"]
Method = Literal["sift", "orb", "marker"]

# Features are detected on a copy at most this long (px): a 24 MP photo's finest texture is noise,
# and SIFT's cost grows with the pixel count.
WORKING_LONG_SIDE = 1600
MAX_FEATURES = 8000
ORB_SCALE_FACTOR = 1.2  # OpenCV's default pyramid step
# High-pass of the log luminance: Gaussian sigma as a fraction of the working copy's long side
# (the flash falloff and vignetting vary over the whole image, texture over a few pixels); the
# log's floor as a fraction of the mean luminance (keeps shadows from amplifying noise).
HIGH_PASS_SIGMA_FRACTION = 0.02
LOG_FLOOR_FRACTION = 0.01
# Working-copy pixels added around masked pixels, so that no keypoint lands on them at full size.
MASK_MARGIN_PX = 3
# Lowe's ratio test, and the robust fit's inlier threshold in working-copy pixels of the view.
RATIO_TEST = 0.75
RANSAC_THRESHOLD_PX = 2.0
RANSAC_MAX_ITERS = 10_000
RANSAC_CONFIDENCE = 0.999
# MAGSAC++ (OpenCV ≥ 4.5) is more accurate than RANSAC for the same threshold; RANSAC elsewhere.
HOMOGRAPHY_METHOD = getattr(cv2, "USAC_MAGSAC", cv2.RANSAC)

# The highlight disc: this many times preprocess's clipping-check disc (5 % of the short side),
# which covers the bright core of a glossy highlight but not its shoulders. Clipped pixels are
# masked too, dilated by this fraction of the long side (at least 3 px).
HIGHLIGHT_DISC_SCALE = 2.0
CLIPPED_DILATION_FRACTION = 0.005
MIN_CLIPPED_DILATION_PX = 3

# check_registration's limits: inliers for features, agreeing tag corners for the board (4 tags),
# the share of matches that agree, the linear scale change of a feature view at the reference
# square's centre, and the share of the reference square the view sees.
MIN_INLIERS = 40
MIN_MARKER_CORNERS = 16
MIN_INLIER_RATIO = 0.2
SCALE_RANGE = (1.0 / 3.0, 3.0)
MIN_VISIBLE_FRACTION = 0.25


@dataclass(frozen=True, eq=False)
class Registration:
    """Where a view sees a common frame.

    Attributes:
        homography: ``(3, 3)`` source → view pixels. The source is the reference photo's pixels
            (features) or the board plane in cm, centred, +y up (``method == "marker"``).
        method: ``"sift"``, ``"orb"`` or ``"marker"``.
        inliers: matches (features) or tag corners (marker) the homography agrees with.
        inlier_ratio: ``inliers`` over the matches that passed the ratio test, or over the
            board corners detected.
        reprojection_px: RMS distance in view pixels between the inliers and where the homography
            sends them.
        source_points: ``(N, 2)`` the inliers in the source frame (for the pose, lifted on the plane).
        view_points: ``(N, 2)`` the inliers in the view, pixels.
    """

    homography: np.ndarray
    method: Method
    inliers: int
    inlier_ratio: float
    reprojection_px: float
    source_points: np.ndarray = field(repr=False)
    view_points: np.ndarray = field(repr=False)


def highlight_mask(linear: Tensor | np.ndarray, *, clipped_is_saturated: bool = True) -> np.ndarray:
    """255 on the flash highlight, 0 elsewhere: a disc around the flash centre of
    :func:`~brdfgan.inference.intake.preprocess.flash_centre` (the image centre when no highlight
    stands out, where a phone's flash then is), plus the dilated clipped pixels unless the source
    has no saturation level (EXR). Features there move with the camera, not with the surface.

    Shape:
        - linear: ``(3, H, W)`` tensor or ``(H, W, 3)`` array, linear RGB, any scale
        - output: ``(H, W)`` uint8
    """
    image = (
        linear
        if isinstance(linear, Tensor)
        else torch.from_numpy(np.ascontiguousarray(linear.transpose(2, 0, 1)))
    )
    height, width = image.shape[-2:]
    # find_hotspot and flash_centre put pixel i's centre at i, as cv2.circle does.
    (centre_x, centre_y), _ = flash_centre(image, find_hotspot(image))
    radius = HIGHLIGHT_DISC_SCALE * max(CLIP_DISC_MIN_RADIUS, CLIP_DISC_FRACTION * min(height, width))
    mask = np.zeros((height, width), dtype=np.uint8)
    bits = 4  # cv2.circle's sub-pixel centre and radius: fixed point with 4 fractional bits
    centre = (round(centre_x * 2**bits), round(centre_y * 2**bits))
    cv2.circle(mask, centre, round(radius * 2**bits), 255, thickness=-1, shift=bits)
    if clipped_is_saturated:
        clipped = (image >= SATURATION_LEVEL).any(dim=0).numpy().astype(np.uint8) * 255
        dilation = max(MIN_CLIPPED_DILATION_PX, round(CLIPPED_DILATION_FRACTION * max(height, width)))
        mask[cv2.dilate(clipped, _disc_kernel(dilation)) > 0] = 255
    return mask


def _disc_kernel(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def detection_image(grey: np.ndarray) -> np.ndarray:
    """The 8-bit image keypoints are found on: the log luminance minus its Gaussian blur (sigma
    :data:`HIGH_PASS_SIGMA_FRACTION` of the long side), stretched from its 0.5th to 99.5th
    percentile. Taking the log makes the exposure and the flash falloff additive, and the
    high-pass removes them, so the same texel looks the same in every photo.

    Shape:
        - grey: ``(H, W)`` linear luminance, any scale
        - output: ``(H, W)`` uint8
    """
    grey = np.maximum(np.asarray(grey, dtype=np.float32), 0.0)
    floor = LOG_FLOOR_FRACTION * float(grey.mean()) + 1e-12
    log = np.log(grey + floor)
    sigma = HIGH_PASS_SIGMA_FRACTION * max(grey.shape)
    detail = log - cv2.GaussianBlur(log, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    low, high = np.percentile(detail, [0.5, 99.5])
    if not high > low:
        return np.zeros(grey.shape, dtype=np.uint8)
    stretched = (detail - low) * (255.0 / (high - low))
    return np.clip(stretched + 0.5, 0.0, 255.0).astype(np.uint8)


def detect_features(
    grey: np.ndarray, ignore_mask: np.ndarray | None, detector: Detector = "sift"
) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints and descriptors of a photo, found on the :func:`detection_image` of a copy at most
    :data:`WORKING_LONG_SIDE` long, none on the pixels where ``ignore_mask`` is non-zero (nor
    within :data:`MASK_MARGIN_PX` working pixels of them).

    Shape:
        - grey: ``(H, W)`` linear luminance; ignore_mask: ``(H, W)`` or ``None``
        - output: points ``(N, 2)`` full-resolution pixels, descriptors ``(N, D)`` (float32 for
          SIFT, uint8 for ORB)
    """
    height, width = grey.shape
    scale = min(1.0, WORKING_LONG_SIDE / max(height, width))
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    small = cv2.resize(np.asarray(grey, dtype=np.float32), size, interpolation=cv2.INTER_AREA)
    allowed = None
    if ignore_mask is not None:
        # Area resampling: a working pixel touching any masked pixel is masked.
        touched = cv2.resize(
            (np.asarray(ignore_mask) > 0).astype(np.float32), size, interpolation=cv2.INTER_AREA
        )
        ignored = cv2.dilate((touched > 0).astype(np.uint8), _disc_kernel(MASK_MARGIN_PX))
        allowed = np.where(ignored > 0, 0, 255).astype(np.uint8)
    keypoints, descriptors = _make_detector(detector).detectAndCompute(detection_image(small), allowed)
    if descriptors is None or len(keypoints) == 0:
        return np.zeros((0, 2)), np.zeros((0, 0), dtype=np.float32)
    working = from_opencv_px(_keypoint_positions(keypoints, detector, size))
    # Edge-based pixel coordinates scale exactly with the image.
    return working * np.array([width / size[0], height / size[1]]), descriptors


def _make_detector(detector: Detector) -> cv2.Feature2D:
    if detector == "sift":
        # Without precise upscaling SIFT's doubled first octave puts every keypoint ¼ px right
        # of and below where it is (measured on OpenCV 5.1: a 180° turn moves them by ½ px).
        return cv2.SIFT.create(nfeatures=MAX_FEATURES, enable_precise_upscale=True)
    if detector == "orb":
        return cv2.ORB.create(nfeatures=MAX_FEATURES, scaleFactor=ORB_SCALE_FACTOR)
    raise ValueError(f"unknown detector {detector!r}: expected 'sift' or 'orb'")


def _keypoint_positions(
    keypoints: Sequence[cv2.KeyPoint], detector: Detector, size: tuple[int, int]
) -> np.ndarray:
    """Keypoint centres in OpenCV pixels of the ``size = (W, H)`` image they were found on.

    ORB reports a point of pyramid level ℓ as its level position times 1.2^ℓ; the level's image is
    ``round(W / 1.2^ℓ)`` wide, resampled centre to centre, so that is off by up to a pixel at the
    coarse levels. Its position is mapped back exactly here. SIFT's are exact (precise upscaling).

    Shape:
        - output: ``(N, 2)`` float64
    """
    reported = np.array([keypoint.pt for keypoint in keypoints], dtype=np.float64).reshape(-1, 2)
    if detector != "orb":
        return reported
    level_scale = ORB_SCALE_FACTOR ** np.array([keypoint.octave for keypoint in keypoints], dtype=np.float64)
    full = np.array(size, dtype=np.float64)
    level_size = np.round(full / level_scale[:, None])
    return (reported / level_scale[:, None] + 0.5) * (full / level_size) - 0.5


def match_features(first: np.ndarray, second: np.ndarray, detector: Detector = "sift") -> np.ndarray:
    """Pairs of descriptors that are each other's clear nearest neighbour (brute force, Lowe's
    ratio test at :data:`RATIO_TEST`).

    Shape:
        - first: ``(N, D)``; second: ``(M, D)``
        - output: ``(P, 2)`` int, indices into ``first`` and ``second``
    """
    if len(first) == 0 or len(second) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    norm = cv2.NORM_L2 if detector == "sift" else cv2.NORM_HAMMING
    pairs = [
        (best.queryIdx, best.trainIdx)
        for best, second_best in (
            match for match in cv2.BFMatcher(norm).knnMatch(first, second, k=2) if len(match) == 2
        )
        if best.distance < RATIO_TEST * second_best.distance
    ]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def feature_homography(
    reference_grey: np.ndarray,
    view_grey: np.ndarray,
    reference_mask: np.ndarray | None = None,
    view_mask: np.ndarray | None = None,
    detector: Detector = "sift",
) -> Registration | None:
    """The homography from the reference photo's pixels to the view's, from matched keypoints
    (:func:`detect_features`, :func:`match_features`, MAGSAC++ at :data:`RANSAC_THRESHOLD_PX`
    working pixels). ``None`` when fewer than 4 matches survive or no homography fits them;
    a poor fit is returned for :func:`check_registration` to judge.

    Shape:
        - reference_grey: ``(H, W)``, view_grey: ``(H', W')`` linear luminance, any scale
        - reference_mask, view_mask: the same sizes, non-zero where no keypoint may be taken
          (:func:`highlight_mask`), or ``None``
    """
    reference = detect_features(reference_grey, reference_mask, detector)
    return homography_to_view(reference, view_grey, view_mask, detector)


def homography_to_view(
    reference: tuple[np.ndarray, np.ndarray],
    view_grey: np.ndarray,
    view_mask: np.ndarray | None = None,
    detector: Detector = "sift",
) -> Registration | None:
    """:func:`feature_homography` with the reference's keypoints and descriptors already found
    (:func:`detect_features`, by the same ``detector``): several views registered to one reference
    detect its features once.

    Shape:
        - reference: points ``(N, 2)`` full-resolution pixels, descriptors ``(N, D)``
        - view_grey: ``(H', W')`` linear luminance; view_mask: the same size or ``None``
    """
    reference_points, reference_descriptors = reference
    view_points, view_descriptors = detect_features(view_grey, view_mask, detector)
    pairs = match_features(reference_descriptors, view_descriptors, detector)
    if len(pairs) < 4:
        return None
    # The threshold is in working pixels of the view; the points are at full size.
    threshold = RANSAC_THRESHOLD_PX * max(1.0, max(view_grey.shape) / WORKING_LONG_SIDE)
    return _fit_registration(reference_points[pairs[:, 0]], view_points[pairs[:, 1]], threshold, detector)


def _fit_registration(
    source: np.ndarray, target: np.ndarray, threshold: float, method: Method
) -> Registration | None:
    """MAGSAC++ over the correspondences, then a least-squares refit on its inliers.

    Shape:
        - source, target: ``(N, 2)``
    """
    homography, inlier_flags = cv2.findHomography(
        source, target, HOMOGRAPHY_METHOD, threshold, maxIters=RANSAC_MAX_ITERS, confidence=RANSAC_CONFIDENCE
    )
    if homography is None:
        return None
    inliers = inlier_flags.ravel().astype(bool)
    if inliers.sum() >= 4:
        # MAGSAC++ weights points by their residual, and the residuals of ORB's whole-pixel corners
        # are mostly their rounding: all inliers at equal weight, refined by Levenberg-Marquardt,
        # average the rounding out (SIFT's sub-pixel corners lose nothing by it).
        refit, _ = cv2.findHomography(source[inliers], target[inliers], 0)
        homography = refit if refit is not None else homography
    residual = np.linalg.norm(apply_homography(homography, source[inliers]) - target[inliers], axis=1)
    return Registration(
        homography=homography / homography[2, 2],
        method=method,
        inliers=int(inliers.sum()),
        inlier_ratio=float(inliers.mean()),
        reprojection_px=float(np.sqrt(np.mean(residual**2))) if len(residual) else math.inf,
        source_points=source[inliers],
        view_points=target[inliers],
    )


@dataclass(frozen=True)
class MarkerBoard:
    """Square tags of one OpenCV dictionary printed upright on a plane.

    ``centres[k]`` is the centre of tag ``ids[k]`` in board units, +y up; each tag's black square
    spans ``±half_side`` units around it; the board's outer side is ``units_across`` units, the
    printed size the user gives in cm.
    """

    dictionary: int
    ids: tuple[int, ...]
    centres: tuple[tuple[float, float], ...]
    half_side: float
    units_across: float

    def corners_cm(self, board_size_cm: float) -> dict[int, np.ndarray]:
        """Each tag's corners on the plane in cm, centred, in OpenCV's order: the upright tag's
        top-left, top-right, bottom-right, bottom-left.

        Shape:
            - values: ``(4, 2)`` float64
        """
        unit = board_size_cm / self.units_across
        offsets = self.half_side * np.array([[-1.0, 1.0], [1.0, 1.0], [1.0, -1.0], [-1.0, -1.0]])
        return {
            tag: (np.asarray(centre) + offsets) * unit
            for tag, centre in zip(self.ids, self.centres, strict=True)
        }


# MaterialGAN's board (Guo et al. 2020; docs/views.md): tags 0–15 on the border of a
# 5×5 grid of pitch 4 units, clockwise from the top-left; a unit is size/18.
MATERIALGAN_BOARD = MarkerBoard(
    dictionary=cv2.aruco.DICT_APRILTAG_36h11,
    ids=tuple(range(16)),
    centres=(
        *((x, 8.0) for x in (-8.0, -4.0, 0.0, 4.0, 8.0)),  # 0–4: top row, left → right
        *((8.0, y) for y in (4.0, 0.0, -4.0)),  # 5–7: right column, top → bottom
        *((x, -8.0) for x in (8.0, 4.0, 0.0, -4.0, -8.0)),  # 8–12: bottom row, right → left
        *((-8.0, y) for y in (-4.0, 0.0, 4.0)),  # 13–15: left column, bottom → top
    ),
    half_side=1.0,
    units_across=18.0,
)


def marker_homography(
    grey: np.ndarray, board_size_cm: float, board: MarkerBoard = MATERIALGAN_BOARD
) -> Registration | None:
    """The homography from the board plane (cm, centred, +y up) to the photo's pixels, from the
    corners of the board's tags the photo shows (sub-pixel refined). ``None`` when no tag of the
    board is found or no homography fits.

    Shape:
        - grey: ``(H, W)`` linear luminance (any scale) or 8-bit
    """
    parameters = cv2.aruco.DetectorParameters()
    # AprilTag's own quad fit: 0.1–0.3 px corners on a rendered board, where CORNER_REFINE_SUBPIX
    # pulls each corner 0.4–0.8 px into the tag (a blurred corner is rounded).
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(board.dictionary), parameters)
    corners, ids, _ = detector.detectMarkers(_eight_bit(grey))
    if ids is None:
        return None
    board_corners = board.corners_cm(board_size_cm)
    found = [
        # Unlike OpenCV's other refinements, the AprilTag fit reports pixel-edge coordinates,
        # the project's convention (a tag filling pixels 70…149 has its corner at 70, not 69.5):
        # no half-pixel shift (tests/inference/views/test_views_register.py pins this).
        (board_corners[int(tag)], np.reshape(tag_corners, (4, 2)).astype(np.float64))
        for tag_corners, tag in zip(corners, np.ravel(ids), strict=True)
        if int(tag) in board_corners
    ]
    if not found:
        return None
    plane = np.concatenate([plane_corners for plane_corners, _ in found])
    image = np.concatenate([image_corners for _, image_corners in found])
    # The board's +y is up, the photo's rows go down: the map reverses orientation, and USAC
    # rejects every such sample as a mirror. It fits (x, −y) → photo, which keeps orientation.
    flip = np.diag([1.0, -1.0, 1.0])
    fitted = _fit_registration(plane * np.array([1.0, -1.0]), image, RANSAC_THRESHOLD_PX, "marker")
    if fitted is None:
        return None
    return replace(
        fitted, homography=fitted.homography @ flip, source_points=fitted.source_points @ flip[:2, :2]
    )


def _eight_bit(grey: np.ndarray) -> np.ndarray:
    """An 8-bit copy for the tag detector, which thresholds locally: linear values over their 99th
    percentile. Linear, not gamma-encoded: a gamma curve moves a blurred edge towards the dark
    side, shrinking every tag (about 0.1 px more corner error on a rendered board).

    Shape:
        - grey: ``(H, W)``; output: ``(H, W)`` uint8
    """
    if grey.dtype == np.uint8:
        return grey
    grey = np.maximum(np.asarray(grey, dtype=np.float32), 0.0)
    top = float(np.percentile(grey, 99.0))
    if not top > 0:
        return np.zeros(grey.shape, dtype=np.uint8)
    return (np.clip(grey / top, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def check_registration(
    registration: Registration,
    reference_square: np.ndarray,
    width: int,
    height: int,
    *,
    reference_size: tuple[int, int] | None = None,
) -> str | None:
    """The one-line reason to leave a registered view out, or ``None`` to keep it: too few inliers
    (:data:`MIN_INLIERS` matches, :data:`MIN_MARKER_CORNERS` tag corners), too small a share of
    the matches agreeing, a mirrored mapping, a feature view whose scale differs from the
    reference's by more than :data:`SCALE_RANGE` (a board homography is in pixels per cm, so this
    check does not apply), or less than :data:`MIN_VISIBLE_FRACTION` of the reference square in
    the ``width × height`` view. With the reference photo's ``(width, height)`` the scale is
    measured per long side, so that photos of different resolutions compare; without it, in pixels.

    Shape:
        - reference_square: ``(4, 2)`` its corners in the registration's source frame, in order
    """
    minimum, what = (
        (MIN_MARKER_CORNERS, "tag corners") if registration.method == "marker" else (MIN_INLIERS, "matches")
    )
    if registration.inliers < minimum:
        return f"only {registration.inliers} {what} agree on one plane (at least {minimum} needed)"
    if registration.inlier_ratio < MIN_INLIER_RATIO:
        return (
            f"only {registration.inlier_ratio:.0%} of the {what} agree on one plane "
            f"(at least {MIN_INLIER_RATIO:.0%} needed)"
        )
    square = np.asarray(reference_square, dtype=np.float64)
    homography = _facing(registration.homography, square.mean(axis=0))
    centre = np.append(square.mean(axis=0), 1.0)
    # The area scale of a homography at p is det(H) / w(p)³ with w(p) = H[2]·(p, 1).
    area_scale = float(np.linalg.det(homography)) / float(homography[2] @ centre) ** 3
    # The board's +y is up and a photo's rows go down, so a board view reverses orientation.
    if (area_scale < 0) != (registration.method == "marker") or area_scale == 0:
        return "the view is mirrored relative to the reference"
    low, high = SCALE_RANGE
    scale = math.sqrt(abs(area_scale))
    if reference_size is not None:
        scale *= max(reference_size) / max(width, height)
    if registration.method != "marker" and not low <= scale <= high:
        return f"the view is {scale:.2f}× the reference's scale (outside {low:.2f}–{high:.0f}×)"
    visible = visible_fraction(homography, square, width, height)
    if visible < MIN_VISIBLE_FRACTION:
        return (
            f"the view shows only {visible:.0%} of the reference square "
            f"(at least {MIN_VISIBLE_FRACTION:.0%} needed)"
        )
    return None


def _facing(homography: np.ndarray, point: np.ndarray) -> np.ndarray:
    """The homography scaled by ±1 so that ``point`` lands in front (w > 0): its overall sign
    is arbitrary, the side of the horizon is not."""
    w = float(homography[2] @ np.append(point, 1.0))
    return -homography if w < 0 else homography


def visible_fraction(homography: np.ndarray, polygon: np.ndarray, width: int, height: int) -> float:
    """The share of a convex polygon's area (in the source frame) that a homography sends inside
    the ``width × height`` image, in front of the camera. With ``w = H[2]·p``, the image's four
    edges are the source half-planes ``H[0]·p ≥ 0``, ``width·w − H[0]·p ≥ 0``, ``H[1]·p ≥ 0``
    and ``height·w − H[1]·p ≥ 0`` (they imply ``w ≥ 0``), so the polygon is clipped exactly there.

    Shape:
        - homography: ``(3, 3)`` with w > 0 inside the polygon; polygon: ``(N, 2)``, convex, in order
    """
    polygon = np.asarray(polygon, dtype=np.float64)
    total = _polygon_area(polygon)
    if not total > 0:
        return 0.0
    row_x, row_y, row_w = np.asarray(homography, dtype=np.float64)
    clipped = polygon
    for half_plane in (row_x, width * row_w - row_x, row_y, height * row_w - row_y):
        clipped = _clip_polygon(clipped, half_plane)
    return _polygon_area(clipped) / total


def _clip_polygon(polygon: np.ndarray, half_plane: np.ndarray) -> np.ndarray:
    """Sutherland–Hodgman: the part of a convex polygon where ``a·x + b·y + c ≥ 0``.

    Shape:
        - polygon: ``(N, 2)``; half_plane: ``(3,)`` = (a, b, c); output: ``(M, 2)``
    """
    values = polygon @ half_plane[:2] + half_plane[2]
    kept = []
    for index in range(len(polygon)):
        following = (index + 1) % len(polygon)
        if values[index] >= 0:
            kept.append(polygon[index])
        if (values[index] >= 0) != (values[following] >= 0):
            t = values[index] / (values[index] - values[following])
            kept.append(polygon[index] + t * (polygon[following] - polygon[index]))
    return np.array(kept, dtype=np.float64).reshape(-1, 2)


def _polygon_area(polygon: np.ndarray) -> float:
    """Shoelace area (absolute). Shape: polygon ``(N, 2)``."""
    if len(polygon) < 3:
        return 0.0
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))
