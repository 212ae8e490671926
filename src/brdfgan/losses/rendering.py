"""Rendering loss L_r (paper §4.1): predicted and true maps re-rendered under the same random
light/view configurations, compared with L1 after ``log(1 + x)``.

The configurations come from :func:`~brdfgan.core.sampling.sample_rendering_loss_configs`
(ten by default: five random, five with a mirror highlight, random light colour).

Pairing: the paper renders the predicted maps together (``joint``). ``cross`` renders each of the
two map groups the anchored network predicts with separate decoders — (base colour, metallic) and
(normal, roughness) — beside the *true* other group, half of the configurations each
(:func:`cross_paired`). Why: under the joint render one map's error is paid back by another's (a
too-bright metal colour by a glossier lobe), and that compensation did not carry over to held-out
scans; the probe and the runs: ``research/notes/2026-12-default-model-v4.md``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Literal

import torch
from torch import Tensor, nn

from brdfgan.core.checks import check_shape
from brdfgan.core.render import (
    PointLights,
    check_scene_shapes,
    linear_basecolor_maps,
    shade_point_lights,
    shading_inputs,
)
from brdfgan.core.sampling import (
    RenderConfigs,
    RenderingLossSampling,
    log_transform,
    sample_rendering_loss_configs,
)
from brdfgan.core.svbrdf import BASECOLOR, METALLIC, NORMAL, ROUGHNESS, check_map_pair, check_map_shape

log = logging.getLogger(__name__)

# image_loss(pred, target with linear base colour, camera_position, lights, plane_half_size) -> scalar.
ImageLossFn = Callable[[Tensor, Tensor, Tensor, PointLights, float], Tensor]
RenderPairing = Literal["joint", "cross"]


def cross_paired(
    pred: Tensor, target: Tensor, configs: RenderConfigs
) -> tuple[Tensor, Tensor, RenderConfigs]:
    """The batch of a ``cross`` rendering loss: each sample twice, once as (predicted base colour
    and metallic, true normal and roughness) under the even-numbered configurations and once as
    (true base colour and metallic, predicted normal and roughness) under the odd-numbered ones.
    The number of rendered images stays ``B × V``, so the loss costs what the joint one does.

    Shape:
        - pred, target: ``(B, 8, H, W)``
        - configs: camera ``(B, V, 3)``, lights ``(B, V, K, ·)``, ``V`` even
        - output: maps ``(2B, 8, H, W)``, targets ``(2B, 8, H, W)``, configs with ``(2B, V/2, ·)``

    Example:
        >>> from brdfgan.core.svbrdf import flat_maps
        >>> configs = sample_rendering_loss_configs(2, generator=torch.Generator().manual_seed(0))
        >>> pred, target = flat_maps(4, 4, batch=(2,)), flat_maps(4, 4, batch=(2,))
        >>> pred[:, 6] = 0.75  # roughness: predicted in the second half only
        >>> maps, targets, paired = cross_paired(pred, target, configs)
        >>> tuple(maps.shape), tuple(paired.camera_position.shape)
        ((4, 8, 4, 4), (4, 5, 3))
        >>> maps[:2, 6].unique().tolist() == target[:, 6].unique().tolist(), maps[2:, 6].unique().tolist()
        (True, [0.75])
    """
    views = configs.camera_position.shape[1]
    if views % 2:
        raise ValueError(f"a cross-paired rendering loss needs an even number of configurations, got {views}")
    basecolor_metallic = torch.cat(
        [pred[:, BASECOLOR], target[:, NORMAL], target[:, ROUGHNESS], pred[:, METALLIC]], dim=1
    )
    normal_roughness = torch.cat(
        [target[:, BASECOLOR], pred[:, NORMAL], pred[:, ROUGHNESS], target[:, METALLIC]], dim=1
    )

    # (B, V, …) -> (2B, V/2, …): the even-numbered configurations, then the odd-numbered ones.
    paired = configs.map_tensors(lambda t: torch.cat([t[:, 0::2], t[:, 1::2]]))
    return torch.cat([basecolor_metallic, normal_roughness]), torch.cat([target, target]), paired


def shaded_image_loss(
    pred: Tensor,
    target: Tensor,
    camera_position: Tensor,
    lights: PointLights,
    plane_half_size: float = 1.0,
) -> Tensor:
    """Mean absolute difference of ``log(1 + x)`` of two map sets with *linear* base colour
    (:func:`~brdfgan.core.render.linear_basecolor_maps`) rendered by
    :func:`~brdfgan.core.render.render_point_lights`; the target without autograd (it is data).
    The part of :func:`rendering_loss` that :class:`RenderingLoss` compiles.

    Shape:
        - pred, target: ``(B, 8, H, W)``, base colour linear
        - camera_position: ``(B, V, 3)``, lights ``(B, V, K, ·)``
        - output: scalar
    """
    pred_inputs = shading_inputs(pred, basecolor_linear=True)
    pred_image = shade_point_lights(pred_inputs, camera_position, lights, plane_half_size)
    with torch.no_grad():
        target_inputs = shading_inputs(target, basecolor_linear=True)
        target_image = shade_point_lights(target_inputs, camera_position, lights, plane_half_size)
    return (log_transform(pred_image) - log_transform(target_image)).abs().mean()


def rendering_loss(
    pred: Tensor,
    target: Tensor,
    configs: RenderConfigs,
    plane_half_size: float = 1.0,
    *,
    image_loss: ImageLossFn = shaded_image_loss,
    pairing: RenderPairing = "joint",
) -> Tensor:
    """Mean absolute difference of ``log(1 + x)`` of both map sets rendered under ``configs``
    (with :func:`~brdfgan.core.render.render_point_lights`).

    The target is rendered without autograd (it is data). Rendering runs in at least float32 —
    point-light radiance spans orders of magnitude, too much for half precision — on the device
    of ``pred``, to which ``configs`` are moved.

    Args:
        pred: predicted maps.
        target: ground-truth maps.
        configs: the light/view configurations, shared by both renderings.
        plane_half_size: half the side of the sample square (as used to draw ``configs``).
        image_loss: :func:`shaded_image_loss` or a compiled version of it; it receives the
            maps with their base colour decoded to linear here.
        pairing: ``"joint"`` (the paper: the predicted maps rendered together) or ``"cross"``
            (:func:`cross_paired`: each decoder's maps beside the true other ones).

    Shape:
        - pred, target: ``(B, 8, H, W)``
        - configs: camera ``(B, V, 3)``, lights ``(B, V, K, ·)``
        - output: scalar

    Example:
        Identical maps render identically (0); the loss is symmetric and grows with the error:

        >>> from brdfgan.core.svbrdf import flat_maps
        >>> configs = sample_rendering_loss_configs(2, generator=torch.Generator().manual_seed(0))
        >>> target = flat_maps(4, 4, batch=(2,))
        >>> rendering_loss(target, target, configs).item()
        0.0
        >>> brighter = target.clone()
        >>> brighter[:, 0:3] = 0.7
        >>> loss = rendering_loss(brighter, target, configs)
        >>> loss.item() == rendering_loss(target, brighter, configs).item()
        True
        >>> brightest = brighter.clone()
        >>> brightest[:, 0:3] = 0.9
        >>> bool(0 < loss < rendering_loss(brightest, target, configs))
        True
    """
    check_map_pair(pred, target)
    check_shape(pred, "B 8 H W", name="maps")
    if configs.camera_position.shape[0] != pred.shape[0]:
        raise ValueError(
            f"configs were drawn for a batch of {configs.camera_position.shape[0]}, maps have {pred.shape[0]}"
        )
    dtype = torch.promote_types(pred.dtype, torch.float32)
    configs = configs.to(pred.device, dtype)
    check_scene_shapes(pred, configs.camera_position, configs.lights)
    pred, target = pred.to(dtype), target.detach().to(device=pred.device, dtype=dtype)
    if pairing == "cross":
        pred, target, configs = cross_paired(pred, target, configs)
    elif pairing != "joint":
        raise ValueError(f"pairing must be 'joint' or 'cross', got {pairing!r}")
    pred_linear = linear_basecolor_maps(pred)
    with torch.no_grad():
        target_linear = linear_basecolor_maps(target)
    return image_loss(pred_linear, target_linear, configs.camera_position, configs.lights, plane_half_size)


class RenderingLoss(nn.Module):
    """:func:`rendering_loss` with fresh configurations drawn for every call.

    Randomness: the module owns a ``torch.Generator`` seeded with ``seed``, so a run's sequence
    of configurations is reproducible. It is a CPU generator on purpose:
    :func:`sample_rendering_loss_configs` draws on the CPU so that one seed gives the same
    configurations on every device; the few numbers (``B × V × 11``) are then moved to the maps'
    device. The generator state is not part of ``state_dict`` (it is not a tensor of the model);
    a training checkpoint stores it through :meth:`rng_state` so a resumed run draws on exactly.

    Under DDP every rank holds its own copy built with the same ``seed``, so all ranks would draw
    the *same* configurations for their different samples — harmless but wasteful. The training
    module should call ``reseed(seed + global_rank)`` once the rank is known (e.g. in ``setup``).

    Args:
        sampling: how configurations are drawn (default: the paper's 5 random + 5 specular).
        seed: initial seed of the generator.
        plane_half_size: half the side of the sample square.
        pairing: ``"joint"`` or ``"cross"`` (see :func:`rendering_loss`).
        compile: run the shading of both map sets, the log transform and the L1
            (:func:`shaded_image_loss`) through ``torch.compile``, which fuses its ~150
            elementwise steps forward and backward into a few loops. It compiles once per input
            shape (training crops have one; the time is logged) and then runs several times
            faster than eager (docs/benchmarks.md#renderer-speed). Off: the eager factored
            renderer, for varying shapes and short runs.

    Shape:
        - pred, target: ``(B, 8, H, W)``
        - output: scalar, or ``(scalar, RenderConfigs)`` with ``return_configs=True``
    """

    def __init__(
        self,
        sampling: RenderingLossSampling = RenderingLossSampling(),
        seed: int = 0,
        plane_half_size: float = 1.0,
        compile: bool = False,
        pairing: RenderPairing = "joint",
    ) -> None:
        super().__init__()
        if pairing not in ("joint", "cross"):
            raise ValueError(f"pairing must be 'joint' or 'cross', got {pairing!r}")
        if pairing == "cross" and sampling.num_configs % 2:
            raise ValueError(
                f"pairing='cross' needs an even number of configurations, got {sampling.num_configs}"
            )
        self.pairing: RenderPairing = pairing
        self.sampling = sampling
        self.plane_half_size = plane_half_size
        self.compiled = compile
        self._image_loss: ImageLossFn = (
            torch.compile(shaded_image_loss, dynamic=False) if compile else shaded_image_loss
        )
        self._compiled_shapes: set[tuple[int, ...]] = set()
        self.rng = torch.Generator(device="cpu")
        self.seed = seed
        self.reseed(seed)

    def reseed(self, seed: int) -> None:
        """Restart the configuration sequence from ``seed`` (under DDP: ``seed + global_rank``)."""
        self.seed = seed
        self.rng.manual_seed(seed)

    def rng_state(self) -> torch.Tensor:
        """The configuration generator's state (to store in a checkpoint)."""
        return self.rng.get_state()

    def set_rng_state(self, state: torch.Tensor) -> None:
        """Continue the configuration sequence from a state of :meth:`rng_state`."""
        self.rng.set_state(state)

    def sample_configs(
        self, batch: int, device: torch.device | str | None = None, dtype: torch.dtype = torch.float32
    ) -> RenderConfigs:
        """Draw the next configurations from the module's generator."""
        return sample_rendering_loss_configs(
            batch,
            self.sampling,
            plane_half_size=self.plane_half_size,
            generator=self.rng,
            dtype=dtype,
            device=device,
        )

    def _compile_for(self, pred: Tensor, target: Tensor, configs: RenderConfigs) -> None:
        """Compile forward and backward for the shape of ``pred`` on a throwaway copy (so the
        time can be logged in one line; the real call then runs the compiled code)."""
        start = time.perf_counter()
        probe = pred.detach().clone().requires_grad_(True)
        rendering_loss(
            probe, target, configs, self.plane_half_size, image_loss=self._image_loss, pairing=self.pairing
        ).backward()
        self._compiled_shapes.add(tuple(pred.shape))
        log.info(
            "rendering loss compiled for maps %s on %s in %.1f s (once per shape)",
            tuple(pred.shape), pred.device.type, time.perf_counter() - start,
        )  # fmt: skip

    def forward(
        self, pred: Tensor, target: Tensor, return_configs: bool = False
    ) -> Tensor | tuple[Tensor, RenderConfigs]:
        check_map_shape(pred)
        check_shape(pred, "B 8 H W", name="maps")
        dtype = torch.promote_types(pred.dtype, torch.float32)
        configs = self.sample_configs(pred.shape[0], device=pred.device, dtype=dtype)
        if self.compiled and pred.requires_grad and tuple(pred.shape) not in self._compiled_shapes:
            self._compile_for(pred, target, configs)
        loss = rendering_loss(
            pred, target, configs, self.plane_half_size, image_loss=self._image_loss, pairing=self.pairing
        )
        return (loss, configs) if return_configs else loss

    def extra_repr(self) -> str:
        return f"sampling={self.sampling}, seed={self.seed}, compile={self.compiled}, pairing={self.pairing}"
