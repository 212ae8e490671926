"""Evaluate checkpoints or weights on a test split: ``python evaluate.py ckpt=… [data=…]``.

Thin entry point: :func:`brdfgan.evaluation.run.evaluate` loads the models, runs the metrics of
:mod:`brdfgan.metrics` and writes tables, the RMSE chart and qualitative grids into the run folder.
"""

from __future__ import annotations

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from brdfgan.errors import exit_on_user_error, run_hydra_app
from brdfgan.evaluation.config import register_configs
from brdfgan.sweep_folders import register_resolvers

register_configs()
register_resolvers()


@hydra.main(version_base="1.3", config_path="conf", config_name="evaluate")
@exit_on_user_error(interrupted="interrupted: nothing was written for the model being evaluated")
def main(cfg: DictConfig) -> None:
    from brdfgan.evaluation.run import evaluate

    evaluate(cfg, HydraConfig.get().runtime.output_dir)


if __name__ == "__main__":
    run_hydra_app(main)
