"""Train the conditional GAN: ``python train.py [experiment=paper] [loss=no_adv] [ckpt_path=...]``.

Thin entry point (lightning-hydra-template style): the config (``conf/train.yaml``) is composed
and type-checked, :func:`brdfgan.training.run.train` builds and runs everything, and the
monitored metric is returned for sweeps (``python train.py -m loss=full,no_adv,...``).
"""

from __future__ import annotations

import hydra
from omegaconf import DictConfig

from brdfgan.errors import exit_on_user_error, run_hydra_app
from brdfgan.sweep_folders import register_resolvers
from brdfgan.training.config import register_configs

register_configs()
register_resolvers()


@hydra.main(version_base="1.3", config_path="conf", config_name="train")
@exit_on_user_error(interrupted="interrupted: resume with ckpt_path=<run>/checkpoints/last.ckpt")
def main(cfg: DictConfig) -> float | None:
    from brdfgan.training.run import train

    return train(cfg)


if __name__ == "__main__":
    run_hydra_app(main)
