"""The material-family interface, parameter sampling and height → normal conversion.

A family is a pure function of documented parameters producing a map set. A sample draws every
parameter from a normal distribution centred on its default with σ spanning its range, clipped
to the range (paper §5: "parameters … sampled from a normal distribution … clipped"), or
uniformly for parameters marked ``uniform`` (hues).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import torch
from torch import Tensor

from brdfgan.core.height import height_slope_channels
from brdfgan.core.svbrdf import join_maps, normalize_normal


@dataclass(frozen=True)
class Parameter:
    """One family parameter: default, range ``[low, high]`` and what it means.

    ``uniform`` draws it uniformly over the range instead: for quantities with no preferred
    value, such as a hue, where the clipped normal would pile a third of the draws onto the two
    bounds (red, for a hue in turns).
    """

    default: float
    low: float
    high: float
    doc: str
    uniform: bool = False

    def __post_init__(self) -> None:
        if not self.low <= self.default <= self.high:
            raise ValueError(f"default {self.default} outside [{self.low}, {self.high}]")

    def sample(self, generator: torch.Generator) -> float:
        """Normal centred on the default with σ = (high − low)/2, clipped to the range (or
        uniform over the range for ``uniform`` parameters)."""
        if self.uniform:
            u = torch.rand((), generator=generator, dtype=torch.float64).item()
            return float(self.low + (self.high - self.low) * u)
        sigma = (self.high - self.low) / 2.0
        value = self.default + sigma * torch.randn((), generator=generator, dtype=torch.float64).item()
        return float(min(max(value, self.low), self.high))


@dataclass(frozen=True)
class MaterialLayers:
    """What a family paints, all ``(C, H, W)`` float tensors in [0, 1] except ``height``.

    basecolor (3, sRGB-encoded), height (1, in texels of the output: 1.0 = one texel width),
    roughness (1), metallic (1).
    """

    basecolor: Tensor
    height: Tensor
    roughness: Tensor
    metallic: Tensor

    @classmethod
    def dielectric(cls, basecolor: Tensor, height: Tensor, roughness: Tensor) -> MaterialLayers:
        """Layers of a non-metal from ``(H, W)`` height and roughness (roughness clipped to [0, 1]).

        Shape: basecolor ``(3, H, W)``, height and roughness ``(H, W)``.
        """
        return cls(basecolor, height[None], roughness.clamp(0.0, 1.0)[None], torch.zeros(1, *height.shape))


GenerateFn = Callable[[Mapping[str, float], int, torch.Generator], MaterialLayers]


@dataclass(frozen=True)
class MaterialFamily:
    """A named parametric generator: ``generate(params, size, generator)`` → layers."""

    name: str
    parameters: Mapping[str, Parameter]
    generate: GenerateFn
    description: str = ""
    tags: tuple[str, ...] = field(default=())

    def defaults(self) -> dict[str, float]:
        return {key: p.default for key, p in self.parameters.items()}

    def sample_parameters(self, generator: torch.Generator) -> dict[str, float]:
        return {key: p.sample(generator) for key, p in self.parameters.items()}

    def make_layers(
        self, params: Mapping[str, float], size: int, generator: torch.Generator
    ) -> MaterialLayers:
        """The painted layers of these parameters (defaults for the missing ones), before the
        height becomes normals: what material mixing blends (:mod:`.mixing`)."""
        unknown = set(params) - set(self.parameters)
        if unknown:
            raise KeyError(f"{self.name}: unknown parameter(s) {', '.join(sorted(unknown))}")
        return self.generate({**self.defaults(), **params}, size, generator)

    def make_maps(self, params: Mapping[str, float], size: int, generator: torch.Generator) -> Tensor:
        """The 8-channel map set ``(8, size, size)`` of these parameters."""
        return layers_to_maps(self.make_layers(params, size, generator))


def layers_to_maps(layers: MaterialLayers) -> Tensor:
    """The 8-channel map set of painted layers: values clipped to [0, 1], height → normals.

    Shape: layers of ``(C, H, W)`` → ``(8, H, W)``.
    """
    return join_maps(
        layers.basecolor.clamp(0.0, 1.0),
        height_to_normal(layers.height),
        layers.roughness.clamp(0.0, 1.0),
        layers.metallic.clamp(0.0, 1.0),
    )


def height_to_normal(height: Tensor) -> Tensor:
    """Tangent-space normals of a height field by central differences (wrapping at the borders,
    so tileable heights give tileable normals). Row 0 is +Y, so +Y is *up the rows*.

    Shape:
        - height: ``(1, H, W)`` in texel units
        - output: ``(3, H, W)`` unit normals
    """
    slopes = height_slope_channels(height[None], periodic=True)[0]
    return normalize_normal(torch.cat([slopes, torch.ones_like(height)], dim=0))
