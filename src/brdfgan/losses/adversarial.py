"""Adversarial (LSGAN, Mao et al. 2017) and feature-matching losses (paper §4.1).

Inputs are the outputs of the multi-scale discriminator: ``outputs[k][i]`` is layer ``i`` of
scale ``k`` (D1 at full resolution, D2 at half), and the last layer of each scale is the
patch-score map ``D_k``.

Scales are **averaged**, not summed. The paper's prose says "we sum up the losses from both
scales", but its only formula over scales, the feature-matching loss, carries an explicit 1/S;
averaging both losses keeps them on the same footing (a constant per-scale value gives the same
loss whatever the number of scales) inside the fixed ¼ of the generator total. Summing would
double L_a for the paper's two scales; :func:`reduce_scales` is the one line to change.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

# outputs[scale][layer]; the last layer of each scale is the patch-score map.
DiscriminatorOutputs = Sequence[Sequence[Tensor]]


def reduce_scales(per_scale: Sequence[Tensor]) -> Tensor:
    """Combine per-scale scalar losses: the mean (see the module docstring)."""
    return torch.stack(list(per_scale)).mean()


def _check_outputs(outputs: DiscriminatorOutputs, name: str) -> None:
    if isinstance(outputs, Tensor) or not isinstance(outputs, Sequence) or len(outputs) == 0:
        raise ValueError(f"{name} must be a non-empty list (per scale) of lists (per layer) of tensors")
    for k, scale in enumerate(outputs):
        if isinstance(scale, Tensor) or not isinstance(scale, Sequence) or len(scale) == 0:
            raise ValueError(
                f"{name}[{k}] must be a non-empty list of per-layer tensors, got {type(scale).__name__}"
            )
        if not all(isinstance(t, Tensor) for t in scale):
            raise ValueError(f"{name}[{k}] must contain tensors only")


def _check_pair(real: DiscriminatorOutputs, fake: DiscriminatorOutputs) -> None:
    _check_outputs(real, "real")
    _check_outputs(fake, "fake")
    if len(real) != len(fake):
        raise ValueError(
            f"real and fake outputs have different numbers of scales: {len(real)} and {len(fake)}"
        )


def lsgan_discriminator_loss(real: DiscriminatorOutputs, fake: DiscriminatorOutputs) -> Tensor:
    """L_a(D) = ½·E[(D(real) − 1)²] + ½·E[D(fake)²] on each scale's patch scores, averaged over scales.

    The caller detaches the fake maps before the discriminator forward of the D step, so this
    loss does not reach the generator.

    Shape:
        - real, fake: ``S`` scales × layers, each ``(B, C, H_i, W_i)``; the last layers are scored
        - output: scalar

    Example:
        A perfect discriminator (real scored 1, fake 0) scores 0; one that answers ½ everywhere
        scores ``½·¼ + ½·¼`` on every scale:

        >>> ones, zeros, half = torch.ones(1, 1, 4, 4), torch.zeros(1, 1, 4, 4), torch.full((1, 1, 4, 4), 0.5)
        >>> lsgan_discriminator_loss([[ones]], [[zeros]]).item()
        0.0
        >>> lsgan_discriminator_loss([[half], [half]], [[half], [half]]).item()
        0.25
    """
    _check_pair(real, fake)
    per_scale = [
        0.5 * (r[-1] - 1.0).square().mean() + 0.5 * f[-1].square().mean()
        for r, f in zip(real, fake, strict=True)
    ]
    return reduce_scales(per_scale)


def lsgan_generator_loss(fake: DiscriminatorOutputs) -> Tensor:
    """L_a(G) = ½·E[(D(fake) − 1)²] on each scale's patch scores, averaged over scales.

    Shape:
        - fake: ``S`` scales × layers, each ``(B, C, H_i, W_i)``; the last layers are scored
        - output: scalar

    Example:
        0 when every fake patch is scored real, ½ when every one is caught; scales are averaged:

        >>> ones, zeros = torch.ones(1, 1, 4, 4), torch.zeros(1, 1, 2, 2)
        >>> lsgan_generator_loss([[ones]]).item(), lsgan_generator_loss([[zeros]]).item()
        (0.0, 0.5)
        >>> lsgan_generator_loss([[ones], [zeros]]).item()
        0.25
    """
    _check_outputs(fake, "fake")
    return reduce_scales([0.5 * (f[-1] - 1.0).square().mean() for f in fake])


def feature_matching_loss(
    real: DiscriminatorOutputs, fake: DiscriminatorOutputs, layers: int = 4, detach_real: bool = True
) -> Tensor:
    """L_f = 1/S Σ_k 1/L Σ_i mean((D_k^i(real) − D_k^i(fake))²) over the first ``layers`` layers.

    Args:
        real: discriminator outputs for (photo, true maps).
        fake: discriminator outputs for (photo, predicted maps).
        layers: how many leading layers of each scale are compared (paper: 4).
        detach_real: treat the real features as constants. For the generator they are the target
            it moves towards: they do not depend on the generator, and a gradient through them
            would only reach the discriminator's weights, which the generator step does not update
            (pix2pixHD does the same). The discriminator total passes ``False``: the paper
            minimises L_f over D as a whole (``min_D L_a(D) + λ·L_f``), through both branches.

    Shape:
        - real, fake: ``S`` scales × at least ``layers`` layers, layer shapes matching pairwise
        - output: scalar

    Example:
        Features that differ by 1 everywhere in one of the two compared layers: the mean squared
        difference per layer (1 and 0) averaged over the layers; the third layer is not compared:

        >>> a, b, scores = torch.zeros(1, 8, 4, 4), torch.zeros(1, 16, 2, 2), torch.zeros(1, 1, 2, 2)
        >>> feature_matching_loss([[a, b, scores]], [[a, b, scores]], layers=2).item()
        0.0
        >>> feature_matching_loss([[a, b, scores]], [[a + 1, b, scores + 5]], layers=2).item()
        0.5
    """
    _check_pair(real, fake)
    if layers < 1:
        raise ValueError(f"layers must be at least 1, got {layers}")
    per_scale = []
    for k, (r_scale, f_scale) in enumerate(zip(real, fake, strict=True)):
        if len(r_scale) < layers or len(f_scale) < layers:
            raise ValueError(
                f"scale {k} has {len(r_scale)} real and {len(f_scale)} fake layers, need at least {layers}"
            )
        per_layer = []
        for i in range(layers):
            r, f = r_scale[i], f_scale[i]
            if r.shape != f.shape:
                raise ValueError(
                    f"scale {k} layer {i}: real {tuple(r.shape)} and fake {tuple(f.shape)} differ"
                )
            per_layer.append(((r.detach() if detach_real else r) - f).square().mean())
        per_scale.append(torch.stack(per_layer).mean())
    return reduce_scales(per_scale)
