"""The paper's learning-rate schedule: constant, then linearly to zero (paper §4.4: 2e-4 for the
first 100 of 200 epochs, then linear decay to 0)."""

from __future__ import annotations

from dataclasses import dataclass

from brdfgan.errors import UserError


@dataclass(frozen=True)
class LinearDecaySchedule:
    """Multiplier of the base learning rate at generator step ``step`` of ``total_steps``:
    1 for the first ``constant_fraction`` of training, then a straight line to 0 at the end."""

    total_steps: int
    constant_fraction: float = 0.5

    def __post_init__(self) -> None:
        if self.total_steps < 1:
            raise UserError(
                f"the schedule needs >= 1 generator step (model.total_steps, trainer.max_epochs), "
                f"got {self.total_steps}"
            )
        if not 0.0 <= self.constant_fraction <= 1.0:
            raise UserError(f"model.constant_lr_fraction must lie in [0, 1], got {self.constant_fraction}")

    @property
    def decay_start(self) -> int:
        return round(self.total_steps * self.constant_fraction)

    def __call__(self, step: int) -> float:
        if step < self.decay_start:
            return 1.0
        remaining = self.total_steps - self.decay_start
        return max(0.0, (self.total_steps - step) / remaining) if remaining > 0 else 0.0
