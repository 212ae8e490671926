"""Shape from shading with the rest of the surface known: what a least-squares reading of these
photos' shading gives the normals (issue 46, item 1b).

For every photo of a set (an ``evaluate.py`` data config), the height whose flash relief shading
best matches an observation is fitted with the photo's **true** base colour, roughness and
metallic (:func:`research.relief.fit_height_to_shading`), and its normals are scored as
the evaluator scores a model's: angle and observable angle over the flat map's, slope cosine and
ratio (pooled over texels); the cosine of the slope along the direction away from the hotspot
(:func:`~research.relief.radial_slope`, the one component a flash at the lens shades to
first order) with the truth's share of it; the fit's misfit (the share of the observation's
energy its shading leaves unexplained: not converged, or more than a height can shade); and the
correlation of the observation with the true relief shading over the valid pixels. Two
observations:

- ``shading``: the true maps' own relief shading (:func:`brdfgan.metrics.relief_shading`): no
  noise, no room light, the fit's own renderer;
- ``photo``: the photo over a flat render of its true maps, known up to a constant
  (:func:`~research.relief.photo_relief_residual`): its room light, phone processing,
  noise and JPEG, and the renderers' differences, besides.

The fit is given what a model must find (base colour, roughness, metallic) and has no learned
prior of relief. Writes ``OUT.json``; prints one line per observation and ridge. The tables of
research/notes/2026-12-relief-investigation.md ("(g)"):

    python -m research.relief_oracle --out logs/v5/oracle/val_procedural_shading \\
        data=procedural_and_scans data.data_dir=data/procedural_and_scans_val_procedural \\
        data.prepare=null --observations shading --ridge 0
    python -m research.relief_oracle --out logs/v5/oracle/ood_photo data=ood \\
        --observations photo --ridge 1 10 --steps 200

``--steps 0`` scores the flat start: only the observation's correlation with the true shading
counts. ``research/default_model_v5.sh relief_light`` measures that way what hides the shading
("(h)" there: the same photos re-generated without room light, read with and without the
evaluation sensor).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import hydra
import torch
from torch import Tensor

from brdfgan.core.height import slope_field
from brdfgan.core.svbrdf import NORMAL
from brdfgan.evaluation.config import register_configs
from brdfgan.io.atomic import write_text_atomic
from brdfgan.metrics import SlopeAgreement, relief_shading
from research.relief import (
    fit_height_to_shading,
    observable_mask,
    photo_relief_residual,
    radial_slope,
    srgb8_rounding_log,
)
from research.relief_learnability import normal_scores, summarize

CONF = Path(__file__).resolve().parents[1] / "conf"
OBSERVATIONS = ("shading", "photo")


def radial_sums(pred: Tensor, true: Tensor, frame: Tensor) -> Tensor:
    """``(Σ p_r t_r, Σ p_r², Σ t_r², Σ |t|²)`` over a batch: the radial slopes' (:func:`radial_slope`)
    pooled products and the truth's whole slope energy, float64.

    Shape:
        - pred, true: ``(B, 3, H, W)`` unit normals; frame: ``(B, 3)``
        - output: ``(4,)``
    """
    p, t = radial_slope(pred, frame).double(), radial_slope(true, frame).double()
    return torch.stack(
        [(p * t).sum(), p.square().sum(), t.square().sum(), slope_field(true).double().square().sum()]
    )


def radial_scores(sums: Tensor) -> dict[str, float]:
    """The radial slopes' cosine (prediction against truth) and the truth's radial share of its
    slope energy, from :func:`radial_sums`."""
    dot, pred_sq, true_sq, total = (float(v) for v in sums)
    return {
        "radial_cosine": dot / max((pred_sq * true_sq) ** 0.5, 1e-300),
        "radial_share": true_sq / max(total, 1e-300),
    }


def fit_scores(sums: Tensor, pixels: int, *, centred: bool) -> dict[str, float]:
    """From the valid pixels' ``(Σ misfit², Σ o, Σ o², Σ t, Σ t², Σ o t)`` (``o`` the observation,
    ``t`` the true relief shading): the misfit's share of the observation's energy about its mean
    when ``centred`` (the fit then had a free offset) or else about 0, and the correlation of the
    observation with the true shading (about their means), NaN without variance."""
    misfit, o, oo, t, tt, ot = (float(v) for v in sums)
    n = max(pixels, 1)
    o_energy = oo - o * o / n if centred else oo
    o_var, t_var, cov = oo - o * o / n, tt - t * t / n, ot - o * t / n
    return {
        "misfit_share": misfit / o_energy if o_energy > 0 else float("nan"),
        "shading_correlation": cov / (o_var * t_var) ** 0.5 if o_var > 0 and t_var > 0 else float("nan"),
    }


def observation(name: str, batch: dict[str, Any], shading: Tensor) -> tuple[Tensor, Tensor]:
    """What the fit matches, and where: the true shading (``shading``, the maps' own relief
    shading) everywhere, or the photo's residual over its unclipped pixels."""
    if name == "shading":
        return shading, torch.ones_like(shading, dtype=torch.bool)
    return photo_relief_residual(batch["photo"], batch["maps"], batch["flash"])


def oracle_scores(
    name: str, ridge: float, steps: int, batches: Sequence[dict[str, Tensor]]
) -> dict[str, float]:
    """One row: every photo's fit to observation ``name`` at ``ridge``, scored (module docstring)."""
    sums: dict[str, float] = {}
    slopes, radial = SlopeAgreement(), torch.zeros(4, dtype=torch.float64)
    fit, pixels = torch.zeros(6, dtype=torch.float64), 0
    for batch in batches:
        shading = relief_shading(batch["maps"], batch["flash"])  # the truth's, made once
        observed, valid = observation(name, batch, shading)
        fitted = batch["maps"].clone()
        # The photo's residual is known up to a constant (its mean was fitted away).
        fitted[:, NORMAL] = fit_height_to_shading(
            batch["maps"],
            batch["flash"],
            observed,
            valid,
            ridge=ridge,
            steps=steps,
            free_offset=name == "photo",
        )
        # How far the fit is from reproducing what it matched (its convergence, or more than a
        # height can shade).
        difference = relief_shading(fitted, batch["flash"]) - observed
        if name == "photo":  # fitted with a free offset
            mean = (difference * valid).sum(dim=(-2, -1), keepdim=True)
            difference = difference - mean / valid.sum(dim=(-2, -1), keepdim=True).clamp_min(1)
        terms = [
            difference.square(),
            observed,
            observed.square(),
            shading,
            shading.square(),
            observed * shading,
        ]
        fit += torch.stack([(term.double() * valid).sum() for term in terms])
        pixels += int(valid.sum())
        # The evaluator's observable texels: the true shading above the photo's 8-bit rounding.
        observable = observable_mask(shading, srgb8_rounding_log(batch["photo"]))
        for key, value in normal_scores(fitted[:, NORMAL], batch["maps"][:, NORMAL], observable).items():
            sums[key] = sums.get(key, 0.0) + float(value)
        slopes.update(fitted, batch["maps"])
        radial += radial_sums(fitted[:, NORMAL], batch["maps"][:, NORMAL], batch["flash"])
    agreement = {key: float(value) for key, value in slopes.compute().items()}
    return {
        **summarize(sums),
        **agreement,
        **radial_scores(radial),
        **fit_scores(fit, pixels, centred=name == "photo"),
    }


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "overrides", nargs="*", help="Hydra overrides of conf/evaluate.yaml (data=…, split=…)"
    )
    parser.add_argument("--out", type=Path, required=True, help="writes OUT.json")
    parser.add_argument("--ridge", type=float, nargs="+", default=[0.0])
    parser.add_argument("--observations", nargs="+", choices=OBSERVATIONS, default=list(OBSERVATIONS))
    parser.add_argument(
        "--steps", type=int, default=400,
        help="L-BFGS iterations at most; 0: no fit (the flat start), for the observation's correlation alone",
    )  # fmt: skip
    parser.add_argument("--limit", type=int, default=None, help="the first N photos only")
    args = parser.parse_args(argv)
    if args.limit is not None and args.limit < 1:
        parser.error(f"--limit must be at least 1, got {args.limit}")
    if args.steps < 0 or any(ridge < 0 for ridge in args.ridge):
        parser.error("--steps and every --ridge must be at least 0")

    register_configs()
    with hydra.initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = hydra.compose(config_name="evaluate", overrides=list(args.overrides))
    datamodule = hydra.utils.instantiate(cfg.data, _convert_="all")
    datamodule.prepare_data()
    datamodule.splits["test"] = cfg.split
    datamodule.setup("test")
    batches, photos = [], 0
    for batch in datamodule.test_dataloader():
        if args.limit is not None and photos >= args.limit:
            break
        keep = None if args.limit is None else args.limit - photos
        batches.append({key: batch[key][:keep] for key in ("photo", "maps", "flash")})
        photos += len(batches[-1]["maps"])
    results: dict[str, dict[str, float]] = {}
    for name in args.observations:
        for ridge in args.ridge:
            start = time.perf_counter()
            row = {**oracle_scores(name, ridge, args.steps, batches), "photos": photos,
                   "seconds": time.perf_counter() - start}  # fmt: skip
            results[f"{name}/ridge={ridge:g}"] = row
            print(json.dumps({"observation": name, "ridge": ridge, **row}), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    payload = {"overrides": list(args.overrides), "steps": args.steps, "results": results}
    write_text_atomic(args.out.with_suffix(".json"), json.dumps(payload, indent=1))


if __name__ == "__main__":
    main()
