"""Registration of handheld flash photos of one flat surface (issue 47): the plane ↔ photo geometry
of ``core.homography`` and the feature and marker paths of ``inference.views.register``, on
synthetic photos of a textured plane warped by the exact homographies of known cameras."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import torch

from brdfgan.core.exposure import luminance
from brdfgan.core.homography import (
    apply_homography,
    from_opencv_homography,
    from_opencv_px,
    homography_error_px,
    intrinsics,
    plane_homography,
    pose_from_plane_points,
    pose_homography,
    texel_to_plane,
    to_opencv_homography,
    to_opencv_px,
)
from brdfgan.core.render import CameraPose, camera_frame, nominal_camera, project_to_image, view_plane_points
from brdfgan.inference.views.register import (
    MATERIALGAN_BOARD,
    Detector,
    Method,
    Registration,
    check_registration,
    detect_features,
    feature_homography,
    highlight_mask,
    marker_homography,
)

FOV_DEG = 60.0
WIDTH, HEIGHT = 480, 360
# The textured plane: side × side texels over [-s, s]², larger than any view sees.
PLANE_HALF_SIZE = 1.5
TEXTURE_SIDE = 1152
REFERENCE = CameraPose((0.0, 0.0, 1.04), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), FOV_DEG)
# Handheld-like views of the reference's area: 15–25° of tilt, rolled by up to 40°.
VIEW_PLACES = (
    ((0.35, -0.2, 1.0), (0.05, 0.0, 0.0), 15.0),
    ((-0.4, 0.3, 1.1), (0.0, -0.05, 0.0), -25.0),
    ((0.1, 0.45, 0.95), (0.0, 0.05, 0.0), 40.0),
)
# Where the flash highlight falls in the reference and in each view (project pixels).
FLASH_CENTRES = ((250.0, 170.0), (120.0, 250.0), (380.0, 90.0), (300.0, 280.0))
FULL_FRAME = np.array([[0.0, 0.0], [WIDTH, 0.0], [WIDTH, HEIGHT], [0.0, HEIGHT]])

# The marker scene, in cm: MaterialGAN's 18 cm board on a 24 cm texture of 40 texels per cm.
BOARD_CM = 18.0
BOARD_PLANE_HALF_SIZE = 12.0
BOARD_TEXTURE_SIDE = 960
MARKER_WIDTH, MARKER_HEIGHT = 640, 480


def look_at(
    origin: tuple[float, float, float], target: tuple[float, float, float], roll_deg: float
) -> CameraPose:
    """A camera at ``origin`` aiming at ``target``, with world +Y up in the image turned by ``roll_deg``."""
    forward = np.subtract(target, origin) / np.linalg.norm(np.subtract(target, origin))
    level_up = np.array([0.0, 1.0, 0.0]) - forward[1] * forward
    level_up /= np.linalg.norm(level_up)
    roll = math.radians(roll_deg)
    up = math.cos(roll) * level_up + math.sin(roll) * np.cross(forward, level_up)
    return CameraPose(origin, target, (float(up[0]), float(up[1]), float(up[2])), FOV_DEG)


def smooth_texture(seed: int, side: int) -> np.ndarray:
    """Blurred noise at three scales, positive like a photo's linear luminance. Shape: ``(side, side)``."""
    rng = np.random.default_rng(seed)
    noise = np.sum(
        [
            sigma * cv2.GaussianBlur(rng.standard_normal((side, side)).astype(np.float32), (0, 0), sigma)
            for sigma in (2.0, 5.0, 12.0)
        ],
        axis=0,
    )
    normalised = (noise - noise.mean()) / noise.std()
    return (0.1 * np.exp(0.4 * normalised)).astype(np.float32)


def photograph(texture: np.ndarray, texture_to_photo: np.ndarray, width: int, height: int) -> np.ndarray:
    """The texture warped by a homography in project pixels, 3×3 supersampled and box-filtered
    (the project's pixel edges scale exactly). Shape: ``(height, width)``."""
    factor = 3
    scaled = np.diag([factor, factor, 1.0]) @ texture_to_photo
    fine = cv2.warpPerspective(
        texture, to_opencv_homography(scaled), (width * factor, height * factor), flags=cv2.INTER_LINEAR
    )
    return cv2.resize(fine, (width, height), interpolation=cv2.INTER_AREA)


def with_flash(grey: np.ndarray, centre: tuple[float, float]) -> np.ndarray:
    """A flash photo: a broad falloff and a clipped highlight at ``centre``, tinted RGB, clipped
    at 1 like an 8-bit file. Shape: ``(H, W)`` → ``(H, W, 3)``."""
    height, width = grey.shape
    ys, xs = np.mgrid[0:height, 0:width] + 0.5
    distance2 = (xs - centre[0]) ** 2 + (ys - centre[1]) ** 2
    lit = grey * (1.0 + np.exp(-distance2 / (2.0 * (0.35 * width) ** 2))) + 6.0 * np.exp(
        -distance2 / (2.0 * 14.0**2)
    )
    return np.clip(np.stack([0.9 * lit, lit, 1.1 * lit], axis=-1), 0.0, 1.0).astype(np.float32)


def grey_of(rgb: np.ndarray) -> np.ndarray:
    """Linear luminance. Shape: ``(H, W, 3)`` → ``(H, W)``."""
    return luminance(torch.from_numpy(rgb).permute(2, 0, 1))[0].numpy()


@pytest.fixture(scope="module")
def texture() -> np.ndarray:
    return smooth_texture(0, TEXTURE_SIDE)


def view_of(texture: np.ndarray, pose: CameraPose) -> np.ndarray:
    return photograph(
        texture, pose_homography(pose, WIDTH, HEIGHT, PLANE_HALF_SIZE, TEXTURE_SIDE), WIDTH, HEIGHT
    )


def reference_to_view(pose: CameraPose) -> np.ndarray:
    """The true homography from the reference photo's pixels to the photo of ``pose``."""
    texture_to_reference = pose_homography(REFERENCE, WIDTH, HEIGHT, PLANE_HALF_SIZE, TEXTURE_SIDE)
    texture_to_view = pose_homography(pose, WIDTH, HEIGHT, PLANE_HALF_SIZE, TEXTURE_SIDE)
    return texture_to_view @ np.linalg.inv(texture_to_reference)


def test_half_pixel_convention_round_trips_and_matches_opencv_projection() -> None:
    points = np.array([[0.0, 0.0], [0.5, 0.5], [479.25, 359.75]])
    np.testing.assert_allclose(to_opencv_px(points), points - 0.5)
    np.testing.assert_allclose(from_opencv_px(to_opencv_px(points)), points)
    homography = np.array([[1.1, 0.05, 3.0], [-0.04, 0.95, -2.0], [1e-4, -2e-4, 1.0]])
    np.testing.assert_allclose(from_opencv_homography(to_opencv_homography(homography)), homography)
    # The converted homography does to OpenCV pixels what the original does to ours.
    np.testing.assert_allclose(
        apply_homography(to_opencv_homography(homography), to_opencv_px(points)),
        to_opencv_px(apply_homography(homography, points)),
    )
    # intrinsics + OpenCV's projection of a tilted, rolled camera = the renderer's projection − ½.
    pose = look_at((0.4, -0.3, 1.2), (0.1, 0.05, 0.0), 20.0)
    right, up, forward = camera_frame(pose)
    rotation = np.stack([right, -up, forward])
    world = np.array([[0.1, 0.2, 0.0], [-0.3, 0.1, 0.0], [0.25, -0.2, 0.0]])
    opencv, _ = cv2.projectPoints(
        world,
        cv2.Rodrigues(rotation)[0],
        -rotation @ np.asarray(pose.origin),
        intrinsics(FOV_DEG, WIDTH, HEIGHT),
        None,
    )
    np.testing.assert_allclose(
        opencv.reshape(-1, 2), to_opencv_px(project_to_image(world, pose, WIDTH, HEIGHT)), atol=1e-9
    )
    shifted = np.array([[1.0, 0.0, 0.3], [0.0, 1.0, 0.4], [0.0, 0.0, 1.0]])
    assert homography_error_px(np.eye(3), shifted, WIDTH, HEIGHT) == pytest.approx(0.5)


def test_pose_homography_follows_the_renderers_texels() -> None:
    side = 64
    # The nominal camera frames the square exactly: texel (i, j) is pixel (i, j).
    nominal = pose_homography(nominal_camera(FOV_DEG, 2.0), side, side, 2.0, side)
    np.testing.assert_allclose(nominal / nominal[2, 2], np.eye(3), atol=1e-9)
    # A tilted view: each pixel centre's ray meets the plane where the inverse homography says.
    pose = look_at((0.3, -0.4, 2.0), (0.1, 0.0, 0.0), 30.0)
    homography = pose_homography(pose, 40, 30, 1.0, side)
    pixel_centres = np.stack(np.meshgrid(np.arange(40) + 0.5, np.arange(30) + 0.5), axis=-1).reshape(-1, 2)
    texels = apply_homography(np.linalg.inv(homography), pixel_centres)
    np.testing.assert_allclose(
        apply_homography(texel_to_plane(1.0, side), texels),
        view_plane_points(pose, 30, 40).reshape(-1, 2),
        atol=1e-9,
    )


@pytest.mark.parametrize(("detector", "bound_px"), [("sift", 0.15), ("orb", 1.0)])
def test_features_recover_known_homographies_with_the_flash_masked(
    texture: np.ndarray, detector: Detector, bound_px: float
) -> None:
    # The issue asks for 0.5 px. SIFT measures 0.015–0.07 px here; its bound is tight enough to
    # catch a quarter-pixel keypoint bias (0.25 px without precise upscaling). ORB's FAST corners
    # are whole pixels: 0.2–0.7 px.
    reference = with_flash(view_of(texture, REFERENCE), FLASH_CENTRES[0])
    reference_mask = highlight_mask(reference)
    for (origin, target, roll), flash in zip(VIEW_PLACES, FLASH_CENTRES[1:], strict=True):
        pose = look_at(origin, target, roll)
        view = with_flash(view_of(texture, pose), flash)
        view_mask = highlight_mask(view)
        registration = feature_homography(
            grey_of(reference), grey_of(view), reference_mask, view_mask, detector
        )
        assert registration is not None and registration.method == detector
        error = homography_error_px(registration.homography, reference_to_view(pose), WIDTH, HEIGHT)
        assert error < bound_px, f"{detector} view at {origin}: {error:.3f} px"
        assert check_registration(registration, FULL_FRAME, WIDTH, HEIGHT) is None
        for mask, points in (
            (reference_mask, registration.source_points),
            (view_mask, registration.view_points),
        ):
            columns, rows = np.floor(points).astype(int).T
            assert not mask[rows, columns].any()


def test_highlight_mask_covers_the_flash_and_keeps_keypoints_off_it(texture: np.ndarray) -> None:
    centre = FLASH_CENTRES[1]
    view = with_flash(view_of(texture, REFERENCE), centre)
    mask = highlight_mask(view)
    assert mask.dtype == np.uint8 and mask.shape == (HEIGHT, WIDTH)
    assert mask[int(centre[1]), int(centre[0])] == 255
    clipped: np.ndarray = np.any(view >= 0.99, axis=-1)
    assert clipped.any() and not clipped[mask == 0].any()  # every clipped pixel is masked
    assert (mask > 0).mean() < 0.05  # and not much more than the highlight
    tensor_mask = highlight_mask(torch.from_numpy(view).permute(2, 0, 1))
    np.testing.assert_array_equal(tensor_mask, mask)

    def inside(points: np.ndarray) -> int:
        columns, rows = np.floor(points).astype(int).T
        return int((mask[rows, columns] > 0).sum())

    unmasked, _ = detect_features(grey_of(view), None)
    masked, _ = detect_features(grey_of(view), mask)
    assert inside(unmasked) > 0
    assert inside(masked) == 0 and len(masked) > 1000


def test_a_large_view_is_registered_on_a_reduced_copy(texture: np.ndarray) -> None:
    # 2000 px on the long side: SIFT runs at 1600 (a factor 0.8) and the points come back to
    # full size exactly (measured 0.10 px in the large view's pixels).
    width, height = 2000, 1500
    pose = look_at(*VIEW_PLACES[1])
    texture_to_view = pose_homography(pose, width, height, PLANE_HALF_SIZE, TEXTURE_SIDE)
    view = photograph(texture, texture_to_view, width, height)
    registration = feature_homography(view_of(texture, REFERENCE), view)
    assert registration is not None
    truth = texture_to_view @ np.linalg.inv(
        pose_homography(REFERENCE, WIDTH, HEIGHT, PLANE_HALF_SIZE, TEXTURE_SIDE)
    )
    assert homography_error_px(registration.homography, truth, WIDTH, HEIGHT) < 0.2
    # About 4 view pixels per reference pixel, yet the same framing of the surface.
    assert check_registration(registration, FULL_FRAME, width, height) is not None
    assert check_registration(registration, FULL_FRAME, width, height, reference_size=(WIDTH, HEIGHT)) is None


def test_a_different_surface_is_rejected(texture: np.ndarray) -> None:
    reference = view_of(texture, REFERENCE)
    pose = look_at(*VIEW_PLACES[0])
    other = photograph(
        smooth_texture(7, TEXTURE_SIDE),
        pose_homography(pose, WIDTH, HEIGHT, PLANE_HALF_SIZE, TEXTURE_SIDE),
        WIDTH,
        HEIGHT,
    )
    detectors: tuple[Detector, ...] = ("sift", "orb")
    for detector in detectors:
        registration = feature_homography(reference, other, detector=detector)
        assert registration is None or check_registration(registration, FULL_FRAME, WIDTH, HEIGHT) is not None


def board_texture() -> np.ndarray:
    """MaterialGAN's board: white paper, tags 0–15 drawn by ``cv2.aruco``, a textured window
    inside. Shape: ``(BOARD_TEXTURE_SIDE,) * 2`` over ``[-12, 12]²`` cm."""
    texels_per_cm = BOARD_TEXTURE_SIDE / (2.0 * BOARD_PLANE_HALF_SIZE)
    board = np.full((BOARD_TEXTURE_SIDE, BOARD_TEXTURE_SIDE), 0.8, dtype=np.float32)
    window = slice(
        round(BOARD_TEXTURE_SIDE / 2 - 6 * texels_per_cm), round(BOARD_TEXTURE_SIDE / 2 + 6 * texels_per_cm)
    )
    board[window, window] = smooth_texture(3, BOARD_TEXTURE_SIDE)[window, window]
    dictionary = cv2.aruco.getPredefinedDictionary(MATERIALGAN_BOARD.dictionary)
    to_texels = np.linalg.inv(texel_to_plane(BOARD_PLANE_HALF_SIZE, BOARD_TEXTURE_SIDE))
    for tag, corners in MATERIALGAN_BOARD.corners_cm(BOARD_CM).items():
        (left, top), _, (right, bottom), _ = np.rint(apply_homography(to_texels, corners)).astype(int)
        tag_image = cv2.aruco.generateImageMarker(dictionary, tag, right - left, borderBits=1)
        board[top:bottom, left:right] = 0.04 + 0.76 * tag_image.astype(np.float32) / 255.0
    return board


@pytest.mark.parametrize(
    "pose",
    [
        look_at((4.0, -3.0, 30.0), (0.5, 0.3, 0.0), 15.0),
        look_at((-9.0, 5.0, 28.0), (0.0, 0.0, 0.0), -30.0),
        look_at((10.0, 8.0, 26.0), (1.0, 1.0, 0.0), 170.0),
    ],
)
def test_marker_board_gives_the_homography_and_the_camera(pose: CameraPose) -> None:
    photo = photograph(
        board_texture(),
        pose_homography(pose, MARKER_WIDTH, MARKER_HEIGHT, BOARD_PLANE_HALF_SIZE, BOARD_TEXTURE_SIDE),
        MARKER_WIDTH,
        MARKER_HEIGHT,
    )
    registration = marker_homography(photo, BOARD_CM)
    assert registration is not None and registration.method == "marker"
    assert registration.inliers >= 56  # 14 of the 16 tags at least
    # Measured 0.10–0.14 px over MaterialGAN's texture square (the centred 0.64·size); half a
    # pixel off the convention would show as about 0.5.
    texture_square = texel_to_plane(0.32 * BOARD_CM, 512)
    truth = plane_homography(pose, MARKER_WIDTH, MARKER_HEIGHT)
    error = homography_error_px(registration.homography @ texture_square, truth @ texture_square, 512, 512)
    assert error < 0.25
    window = 0.32 * BOARD_CM * np.array([[-1.0, 1.0], [1.0, 1.0], [1.0, -1.0], [-1.0, -1.0]])
    assert check_registration(registration, window, MARKER_WIDTH, MARKER_HEIGHT) is None

    camera_matrix = intrinsics(FOV_DEG, MARKER_WIDTH, MARKER_HEIGHT)
    estimate, reprojection_px, _ = pose_from_plane_points(
        registration.source_points, registration.view_points, camera_matrix
    )
    distance = float(np.linalg.norm(np.subtract(pose.origin, pose.target)))
    assert np.linalg.norm(np.subtract(estimate.origin, pose.origin)) < 0.01 * distance
    assert reprojection_px < 0.5
    assert estimate.fov_deg == pytest.approx(FOV_DEG)
    for estimated, true in zip(camera_frame(estimate), camera_frame(pose), strict=True):
        assert float(estimated @ true) > math.cos(math.radians(1.0))


def test_apriltag_corners_come_in_pixel_edge_coordinates() -> None:
    # marker_homography takes CORNER_REFINE_APRILTAG's corners without the half-pixel shift the
    # other refinements need: a tag filling pixels 70…149 × 50…129 has its corners on those edges.
    dictionary = cv2.aruco.getPredefinedDictionary(MATERIALGAN_BOARD.dictionary)
    image = np.full((200, 220), 220, dtype=np.uint8)
    image[50:130, 70:150] = np.where(
        cv2.aruco.generateImageMarker(dictionary, 3, 80, borderBits=1) > 0, 220, 20
    )
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
    corners, ids, _ = cv2.aruco.ArucoDetector(dictionary, parameters).detectMarkers(image)
    assert ids is not None and ids.ravel().tolist() == [3]
    np.testing.assert_allclose(
        corners[0].reshape(4, 2), [[70, 50], [150, 50], [150, 130], [70, 130]], atol=0.05
    )


def test_pose_from_plane_points_picks_the_physical_ippe_solution() -> None:
    rng = np.random.default_rng(0)
    plane_xy = rng.uniform(-8.0, 8.0, (40, 2))
    world = np.concatenate([plane_xy, np.zeros((40, 1))], axis=1)
    camera_matrix = intrinsics(FOV_DEG, MARKER_WIDTH, MARKER_HEIGHT)
    # A clearly tilted view: IPPE's other pose reprojects about 13 px worse; the true one is kept.
    tilted = look_at((12.0, 0.0, 25.0), (1.0, 1.0, 0.0), 10.0)
    image = project_to_image(world, tilted, MARKER_WIDTH, MARKER_HEIGHT)
    estimate, reprojection_px, ambiguous = pose_from_plane_points(plane_xy, image, camera_matrix)
    np.testing.assert_allclose(estimate.origin, tilted.origin, atol=1e-4)
    assert reprojection_px < 1e-3 and not ambiguous
    _, rotations, translations, errors = cv2.solvePnPGeneric(
        world, to_opencv_px(image), camera_matrix, None, flags=cv2.SOLVEPNP_IPPE
    )
    origins = [-cv2.Rodrigues(r)[0].T @ t.ravel() for r, t in zip(rotations, translations, strict=True)]
    assert max(np.linalg.norm(origin - tilted.origin) for origin in origins) > 5.0  # there was a choice
    assert np.ravel(errors).max() > 10.0
    # Seen from below (a mirrored photo) no pose is physical.
    with pytest.raises(ValueError, match="mirrored"):
        pose_from_plane_points(plane_xy * np.array([-1.0, 1.0]), image, camera_matrix)
    # Nearly fronto-parallel with 0.3 px of noise: both poses fit about as well, which is flagged.
    frontal = look_at((0.5, 0.2, 30.0), (1.0, 1.0, 0.0), 0.0)
    noisy = project_to_image(world, frontal, MARKER_WIDTH, MARKER_HEIGHT) + rng.normal(0.0, 0.3, (40, 2))
    _, _, ambiguous = pose_from_plane_points(plane_xy, noisy, camera_matrix)
    assert ambiguous


def registration_with(
    homography: np.ndarray, *, inliers: int = 500, ratio: float = 0.9, method: Method = "sift"
) -> Registration:
    return Registration(homography, method, inliers, ratio, 0.3, np.zeros((0, 2)), np.zeros((0, 2)))


def test_check_registration_gives_one_line_reasons() -> None:
    turned = np.array([[0.95, -0.2, 30.0], [0.2, 0.95, -10.0], [1e-5, 2e-5, 1.0]])
    assert check_registration(registration_with(turned), FULL_FRAME, WIDTH, HEIGHT) is None
    assert (
        check_registration(registration_with(-turned), FULL_FRAME, WIDTH, HEIGHT) is None
    )  # the sign is arbitrary
    reasons = {
        "few": check_registration(registration_with(turned, inliers=12), FULL_FRAME, WIDTH, HEIGHT),
        "ratio": check_registration(registration_with(turned, ratio=0.1), FULL_FRAME, WIDTH, HEIGHT),
        "mirror": check_registration(registration_with(np.diag([-1.0, 1.0, 1.0])), FULL_FRAME, WIDTH, HEIGHT),
        "scale": check_registration(registration_with(np.diag([4.0, 4.0, 1.0])), FULL_FRAME, WIDTH, HEIGHT),
        "outside": check_registration(
            registration_with(np.array([[1.0, 0.0, 400.0], [0.0, 1.0, 300.0], [0.0, 0.0, 1.0]])),
            FULL_FRAME,
            WIDTH,
            HEIGHT,
        ),
    }
    for name, reason in reasons.items():
        assert reason is not None and "\n" not in reason, name
    assert "12 matches" in str(reasons["few"]) and "mirrored" in str(reasons["mirror"])
    assert "4.00×" in str(reasons["scale"]) and "3%" in str(reasons["outside"])
    # A board (+y up) seen by a camera: orientation reverses and px/cm is no scale change.
    board_view = plane_homography(
        look_at((4.0, -3.0, 30.0), (0.0, 0.0, 0.0), 15.0), MARKER_WIDTH, MARKER_HEIGHT
    )
    window = 5.0 * np.array([[-1.0, 1.0], [1.0, 1.0], [1.0, -1.0], [-1.0, -1.0]])
    marker = registration_with(board_view, inliers=64, method="marker")
    assert check_registration(marker, window, MARKER_WIDTH, MARKER_HEIGHT) is None
