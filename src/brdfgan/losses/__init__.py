"""The paper's loss terms (§4.1): parameter, rendering, adversarial (LSGAN), feature matching,
and the generator/discriminator totals. Pure torch; nothing here imports Lightning or Hydra.
"""

from brdfgan.losses.adversarial import (
    DiscriminatorOutputs,
    feature_matching_loss,
    lsgan_discriminator_loss,
    lsgan_generator_loss,
)
from brdfgan.losses.parameter import ANGULAR_EPS, angular_distance, parameter_loss
from brdfgan.losses.rendering import RenderingLoss, rendering_loss
from brdfgan.losses.total import GANLoss, LossSwitches, discriminator_total, generator_total

__all__ = [
    "ANGULAR_EPS",
    "DiscriminatorOutputs",
    "GANLoss",
    "LossSwitches",
    "RenderingLoss",
    "angular_distance",
    "discriminator_total",
    "feature_matching_loss",
    "generator_total",
    "lsgan_discriminator_loss",
    "lsgan_generator_loss",
    "parameter_loss",
    "rendering_loss",
]
