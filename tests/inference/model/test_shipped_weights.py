"""The weights shipped inside the package: they load without Hydra or pickle, and a fixed sample
photo still gives the stored output statistics (so an accidental change to the weights or to
the preprocessing is caught).

After deliberately retraining or changing preprocessing, refresh the expectations with::

    python -m tests.inference.model.test_shipped_weights
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import torch

from brdfgan.core.svbrdf import CHANNELS
from brdfgan.inference.intake.photo import read_photo
from brdfgan.inference.intake.preprocess import preprocess
from brdfgan.inference.model.tiling import predict_maps
from brdfgan.inference.model.weights import default_weights_path, load_model
from tests.conftest import GOLDEN

EXPECTED = GOLDEN / "shipped_weights.json"
SAMPLE = "wood_planks.jpg"
MAX_BYTES = 30 * 1024 * 1024


def output_statistics() -> dict[str, object]:
    """Per-map mean and standard deviation of the shipped model's prediction for the sample."""
    model = load_model()
    photo = read_photo(Path(str(resources.files("brdfgan") / "samples" / SAMPLE)))
    prepared = preprocess(photo, model.resolution)
    maps = predict_maps(model.generator, prepared.photo[None])[0].double()
    stats = {name: {"mean": maps[index].mean().item(), "std": maps[index].std().item()}
             for name, index in CHANNELS.items()}  # fmt: skip
    return {"model_id": model.model_id, "sample": SAMPLE, "statistics": stats}


def test_shipped_weights_load_and_are_small() -> None:
    path = default_weights_path()
    assert path.is_file(), f"{path}: the package ships no default weights"
    assert path.stat().st_size <= MAX_BYTES
    model = load_model()
    summary = json.loads(path.with_suffix(".json").read_text())
    assert model.model_id == summary["model_id"]
    assert model.resolution == summary["resolution"]
    for key in ("optimizer_steps", "wall_time_s", "hardware", "dataset", "loss"):
        assert key in model.extra, key


def test_the_networks_code_defaults_are_the_shipped_model() -> None:
    # AnchoredUNet() with no arguments builds the shipped network: its stored config, less the
    # retired options it names at the value now always built, is the constructor's defaults.
    from brdfgan.models.anchored import AnchoredUNet
    from brdfgan.runs import load_weights

    generator, meta = load_weights(default_weights_path())
    stored = dict(meta["config"])
    for name, value in AnchoredUNet.RETIRED_OPTIONS.items():
        assert stored.pop(name, value) == value
    assert isinstance(generator, AnchoredUNet)
    assert {**AnchoredUNet().config(), **stored} == AnchoredUNet().config()
    assert generator.config() == AnchoredUNet().config()


def test_shipped_weights_give_the_stored_statistics_on_a_fixed_sample() -> None:
    expected = json.loads(EXPECTED.read_text())
    actual = output_statistics()
    assert actual["model_id"] == expected["model_id"], (
        "weights changed: refresh tests/expected (see docstring)"
    )
    for name, values in expected["statistics"].items():
        for key, value in values.items():
            # fp16 weights evaluated in fp32: bit-stable on one machine; 1e-3 leaves room for
            # another CPU's summation order, far below what a changed weight or crop moves.
            assert abs(actual["statistics"][name][key] - value) < 1e-3, (name, key)
    # The prediction is a real material estimate, not a constant: every map varies.
    assert all(v["std"] > 1e-3 for k, v in expected["statistics"].items() if k != "metallic")


if __name__ == "__main__":
    torch.set_num_threads(1)
    EXPECTED.write_text(json.dumps(output_statistics(), indent=2) + "\n")
    print(EXPECTED.read_text())
