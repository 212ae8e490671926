"""Light/view configurations for the rendering loss (paper §4.1) and its log(1 + x) transform.

Per sample the paper renders ten configurations "with randomly sampled viewing and lighting
directions from the upper hemisphere"; five of them are "chosen such that they contain a specular
highlight by mirroring one randomly sampled direction on a random surface point", and the light
colour is random. Concretely, for a sample square ``[-s, s]²``:

- *random* configurations: camera and light directions are drawn independently,
  cosine-weighted on the upper hemisphere (grazing directions render almost black and teach
  little), and placed at random distances from the sample centre;
- *specular* configurations: a surface point ``p`` is drawn uniformly on the square and a
  direction ``d`` cosine-weighted; the light sits at ``p + a·d`` and the camera at
  ``p + b·reflect(d)``, with ``reflect(d) = (-d_x, -d_y, d_z)`` the mirror about the geometric
  normal, so ``p`` shows the mirror highlight whatever the distances;
- light colour: each RGB channel uniform in ``[color_min, 1]``, then scaled so its brightest
  channel is 1; light intensity ``π·r²·U(intensity_min, intensity_max)`` so that a white
  Lambertian surface facing the light at distance r renders around 1 whatever the distance.

Everything is reproducible from a ``torch.Generator``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from brdfgan.core.render import PointLights


@dataclass(frozen=True)
class RenderingLossSampling:
    """Parameters of the rendering-loss configurations (distances in units of the half size)."""

    random_configs: int = 5
    specular_configs: int = 5
    distance_min: float = 2.0
    distance_max: float = 5.0
    intensity_min: float = 0.5
    intensity_max: float = 1.5
    color_min: float = 0.3

    def __post_init__(self) -> None:
        if (
            self.random_configs < 0
            or self.specular_configs < 0
            or self.random_configs + self.specular_configs == 0
        ):
            raise ValueError("need at least one rendering-loss configuration")
        if not 0.0 < self.distance_min <= self.distance_max:
            raise ValueError(
                f"need 0 < distance_min <= distance_max, got {self.distance_min}, {self.distance_max}"
            )
        if not 0.0 < self.intensity_min <= self.intensity_max:
            raise ValueError("need 0 < intensity_min <= intensity_max")
        if not 0.0 <= self.color_min <= 1.0:
            raise ValueError(f"color_min must lie in [0, 1], got {self.color_min}")

    @property
    def num_configs(self) -> int:
        return self.random_configs + self.specular_configs


@dataclass(frozen=True)
class RenderConfigs:
    """Cameras ``(B, V, 3)`` and one point light per configuration; ``V`` = random + specular,
    random ones first."""

    camera_position: Tensor
    lights: PointLights

    def map_tensors(self, fn: Callable[[Tensor], Tensor]) -> RenderConfigs:
        """``fn`` applied to the camera and to each light tensor, all of which lead with the batch
        and view axes ``(B, V, …)`` — the one place that lists the fields.

        Example:
            >>> configs = sample_rendering_loss_configs(2, generator=torch.Generator().manual_seed(0))
            >>> odd = configs.map_tensors(lambda t: t[:, 1::2])
            >>> tuple(odd.camera_position.shape), tuple(odd.lights.intensity.shape)
            ((2, 5, 3), (2, 5, 1))
        """
        lights = self.lights
        return RenderConfigs(
            camera_position=fn(self.camera_position),
            lights=PointLights(
                position=fn(lights.position), intensity=fn(lights.intensity), color=fn(lights.color)
            ),
        )

    def to(self, device: torch.device | str | None, dtype: torch.dtype) -> RenderConfigs:
        """The same configurations on ``device`` in ``dtype`` (a no-op for tensors already there)."""
        return self.map_tensors(lambda t: t.to(device=device, dtype=dtype))

    def configuration(self, index: int) -> RenderConfigs:
        """Configuration ``index`` alone, as a batch of the same size with ``V = 1`` (views).

        Shape:
            - self: camera ``(B, V, 3)``, lights ``(B, V, K, ·)``
            - output: camera ``(B, 1, 3)``, lights ``(B, 1, K, ·)``

        Example:
            >>> configs = sample_rendering_loss_configs(2, generator=torch.Generator().manual_seed(0))
            >>> third = configs.configuration(3)
            >>> tuple(third.camera_position.shape), tuple(third.lights.color.shape)
            ((2, 1, 3), (2, 1, 1, 3))
            >>> torch.equal(third.lights.position[:, 0], configs.lights.position[:, 3])
            True
        """
        return self.map_tensors(lambda t: t[:, index : index + 1])

    def expand(self, batch: int) -> RenderConfigs:
        """The configurations of a batch of 1 shared by every sample of a batch of ``batch``
        (views, not copies).

        Shape:
            - self: camera ``(1, V, 3)``, lights ``(1, V, K, ·)``
            - output: camera ``(batch, V, 3)``, lights ``(batch, V, K, ·)``

        Example:
            >>> shared = sample_rendering_loss_configs(1, generator=torch.Generator().manual_seed(0))
            >>> configs = shared.expand(4)
            >>> tuple(configs.camera_position.shape), tuple(configs.lights.color.shape)
            ((4, 10, 3), (4, 10, 1, 3))
            >>> torch.equal(configs.camera_position[3], shared.camera_position[0])
            True
            >>> configs.camera_position.data_ptr() == shared.camera_position.data_ptr()  # a view
            True
        """
        if self.camera_position.shape[0] != 1:
            raise ValueError(
                f"expand needs configurations of a batch of 1, got {self.camera_position.shape[0]}"
            )
        return self.map_tensors(lambda t: t.expand(batch, *t.shape[1:]))


def sample_cosine_hemisphere(
    shape: tuple[int, ...], generator: torch.Generator | None = None, **kw: Any
) -> Tensor:
    """Cosine-weighted unit directions on the +Z hemisphere.

    Shape:
        - output: ``(*shape, 3)``

    Example:
        Unit vectors above the plane with density ``cos θ / π``, so ``E[cos θ] = 2/3``:

        >>> d = sample_cosine_hemisphere((20_000,), torch.Generator().manual_seed(0), dtype=torch.float64)
        >>> torch.allclose(d.norm(dim=-1), torch.ones(20_000, dtype=torch.float64))
        True
        >>> bool((d[:, 2] >= 0).all())
        True
        >>> abs(d[:, 2].mean().item() - 2 / 3) < 0.01  # Monte Carlo error ≈ 0.002
        True
    """
    u1 = torch.rand(shape, generator=generator, **kw)
    u2 = torch.rand(shape, generator=generator, **kw)
    radius = u1.sqrt()
    phi = 2.0 * math.pi * u2
    z = (1.0 - u1).clamp(min=0.0).sqrt()
    return torch.stack([radius * torch.cos(phi), radius * torch.sin(phi), z], dim=-1)


def _uniform(
    shape: tuple[int, ...], low: float, high: float, generator: torch.Generator | None, **kw: Any
) -> Tensor:
    return low + (high - low) * torch.rand(shape, generator=generator, **kw)


def log_uniform(u: float | Tensor, low: float, high: float) -> float:
    """``exp(log low + u·(log high − log low))``: the log-uniform value in ``[low, high]`` at the
    uniform variate ``u`` in [0, 1), so every factor of ten in the range is equally likely.

    A float ``u`` is computed with :mod:`math`, a 0-dim float64 tensor with torch (whose log/exp
    round differently): each caller keeps the numbers it has always drawn.

    Example:
        The middle of ``[1, 100]`` on a log scale is 10:

        >>> round(log_uniform(0.5, 1.0, 100.0), 6), round(log_uniform(0.0, 1.0, 100.0), 6)
        (10.0, 1.0)
    """
    if not 0.0 < low <= high:
        raise ValueError(f"need 0 < low <= high for a log-uniform draw, got {low}, {high}")
    if isinstance(u, Tensor):
        log_range = torch.log(u.new_tensor([low, high]))
        return float(torch.exp(log_range[0] + u * (log_range[1] - log_range[0])))
    lo, hi = math.log(low), math.log(high)
    return math.exp(lo + u * (hi - lo))


def sample_rendering_loss_configs(
    batch: int,
    sampling: RenderingLossSampling = RenderingLossSampling(),
    *,
    plane_half_size: float = 1.0,
    generator: torch.Generator | None = None,
    dtype: torch.dtype = torch.float32,
    device: torch.device | str | None = None,
) -> RenderConfigs:
    """Draw the rendering-loss light/view configurations for a batch.

    Random numbers are drawn on the CPU (so a seeded generator gives the same configurations on
    every device) and moved to ``device``.

    Shape:
        - output: camera_position ``(batch, V, 3)``; lights position ``(batch, V, 1, 3)``,
          intensity ``(batch, V, 1)``, color ``(batch, V, 1, 3)``

    Example:
        >>> configs = sample_rendering_loss_configs(2, generator=torch.Generator().manual_seed(0))
        >>> tuple(configs.camera_position.shape), tuple(configs.lights.position.shape)
        ((2, 10, 3), (2, 10, 1, 3))
        >>> bool((configs.camera_position[..., 2] > 0).all() and (configs.lights.position[..., 2] > 0).all())
        True

        The five random lights lie 2–5 half sizes from the centre with intensity
        ``π r² · U(0.5, 1.5)``, and every light colour's brightest channel is 1:

        >>> r = configs.lights.position[:, :5, 0].norm(dim=-1)
        >>> bool(((r >= 2) & (r <= 5)).all())
        True
        >>> gain = configs.lights.intensity[:, :5, 0] / (math.pi * r**2)
        >>> bool(((gain >= 0.5) & (gain <= 1.5)).all())
        True
        >>> configs.lights.color.amax(dim=-1).unique().tolist()
        [1.0]
    """
    s = plane_half_size
    kw: dict[str, Any] = {"dtype": torch.float64}
    n_rand, n_spec = sampling.random_configs, sampling.specular_configs
    dist = (sampling.distance_min * s, sampling.distance_max * s)

    def distances(n: int) -> Tensor:
        return _uniform((batch, n, 1), *dist, generator, **kw)

    cam_random = sample_cosine_hemisphere((batch, n_rand), generator, **kw) * distances(n_rand)
    light_random = sample_cosine_hemisphere((batch, n_rand), generator, **kw) * distances(n_rand)
    light_distance_random = torch.linalg.vector_norm(light_random, dim=-1)

    point = torch.cat(
        [_uniform((batch, n_spec, 2), -s, s, generator, **kw), torch.zeros((batch, n_spec, 1), **kw)], dim=-1
    )
    direction = sample_cosine_hemisphere((batch, n_spec), generator, **kw)
    mirrored = direction * direction.new_tensor([-1.0, -1.0, 1.0])
    light_distance_spec = distances(n_spec)
    light_spec = point + direction * light_distance_spec
    cam_spec = point + mirrored * distances(n_spec)

    camera = torch.cat([cam_random, cam_spec], dim=1)
    light = torch.cat([light_random, light_spec], dim=1)
    light_distance = torch.cat([light_distance_random, light_distance_spec[..., 0]], dim=1)
    scale = _uniform(
        (batch, sampling.num_configs), sampling.intensity_min, sampling.intensity_max, generator, **kw
    )
    intensity = math.pi * light_distance.square() * scale
    color = _uniform((batch, sampling.num_configs, 3), sampling.color_min, 1.0, generator, **kw)
    color = color / color.amax(dim=-1, keepdim=True)

    def out(t: Tensor) -> Tensor:
        return t.to(device=device, dtype=dtype)

    return RenderConfigs(
        camera_position=out(camera),
        lights=PointLights(
            position=out(light).unsqueeze(2),
            intensity=out(intensity).unsqueeze(2),
            color=out(color).unsqueeze(2),
        ),
    )


def log_transform(radiance: Tensor) -> Tensor:
    """log(1 + x), the paper's range compression of re-renderings before the L1. Shape: any.

    Example:
        0 stays 0, ``e − 1`` becomes 1, and a highlight ten times brighter than another (100
        against 10) counts only about twice as much:

        >>> [round(v, 4) for v in log_transform(torch.tensor([0.0, math.e - 1.0])).tolist()]
        [0.0, 1.0]
        >>> round((log_transform(torch.tensor(100.0)) / log_transform(torch.tensor(10.0))).item(), 2)
        1.92
    """
    return torch.log1p(radiance)
