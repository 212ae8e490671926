"""Build everything a training run needs from its config, then fit and test (``train.py``).

Everything is instantiated before the first step, so a wrong ``_target_`` argument or value is
reported as one line before any data is generated or any time is spent training.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import hydra
import lightning as L
import torch
from omegaconf import DictConfig, OmegaConf

from brdfgan.evaluation.evaluator import evaluate_models, write_results

log = logging.getLogger(__name__)


class TrainConfigError(ValueError):
    """The run config is unusable; the message names the key."""


def _instantiate_all(group: DictConfig | None) -> list[Any]:
    if not group:
        return []
    return [hydra.utils.instantiate(node, _convert_="all") for node in group.values() if node is not None]


def build(cfg: DictConfig) -> tuple[L.LightningDataModule, L.LightningModule, L.Trainer]:
    """Datamodule, module (with its loss) and trainer of a run config."""
    datamodule = hydra.utils.instantiate(cfg.data, _convert_="all")
    loss = hydra.utils.instantiate(cfg.loss, _convert_="all")
    module = hydra.utils.instantiate(cfg.model, loss=loss, _convert_="all")
    callbacks = _instantiate_all(cfg.get("callbacks"))
    loggers = _instantiate_all(cfg.get("logger"))
    trainer = hydra.utils.instantiate(cfg.trainer, callbacks=callbacks, logger=loggers)
    return datamodule, module, trainer


def _network_weights(path: Path) -> dict[str, dict[str, torch.Tensor]]:
    """The state dicts per network (``generator``, ``discriminator``) stored in a training
    checkpoint, or the generator of a ``.safetensors`` weights file."""
    if path.suffix.lower() == ".safetensors":
        from safetensors.torch import load_file

        return {"generator": {name: value.float() for name, value in load_file(str(path)).items()}}
    state = torch.load(path, map_location="cpu", weights_only=True)["state_dict"]
    networks: dict[str, dict[str, torch.Tensor]] = {}
    for key, value in state.items():
        network, _, name = key.partition(".")
        if network in ("generator", "discriminator"):
            networks.setdefault(network, {})[name] = value
    return networks


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
        networks = _network_weights(path)
    except Exception as error:  # any unreadable file is the same user error
        raise TrainConfigError(f"init_from: {path} is not a checkpoint or weights file ({error})") from None
    if "generator" not in networks:
        raise TrainConfigError(f"init_from: {path} holds no generator weights")
    loaded = []
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


def train(cfg: DictConfig) -> float | None:
    """Fit (optionally resuming from ``ckpt_path`` or starting from ``init_from``'s weights), test
    the best checkpoint, and return the monitored metric (for sweeps), or ``None`` when it was
    not logged."""
    if cfg.ckpt_path is not None and not Path(cfg.ckpt_path).is_file():
        raise TrainConfigError(f"ckpt_path: checkpoint {cfg.ckpt_path} does not exist")
    init_from = cfg.get("init_from")
    if init_from is not None and cfg.ckpt_path is not None:
        raise TrainConfigError("init_from and ckpt_path: set one (init_from starts a new run from weights)")
    L.seed_everything(cfg.seed, workers=True)
    datamodule, module, trainer = build(cfg)
    if init_from is not None:
        loaded = warm_start(module, init_from)
        log.info("init_from: %s from %s (new optimizers and schedule)", " and ".join(loaded), init_from)
    log.info("run config:\n%s", OmegaConf.to_yaml(cfg, resolve=True))
    if cfg.train:
        trainer.fit(module, datamodule=datamodule, ckpt_path=cfg.ckpt_path)
    metric = trainer.callback_metrics.get(cfg.monitor)
    value = float(metric) if metric is not None else None
    if cfg.test:
        checkpoint = getattr(trainer.checkpoint_callback, "best_model_path", "") or None
        if not cfg.train:
            checkpoint = cfg.ckpt_path
        trainer.test(module, datamodule=datamodule, ckpt_path=checkpoint)
        if cfg.get("metrics") is not None:
            # The evaluator's tables for this run (brdfgan.report builds the ablation from them).
            # Every rank evaluates its part; the metrics' compute() gathers the sums of all ranks.
            results = evaluate_models(
                {"model": module.generator},
                datamodule.test_dataloader(),
                hydra.utils.instantiate(cfg.metrics),
                module.device,
            )
            if trainer.is_global_zero:
                write_results(results, cfg.paths.output_dir)
    if value is not None and not math.isfinite(value):
        log.warning("%s is %s", cfg.monitor, value)
    return value
