"""The typed top level of ``conf/evaluate.yaml``: a wrong key or a wrong type is one line at
composition. Group nodes (``data``, ``metrics``, ``logger``) are ``_target_`` configs checked
against their signatures by :func:`brdfgan.config_check.check_config` before anything is built."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, make_dataclass
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from brdfgan.inference.refine_config import RefineConfig

# evaluate.py's refine.<key>: every refinement setting but the steps (refine_steps gives those),
# typed like RefineConfig's defaults, so a wrong key or type fails when the config is composed.
RefineSettings = make_dataclass(
    "RefineSettings",
    [(f.name, type(f.default), field(default=f.default)) for f in fields(RefineConfig) if f.name != "steps"],
)


@dataclass
class PairRowNames:
    """evaluate.py's ``pair_rows``: :class:`~brdfgan.evaluation.evaluator.PairRows` as lists."""

    flash_only: list[str] = field(default_factory=list)
    fit: list[str] = field(default_factory=list)


@dataclass
class EvaluateConfig:
    task_name: str = "evaluate"
    ckpt: Any = MISSING  # a path, a list of paths, or a mapping name -> path
    split: str = "test"
    device: str = "auto"
    grid_samples: int = 6
    grid_keys: list[str] | None = None
    flash_frame: str = "recorded"  # recorded | centred (see conf/evaluate.yaml)
    refine_steps: list[int] = field(default_factory=list)  # each model also after --refine N
    refine: Any = field(default_factory=RefineSettings)  # RefineConfig settings besides steps
    pair_rows: PairRowNames = field(default_factory=PairRowNames)  # rows on flash + no-flash pairs
    paths: dict[str, Any] = field(default_factory=dict)
    data: dict[str, Any] = field(default_factory=dict)
    logger: dict[str, Any] | None = None
    metrics: dict[str, Any] = field(default_factory=dict)


def register_configs() -> None:
    """Make ``evaluate_schema`` available to the defaults list of ``conf/evaluate.yaml``."""
    ConfigStore.instance().store(name="evaluate_schema", node=EvaluateConfig)
