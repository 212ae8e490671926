"""The settings of a test-time refinement (:mod:`brdfgan.inference.refine`), in a module without
torch: ``evaluate.py``'s config schema types its ``refine.<key>`` overrides with them."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from brdfgan.errors import UserError
from brdfgan.inference import DEFAULT_REFINE_STEPS


@dataclass(frozen=True)
class RefineConfig:
    """Everything a refinement chooses; see the module docstring for the terms.

    The defaults are provisional (issue 17 is open): on 4 validation photos of the procedural data
    they lowered the novel-light re-render error of the shipped model by ~3 % and the diffuse
    albedo's RMSE by ~11 %, with the normals unchanged (a pull of 0.1 on the slopes let them fit
    the photo and raised the normal angle by 58 %).
    """

    # Provisional: 100 steps at 256² take ~3 s per photo on the 2-core CPU (evaluate.py over 112 photos).
    steps: int = DEFAULT_REFINE_STEPS
    learning_rate: float = 0.05
    working_size: int = 256
    prior_weight: float = 1.0
    normal_prior_weight: float = 3.0
    material_prior_weight: float = 1.0  # roughness and metallic
    material_grid: int = 0  # their correction: a g × g grid of logits, upsampled; 0: per pixel
    pixel_maps: bool = True  # base colour and normals corrected per pixel; False: kept as predicted
    low_frequency_weight: float = 1.0
    low_frequency_sigma: float = 8.0  # pixels at working_size
    tv_weight: float = 0.01
    ambient: bool = True
    ambient_grid: int = 4
    fit_flash_offset: bool = False
    clip_level: float = 0.98

    def __post_init__(self) -> None:
        for setting in fields(self):
            value, default = getattr(self, setting.name), setting.default
            number = isinstance(value, int | float) and not isinstance(value, bool)
            kind = type(default)
            typed = isinstance(value, bool) if kind is bool else number and isinstance(value, kind | int)
            if not typed:
                raise UserError(f"refine.{setting.name}={value!r}: expected {kind.__name__}")
        checks = {
            "steps": self.steps >= 0,
            "learning_rate": self.learning_rate > 0,
            "working_size": self.working_size >= 16,
            "prior_weight": self.prior_weight >= 0,
            "normal_prior_weight": self.normal_prior_weight >= 0,
            "material_prior_weight": self.material_prior_weight >= 0,
            "low_frequency_weight": self.low_frequency_weight >= 0,
            "low_frequency_sigma": self.low_frequency_sigma > 0,
            "tv_weight": self.tv_weight >= 0,
            "ambient_grid": self.ambient_grid >= 1,
            "material_grid": self.material_grid >= 0,
            "clip_level": 0 < self.clip_level <= 1,
        }
        for key, ok in checks.items():
            if not ok:
                raise UserError(f"refine.{key}={getattr(self, key)!r}: out of range")

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)
