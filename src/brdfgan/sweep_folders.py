"""Names of multirun job folders: short, safe and saying what each run is.

Hydra's default names a job's folder by all its overrides (``key=value,key=value``): a dozen
overrides exceed a file name's 255 bytes, and ``=`` and ``,`` make the path unusable as an
unquoted override value (``evaluate.py ckpt=<path>``). Light module (no torch): the entry points
register its resolver before Hydra composes anything.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Sequence

from omegaconf import OmegaConf

# Overrides that set a run's budget, paths or outputs rather than what is being compared: left out
# of multirun folder names (every override stays in the job's .hydra/overrides.yaml). A key
# matches an entry equal to it or starting with it followed by a dot; entries ending in "_" are prefixes.
UNNAMED_OVERRIDE_KEYS = (
    "paths", "hydra", "ckpt_path", "init_from", "task_name", "train", "test", "logger", "callbacks",
    "debug", "trainer.max_", "trainer.min_", "trainer.limit_", "trainer.val_check_interval",
    "trainer.log_every_n_steps", "trainer.enable_", "trainer.fast_dev_run", "trainer.profiler",
    "trainer.num_sanity_val_steps", "trainer.check_val_every_n_epoch", "trainer.accelerator",
    "trainer.devices", "trainer.num_nodes", "trainer.strategy", "trainer.detect_anomaly",
    "trainer.default_root_dir", "grid_samples",
    "data.data_dir", "data.num_workers", "data.epoch_samples", "data.val_samples", "data.prepare",
)  # fmt: skip
# Longer names are cut and end in a hash of the whole: a folder name stays far below the 255
# bytes of a file name whatever the number of overrides.
JOB_FOLDER_MAX_LENGTH = 80


def _named(key: str) -> bool:
    key = key.split("@", 1)[0]  # a group chosen into another package (+logger@logger=wandb)
    for entry in UNNAMED_OVERRIDE_KEYS:
        if key == entry or key.startswith(entry + ".") or (entry.endswith("_") and key.startswith(entry)):
            return False
    return True


def override_key_value(override: str) -> tuple[str, str]:
    """``key`` and ``value`` of a command-line override (``key=value``, ``+key=value``,
    ``++key=value``, ``~key``); the value is empty for a deletion."""
    key, _, value = str(override).lstrip("+~").partition("=")
    return key, value


def named_overrides(overrides: Sequence[str]) -> list[tuple[str, str]]:
    """``(key, value)`` of the overrides that say what a run is (not :data:`UNNAMED_OVERRIDE_KEYS`),
    in their order: the parts of a job folder's name and of the run's name in the trackers."""
    pairs = [override_key_value(override) for override in overrides]
    return [(key, value) for key, value in pairs if _named(key)]


def job_folder_name(number: int, overrides: Sequence[str]) -> str:
    """The folder of one multirun job: its number, then ``key-value`` of each override that says
    what the run is (not :data:`UNNAMED_OVERRIDE_KEYS`), joined by ``_``, with every character
    other than letters, digits, ``.``, ``-`` and ``_`` replaced by ``_`` — no ``=`` or ``,``, so
    the path can be passed as ``evaluate.py ckpt=<path>`` unquoted — and cut to
    :data:`JOB_FOLDER_MAX_LENGTH` with a hash of the whole name.

    ``hydra.sweep.subdir`` (conf/hydra/default.yaml) calls it through the ``brdfgan.job_folder``
    resolver with the job's overrides; e.g. ``3_loss-no_adv_seed-1``.
    """
    parts = [str(number)] + [f"{key}-{value}" if value else key for key, value in named_overrides(overrides)]
    name = re.sub(r"[^A-Za-z0-9._-]+", "_", "_".join(parts)).strip(".")
    if len(name) > JOB_FOLDER_MAX_LENGTH:
        digest = hashlib.sha1(name.encode()).hexdigest()[:8]
        name = f"{name[: JOB_FOLDER_MAX_LENGTH - 9].rstrip('._-')}-{digest}"
    return name


def register_resolvers() -> None:
    """The resolvers the configs of the entry points use (``brdfgan.job_folder``)."""
    OmegaConf.register_new_resolver(
        "brdfgan.job_folder",
        lambda number, overrides: job_folder_name(int(number), list(overrides)),
        replace=True,
    )
