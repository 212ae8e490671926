"""Parameter loss L_p (paper §4.1): the predicted maps compared directly with the ground truth.

"For every parameter map except the surface normals the MAE is used"; normals use the angular
distance ``acos(a·b)/π``. Maps are compared in their stored encoding
(docs/conventions.md#maps-and-encodings): base color sRGB-encoded, as the paper compares the
parameter maps themselves, not derived quantities.

How the four per-map terms make L_p: the **plain sum of the four per-map means**
(``param = basecolor + normal + roughness + metallic``). Each map counts once whatever its
channel count — a mean over all channels would weight base color (3 channels) three times as
much as roughness, though the paper treats the maps alike and reports their errors separately —
and the paper adds terms up wherever it combines losses ("the content loss is a sum of two
different losses"). The combination is one line in :func:`parameter_loss`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import torch
from torch import Tensor

from brdfgan.core.height import slope_field
from brdfgan.core.svbrdf import check_map_pair, normalize_normal, split_maps

# The dot product is clamped to [-1 + ε, 1 - ε] because d acos(x)/dx = -1/√(1-x²) is infinite at
# x = ±1, which identical (or opposite) normals reach. ε = 1e-6 stays representable next to 1 in
# float32 (spacing 6e-8) and costs little: the loss is flat below an angle of √(2ε) ≈ 0.08°
# (finer than the ≈ 0.45° step of an 8-bit normal map), and identical normals score
# acos(1 - ε)/π ≈ 4.5e-4 instead of 0.
ANGULAR_EPS = 1e-6

PARAMETER_MAPS: tuple[str, ...] = ("basecolor", "normal", "roughness", "metallic")
PARAMETER_TERMS: tuple[str, ...] = tuple(f"param_{name}" for name in PARAMETER_MAPS)

MetallicLoss = Literal["l1", "bce"]
# Predicted metallic values are clamped to [ε, 1 − ε] inside the BCE so log(0) never occurs.
BCE_EPS = 1e-6


def angular_distance(a: Tensor, b: Tensor, dim: int = -3, eps: float = ANGULAR_EPS) -> Tensor:
    """Per-pixel angle between two normal fields divided by π, in [0, 1] (paper: ``acos(a·b)/π``).

    Both inputs are renormalised first, like the renderer does, so the loss measures the normals
    that are shaded and its gradient is tangent to the unit sphere. The computation runs in at
    least float32 so the clamp bound ``1 - eps`` does not round to 1 under reduced precision.

    Args:
        a, b: normal fields, unit vectors along ``dim``.
        dim: the vector axis.
        eps: the dot product is clamped to ``[-1 + eps, 1 - eps]`` (see :data:`ANGULAR_EPS`).

    Shape:
        - a, b: ``(*, 3, H, W)`` (vector axis ``dim``), the same shape
        - output: the input shape without ``dim``, e.g. ``(*, H, W)``

    Example:
        45° is a quarter of π, 90° a half; identical normals score ``acos(1 − ε)/π`` ≈ 4.5e-4
        rather than 0 (the clamp, :data:`ANGULAR_EPS`):

        >>> up = torch.tensor([0.0, 0.0, 1.0])
        >>> round(angular_distance(up, torch.tensor([1.0, 0.0, 1.0]), dim=0).item(), 4)  # renormalised
        0.25
        >>> round(angular_distance(up, torch.tensor([0.0, 1.0, 0.0]), dim=0).item(), 4)
        0.5
        >>> round(angular_distance(up, up, dim=0).item(), 5), round(math.acos(1 - ANGULAR_EPS) / math.pi, 5)
        (0.00045, 0.00045)
        >>> tuple(angular_distance(torch.ones(2, 3, 4, 5), torch.ones(2, 3, 4, 5)).shape)
        (2, 4, 5)
    """
    if not isinstance(a, Tensor) or not isinstance(b, Tensor):
        raise TypeError("angular_distance expects tensors")
    if a.shape != b.shape:
        raise ValueError(f"normal fields must have the same shape, got {tuple(a.shape)} and {tuple(b.shape)}")
    if a.ndim == 0 or a.shape[dim] != 3:
        raise ValueError(f"normal fields need 3 components along dim {dim}, got shape {tuple(a.shape)}")
    if not 0.0 < eps < 1.0:
        raise ValueError(f"eps must lie in (0, 1), got {eps}")
    dtype = torch.promote_types(torch.promote_types(a.dtype, b.dtype), torch.float32)
    a_unit = normalize_normal(a.to(dtype), dim=dim)
    b_unit = normalize_normal(b.to(dtype), dim=dim)
    cosine = (a_unit * b_unit).sum(dim=dim).clamp(-1.0 + eps, 1.0 - eps)
    return torch.acos(cosine) / math.pi


def metallic_bce(pred: Tensor, target: Tensor, eps: float = BCE_EPS) -> Tensor:
    """Binary cross-entropy of predicted metallic probabilities against the (mostly 0/1) truth,
    per texel, in at least float32 (autocast must not run it in half precision).

    Why an alternative to the paper's L1: L1's minimiser is the conditional *median*, which for a
    map that is 0 on most texels and 1 on some is 0 wherever the photo leaves doubt — a network
    trained with it predicts no metal at all when metals are hard to tell, scoring worse in RMSE
    than the constant mean. Cross-entropy's minimiser is the conditional probability (the mean),
    and its gradient with respect to the sigmoid's logit, ``p − t``, does not vanish when a
    prediction is confidently wrong.

    Shape:
        - pred, target: ``(*, 1, H, W)`` in [0, 1]
        - output: same
    """
    dtype = torch.promote_types(pred.dtype, torch.float32)
    p = pred.to(dtype).clamp(eps, 1.0 - eps)
    t = target.to(dtype)
    return -(t * torch.log(p) + (1.0 - t) * torch.log1p(-p))


def tilt_squared_error(pred: Tensor, target: Tensor) -> Tensor:
    """Squared difference of the surface slopes (:func:`~brdfgan.core.height.slope_field`) of two
    normal fields, per pixel (summed over the two slopes), in at least float32.

    Why beside the angular distance: an angle is an L1-type error, minimised by the conditional
    *median*; where the photo leaves a tilt uncertain — and a quarter of the training texels are
    flat — that median is exactly flat, so the network's normals collapse to flat first and learn
    slowly after (the normal-only runs: ``research/notes/2026-12-default-model-v3.md``, "The maps
    were not where the photos showed them"). Squared error targets the conditional mean, whose
    gradient grows with the miss.

    Shape:
        - pred, target: ``(*, 3, H, W)``, unit normals with z > 0
        - output: ``(*, H, W)``
    """
    dtype = torch.promote_types(torch.promote_types(pred.dtype, target.dtype), torch.float32)
    return (slope_field(pred.to(dtype)) - slope_field(target.to(dtype))).square().sum(dim=-3)


def parameter_loss(
    pred: Tensor,
    target: Tensor,
    metallic: MetallicLoss = "l1",
    normal_tilt_weight: float = 0.0,
    maps: Sequence[str] = PARAMETER_MAPS,
) -> dict[str, Tensor]:
    """The paper's L_p and its per-map parts: L1 on base color, roughness and metallic, mean
    angular distance on the normals.

    Args:
        pred, target: predicted and true maps.
        metallic: ``"l1"`` (the paper) or ``"bce"`` (:func:`metallic_bce`) for the metallic term.
        normal_tilt_weight: when positive, ``param_normal`` also adds this times the mean
            :func:`tilt_squared_error` (not the paper's; 0 leaves the paper's term).
        maps: the maps whose terms ``param`` sums (all four: the paper's L_p); a subset trains
            those maps alone, e.g. ``("normal",)`` for a stage that learns the normals first.

    Returns:
        ``param_basecolor``, ``param_normal``, ``param_roughness``, ``param_metallic`` (scalars,
        all four whatever ``maps``, to be logged) and ``param`` = L_p, the sum of those ``maps``
        names (see the module docstring).

    Shape:
        - pred, target: ``(*, 8, H, W)`` in the layout of :mod:`brdfgan.core.svbrdf`
        - output: scalars

    Example:
        Base color off by 0.1 in every channel, normals tilted by 45°, roughness off by 0.2 and
        metal for dielectric: each map counts once in the sum, 0.1 + 0.25 + 0.2 + 1:

        >>> from brdfgan.core.svbrdf import flat_maps
        >>> target = flat_maps(2, 2, basecolor=(0.5, 0.5, 0.5), roughness=0.7, metallic=0.0)
        >>> pred = flat_maps(2, 2, basecolor=(0.6, 0.6, 0.6), roughness=0.5, metallic=1.0)
        >>> pred[3:6] = torch.tensor([1.0, 0.0, 1.0]).view(3, 1, 1) / math.sqrt(2.0)
        >>> for name, value in parameter_loss(pred, target).items():
        ...     print(name, round(value.item(), 4))
        param_basecolor 0.1
        param_normal 0.25
        param_roughness 0.2
        param_metallic 1.0
        param 1.55
    """
    check_map_pair(pred, target)
    if metallic not in ("l1", "bce"):
        raise ValueError(f"metallic must be 'l1' or 'bce', got {metallic!r}")
    if not normal_tilt_weight >= 0.0:
        raise ValueError(f"normal_tilt_weight must be >= 0, got {normal_tilt_weight}")
    if not maps or not set(maps) <= set(PARAMETER_MAPS):
        raise ValueError(f"maps must be a non-empty subset of {PARAMETER_MAPS}, got {tuple(maps)}")
    p, t = split_maps(pred), split_maps(target)
    metallic_term = (
        metallic_bce(p.metallic, t.metallic) if metallic == "bce" else (p.metallic - t.metallic).abs()
    )
    terms = {
        "param_basecolor": (p.basecolor - t.basecolor).abs().mean(),
        "param_normal": angular_distance(p.normal, t.normal).mean(),
        "param_roughness": (p.roughness - t.roughness).abs().mean(),
        "param_metallic": metallic_term.mean(),
    }
    if normal_tilt_weight > 0.0:
        terms["param_normal"] = terms["param_normal"] + normal_tilt_weight * (
            tilt_squared_error(p.normal, t.normal).mean()
        )
    counted = [terms[f"param_{name}"] for name in PARAMETER_MAPS if name in maps]
    terms["param"] = sum(counted[1:], counted[0])
    return terms
