"""Measure test-time fine-tuning of the *network* against the photo (issue 17, session 8).

:func:`~brdfgan.inference.refine.refine_maps` corrects the predicted maps; this corrects the
generator's weights instead, per photo (the "deep image prior" form of guided fine-tuning,
Deschaintre et al. 2020): the network's own structure is the prior, so a correction can follow
what its features see in the photo — relief included — where one offset per map cannot. The
objective is ``refine_maps``'s photo term with the same fitted per-channel gain and 4 × 4 ambient
irradiance; optionally an L1 pull of the maps toward the network's first prediction. Adam, cosine
decay, a copy of the generator per photo (the shipped weights never change).

It runs ``evaluate.py`` with this fine-tuning in place of ``--refine`` for the
``<model>+refine<N>`` rows (N: the steps), so the table is the evaluator's:

    FT_LR=1e-4 FT_PART=all FT_PULL=0 python scripts/measure_refine_network.py \\
        data=default_model split=val data.prepare=null grid_samples=0 \\
        "ckpt={v3: src/brdfgan/weights/default.safetensors}" "refine_steps=[60]"

``FT_PART``: ``all`` (every weight), ``up`` (the decoder and the output layer) or ``out`` (the
output layer only). ~13 s per photo at 256² and 60 steps with every weight (2 threads).
Not part of the package: it did not pass validation (docs/refinement.md).
"""

from __future__ import annotations

import copy
import math
import os
import runpy
import sys

import torch
from torch import Tensor, nn

import brdfgan.evaluation.run
from brdfgan.core.flash_geometry import centred_flash_frame, field_of_view, hotspot_position
from brdfgan.core.render import FlashCapture, render_flash
from brdfgan.inference.refine import add_ambient, cosine_decay, initial_log_gain, photo_loss
from brdfgan.inference.refine_config import RefineConfig

LEARNING_RATE = float(os.environ.get("FT_LR", "1e-4"))
PULL_WEIGHT = float(os.environ.get("FT_PULL", "0"))
PART = os.environ.get("FT_PART", "all")
PREFIXES = {"all": ("",), "up": ("up.", "out."), "out": ("out.",)}


def finetune(generator: nn.Module, photo: Tensor, flash_frame: Tensor, config: RefineConfig) -> Tensor:
    """The maps of a copy of ``generator`` fine-tuned on ``photo`` for ``config.steps`` steps.

    Shape: photo ``(3, N, N)``, flash_frame ``(3,)`` → ``(8, N, N)``."""
    network = copy.deepcopy(generator).eval()
    trained = [p for name, p in network.named_parameters() if name.startswith(PREFIXES[PART])]
    network.requires_grad_(False)
    for parameter in trained:
        parameter.requires_grad_(True)
    size = photo.shape[-1]
    frame = flash_frame.reshape(1, -1)
    capture = FlashCapture(fov_deg=field_of_view(float(frame[0, 2]), size))
    camera_xy = hotspot_position(frame, size, size)
    target = photo[None]
    with torch.no_grad():
        first = generator(target, frame)
        log_gain = initial_log_gain(
            target, render_flash(first, capture, camera_xy=camera_xy), config.clip_level
        )
    log_gain = log_gain.clone().requires_grad_(True)
    ambient = torch.full((1, 3, config.ambient_grid, config.ambient_grid), math.log(1e-2), requires_grad=True)
    optimizer = torch.optim.Adam(
        [
            {"params": trained, "lr": LEARNING_RATE},
            {"params": [log_gain, ambient], "lr": config.learning_rate},
        ]
    )
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: cosine_decay(step, config.steps))
    with torch.enable_grad():
        for _ in range(config.steps):
            maps = network(target, frame)
            render = add_ambient(render_flash(maps, capture, camera_xy=camera_xy), maps, ambient)
            loss = photo_loss(render * log_gain.exp(), target, config.clip_level)
            loss = loss + PULL_WEIGHT * (maps - first).abs().mean()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            schedule.step()
    with torch.no_grad():
        return network(target, frame)[0]


class FinetunedGenerator(nn.Module):
    """Stands in for :class:`~brdfgan.inference.refine.RefinedGenerator` in the evaluator."""

    def __init__(self, generator: nn.Module, config: RefineConfig) -> None:
        super().__init__()
        self.generator = generator
        self.config = config

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        if flash is None:
            flash = centred_flash_frame(photo.shape[0], photo.shape[-2], photo.shape[-1], device=photo.device)
        return torch.stack(
            [finetune(self.generator, photo[i], flash[i], self.config) for i in range(photo.shape[0])]
        )


if __name__ == "__main__":
    if PART not in PREFIXES:
        sys.exit(f"FT_PART={PART!r}: must be one of {', '.join(PREFIXES)}")
    brdfgan.evaluation.run.RefinedGenerator = FinetunedGenerator  # type: ignore[misc,assignment]
    sys.argv = ["evaluate.py", *sys.argv[1:]]
    runpy.run_path("evaluate.py", run_name="__main__")
