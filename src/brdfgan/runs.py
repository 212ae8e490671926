"""Run folders, checkpoints and weights files — and the one way to build a network from them.

A training run folder (``train.py``'s output directory) holds ``.hydra/config.yaml`` and
``checkpoints/*.ckpt``. Every path that reads a run folder, a checkpoint or a weights file
(evaluate, export_weights, init_from, resume, predict, report) goes through this module, and
every network it builds is made by :func:`network_from_config`: only the project's own network
classes (:data:`NETWORK_CLASSES`), only plain values as their arguments (no nested
``_target_``, nothing Hydra could turn into a call), type-checked against the constructor and
sized on the ``meta`` device before any memory is allocated. A run folder is data, not code: a
crafted ``config.yaml`` whose ``model.generator`` says ``_target_: torch.load`` or
``builtins.open`` is refused with one line instead of being called.

Checkpoints are read with ``torch.load(weights_only=True)`` (no arbitrary unpickling); weights
files are safetensors with the architecture as JSON metadata.
"""

from __future__ import annotations

import json
import os
import pickle
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import torch
from torch import Tensor, nn

from brdfgan.errors import UserError
from brdfgan.io.atomic import atomic_replace

# Every class a stored config or weights file may name. A dotted path outside this table —
# even inside brdfgan (a function, a CLI, a writer) — is not a network and is never called.
NETWORK_CLASSES: dict[str, tuple[str, str]] = {
    "brdfgan.models.generator.Generator": ("brdfgan.models.generator", "Generator"),
    "brdfgan.models.deschaintre2018.Deschaintre2018": ("brdfgan.models.deschaintre2018", "Deschaintre2018"),
    "brdfgan.models.discriminator.MultiScaleDiscriminator": (
        "brdfgan.models.discriminator",
        "MultiScaleDiscriminator",
    ),
    "brdfgan.models.discriminator.PatchDiscriminator": ("brdfgan.models.discriminator", "PatchDiscriminator"),
    "brdfgan.models.reference.ConstantMaps": ("brdfgan.models.reference", "ConstantMaps"),
    "brdfgan.models.reference.PhotoAsBasecolor": ("brdfgan.models.reference", "PhotoAsBasecolor"),
    "brdfgan.models.reference.DeLitPhoto": ("brdfgan.models.reference", "DeLitPhoto"),
    "brdfgan.models.anchored.AnchoredUNet": ("brdfgan.models.anchored", "AnchoredUNet"),
}
# Hydra flags that may sit in a stored network node; they change how Hydra would call the
# class, and we call it ourselves, so they are dropped (``_partial_``: the discriminator).
IGNORED_HYDRA_FLAGS = frozenset({"_partial_", "_convert_", "_recursive_"})
# The paper's generator has 45.6 M parameters; a stored config asking for more than this is
# not a model anyone trained (``width=1e6`` would need terabytes) and is refused unbuilt.
MAX_NETWORK_PARAMETERS = 2_000_000_000

RUN_CONFIG = Path(".hydra") / "config.yaml"
RUN_HYDRA = Path(".hydra") / "hydra.yaml"
RUN_OVERRIDES = Path(".hydra") / "overrides.yaml"
CHECKPOINT_DIR = "checkpoints"
LAST_CHECKPOINT = "last.ckpt"


class WeightsError(UserError):
    """A weights file, checkpoint or run folder cannot be used; the message names the file."""


@runtime_checkable
class GeneratorLike(Protocol):
    """What the evaluator, ``brdfgan predict`` and the exporters need of a generator."""

    @property
    def size_multiple(self) -> int:
        """Input height and width must be multiples of this."""
        ...

    def config(self) -> dict[str, Any]:
        """The constructor arguments (plain values) that rebuild this network."""
        ...

    def __call__(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        """Photo ``(B, 3, H, W)`` linear LDR and its flash frame ``(B, 3)``
        (:mod:`brdfgan.core.flash_geometry`; ``None``: the hotspot at the centre, or not read by a
        network blind to it) → maps ``(B, 8, H, W)`` in the stored encodings."""
        ...


# -- run folders ---------------------------------------------------------------------------


@dataclass(frozen=True)
class RunFolder:
    """A ``train.py`` output directory."""

    path: Path

    @classmethod
    def of_checkpoint(cls, checkpoint: str | os.PathLike[str]) -> RunFolder:
        """The run a checkpoint belongs to (``RUN/checkpoints/NAME.ckpt``)."""
        return cls(Path(checkpoint).resolve().parent.parent)

    @property
    def name(self) -> str:
        return self.path.name

    @property
    def config_path(self) -> Path:
        return self.path / RUN_CONFIG

    @property
    def hydra_path(self) -> Path:
        return self.path / RUN_HYDRA

    @property
    def overrides_path(self) -> Path:
        return self.path / RUN_OVERRIDES

    @property
    def checkpoint_dir(self) -> Path:
        return self.path / CHECKPOINT_DIR

    def is_run(self) -> bool:
        return self.config_path.is_file()

    def config(self) -> Any:
        """The run's composed config (an OmegaConf ``DictConfig``; data only, nothing called)."""
        from omegaconf import OmegaConf
        from omegaconf.errors import OmegaConfBaseException

        if not self.config_path.is_file():
            raise WeightsError(f"{self.path}: not a training run directory (no {RUN_CONFIG})")
        try:
            return OmegaConf.load(self.config_path)
        except (OSError, OmegaConfBaseException, ValueError) as error:
            raise WeightsError(f"{self.config_path}: unreadable run config ({_short(error)})") from None

    def checkpoint(self, which: str = "last") -> Path:
        """``last``/``best`` checkpoint of this run (best: the newest epoch file), or a path."""
        if which not in ("last", "best"):
            return Path(which)
        if which == "last":
            path = self.checkpoint_dir / LAST_CHECKPOINT
        else:
            candidates = sorted(p for p in self.checkpoint_dir.glob("*.ckpt") if p.name != LAST_CHECKPOINT)
            path = candidates[-1] if candidates else self.checkpoint_dir / "best.ckpt"
        if not path.is_file():
            raise WeightsError(f"{path}: no {which} checkpoint in {self.path}")
        return path


# -- building networks ----------------------------------------------------------------------


def network_from_config(node: Any, where: str | os.PathLike[str]) -> nn.Module:
    """Build a network from a stored config node — the only way a stored config becomes code.

    ``node``: a mapping (dict or ``DictConfig``) with ``_target_`` naming one of
    :data:`NETWORK_CLASSES` and plain constructor arguments. ``where``: the file it came from,
    for the message. Raises :class:`WeightsError` (``<where>: not a brdfgan model config
    (<target>)``) for anything else, before importing or allocating anything.
    """
    arguments = _plain_arguments(node, where)
    target = str(arguments.pop("_target_", None))
    return build_network(target, arguments, where)


def stored_constructor_arguments(
    cls: type, arguments: Mapping[str, Any], where: str | os.PathLike[str], target: str
) -> dict[str, Any]:
    """The constructor arguments of ``cls`` from a stored config's ``arguments`` (``target`` its
    name, ``where`` the file, for errors): brought up to date (its ``upgrade_stored_config``, where
    it has one), less the options ``cls`` has retired (its ``RETIRED_OPTIONS``: name → the value the
    network is now always built with), so that configs stored before an option went still load; a
    retired option stored with another value cannot be honoured: an error."""
    upgrade = getattr(cls, "upgrade_stored_config", None)
    arguments = upgrade(arguments) if upgrade else arguments
    retired: Mapping[str, Any] = getattr(cls, "RETIRED_OPTIONS", {})
    for name, value in arguments.items():
        if name in retired and value != retired[name]:
            raise WeightsError(
                f"{where}: {target} {name}={value!r} is a retired option; this version only builds "
                f"{name}={retired[name]!r}"
            )
    return {name: value for name, value in arguments.items() if name not in retired}


def build_network(target: str, arguments: Mapping[str, Any], where: str | os.PathLike[str]) -> nn.Module:
    """Build the allowlisted class ``target`` with ``arguments`` (checked, then sized unallocated)."""
    import importlib

    from brdfgan.config_check import describe, fits, signature_of

    if target not in NETWORK_CLASSES:
        raise WeightsError(f"{where}: not a brdfgan model config ({target})")
    module_name, class_name = NETWORK_CLASSES[target]
    cls = getattr(importlib.import_module(module_name), class_name)
    _reject_nested_targets(arguments, where, target)
    arguments = stored_constructor_arguments(cls, arguments, where, target)
    parameters, hints, _ = signature_of(cls)
    for name, value in arguments.items():
        if name not in parameters:
            raise WeightsError(f"{where}: {target} has no parameter {name!r}")
        if fits(value, hints.get(name, Any)) is False:
            raise WeightsError(f"{where}: {target} {name}={value!r}: expected {describe(hints[name])}")
    try:
        with torch.device("meta"):
            unallocated = cls(**arguments)
    except (TypeError, ValueError) as error:
        raise WeightsError(f"{where}: cannot build {target} ({_short(error)})") from None
    parameters_count = sum(p.numel() for p in unallocated.parameters())
    if parameters_count > MAX_NETWORK_PARAMETERS:
        gib = parameters_count * 4 / 2**30
        raise WeightsError(
            f"{where}: {target} with {dict(arguments)} would have {parameters_count:.3g} parameters "
            f"(~{gib:,.0f} GiB); not a brdfgan model"
        )
    return cls(**arguments)


def _plain_arguments(node: Any, where: str | os.PathLike[str]) -> dict[str, Any]:
    from omegaconf import DictConfig, OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    if isinstance(node, DictConfig):
        try:
            node = OmegaConf.to_container(node, resolve=True)
        except OmegaConfBaseException as error:
            raise WeightsError(f"{where}: unreadable model config ({_short(error)})") from None
    if not isinstance(node, Mapping) or "_target_" not in node:
        raise WeightsError(f"{where}: not a brdfgan model config (no _target_)")
    arguments = {str(k): v for k, v in node.items() if str(k) not in IGNORED_HYDRA_FLAGS}
    for key in arguments:
        if key.startswith("_") and key != "_target_":
            raise WeightsError(f"{where}: not a brdfgan model config ({key} in {node['_target_']})")
    return arguments


def _reject_nested_targets(value: Any, where: str | os.PathLike[str], target: str) -> None:
    """Only plain values (numbers, strings, booleans, None, lists and mappings of them)."""
    if isinstance(value, Mapping):
        for key, item in value.items():
            if str(key).startswith("_"):
                raise WeightsError(f"{where}: not a brdfgan model config ({target}: nested {key})")
            _reject_nested_targets(item, where, target)
    elif isinstance(value, list | tuple):
        for item in value:
            _reject_nested_targets(item, where, target)
    elif not (value is None or isinstance(value, bool | int | float | str)):
        raise WeightsError(f"{where}: not a brdfgan model config ({target}: {type(value).__name__} value)")


# -- checkpoints ----------------------------------------------------------------------------


def read_checkpoint(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A Lightning checkpoint's contents, loaded without arbitrary unpickling.

    Raises :class:`WeightsError` naming ``path`` for a missing, truncated or corrupt file.
    """
    path = Path(path)
    if not path.is_file():
        raise WeightsError(f"{path}: checkpoint not found")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as error:  # weights_only refusing a pickle that wants code
        raise WeightsError(f"{path}: not a brdfgan checkpoint ({_short(error)})") from None
    except (RuntimeError, OSError, EOFError, ValueError, zipfile.BadZipFile, KeyError) as error:
        reason = f"truncated or corrupt: {_short(error)}"
        raise WeightsError(f"{path}: not a readable checkpoint ({reason})") from None
    if not isinstance(state, dict):
        raise WeightsError(f"{path}: not a Lightning checkpoint ({type(state).__name__}, not a mapping)")
    return state


def checkpoint_networks(path: str | os.PathLike[str]) -> dict[str, dict[str, Tensor]]:
    """The state dicts per network (``generator``, ``discriminator``) of a training checkpoint."""
    state = read_checkpoint(path)
    if not isinstance(state.get("state_dict"), Mapping):
        raise WeightsError(f"{path}: not a Lightning checkpoint (no state_dict)")
    networks: dict[str, dict[str, Tensor]] = {}
    for key, value in state["state_dict"].items():
        network, _, name = str(key).partition(".")
        if network in ("generator", "discriminator"):
            networks.setdefault(network, {})[name] = value
    return networks


def network_weights(path: str | os.PathLike[str]) -> dict[str, dict[str, Tensor]]:
    """The state dicts per network stored in a ``.ckpt``, or the generator of a ``.safetensors``."""
    path = Path(path)
    if path.suffix.lower() == ".safetensors":
        tensors, _ = _read_safetensors(path)
        return {"generator": {name: value.float() for name, value in tensors.items()}}
    return checkpoint_networks(path)


def load_checkpoint_generator(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """The generator of a training checkpoint (eval mode), rebuilt from its run's stored config."""
    path = Path(path)
    if not path.is_file():
        raise WeightsError(f"{path}: checkpoint not found")
    run = RunFolder.of_checkpoint(path)
    if not run.is_run():
        raise WeightsError(f"{path}: no run config at {run.config_path} to rebuild the generator from")
    from omegaconf import OmegaConf

    node = OmegaConf.select(run.config(), "model.generator", default=None)
    if node is None:
        raise WeightsError(f"{run.config_path}: not a brdfgan model config (no model.generator)")
    config = _plain_arguments(node, run.config_path)
    target = str(config.pop("_target_"))
    generator = build_network(target, config, run.config_path)
    try:
        generator.load_state_dict(checkpoint_networks(path).get("generator", {}))
    except RuntimeError as error:
        raise WeightsError(f"{path}: checkpoint does not fit its run's generator ({_short(error)})") from None
    meta = {"model_id": run.name, "target": target, "config": config, "extra": {}}
    return generator.eval(), meta


def check_resume_checkpoint(path: str | os.PathLike[str], networks: Mapping[str, nn.Module]) -> None:
    """Refuse (one line) a checkpoint that ``ckpt_path`` cannot resume this run from: unreadable,
    or holding networks of another architecture than ``networks`` (name → this run's module)."""
    stored = checkpoint_networks(path)
    for name, network in networks.items():
        expected = {k: tuple(v.shape) for k, v in network.state_dict().items()}
        found = {k: tuple(v.shape) for k, v in stored.get(name, {}).items()}
        if expected != found:
            missing = sorted(set(expected) - set(found))
            other = sorted(k for k in expected if k in found and expected[k] != found[k])
            detail = (
                f"{len(missing)} missing tensors (e.g. {missing[0]})"
                if missing
                else (f"{other[0]} is {found[other[0]]}, this run's is {expected[other[0]]}" if other else
                      f"{len(set(found) - set(expected))} unexpected tensors")
            )  # fmt: skip
            raise WeightsError(f"{path}: the {name} does not fit this run's model ({detail})")
    extra = sorted(set(stored) - set(networks))
    if extra:
        raise WeightsError(f"{path}: holds a {extra[0]} this run's model does not have (another loss?)")


# -- weights files (safetensors) ------------------------------------------------------------


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


def _read_safetensors(path: Path) -> tuple[dict[str, Tensor], dict[str, str]]:
    from safetensors import SafetensorError
    from safetensors.torch import load_file, safe_open

    if not path.is_file():
        raise WeightsError(f"{path}: weights file not found")
    try:
        with safe_open(str(path), framework="pt") as handle:
            metadata = dict(handle.metadata() or {})
        return load_file(str(path)), metadata
    except (SafetensorError, OSError, ValueError) as error:
        raise WeightsError(f"{path}: not a brdfgan safetensors weights file ({_short(error)})") from None


def load_weights(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """The generator of a weights file (float32, eval mode) and its metadata."""
    path = Path(path)
    tensors, metadata = _read_safetensors(path)
    try:
        meta = {
            "model_id": metadata["model_id"],
            "target": metadata["target"],
            "config": json.loads(metadata["config"]),
            "extra": json.loads(metadata.get("extra", "{}")),
        }
    except (KeyError, ValueError) as error:
        raise WeightsError(f"{path}: not a brdfgan safetensors weights file ({_short(error)})") from None
    if not isinstance(meta["config"], dict):
        raise WeightsError(f"{path}: not a brdfgan model config (config is not a mapping)")
    generator = network_from_config({"_target_": meta["target"], **meta["config"]}, path)
    try:
        generator.load_state_dict({k: v.float() for k, v in tensors.items()})
    except RuntimeError as error:
        raise WeightsError(f"{path}: tensors do not fit {meta['target']} ({_short(error)})") from None
    return generator.eval(), meta


def load_generator(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """A generator from a ``.safetensors`` weights file or a training ``.ckpt``."""
    suffix = Path(path).suffix.lower()
    if suffix == ".safetensors":
        return load_weights(path)
    if suffix == ".ckpt":
        return load_checkpoint_generator(path)
    raise WeightsError(f"{path}: expected a .safetensors weights file or a .ckpt checkpoint")


def model_name(path: str | os.PathLike[str]) -> str:
    """How a model file is named in tables: its run's name for a checkpoint, else the file stem."""
    path = Path(path)
    return RunFolder.of_checkpoint(path).name if path.suffix.lower() == ".ckpt" else path.stem


def _short(error: BaseException, limit: int = 300) -> str:
    text = " ".join(str(error).split()) or type(error).__name__
    return text if len(text) <= limit else text[: limit - 1] + "…"


__all__ = [
    "MAX_NETWORK_PARAMETERS",
    "NETWORK_CLASSES",
    "GeneratorLike",
    "RunFolder",
    "WeightsError",
    "build_network",
    "check_resume_checkpoint",
    "checkpoint_networks",
    "load_checkpoint_generator",
    "load_generator",
    "load_weights",
    "model_name",
    "network_from_config",
    "network_weights",
    "read_checkpoint",
    "save_weights",
]
