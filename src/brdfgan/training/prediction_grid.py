"""The dashboards' picture of training: every validation epoch, the model's predictions for a
fixed list of validation samples, beside the truth, under labelled columns.

The grid is ``evaluate.py``'s (:func:`~brdfgan.evaluation.evaluator.comparison_grid`: input |
truth and prediction per map | re-render under a novel light) for the first ``samples`` samples
of the validation split in shard order — chosen before training, the same for every run and
epoch, so runs and epochs compare picture by picture. It goes to every logger that shows images
(TensorBoard, W&B) as ``val/grid`` at the current step, and the latest one to
``<run>/grid_val.png`` (for CSV-only runs).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import lightning as L
from lightning.pytorch.callbacks import Callback
from torch import nn

from brdfgan.data.storage.shards import Sample
from brdfgan.evaluation.evaluator import comparison_grid, fixed_samples
from brdfgan.io.images import write_image
from brdfgan.tracking import log_image

log = logging.getLogger(__name__)

VALIDATION_GRID = "grid_val.png"


class PredictionGrid(Callback):
    """Log the fixed-sample prediction grid after every validation epoch (rank zero only).

    Args:
        samples: rows of the grid: the first ``samples`` of the validation split.
    """

    def __init__(self, samples: int = 4) -> None:
        if samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        self.samples = samples
        self._rows: list[Sample] | None = None

    def setup(self, trainer: L.Trainer, pl_module: L.LightningModule, stage: str) -> None:
        if stage != "fit" or not trainer.is_global_zero or self._rows is not None:
            return
        datamodule: Any = getattr(trainer, "datamodule", None)
        split = getattr(datamodule, "splits", {}).get("val")
        if split is None:
            log.info("no validation split: no prediction grid")
            self._rows = []
            return
        self._rows = fixed_samples(
            Path(datamodule.data_dir), split, self.samples, align_maps=datamodule.align_maps
        )

    def on_validation_epoch_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        # fast_dev_run (a Trainer attribute Lightning sets but does not declare) writes nothing.
        quick = getattr(trainer, "fast_dev_run", False)
        if trainer.sanity_checking or quick or not trainer.is_global_zero or not self._rows:
            return
        generator = pl_module.generator
        assert isinstance(generator, nn.Module)
        grid = comparison_grid(generator, self._rows)
        log_image(trainer.loggers, "val/grid", grid, trainer.global_step)
        write_image(Path(trainer.default_root_dir) / VALIDATION_GRID, grid)
