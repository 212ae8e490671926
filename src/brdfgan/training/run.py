"""Build everything a training run needs from its config, then fit and test (``train.py``).

The config is type-checked first (:func:`brdfgan.config_check.check_config`: every value of the
data, model, loss, trainer, callbacks, logger and metrics groups against the signature it is
passed to), then everything is instantiated before the first step, so a wrong key or value is
one line naming it before any data is generated or any time is spent training. A checkpoint to
resume from is checked against the built model before Lightning touches it; every checkpoint is
written atomically in its own directory (:class:`~brdfgan.training.checkpoint_io.AtomicCheckpointIO`).
"""

from __future__ import annotations

import logging
import math
import warnings
from pathlib import Path
from typing import Any, cast

import hydra
import lightning as L
from omegaconf import DictConfig, OmegaConf
from torch import nn

from brdfgan.config_check import check_config
from brdfgan.errors import UserError, single_console_logging
from brdfgan.evaluation.evaluator import comparison_grid, evaluate_models, fixed_samples, write_results
from brdfgan.io.atomic import stale_temp_files
from brdfgan.io.images import write_image
from brdfgan.runs import LAST_CHECKPOINT, WeightsError, check_resume_checkpoint, network_weights
from brdfgan.tracking import (
    current_run_identity,
    finish_tracker_runs,
    log_image,
    log_run_config,
    with_identity,
)
from brdfgan.training.checkpoint_io import AtomicCheckpointIO

log = logging.getLogger(__name__)


# The groups whose values are passed to constructors (type-checked before anything is built).
CHECKED_GROUPS = ("data", "model", "loss", "trainer", "callbacks", "logger", "metrics")


class TrainConfigError(UserError):
    """The run config is unusable; the message names the key."""


def _instantiate_all(group: DictConfig | None) -> list[Any]:
    if not group:
        return []
    return [hydra.utils.instantiate(node, _convert_="all") for node in group.values() if node is not None]


def build(cfg: DictConfig) -> tuple[L.LightningDataModule, L.LightningModule, L.Trainer]:
    """Datamodule, module (with its loss) and trainer of a run config; the loggers carry the
    run's name, tags and group (:func:`brdfgan.tracking.current_run_identity`).

    The data path is checked first (``check_data``: what ``prepare_data`` would refuse, without
    generating anything, so no two processes generate side by side), then everything is seeded
    with ``cfg.seed`` and built: a mistyped path is the run's first and only output line.
    """
    datamodule = hydra.utils.instantiate(cfg.data, _convert_="all")
    check_data = getattr(datamodule, "check_data", None)
    if check_data is not None:
        check_data("fit")  # what testing reads is checked when the test starts
    L.seed_everything(cfg.seed, workers=True)
    loss = hydra.utils.instantiate(cfg.loss, _convert_="all")
    module = hydra.utils.instantiate(cfg.model, loss=loss, _convert_="all")
    callbacks = _instantiate_all(cfg.get("callbacks"))
    identity = current_run_identity(cfg.task_name)
    logger_group = cfg.get("logger") or {}
    loggers = [hydra.utils.instantiate(with_identity(node, identity), _convert_="all")
               for node in logger_group.values() if node is not None]  # fmt: skip
    # Checkpoints go to a temporary file beside their target and are renamed over it, on any
    # filesystem (Lightning's default stages them in $TMPDIR and copies across filesystems).
    trainer = hydra.utils.instantiate(
        cfg.trainer, callbacks=callbacks, logger=loggers, plugins=[AtomicCheckpointIO()]
    )
    return datamodule, module, trainer


def warm_start(module: L.LightningModule, path: str | Path) -> list[str]:
    """Initialise ``module``'s networks from ``path`` (``init_from``) and return their names.

    Unlike resuming (``ckpt_path``) only weights are taken: the optimizers, the learning-rate
    schedule, the step count and the loss switches are this run's, so a run can continue another
    one with a different loss (e.g. a GAN-trained generator fine-tuned without the adversarial
    term). The generator must fit exactly; the discriminator is taken when both sides have one.
    """
    path = Path(path)
    if not path.is_file():
        raise TrainConfigError(f"init_from: {path} does not exist")
    try:
        networks = network_weights(path)
    except WeightsError as error:
        raise TrainConfigError(f"init_from: {path} is not a checkpoint or weights file ({error})") from None
    if "generator" not in networks:
        raise TrainConfigError(f"init_from: {path} holds no generator weights")
    loaded: list[str] = []
    for name in ("generator", "discriminator"):
        network = getattr(module, name, None)
        if network is None or name not in networks:
            continue
        try:
            network.load_state_dict(networks[name])
        except RuntimeError as error:
            first = str(error).strip().splitlines()[0]
            message = f"init_from: the {name} in {path} does not fit this model ({first})"
            raise TrainConfigError(message) from None
        loaded.append(name)
    return loaded


def _run_interruptible(trainer: L.Trainer, stage: Any, **kwargs: Any) -> None:
    """Run ``trainer.fit``/``trainer.test``; Lightning ends a stage on Ctrl-C with ``exit(1)``
    and on SIGTERM (at the next batch boundary) with a ``SystemExit`` of status 0 — both become
    a ``KeyboardInterrupt`` that says where to resume from."""
    try:
        with warnings.catch_warnings():
            # The shard streams' lengths are exact per rank and per worker (ShardStream.__len__),
            # which is what this generic warning about IterableDatasets with a length doubts.
            warnings.filterwarnings("ignore", message="Your `IterableDataset` has `__len__` defined")
            stage(**kwargs)
    except SystemExit:
        if not trainer.interrupted:
            raise
        last = _last_checkpoint(trainer)
        hint = f"resume with ckpt_path={last}" if last is not None else "no checkpoint was written yet"
        raise KeyboardInterrupt(f"interrupted: {hint}") from None


def _last_checkpoint(trainer: L.Trainer) -> Path | None:
    """The ``last.ckpt`` the run's checkpoint callbacks write, when one exists."""
    for callback in trainer.checkpoint_callbacks:
        dirpath = getattr(callback, "dirpath", None)
        if dirpath and getattr(callback, "filename", None) == "last":
            last = Path(dirpath) / LAST_CHECKPOINT
            if last.is_file():
                return last
    return None


def _remove_stale_checkpoint_temps(checkpoint: Path) -> None:
    """A writer killed mid-checkpoint leaves its hidden temporary file (the checkpoint itself is
    intact); the run that resumes from that folder removes it."""
    for stale in stale_temp_files(checkpoint):
        log.info("removing %s, left by a checkpoint write that was killed", stale)
        stale.unlink(missing_ok=True)


def _write_test_grid(cfg: DictConfig, datamodule: Any, module: L.LightningModule, trainer: L.Trainer) -> None:
    """``grid_model.png`` of the tested model, as ``evaluate.py`` writes it for a checkpoint (the
    first ``grid_samples`` of the test split), also to the loggers as ``test/grid``."""
    split = getattr(datamodule, "splits", {}).get("test")
    if split is None:
        return
    samples = fixed_samples(
        Path(datamodule.data_dir), split, cfg.grid_samples, align_maps=datamodule.align_maps
    )
    if not samples:
        return
    grid = comparison_grid(cast(nn.Module, module.generator), samples)
    write_image(Path(cfg.paths.output_dir) / "grid_model.png", grid)
    log_image(trainer.loggers, "test/grid", grid, trainer.global_step)


def _fit_and_test(
    cfg: DictConfig, datamodule: Any, module: L.LightningModule, trainer: L.Trainer
) -> float | None:
    """Warm start, log the config to the trackers, fit, test and write the evaluator's tables
    and the test grid; the monitored metric after fitting."""
    init_from = cfg.get("init_from")
    if init_from is not None:
        loaded = warm_start(module, init_from)
        log.info("init_from: %s from %s (new optimizers and schedule)", " and ".join(loaded), init_from)
    # The whole config is in the run folder (.hydra/config.yaml) and in the tracker; the console
    # gets it only at DEBUG level (hydra.verbose=true).
    log.info("run folder: %s", cfg.paths.output_dir)
    if log.isEnabledFor(logging.DEBUG):  # resolving and printing the whole config is not free
        log.debug("run config:\n%s", OmegaConf.to_yaml(cfg, resolve=True))
    if trainer.is_global_zero:
        log_run_config(trainer.loggers, cfg, cfg.monitor)
    if cfg.train:
        _run_interruptible(trainer, trainer.fit, model=module, datamodule=datamodule, ckpt_path=cfg.ckpt_path)
    metric = trainer.callback_metrics.get(cfg.monitor)
    value = float(metric) if metric is not None else None
    if cfg.test:
        checkpoint = getattr(trainer.checkpoint_callback, "best_model_path", "") or None
        if not cfg.train:
            checkpoint = cfg.ckpt_path
        _run_interruptible(trainer, trainer.test, model=module, datamodule=datamodule, ckpt_path=checkpoint)
        if cfg.get("metrics") is not None:
            # The evaluator's tables for this run (brdfgan.report builds the ablation from them).
            # Every rank evaluates its part; the metrics' compute() gathers the sums of all ranks.
            results = evaluate_models(
                {"model": cast(nn.Module, module.generator)},
                datamodule.test_dataloader(),
                hydra.utils.instantiate(cfg.metrics),
                module.device,
            )
            if trainer.is_global_zero:
                write_results(results, cfg.paths.output_dir)
        # fast_dev_run (a Trainer attribute Lightning sets but does not declare) writes nothing.
        if trainer.is_global_zero and not getattr(trainer, "fast_dev_run", False):
            _write_test_grid(cfg, datamodule, module, trainer)
    return value


def train(cfg: DictConfig) -> float | None:
    """Fit (optionally resuming from ``ckpt_path`` or starting from ``init_from``'s weights), test
    the best checkpoint, and return the monitored metric (for sweeps), or ``None`` when it was
    not logged."""
    single_console_logging()
    check_config(cfg, CHECKED_GROUPS)
    if cfg.ckpt_path is not None and not Path(cfg.ckpt_path).is_file():
        raise TrainConfigError(f"ckpt_path: checkpoint {cfg.ckpt_path} does not exist")
    init_from = cfg.get("init_from")
    if init_from is not None and cfg.ckpt_path is not None:
        raise TrainConfigError("init_from and ckpt_path: set one (init_from starts a new run from weights)")
    datamodule, module, trainer = build(cfg)
    if cfg.ckpt_path is not None:
        found = {name: getattr(module, name, None) for name in ("generator", "discriminator")}
        networks = {name: network for name, network in found.items() if isinstance(network, nn.Module)}
        try:
            check_resume_checkpoint(cfg.ckpt_path, networks)
        except WeightsError as error:
            raise TrainConfigError(f"ckpt_path: {error}") from None
        _remove_stale_checkpoint_temps(Path(cfg.ckpt_path))
    try:
        value = _fit_and_test(cfg, datamodule, module, trainer)
    finally:
        # A W&B run stays open after Lightning finalizes its logger; the next job of a multirun
        # would log into it (wandb reuses a run in progress).
        finish_tracker_runs(trainer.loggers)
    if value is not None and not math.isfinite(value):
        log.warning("%s is %s", cfg.monitor, value)
    return value
