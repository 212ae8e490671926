"""The typed top level of ``conf/train.yaml``: a wrong key or a wrong type is an error at
composition time, before anything is built or run. Group nodes (``model``, ``data``, …) are
``_target_`` configs checked by instantiating them all before training starts."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore


@dataclass
class TrainConfig:
    task_name: str = "train"
    seed: int = 0
    train: bool = True
    test: bool = True
    ckpt_path: str | None = None
    init_from: str | None = None
    monitor: str = "val/loss"
    grid_samples: int = 4
    paths: dict[str, Any] = field(default_factory=dict)
    data: dict[str, Any] = field(default_factory=dict)
    model: dict[str, Any] = field(default_factory=dict)
    loss: dict[str, Any] = field(default_factory=dict)
    trainer: dict[str, Any] = field(default_factory=dict)
    logger: dict[str, Any] | None = None
    callbacks: dict[str, Any] | None = None
    metrics: dict[str, Any] | None = None


def register_configs() -> None:
    """Make ``train_schema`` available to the defaults list of ``conf/train.yaml``."""
    ConfigStore.instance().store(name="train_schema", node=TrainConfig)
