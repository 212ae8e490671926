"""The pair fit's guard on Mitsuba pairs (issue 59): how much the fitted relief must lower the
held-out pixels' residual (``PairFitConfig.min_improvement``) before it replaces the network's
normals, chosen on the validation split and then read on the test split.

Each pair of a generated dataset with twins (``dataset_spec.pairs``) is fitted once with the
guard off; its held-out improvement ``1 − residual_fit / residual_flat`` and the mean normal angle
of the fit, of the network on the flash-only image and of a flat map are kept, so that every
threshold is scored on the same fits.

    python -m research.pair_guard --shards data/pas_pairs --out outputs/pair_fit/guard.md
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from dataclasses import replace
from pathlib import Path

import torch

from brdfgan.core.svbrdf import NORMAL
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.pair.relief_fit import PairFitConfig, fit_pair
from brdfgan.io.atomic import write_text_atomic
from brdfgan.losses.parameter import angular_distance
from research.pair_fit_table import shard_pairs

THRESHOLDS = (0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.5)


def mean_angle(normal: torch.Tensor, truth: torch.Tensor) -> float:
    return float(angular_distance(normal, truth, dim=0).mean()) * 180.0


def measure(root: Path, split: str, scanned: bool, limit: int) -> list[dict[str, float]]:
    v4 = load_model(None).generator.eval()
    always = replace(PairFitConfig(), min_improvement=-1e9)  # the fit's relief whatever it does
    rows = []
    for pair in itertools.islice(shard_pairs(root, scanned, split), limit or None):
        with torch.no_grad():
            network = v4(pair.flash_only[None], pair.frame)[0]
        fitted = fit_pair(pair.flash_only, pair.room, pair.valid, network, pair.frame, always)
        flat = torch.zeros_like(pair.truth[NORMAL])
        flat[2] = 1.0
        rows.append({
            "improvement": 1.0 - fitted.residual_fit / max(fitted.residual_flat, 1e-12),
            "flat": mean_angle(flat, pair.truth[NORMAL]),
            "network": mean_angle(network[NORMAL], pair.truth[NORMAL]),
            "fit": mean_angle(fitted.maps[NORMAL], pair.truth[NORMAL]),
        })  # fmt: skip
    return rows


def table(rows: list[dict[str, float]]) -> str:
    flat = sum(r["flat"] for r in rows)
    lines = ["| min_improvement | fits kept | angle / flat |", "|---|---|---|"]
    network = sum(r["network"] for r in rows) / flat
    lines.append(f"| (network only) | 0 / {len(rows)} | {network:.3f} |")
    for threshold in THRESHOLDS:
        kept = [r["improvement"] > threshold for r in rows]
        angle = sum(r["fit"] if k else r["network"] for r, k in zip(rows, kept, strict=True)) / flat
        lines.append(f"| {threshold} | {sum(kept)} / {len(rows)} | {angle:.3f} |")
    return "\n".join(lines) + f"\n\nflat map's angle {flat / len(rows):.2f}°\n"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--shards", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--limit", type=int, default=32, help="pairs per set (0: all)")
    args = parser.parse_args()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    started = time.time()
    report = [f"# The pair fit's guard: {args.shards}\n"]
    for split, scanned in (("val", True), ("val", False), ("test", True), ("test", False)):
        rows = measure(args.shards, split, scanned, args.limit)
        name = f"{split} {'scans' if scanned else 'procedural'}"
        report += [f"**{name}** ({len(rows)} pairs, {time.time() - started:.0f} s)\n", table(rows)]
        write_text_atomic(args.out, "\n".join(report))
        write_text_atomic(args.out.with_suffix(f".{split}_{'scans' if scanned else 'procedural'}.json"),
                          json.dumps(rows))  # fmt: skip
        print("\n".join(report[-2:]), flush=True)


if __name__ == "__main__":
    main()
