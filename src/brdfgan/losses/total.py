"""Total losses (paper §4.1) and :class:`GANLoss`, which computes only the switched-on terms.

Generator: ``L_t(G) = ¼·(L_a(G) + L_f + L_p + L_r)``. The ¼ stays fixed when a term is switched
off, so an ablation changes exactly one term and leaves the weight of the others as in the full
loss (renormalising to ⅓ would also scale up the remaining three, a second change at once).

Discriminator: ``L_t(D) = L_a(D) + λ·L_f`` with λ = 0.01. The switches name the *generator's*
terms; the discriminator is trained whenever one of them needs it (``needs_discriminator``),
always with L_a(D), plus λ·L_f when the feature term is on.

Who detaches what (the training module): the D step feeds the discriminator
``pred_maps.detach()``, so ``d_total`` does not reach the generator; the G step feeds it the
live predictions and may compute the real outputs under ``torch.no_grad()`` (they are targets).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from torch import Tensor, nn
from torch.profiler import record_function

from brdfgan.core.sampling import RenderingLossSampling
from brdfgan.errors import UserError
from brdfgan.losses.adversarial import (
    DiscriminatorOutputs,
    feature_matching_loss,
    lsgan_discriminator_loss,
    lsgan_generator_loss,
)
from brdfgan.losses.parameter import PARAMETER_MAPS, MetallicLoss, parameter_loss
from brdfgan.losses.rendering import RenderingLoss, RenderPairing

GENERATOR_WEIGHT = 0.25  # the paper's ¼
FEATURE_WEIGHT = 0.01  # the paper's λ in the discriminator total
FEATURE_LAYERS = 4  # "the first four layers from each of the two discriminators"


@dataclass(frozen=True)
class LossSwitches:
    """Which generator terms are on; a term that is off is not computed at all."""

    adversarial: bool = True
    feature: bool = True
    parameter: bool = True
    rendering: bool = True

    def __post_init__(self) -> None:
        if not self.enabled_terms:
            raise ValueError("at least one generator loss term must be switched on")

    @property
    def needs_discriminator(self) -> bool:
        """Whether any term uses discriminator outputs (and so a discriminator must train)."""
        return self.adversarial or self.feature

    @property
    def enabled_terms(self) -> tuple[str, ...]:
        """Names of the switched-on generator terms, among ``g_adv``, ``g_feat``, ``param``, ``render``."""
        flags = {
            "g_adv": self.adversarial,
            "g_feat": self.feature,
            "param": self.parameter,
            "render": self.rendering,
        }
        return tuple(name for name, on in flags.items() if on)


def generator_total(
    terms: Mapping[str, Tensor], switches: LossSwitches = LossSwitches(), weight: float = GENERATOR_WEIGHT
) -> Tensor:
    """``weight · Σ`` of the switched-on terms among ``g_adv``, ``g_feat``, ``param``, ``render``.

    Other entries of ``terms`` (per-map parts, switched-off terms) are ignored.

    Shape:
        - terms: scalars
        - output: scalar

    Example:
        Four terms of 1 make 1; with the rendering term off the ¼ stays, so three make ¾:

        >>> import torch
        >>> terms = {name: torch.tensor(1.0) for name in ("g_adv", "g_feat", "param", "render")}
        >>> generator_total(terms).item()
        1.0
        >>> generator_total(terms, LossSwitches(rendering=False)).item()
        0.75
    """
    names = switches.enabled_terms
    missing = [name for name in names if name not in terms]
    if missing:
        raise KeyError(f"switched-on generator terms missing from terms: {', '.join(missing)}")
    total = sum((terms[name] for name in names[1:]), terms[names[0]])
    return weight * total


def discriminator_total(
    d_adv: Tensor, d_feat: Tensor | None = None, feature_weight: float = FEATURE_WEIGHT
) -> Tensor:
    """``L_a(D) + λ·L_f``; without a feature term (``d_feat is None``) just ``L_a(D)``.

    Shape:
        - d_adv, d_feat: scalars
        - output: scalar

    Example:
        >>> import torch
        >>> round(discriminator_total(torch.tensor(0.5), torch.tensor(2.0)).item(), 4)  # 0.5 + 0.01 · 2
        0.52
        >>> discriminator_total(torch.tensor(0.5)).item()
        0.5
    """
    return d_adv if d_feat is None else d_adv + feature_weight * d_feat


class GANLoss(nn.Module):
    """All loss terms of the paper behind switches; only the switched-on terms are computed.
    Which terms are on is a recipe's choice (``conf/loss/``); each term's own options default to
    the shipped model's (``metallic_loss="bce"``, ``rendering_pairing="cross"``), the paper's are
    set by ``conf/loss/full.yaml``.

    A renderer exists only when the rendering term is on, and nothing asks for discriminator
    outputs unless ``switches.needs_discriminator``.

    Args:
        switches: which generator terms are on.
        rendering_sampling: how the rendering-loss configurations are drawn.
        seed: seed of the rendering-loss configurations (see :class:`RenderingLoss` for DDP).
        plane_half_size: half the side of the sample square.
        compile: render through ``torch.compile``.
        feature_layers: leading discriminator layers compared by feature matching.
        weight: the generator total's factor (paper: ¼).
        feature_weight: λ of the discriminator total (paper: 0.01).
        metallic_loss: the parameter loss's metallic term, ``"bce"`` (shipped; see
            :func:`~brdfgan.losses.parameter.metallic_bce`) or ``"l1"`` (the paper).
        normal_tilt_weight: weight of the squared slope error added to the normal term (0, the
            paper: none; see :func:`~brdfgan.losses.parameter.tilt_squared_error`).
        parameter_maps: the maps the parameter term trains (all four: the paper); with
            ``("normal",)`` and no other term the generator learns the normals alone (a first
            stage; the other maps' terms are still reported).
        rendering_pairing: ``"cross"`` (shipped) or ``"joint"`` (the paper): which maps are
            rendered together (see :func:`~brdfgan.losses.rendering.cross_paired`).
    """

    def __init__(
        self,
        switches: LossSwitches = LossSwitches(),
        rendering_sampling: RenderingLossSampling = RenderingLossSampling(),
        seed: int = 0,
        plane_half_size: float = 1.0,
        compile: bool = False,
        feature_layers: int = FEATURE_LAYERS,
        weight: float = GENERATOR_WEIGHT,
        feature_weight: float = FEATURE_WEIGHT,
        metallic_loss: MetallicLoss = "bce",
        normal_tilt_weight: float = 0.0,
        rendering_pairing: RenderPairing = "cross",
        parameter_maps: Sequence[str] = PARAMETER_MAPS,
    ) -> None:
        super().__init__()
        if rendering_pairing not in ("joint", "cross"):
            raise UserError(f"loss.rendering_pairing={rendering_pairing!r}: must be 'joint' or 'cross'")
        if rendering_pairing == "cross" and rendering_sampling.num_configs % 2:
            raise UserError(
                f"loss.rendering_pairing=cross: needs an even number of rendering configurations, "
                f"loss.rendering_sampling gives {rendering_sampling.num_configs}"
            )
        if not normal_tilt_weight >= 0.0:
            raise UserError(f"loss.normal_tilt_weight={normal_tilt_weight}: must be >= 0")
        self.normal_tilt_weight = float(normal_tilt_weight)
        maps = tuple(str(name) for name in parameter_maps)
        if not maps or not set(maps) <= set(PARAMETER_MAPS):
            raise UserError(
                f"loss.parameter_maps={list(maps)}: must be a non-empty list among {list(PARAMETER_MAPS)}"
            )
        self.parameter_maps = maps
        self.switches = switches
        self.seed = seed
        self.rendering_sampling = rendering_sampling
        self.plane_half_size = plane_half_size
        self.feature_layers = feature_layers
        self.weight = weight
        self.feature_weight = feature_weight
        self.metallic_loss: MetallicLoss = metallic_loss
        self.rendering_loss = (
            RenderingLoss(
                rendering_sampling,
                seed=seed,
                plane_half_size=plane_half_size,
                compile=compile,
                pairing=rendering_pairing,
            )
            if switches.rendering
            else None
        )

    def reseed(self, seed: int) -> None:
        """Reseed the rendering-loss configurations (under DDP: ``seed + global_rank``)."""
        if self.rendering_loss is not None:
            self.rendering_loss.reseed(seed)

    def rng_state(self) -> Tensor | None:
        """The state of the loss's own randomness (``None``: the loss draws nothing)."""
        return self.rendering_loss.rng_state() if self.rendering_loss is not None else None

    def set_rng_state(self, state: Tensor | None) -> None:
        """Continue from a state of :meth:`rng_state` (a resumed run draws what it would have)."""
        if self.rendering_loss is not None and state is not None:
            self.rendering_loss.set_rng_state(state)

    def generator_terms(
        self,
        pred_maps: Tensor,
        true_maps: Tensor,
        d_fake: DiscriminatorOutputs | None = None,
        d_real: DiscriminatorOutputs | None = None,
    ) -> dict[str, Tensor]:
        """The switched-on generator terms and their total.

        Args:
            pred_maps: the generator's maps (with autograd).
            true_maps: the ground truth.
            d_fake: discriminator outputs for (photo, pred_maps); needed by ``g_adv`` and ``g_feat``.
            d_real: discriminator outputs for (photo, true_maps); needed by ``g_feat`` only.

        Returns:
            Among ``g_adv``, ``g_feat``, ``param``, ``param_basecolor``, ``param_normal``,
            ``param_roughness``, ``param_metallic``, ``render``: those switched on; and ``g_total``.

        Shape:
            - pred_maps, true_maps: ``(B, 8, H, W)``
            - output: scalars
        """
        s = self.switches
        if s.adversarial and d_fake is None:
            raise ValueError("the adversarial term is on: pass the discriminator outputs d_fake")
        if s.feature and (d_fake is None or d_real is None):
            raise ValueError("the feature term is on: pass the discriminator outputs d_fake and d_real")
        terms: dict[str, Tensor] = {}
        if s.adversarial and d_fake is not None:
            terms["g_adv"] = lsgan_generator_loss(d_fake)
        if s.feature and d_fake is not None and d_real is not None:
            terms["g_feat"] = feature_matching_loss(d_real, d_fake, self.feature_layers)
        if s.parameter:
            with record_function("brdfgan/parameter_loss_forward"):
                terms.update(
                    parameter_loss(
                        pred_maps, true_maps, self.metallic_loss, self.normal_tilt_weight, self.parameter_maps
                    )
                )
        if s.rendering and self.rendering_loss is not None:
            with record_function("brdfgan/rendering_loss_forward"):
                terms["render"] = self.rendering_loss(pred_maps, true_maps)
        terms["g_total"] = generator_total(terms, s, self.weight)
        return terms

    def discriminator_terms(
        self, d_real: DiscriminatorOutputs, d_fake: DiscriminatorOutputs
    ) -> dict[str, Tensor]:
        """``d_adv``, ``d_feat`` (when the feature term is on) and ``d_total``.

        ``d_fake`` must come from detached predictions (the caller's job, see the module
        docstring). The feature term is differentiated through both branches here, as the
        paper minimises L_f over the discriminator.
        """
        if not self.switches.needs_discriminator:
            raise RuntimeError("no loss term uses the discriminator; it should not be trained")
        terms = {"d_adv": lsgan_discriminator_loss(d_real, d_fake)}
        if self.switches.feature:
            terms["d_feat"] = feature_matching_loss(d_real, d_fake, self.feature_layers, detach_real=False)
        terms["d_total"] = discriminator_total(terms["d_adv"], terms.get("d_feat"), self.feature_weight)
        return terms

    forward = generator_terms  # calling the module computes the generator terms

    def extra_repr(self) -> str:
        return (
            f"switches={self.switches}, weight={self.weight}, feature_weight={self.feature_weight}, "
            f"metallic_loss={self.metallic_loss}, normal_tilt_weight={self.normal_tilt_weight}, "
            f"parameter_maps={list(self.parameter_maps)}, "
            f"rendering_pairing={self.rendering_loss.pairing if self.rendering_loss is not None else None}"
        )
