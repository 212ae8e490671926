"""The multi-view fit's settings compared on validation materials (docs/views.md, "Choosing the
fit's settings"): synthetic handheld captures of the first 4 procedural and 2 scan samples of the
validation split, the shipped model's prediction of view 0 fitted to K = 2, 3, 5 views with each
variant, scored on views 5–8 (one gain fitted on view 0) and against the truth.

    python -m research.views_settings --out logs/views_settings [variant …]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

from brdfgan.evaluation.real_captures import (
    capture_models,
    fit_capture_maps,
    predict_capture_maps,
    read_capture,
    read_views,
)
from brdfgan.inference.views.config import ViewFitConfig
from research.synthetic_captures import (
    HandheldSettings,
    locked_phone,
    render_synthetic_capture,
    write_synthetic_capture,
)
from research.views_table import held_out_errors, map_errors, materials

MATERIALS = (
    ("vproc", "data/procedural_and_scans_val_procedural", 4),
    ("vscan", "data/procedural_and_scans_val_scans", 2),
)
BASE = ViewFitConfig()
VARIANTS = {
    "tv0.05": replace(BASE, tv_weight=0.05),
    "tv0.25": replace(BASE, tv_weight=0.25),
    "tv1.25": replace(BASE, tv_weight=1.25),
    "tv0.25_prior÷5": replace(
        BASE,
        tv_weight=0.25,
        prior_basecolor=0.004,
        prior_slopes=0.004,
        prior_roughness=0.004,
        prior_metallic=0.02,
    ),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("variants", nargs="*", default=list(VARIANTS), choices=list(VARIANTS))
    args = parser.parse_args()
    phone = locked_phone("conf/sensor/phone_eval.yaml")
    captures = []
    for seed, (name, maps) in enumerate(materials(MATERIALS)):
        target = args.out / "captures" / name
        if not (target / "parameters.json").is_file():
            write_synthetic_capture(
                render_synthetic_capture(maps, HandheldSettings(), phone, seed=100 + seed), maps, target
            )
        captures.append((read_capture(target), maps.float()))
    model = capture_models()[0]
    results: dict[str, list[list[float]]] = {}
    for capture, truth in captures:
        photos = read_views(capture)
        prediction = predict_capture_maps(capture, photos[0], model)

        results.setdefault("prediction", []).append(
            [held_out_errors(capture, photos, prediction, model.name)[0]]
        )
        for variant in args.variants:
            for views in (2, 3, 5):
                start = time.perf_counter()
                maps = fit_capture_maps(capture, photos, prediction, views, VARIANTS[variant])
                errors = map_errors(maps, truth)
                results.setdefault(f"{variant} K={views}", []).append(
                    [
                        held_out_errors(capture, photos, maps, model.name)[0],
                        errors["normal_angle_deg"],
                        errors["rmse/basecolor"],
                        errors["rmse/roughness"],
                        time.perf_counter() - start,
                    ]
                )
        print(capture.name, {key: round(rows[-1][0], 4) for key, rows in results.items()}, flush=True)
    lines = [
        "| variant | held-out | normal ° | base colour | roughness | fit s |",
        "|---|---|---|---|---|---|",
    ]
    for key, rows in results.items():
        means = [sum(row[i] for row in rows) / len(rows) for i in range(len(rows[0]))]
        lines.append(f"| {key} | " + " | ".join(f"{value:.4f}" for value in means) + " |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "views_settings.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (args.out / "views_settings.json").write_text(json.dumps(results, indent=1), encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
