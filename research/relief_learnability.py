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

``--input`` picks what the network sees of a flash + no-flash pair (issue 59; needs
``data.pairs.enabled=true`` and validation shards with twins, ``dataset_spec.pairs=true``):
``flash`` the flash photo (today), ``flash_only`` the flash photo less the room light
(:func:`~brdfgan.data.phone.pairs.flash_only_photos`, auto-exposed), ``pair`` the flash photo with
the no-flash photo's log as three more channels, ``ratio`` the flash photo with the log ratio of
the room light's share to the flash photo as three more channels. The extra channels join the
encoder's input (:class:`PairInputUNet`). ``--ood DIR`` also scores a generated dataset's test
pairs (the OOD benchmark's, ``data/ood``); the validation rows are split into procedural
materials and scans. ``--init WEIGHTS`` starts from a weights file (the shipped v4) instead of at
random: a pair model fine-tuned from v4 (issue 59, item 5), the extra channels' weights at zero.

    python -m research.relief_learnability --out outputs/learnability/base
    python -m research.relief_learnability --out outputs/learnability/bumps \\
        data.relief.bump_probability=0.5
    python -m research.relief_learnability --input ratio --ood data/ood --out outputs/learnability/ratio \\
        data.pairs.enabled=true data.data_dir=data/pas_pairs data.prepare.spec.pairs=true
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar, cast

import hydra
import torch
from omegaconf import OmegaConf
from torch import Tensor, nn

from brdfgan.core.exposure import auto_expose
from brdfgan.core.svbrdf import NORMAL
from brdfgan.data.loading.datamodule import collate_samples
from brdfgan.data.loading.rendered import RenderedDataModule
from brdfgan.data.phone.conditions import sample_as_photographed
from brdfgan.data.phone.pairs import flash_only_photos
from brdfgan.data.storage.shards import Sample, iter_shard, list_shards
from brdfgan.inference.model.weights import load_model
from brdfgan.io.atomic import write_text_atomic
from brdfgan.losses.parameter import angular_distance
from brdfgan.metrics import SlopeAgreement
from brdfgan.metrics import relief_shading as flash_relief_shading
from brdfgan.models.anchored import AnchoredUNet
from brdfgan.runs import stored_constructor_arguments
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


INPUTS = ("flash", "flash_only", "pair", "ratio")
NetworkT = TypeVar("NetworkT", bound=nn.Module)
LOG_FLOOR = 1e-3  # log of a linear value below ~one 8-bit step of a photo exposed for white
OOD_BATCH = 8


class PairInputUNet(AnchoredUNet):
    """v4's generator with ``extra_channels`` more input channels beside its own (log photo, log
    anchor, flash geometry): the first convolution is widened, and :meth:`predict` passes them."""

    def __init__(self, extra_channels: int, **config: Any) -> None:
        super().__init__(**config)
        block = cast(nn.Sequential, self.encoder[0])
        first = cast(nn.Conv2d, block[0])
        block[0] = nn.Conv2d(first.in_channels + extra_channels, first.out_channels, 3, padding=1,
                             padding_mode="reflect", bias=False)  # fmt: skip
        self._extra: Tensor | None = None

    def _encode(self, x: Tensor) -> tuple[list[Tensor], list[Tensor]]:
        assert self._extra is not None, "PairInputUNet is called through predict(photo, flash, extra)"
        return super()._encode(torch.cat([x, self._extra.to(x)], dim=1))

    def predict(self, photo: Tensor, flash: Tensor, extra: Tensor) -> Tensor:
        self._extra = extra
        try:
            return self(photo, flash)
        finally:
            self._extra = None


def warm_started(generator: NetworkT, state: Mapping[str, Tensor]) -> NetworkT:
    """``generator`` with a shipped generator's weights (``state``); a :class:`PairInputUNet`'s
    extra input channels start at zero weight, so it starts as the shipped network exactly."""
    first = "encoder.0.0.weight"
    own = generator.state_dict()[first]
    widened = dict(state)
    if own.shape[1] > state[first].shape[1]:
        extra = own.new_zeros(own.shape[0], own.shape[1] - state[first].shape[1], *own.shape[2:])
        widened[first] = torch.cat([state[first], extra], dim=1)
    generator.load_state_dict(widened)
    return generator


def network_inputs(batch: Mapping[str, Any], kind: str) -> tuple[Tensor, Tensor | None]:
    """What the network sees of a batch (``--input``, module docstring): the photo and the extra
    channels (``None`` for ``flash`` and ``flash_only``).

    Shape:
        - output: ``(B, 3, H, W)``, ``(B, 3, H, W)`` or None
    """
    photo = batch["photo"]
    if kind == "flash":
        return photo, None
    pair = flash_only_photos(photo, batch["photo_noflash"], batch["exposure_ratio"], batch["white_balance"])
    if kind == "flash_only":
        return auto_expose(pair.flash_only)[0], None
    if kind == "pair":
        return photo, batch["photo_noflash"].clamp_min(LOG_FLOOR).log()
    flash_gain = batch["white_balance"][:, 0, :, None, None].to(photo)
    return photo, pair.room.clamp_min(LOG_FLOOR).log() - (photo / flash_gain).clamp_min(LOG_FLOOR).log()


def predict(generator: nn.Module, batch: Mapping[str, Any], kind: str) -> Tensor:
    photo, extra = network_inputs(batch, kind)
    if extra is None:
        return cast(Tensor, generator(photo, batch["flash"]))
    return cast(PairInputUNet, generator).predict(photo, batch["flash"], extra)


def is_scan(meta: Mapping[str, Any]) -> bool:
    return str(meta.get("family", "")).startswith("scanned/")


def evaluate(
    generator: nn.Module, sets: Mapping[str, Sequence[Mapping[str, Any]]], kind: str
) -> dict[str, dict[str, float]]:
    """The scores of every held-out set; a set named ``val`` is split into its procedural
    materials and its scans."""
    generator.eval()
    sums: dict[str, dict[str, float]] = {}
    slopes: dict[str, SlopeAgreement] = {}
    with torch.no_grad():
        for set_name, batches in sets.items():
            for batch in batches:
                pred = predict(generator, batch, kind)
                # What the photo shows of the relief: its flash shading above the 8-bit rounding.
                shading = flash_relief_shading(batch["maps"], batch["flash"])
                observable = observable_mask(shading, srgb8_rounding_log(batch["photo"]))
                groups: dict[str, list[int]] = {}
                for index, meta in enumerate(batch["meta"]):
                    name = (
                        set_name
                        if set_name != "val"
                        else ("val scans" if is_scan(meta) else "val procedural")
                    )
                    groups.setdefault(name, []).append(index)
                for name, rows in groups.items():
                    chosen = torch.tensor(rows)
                    maps, truth = pred[chosen], batch["maps"][chosen]
                    scores = normal_scores(maps[:, NORMAL], truth[:, NORMAL], observable[chosen])
                    group = sums.setdefault(name, {})
                    for key, value in scores.items():
                        group[key] = group.get(key, 0.0) + float(value)
                    slopes.setdefault(name, SlopeAgreement()).update(maps, truth)
    generator.train()
    return {
        name: {**summarize(group), "slope_cosine": float(slopes[name].compute()["normal_slope_cosine"])}
        for name, group in sorted(sums.items())
    }


def shard_batches(root: Path, split: str = "test") -> list[dict[str, Any]]:
    """A generated dataset's samples as the evaluator's loader batches them (maps aligned)."""
    samples = []
    for shard in list_shards(root, split):
        for stored in iter_shard(shard):
            photographed = sample_as_photographed(stored)
            samples.append(Sample(stored.key, photographed.photo, photographed.maps, photographed.meta,
                                  check=False, no_flash=stored.no_flash))  # fmt: skip
    return [collate_samples(samples[i : i + OOD_BATCH]) for i in range(0, len(samples), OOD_BATCH)]


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
    parser.add_argument("--input", choices=INPUTS, default="flash", help="what the network sees of a pair")
    parser.add_argument(
        "--init",
        type=Path,
        default=None,
        help="start from a weights file (.safetensors, e.g. the shipped v4) instead of at random",
    )
    parser.add_argument(
        "--ood", type=Path, default=None, help="a generated dataset whose test split is scored too"
    )
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
    sets = {"val": list(module.val_dataloader())}
    if args.ood is not None:
        sets["ood"] = shard_batches(args.ood)
    # A warm start takes the weights file's own architecture (its config), not the experiment's.
    shipped = load_model(args.init) if args.init is not None else None
    if shipped is not None:
        config = stored_constructor_arguments(AnchoredUNet, shipped.config, args.init, "AnchoredUNet")
    else:
        node = cast(dict[str, Any], OmegaConf.to_container(cfg.model.generator, resolve=True))
        config = {k: v for k, v in node.items() if k != "_target_"}
    pair_input = args.input in ("pair", "ratio")
    generator: nn.Module = PairInputUNet(3, **config) if pair_input else AnchoredUNet(**config)
    if shipped is not None:
        generator = warm_started(generator, shipped.generator.state_dict())
    optimizer = torch.optim.Adam(
        generator.parameters(), lr=cfg.model.optimizer.lr, betas=tuple(cfg.model.optimizer.betas)
    )
    curve: list[dict[str, Any]] = [{"step": 0, **evaluate(generator, sets, args.input)}]
    start = time.perf_counter()
    for step, batch in enumerate(training_batches(module), start=1):
        pred = predict(generator, batch, args.input)
        loss = angular_distance(pred[:, NORMAL], batch["maps"][:, NORMAL], dim=1).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        if step % args.eval_every == 0 or step == args.steps:
            curve.append(
                {
                    "step": step,
                    "seconds": time.perf_counter() - start,
                    **evaluate(generator, sets, args.input),
                }
            )
            print(json.dumps(curve[-1]), flush=True)
        if step == args.steps:
            break
    module.teardown("fit")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result = {"overrides": list(args.overrides), "input": args.input, "steps": args.steps, "seed": args.seed,
              "init": None if args.init is None else str(args.init),
              "curve": curve, "final": curve[-1]}  # fmt: skip
    write_text_atomic(args.out.with_suffix(".json"), json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
