"""Generate a synthetic SVBRDF dataset: ``python generate.py [dataset_spec=paper] [shard=N] [plan=true]``.

Thin entry point: the config (``conf/generate.yaml``) becomes a
:class:`brdfgan.data.spec.dataset_spec.DatasetSpec` (every value checked, naming its key, before
anything is written); :func:`brdfgan.data.generation.generation.run_generation` does the work. See the
config file for multi-process and SLURM use. A bad value, a bad environment file or a full disk
ends with one ``error:`` line; Ctrl-C or SIGTERM with one line too, keeping complete shards.
"""

from __future__ import annotations

import logging

import hydra
from omegaconf import DictConfig, OmegaConf

from brdfgan.config_check import check_config
from brdfgan.data.generation.generate_config import register_configs
from brdfgan.errors import exit_on_user_error, interrupts_raise, run_hydra_app
from brdfgan.sweep_folders import register_resolvers

register_configs()
register_resolvers()
log = logging.getLogger("generate")


@hydra.main(version_base="1.3", config_path="conf", config_name="generate")
@exit_on_user_error(interrupted="interrupted: complete shards are kept; re-run the same command to finish")
def main(cfg: DictConfig) -> None:
    # SIGTERM (``kill``, a scheduler ending the job) stops the run as Ctrl-C does: the shard
    # being written is dropped, complete ones stay, one line is printed.
    with interrupts_raise():
        generate(cfg)


def generate(cfg: DictConfig) -> None:
    from brdfgan.data.generation.generation import dataset_ready, plan_shards, run_generation
    from brdfgan.data.materials.scanned import scanned_material_folders
    from brdfgan.data.spec.dataset_spec import (
        scan_materials,
        spec_from_config,
        split_materials,
        split_scan_sets,
    )
    from brdfgan.data.tools.contact_sheet import write_contact_sheet

    check_config(cfg, ["dataset_spec"])  # types, naming the key; the spec checks ranges
    spec = spec_from_config(cfg.dataset_spec)
    shard = OmegaConf.to_object(cfg.shard) if isinstance(cfg.shard, DictConfig | list) else cfg.shard
    if cfg.plan:
        jobs = plan_shards(spec)
        scans = scan_materials(spec)
        for position, job in enumerate(jobs):
            scanned = sum(material in scans for material in job.materials)
            print(
                f"{position:6d}  {job.split:5s}  shard {job.index:6d}  "
                f"materials {list(job.materials)}  samples {job.sample_count(spec)}"
                + (f"  ({scanned} scanned)" if scans else "")
            )
        if scans:
            names = [folder.name for folder in scanned_material_folders(str(spec.scans.folder))]
            for split, sets in split_scan_sets(spec).items():
                print(f"scanned sets of {split} ({len(sets)}): {', '.join(names[i] for i in sets)}")
        print(f"{len(jobs)} shards; run them all with: python generate.py -m shard='range(0,{len(jobs)})'")
        return
    summary = run_generation(spec, cfg.out_dir, shards=shard, progress=cfg.progress)
    log.info("%s", summary.describe())
    if cfg.contact_sheet and shard is None and dataset_ready(spec, cfg.out_dir):
        # Training data is what a person judges; a test-only dataset (scanned sets) shows its test split.
        split = "train" if split_materials(spec)["train"] else "test"
        path = write_contact_sheet(cfg.out_dir, split, rows=cfg.contact_sheet, seed=spec.seed)
        log.info("contact sheet: %s", path)


if __name__ == "__main__":
    run_hydra_app(main)
