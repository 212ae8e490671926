"""Validation learning curves of training runs, side by side: one metric against the optimizer
step, read from each run's CSV log (``RUN/csv/version_*/metrics.csv``; a resumed run's versions
joined). Writes a markdown table (steps as rows, runs as columns) and a PNG plot.

    python -m scripts.learning_curve shading=logs/default_model_v4/seed0 \\
        none=logs/default_model_v4/no_shading --metric val/normal_angle_deg \\
        --out docs/default_model_normal_curve
    # -> docs/default_model_normal_curve.md, docs/default_model_normal_curve.png
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; no display on a server or in CI
import matplotlib.pyplot as plt  # after choosing the backend

from brdfgan.io.atomic import atomic_replace, write_text_atomic


def validation_curve(run_dir: Path, metric: str) -> dict[int, float]:
    """``{step: value}`` of ``metric`` over every CSV version of ``run_dir`` (later versions win a
    step logged twice, as a resume repeats the validation it stopped in)."""
    versions = sorted((run_dir / "csv").glob("version_*/metrics.csv"), key=lambda p: int(p.parent.name[8:]))
    if not versions:
        raise FileNotFoundError(f"{run_dir}: no csv/version_*/metrics.csv (not a train.py run folder?)")
    curve: dict[int, float] = {}
    for path in versions:
        with path.open(newline="") as handle:
            for row in csv.DictReader(handle):
                if row.get(metric):
                    curve[int(row["step"])] = float(row[metric])
    if not curve:
        raise KeyError(f"{run_dir}: metric {metric!r} was never logged")
    return curve


def markdown_table(curves: dict[str, dict[int, float]], metric: str) -> str:
    """Steps as rows (the union of every run's), runs as columns; ``–`` where a run has no value."""
    steps = sorted({step for curve in curves.values() for step in curve})
    lines = [f"| step | {' | '.join(curves)} |", "|---" * (len(curves) + 1) + "|"]
    for step in steps:
        cells = [f"{curve[step]:.4g}" if step in curve else "–" for curve in curves.values()]
        lines.append(f"| {step} | {' | '.join(cells)} |")
    return f"{metric} against the optimizer step\n\n" + "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", metavar="NAME=RUN_DIR")
    parser.add_argument("--metric", default="val/normal_angle_deg")
    parser.add_argument("--out", type=Path, required=True, help="output path without suffix (.md and .png)")
    args = parser.parse_args(argv)
    curves: dict[str, dict[int, float]] = {}
    try:
        for spec in args.runs:
            name, sep, folder = spec.partition("=")
            if not sep or not name or not folder:
                raise ValueError(f"{spec!r}: expected NAME=RUN_DIR")
            curves[name] = validation_curve(Path(folder), args.metric)
    except (FileNotFoundError, KeyError, ValueError) as error:
        print(f"learning_curve: {error}", file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    table = write_text_atomic(args.out.with_suffix(".md"), markdown_table(curves, args.metric))
    figure, axes = plt.subplots(figsize=(6, 4), dpi=100)
    for name, curve in curves.items():
        steps = sorted(curve)
        axes.plot(steps, [curve[step] for step in steps], marker="o", label=name)
    axes.set_xlabel("optimizer step")
    axes.set_ylabel(args.metric)
    axes.grid(alpha=0.3)
    axes.legend()
    figure.tight_layout()
    with atomic_replace(args.out.with_suffix(".png"), keep_suffix=True) as image:
        figure.savefig(image)  # the format from the temporary name's .png suffix
    plt.close(figure)
    print(table.read_text(), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
