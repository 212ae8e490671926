"""Generate a synthetic SVBRDF dataset: ``python generate.py [dataset=paper] [shard=N] [plan=true]``.

Thin entry point: the config (``conf/generate.yaml``) becomes a
:class:`brdfgan.data.generation.DatasetSpec` (every value checked, naming its key, before
anything is written); :func:`brdfgan.data.generation.run_generation` does the work. See the
config file for multi-process and SLURM use. A bad value, a bad environment file or a full disk
ends with one ``error:`` line; Ctrl-C or SIGTERM with one line too, keeping complete shards.
"""

from __future__ import annotations

import logging
import signal
from types import FrameType

import hydra
from omegaconf import DictConfig, OmegaConf

from brdfgan.config_check import check_config
from brdfgan.data.generate_config import register_configs
from brdfgan.errors import exit_on_user_error, run_hydra_app

register_configs()
log = logging.getLogger("generate")


def _interrupt_on_sigterm() -> None:
    """Make SIGTERM (``kill PID``, a scheduler ending the job) stop the run the way Ctrl-C does:
    the shard being written is dropped, complete ones stay, one line is printed. A handler a
    launcher installed already (submitit's, for requeueing) is left alone."""

    def interrupt(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt

    try:
        if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
            signal.signal(signal.SIGTERM, interrupt)
    except ValueError:  # not the main thread (an in-process launcher): keep the default
        pass


@hydra.main(version_base="1.3", config_path="conf", config_name="generate")
@exit_on_user_error(interrupted="interrupted: complete shards are kept; re-run the same command to finish")
def main(cfg: DictConfig) -> None:
    _interrupt_on_sigterm()
    from brdfgan.data.contact_sheet import write_contact_sheet
    from brdfgan.data.generation import dataset_ready, plan_shards, run_generation, spec_from_config

    check_config(cfg, ["dataset"])  # types, naming the key; the spec checks ranges
    spec = spec_from_config(cfg.dataset)
    shard = OmegaConf.to_object(cfg.shard) if isinstance(cfg.shard, DictConfig | list) else cfg.shard
    if cfg.plan:
        jobs = plan_shards(spec)
        for position, job in enumerate(jobs):
            print(
                f"{position:6d}  {job.split:5s}  shard {job.index:6d}  "
                f"materials {list(job.materials)}  samples {job.sample_count(spec)}"
            )
        print(f"{len(jobs)} shards; run them all with: python generate.py -m shard='range(0,{len(jobs)})'")
        return
    summary = run_generation(spec, cfg.out_dir, shards=shard, progress=cfg.progress)
    log.info("%s", summary.describe())
    if cfg.contact_sheet and shard is None and dataset_ready(spec, cfg.out_dir):
        path = write_contact_sheet(cfg.out_dir, "train", rows=cfg.contact_sheet, seed=spec.seed)
        log.info("contact sheet: %s", path)


if __name__ == "__main__":
    run_hydra_app(main)
