"""The networks: the photo-anchored U-Net the shipped model is (:class:`AnchoredUNet`), the
conditional GAN of the paper (§4.3) — generator and multi-scale PatchGAN discriminators — and the
Deschaintre et al. 2018 baseline generator.

Plain ``nn.Module``s with int-only constructor arguments (``Model(**model.config())`` rebuilds one);
nothing here imports Lightning or Hydra.
"""

from brdfgan.models.anchored import AnchoredUNet
from brdfgan.models.deschaintre2018 import Deschaintre2018
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
    "AnchoredUNet",
    "Deschaintre2018",
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
