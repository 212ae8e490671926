"""What the pair's ratio can show of a relief at all (issue 59): the held-out residual of the *true*
normals against a flat surface's, each scored as the fit's guard scores a relief (the room light
and the material terms refitted for it on the fitted pixels, the residual read on the held-out
ones; :func:`~brdfgan.inference.pair.relief_fit.fit_pair`), with one difference: the guard refits
from each relief's own fitted light for ``GUARD_STEPS``, here every relief starts from the flat
surface's median light and gets twice the steps, since no fit precedes it. Where the truth itself
does not lower the flat surface's residual by the guard's ``min_improvement``, no fit of this model
could pass the guard with the right relief: the ratio's evidence, not the fit, is the limit there.

    python -m research.pair_guard_ceiling --shards data/pas_pairs --out outputs/pair_fit/ceiling.md
"""

from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path

import torch

from brdfgan.core.svbrdf import NORMAL
from brdfgan.inference.model.weights import load_model
from brdfgan.inference.pair.relief_fit import (
    GUARD_STEPS,
    PairFitConfig,
    _initial_light,
    _Level,
    _working_normals,
    held_out_residuals,
    material_confounds,
    pair_log_ratio,
    usable_ratio_mask,
)
from brdfgan.io.atomic import write_text_atomic
from research.pair_fit_table import Pair, shard_pairs
from research.pair_guard import fit_config


# The fit's own pieces (its private _Level among them) are used: the truth must be scored on the
# same masks, held-out pixels and model, by the same function, as the guard scores a relief.
def residuals(pair: Pair, network: torch.Tensor, config: PairFitConfig) -> dict[str, float] | None:
    """Held-out residuals of flat, the truth and the network's normals (None: nothing usable)."""
    usable = usable_ratio_mask(pair.flash_only, pair.room, pair.valid, network, pair.frame, config)
    log_ratio = pair_log_ratio(pair.flash_only, pair.room)
    size = min(config.levels[-1], pair.flash_only.shape[-1])
    confounds = material_confounds(network, usable) if config.guard_with_maps else None
    fitted, held_out = _Level.of(log_ratio, usable, pair.frame, size, confounds).split()
    if held_out.weight.sum() == 0:
        return None
    start = _initial_light(fitted, torch.zeros(1, 1, size, size))
    flat = torch.zeros(1, 3, size, size)
    flat[:, 2] = 1.0
    reliefs = {
        "flat": (flat, start),
        "truth": (_working_normals(pair.truth[NORMAL], size), start),
        "network": (_working_normals(network[NORMAL], size), start),
    }
    return held_out_residuals(fitted, held_out, reliefs, 2 * GUARD_STEPS, config)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--shards", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--limit", type=int, default=24)
    parser.add_argument(
        "--sets", nargs="+", default=["val:scans", "val:procedural", "test:scans", "test:procedural"]
    )
    parser.add_argument("--fit", nargs="*", default=[], help="PairFitConfig fields, KEY=VALUE")
    args = parser.parse_args()
    config = fit_config(args.fit)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    v4 = load_model(None).generator.eval()
    report = [
        f"# The guard's ceiling: {args.shards}, {' '.join(args.fit) or 'defaults'}\n",
        "| set | pairs | scored | truth / flat residual: median | truth passes the guard | network / flat |",
        "|---|---|---|---|---|---|",
    ]
    all_rows: dict[str, list[dict[str, float] | None]] = {}
    for chosen_set in args.sets:
        split, kind = chosen_set.split(":")
        rows = []
        for pair in itertools.islice(shard_pairs(args.shards, kind == "scans", split), args.limit or None):
            with torch.no_grad():
                network = v4(pair.flash_only[None], pair.frame)[0]
            rows.append(residuals(pair, network, config))
        scored = [r for r in rows if r is not None]
        ratios = torch.tensor([r["truth"] / r["flat"] for r in scored])
        network_ratios = torch.tensor([r["network"] / r["flat"] for r in scored])
        passes = int((ratios < 1 - config.min_improvement).sum())
        report.append(f"| {split} {kind} | {len(rows)} | {len(scored)} | {ratios.median():.3f} | {passes} |"
                      f" {network_ratios.median():.3f} |")  # fmt: skip
        all_rows[chosen_set] = rows
        print(report[-1], flush=True)
        write_text_atomic(args.out, "\n".join(report) + "\n")
        write_text_atomic(args.out.with_suffix(".json"), json.dumps(all_rows))


if __name__ == "__main__":
    main()
