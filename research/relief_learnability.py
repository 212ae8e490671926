"""Normals-only learnability: can a network learn relief from these training photos?

Trains the v4 generator (``experiment=anchored``'s model) on its normals alone — the angular
loss, nothing else — for ``--steps`` batches of photos rendered on the fly (``data=rendered``,
any of its options as Hydra overrides), then scores the normals on the validation split's Mitsuba
photos (delivered through the evaluation sensor): mean angle against the flat map's, and the
slope cosine (the evaluator's :class:`~brdfgan.metrics.SlopeAgreement`: pooled over texels, the
cosine between predicted and true slope fields; 0 for flat or unrelated normals, 1 for the right
relief up to scale).
The observable angle counts only the texels whose relief the photo shows (the flash's relief
shading, :func:`brdfgan.metrics.relief_shading`, above the photo's 8-bit rounding,
:func:`research.relief.observable_mask`). Each change to the data is judged by this run at
equal steps (issue 46, item 1d). Writes
``OUT.json`` (the curve and the final scores).

    python -m research.relief_learnability --out outputs/learnability/base
    python -m research.relief_learnability --out outputs/learnability/bumps \\
        data.relief.bump_probability=0.5
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import hydra
import torch
from torch import Tensor, nn

from brdfgan.core.svbrdf import NORMAL
from brdfgan.data.loading.rendered import RenderedDataModule
from brdfgan.io.atomic import write_text_atomic
from brdfgan.losses.parameter import angular_distance
from brdfgan.metrics import SlopeAgreement
from brdfgan.metrics import relief_shading as flash_relief_shading
from brdfgan.training.config import register_configs
from research.relief import observable_mask, srgb8_rounding_log

CONF = Path(__file__).resolve().parents[1] / "conf"


def normal_scores(pred: Tensor, true: Tensor, observable: Tensor) -> dict[str, Tensor]:
    """Sums for the normals' angles over a batch: angle to the truth and the flat map's angle
    (degrees, summed over texels, and over the ``observable`` texels), and the texel count.

    Shape:
        - pred, true: ``(B, 3, H, W)`` unit normals; observable: ``(B, 1, H, W)`` bool
        - output: scalars
    """
    flat = torch.zeros_like(true)
    flat[:, 2] = 1.0
    angle = angular_distance(pred, true, dim=1) * 180.0
    flat_angle = angular_distance(flat, true, dim=1) * 180.0
    weight = observable[:, 0].to(angle.dtype)
    return {
        "angle": angle.sum(),
        "flat_angle": flat_angle.sum(),
        "observable_angle": (angle * weight).sum(),
        "observable_flat_angle": (flat_angle * weight).sum(),
        "texels": torch.tensor(float(true[:, 0].numel())),
    }


def summarize(sums: Mapping[str, float]) -> dict[str, float]:
    """Mean angles (all texels; the observable ones, ``Σ θ·mask / N`` as :func:`~brdfgan.data
    .relief.observable_angle`) and their ratios to the flat map's."""
    angle = sums["angle"] / sums["texels"]
    flat = sums["flat_angle"] / sums["texels"]
    observable = sums["observable_angle"] / sums["texels"]
    observable_flat = sums["observable_flat_angle"] / sums["texels"]
    return {
        "angle_deg": angle,
        "flat_angle_deg": flat,
        "angle_vs_flat": angle / flat - 1.0,
        "observable_angle_deg": observable,
        "observable_flat_angle_deg": observable_flat,
        "observable_vs_flat": observable / max(observable_flat, 1e-12) - 1.0,
    }


def evaluate(generator: nn.Module, batches: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    generator.eval()
    sums: dict[str, float] = {}
    slopes = SlopeAgreement()
    with torch.no_grad():
        for batch in batches:
            pred = generator(batch["photo"], batch["flash"])
            # What the photo shows of the relief: its flash shading above the 8-bit rounding.
            shading = flash_relief_shading(batch["maps"], batch["flash"])
            observable = observable_mask(shading, srgb8_rounding_log(batch["photo"]))
            for name, value in normal_scores(pred[:, NORMAL], batch["maps"][:, NORMAL], observable).items():
                sums[name] = sums.get(name, 0.0) + float(value)
            slopes.update(pred, batch["maps"])
    generator.train()
    return {**summarize(sums), "slope_cosine": float(slopes.compute()["normal_slope_cosine"])}


def training_batches(module: RenderedDataModule) -> Iterator[dict[str, Any]]:
    while True:
        for scenes in module.train_dataloader():
            yield module.on_after_batch_transfer(scenes, 0)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "overrides", nargs="*", help="Hydra overrides of conf/train.yaml (data.relief.…, data.sensor.…)"
    )
    parser.add_argument("--out", type=Path, required=True, help="writes OUT.json")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--eval-every", type=int, default=250)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    register_configs()
    with hydra.initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = hydra.compose(
            config_name="train",
            overrides=["experiment=anchored", "data=rendered", "data.compile_renderer=true",
                       "+data.test_split=null", f"seed={args.seed}", *args.overrides],
        )  # fmt: skip
    torch.manual_seed(args.seed)
    module = hydra.utils.instantiate(cfg.data, _convert_="all")
    module.prepare_data()
    module.setup("fit")
    validation = list(module.val_dataloader())
    generator = hydra.utils.instantiate(cfg.model.generator, _convert_="all")
    optimizer = torch.optim.Adam(
        generator.parameters(), lr=cfg.model.optimizer.lr, betas=tuple(cfg.model.optimizer.betas)
    )
    curve: list[dict[str, float]] = [{"step": 0, **evaluate(generator, validation)}]
    start = time.perf_counter()
    for step, batch in enumerate(training_batches(module), start=1):
        pred = generator(batch["photo"], batch["flash"])
        loss = angular_distance(pred[:, NORMAL], batch["maps"][:, NORMAL], dim=1).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        if step % args.eval_every == 0 or step == args.steps:
            curve.append(
                {"step": step, "seconds": time.perf_counter() - start, **evaluate(generator, validation)}
            )
            print(json.dumps(curve[-1]), flush=True)
        if step == args.steps:
            break
    module.teardown("fit")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result = {"overrides": list(args.overrides), "steps": args.steps, "seed": args.seed, "curve": curve,
              "final": curve[-1]}  # fmt: skip
    write_text_atomic(args.out.with_suffix(".json"), json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
