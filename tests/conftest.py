from __future__ import annotations

import torch
from torch import Tensor

from brdfgan.core.svbrdf import join_maps, normalize_normal


def random_maps(
    height: int, width: int, *, seed: int = 0, batch: tuple[int, ...] = (), dtype: torch.dtype = torch.float32
) -> Tensor:
    """Valid, spatially varying map sets that are not symmetric in X or Y."""
    g = torch.Generator().manual_seed(seed)
    shape = (*batch, 1, height, width)

    def rand(channels: int = 1) -> Tensor:
        return torch.rand((*batch, channels, height, width), generator=g, dtype=dtype)

    ramp = torch.linspace(-0.4, 0.25, height, dtype=dtype).view(height, 1).expand(shape)
    normal = torch.cat([0.5 * rand() - 0.1, ramp + 0.1 * rand(), torch.ones(shape, dtype=dtype)], dim=-3)
    return join_maps(rand(3), normalize_normal(normal), 0.1 + 0.9 * rand(), (rand() > 0.5).to(dtype))
