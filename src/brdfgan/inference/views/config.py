"""The settings of a multi-view fit (:mod:`brdfgan.inference.views.fit`), in a module without torch,
so that a command's option parsing and a config schema can type and check them cheaply."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from brdfgan.errors import UserError


@dataclass(frozen=True)
class ViewFitConfig:
    """Everything a multi-view fit chooses; :mod:`brdfgan.inference.views.fit` describes the fit.

    The fit runs at each size of ``levels`` in turn (coarse to fine, ``steps[i]`` Adam steps at
    ``levels[i]``); the maps' correction is carried from one level to the next and, at the end, to
    the prediction's own size. A level larger than the photos or the maps is lowered to the smaller
    of the two.
    """

    levels: tuple[int, ...] = (128, 256)
    steps: tuple[int, ...] = (150, 80)
    learning_rate: float = 0.05
    # Prior toward the prediction, per map (L1 on the parameters of refine.maps_to_parameters:
    # logits, slopes), divided per texel by 1 + the number of views that see it. The maps' global
    # levels (one logit offset each for base colour, roughness, metallic) are fitted without it.
    prior_basecolor: float = 0.02
    prior_slopes: float = 0.02
    prior_roughness: float = 0.02
    prior_metallic: float = 0.1  # metal is rarely what a few flash photos prove wrong
    # Total variation of the slopes' and roughness's per-texel correction; chosen on synthetic Mitsuba
    # captures of validation materials (docs/views.md, "Choosing the fit's settings").
    tv_weight: float = 0.25
    clip_level: float = 0.98  # a pixel with a channel at or above this is clipped: a lower bound
    outlier_mads: float = 3.0  # a view is dropped above median + this many (scaled) MADs of residual
    spike_factor: float = 1.5  # the guard restores the best state when a step's loss exceeds this × best
    max_restores: int = 4  # restores allowed per level before the level stops at its best state
    min_improvement: float = 0.0  # relative drop of the fitted views' loss the fit must beat to be kept

    def __post_init__(self) -> None:
        for setting in fields(self):
            value, default = getattr(self, setting.name), setting.default
            if isinstance(default, tuple):
                # A list is what JSON and Hydra give back: stored as a tuple (the config is frozen).
                if not (
                    isinstance(value, tuple | list)
                    and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
                ):
                    raise UserError(f"views.{setting.name}={value!r}: expected a list of int")
                object.__setattr__(self, setting.name, tuple(value))
                continue
            number = isinstance(value, int | float) and not isinstance(value, bool)
            kind = type(default)
            if not (number and isinstance(value, kind | int)):
                raise UserError(f"views.{setting.name}={value!r}: expected {kind.__name__}")
        rules = {
            "levels": (
                len(self.levels) >= 1
                and all(v >= 8 for v in self.levels)
                and list(self.levels) == sorted(set(self.levels)),
                "expected increasing sizes of at least 8",
            ),
            "steps": (
                len(self.steps) == len(self.levels) and all(v >= 0 for v in self.steps),
                f"expected {len(self.levels)} counts (one per level), none negative",
            ),
            "learning_rate": (self.learning_rate > 0, "expected > 0"),
            "prior_basecolor": (self.prior_basecolor >= 0, "expected >= 0"),
            "prior_slopes": (self.prior_slopes >= 0, "expected >= 0"),
            "prior_roughness": (self.prior_roughness >= 0, "expected >= 0"),
            "prior_metallic": (self.prior_metallic >= 0, "expected >= 0"),
            "tv_weight": (self.tv_weight >= 0, "expected >= 0"),
            "clip_level": (0 < self.clip_level <= 1, "expected in (0, 1]"),
            "outlier_mads": (self.outlier_mads > 0, "expected > 0"),
            "spike_factor": (self.spike_factor > 1, "expected > 1"),
            "max_restores": (self.max_restores >= 0, "expected >= 0"),
            "min_improvement": (0 <= self.min_improvement < 1, "expected in [0, 1)"),
        }
        for key, (ok, expected) in rules.items():
            if not ok:
                raise UserError(f"views.{key}={getattr(self, key)!r}: out of range ({expected})")

    def to_json(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self.__dict__.items()}
