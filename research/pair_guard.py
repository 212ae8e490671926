"""The pair fit's guard on Mitsuba pairs (issue 59): how much the fitted relief must lower the
held-out pixels' residual (``PairFitConfig.min_improvement``) before it replaces the network's
normals, chosen on the validation split and then read on the test split.

Each pair of a generated dataset with twins (``dataset_spec.pairs``) is fitted once; the three
held-out residuals (flat, fit, network) and the mean normal angle of the fit, of the network on the
flash-only image and of a flat map are kept, so that every threshold is scored on the same fits
(:func:`~brdfgan.inference.pair.relief_fit.choose_relief`, as the fit itself chooses).

    python -m research.pair_guard --shards data/pas_pairs --out outputs/pair_fit/guard.md

``--fit KEY=VALUE`` (repeatable) sets a field of :class:`PairFitConfig` for every fit, e.g. the masks
chosen before the guard existed (``--fit min_roughness=0.3``).
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from dataclasses import fields
from pathlib import Path

import torch

from brdfgan.core.svbrdf import NORMAL
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.pair.relief_fit import (
    Kept,
    PairFitConfig,
    Scored,
    choose_relief,
    fit_pair,
    with_relief,
)
from brdfgan.io.atomic import write_text_atomic
from brdfgan.losses.parameter import angular_distance
from research.pair_fit_table import shard_pairs

THRESHOLDS = (0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.5)
# The fitted relief shrunk toward flat: the angle of a relief that is right in part (slope cosine c,
# slope ratio r) is least at the scale c / r, kept in the rows for the study of a fixed shrink.
RELIEF_SCALES = (0.25, 0.5, 0.75)
# How much more of the held-out residual the fitted relief turned over must leave (choose_relief).
SIGN_MARGINS = (0.0, 0.02, 0.05, 0.1, 0.15, 0.2)


def mean_angle(normal: torch.Tensor, truth: torch.Tensor) -> float:
    return float(angular_distance(normal, truth, dim=0).mean()) * 180.0


def fit_config(settings: list[str]) -> PairFitConfig:
    """``KEY=VALUE`` strings → the config with those fields set (each value of its field's type)."""
    types = {f.name: type(getattr(PairFitConfig(), f.name)) for f in fields(PairFitConfig)}
    values: dict[str, object] = {}
    for setting in settings:
        key, _, value = setting.partition("=")
        if key not in types or types[key] not in (int, float, bool, tuple):
            raise SystemExit(f"--fit {setting}: not a number, switch or sizes field of PairFitConfig")
        if types[key] is tuple:  # the levels' sizes and steps: comma-separated integers
            values[key] = tuple(int(v) for v in value.split(","))
        else:
            values[key] = value.lower() in ("1", "true") if types[key] is bool else types[key](value)
    return PairFitConfig(**values)  # type: ignore[arg-type]


def measure(
    root: Path, split: str, scanned: bool, limit: int, config: PairFitConfig
) -> list[dict[str, float]]:
    v4 = load_model(None).generator.eval()
    rows = []
    for pair in itertools.islice(shard_pairs(root, scanned, split), limit or None):
        with torch.no_grad():
            network = v4(pair.flash_only[None], pair.frame)[0]
        fitted = fit_pair(pair.flash_only, pair.room, pair.valid, network, pair.frame, config)
        # The fitted relief whatever the guard chose: every candidate's angle is kept.
        relief = with_relief(network, fitted.height, pair.frame)
        flat = torch.zeros_like(pair.truth[NORMAL])
        flat[2] = 1.0
        rows.append({
            "residual_flat": fitted.residual_flat,
            "residual_fit": fitted.residual_fit,
            "residual_prediction": fitted.residual_prediction,
            "residual_turned": fitted.residual_turned,
            "flat": mean_angle(flat, pair.truth[NORMAL]),
            "prediction": mean_angle(network[NORMAL], pair.truth[NORMAL]),
            "fit": mean_angle(relief[NORMAL], pair.truth[NORMAL]),
            "masked": fitted.masked_fraction,
            **{
                f"fit@{scale}": mean_angle(with_relief(network, scale * fitted.height, pair.frame)[NORMAL],
                                           pair.truth[NORMAL])
                for scale in RELIEF_SCALES
            },
        })  # fmt: skip
    return rows


def chosen(row: dict[str, float], threshold: float, margin: float) -> Kept:
    residuals: dict[Scored, float] = {
        "flat": row["residual_flat"],
        "fit": row["residual_fit"],
        "prediction": row["residual_prediction"],
        "turned": row.get("residual_turned", float("inf")),  # rows measured before the sign check
    }
    return choose_relief(residuals, threshold, margin)


def table(rows: list[dict[str, float]], margin: float) -> str:
    flat = sum(r["flat"] for r in rows)
    lines = ["| min_improvement | fit / network / flat kept | angle / flat |", "|---|---|---|"]
    network = sum(r["prediction"] for r in rows) / flat
    lines.append(f"| (network only) | 0 / {len(rows)} / 0 | {network:.3f} |")
    for threshold in THRESHOLDS:
        lines.append(f"| {threshold} | {_kept_and_angle(rows, threshold, margin)} |")
    unseen = sum(r["residual_flat"] == 0 for r in rows)
    masked = sum(r["masked"] for r in rows) / len(rows)
    lines += [
        "",
        f"At the shipped min_improvement ({PairFitConfig().min_improvement}), by the fit's sign margin:",
        "",
        "| min_sign_margin | fit / network / flat kept | angle / flat |",
        "|---|---|---|",
    ]
    for sign_margin in SIGN_MARGINS:
        lines.append(
            f"| {sign_margin} | {_kept_and_angle(rows, PairFitConfig().min_improvement, sign_margin)} |"
        )
    return "\n".join(lines) + (
        f"\n\nflat map's angle {flat / len(rows):.2f}°; masked {masked:.2f} of the pixels on average,"
        f" nothing held out on {unseen} of {len(rows)} pairs\n"
    )


def _kept_and_angle(rows: list[dict[str, float]], threshold: float, margin: float) -> str:
    """The reliefs kept (fit / network / flat) and their mean angle over a flat map's."""
    kept = [chosen(r, threshold, margin) for r in rows]
    angle = sum(r[k] for r, k in zip(rows, kept, strict=True)) / sum(r["flat"] for r in rows)
    counts = " / ".join(str(kept.count(name)) for name in ("fit", "prediction", "flat"))
    return f"{counts} | {angle:.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--shards", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--limit", type=int, default=32, help="pairs per set (0: all)")
    parser.add_argument(
        "--sets",
        nargs="+",
        default=["val:scans", "val:procedural", "test:scans", "test:procedural"],
        help="split:scans or split:procedural (the OOD benchmark: test:scans)",
    )
    parser.add_argument("--fit", nargs="*", default=[], help="PairFitConfig fields, KEY=VALUE")
    args = parser.parse_args()
    config = fit_config(args.fit)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    started = time.time()
    report = [f"# The pair fit's guard: {args.shards}, {' '.join(args.fit) or 'defaults'}\n"]
    for chosen_set in args.sets:
        split, kind = chosen_set.split(":")
        scanned = kind == "scans"
        rows = measure(args.shards, split, scanned, args.limit, config)
        name = f"{split} {kind}"
        report += [
            f"**{name}** ({len(rows)} pairs, {time.time() - started:.0f} s)\n",
            table(rows, config.min_sign_margin),
        ]
        write_text_atomic(args.out, "\n".join(report))
        write_text_atomic(args.out.with_suffix(f".{split}_{kind}.json"),
                          json.dumps(rows))  # fmt: skip
        print("\n".join(report[-2:]), flush=True)


if __name__ == "__main__":
    main()
