"""``evaluate.py``: models from checkpoints or weights → metrics tables, chart and grids."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import hydra
import torch
from omegaconf import DictConfig, OmegaConf
from torch import nn

from brdfgan.config_check import check_config
from brdfgan.errors import UserError, single_console_logging
from brdfgan.evaluation.evaluator import (
    PairRows,
    evaluate_models,
    fixed_samples,
    markdown_table,
    write_grid,
    write_results,
)
from brdfgan.inference.refine import RefineConfig, RefinedGenerator
from brdfgan.runs import load_generator, model_name

log = logging.getLogger(__name__)


def _models(ckpt: Any) -> dict[str, str]:
    if isinstance(ckpt, Mapping):
        return {str(k): str(v) for k, v in ckpt.items()}
    paths = [ckpt] if isinstance(ckpt, str) else list(ckpt)
    return {model_name(p): p for p in paths}


def refined_variants(
    models: Mapping[str, nn.Module], steps: Sequence[int], settings: Mapping[str, Any] | None = None
) -> dict[str, nn.Module]:
    """The models, each followed by ``<name>+refine<N>``: the same model with ``brdfgan predict
    --refine N``'s fit (:class:`~brdfgan.inference.refine.RefinedGenerator`; the capture geometry
    from the batches' flash frames, as EXIF and the hotspot would give it), with ``settings``
    (``RefineConfig`` fields other than ``steps``, evaluate's ``refine.<key>``) changed from
    their defaults."""
    settings = dict(settings or {})
    known = {f.name for f in dataclasses.fields(RefineConfig)} - {"steps"}
    for key in settings:
        if key not in known:
            raise UserError(f"refine.{key}: not a refinement setting (one of {', '.join(sorted(known))})")
    out = dict(models)
    for count in steps:
        if not isinstance(count, int) or count < 1:
            raise UserError(f"refine_steps: {count!r} is not a positive step count")
        for name, model in models.items():
            out[f"{name}+refine{count}"] = RefinedGenerator(model, RefineConfig(**settings, steps=count))
    return out


def log_to_loggers(
    logger_cfg: DictConfig | None, results: Mapping[str, Mapping[str, float]], images: list[Path]
) -> None:
    """Send the metrics (``<model>/<metric>``) and the PNGs to the configured Lightning loggers:
    every logger takes the metrics; TensorBoard and W&B also take the chart and the grids."""
    from brdfgan.io.images import read_image
    from brdfgan.tracking import log_image

    flat = {f"{model}/{k}": v for model, values in results.items() for k, v in values.items()}
    for node in (logger_cfg or {}).values():
        logger = hydra.utils.instantiate(node)
        logger.log_metrics(flat)
        for path in images:
            log_image([logger], path.stem, read_image(path)[..., :3], step=0)
        logger.finalize("success")


def evaluate(cfg: DictConfig, out_dir: str | Path) -> dict[str, dict[str, float]]:
    """Run every model of ``cfg.ckpt`` over ``cfg.split`` of ``cfg.data`` and write the results."""
    single_console_logging()
    check_config(cfg, ("data", "metrics", "logger"))
    device = torch.device("cuda" if cfg.device == "auto" and torch.cuda.is_available() else
                          ("cpu" if cfg.device == "auto" else cfg.device))  # fmt: skip
    ckpt = OmegaConf.to_container(cfg.ckpt, resolve=True) if OmegaConf.is_config(cfg.ckpt) else cfg.ckpt
    settings = {str(k): v for k, v in dict(cfg.refine).items()}
    models = refined_variants({name: load_generator(path)[0] for name, path in _models(ckpt).items()},
                              cfg.refine_steps, settings)  # fmt: skip
    datamodule = hydra.utils.instantiate(cfg.data, _convert_="all")
    datamodule.prepare_data()
    datamodule.splits["test"] = cfg.split  # the test loader streams each sample once, in order
    datamodule.setup("test")
    make_metrics = hydra.utils.instantiate(cfg.metrics)
    pair_rows = PairRows(tuple(cfg.pair_rows.flash_only), tuple(cfg.pair_rows.fit))
    results = evaluate_models(
        models, datamodule.test_dataloader(), make_metrics, device, cfg.flash_frame, pair_rows
    )
    written = write_results(results, out_dir)
    samples = fixed_samples(
        Path(datamodule.data_dir),
        cfg.split,
        cfg.grid_samples,
        cfg.get("grid_keys"),
        align_maps=datamodule.align_maps,
    )
    for name, model in models.items():
        if samples:
            written.append(write_grid(model.cpu(), samples, Path(out_dir) / f"grid_{name}.png"))
    log_to_loggers(cfg.get("logger"), results, [p for p in written if p.suffix == ".png"])
    log.info("\n%s", markdown_table(results))
    log.info("wrote %s", ", ".join(str(p) for p in written))
    return results
