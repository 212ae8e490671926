"""The networks of the conditional GAN (paper §4.3): generator and multi-scale PatchGAN discriminators.

Plain ``nn.Module``s with int-only constructor arguments (``Model(**model.config())`` rebuilds one);
nothing here imports Lightning or Hydra.
"""

from brdfgan.models.discriminator import (
    DISCRIMINATOR_CHANNELS,
    MultiScaleDiscriminator,
    PatchDiscriminator,
    discriminator_input,
    downsample,
)
from brdfgan.models.generator import Generator, ResidualBlock
from brdfgan.models.heads import PHOTO_CHANNELS, encode_photo, init_weights, maps_from_raw

__all__ = [
    "DISCRIMINATOR_CHANNELS",
    "PHOTO_CHANNELS",
    "Generator",
    "MultiScaleDiscriminator",
    "PatchDiscriminator",
    "ResidualBlock",
    "discriminator_input",
    "downsample",
    "encode_photo",
    "init_weights",
    "maps_from_raw",
]
