"""The typed top level of ``conf/train.yaml``: a wrong key or a wrong type is an error at
composition time, before anything is built or run. Group nodes (``model``, ``data``, …) are
``_target_`` configs checked by instantiating them all before training starts."""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore

from brdfgan.models.anchored import AnchoredUNet


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


def constructor_node(cls: type) -> dict[str, Any]:
    """A config node that builds ``cls``: its ``_target_`` and every constructor argument at the
    code's default. A YAML config that selects it carries only what differs from the code, and
    every argument can still be overridden by name (``model.generator.shading=none``) without
    repeating the defaults in YAML."""
    node: dict[str, Any] = {"_target_": f"{cls.__module__}.{cls.__qualname__}"}
    for parameter in inspect.signature(cls).parameters.values():
        if parameter.default is inspect.Parameter.empty:
            raise TypeError(f"{cls.__qualname__}.{parameter.name} has no default: not a config node")
        node[parameter.name] = parameter.default
    return node


def register_configs() -> None:
    """Make ``train_schema`` available to the defaults list of ``conf/train.yaml``, and the
    generators whose code defaults are a shipped model's as ``/generator@generator: <name>``."""
    store = ConfigStore.instance()
    store.store(name="train_schema", node=TrainConfig)
    store.store(group="generator", name="anchored_unet", node=constructor_node(AnchoredUNet))
