"""The generator ``brdfgan predict`` runs: a ``.safetensors`` weights file and what it says about itself.

Reading the file (and never unpickling anything) is :func:`brdfgan.runs.load_weights`; this module
picks the file (the shipped default or ``--weights``) and keeps the metadata ``material.json``
records.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from torch import nn

from brdfgan.errors import UserError
from brdfgan.runs import WeightsError, load_weights

DEFAULT_WEIGHTS = "default.safetensors"
# The resolution a weights file was trained at, when its metadata does not say.
FALLBACK_RESOLUTION = 256


class PredictError(UserError):
    """A predict request cannot run at all (no weights, not enough memory); one line."""


@dataclass(frozen=True)
class Model:
    """A generator ready for inference and what is known about it."""

    generator: nn.Module
    model_id: str
    target: str
    config: dict[str, Any]
    extra: dict[str, Any]
    path: Path

    @property
    def resolution(self) -> int:
        return int(self.extra.get("resolution", FALLBACK_RESOLUTION))

    def to_json(self) -> dict[str, Any]:
        """The ``model`` entry of ``material.json``."""
        return {"id": self.model_id, "class": self.target, "config": self.config, "weights": self.path.name}


def default_weights_path() -> Path:
    """The weights shipped inside the package (``brdfgan/weights/default.safetensors``)."""
    return Path(str(resources.files("brdfgan") / "weights" / DEFAULT_WEIGHTS))


def load_model(path: str | os.PathLike[str] | None = None) -> Model:
    """Load a ``.safetensors`` weights file (default: the shipped one); never unpickles anything."""
    path = Path(path) if path is not None else default_weights_path()
    if path.suffix.lower() != ".safetensors":
        raise WeightsError(
            f"{path}: predict loads .safetensors weights only (a pickle-based file could run code); "
            "convert a training checkpoint with: brdfgan export-weights RUN_DIR"
        )
    if not path.is_file() and path == default_weights_path():
        raise PredictError(f"{path}: no default weights are installed with this package; pass --weights")
    generator, meta = load_weights(path)
    return Model(
        generator=generator.eval(),
        model_id=str(meta.get("model_id", path.stem)),
        target=str(meta.get("target", "")),
        config=dict(meta.get("config", {})),
        extra=dict(meta.get("extra", {})),
        path=path,
    )
