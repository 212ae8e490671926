"""Weight files of the reference predictors (:mod:`brdfgan.models.reference`), built from a dataset.

Kept out of ``models/``: averaging a dataset needs the Lightning data module.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from torch import nn

from brdfgan.data.loading.datamodule import ShardDataModule
from brdfgan.errors import UserError
from brdfgan.models.reference import fit_delit_reference, mean_maps, reference_models
from brdfgan.runs import save_weights

REFERENCE_NAMES = ("mean_maps", "photo_basecolor", "de_lit")


def write_reference_weights(data_dir: Path, out: Path, only: Sequence[str] = REFERENCE_NAMES) -> list[Path]:
    """``out/<name>.safetensors`` for each reference of ``only``, fitted on ``data_dir``'s train
    split: ``mean_maps`` and ``photo_basecolor`` from its mean maps, ``de_lit`` from its photos
    and maps (:func:`~brdfgan.models.reference.fit_delit_reference`)."""
    unknown = sorted(set(only) - set(REFERENCE_NAMES))
    if unknown or not only:
        raise UserError(f"--only {' '.join(only)}: choose among {', '.join(REFERENCE_NAMES)}")

    def train_batches() -> ShardDataModule:
        datamodule = ShardDataModule(str(data_dir), batch_size=16, train_split=None, val_split=None,
                                     test_split="train")  # fmt: skip
        datamodule.setup("test")
        return datamodule

    models: dict[str, tuple[nn.Module, dict[str, Any]]] = {}
    if {"mean_maps", "photo_basecolor"} & set(only):
        mean = mean_maps(train_batches().test_dataloader())
        averaged: dict[str, Any] = {"train_mean": [round(float(v), 6) for v in mean]}
        models.update({name: (model, averaged) for name, model in reference_models(mean).items()})
    if "de_lit" in only:
        delit = fit_delit_reference(train_batches().test_dataloader())
        models["de_lit"] = (delit, {name: round(float(b), 6) for name, b in delit.named_buffers()})
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    for name in only:
        model, extra = models[name]
        path = out / f"{name}.safetensors"
        save_weights(path, model, target=f"brdfgan.models.reference.{type(model).__name__}", config={},
                     model_id=f"{name} ({data_dir.name} train split)", extra=extra)  # fmt: skip
        paths.append(path)
    return paths
