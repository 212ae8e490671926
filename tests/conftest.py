from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import hydra
import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig, OmegaConf
from torch import Tensor

from brdfgan.core.svbrdf import flat_maps, join_maps, normalize_normal, validate_maps
from brdfgan.data.generation.generate_config import register_configs as register_generate_configs
from brdfgan.data.materials.base import MaterialFamily
from brdfgan.evaluation.config import register_configs as register_evaluate_configs
from brdfgan.training.config import register_configs


def random_maps(
    height: int, width: int, *, seed: int = 0, batch: tuple[int, ...] = (), dtype: torch.dtype = torch.float32
) -> Tensor:
    """Valid, spatially varying map sets that are not symmetric in X or Y."""
    g = torch.Generator().manual_seed(seed)
    shape = (*batch, 1, height, width)

    def rand(channels: int = 1) -> Tensor:
        return torch.rand((*batch, channels, height, width), generator=g, dtype=dtype)

    ramp = torch.linspace(-0.4, 0.25, height, dtype=dtype).view(height, 1).expand(shape)
    normal = torch.cat([0.5 * rand() - 0.1, ramp + 0.1 * rand(), torch.ones(shape, dtype=dtype)], dim=-3)
    return join_maps(rand(3), normalize_normal(normal), 0.1 + 0.9 * rand(), (rand() > 0.5).to(dtype))


def tilted_plane(
    size: int = 32,
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0),
    *,
    basecolor: tuple[float, float, float] = (0.8, 0.8, 0.8),
    roughness: float = 0.5,
    metallic: float = 0.0,
) -> Tensor:
    """A uniform plane ``(8, size, size)``, by default a white-ish dielectric, optionally with every
    normal tilted the same way (for relighting, preview and statistics tests)."""
    maps = flat_maps(size, size, basecolor=basecolor, roughness=roughness, metallic=metallic)
    maps[3:6] = normalize_normal(torch.tensor(normal).view(3, 1, 1).expand(3, size, size).clone())
    return maps


def family_maps(
    family: MaterialFamily, params: dict[str, float] | None = None, seed: int = 0, size: int = 128
) -> Tensor:
    """The checked map set ``(8, size, size)`` that ``family`` paints with ``params`` (its defaults
    for the rest) from a generator seeded with ``seed``."""
    maps = family.make_maps(params or {}, size, torch.Generator().manual_seed(seed))
    validate_maps(maps)
    return maps


def relative_l1(a: Tensor, b: Tensor) -> float:
    """``Σ|a − b| / Σ|b|``."""
    return float((a - b).abs().sum() / b.abs().sum())


# The project, wherever a test file sits under tests/: test modules take their paths from here.
ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"
GOLDEN = ROOT / "tests" / "expected"  # stored golden values
SHARED = ROOT.parent / "shared"  # data beside the checkout (scans, the OOD sets), where present
register_configs()
register_generate_configs()
register_evaluate_configs()


def compose_train(overrides: list[str], root: Path) -> DictConfig:
    """``conf/train.yaml`` with ``overrides``, its project root at ``root`` (a test's ``tmp_path``,
    so two test runs on one machine never share a folder)."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="train", overrides=overrides, return_hydra_config=True)
    # Outside a Hydra run there is no runtime.output_dir: pin the paths the run would get.
    OmegaConf.set_struct(cfg, False)
    cfg.paths.root_dir = str(root)
    cfg.paths.output_dir = str(root / "run")
    del cfg["hydra"]
    return cfg


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny dataset of conf/data/tiny.yaml, made once with Mitsuba."""
    root = tmp_path_factory.mktemp("project")
    cfg = compose_train(["debug=default"], root)
    module = hydra.utils.instantiate(cfg.data, _convert_="all")
    assert module.data_dir == root / "data" / "tiny"
    module.prepare_data()
    return root


# The project's entry points: run_python resolves them to this checkout's scripts.
ENTRY_POINTS = ("train.py", "evaluate.py", "generate.py")


def run_python(
    *args: str, cwd: Path, project_root: Path | None = None, timeout: float = 600
) -> subprocess.CompletedProcess[str]:
    """``python ARGS`` in a subprocess, as a user runs this checkout's commands: its sources first
    on the path, ``PROJECT_ROOT`` (where data and logs go) at ``project_root`` or else ``cwd``,
    W&B silent. A first argument naming an entry point (``train.py``, ``evaluate.py``,
    ``generate.py``) runs that script of this checkout; ``-m brdfgan.cli …`` runs the console."""
    root = CONF.parent
    command = [str(root / args[0]), *args[1:]] if args and args[0] in ENTRY_POINTS else list(args)
    env = {**os.environ, "PYTHONPATH": str(root / "src"), "PROJECT_ROOT": str(project_root or cwd),
           "WANDB_SILENT": "true"}  # fmt: skip
    return subprocess.run([sys.executable, *command], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)  # fmt: skip
