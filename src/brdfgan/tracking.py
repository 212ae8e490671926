"""What a training run tells its experiment trackers (the Lightning loggers of ``logger=…``).

- Its identity: a readable name from the overrides that say what the run is
  (``loss=no_adv seed=1``), tags from the chosen config groups and those overrides, and a group
  per multirun (every job of one ``-m`` sweep), for W&B's run table.
- Its whole resolved config, once: W&B's config, CSV's and TensorBoard's ``hparams.yaml``, and
  TensorBoard's HParams plugin (without the output groups: :data:`OUTPUT_GROUPS`) with the
  monitored metric as the plugin's metric, so the runs of a sweep line up in one table.
  (Lightning's own logging of the module's and datamodule's init arguments is off: it sent a
  partial config, twice.)
- Images: the prediction grids, to every logger that shows images.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from lightning.pytorch.loggers import Logger, TensorBoardLogger, WandbLogger
from omegaconf import DictConfig, OmegaConf

from brdfgan.sweep_folders import named_overrides

# Config groups whose choice is a tag of the run (the others set where and how it runs).
TAGGED_GROUPS = ("experiment", "data", "model", "loss", "trainer", "hparams_search", "debug")
# Groups that say where a run writes, not what it is: left out of TensorBoard's HParams table
# (their absolute paths differ between any two runs and would bury the settings compared); W&B's
# config and hparams.yaml still hold them.
OUTPUT_GROUPS = ("paths", "logger", "callbacks")
# W&B refuses longer tags.
MAX_TAG_LENGTH = 64


@dataclass(frozen=True)
class RunIdentity:
    """How a run is named, tagged and grouped in the trackers."""

    name: str
    tags: tuple[str, ...]
    group: str


def run_identity(
    task_name: str,
    overrides: Sequence[str] = (),
    choices: Mapping[str, Any] | None = None,
    sweep_dir: str | None = None,
) -> RunIdentity:
    """The identity of a run started with ``overrides`` and the config group ``choices`` Hydra
    made; ``sweep_dir`` is the multirun's folder (``None`` for a single run).

    Name: ``key=value`` of the overrides that say what the run is (budget and path keys left
    out), or ``task_name`` without any. Group: ``task_name/<sweep folder>`` for a multirun's
    jobs, ``task_name`` otherwise.
    """
    named = [f"{key}={value}" if value else key for key, value in named_overrides(overrides)]
    chosen = [f"{group}={choice}" for group, choice in (choices or {}).items()
              if group in TAGGED_GROUPS and choice is not None]  # fmt: skip
    tags = tuple(dict.fromkeys(tag[:MAX_TAG_LENGTH] for tag in [*chosen, *named]))
    group = f"{task_name}/{Path(sweep_dir).name}" if sweep_dir else task_name
    return RunIdentity(name=" ".join(named) or task_name, tags=tags, group=group)


def current_run_identity(task_name: str) -> RunIdentity:
    """:func:`run_identity` of the running Hydra job (the task name alone outside Hydra)."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    if not HydraConfig.initialized():
        return run_identity(task_name)
    hydra_cfg = HydraConfig.get()
    sweep_dir = str(hydra_cfg.sweep.dir) if hydra_cfg.mode == RunMode.MULTIRUN else None
    choices = {str(group): choice for group, choice in hydra_cfg.runtime.choices.items()}
    return run_identity(task_name, list(hydra_cfg.overrides.task), choices, sweep_dir)


def with_identity(logger_cfg: DictConfig, identity: RunIdentity) -> DictConfig:
    """A logger's config with the run's name, tags and group filled in where the tracker takes
    them (W&B) and the config leaves them unset (``null``); other loggers' configs unchanged."""
    if not str(logger_cfg.get("_target_", "")).endswith("WandbLogger"):
        return logger_cfg
    filled = logger_cfg.copy()
    for key, value in (("name", identity.name), ("tags", list(identity.tags)), ("group", identity.group)):
        if filled.get(key) is None:
            filled[key] = value
    return filled


def flat_config(config: Mapping[str, Any], prefix: str = "") -> dict[str, str | int | float | bool]:
    """``config`` flattened to ``a/b/c`` keys with values TensorBoard's HParams plugin takes
    (numbers, strings, booleans; lists and ``None`` as their text)."""
    flat: dict[str, str | int | float | bool] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flat_config(value, f"{name}/"))
        elif isinstance(value, bool | int | float | str):
            flat[name] = value
        else:
            flat[name] = str(value)
    return flat


def log_run_config(loggers: Iterable[Logger], cfg: DictConfig, monitor: str) -> dict[str, Any]:
    """Send the resolved run config (without Hydra's own node) to every logger once, and to
    TensorBoard's HParams plugin with ``monitor`` as its metric; return the config sent."""
    from torch.utils.tensorboard.summary import hparams

    resolved = OmegaConf.to_container(cfg, resolve=True)
    assert isinstance(resolved, dict)
    config = {str(key): value for key, value in resolved.items() if key != "hydra"}
    for logger in loggers:
        logger.log_hyperparams(config)
        if isinstance(logger, TensorBoardLogger):
            # The plugin's session records (experiment, session start and end), without the
            # metric value Lightning's log_hyperparams(metrics=…) would log at step 0: the
            # plugin reads the metric from the run's own scalars of that tag.
            writer = logger.experiment._get_file_writer()
            compared = {key: value for key, value in config.items() if key not in OUTPUT_GROUPS}
            for summary in hparams(flat_config(compared), {monitor: 0.0}):
                writer.add_summary(summary)
    return config


def log_image(loggers: Iterable[Logger], tag: str, image: np.ndarray, step: int) -> None:
    """Send a display-ready image to every logger that shows images (TensorBoard, W&B).

    Shape: ``image`` ``(H, W, 3)`` in ``[0, 1]``.
    """
    pixels = (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    for logger in loggers:
        if isinstance(logger, TensorBoardLogger):
            logger.experiment.add_image(tag, pixels, global_step=step, dataformats="HWC")
            # Written now: after the final test Lightning has closed its writer, and the one
            # this call reopened would otherwise hold the picture until a flush that never comes.
            logger.experiment.flush()
        elif isinstance(logger, WandbLogger):
            logger.log_image(key=tag, images=[pixels], step=step)


def finish_tracker_runs(loggers: Iterable[Logger]) -> None:
    """End the W&B runs of ``loggers`` that were started (Lightning leaves them open)."""
    for logger in loggers:
        if isinstance(logger, WandbLogger) and logger._experiment is not None:
            logger.experiment.finish()
