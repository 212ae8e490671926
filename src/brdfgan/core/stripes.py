"""1-D patterns for ``--tileable``: stripes, planks, courses of bricks and rows of setts repeat across
one direction only, and a tile keeps them whole when its wraps shift them by whole periods.

A 1-D pattern has no isolated peak in its autocorrelation ρ (:func:`~brdfgan.core.lattice.autocorrelation`),
so :func:`~brdfgan.core.lattice.find_lattice` finds no 2-D lattice: ρ has a *ridge* through the
origin along the stripes (the maps shifted along them still match themselves) and parallel ridges
one period ``p`` apart across them. :func:`find_stripes` reads both from ρ of the detection features
(:func:`~brdfgan.core.lattice.detection_features`):

1. **Direction**: the mean of ρ along each line through the origin (lags from
   :data:`~brdfgan.core.lattice.MIN_PERIOD` to :data:`RIDGE_REACH` of the shorter side, every
   :data:`RIDGE_STEP_DEG`); the stripes run along the highest, which must reach
   :data:`RIDGE_LEVEL` (the rendered 1-D materials 0.19-0.77; non-periodic ones at most 0.13).
2. **Period**: the *across profile*, ρ along the normal ``n`` averaged over a band of lags along the
   stripes; its local maxima are the periods' multiples. The period is the shortest maximum that
   reaches :data:`RELATIVE_PEAK` of the highest and stands :data:`ACROSS_PROMINENCE` above the
   lowest point before it (planks' grooves a few pixels apart with a deeper gap every fifth take
   the grooves' period when the two are close in height, the planks' when the gaps dominate); it is
   refined by a parabola through each multiple's peak that reaches half its height and a least
   squares fit through the origin, which averages a photo's drift.
3. **Mild perspective** (:func:`find_stripe_perspective`): as for a lattice
   (:func:`~brdfgan.core.lattice.find_perspective`), the stripes are measured again in a 3 × 3 grid
   of overlapping windows, each holding :data:`WINDOW_PERIODS` periods, and a homography about the
   centre is fitted to how their frequency ``n / p`` changes (:func:`fit_stripe_perspective`); the
   maps are rectified through it where it explains the windows. Each window's direction is read
   across its ridge (:func:`ridge_direction`), so that the slight convergence of level stripes, the
   only sign there of the scale change along them, is seen.

The maps then tile as a 2-D lattice would (:func:`~brdfgan.core.lattice.choose_cells`,
:func:`~brdfgan.core.lattice.tile_whole_cells`) on the vectors ``p·n`` and ``p·d``
(:meth:`Stripes.cell_vectors`, ``d`` along the stripes): any shift along the stripes keeps them
whole, so ``p·d`` only sets the step in which the tile's edges are chosen (a step of a quarter
period gave wood planks turned 30° a tile stretched by 7.1 % where whole periods gave 0.3 %: the
finer choice traded stretch for area), and the residual seam of each wrap
(:func:`~brdfgan.core.lattice.cut_wrap`) runs where the texture along the stripes (grain, joints)
agrees.

Vectors are ``(dx, dy)`` in pixels of the maps, ``x`` to the right, ``y`` down (rows).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from brdfgan.core.lattice import (
    MIN_PERIOD,
    CellTiling,
    Perspective,
    Vector,
    autocorrelation,
    check_single_maps,
    choose_cells,
    detection_features,
    parabola_vertex,
    perspective_of_fit,
    perspective_windows,
    sample_rho,
)

RIDGE_STEP_DEG = 0.25
RIDGE_REACH = 0.35
RIDGE_LEVEL = 0.15
RELATIVE_PEAK = 0.5
ACROSS_PROMINENCE = 0.1
# The across profile's band: lags along the stripes up to this share of RIDGE_REACH either way.
BAND_SHARE = 0.5
# Mild perspective (find_stripe_perspective): windows of at least WINDOW_PERIODS periods (a share of
# the side from 1/2 to 3/4), each window's direction read within DIRECTION_REACH_DEG of the stripes'
# every DIRECTION_STEP_DEG and its period within PERIOD_REACH of theirs.
WINDOW_PERIODS = 2.5
WINDOW_SHARE = (0.5, 0.75)
DIRECTION_REACH_DEG = 3.0
DIRECTION_STEP_DEG = 0.1
PERIOD_REACH = 0.2
# With --align-pattern, the tile's edges turn at most this far from the stripes and their normal.
ALIGNED_TURN_DEG = 1.0
# Each period holds at least this many times across the maps' shorter side (else there is nothing
# to tile by).
MIN_PERIODS = 3.0


@dataclass(frozen=True)
class Stripes:
    """What :func:`find_stripes` found: ``across``, one period across the stripes (``p·n``, pointing
    down or right), ``along``, the stripes' unit direction (``d``, ``across × along > 0``), both in the maps'
    pixels; ``ridge``, the mean of ρ along the stripes; ``peak``, the across profile at the period."""

    across: Vector
    along: Vector
    ridge: float
    peak: float

    @property
    def period(self) -> float:
        return math.hypot(*self.across)

    @property
    def direction_deg(self) -> float:
        """The stripes' direction, clockwise on screen from +x, in ``[0, 180)``."""
        return math.degrees(math.atan2(self.along[1], self.along[0])) % 180.0

    def cell_vectors(self) -> tuple[Vector, Vector]:
        """The pseudo-lattice the maps tile on (module docstring): ``p·n`` and ``p·d``."""
        p = self.period
        return self.across, (p * self.along[0], p * self.along[1])

    def to_json(self) -> dict[str, Any]:
        return {
            "across": list(self.across),
            "along": list(self.along),
            "period_px": self.period,
            "direction_deg": self.direction_deg,
            "ridge": self.ridge,
            "peak": self.peak,
            "ridge_threshold": RIDGE_LEVEL,
        }

    @classmethod
    def from_json(cls, record: dict[str, Any]) -> Stripes:
        across, along = record["across"], record["along"]
        return cls(
            across=(float(across[0]), float(across[1])),
            along=(float(along[0]), float(along[1])),
            ridge=float(record["ridge"]),
            peak=float(record["peak"]),
        )


def choose_stripe_cells(
    stripes: Stripes, height: int, width: int, *, align: bool = False
) -> CellTiling | None:
    """The whole-period tile of an ``H × W`` map set with ``stripes``
    (:func:`~brdfgan.core.lattice.choose_cells` on :meth:`Stripes.cell_vectors`). With ``align``
    (``--align-pattern``) the tile's edges keep within :data:`ALIGNED_TURN_DEG` of the stripes and
    their normal: the stripes come out along an axis, where the lattice's wider choice (up to
    :data:`~brdfgan.core.lattice.MAX_TURN_DEG` off) left planks at 30° turned by 20.5° only.

    Shape: sizes → :class:`~brdfgan.core.lattice.CellTiling` or ``None``.
    """
    if align:
        return choose_cells(stripes.cell_vectors(), height, width, align=True, max_turn_deg=ALIGNED_TURN_DEG)
    return choose_cells(stripes.cell_vectors(), height, width)


def ridge_means(rho: Tensor, reach: float, angles: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """The mean of ρ along lines through the origin, lags ``MIN_PERIOD..reach`` pixels, at
    ``angles`` (degrees clockwise on screen from +x; default every :data:`RIDGE_STEP_DEG` from 0 to
    180°).

    Shape: ``(2H, 2W)``, ``(A,)`` → ``(A,)`` angles in degrees, ``(A,)`` means.
    """
    if angles is None:
        angles = torch.arange(0.0, 180.0, RIDGE_STEP_DEG, dtype=rho.dtype)
    radians = torch.deg2rad(angles)
    directions = torch.stack([torch.cos(radians), torch.sin(radians)], dim=-1)
    distances = torch.arange(MIN_PERIOD, max(reach, MIN_PERIOD + 1.0), 1.0, dtype=rho.dtype)
    return angles, sample_rho(rho, directions[:, None, :] * distances[None, :, None]).mean(dim=-1)


def _stripe_axes(direction_deg: float, like: Tensor) -> tuple[Tensor, Tensor]:
    """The unit vectors along stripes at ``direction_deg`` and across them (``n``, the along
    vector turned +90°), in ``like``'s dtype. Shape: → ``(2,)``, ``(2,)``."""
    radians = math.radians(direction_deg)
    along = torch.tensor([math.cos(radians), math.sin(radians)], dtype=like.dtype)
    return along, torch.tensor([-math.sin(radians), math.cos(radians)], dtype=like.dtype)


def across_profile(
    rho: Tensor, direction_deg: float, reach: float, step: float = 0.5
) -> tuple[Tensor, Tensor]:
    """ρ across the stripes: at offsets ``s`` along the normal ``n`` (``0..reach`` every ``step``),
    averaged over lags along the stripes within ``BAND_SHARE · reach`` either way.

    Shape: ``(2H, 2W)`` → ``(S,)`` offsets, ``(S,)`` values.
    """
    along, normal = _stripe_axes(direction_deg, rho)
    offsets = torch.arange(0.0, reach, step, dtype=rho.dtype)
    band = BAND_SHARE * reach
    shifts = torch.arange(-band, band + 0.5, 1.0, dtype=rho.dtype)
    lags = offsets[:, None, None] * normal + shifts[None, :, None] * along
    return offsets, sample_rho(rho, lags).mean(dim=-1)


def _local_maxima(values: Tensor) -> list[int]:
    return [
        k for k in range(1, values.shape[0] - 1) if values[k] >= values[k - 1] and values[k] > values[k + 1]
    ]


def _parabola_peak(offsets: Tensor, values: Tensor, k: int) -> float:
    """The offset of a maximum at index ``k`` of evenly spaced ``offsets``, refined by a parabola
    through it and its neighbours (:func:`~brdfgan.core.lattice.parabola_vertex`)."""
    shift = parabola_vertex(*(float(values[i]) for i in (k - 1, k, k + 1)))
    return float(offsets[k]) + shift * float(offsets[1] - offsets[0])


def stripe_period(offsets: Tensor, values: Tensor) -> tuple[float, float] | None:
    """The period of an across profile (module docstring, step 2) and the profile's value there, or
    ``None`` where no maximum qualifies.

    Shape: ``(S,)``, ``(S,)`` → period in the offsets' units, value.

    Example:
        A profile with a maximum every 10 offsets:

        >>> s = torch.arange(0.0, 60.0, 0.5)
        >>> period, value = stripe_period(s, torch.cos(2 * math.pi * s / 10.0))
        >>> round(period, 3), round(value, 3)
        (10.0, 1.0)
    """
    peaks = _local_maxima(values)
    maxima = [k for k in peaks if float(offsets[k]) >= MIN_PERIOD]
    if not maxima:
        return None
    highest = max(float(values[k]) for k in maxima)
    chosen = None
    for k in maxima:
        height = float(values[k])
        lowest = float(values[: k + 1].min())
        if height >= RELATIVE_PEAK * highest and height - lowest >= ACROSS_PROMINENCE:
            chosen = k
            break
    if chosen is None:
        return None
    period, value = _parabola_peak(offsets, values, chosen), float(values[chosen])
    # Each further multiple whose peak reaches half the period's height refines it: s_m ≈ m·p.
    multiples, positions = [1.0], [period]
    reach = float(offsets[-1])
    for m in range(2, int(reach / period) + 1):
        near = [k for k in peaks if abs(float(offsets[k]) - m * period) <= 0.25 * period]
        if not near:
            continue
        best = max(near, key=lambda k: float(values[k]))
        if float(values[best]) >= 0.5 * value:
            multiples.append(float(m))
            positions.append(_parabola_peak(offsets, values, best))
    m_values = torch.tensor(multiples, dtype=torch.float64)
    s_values = torch.tensor(positions, dtype=torch.float64)
    return float((m_values * s_values).sum() / m_values.square().sum()), value


def find_stripes(maps: Tensor) -> Stripes | None:
    """The maps' 1-D pattern (module docstring), or ``None``: no ridge of :data:`RIDGE_LEVEL`, no
    period across it, or fewer than :data:`MIN_PERIODS` periods across the maps.

    Shape: ``(8, H, W)`` → :class:`Stripes` or ``None``.
    """
    check_single_maps(maps)
    features, factor = detection_features(maps)
    small_h, small_w = features.shape[-2:]
    rho = autocorrelation(features)
    reach = RIDGE_REACH * min(small_h, small_w)
    angles, means = ridge_means(rho, reach)
    best = int(torch.argmax(means))
    ridge = float(means[best])
    if not ridge >= RIDGE_LEVEL:
        return None
    direction = float(angles[best])
    found = stripe_period(*across_profile(rho, direction, reach))
    if found is None:
        return None
    period, peak = found
    radians = math.radians(direction)
    # In the maps' pixels (the features may be shrunk, by factor per axis).
    fx, fy = float(factor[0]), float(factor[1])
    across = (-math.sin(radians) * period * fx, math.cos(radians) * period * fy)
    along_x, along_y = math.cos(radians) * fx, math.sin(radians) * fy
    length = math.hypot(along_x, along_y)
    if across[1] < 0 or (across[1] == 0 and across[0] < 0):
        across = (-across[0], -across[1])
    along = (along_x / length, along_y / length)
    if across[0] * along[1] - across[1] * along[0] < 0:
        along = (-along[0], -along[1])
    height, width = maps.shape[-2:]
    if MIN_PERIODS * math.hypot(*across) > min(height, width):
        return None
    return Stripes(across=across, along=along, ridge=ridge, peak=peak)


def ridge_direction(rho: Tensor, direction_deg: float, reach: float) -> float:
    """The ridge's direction refined from ``direction_deg``: across the ridge through the origin,
    at every whole lag ``t`` from :data:`MIN_PERIOD` to ``reach`` along it, the sub-pixel offset of
    ρ's maximum (a parabola through the samples one pixel either side), and the line through the
    origin that fits those offsets. A mean along each line (:func:`ridge_means`) favours lines on
    the pixel grid, where bilinear sampling does not blur ρ, and cannot see a stripe's tilt of a
    few tenths of a degree in a window (the convergence of level stripes in perspective); the
    offsets across the ridge do.

    Shape: ``(2H, 2W)`` → degrees.
    """
    along, normal = _stripe_axes(direction_deg, rho)
    steps = torch.arange(MIN_PERIOD, max(reach, MIN_PERIOD + 1.0), 1.0, dtype=rho.dtype)
    across = torch.tensor([-1.0, 0.0, 1.0], dtype=rho.dtype)
    lags = steps[:, None, None] * along + across[None, :, None] * normal
    samples = sample_rho(rho, lags)  # (T, 3)
    offsets = torch.tensor([parabola_vertex(*row) for row in samples.tolist()], dtype=rho.dtype)
    slope = float((steps * offsets).sum() / steps.square().sum())
    return direction_deg + math.degrees(math.atan(slope))


def window_frequency(window: Tensor, direction_deg: float, period: float) -> Tensor | None:
    """The stripes' spatial frequency ``n / p`` (cycles per pixel, ``n`` their unit normal) in one
    window of detection features, read near the maps' ``direction_deg`` and ``period`` (module
    docstring of :func:`find_stripe_perspective`); ``None`` where the window shows no peak near the
    period.

    Shape: ``(C, h, w)`` → ``(2,)`` float64 or ``None``.
    """
    rho = autocorrelation(window)
    height, width = window.shape[-2:]
    reach = RIDGE_REACH * min(height, width)
    angles, means = ridge_means(
        rho,
        reach,
        torch.arange(
            direction_deg - DIRECTION_REACH_DEG,
            direction_deg + DIRECTION_REACH_DEG + 0.5 * DIRECTION_STEP_DEG,
            DIRECTION_STEP_DEG,
            dtype=rho.dtype,
        ),
    )
    best = min(max(int(torch.argmax(means)), 1), angles.shape[0] - 2)
    direction = ridge_direction(rho, _parabola_peak(angles, means, best), reach)
    offsets, values = across_profile(
        rho, direction, min(0.5 * min(height, width), (1 + 3 * PERIOD_REACH) * period)
    )
    near = [k for k in _local_maxima(values) if abs(float(offsets[k]) - period) <= PERIOD_REACH * period]
    if not near:
        return None
    found = _parabola_peak(offsets, values, max(near, key=lambda k: float(values[k])))
    radians_found = math.radians(direction)
    return torch.tensor([-math.sin(radians_found), math.cos(radians_found)], dtype=torch.float64) / found


def fit_stripe_perspective(centres: Tensor, frequencies: Tensor) -> tuple[Tensor, Tensor, float, float]:
    """The perspective ``g`` and the rectified frequency ``k`` that explain the stripes' frequency
    measured around the maps. A phase ``k·r`` on the rectified plane, seen through
    ``r = d / (1 + g·d)``, has the image gradient ``Jᵀ k``, to first order in ``g``
    ``k − (k dᵀ + (d·k) I) g`` at offset ``d`` (a frequency is a covector: it shrinks where the
    lattice's vectors grow, :func:`~brdfgan.core.lattice.fit_perspective`); solved by least squares
    with the measured frequencies in the bracket; with the spreads of the frequencies about one
    (``g = 0``) and about the model.

    Shape: centres ``(K, 2)``, frequencies ``(K, 2)`` → ``g`` ``(2,)``, ``k`` ``(2,)``, two floats.

    Example:
        Stripes across x every 10 px whose period grows by 2 % towards the right (±100 px):

        >>> f64 = torch.float64
        >>> centres = 100.0 * torch.tensor([[-1.0, 0], [1, 0], [0, -1], [0, 1], [0, 0]], dtype=f64)
        >>> g_true = torch.tensor([2e-4, 0.0], dtype=f64)
        >>> k = torch.tensor([0.1, 0.0], dtype=f64)
        >>> def seen_at(d):  # the gradient of k·r(d), r = d / (1 + g·d)
        ...     w = 1 + g_true @ d
        ...     jacobian = (torch.eye(2, dtype=f64) * w - torch.outer(d, g_true)) / w**2
        ...     return jacobian.T @ k
        >>> seen = torch.stack([seen_at(d) for d in centres])
        >>> g, _, before, after = fit_stripe_perspective(centres, seen)
        >>> [round(v * 1e4, 2) + 0.0 for v in g.tolist()], after < 0.05 * before
        ([2.0, 0.0], True)
    """
    eye = torch.eye(2, dtype=frequencies.dtype)
    rows = []
    for d, k in zip(centres, frequencies, strict=True):
        block = torch.zeros(2, 4, dtype=frequencies.dtype)
        block[:, :2] = -(torch.outer(k, d) + (d @ k) * eye)
        block[:, 2:] = eye
        rows.append(block)
    design, target = torch.cat(rows), frequencies.reshape(-1)
    solution = torch.linalg.lstsq(design, target[:, None]).solution[:, 0]
    spread_before = float((frequencies - frequencies.mean(dim=0)).square().sum(dim=-1).mean().sqrt())
    spread_after = float((design @ solution - target).view(-1, 2).square().sum(dim=-1).mean().sqrt())
    return solution[:2], solution[2:], spread_before, spread_after


def find_stripe_perspective(maps: Tensor, stripes: Stripes) -> Perspective | None:
    """The maps' mild perspective from how their stripes' frequency changes across them, as
    :func:`~brdfgan.core.lattice.find_perspective` finds it from a lattice: in a 3 × 3 grid of
    windows holding :data:`WINDOW_PERIODS` periods, each window's direction and period
    (:func:`window_frequency`), a homography about the centre fitted to them
    (:func:`fit_stripe_perspective`); ``None`` where a window shows no period, where the windows
    cannot hold enough periods, or where the keystone or the fit's gain are outside the lattice's
    limits (:func:`~brdfgan.core.lattice.perspective_of_fit`). The spreads are converted to pixels
    of the period (``δp ≈ p² δk``).

    Shape: ``(8, H, W)`` → :class:`~brdfgan.core.lattice.Perspective` or ``None``.
    """
    check_single_maps(maps)
    features, factor = detection_features(maps)
    small_h, small_w = features.shape[-2:]
    fx, fy = float(factor[0]), float(factor[1])
    period = stripes.period / math.sqrt(fx * fy)
    share = max(WINDOW_SHARE[0], WINDOW_PERIODS * period / min(small_h, small_w))
    if share > WINDOW_SHARE[1]:
        return None
    height, width = maps.shape[-2:]
    centres, frequencies = [], []
    for window, centre in perspective_windows(features, factor, share, (height, width)):
        frequency = window_frequency(window, stripes.direction_deg, period)
        if frequency is None:
            return None
        # Feature pixels to the maps' (a frequency scales inversely).
        frequencies.append(frequency / torch.tensor([fx, fy], dtype=torch.float64))
        centres.append(centre)
    g, _, before, after = fit_stripe_perspective(
        torch.tensor(centres, dtype=torch.float64), torch.stack(frequencies)
    )
    to_px = stripes.period**2
    return perspective_of_fit(g, (height, width), before * to_px, after * to_px)[0]
