"""Generator weights on disk: safetensors with the architecture stored beside the tensors.

A weights file holds the generator's tensors and, in the safetensors metadata, the model id, the
class (``target``, restricted to :mod:`brdfgan.models`) and its constructor arguments, so the
network is rebuilt without Hydra and nothing is ever unpickled. Training checkpoints (``.ckpt``)
are read through the run's saved Hydra config (``<run>/.hydra/config.yaml``).
"""

from __future__ import annotations

import importlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

from brdfgan.io.atomic import atomic_replace

MODEL_PACKAGE = "brdfgan.models."


class WeightsError(ValueError):
    """A weights file or checkpoint cannot be used; the message names the file."""


def _build(target: str, config: Mapping[str, Any], where: Path) -> nn.Module:
    if not target.startswith(MODEL_PACKAGE):
        raise WeightsError(f"{where}: model class {target!r} is not a brdfgan model")
    module_name, _, class_name = target.rpartition(".")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
        return cls(**config)
    except (ImportError, AttributeError, TypeError) as error:
        raise WeightsError(f"{where}: cannot build {target} ({error})") from None


def save_weights(
    path: str | os.PathLike[str],
    generator: nn.Module,
    *,
    target: str,
    config: Mapping[str, Any],
    model_id: str,
    extra: Mapping[str, Any] | None = None,
    half: bool = False,
) -> Path:
    """Write ``generator``'s tensors (optionally fp16) and its architecture, atomically."""
    from safetensors.torch import save_file

    path = Path(path)
    tensors = {k: (v.half() if half and v.is_floating_point() else v).contiguous() for k, v in
               generator.state_dict().items()}  # fmt: skip
    metadata = {
        "model_id": model_id,
        "target": target,
        "config": json.dumps(dict(config), sort_keys=True),
        "extra": json.dumps(dict(extra or {}), sort_keys=True),
    }
    with atomic_replace(path) as temp:
        save_file(tensors, str(temp), metadata=metadata)
    return path


def load_weights(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """The generator of a weights file (float32, eval mode) and its metadata."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file, safe_open

    path = Path(path)
    if not path.is_file():
        raise WeightsError(f"{path}: weights file not found")
    try:
        with safe_open(str(path), framework="pt") as handle:
            metadata = dict(handle.metadata() or {})
        tensors = load_file(str(path))
        meta = {
            "model_id": metadata["model_id"],
            "target": metadata["target"],
            "config": json.loads(metadata["config"]),
            "extra": json.loads(metadata.get("extra", "{}")),
        }
    except (SafetensorError, OSError, KeyError, ValueError) as error:
        raise WeightsError(f"{path}: not a brdfgan safetensors weights file ({error})") from None
    generator = _build(meta["target"], meta["config"], path)
    try:
        generator.load_state_dict({k: v.float() for k, v in tensors.items()})
    except RuntimeError as error:
        raise WeightsError(f"{path}: tensors do not fit {meta['target']} ({error})") from None
    return generator.eval(), meta


def load_checkpoint_generator(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """The generator of a training checkpoint, rebuilt from its run's Hydra config."""
    import hydra
    from omegaconf import OmegaConf

    path = Path(path)
    if not path.is_file():
        raise WeightsError(f"{path}: checkpoint not found")
    run_config = path.resolve().parent.parent / ".hydra" / "config.yaml"
    if not run_config.is_file():
        raise WeightsError(f"{path}: no run config at {run_config} to rebuild the generator from")
    node = OmegaConf.load(run_config).model.generator
    config = {k: v for k, v in OmegaConf.to_container(node, resolve=True).items() if not k.startswith("_")}
    generator = hydra.utils.instantiate(node)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)["state_dict"]
        prefix = "generator."
        generator.load_state_dict({k[len(prefix) :]: v for k, v in state.items() if k.startswith(prefix)})
    except (RuntimeError, KeyError, OSError, EOFError) as error:
        message = " ".join(str(error).split())[:300]
        raise WeightsError(f"{path}: checkpoint does not fit its run's generator ({message})") from None
    run_name = path.resolve().parent.parent.name
    meta = {"model_id": run_name, "target": node._target_, "config": config, "extra": {}}
    return generator.eval(), meta


def load_generator(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """A generator from a ``.safetensors`` weights file or a training ``.ckpt``."""
    suffix = Path(path).suffix.lower()
    if suffix == ".safetensors":
        return load_weights(path)
    if suffix == ".ckpt":
        return load_checkpoint_generator(path)
    raise WeightsError(f"{path}: expected a .safetensors weights file or a .ckpt checkpoint")
