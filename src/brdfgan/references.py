"""Weight files of the reference predictors (:mod:`brdfgan.models.reference`), built from a dataset.

Kept out of ``models/``: averaging a dataset needs the Lightning data module.
"""

from __future__ import annotations

from pathlib import Path

from brdfgan.data.datamodule import ShardDataModule
from brdfgan.models.reference import mean_maps, reference_models
from brdfgan.runs import save_weights


def write_reference_weights(data_dir: Path, out: Path) -> list[Path]:
    """``out/{mean_maps,photo_basecolor}.safetensors`` from the mean of ``data_dir``'s train split."""
    datamodule = ShardDataModule(str(data_dir), batch_size=16, train_split=None, val_split=None,
                                 test_split="train")  # fmt: skip
    datamodule.setup("test")
    mean = mean_maps(datamodule.test_dataloader())
    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    for name, model in reference_models(mean).items():
        path = out / f"{name}.safetensors"
        save_weights(path, model, target=f"brdfgan.models.reference.{type(model).__name__}", config={},
                     model_id=f"{name} ({data_dir.name} train mean)",
                     extra={"train_mean": [round(float(v), 6) for v in mean]})  # fmt: skip
        paths.append(path)
    return paths
