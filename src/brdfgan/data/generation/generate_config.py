"""The typed top level of ``conf/generate.yaml``: a wrong key or type is one line at composition.
The ``dataset_spec`` node is type-checked against :class:`~brdfgan.data.spec.dataset_spec.DatasetSpec` by
:func:`brdfgan.config_check.check_config`, then range-checked by the spec itself."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore


@dataclass
class GenerateConfig:
    task_name: str = "generate"
    out_dir: str = "data"
    shard: Any = None  # None: every shard; an int or a list of ints: those positions of the plan
    plan: bool = False
    progress: bool = True
    contact_sheet: int = 16
    paths: dict[str, Any] = field(default_factory=dict)
    dataset_spec: dict[str, Any] = field(default_factory=dict)


def register_configs() -> None:
    """Make ``generate_schema`` available to the defaults list of ``conf/generate.yaml``."""
    ConfigStore.instance().store(name="generate_schema", node=GenerateConfig)
