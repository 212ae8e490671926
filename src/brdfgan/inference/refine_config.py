"""The settings of a test-time refinement (:mod:`brdfgan.inference.refine`), in a module without
torch: ``evaluate.py``'s config schema types its ``refine.<key>`` overrides with them."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from brdfgan.errors import UserError
from brdfgan.inference import DEFAULT_REFINE_STEPS


@dataclass(frozen=True)
class RefineConfig:
    """Everything a refinement chooses; :mod:`brdfgan.inference.refine` describes the fit.

    The default fits one logit offset per map (base colour, all channels alike; roughness;
    metallic) with the exposure gain and a ``4 × 4`` ambient irradiance: 60 Adam steps at learning
    rate 0.02, chosen on the validation split by the rule "the largest novel-light gain that raises
    no map's RMSE by more than 5 %"; the measurements, and the variants that failed it, are in
    docs/refinement.md.
    """

    steps: int = DEFAULT_REFINE_STEPS
    learning_rate: float = 0.02
    working_size: int = 256  # larger maps are fitted at this size and the correction carried over
    ambient: bool = True  # fit a low-frequency ambient irradiance (room or sky light)
    ambient_grid: int = 4
    fit_flash_offset: bool = False  # fit the flash's offset from the lens (a 2-vector in the plane)
    fit_roughness: bool = True  # False: the roughness map is kept as predicted
    fit_basecolor: bool = True  # False: the base colour is kept as predicted (gain and ambient still fitted)
    roughness_nuisance: bool = False  # with fit_roughness: fit the offset, return the predicted roughness
    clip_level: float = 0.98  # a pixel with a channel at or above this is clipped: a lower bound

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
            "ambient_grid": self.ambient_grid >= 1,
            "clip_level": 0 < self.clip_level <= 1,
        }
        for key, ok in checks.items():
            if not ok:
                raise UserError(f"refine.{key}={getattr(self, key)!r}: out of range")

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)
