"""Untrusted run folders, checkpoints and weights files run no code (brdfgan.runs).

Every path that reads a run folder builds its networks through ``network_from_config``: only
the project's own network classes with plain arguments. The crafted configs below made
``evaluate.py`` unpickle a payload and ``builtins.open`` empty a file before this was so.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import torch
import yaml

from brdfgan.models.generator import Generator
from brdfgan.runs import (
    WeightsError,
    load_generator,
    load_weights,
    network_from_config,
    save_weights,
)
from tests.conftest import run_python

ROOT = Path(__file__).resolve().parents[1]
GENERATOR = "brdfgan.models.generator.Generator"
SMALL = {"in_channels": 3, "width": 4, "downsamplings": 1, "residual_blocks": 1}


class Payload:
    """Unpickling this creates ``marker``: proof that a pickle ran code."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, ...]:
        return (open, (str(self.marker), "w"))


def _crafted_run(tmp_path: Path, generator_node: dict[str, Any]) -> tuple[Path, Path]:
    """A run folder with a real checkpoint whose stored config holds ``generator_node``."""
    run = tmp_path / "run"
    (run / ".hydra").mkdir(parents=True)
    (run / "checkpoints").mkdir()
    (run / ".hydra" / "config.yaml").write_text(
        yaml.safe_dump({"model": {"generator": generator_node}, "seed": 0})
    )
    generator = Generator(**SMALL)
    checkpoint = run / "checkpoints" / "last.ckpt"
    torch.save({"state_dict": {f"generator.{k}": v for k, v in generator.state_dict().items()}}, checkpoint)
    return run, checkpoint


def _evil_nodes(tmp_path: Path) -> dict[str, tuple[dict[str, Any], str]]:
    """name → (model.generator node, the target the error must name)."""
    evil = tmp_path / "evil.ckpt"
    torch.save(Payload(tmp_path / "pwned"), evil)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    return {
        "pickle": ({"_target_": "torch.load", "f": str(evil), "weights_only": False}, "torch.load"),
        "open": ({"_target_": "builtins.open", "file": str(victim), "mode": "w"}, "builtins.open"),
        "nested": (
            {
                "_target_": GENERATOR,
                **SMALL,
                "width": {"_target_": "builtins.open", "file": str(victim), "mode": "w"},
            },
            f"{GENERATOR}: nested _target_",
        ),
        "not a network": (
            {"_target_": "brdfgan.data.loading.datamodule.ShardDataModule", "data_dir": str(tmp_path)},
            "brdfgan.data.loading.datamodule.ShardDataModule",
        ),
    }


def _untouched(tmp_path: Path) -> None:
    assert not (tmp_path / "pwned").exists(), "the pickle payload ran"
    assert (tmp_path / "victim.txt").read_text() == "precious", "builtins.open was called"


@pytest.mark.parametrize("case", ["pickle", "open", "nested", "not a network"])
def test_a_crafted_run_config_is_refused_without_running_anything(tmp_path: Path, case: str) -> None:
    node, target = _evil_nodes(tmp_path)[case]
    _run, checkpoint = _crafted_run(tmp_path, node)
    with pytest.raises(WeightsError, match=rf"config\.yaml: not a brdfgan model config \({target}"):
        load_generator(checkpoint)
    _untouched(tmp_path)


@pytest.mark.integration
def test_evaluate_and_export_weights_refuse_a_crafted_run_in_one_line(tmp_path: Path) -> None:
    node, _ = _evil_nodes(tmp_path)["pickle"]
    run, checkpoint = _crafted_run(tmp_path, node)
    expected = f"error: {run.resolve()}/.hydra/config.yaml: not a brdfgan model config (torch.load)"
    for command in (
        ["evaluate.py", f"ckpt={checkpoint}", "data=tiny"],
        ["-m", "brdfgan.cli", "export-weights", str(run)],
    ):
        result = run_python(*command, cwd=tmp_path)
        assert result.returncode == 2, result.stderr[-2000:]
        assert result.stderr.strip().splitlines()[-1] == expected
        assert "Traceback" not in result.stderr
    _untouched(tmp_path)
    assert not (tmp_path / "data").exists()  # refused before any data was prepared


def test_a_weights_file_naming_another_callable_is_refused(tmp_path: Path) -> None:
    generator = Generator(**SMALL)
    for target in ("builtins.open", "brdfgan.models.reference.mean_maps", "brdfgan.runs.save_weights"):
        path = save_weights(tmp_path / "w.safetensors", generator, target=target, config={}, model_id="x")
        with pytest.raises(WeightsError, match=rf"w\.safetensors: not a brdfgan model config \({target}\)"):
            load_weights(path)
    nested = {**SMALL, "width": {"_target_": "builtins.open", "file": "x"}}
    path = save_weights(tmp_path / "n.safetensors", generator, target=GENERATOR, config=nested, model_id="x")
    with pytest.raises(WeightsError, match="nested _target_"):
        load_weights(path)


def test_absurd_sizes_are_refused_before_allocating(tmp_path: Path) -> None:
    generator = Generator(**SMALL)
    huge = {**SMALL, "width": 1_000_000}
    path = save_weights(tmp_path / "huge.safetensors", generator, target=GENERATOR, config=huge, model_id="x")
    # Sized on the meta device: terabytes are refused in well under a second, nothing allocated.
    with pytest.raises(WeightsError, match=r"huge\.safetensors: .* would have .* parameters \(~[\d,]+ GiB\)"):
        load_weights(path)
    as_float = {**SMALL, "width": 1e6}
    path = save_weights(
        tmp_path / "float.safetensors", generator, target=GENERATOR, config=as_float, model_id="x"
    )
    with pytest.raises(WeightsError, match=r"width=1000000\.0: expected int"):
        load_weights(path)
    with pytest.raises(WeightsError, match="has no parameter 'depth'"):
        network_from_config({"_target_": GENERATOR, "depth": 3}, "x.yaml")


def test_the_allowed_classes_still_load(tmp_path: Path) -> None:
    _run, checkpoint = _crafted_run(tmp_path, {"_target_": GENERATOR, **SMALL})
    generator, meta = load_generator(checkpoint)
    assert isinstance(generator, Generator) and meta["config"] == SMALL and meta["target"] == GENERATOR
    # The discriminator node of a run config is a Hydra partial: the flag is not an argument.
    discriminator = network_from_config(
        {"_target_": "brdfgan.models.discriminator.MultiScaleDiscriminator", "_partial_": True, "width": 4},
        "config.yaml",
    )
    assert sum(p.numel() for p in discriminator.parameters()) > 0


@pytest.mark.integration
def test_predict_refuses_a_crafted_weights_file_in_one_line(tmp_path: Path) -> None:
    generator = Generator(**SMALL)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    weights = save_weights(tmp_path / "evil.safetensors", generator, target="builtins.open",
                           config={"file": str(victim), "mode": "w"}, model_id="x")  # fmt: skip
    photo = ROOT / "src" / "brdfgan" / "samples" / "bricks.jpg"
    result = run_python("-m", "brdfgan.cli", "predict", str(photo), "--weights", str(weights), "--out",
                        str(tmp_path / "out"), cwd=tmp_path)  # fmt: skip
    assert result.returncode == 2, result.stderr[-2000:]
    assert f"error: {weights}: not a brdfgan model config (builtins.open)" in result.stderr
    assert "Traceback" not in result.stderr and victim.read_text() == "precious"


def test_the_generator_like_classes_follow_the_protocol() -> None:
    from brdfgan.core.flash_geometry import centred_flash_frame
    from brdfgan.models import AnchoredUNet
    from brdfgan.models.deschaintre2018 import Deschaintre2018
    from brdfgan.models.reference import ConstantMaps, PhotoAsBasecolor
    from brdfgan.runs import GeneratorLike

    photo = torch.rand(1, 3, 32, 32)
    flash = centred_flash_frame(1, 32, 32)
    networks = (
        Generator(**SMALL),
        Deschaintre2018(width=4, levels=2),
        AnchoredUNet(width=4, depth=2),
        ConstantMaps(),
        PhotoAsBasecolor(),
    )
    for network in networks:
        assert isinstance(network, GeneratorLike)
        assert isinstance(network.size_multiple, int) and isinstance(network.config(), dict)
        # Every generator is called as the protocol says: the photo and its flash frame, or none.
        assert network(photo, flash).shape == network(photo).shape == (1, 8, 32, 32)
        # config() rebuilds the same architecture through the one allowlisted builder
        target = f"{type(network).__module__}.{type(network).__name__}"
        rebuilt = network_from_config({"_target_": target, **network.config()}, "test")
        assert rebuilt.state_dict().keys() == network.state_dict().keys()
