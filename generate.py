"""Generate a synthetic SVBRDF dataset: ``python generate.py [dataset=paper] [shard=N] [plan=true]``.

Thin entry point: the config (``conf/generate.yaml``) becomes a
:class:`brdfgan.data.generation.DatasetSpec`; :func:`brdfgan.data.generation.run_generation`
does the work. See the config file for multi-process and SLURM use.
"""

from __future__ import annotations

import logging

import hydra
from omegaconf import DictConfig, OmegaConf

from brdfgan.errors import exit_on_user_error

log = logging.getLogger("generate")


@hydra.main(version_base="1.3", config_path="conf", config_name="generate")
@exit_on_user_error
def main(cfg: DictConfig) -> None:
    from brdfgan.data.contact_sheet import write_contact_sheet
    from brdfgan.data.generation import dataset_ready, plan_shards, run_generation

    spec = hydra.utils.instantiate(cfg.dataset, _convert_="all")
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
    main()
