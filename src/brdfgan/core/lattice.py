"""Pattern-true tiling (``brdfgan predict --tileable``): whether a map set repeats on a 2-D lattice,
its two lattice vectors, and a tile made of whole lattice cells.

Tiles, bricks, pavers and mosaics repeat a cell. A minimum-error cut (:mod:`brdfgan.core.seamless`)
joins copies wherever they agree and so can join half a tile to half a tile; tiling by whole
periods keeps every cell whole (Rodriguez-Pardo, Suja & Garces 2019, "Automatic extraction and
synthesis of regular repeatable patterns"). The steps:

1. **Features** (:func:`pattern_features`): the base colour's luminance and the normal's two
   slopes, the pattern an artist sees and its relief, each with a quadratic trend (shading) removed.
2. **Autocorrelation** (:func:`autocorrelation`): per feature group (colour, relief) the linear
   autocorrelation through a zero-padded FFT of the mean-free features under a Tukey window,
   divided by the window's own (an unbiased estimate at every lag) and by its value at lag 0; the
   groups averaged. ``ρ(l) = 1`` where the maps shifted by ``l`` equal themselves.
3. **Lattice** (:func:`find_lattice`): a lattice vector is a local maximum of ρ that stands above
   the ring around it (:func:`peak_prominence`). That is what separates a 2-D lattice from a 1-D
   pattern: stripes, planks and wood grain have *ridges* in ρ (ρ stays high along the stripes), so
   every point of a ridge has a ring as high as itself. The shortest prominent peak is ``a``, the
   shortest prominent one at an angle to it ``b``; the pair is Lagrange–Gauss reduced
   (:func:`reduce_basis`) and refined by least squares over the sub-pixel positions (parabolic
   interpolation) of the peaks at the small integer combinations ``i·a + j·b``
   (:func:`refine_lattice`), which averages the broadened peaks of a photo in mild perspective.
   The lattice is accepted when its *score*, the least prominence among the peaks at ``a``, ``b``
   and the combinations ``a ± b``, ``2a``, ``2b`` that the maps are large enough to show (at least
   one of them), reaches :data:`PROMINENCE_THRESHOLD`: a spurious pair of noise maxima has no peak
   at its sum. The lattice is read from both groups' ρ, and again from each group's alone: where
   one group alone is periodic and scores at least :data:`ONE_GROUP_FACTOR` times both together,
   the other group only blurs the lattice's peaks (a scanned checkerboard of marble whose relief is
   each slab's own: both together 0.7 % off square-on and nothing found at 15° and 30°; its colour
   alone within 0.2 % at every angle), and that group is the lattice's :attr:`Lattice.features`,
   which the perspective's windows, the cells' match and their closure read too.
3b. **Mild perspective** (:func:`find_perspective`, :func:`rectify`): a phone tilted by a degree or
   two shrinks the cells towards one side, so whole periods at the centre are off by a pixel or
   more at the wraps. The lattice is refined again in a 3 × 3 grid of overlapping windows (each
   the smallest share of the side, from 1/2 to 3/4, that holds two cells), and a homography about
   the centre, ``q = d / (1 + g·d)`` (the Jacobian at the centre the identity), is fitted to how
   the windows' vectors change: to first order the vector seen at offset ``d`` is
   ``m + (v dᵀ + d vᵀ) g`` (:func:`fit_perspective`). Where it explains the windows (their spread
   at most halved; else once more without the one window that holds it back most; else in the
   largest windows, of 3/4 of the side) with a keystone of 0.25-10 %, the maps are resampled
   through it and the rest runs on the rectified maps. A lattice whose score falls just short
   (:attr:`Lattice.ambiguous`) is tried too: perspective broadens the peaks of ρ (a 6 % keystone
   takes a clear lattice from 0.49 to 0.09), and the rectified maps, scored again, decide. Where
   the whole maps show no lattice at all, their central half is tried (:func:`central_lattice`):
   the scale varies half as much across it, so the far peaks perspective smears across the whole
   maps stay sharp there (a scanned tile grid turned 30° under a 2 % keystone scores −0.07 whole
   and 0.18 in its centre); its lattice only seeds the perspective, and again the rectified maps
   decide. The perspective is then measured once more on the rectified maps
   (:func:`refine_perspective`), and what is left is added. Where no window can hold two cells (a
   checkerboard of marble slabs, two periods a crop), or the windows saw a keystone they could not
   agree on, the homography is fitted to the whole maps instead (:func:`fit_self_match`): the ``g``
   and central lattice vectors that make the maps, seen through it, match themselves best one
   lattice vector on (the mean squared difference of the detrended features at ``q`` and
   ``q ± a``, ``q ± b``), by L-BFGS, coarse to fine; kept where it leaves at most
   :data:`SELF_MATCH_GAIN` of the residual without it, with a keystone of 0.25-10 %.
4. **Whole cells** (:func:`choose_cells`): integer combinations ``u = m₁a + n₁b`` (about
   horizontal) and ``v = m₂a + n₂b`` (about vertical) spanning a parallelogram that fits in the
   maps, the largest with the least stretch and turn; with ``align`` the frame is turned so that the
   lattice's own direction nearest an axis becomes that axis (the pattern is rectified). A coarse
   lattice (bricks two to a crop) may have no such tile with room for the seam's margin around
   it; it then takes the largest of at most the maps' area, and what it reaches beyond the maps
   (its margin, a turned tile's corners) is fetched (step 5).
4b. **Closure** (:func:`close_cells`): the lattice is measured to a fraction of a per cent, but a
   tile spans many cells, so 0.5 % becomes a step of a pixel or more where the wrap joins the
   tile's last cell to its first (a checkerboard of two periods a crop: 2.7-4.9 px). ``u`` and
   ``v`` themselves are measured instead: each moves to the sub-pixel shift, within
   :data:`CLOSURE_REACH` pixels, at which the maps best match themselves (the normalised
   correlation of the detrended pattern features over the overlap, a parabola through the best
   whole shift and its neighbours). That is the shift the wrap makes, so the wrap closes whatever
   the lattice's precision. Moved only where the match is a clear peak (at least
   :data:`CLOSURE_MIN_CORRELATION`) inside the search, at least :data:`CLOSURE_MIN_MOVE` pixels
   away, and the cells still fit with their margin.
5. **Resample** (:func:`sample_cells`): the affine map taking ``u`` to ``(W, 0)`` and ``v`` to
   ``(0, H)`` samples the maps (bilinear, ``grid_sample``; normals renormalised), a margin of whole
   pixels beyond each edge included. The result repeats by whole periods: its wrap joins a cell to
   the same cell one period on. A sample that falls outside the maps (a fetched margin) is taken
   from the same place in the nearest cell inside them: moved by the shortest lattice vector
   ``i·a + j·b`` that brings it in, a neighbouring cell rather than the tile's own opposite edge,
   so that the residual seam still has two copies to choose between.
6. **Residual seam** (:func:`cut_wrap`): where the photo is not perfectly periodic (stains, grain,
   shading, perspective) the wrap still shows a step. Across it the tile may take either the pixel
   or the pixel one period ``u`` (``v``) on, sampled from the photo in the margin: the two agree
   in the pattern, so a minimum-error path between them (the seam cut's own
   :func:`~brdfgan.core.seamless.min_error_path` and :func:`~brdfgan.core.seamless.seam_cost`)
   moves the seam where the rest agrees too, and the lattice stays whole. Today's cut, which
   rolls the maps by about half a side, would shift the pattern by a fraction of a cell instead.
7. **Roll** (:func:`tile_whole_cells`): the tile now repeats without a seam, so rolling it is a
   shift of the whole tiling and keeps every cell. As today's cut does, the quietest step in the
   middle half of each axis (:func:`~brdfgan.core.seamless.quiet_cut`) becomes the tile's wrap, and
   the residual seams move inside.

**1-D patterns are not periodic here.** Stripes, planks and wood grain repeat along one direction
only: ρ has a ridge, no isolated peak, and :func:`find_lattice` reports no lattice. Such maps are
tiled by whole periods across their stripes (:mod:`brdfgan.core.stripes`, with this module's
cells, closure, seam and roll).

Lattice vectors are ``(dx, dy)`` in pixels of the maps, ``x`` to the right, ``y`` down (rows).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor

from brdfgan.core.checks import check_shape
from brdfgan.core.exposure import luminance
from brdfgan.core.filtering import gaussian_blur
from brdfgan.core.seamless import (
    COPY_TOLERANCE,
    FEATHER,
    MAP_GROUPS,
    MAP_NAMES,
    TilingMeasures,
    file_units,
    map_scales,
    min_error_path,
    quiet_cut,
    seam_cost,
    wrap_ratios,
)
from brdfgan.core.svbrdf import check_single_maps, join_maps, normalize_normal, split_maps

Vector = tuple[float, float]

# Feature channels (pattern_features) and their groups: colour (luminance) and relief (slopes).
FEATURE_GROUPS = (1, 2)
# The groups a lattice can be read from (module docstring, step 3): both, or either alone where
# only it repeats (a scanned checkerboard of marble whose relief is each slab's own).
FEATURE_CHOICES: dict[str, tuple[int, ...]] = {"colour and relief": (0, 1), "colour": (0,), "relief": (1,)}
ALL_FEATURES = "colour and relief"
ONE_GROUP_FACTOR = 2.0
# A feature group whose detrended energy per pixel is below this square (a constant map, a flat
# normal map) carries no pattern: it is left out instead of normalising its noise up to weight 1.
FEATURE_FLOOR = 1e-3
# Normals tilted beyond this z are clamped before their slope is taken (|slope| ≤ ~20).
MIN_NORMAL_Z = 0.05
# Detection runs on the features shrunk to at most this side (area averaging): the FFT grows with
# the padded area, and what it loses at 2048² is periods under 2 × MIN_PERIOD, texture anyway.
DETECT_SIDE = 1024
# The Tukey window's tapered fraction (half at each end): enough to keep the image's border out of
# the estimate without starving the large lags a lattice of two periods per side needs.
WINDOW_TAPER = 0.2
# Lags whose overlap (the fraction of pixels that have a partner at that shift) is below this are
# too noisy for a lattice vector; combinations are checked down to CHECK_OVERLAP.
MIN_OVERLAP = 0.25
CHECK_OVERLAP = 0.1
# Periods shorter than this (pixels at detection size) are texture, not a pattern (at 4 px a scanned
# tile's grain, resampled at 45° in perspective, made a 3.7 px peak that hid its 64 px lattice).
MIN_PERIOD = 6.0
# A lattice peak's height in ρ at least this; candidates are the strongest MAX_CANDIDATES maxima.
MIN_PEAK = 0.15
MAX_CANDIDATES = 400
# The ring on which a peak's prominence is measured: this fraction of the shorter lattice vector
# (away from the neighbouring lattice points, outside a peak's core), at least MIN_RING pixels.
RING_FRACTION = 0.3
MIN_RING = 2.0
# The score (the weakest lattice peak's prominence: its height minus the ring's highest point) a
# lattice needs. Measured: blurred noise at most 0.09 in 240 draws (192², grain 1.5–10 px), stripes
# and wood grain ≤ 0; synthetic tiles and bricks 0.24–0.51 (0.12 at 8 % perspective); the ceramic
# sample 0.19 (tests/core/test_lattice.py).
PROMINENCE_THRESHOLD = 0.1
# Candidates are picked from half the threshold, so that a weak lattice is scored, not missed.
SELECT_FRACTION = 0.5
# Among the candidates that stand out, the shortest within this fraction of the best prominence.
RELATIVE_PROMINENCE = 0.5
# A score within this factor of the threshold is ambiguous: a note says which path was taken.
AMBIGUITY_FACTOR = 1.5
# The two vectors at least this far from parallel (degrees).
MIN_ANGLE_DEG = 20.0
# A lattice point is searched within this fraction of the shorter vector around its prediction;
# the refinement fits peaks that reach COMBINATION_LEVEL × the weaker of the two vectors' peaks.
SEARCH_FRACTION = 0.15
COMBINATION_LEVEL = 0.5
# Refinement fits the peaks at i·a + j·b with |i|, |j| ≤ REFINE_ORDER (the 2–3 nearest per vector).
REFINE_ORDER = 2
# Whole cells: the tile's edges turn at most MAX_TURN_DEG from the frame's axes; the choice pays
# STRETCH_WEIGHT per unit of log-anisotropy and TURN_WEIGHT per radian of turn against the log of
# the area kept (1 % stretch is worth ~3 % area: shapes matter more than resolution).
MAX_TURN_DEG = 15.0
STRETCH_WEIGHT = 3.0
TURN_WEIGHT = 1.0
# Combinations tried per vector at most; of the candidates for each edge, the least turned of each
# length (bins of LENGTH_STEP in the log: 1 %) is paired with those of the other.
MAX_COUNT = 512
LENGTH_STEP = 0.01
# A tile stretching shapes more than this (log-anisotropy, ~16 %) is not used: the maps keep the cut.
MAX_STRETCH = 0.15
# The residual seam's band: up to MAX_MARGIN of the side beyond each edge (as much as the photo
# has), at least MIN_MARGIN of it and MIN_BAND output pixels; a cell that leaves less room is not
# used (the path needs room to find where the copies agree).
MAX_MARGIN = 1.0 / 16.0
MIN_MARGIN = 1.0 / 32.0
MIN_BAND = 4
# Cells whose margin is fetched (choose_cells' second pass) hold at most this share of the maps'
# area, and neither edge spans more than the maps' side along an axis: a larger tile would hold
# the same photographed cell twice over (tried at 1.5 sides: bricks at 0° then took a stretched
# tile and lost whole cells, 100 → 81-95 %).
FETCH_AREA = 1.0
# A lattice measured a per cent long makes a tile of exactly the maps' area a little larger.
AREA_TOLERANCE = 0.02
# Closure (close_cells): the tile's edges are searched this many pixels (at most a quarter of the
# shorter lattice vector) around the lattice's combinations, on features of at most DETECT_SIDE,
# and moved where the maps match themselves with at least this correlation.
CLOSURE_REACH = 3
CLOSURE_MIN_CORRELATION = 0.5
# Cells that match each other less than this one lattice vector on (cell_match) are no pattern to
# keep whole: where the maps have stripes, make_tileable tiles by them instead.
MIN_CELL_MATCH = 0.4
# … and moved only where the match lies at least this far (pixels) from them: the lattice's own
# refinement, over many peaks, is more precise than one correlation peak (measured: a closure of
# every tile took exact lattices' wrap steps from ~0.1 px to up to 0.9 px).
CLOSURE_MIN_MOVE = 0.5


@dataclass(frozen=True)
class Lattice:
    """What :func:`find_lattice` found: the reduced lattice vectors ``(dx, dy)`` in pixels
    (``a`` the shorter; ``None`` where no candidate pair was found), the score (the weakest lattice
    peak's prominence in the autocorrelation; 0 without vectors, or where the maps show too few
    periods to check), whether the maps count as periodic, the method, and a note on the decision."""

    vectors: tuple[Vector, Vector] | None
    score: float
    periodic: bool
    method: str = "autocorrelation"
    notes: str = ""
    features: str = ALL_FEATURES  # the feature groups it was read from (FEATURE_CHOICES)

    @property
    def ambiguous(self) -> bool:
        """Whether the score is within :data:`AMBIGUITY_FACTOR` of the threshold either way."""
        return (
            self.vectors is not None
            and PROMINENCE_THRESHOLD / AMBIGUITY_FACTOR
            <= self.score
            <= PROMINENCE_THRESHOLD * AMBIGUITY_FACTOR
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "vectors": None if self.vectors is None else [list(vector) for vector in self.vectors],
            "score": self.score,
            "threshold": PROMINENCE_THRESHOLD,
            "periodic": self.periodic,
            "method": self.method,
            "notes": self.notes,
            "features": self.features,
        }

    @classmethod
    def from_json(cls, record: dict[str, Any]) -> Lattice:
        vectors = record["vectors"]
        return cls(
            vectors=None if vectors is None else (_vector(vectors[0]), _vector(vectors[1])),
            score=float(record["score"]),
            periodic=bool(record["periodic"]),
            method=str(record["method"]),
            notes=str(record["notes"]),
            # A record from before the choice of features read both groups.
            features=str(record.get("features", ALL_FEATURES)),
        )


def _vector(values: Sequence[float]) -> Vector:
    """Shape: two numbers → ``(dx, dy)`` floats."""
    return (float(values[0]), float(values[1]))


def pattern_features(maps: Tensor) -> Tensor:
    """The channels a pattern shows in: the base colour's luminance (of its sRGB values, as a
    texture shows them) and the normal's slopes ``(nx / nz, ny / nz)`` (the relief's gradient).

    Shape: ``(8, H, W)`` → ``(3, H, W)`` (groups :data:`FEATURE_GROUPS`).
    """
    check_single_maps(maps)
    parts = split_maps(maps)
    slopes = parts.normal[:2] / parts.normal[2:].clamp_min(MIN_NORMAL_Z)
    return torch.cat([luminance(parts.basecolor), slopes])


def detection_features(maps: Tensor) -> tuple[Tensor, Tensor]:
    """:func:`pattern_features` area-averaged to at most :data:`DETECT_SIDE` a side, float64, and
    the factor ``(x, y)`` from their pixels to the maps' (1 where they were not shrunk).

    Shape: ``(8, H, W)`` → ``(3, h, w)``, ``(2,)``.
    """
    return area_shrink(pattern_features(maps.detach().double()), DETECT_SIDE)


def area_shrink(image: Tensor, side: int) -> tuple[Tensor, Tensor]:
    """``image`` area-averaged to at most ``side`` pixels a side (as it is where it is no larger),
    and the factor ``(x, y)`` from its new pixels to its old ones (1 where it was not shrunk).

    Shape: ``(C, H, W)`` → ``(C, h, w)``, ``(2,)`` float64.
    """
    height, width = image.shape[-2:]
    scale = max(height, width) / side
    if scale > 1.0:
        size = (max(1, round(height / scale)), max(1, round(width / scale)))
        image = F.interpolate(image[None], size=size, mode="area")[0]
    small_h, small_w = image.shape[-2:]
    return image, torch.tensor([width / small_w, height / small_h], dtype=torch.float64)


def feature_groups(features: Tensor, choice: str) -> tuple[Tensor, tuple[int, ...]]:
    """The channels of the feature groups ``choice`` names (:data:`FEATURE_CHOICES`) and their
    group sizes, for :func:`autocorrelation`. Shape: ``(3, H, W)`` → ``(C, H, W)``."""
    if choice not in FEATURE_CHOICES:
        raise ValueError(f"unknown pattern features {choice!r}: one of {', '.join(FEATURE_CHOICES)}")
    starts = [sum(FEATURE_GROUPS[:index]) for index in range(len(FEATURE_GROUPS))]
    chosen = FEATURE_CHOICES[choice]
    channels = [c for group in chosen for c in range(starts[group], starts[group] + FEATURE_GROUPS[group])]
    return features[channels], tuple(FEATURE_GROUPS[group] for group in chosen)


def _detrend(features: Tensor) -> Tensor:
    """Each channel minus its least-squares quadratic in ``(x, y)``: the shading and vignetting a
    photo's maps keep would otherwise dominate ρ at every lag. Shape: ``(C, H, W)`` → same."""
    channels, height, width = features.shape
    y = torch.linspace(-1.0, 1.0, height, dtype=features.dtype, device=features.device)
    x = torch.linspace(-1.0, 1.0, width, dtype=features.dtype, device=features.device)
    yy, xx = torch.meshgrid(y, x, indexing="ij")
    basis = torch.stack([torch.ones_like(xx), xx, yy, xx * xx, xx * yy, yy * yy]).view(6, -1)
    values = features.reshape(channels, -1)
    coefficients = torch.linalg.lstsq(basis.T, values.T).solution  # (6, C)
    return (values - (basis.T @ coefficients).T).view(channels, height, width)


def _tukey(length: int, like: Tensor) -> Tensor:
    """A Tukey window: 1 in the middle, cosine tapers over :data:`WINDOW_TAPER`/2 at each end.
    Shape: ``length`` → ``(length,)`` in ``like``'s dtype."""
    position = (torch.arange(length, dtype=like.dtype, device=like.device) + 0.5) / length
    edge = torch.minimum(position, 1.0 - position) / (0.5 * WINDOW_TAPER)
    return torch.where(edge < 1.0, 0.5 - 0.5 * torch.cos(math.pi * edge), torch.ones_like(edge))


def autocorrelation(features: Tensor, groups: Sequence[int] = FEATURE_GROUPS) -> Tensor:
    """The normalised autocorrelation ρ of the features (module docstring, step 2): per channel
    group, the windowed linear autocorrelation of the detrended channels summed, over the window's
    own, over its value at lag 0; the mean over the groups that are not constant
    (:data:`FEATURE_FLOOR`). Lag ``(lx, ly)`` is at index ``[H + ly, W + lx]``; ρ is symmetric.

    Shape: ``(C, H, W)`` → ``(2H, 2W)``, lags ``-H..H-1`` × ``-W..W-1``, ``ρ[H, W] = 1``
    (0 everywhere when every group is constant).

    Example:
        A pattern repeating every 8 columns matches itself 8 columns on:

        >>> columns = torch.arange(32.0).remainder(8.0).lt(2.0).double().expand(1, 32, 32)
        >>> rho = autocorrelation(columns, groups=(1,))
        >>> round(float(rho[32, 32]), 3), float(rho[32, 40]) > 0.9, float(rho[32, 36]) < 0
        (1.0, True, True)
    """
    return _mean_rho(group_autocorrelations(features, groups), features)


def _mean_rho(rhos: Sequence[Tensor | None], features: Tensor) -> Tensor:
    """The mean of the groups' ρ that are not constant; 0 everywhere where none is.
    Shape: each ``(2H, 2W)``; features ``(C, H, W)`` → ``(2H, 2W)``."""
    used = [rho for rho in rhos if rho is not None]
    if not used:
        height, width = features.shape[-2:]
        return torch.zeros(2 * height, 2 * width, dtype=torch.float64, device=features.device)
    return torch.stack(used).mean(dim=0)


def group_autocorrelations(features: Tensor, groups: Sequence[int] = FEATURE_GROUPS) -> list[Tensor | None]:
    """Per channel group, its normalised autocorrelation (:func:`autocorrelation`'s terms), or
    ``None`` where the group is constant (:data:`FEATURE_FLOOR`).

    Shape: ``(C, H, W)`` → each ``(2H, 2W)``.
    """
    check_shape(features, "C H W", name="features")
    channels, height, width = features.shape
    if sum(groups) != channels or min(groups) < 1:
        raise ValueError(f"feature groups {tuple(groups)} do not split {channels} channels")
    work = _detrend(features.double())
    window = _tukey(height, work).view(height, 1) * _tukey(width, work).view(1, width)
    size = (2 * height, 2 * width)
    weighted_mean = (work * window).sum(dim=(-2, -1), keepdim=True) / window.sum()
    spectrum = torch.fft.rfft2((work - weighted_mean) * window, s=size)
    per_channel = torch.fft.irfft2(spectrum.real.square() + spectrum.imag.square(), s=size)
    overlap = torch.fft.irfft2(torch.fft.rfft2(window, s=size).abs().square(), s=size)
    # The window's autocorrelation vanishes at lags beyond the image; those are cut off later.
    unbiased = per_channel / overlap.clamp_min(1e-9 * float(overlap[0, 0]))
    rhos: list[Tensor | None] = []
    for part in unbiased.split(list(groups)):
        summed = part.sum(dim=0)
        rhos.append(
            torch.fft.fftshift(summed / summed[0, 0]) if float(summed[0, 0]) > FEATURE_FLOOR**2 else None
        )
    return rhos


def _lag_overlap(lags: Tensor, height: int, width: int) -> Tensor:
    """The fraction of pixels that have a partner at each lag ``(lx, ly)``. Shape: ``(N, 2)`` → ``(N,)``."""
    fraction = (1.0 - lags[:, 0].abs() / width).clamp_min(0) * (1.0 - lags[:, 1].abs() / height).clamp_min(0)
    return fraction


def sample_rho(rho: Tensor, lags: Tensor) -> Tensor:
    """ρ at sub-pixel lags ``(lx, ly)``, bilinear. Shape: ``(2H, 2W)``, ``(*, 2)`` → ``(*)``."""
    check_shape(rho, "H2 W2", name="rho")
    height, width = rho.shape[0] // 2, rho.shape[1] // 2
    flat = lags.reshape(-1, 2).to(rho.dtype)
    # align_corners=False: index i's centre is at normalised (2i + 1) / n − 1.
    grid = torch.stack(
        [
            (2.0 * (flat[:, 0] + width) + 1.0) / (2 * width) - 1.0,
            (2.0 * (flat[:, 1] + height) + 1.0) / (2 * height) - 1.0,
        ],
        dim=-1,
    )
    values = F.grid_sample(
        rho[None, None], grid.view(1, 1, -1, 2), align_corners=False, padding_mode="border"
    )
    return values.view(lags.shape[:-1])


def peak_prominence(rho: Tensor, lags: Tensor, radius: Tensor | float) -> Tensor:
    """How far ρ at each lag stands above the ring of ``radius`` pixels around it: ρ(l) minus the
    ring's highest point (32 or more points on it). A lattice point is positive; a point on a ridge
    (stripes) ~0; a point on a slope negative.

    Shape: ``(2H, 2W)``, ``(N, 2)``, scalar or ``(N,)`` → ``(N,)``.
    """
    radii = torch.as_tensor(radius, dtype=rho.dtype, device=rho.device).expand(lags.shape[0])
    largest = float(radii.max()) if radii.numel() else 0.0
    count = min(128, max(32, math.ceil(2 * math.pi * largest)))  # ~1 px apart, bounded
    angles = torch.arange(count, dtype=rho.dtype, device=rho.device) * (2 * math.pi / count)
    ring = torch.stack([torch.cos(angles), torch.sin(angles)], dim=-1)  # (K, 2)
    points = lags.to(rho.dtype).unsqueeze(1) + radii.view(-1, 1, 1) * ring  # (N, K, 2)
    return sample_rho(rho, lags) - sample_rho(rho, points).amax(dim=-1)


def reduce_basis(a: Vector, b: Vector) -> tuple[Vector, Vector]:
    """The Lagrange–Gauss reduced basis of the lattice spanned by ``a`` and ``b``: the shortest
    vector first, the second the shortest not parallel to it (``|a·b| ≤ |a|²/2``), ``a`` pointing
    down or right (``dy > 0``, or ``dy = 0`` and ``dx > 0``), ``b`` turning clockwise on screen
    from ``a`` (``a × b > 0`` with ``y`` down).

    Shape: two ``(dx, dy)`` → two ``(dx, dy)``.

    Example:
        >>> reduce_basis((10.0, 0.0), (31.0, 10.0))
        ((10.0, 0.0), (1.0, 10.0))
    """
    ax, ay = a
    bx, by = b
    if abs(ax * by - ay * bx) < 1e-12:
        raise ValueError(f"lattice vectors {a} and {b} are parallel")
    for _ in range(64):  # converges in O(log) steps; the bound guards against NaN input
        if ax * ax + ay * ay > bx * bx + by * by:
            ax, ay, bx, by = bx, by, ax, ay
        mu = round((ax * bx + ay * by) / (ax * ax + ay * ay))
        if mu == 0:
            break
        bx, by = bx - mu * ax, by - mu * ay
    if ay < 0 or (ay == 0 and ax < 0):
        ax, ay = -ax, -ay
    if ax * by - ay * bx < 0:
        bx, by = -bx, -by
    return (ax, ay), (bx, by)


def parabola_vertex(below: float, centre: float, above: float) -> float:
    """The offset in (−½, ½) of the vertex of the parabola through three equally spaced values
    whose middle one is the largest (0 where they do not curve down).

    Example:
        >>> parabola_vertex(0.0, 1.0, 0.5)
        0.16666666666666666
    """
    curvature = below - 2.0 * centre + above
    return 0.0 if curvature >= 0 else max(-0.5, min(0.5, 0.5 * (below - above) / curvature))


def _peak_near(rho: Tensor, lag: Tensor, radius: float) -> tuple[Tensor, float, bool]:
    """The highest point of ρ within ``radius`` of ``lag``, refined to sub-pixel by a parabola
    through it and its neighbours along each axis; with its height and whether it is a local
    maximum inside the disk (not on its rim, where ρ is still rising).

    Shape: ``(2H, 2W)``, ``(2,)`` → ``(2,)`` lag, height, flag.
    """
    height, width = rho.shape[0] // 2, rho.shape[1] // 2
    reach = max(1, math.ceil(radius))
    cx, cy = round(float(lag[0])) + width, round(float(lag[1])) + height
    x0, x1 = max(cx - reach, 1), min(cx + reach + 1, 2 * width - 1)
    y0, y1 = max(cy - reach, 1), min(cy + reach + 1, 2 * height - 1)
    if x0 >= x1 or y0 >= y1:
        return lag.to(rho.dtype), -math.inf, False
    ys = torch.arange(y0, y1, device=rho.device).view(-1, 1)
    xs = torch.arange(x0, x1, device=rho.device).view(1, -1)
    inside = (xs - (float(lag[0]) + width)) ** 2 + (ys - (float(lag[1]) + height)) ** 2 <= reach * reach
    patch = torch.where(inside, rho[y0:y1, x0:x1], torch.tensor(-math.inf, dtype=rho.dtype))
    index = int(torch.argmax(patch))
    iy, ix = y0 + index // (x1 - x0), x0 + index % (x1 - x0)
    centre = float(rho[iy, ix])
    local = centre >= float(rho[iy - 1 : iy + 2, ix - 1 : ix + 2].max())
    offsets = [
        parabola_vertex(float(before), centre, float(after))
        for before, after in ((rho[iy, ix - 1], rho[iy, ix + 1]), (rho[iy - 1, ix], rho[iy + 1, ix]))
    ]
    position = torch.tensor([ix - width + offsets[0], iy - height + offsets[1]], dtype=rho.dtype)
    return position, centre, local


def refine_lattice(rho: Tensor, a: Vector, b: Vector, image_size: tuple[int, int]) -> tuple[Vector, Vector]:
    """``a`` and ``b`` fitted by weighted least squares to the sub-pixel peaks of ρ near the lattice
    points ``i·a + j·b`` (``|i|, |j| ≤`` :data:`REFINE_ORDER`, overlap at least
    :data:`CHECK_OVERLAP`, high enough to be a peak; weights their heights), twice: a peak at
    ``2a`` halves the error of one at ``a``, and in mild perspective averages the drift.

    Shape: ``(2H, 2W)``, two ``(dx, dy)``, ``(H, W)`` → two ``(dx, dy)``.
    """
    height, width = image_size
    basis = torch.tensor([a, b], dtype=rho.dtype)  # rows a, b
    orders = [
        (i, j)
        for i in range(-REFINE_ORDER, REFINE_ORDER + 1)
        for j in range(-REFINE_ORDER, REFINE_ORDER + 1)
        if (i, j) > (0, 0) or (i == 0 and j > 0)
    ]
    coefficients = torch.tensor(orders, dtype=rho.dtype)
    for _ in range(2):
        shortest = float(basis.norm(dim=1).min())
        predicted = coefficients @ basis
        level = COMBINATION_LEVEL * float(sample_rho(rho, basis).min())
        rows, targets, weights = [], [], []
        for k, lag in enumerate(predicted):
            if float(_lag_overlap(lag.view(1, 2), height, width)) < CHECK_OVERLAP:
                continue
            position, value, local = _peak_near(rho, lag, SEARCH_FRACTION * shortest)
            # A negative ρ is no peak, however the level falls (a basis vector's own ρ can be
            # negative, which would let every dip through and give the fit negative weights).
            if local and value >= level and value > 0:
                rows.append(coefficients[k])
                targets.append(position)
                weights.append(value)
        if len(rows) < 2:
            break
        design, target = torch.stack(rows), torch.stack(targets)
        if torch.linalg.matrix_rank(design) < 2:
            break
        root = torch.tensor(weights, dtype=rho.dtype).sqrt().view(-1, 1)
        basis = torch.linalg.lstsq(root * design, root * target).solution
    return _vector(basis[0].tolist()), _vector(basis[1].tolist())


def _candidates(rho: Tensor, height: int, width: int) -> Tensor:
    """The local maxima of ρ (3×3) in one half-plane of lags, at least :data:`MIN_PEAK` high,
    :data:`MIN_PERIOD` long, with :data:`MIN_OVERLAP`: the strongest :data:`MAX_CANDIDATES`,
    shortest first. Shape: ``(2H, 2W)`` → ``(N, 2)`` lags ``(lx, ly)``."""
    pooled = F.max_pool2d(rho[None, None], 3, stride=1, padding=1)[0, 0]
    ys, xs = torch.nonzero((rho >= pooled) & (rho >= MIN_PEAK), as_tuple=True)
    lags = torch.stack([xs - width, ys - height], dim=-1).to(rho.dtype)
    upper = (lags[:, 1] > 0) | ((lags[:, 1] == 0) & (lags[:, 0] > 0))
    keep = upper & (lags.norm(dim=-1) >= MIN_PERIOD) & (_lag_overlap(lags, height, width) >= MIN_OVERLAP)
    lags, values = lags[keep], rho[ys[keep], xs[keep]]
    lags = lags[torch.argsort(values, descending=True)[:MAX_CANDIDATES]]
    return lags[torch.argsort(lags.norm(dim=-1), stable=True)]


def _shortest_standing_out(prominence: Tensor) -> int | None:
    """The first (shortest) candidate whose prominence is at least half the threshold and at least
    :data:`RELATIVE_PROMINENCE` × the best: a ridge's bumps (stripes, grout lines) reach a few
    hundredths, a lattice point several tenths. Shape: ``(N,)`` → an index or ``None``."""
    if prominence.numel() == 0:
        return None
    level = max(SELECT_FRACTION * PROMINENCE_THRESHOLD, RELATIVE_PROMINENCE * float(prominence.max()))
    chosen = torch.nonzero(prominence >= level)
    return int(chosen[0]) if chosen.numel() else None


def _pick_pair(rho: Tensor, lags: Tensor) -> tuple[Vector, Vector] | None:
    """The shortest candidate that stands out (:func:`_shortest_standing_out`) and the shortest one
    at least :data:`MIN_ANGLE_DEG` from it that does, rings sized by the first. Shape: ``(N, 2)``."""
    if lags.shape[0] == 0:
        return None
    first = _shortest_standing_out(
        peak_prominence(rho, lags, (RING_FRACTION * lags.norm(dim=-1)).clamp_min(MIN_RING))
    )
    if first is None:
        return None
    a = lags[first]
    sine = (a[0] * lags[:, 1] - a[1] * lags[:, 0]).abs() / (a.norm() * lags.norm(dim=-1))
    others = lags[sine >= math.sin(math.radians(MIN_ANGLE_DEG))]
    ring = max(MIN_RING, RING_FRACTION * float(a.norm()))
    second = _shortest_standing_out(peak_prominence(rho, others, ring))
    if second is None:
        return None
    return _vector(a.tolist()), _vector(others[second].tolist())


def _score_lattice(rho: Tensor, a: Vector, b: Vector, image_size: tuple[int, int]) -> tuple[float, str]:
    """The lattice's score: the least prominence (:func:`peak_prominence`, rings sized by the
    shorter vector) among the peaks of ρ nearest ``a``, ``b`` and the combinations ``a ± b``,
    ``2a``, ``2b`` that the maps can show (:data:`CHECK_OVERLAP`), with the weakest one's name;
    ``-inf`` and why where no combination can be checked (less than two periods in the maps).
    A pair of noise maxima has no peak at its sum: its score is 0 or negative there.

    Shape: ``(2H, 2W)``, two ``(dx, dy)``, ``(H, W)`` → a score and a name.
    """
    height, width = image_size
    basis = torch.tensor([a, b], dtype=rho.dtype)
    shortest = float(basis.norm(dim=1).min())
    ring = max(MIN_RING, RING_FRACTION * shortest)
    points = {"a": basis[0], "b": basis[1]}
    combinations = {
        "a+b": basis[0] + basis[1],
        "a-b": basis[0] - basis[1],
        "2a": 2 * basis[0],
        "2b": 2 * basis[1],
    }
    for name, lag in combinations.items():
        if float(_lag_overlap(lag.view(1, 2), height, width)) >= CHECK_OVERLAP:
            points[name] = lag
    if len(points) == 2:
        return -math.inf, "the maps show less than two periods: no combination of the vectors to check"
    # Each point's own peak: the highest ρ near it, which must be a local maximum (on the search
    # disk's rim ρ is still rising towards something else: no peak here, prominence 0 at most).
    found = [_peak_near(rho, lag, SEARCH_FRACTION * shortest) for lag in points.values()]
    prominence = peak_prominence(rho, torch.stack([position for position, _, _ in found]), ring)
    local = torch.tensor([is_local for _, _, is_local in found])
    prominence = torch.where(local, prominence, prominence.clamp_max(0.0))
    weakest = int(torch.argmin(prominence))
    return float(prominence[weakest]), list(points)[weakest]


def find_lattice(maps: Tensor) -> Lattice:
    """Whether the map set repeats on a 2-D lattice, and its reduced lattice vectors in the maps'
    pixels (module docstring, steps 1–3): read from both feature groups, or from one alone where
    that one is periodic and scores at least :data:`ONE_GROUP_FACTOR` times both together (the
    other group then only blurs the lattice's peaks). Stripes and other 1-D patterns are not
    periodic.

    Shape: ``(8, H, W)`` → :class:`Lattice`.
    """
    check_single_maps(maps)
    features, factor = detection_features(maps)
    image_size = (features.shape[-2], features.shape[-1])
    rhos = group_autocorrelations(features)
    both = _lattice_in(_mean_rho(rhos, features), image_size, factor, ALL_FEATURES)
    best = both
    present = [rho for rho in rhos if rho is not None]
    if len(present) < len(rhos):
        return best  # a constant group leaves the other's lattice as it is: nothing to compare
    for choice, groups in FEATURE_CHOICES.items():
        if len(groups) != 1:
            continue
        alone = _lattice_in(present[groups[0]], image_size, factor, choice)
        standing_out = alone.periodic and alone.score >= ONE_GROUP_FACTOR * max(both.score, 0.0)
        if standing_out and alone.score > best.score:
            best = alone
    return best


def _lattice_in(rho: Tensor, image_size: tuple[int, int], factor: Tensor, choice: str) -> Lattice:
    """:func:`find_lattice` on one autocorrelation (of the feature groups ``choice``), in the maps'
    pixels (``factor`` per detection pixel). Shape: ``(2H, 2W)``, ``(H, W)``, ``(2,)``."""
    pair = _pick_pair(rho, _candidates(rho, *image_size))
    if pair is None:
        return Lattice(
            None, 0.0, False, notes="no isolated autocorrelation peak (no 2-D lattice)", features=choice
        )
    a, b = reduce_basis(*pair)
    a, b = refine_lattice(rho, a, b, image_size)
    a, b = reduce_basis(a, b)
    score, weakest = _score_lattice(rho, a, b, image_size)
    periodic = score >= PROMINENCE_THRESHOLD
    if not math.isfinite(score):
        notes, score = weakest, 0.0
    elif periodic:
        notes = f"2-D lattice (weakest peak: {weakest})"
    else:
        notes = f"lattice peaks too weak (at {weakest}: score {score:.3f} < {PROMINENCE_THRESHOLD})"
    scaled = tuple(
        _vector((torch.tensor(vector, dtype=torch.float64) * factor).tolist()) for vector in (a, b)
    )
    return Lattice((scaled[0], scaled[1]), score, periodic, notes=notes, features=choice)


# Perspective (module docstring, step 3b): the lattice measured in a grid of windows this many a
# side, each the smallest share of the maps' side from WINDOW_SHARE (overlapping) in which each
# lattice vector fits MIN_WINDOW_CELLS times; a keystone (scale change from the centre to an edge)
# below MIN_KEYSTONE is left alone, one above MAX_KEYSTONE is no mild perspective; the fit must
# bring the windows' lattices together (their spread about the model) to at most
# PERSPECTIVE_GAIN of their spread about one lattice.
PERSPECTIVE_WINDOWS = 3
WINDOW_SHARE = (0.5, 0.75)
MIN_WINDOW_CELLS = 2.0
MIN_KEYSTONE = 0.0025
MAX_KEYSTONE = 0.1
PERSPECTIVE_GAIN = 0.5
# The largest windows are tried only where the smallest saw a keystone of at least this much (or a
# window's lattice that was not the maps'): on square-on lattices their fits see 0.01-0.17 %, and
# the retry there (nine windows of 3/4 of the side) cost 3.9 CPU s at 2048²; where the retry found
# a perspective on the rendered regular materials, the small windows had seen 0.22-2.8 %.
RETRY_KEYSTONE = 0.5 * MIN_KEYSTONE
# Where the whole maps show no lattice, it is sought in their central square of this share of the
# shorter side (half: a 2 % keystone's scale change across it is halved).
CENTRAL_SHARE = 0.5
# Where no window holds MIN_WINDOW_CELLS cells (a checkerboard of two periods a crop), or no grid
# of windows agrees, the perspective is fitted to the whole maps' match with themselves one lattice
# vector on (:func:`fit_self_match`): at most SELF_MATCH_SIDE a side, coarse to fine through
# Gaussian blurs of SELF_MATCH_BLURS px (every blur-th pixel scored), SELF_MATCH_STEPS L-BFGS
# iterations each (20 gave the same keystones within 0.04 % at three times the cost). It is
# kept where it leaves at most SELF_MATCH_GAIN of the residual without it, with a keystone between
# MIN_KEYSTONE and MAX_KEYSTONE. Measured on the tiling table's periodic materials (256² crops):
# with a ±2 % / ±1.5 % keystone the fit finds it within 0.4 % and leaves 0.04-0.89 of the
# residual (the mosaic's and the herringbone's own variation the most); square-on its keystone is
# 0-0.64 % and it leaves 0.87-1.00 (0.92-1.00 where that keystone reaches MIN_KEYSTONE).
SELF_MATCH_SIDE = 256
SELF_MATCH_BLURS = (4.0, 2.0, 1.0)
SELF_MATCH_STEPS = 8
SELF_MATCH_GAIN = 0.9
# How a Perspective was measured (Perspective.method).
WINDOWS = "windows"
SELF_MATCH = "self-match"


def through_perspective(rectified: Tensor, g: Tensor) -> Tensor:
    """The image offsets ``d = q / (1 − g·q)`` from the centre that show the rectified offsets
    ``q`` through the perspective ``g`` (per pixel; :class:`Perspective`). Differentiable in both.

    Shape: ``(*, 2)``, ``(2,)`` → ``(*, 2)``.
    """
    return rectified / (1.0 - (rectified * g).sum(dim=-1, keepdim=True))


@dataclass(frozen=True)
class Perspective:
    """A mild perspective of the maps (module docstring, step 3b): image offset ``d`` from the maps'
    ``centre`` shows the rectified offset ``q = d / (1 + g·d)`` (and ``d = q / (1 − g·q)``), ``g``
    per pixel; ``keystone`` the scale change from the centre to the right and bottom edges
    (``g · half side``); how it was measured (``method``): from the lattices of a grid of windows
    (:data:`WINDOWS`; ``spread_before`` and ``spread_after`` their vectors' RMS distance (px) from
    one lattice and from the model's; for :func:`~brdfgan.core.stripes.find_stripe_perspective`
    the windows' stripe frequencies', in pixels of the period) or from the whole maps' match with
    themselves (:data:`SELF_MATCH`; the spreads are that match's residual without the keystone and
    with it, :func:`fit_self_match`)."""

    g: Vector
    centre: Vector
    keystone: Vector
    spread_before: float
    spread_after: float
    method: str = WINDOWS

    def to_image(self, rectified: Tensor) -> Tensor:
        """Rectified positions → the maps' positions. Shape: ``(*, 2)`` → ``(*, 2)``."""
        centre = torch.tensor(self.centre, dtype=rectified.dtype, device=rectified.device)
        g = torch.tensor(self.g, dtype=rectified.dtype, device=rectified.device)
        return centre + through_perspective(rectified - centre, g)

    def to_json(self) -> dict[str, Any]:
        return {
            "g_per_pixel": list(self.g),
            "centre": list(self.centre),
            "keystone": list(self.keystone),
            "spread_before_px": self.spread_before,
            "spread_after_px": self.spread_after,
            "method": self.method,
        }

    def then(self, rest: Perspective) -> Perspective:
        """This perspective and ``rest``, measured on the maps this one rectified, as one: two
        homographies about one centre compose by adding their ``g`` (``q = d / (1 + (g₁ + g₂)·d)``);
        the spread before is this one's, the spread after the second fit's where both were measured
        alike (else this one's: a windows' spread in pixels and a self-match residual do not
        compare), the method both (``"windows, then self-match"``)."""
        alike = rest.method == self.method
        return Perspective(
            g=(self.g[0] + rest.g[0], self.g[1] + rest.g[1]),
            centre=self.centre,
            keystone=(self.keystone[0] + rest.keystone[0], self.keystone[1] + rest.keystone[1]),
            spread_before=self.spread_before,
            spread_after=rest.spread_after if alike else self.spread_after,
            method=self.method if alike else f"{self.method}, then {rest.method}",
        )

    @classmethod
    def from_json(cls, record: dict[str, Any]) -> Perspective:
        return cls(
            g=_vector(record["g_per_pixel"]),
            centre=_vector(record["centre"]),
            keystone=_vector(record["keystone"]),
            spread_before=float(record["spread_before_px"]),
            spread_after=float(record["spread_after_px"]),
            # A record from before the whole maps' fit was measured from windows.
            method=str(record.get("method", WINDOWS)),
        )


def fit_perspective(centres: Tensor, vectors: Tensor) -> tuple[Tensor, Tensor, float, float]:
    """The perspective ``g`` and the rectified lattice ``m`` that explain lattice vectors measured
    around the maps: to first order in ``g``, the vector ``v`` seen at offset ``d`` from the centre
    is ``m + (v dᵀ + d vᵀ) g`` (the rectified lattice through the Jacobian of ``q = d / (1 + g·d)``),
    solved by least squares; with the spreads of the vectors about one lattice (``g = 0``) and about
    the model.

    Shape: centres ``(K, 2)``, vectors ``(K, V, 2)`` → ``g`` ``(2,)``, ``m`` ``(V, 2)``, two floats.

    Example:
        Vectors that shrink by 2 % to the right (a 10-pixel lattice seen at ±100 px):

        >>> f64 = torch.float64
        >>> m = torch.tensor([[10.0, 0.0], [0.0, 10.0]], dtype=f64)
        >>> centres = 100.0 * torch.tensor([[-1.0, 0], [1, 0], [0, -1], [0, 1]], dtype=f64)
        >>> g_true = torch.tensor([2e-4, 0.0], dtype=f64)
        >>> def seen_at(d):  # the image vectors whose rectified images are m's rows
        ...     w = 1 + g_true @ d
        ...     jacobian = (torch.eye(2, dtype=f64) * w - torch.outer(d, g_true)) / w**2
        ...     return torch.linalg.solve(jacobian, m.T).T
        >>> seen = torch.stack([seen_at(d) for d in centres])
        >>> g, lattice, before, after = fit_perspective(centres, seen)
        >>> [round(v * 1e4, 2) for v in g.tolist()], after < 0.05 * before
        ([2.0, 0.0], True)
    """
    count, per_window = vectors.shape[:2]
    rows, targets = [], []
    for k in range(count):
        d = centres[k]
        for j in range(per_window):
            v = vectors[k, j]
            block = torch.zeros(2, 2 + 2 * per_window, dtype=vectors.dtype)
            block[:, :2] = torch.outer(v, d) + torch.outer(d, v)
            block[:, 2 + 2 * j : 4 + 2 * j] = torch.eye(2, dtype=vectors.dtype)
            rows.append(block)
            targets.append(v)
    design, target = torch.cat(rows), torch.cat(targets)
    solution = torch.linalg.lstsq(design, target[:, None]).solution[:, 0]
    spread_before = float((vectors - vectors.mean(dim=0)).square().sum(dim=-1).mean().sqrt())
    spread_after = float((design @ solution - target).view(-1, 2).square().sum(dim=-1).mean().sqrt())
    return solution[:2], solution[2:].view(per_window, 2), spread_before, spread_after


def find_perspective(maps: Tensor, lattice: Lattice) -> Perspective | None:
    """The maps' mild perspective from how their lattice changes across them (module docstring,
    step 3b), or ``None``: no lattice that is periodic or just short of it
    (:attr:`Lattice.ambiguous`), a keystone below :data:`MIN_KEYSTONE` or above
    :data:`MAX_KEYSTONE`, or a fit that does not bring the windows' lattices together; where no
    window holds enough cells, or the windows saw a keystone that no fit of theirs explains (a
    window whose lattice is not the maps' among them), the whole maps' match with themselves
    decides instead (:func:`self_match_perspective`). The windows are the smallest that hold
    :data:`MIN_WINDOW_CELLS` cells; where those give no perspective, the largest
    (:data:`WINDOW_SHARE`) are tried: a window of two or three cells sees few of the lattice's
    peaks, and its lattice can be a pixel off, as much as a 2 % keystone moves it (a scanned tile
    grid at 15°: spread ratio 0.79 in windows of half the side, 0.16 in windows of three quarters).
    They are tried only where the smallest saw a keystone of :data:`RETRY_KEYSTONE` or more, or a
    lattice other than the maps': a square-on lattice is not measured twice.

    Shape: ``(8, H, W)``.
    """
    check_single_maps(maps)
    if lattice.vectors is None or not (lattice.periodic or lattice.ambiguous):
        return None
    features, factor = detection_features(maps)
    features, groups = feature_groups(features, lattice.features)
    small_h, small_w = features.shape[-2:]
    start = torch.stack([torch.tensor(vector, dtype=torch.float64) / factor for vector in lattice.vectors])
    extent = start.abs().amax(dim=0)  # the lattice vectors' reach along x and y
    share = max(
        WINDOW_SHARE[0], MIN_WINDOW_CELLS * max(float(extent[0]) / small_w, float(extent[1]) / small_h)
    )
    if share > WINDOW_SHARE[1]:
        # Too few cells for windows to see the lattice change across the maps: the whole maps'
        # match with themselves one lattice vector on shows it instead.
        return self_match_perspective(features, factor, start, (maps.shape[-2], maps.shape[-1]))
    for tried in dict.fromkeys((share, WINDOW_SHARE[1])):
        perspective, seen = _perspective_in_windows(
            features, groups, factor, start, tried, (maps.shape[-2], maps.shape[-1])
        )
        if perspective is not None or seen < RETRY_KEYSTONE:
            return perspective
    # The windows saw a keystone they could not agree on, or lattices other than the maps'.
    return self_match_perspective(features, factor, start, (maps.shape[-2], maps.shape[-1]))


def _perspective_in_windows(
    features: Tensor,
    groups: tuple[int, ...],
    factor: Tensor,
    start: Tensor,
    share: float,
    size: tuple[int, int],
) -> tuple[Perspective | None, float]:
    """:func:`find_perspective` in a grid of windows of ``share`` of the detection features'
    sides (feature ``groups``, the lattice's): each window's lattice refined from ``start`` (rows
    a, b, in the features' pixels), and the perspective fitted to them (:func:`_fit_windows`), or
    ``None`` (its conditions); in the maps' pixels (``size`` ``(H, W)``, ``factor`` the maps'
    pixels per feature pixel). With it, the keystone's strength the fit saw, kept or not (infinite
    where a window's lattice was not the maps': nothing was fitted)."""
    seed = (_vector(start[0].tolist()), _vector(start[1].tolist()))
    reach = SEARCH_FRACTION * float(start.norm(dim=-1).min())
    centres, measured = [], []
    for window, centre in perspective_windows(features, factor, share, size):
        rho = autocorrelation(window, groups)
        refined = refine_lattice(rho, *seed, (window.shape[-2], window.shape[-1]))
        local = torch.tensor(refined, dtype=torch.float64)
        if float((local - start).norm(dim=-1).max()) > reach:
            return None, math.inf  # the window's lattice is not the maps' (a window of grout, a stain)
        centres.append(centre)
        measured.append(local * factor)
    g, spread_before, spread_after = _fit_windows(
        torch.tensor(centres, dtype=torch.float64), torch.stack(measured)
    )
    return perspective_of_fit(g, size, spread_before, spread_after)


def perspective_of_fit(
    g: Tensor,
    size: tuple[int, int],
    spread_before: float,
    spread_after: float,
    *,
    gain: float = PERSPECTIVE_GAIN,
    method: str = WINDOWS,
) -> tuple[Perspective | None, float]:
    """The :class:`Perspective` of a homography ``g`` fitted to maps of ``size`` ``(H, W)``,
    about their centre (measured by ``method``), with the keystone's strength (its larger
    component); ``None`` with it where the keystone is below :data:`MIN_KEYSTONE` or above
    :data:`MAX_KEYSTONE` (or not finite), or the fit leaves more than ``gain`` of the spread it
    started from.

    Shape: ``(2,)`` → :class:`Perspective` or ``None``, a float.
    """
    height, width = size
    keystone = (float(g[0]) * width / 2, float(g[1]) * height / 2)
    strength = max(abs(keystone[0]), abs(keystone[1]))
    if not (MIN_KEYSTONE <= strength <= MAX_KEYSTONE) or not spread_after <= gain * spread_before:
        return None, strength
    perspective = Perspective(
        g=_vector(g.tolist()),
        centre=(width / 2, height / 2),
        keystone=keystone,
        spread_before=spread_before,
        spread_after=spread_after,
        method=method,
    )
    return perspective, strength


def self_match_residual(features: Tensor, g: Tensor, vectors: Tensor, points: Tensor) -> Tensor:
    """How far the features, seen through the perspective ``g`` (per pixel, about their centre),
    are from matching themselves one lattice vector on: the mean squared difference between the
    features at the rectified offsets ``points`` and at ``points ± a`` and ``points ± b`` (bilinear,
    pixel centres at ``index + 0.5``), over the pairs that both lie a pixel or more inside.
    Differentiable in ``g`` and ``vectors``.

    Shape: features ``(C, h, w)``, g ``(2,)``, vectors ``(2, 2)`` (rows a, b), points ``(N, 2)``
    → ``()``.

    Example:
        Stripes of period 8 along x match themselves 8 px on; half a period on, ``sin`` meets
        ``−sin``, a mean squared difference of 2 on the two shifts across (none along):

        >>> x = torch.arange(64, dtype=torch.float64) + 0.5
        >>> stripes = torch.sin(2 * math.pi * x / 8).expand(1, 64, 64)
        >>> points = torch.stack(torch.meshgrid(x - 32, x - 32, indexing="xy"), -1).view(-1, 2)
        >>> g = torch.zeros(2, dtype=torch.float64)
        >>> period, half = torch.tensor([[[8.0, 0], [0, 4]], [[4.0, 0], [0, 4]]], dtype=torch.float64)
        >>> on = self_match_residual(stripes, g, period, points)
        >>> off = self_match_residual(stripes, g, half, points)
        >>> round(float(on), 6), round(float(off), 1)
        (0.0, 1.0)
    """
    height, width = features.shape[-2:]
    centre = torch.tensor([width / 2, height / 2], dtype=points.dtype, device=points.device)
    scale = torch.tensor([2.0 / width, 2.0 / height], dtype=points.dtype, device=points.device)
    lo, hi = torch.ones_like(centre), 2.0 * centre - 1.0

    def seen(shift: Tensor) -> tuple[Tensor, Tensor]:
        image = centre + through_perspective(points + shift, g)
        grid = (image * scale - 1.0).to(features.dtype)
        values = F.grid_sample(
            features[None], grid[None, None], mode="bilinear", padding_mode="border", align_corners=False
        )[0, :, 0]
        return values, ((image >= lo) & (image <= hi)).all(dim=-1)

    here, inside = seen(torch.zeros_like(centre))
    total = torch.zeros((), dtype=features.dtype, device=features.device)
    count = torch.zeros((), dtype=features.dtype, device=features.device)
    for shift in (vectors[0], -vectors[0], vectors[1], -vectors[1]):
        there, also = seen(shift)
        both = (inside & also).to(features.dtype)
        total = total + ((there - here).square() * both).sum()
        count = count + both.sum() * features.shape[0]
    return total / count.clamp_min(1.0)


def fit_self_match(features: Tensor, start: Tensor) -> tuple[Tensor, Tensor, float, float]:
    """The perspective ``g`` (per pixel, about the features' centre) and the lattice vectors at the
    centre that make the features match themselves best one lattice vector on
    (:func:`self_match_residual`), by L-BFGS from no perspective and ``start``, coarse to fine
    (:data:`SELF_MATCH_BLURS`); with the residual at full detail of the fitted vectors without the
    perspective and with it. The features are detrended and each channel scaled to unit spread.

    Shape: features ``(C, h, w)``, start ``(2, 2)`` (rows a, b, in the features' pixels) →
    ``(2,)``, ``(2, 2)``, two floats.
    """
    detail = _detrend(features.double())
    detail = detail / detail.flatten(1).std(dim=1).clamp_min(FEATURE_FLOOR)[:, None, None]
    height, width = detail.shape[-2:]
    half = torch.tensor([width / 2, height / 2], dtype=torch.float64)
    keystone = torch.zeros(2, dtype=torch.float64, requires_grad=True)  # g · half side: unit scale
    vectors = start.double().clone().requires_grad_(True)

    def points(step: int) -> Tensor:
        ys = torch.arange(0, height, step, dtype=torch.float64) + 0.5 - height / 2
        xs = torch.arange(0, width, step, dtype=torch.float64) + 0.5 - width / 2
        return torch.stack(torch.meshgrid(xs, ys, indexing="xy"), dim=-1).view(-1, 2)

    for sigma in SELF_MATCH_BLURS:
        blurred = gaussian_blur(detail[None], sigma, "reflect")[0]
        scored = points(max(1, round(sigma)))
        optimiser = torch.optim.LBFGS(
            [keystone, vectors], max_iter=SELF_MATCH_STEPS, line_search_fn="strong_wolfe"
        )

        def closure(
            optimiser: torch.optim.LBFGS = optimiser, blurred: Tensor = blurred, scored: Tensor = scored
        ) -> Tensor:
            optimiser.zero_grad()
            loss = self_match_residual(blurred, keystone / half, vectors, scored)
            loss.backward()
            return loss

        optimiser.step(closure)
    with torch.no_grad():
        g, fitted, every = keystone.detach() / half, vectors.detach(), points(1)
        before = float(self_match_residual(detail, torch.zeros_like(g), fitted, every))
        after = float(self_match_residual(detail, g, fitted, every))
    return g, fitted, before, after


def self_match_perspective(
    features: Tensor, factor: Tensor, start: Tensor, size: tuple[int, int]
) -> Perspective | None:
    """:func:`find_perspective` where no window holds enough cells or no grid of windows agrees:
    the perspective that makes the whole maps match themselves one lattice vector on
    (:func:`fit_self_match`, at most :data:`SELF_MATCH_SIDE` a side), kept where it leaves at most
    :data:`SELF_MATCH_GAIN` of the residual without it and its keystone is mild
    (:func:`perspective_of_fit`); in the maps' pixels
    (``size`` ``(H, W)``, ``factor`` the maps' pixels per feature pixel, ``start`` the lattice
    vectors in the features' pixels).

    Shape: ``(C, h, w)`` → :class:`Perspective` or ``None``.
    """
    small, shrink = area_shrink(features, SELF_MATCH_SIDE)
    g, _, before, after = fit_self_match(small, start / shrink)
    # g · d is the same in any pixels: per maps' pixel, g divided by the maps' pixels per small one.
    return perspective_of_fit(
        g / (shrink * factor), size, before, after, gain=SELF_MATCH_GAIN, method=SELF_MATCH
    )[0]


def perspective_windows(
    features: Tensor, factor: Tensor, share: float, size: tuple[int, int]
) -> list[tuple[Tensor, list[float]]]:
    """The :data:`PERSPECTIVE_WINDOWS` × :data:`PERSPECTIVE_WINDOWS` grid of overlapping windows of
    ``share`` of the detection features' sides, corner to corner (module docstring, step 3b), each
    with its centre as an offset from the maps' centre in the maps' pixels (``size`` ``(H, W)``,
    ``factor`` the maps' pixels per feature pixel).

    Shape: ``(C, h, w)`` → windows ``(C, share·h, share·w)`` and ``[dx, dy]``.
    """
    height, width = size
    small_h, small_w = features.shape[-2:]
    window_h, window_w = round(share * small_h), round(share * small_w)
    windows = []
    for row in range(PERSPECTIVE_WINDOWS):
        for column in range(PERSPECTIVE_WINDOWS):
            top = round(row * (small_h - window_h) / (PERSPECTIVE_WINDOWS - 1))
            left = round(column * (small_w - window_w) / (PERSPECTIVE_WINDOWS - 1))
            centre = [(left + window_w / 2) * float(factor[0]) - width / 2,
                      (top + window_h / 2) * float(factor[1]) - height / 2]  # fmt: skip
            windows.append((features[:, top : top + window_h, left : left + window_w], centre))
    return windows


def central_lattice(maps: Tensor) -> Lattice:
    """The lattice of the maps' central square of :data:`CENTRAL_SHARE` of their shorter side
    (module docstring, step 3b), in the maps' pixels: a seed for :func:`find_perspective` where
    the whole maps show none.

    Shape: ``(8, H, W)`` → :class:`Lattice`.
    """
    check_single_maps(maps)
    height, width = maps.shape[-2:]
    side = round(CENTRAL_SHARE * min(height, width))
    top, left = (height - side) // 2, (width - side) // 2
    centre = maps[:, top : top + side, left : left + side]
    # At the whole maps' detection scale (:func:`detection_features`): finer would cost as much as
    # the whole maps' detection and see only texture more.
    small = min(side, round(side * DETECT_SIDE / max(height, width)))
    if small == side:
        return find_lattice(centre.contiguous())
    found = find_lattice(F.interpolate(centre[None], size=(small, small), mode="area")[0])
    if found.vectors is None:
        return found
    factor = side / small
    a, b = (_vector([factor * value for value in vector]) for vector in found.vectors)
    return replace(found, vectors=(a, b))


def _fit_windows(centres: Tensor, vectors: Tensor) -> tuple[Tensor, float, float]:
    """:func:`fit_perspective` on the windows' lattices (its ``g`` and spreads); where that fit does
    not bring them together (spread after > :data:`PERSPECTIVE_GAIN` × before), once more without
    the one window whose absence brings the rest together best: a window of grout, a stain or a
    lattice point its refinement missed holds the fit back (a scanned tile grid in a 2 % keystone:
    0.52 with all nine windows, 0.30 without a corner window whose lattice came out unrefined).

    Shape: ``(K, 2)``, ``(K, V, 2)`` → ``(2,)``, two floats.
    """
    g, _, before, after = fit_perspective(centres, vectors)
    if after <= PERSPECTIVE_GAIN * before:
        return g, before, after
    trials = []
    for left_out in range(len(centres)):
        kept = [k for k in range(len(centres)) if k != left_out]
        g_kept, _, before_kept, after_kept = fit_perspective(centres[kept], vectors[kept])
        trials.append((after_kept / max(before_kept, 1e-12), g_kept, before_kept, after_kept))
    _, g, before, after = min(trials, key=lambda trial: trial[0])
    return g, before, after


def refine_perspective(maps: Tensor, perspective: Perspective) -> tuple[Perspective, Tensor, Lattice]:
    """The perspective measured once more on the maps it rectifies, with the maps rectified
    through the result and their lattice: where the first fit over- or undershoots by more than
    :data:`MIN_KEYSTONE` (a tread plate at 45°: 2.4 % for the truth's 2 %), the rectified maps show
    the rest, and since two such homographies about one centre compose by adding their ``g``
    (:meth:`Perspective.then`), the sum is returned; else ``perspective`` as it is.

    Shape: ``(8, H, W)`` and their :class:`Perspective` → :class:`Perspective`, ``(8, H, W)``,
    :class:`Lattice`.
    """
    rectified = rectify(maps, perspective)
    straight = find_lattice(rectified)
    if perspective.method == SELF_MATCH:
        return perspective, rectified, straight  # fitted to the whole maps: a second fit repeats it
    rest = find_perspective(rectified, straight)
    if rest is None:
        return perspective, rectified, straight
    combined = perspective.then(rest)
    rectified = rectify(maps, combined)
    return combined, rectified, find_lattice(rectified)


def rectify(maps: Tensor, perspective: Perspective) -> Tensor:
    """The maps with their perspective taken out: output pixel ``q`` samples the maps at
    :meth:`Perspective.to_image` (bilinear, the border extended; normals renormalised). The
    Jacobian at the centre is the identity, so the lattice there keeps its vectors.

    Shape: ``(8, H, W)`` → ``(8, H, W)`` in the maps' dtype.
    """
    check_single_maps(maps)
    height, width = maps.shape[-2:]
    ys = torch.arange(height, dtype=torch.float64, device=maps.device) + 0.5
    xs = torch.arange(width, dtype=torch.float64, device=maps.device) + 0.5
    yy, xx = torch.meshgrid(ys, xs, indexing="ij")
    points = perspective.to_image(torch.stack([xx, yy], dim=-1))
    grid = torch.stack([2.0 * points[..., 0] / width - 1.0, 2.0 * points[..., 1] / height - 1.0], dim=-1)
    sampled = F.grid_sample(
        maps.detach()[None],
        grid.to(maps.dtype)[None],
        mode="bilinear",
        padding_mode="border",
        align_corners=False,
    )[0]
    parts = split_maps(sampled)
    return join_maps(parts.basecolor, normalize_normal(parts.normal), parts.roughness, parts.metallic)


def _distortion(u: Tensor, v: Tensor, height: int, width: int) -> tuple[Tensor, Tensor]:
    """The stretch (log of the singular values' ratio: 0 for a rotation with a uniform scale) and
    the turn (radians, clockwise on screen; the rotation of the polar decomposition) of the affine
    map taking ``u`` to ``(W, 0)`` and ``v`` to ``(0, H)``; ``u × v > 0``. In closed form, so that
    all pairs of candidates are scored at once.

    Shape: ``(*, 2)``, ``(*, 2)`` (broadcast) → ``(*)``, ``(*)``.
    """
    cross = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    # A = diag(W, H) · [u v]⁻¹ = [[p, q], [r, s]].
    p, q = width * v[..., 1] / cross, -width * v[..., 0] / cross
    r, s = -height * u[..., 1] / cross, height * u[..., 0] / cross
    frobenius = p * p + q * q + r * r + s * s
    determinant = p * s - q * r
    spread = (frobenius * frobenius - 4.0 * determinant * determinant).clamp_min(0.0).sqrt()
    larger = (0.5 * (frobenius + spread)).sqrt()
    smaller = (0.5 * (frobenius - spread)).clamp_min(1e-300).sqrt()
    return torch.log(larger / smaller), torch.atan2(r - q, p + s)


@dataclass(frozen=True)
class CellTiling:
    """Whole lattice cells as a tile (module docstring, steps 4–5): ``u = m₁a + n₁b`` and
    ``v = m₂a + n₂b`` (``counts = ((m₁, n₁), (m₂, n₂))``, pixels ``(dx, dy)`` of the maps) become
    the tile's edges ``(W, 0)`` and ``(0, H)`` (``size = (H, W)``, the maps' size): output point
    ``(x, y)`` (pixel edges) is source point ``origin + (x / W)·u + (y / H)·v`` before the tile is
    rolled by ``roll = (ry, rx)`` pixels (:func:`tile_whole_cells`; the tile's pixel ``(i, j)`` is
    then the unrolled one's ``((i + ry) mod H, (j + rx) mod W)``). ``margin = (mx, my)`` output
    pixels are sampled beyond each edge for the residual seam; ``aligned``: the frame was turned to
    the lattice (``--align-pattern``)."""

    counts: tuple[tuple[int, int], tuple[int, int]]
    u: Vector
    v: Vector
    origin: Vector
    size: tuple[int, int]
    margin: tuple[int, int]
    aligned: bool = False
    roll: tuple[int, int] = (0, 0)
    # How far close_cells moved u and v (pixels of the maps; 0 where it kept the lattice's).
    closure: tuple[float, float] = (0.0, 0.0)
    # The cells fill the maps with no room for the margin, which sample_cells fetches a cell in.
    margin_fetched: bool = False

    @property
    def cells(self) -> int:
        """How many lattice cells the tile holds: ``|m₁n₂ − n₁m₂|``."""
        (m1, n1), (m2, n2) = self.counts
        return abs(m1 * n2 - n1 * m2)

    def basis(self) -> Tensor:
        """The lattice vectors ``a``, ``b`` as ``u``, ``v`` and the counts give them (after
        :func:`close_cells`, the closed lattice). Shape: ``(2, 2)`` float64, rows ``a``, ``b``."""
        edges = torch.tensor([self.u, self.v], dtype=torch.float64)
        return torch.linalg.solve(torch.tensor(self.counts, dtype=torch.float64), edges)

    def affine(self) -> Tensor:
        """The linear part of the map from source offsets to output offsets: ``A·u = (W, 0)``,
        ``A·v = (0, H)``. Shape: ``(2, 2)`` float64."""
        height, width = self.size
        edges = torch.tensor([[self.u[0], self.v[0]], [self.u[1], self.v[1]]], dtype=torch.float64)
        scale = torch.diag(torch.tensor([float(width), float(height)], dtype=torch.float64))
        return scale @ torch.linalg.inv(edges)

    def _distortion(self) -> tuple[float, float]:
        stretch, turn = _distortion(
            torch.tensor(self.u, dtype=torch.float64), torch.tensor(self.v, dtype=torch.float64), *self.size
        )
        return float(stretch), float(turn)

    @property
    def stretch(self) -> float:
        """How much the resampling distorts shapes: the log of the ratio of the affine map's
        singular values (0 for a rotation with a uniform scale; 0.05 ≈ 5 % longer one way)."""
        return self._distortion()[0]

    @property
    def turn_deg(self) -> float:
        """How far the resampling turns the pattern, degrees clockwise on screen."""
        return math.degrees(self._distortion()[1])

    def to_json(self) -> dict[str, Any]:
        return {
            "counts": {"u": list(self.counts[0]), "v": list(self.counts[1])},
            "cells": self.cells,
            "u": list(self.u),
            "v": list(self.v),
            "origin": list(self.origin),
            "size": list(self.size),
            "margin": list(self.margin),
            "aligned": self.aligned,
            "roll": list(self.roll),
            "closure_px": list(self.closure),
            "margin_fetched": self.margin_fetched,
            "stretch": self.stretch,
            "turn_deg": self.turn_deg,
        }

    @classmethod
    def from_json(cls, record: dict[str, Any]) -> CellTiling:
        counts = record["counts"]
        return cls(
            counts=((int(counts["u"][0]), int(counts["u"][1])), (int(counts["v"][0]), int(counts["v"][1]))),
            u=_vector(record["u"]),
            v=_vector(record["v"]),
            origin=_vector(record["origin"]),
            size=(int(record["size"][0]), int(record["size"][1])),
            margin=(int(record["margin"][0]), int(record["margin"][1])),
            aligned=bool(record["aligned"]),
            roll=(int(record["roll"][0]), int(record["roll"][1])),
            closure=_vector(record.get("closure_px", (0.0, 0.0))),
            margin_fetched=bool(record.get("margin_fetched", False)),
        )


def _frame_angle(a: Vector, b: Vector) -> float:
    """The turn (radians, in (−π/4, π/4]) that brings the lattice direction nearest an image axis
    onto that axis: of ``a`` and ``b`` the one whose angle modulo 90° is smallest.
    Shape: two ``(dx, dy)`` → radians."""
    turns = []
    for dx, dy in (a, b):
        angle = math.atan2(dy, dx)
        turns.append(angle - (math.pi / 2) * round(angle / (math.pi / 2)))
    return min(turns, key=abs)


def _axis_candidates(
    vectors: Tensor, counts: Tensor, axis: Tensor, extent: tuple[float, float], max_turn_deg: float
) -> tuple[Tensor, Tensor]:
    """The lattice vectors within ``max_turn_deg`` of ``axis`` that fit ``extent`` (the maps'
    ``(W − 1, H − 1)`` less the smallest margin) on their own: of each length (bins of
    :data:`LENGTH_STEP` in the log) the one turned least, so that every size of tile is tried.
    Shape: ``(N, 2)``, ``(N, 2)``, ``(2,)`` → ``(K, 2)``, ``(K, 2)``."""
    along = vectors @ axis
    across = vectors[:, 0] * axis[1] - vectors[:, 1] * axis[0]
    turn = torch.atan2(across.abs(), along)
    keep = (
        (along > 0)
        & (turn <= math.radians(max_turn_deg))
        & (vectors[:, 0].abs() <= extent[0])
        & (vectors[:, 1].abs() <= extent[1])
    )
    vectors, counts, along, turn = vectors[keep], counts[keep], along[keep], turn[keep]
    bins = torch.floor(torch.log(vectors.norm(dim=-1)) / LENGTH_STEP)
    order = torch.argsort(turn)
    order = order[torch.argsort(bins[order], stable=True)]  # by bin, the least turned first
    _, sizes = torch.unique_consecutive(bins[order], return_counts=True)
    firsts = order[torch.cumsum(sizes, 0) - sizes]
    return vectors[firsts], counts[firsts]


def choose_cells(
    vectors: tuple[Vector, Vector],
    height: int,
    width: int,
    *,
    align: bool = False,
    max_turn_deg: float = MAX_TURN_DEG,
) -> CellTiling | None:
    """The whole-cell tile of an ``H × W`` map set with lattice ``vectors`` (module docstring,
    step 4): among the integer combinations ``u`` within ``max_turn_deg`` of the frame's x axis
    and ``v`` of its y axis (the image's axes; with ``align`` turned onto the lattice's direction
    nearest an axis), the pair whose parallelogram, centred, fits in the maps with a margin
    (:data:`MIN_MARGIN` to :data:`MAX_MARGIN` of the side, :data:`MIN_BAND` pixels) and a stretch
    of at most :data:`MAX_STRETCH`, maximising ``log(area / HW) − STRETCH_WEIGHT · stretch −
    TURN_WEIGHT · |turn − frame|``. Where none fits so, the same among pairs of at least two cells
    and at most :data:`FETCH_AREA` of the maps' area, each edge within the maps' side, whatever
    they reach beyond the maps fetched by :func:`sample_cells` (``margin_fetched``; a margin of
    :data:`MIN_MARGIN`). ``None`` where no cell fits either way.

    Shape: two ``(dx, dy)``, sizes → :class:`CellTiling` or ``None``.

    Example:
        A square lattice of 30 pixels in a 100² map: three cells each way (90 pixels, with room
        for the seam's margin), neither stretched nor turned:

        >>> tiling = choose_cells(((30.0, 0.0), (0.0, 30.0)), 100, 100)
        >>> tiling.counts, tiling.cells, round(tiling.stretch, 6), tiling.margin
        (((3, 0), (0, 3)), 9, 0.0, (5, 5))
    """
    a = torch.tensor(vectors[0], dtype=torch.float64)
    b = torch.tensor(vectors[1], dtype=torch.float64)
    area = float(abs(a[0] * b[1] - a[1] * b[0]))
    if not area > 0:
        raise ValueError(f"lattice vectors {vectors} are parallel")
    longest = float(torch.maximum(a.norm(), b.norm()))
    # Coefficients of a reduced basis stay below length × longest / area for vectors that long.
    reach = min(MAX_COUNT, math.ceil(math.hypot(width, height) * longest / area) + 1)
    steps = torch.arange(-reach, reach + 1, dtype=torch.float64)
    mm, nn = torch.meshgrid(steps, steps, indexing="ij")
    counts = torch.stack([mm.flatten(), nn.flatten()], dim=-1)
    combos = counts @ torch.stack([a, b])
    frame = _frame_angle(vectors[0], vectors[1]) if align else 0.0
    x_axis = torch.tensor([math.cos(frame), math.sin(frame)], dtype=torch.float64)
    y_axis = torch.tensor([-math.sin(frame), math.cos(frame)], dtype=torch.float64)
    # First with room for the seam's margin; a coarse lattice then without (what the cells reach
    # beyond the maps fetched): cells of up to the maps' own area.
    room = 1.0 + 2.0 * MIN_MARGIN
    for fetched in (False, True):
        extent = (float(width), float(height)) if fetched else ((width - 1.0) / room, (height - 1.0) / room)
        us, u_counts = _axis_candidates(combos, counts, x_axis, extent, max_turn_deg)
        vs, v_counts = _axis_candidates(combos, counts, y_axis, extent, max_turn_deg)
        if us.shape[0] == 0 or vs.shape[0] == 0:
            continue
        u, v = us.unsqueeze(1), vs.unsqueeze(0)  # (U, 1, 2), (1, V, 2): every pair at once
        cross = (u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]).clamp_min(1e-12)
        stretch, turn = _distortion(u, v, height, width)
        score = (
            torch.log(cross / (height * width))
            - STRETCH_WEIGHT * stretch
            - TURN_WEIGHT * (turn + frame).abs()
        )
        if fetched:
            # Cells of at most the maps' area, wherever they reach (a turned tile's corners are
            # fetched too); a tile of one cell would fetch its margin from its own opposite edge,
            # leaving the seam no choice.
            fits = cross <= FETCH_AREA * height * width * (1.0 + AREA_TOLERANCE)
            uc, vc = u_counts.unsqueeze(1), v_counts.unsqueeze(0)
            fits &= (uc[..., 0] * vc[..., 1] - uc[..., 1] * vc[..., 0]).abs() >= 2
            margin = torch.where(fits, torch.full_like(cross, MIN_MARGIN), torch.full_like(cross, -1.0))
        else:
            margin = _margins(u, v, height, width)
        usable = (margin >= MIN_MARGIN) & (stretch <= MAX_STRETCH)
        usable &= (torch.floor(margin * min(height, width)) >= MIN_BAND) & (cross > 1e-9)
        if bool(usable.any()):
            break
    else:
        return None
    best = int(torch.argmax(torch.where(usable, score, torch.tensor(-math.inf, dtype=score.dtype))))
    i, j = divmod(best, vs.shape[0])
    chosen_u, chosen_v, fraction = us[i], vs[j], float(margin[i, j])
    origin = (
        0.5 * (width - float(chosen_u[0] + chosen_v[0])),
        0.5 * (height - float(chosen_u[1] + chosen_v[1])),
    )
    return CellTiling(
        counts=(_count(u_counts[i]), _count(v_counts[j])),
        u=_vector(chosen_u.tolist()),
        v=_vector(chosen_v.tolist()),
        origin=origin,
        size=(height, width),
        margin=(math.floor(fraction * width), math.floor(fraction * height)),
        aligned=align,
        margin_fetched=fetched,
    )


def _match_features(maps: Tensor, choice: str = ALL_FEATURES) -> tuple[Tensor, Tensor]:
    """The detrended pattern features (the groups ``choice`` names, :data:`FEATURE_CHOICES`) the
    maps are matched against themselves on (at most :data:`DETECT_SIDE` a side), each channel at
    unit spread, and the detection's pixel size. Shape: ``(8, H, W)`` → ``(C, h, w)``, ``(2,)``."""
    features, factor = detection_features(maps)
    features = _detrend(feature_groups(features, choice)[0])
    return features / features.flatten(1).std(dim=1).clamp_min(FEATURE_FLOOR).view(-1, 1, 1), factor


def cell_match(maps: Tensor, vectors: tuple[Vector, Vector], features: str = ALL_FEATURES) -> float:
    """How well the maps' cells match each other: the lesser of their normalised self-correlations
    (:func:`_shift_match`, the pattern ``features`` the lattice was read from) one lattice vector
    on, ``a`` and ``b`` rounded to whole detection pixels. A tiled floor or a brick wall repeats
    its cells (0.45-0.99 on the rendered families and regular scans, square-on or in mild
    perspective); rows of setts whose joints wander do not (0.30-0.36), though their
    autocorrelation shows a weak lattice.

    Shape: ``(8, H, W)``, two ``(dx, dy)`` → a number in [−1, 1].
    """
    check_single_maps(maps)
    matched, factor = _match_features(maps, features)
    step_x, step_y = float(factor[0]), float(factor[1])
    return min(_shift_match(matched, round(dx / step_x), round(dy / step_y)) for dx, dy in vectors)


def _shift_match(features: Tensor, dx: int, dy: int) -> float:
    """The normalised correlation of ``features`` with themselves shifted by ``(dx, dy)`` whole
    pixels (each pixel ``p`` against ``p + (dx, dy)``) over the pixels that have a partner.
    Shape: ``(C, H, W)`` → a number in [−1, 1]."""
    _, height, width = features.shape
    x0, x1 = max(0, -dx), width - max(0, dx)
    y0, y1 = max(0, -dy), height - max(0, dy)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return -1.0
    here = features[:, y0:y1, x0:x1].flatten()
    there = features[:, y0 + dy : y1 + dy, x0 + dx : x1 + dx].flatten()
    here, there = here - here.mean(), there - there.mean()
    return float((here * there).sum() / (here.norm() * there.norm()).clamp_min(1e-12))


def closing_shift(features: Tensor, shift: Vector, reach: int) -> tuple[Vector, float] | None:
    """The sub-pixel shift within ``reach`` whole pixels of ``shift`` at which ``features`` best
    match themselves (:func:`_shift_match` on a grid of whole shifts, then a parabola through the
    best and its neighbours on each axis), and that match; ``None`` where the best lies on the
    search's rim (no peak inside it).

    Shape: ``(C, H, W)``, ``(dx, dy)`` → ``((dx, dy), correlation)`` or ``None``.
    """
    cx, cy = round(shift[0]), round(shift[1])
    span = range(-reach - 1, reach + 2)
    grid = torch.tensor([[_shift_match(features, cx + i, cy + j) for i in span] for j in span])
    row, column = divmod(int(torch.argmax(grid)), len(span))
    if not (0 < row < len(span) - 1 and 0 < column < len(span) - 1):
        return None
    dx = parabola_vertex(*grid[row, column - 1 : column + 2].tolist())
    dy = parabola_vertex(*grid[row - 1 : row + 2, column].tolist())
    return (cx + span[column] + dx, cy + span[row] + dy), float(grid[row, column])


def close_cells(maps: Tensor, tiling: CellTiling, features: str = ALL_FEATURES) -> CellTiling:
    """The tiling with ``u`` and ``v`` moved to the shifts at which the maps match themselves
    (module docstring, step 4b: :func:`closing_shift` over the detrended pattern ``features``, the
    lattice's, on a copy of at most :data:`DETECT_SIDE` a side), re-centred; each kept as the lattice gave it
    where no clear match lies within :data:`CLOSURE_REACH` pixels (at most a quarter of the
    shorter lattice vector, from ``u``, ``v`` and their counts) or the match is under
    :data:`CLOSURE_MIN_MOVE` pixels from it, and both where the cells would no longer fit their
    margin.

    Shape: ``(8, H, W)``, :class:`CellTiling` for them → :class:`CellTiling`.
    """
    check_single_maps(maps)
    height, width = tiling.size
    matched, factor = _match_features(maps, features)
    edges = torch.tensor([tiling.u, tiling.v], dtype=torch.float64) / factor  # detection pixels
    lattice = tiling.basis() / factor
    reach = min(CLOSURE_REACH, math.floor(0.25 * float(lattice.norm(dim=1).min())))
    if reach < 1:
        return tiling
    closed: list[Vector] = []
    for edge, small in zip((tiling.u, tiling.v), edges.tolist(), strict=True):
        found = closing_shift(matched, _vector(small), reach)
        if (
            found is None
            or found[1] < CLOSURE_MIN_CORRELATION
            or math.dist(found[0], small) < CLOSURE_MIN_MOVE
        ):
            closed.append(edge)
        else:
            closed.append(_vector((torch.tensor(found[0], dtype=torch.float64) * factor).tolist()))
    u, v = closed
    room = float(
        _margins(torch.tensor(u, dtype=torch.float64), torch.tensor(v, dtype=torch.float64), height, width)
    )
    if tiling.margin_fetched:
        if room < 0.0:  # the closed cells no longer fit the maps at all
            return tiling
    elif room * width < tiling.margin[0] or room * height < tiling.margin[1]:
        return tiling
    moved = (math.dist(u, tiling.u), math.dist(v, tiling.v))
    origin = (0.5 * (width - u[0] - v[0]), 0.5 * (height - u[1] - v[1]))
    return replace(tiling, u=u, v=v, origin=origin, closure=moved)


def _count(pair: Tensor) -> tuple[int, int]:
    """Shape: ``(2,)`` whole numbers → ``(m, n)`` ints."""
    return (round(float(pair[0])), round(float(pair[1])))


def _margins(u: Tensor, v: Tensor, height: int, width: int) -> Tensor:
    """The largest margin (a fraction of each edge, at most :data:`MAX_MARGIN`) with which the
    parallelogram of ``u`` and ``v``, centred, keeps every sample between the maps' outer pixel
    centres (bilinear needs two); negative where it does not fit at all.

    Shape: ``(*, 2)``, ``(*, 2)`` (broadcast) → ``(*)``.
    """
    zero = torch.zeros_like(u[..., 0] + v[..., 0])
    xs = torch.stack([zero, u[..., 0] + zero, v[..., 0] + zero, u[..., 0] + v[..., 0]])
    ys = torch.stack([zero, u[..., 1] + zero, v[..., 1] + zero, u[..., 1] + v[..., 1]])
    extent_x = (xs.amax(dim=0) - xs.amin(dim=0)).clamp_min(1e-9)
    extent_y = (ys.amax(dim=0) - ys.amin(dim=0)).clamp_min(1e-9)
    # Samples reach from −margin to 1 + margin along each edge.
    room = torch.minimum((width - 1.0) / extent_x, (height - 1.0) / extent_y)
    return (0.5 * (room - 1.0)).clamp_max(MAX_MARGIN)


# Lattice shifts i·a + j·b tried for a sample outside the maps: |i|, |j| up to this.
FOLD_REACH = 3


def fold_inside(px: Tensor, py: Tensor, basis: Tensor, height: int, width: int) -> tuple[Tensor, Tensor]:
    """Sample positions (pixel edges, as :func:`sample_cells` computes them) outside an ``H × W``
    map's pixel centres moved by the shortest lattice vector ``i·a + j·b`` (``|i|, |j| ≤``
    :data:`FOLD_REACH`) that brings them between them: the same place in the nearest cell inside.
    Positions inside, and those no such shift brings in, are kept.

    Shape: ``(*)``, ``(*)`` float64, ``(2, 2)`` rows ``a``, ``b`` → ``(*)``, ``(*)``.
    """

    def inside(x: Tensor, y: Tensor) -> Tensor:
        return (x >= 0.5) & (x <= width - 0.5) & (y >= 0.5) & (y <= height - 0.5)

    outside = ~inside(px, py)
    if not bool(outside.any()):
        return px, py
    steps = torch.arange(-FOLD_REACH, FOLD_REACH + 1, dtype=torch.float64)
    ii, jj = torch.meshgrid(steps, steps, indexing="ij")
    shifts = torch.stack([ii.flatten(), jj.flatten()], dim=-1) @ basis.to(torch.float64)
    shifts = shifts[torch.argsort(shifts.norm(dim=-1), stable=True)][1:]  # shortest first, not zero
    x, y = px[outside], py[outside]
    new_x, new_y = x.clone(), y.clone()
    moved = torch.zeros_like(x, dtype=torch.bool)
    for dx, dy in shifts.tolist():
        take = ~moved & inside(x + dx, y + dy)
        new_x = torch.where(take, x + dx, new_x)
        new_y = torch.where(take, y + dy, new_y)
        moved |= take
        if bool(moved.all()):
            break
    px, py = px.clone(), py.clone()
    px[outside], py[outside] = new_x, new_y
    return px, py


def sample_cells(maps: Tensor, tiling: CellTiling) -> Tensor:
    """The maps resampled so that the tiling's cells fill the output (module docstring, step 5):
    bilinear (``grid_sample``), normals renormalised, with ``margin`` pixels beyond each edge, the
    photo's continuation one period on (where the margin is fetched, :func:`fold_inside`).

    Shape: ``(8, H, W)`` → ``(8, H + 2·my, W + 2·mx)`` in the maps' dtype; output
    ``[my + i, mx + j]`` is tile pixel ``(i, j)``.
    """
    check_single_maps(maps)
    source_h, source_w = maps.shape[-2:]
    height, width = tiling.size
    mx, my = tiling.margin
    # In the maps' own precision: at 2048² every full-size pass is memory-bound, and float32
    # holds a bilinear sample and the seam's costs to far below an 8-bit level.
    work = maps.detach()
    sx = (torch.arange(-mx, width + mx, dtype=torch.float64, device=maps.device) + 0.5) / width
    sy = (torch.arange(-my, height + my, dtype=torch.float64, device=maps.device) + 0.5) / height
    px = tiling.origin[0] + sx.view(1, -1) * tiling.u[0] + sy.view(-1, 1) * tiling.v[0]
    py = tiling.origin[1] + sx.view(1, -1) * tiling.u[1] + sy.view(-1, 1) * tiling.v[1]
    if tiling.margin_fetched:
        px, py = fold_inside(px, py, tiling.basis(), source_h, source_w)
    # align_corners=False: normalised −1 and 1 are the outer edges of the border pixels.
    grid = torch.stack([2.0 * px / source_w - 1.0, 2.0 * py / source_h - 1.0], dim=-1)
    grid = grid.to(work.dtype)  # positions computed in float64, sampled at the maps' precision
    sampled = F.grid_sample(
        work[None], grid[None], mode="bilinear", padding_mode="border", align_corners=False
    )
    parts = split_maps(sampled[0])
    return join_maps(parts.basecolor, normalize_normal(parts.normal), parts.roughness, parts.metallic)


def _cut_wrap_columns(image: Tensor, margin: int, scales: Tensor, row_offset: int, period: int) -> Tensor:
    """One residual seam (module docstring, step 6): ``image`` holds ``margin`` columns beyond each
    edge of a tile ``L`` wide that repeats by ``L``; across the wrap, each row switches once from
    the tile's end to the pixels one period before its start along a minimum-error path through the
    ``2·margin`` columns around it, blended over :data:`FEATHER` pixels. The path is found on the
    ``period`` rows from ``row_offset`` and closes around them; other rows repeat it.

    Shape: ``(C, R, L + 2·margin)`` → ``(C, R, L)``.
    """
    rows, total = image.shape[-2:]
    length = total - 2 * margin
    start = image[..., : 2 * margin]  # positions −margin .. margin − 1 from the tile's first column
    end = image[..., length : length + 2 * margin]  # the same positions one period on
    cost = seam_cost(start, end, scales, MAP_GROUPS)[row_offset : row_offset + period]
    keep = math.ceil(FEATHER)  # the blend stays inside the band, which joins the tile unblended
    path = min_error_path(cost[:, keep : 2 * margin - keep], cyclic=True) + keep
    positions = path[(torch.arange(rows, device=image.device) - row_offset) % period].to(image.dtype)
    centres = torch.arange(2 * margin, dtype=image.dtype, device=image.device) + 0.5
    weight = ((centres.view(1, -1) - positions.view(-1, 1)) / FEATHER + 0.5).clamp(0.0, 1.0)
    band = end + weight * (start - end)  # the end before the path, the start after it
    tile = image[..., margin : margin + length].clone()
    tile[..., length - margin :] = band[..., :margin]
    tile[..., :margin] = band[..., margin:]
    return tile


def cut_wrap(extended: Tensor, margin: tuple[int, int]) -> Tensor:
    """The tile of a resampled map set (:func:`sample_cells`) with both wraps cut (module docstring,
    step 6): the columns, then the rows of that result; normals renormalised after the blend.

    Shape: ``(8, H + 2·my, W + 2·mx)`` → ``(8, H, W)``.
    """
    check_single_maps(extended)
    mx, my = margin
    height = extended.shape[-2] - 2 * my
    scales = map_scales(extended, MAP_GROUPS)
    columns = _cut_wrap_columns(extended, mx, scales, my, height)
    tile = _cut_wrap_columns(columns.transpose(-2, -1), my, scales, 0, columns.shape[-1]).transpose(-2, -1)
    parts = split_maps(tile)
    return join_maps(parts.basecolor, normalize_normal(parts.normal), parts.roughness, parts.metallic)


def period_copied_fraction(
    tiled: Tensor, extended: Tensor, margin: tuple[int, int], tolerance: float = COPY_TOLERANCE
) -> float:
    """:func:`~brdfgan.core.seamless.copied_fraction` for a whole-cell tile: the fraction of its
    pixels within ``tolerance`` (every channel) of the resampled maps at the same place or one
    period (``W``, ``H``) before or after, where the margin has it.

    Shape: ``(C, H, W)``, ``(C, H + 2·my, W + 2·mx)`` → a number in [0, 1].
    """
    channels, height, width = tiled.shape
    mx, my = margin
    check_shape(
        extended, "C H W", name="extended", dims={"C": channels, "H": height + 2 * my, "W": width + 2 * mx}
    )
    copied = torch.zeros(height, width, dtype=torch.bool, device=tiled.device)
    for dy in (-height, 0, height):
        for dx in (-width, 0, width):
            # Tile rows i with my + i + dy inside the extended rows, likewise columns.
            i0, i1 = max(0, -dy - my), min(height, height + my - dy)
            j0, j1 = max(0, -dx - mx), min(width, width + mx - dx)
            if i0 >= i1 or j0 >= j1:
                continue
            copy = extended[:, my + i0 + dy : my + i1 + dy, mx + j0 + dx : mx + j1 + dx]
            close = (tiled[:, i0:i1, j0:j1] - copy).abs().amax(dim=0) <= tolerance
            copied[i0:i1, j0:j1] |= close
    return float(copied.double().mean())


@dataclass(frozen=True)
class CellTile:
    """A whole-cell tile: the tile's maps, the tiling with its ``roll``, the resampled maps it was
    cut from (with the margin), and how it wraps and how much of it is copied (against those)."""

    maps: Tensor
    tiling: CellTiling
    resampled: Tensor
    measures: TilingMeasures


def tile_whole_cells(maps: Tensor, tiling: CellTiling, features: str = ALL_FEATURES) -> CellTile:
    """The tiling closed on the maps (:func:`close_cells` on the pattern ``features``), the maps
    resampled to its whole lattice cells, their wraps cut and the tile rolled to a quiet wrap
    (module docstring, steps 4b–7), in the maps' dtype, with
    :class:`~brdfgan.core.seamless.TilingMeasures` (wrap ratios of the tile; copied fractions
    against the resampled maps, :func:`period_copied_fraction`, which a roll does not change).

    Shape: ``(8, H, W)`` → :class:`CellTile` with ``maps`` ``(8, H, W)``.
    """
    check_single_maps(maps)
    if tuple(maps.shape[-2:]) != tiling.size:
        raise ValueError(f"the tiling is for maps of {tiling.size}, got {tuple(maps.shape[-2:])}")
    tiling = close_cells(maps, tiling, features)
    resampled = sample_cells(maps, tiling)
    tile = cut_wrap(resampled, tiling.margin)
    roll_x = quiet_cut(tile, -1, MAP_GROUPS)
    roll_y = quiet_cut(torch.roll(tile, -roll_x, dims=-1), -2, MAP_GROUPS)
    rolled = torch.roll(tile, (-roll_y, -roll_x), dims=(-2, -1))
    wrap: dict[str, tuple[float, float]] = {}
    copied: dict[str, float] = {}
    for name, after, cut, source in zip(
        MAP_NAMES, file_units(rolled), file_units(tile), file_units(resampled), strict=True
    ):
        wrap[name] = wrap_ratios(after)
        copied[name] = period_copied_fraction(cut, source, tiling.margin)
    rolled_tiling = replace(tiling, roll=(roll_y, roll_x))
    return CellTile(rolled.to(maps.dtype), rolled_tiling, resampled, TilingMeasures(wrap, copied))
