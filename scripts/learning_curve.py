"""Validation learning curves of training runs, side by side: one metric against the optimizer
step, read from each run's CSV log (``RUN/csv/version_*/metrics.csv``; a resumed run's versions
joined). A run trained in stages names its folders joined by ``+``: each later stage's steps
continue after the previous stage's last. Writes a markdown table (steps as rows, runs as columns)
and a PNG plot, with optional horizontal reference lines (``--reference "flat map=7.95"``).

    OUT=logs/default_model_v4
    python -m scripts.learning_curve shading=$OUT/final_seed0+$OUT/fixres_seed0 \\
        none=$OUT/no_shading_seed0+$OUT/no_shading_fixres_seed0 --metric val/normal_angle_deg \\
        --reference "flat map=7.95" --out $OUT/normal_curve
    # -> $OUT/normal_curve.md, $OUT/normal_curve.png
"""

from __future__ import annotations

import argparse
import csv
import itertools
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


def staged_curve(run_dirs: list[Path], metric: str) -> dict[int, float]:
    """``{step: value}`` of a run trained in stages (a warm start of the previous stage's weights,
    whose own step count restarts at 0): each stage's steps shifted past the previous stage's last
    logged step."""
    curve: dict[int, float] = {}
    for run_dir in run_dirs:
        offset = max(curve) + 1 if curve else 0
        curve.update({offset + step: value for step, value in validation_curve(run_dir, metric).items()})
    return curve


def parse_reference(spec: str) -> tuple[str, float]:
    """``"LABEL=VALUE"`` -> ``(LABEL, VALUE)``."""
    label, sep, value = spec.rpartition("=")
    try:
        if not sep or not label:
            raise ValueError
        return label, float(value)
    except ValueError:
        raise ValueError(f"--reference {spec!r}: expected LABEL=VALUE") from None


def markdown_table(
    curves: dict[str, dict[int, float]], metric: str, references: list[tuple[str, float]] | None = None
) -> str:
    """Steps as rows (the union of every run's), runs as columns; ``–`` where a run has no value;
    the reference lines' values below."""
    steps = sorted({step for curve in curves.values() for step in curve})
    lines = [f"| step | {' | '.join(curves)} |", "|---" * (len(curves) + 1) + "|"]
    for step in steps:
        cells = [f"{curve[step]:.4g}" if step in curve else "–" for curve in curves.values()]
        lines.append(f"| {step} | {' | '.join(cells)} |")
    notes = "".join(f"\n{label}: {value:.4g}\n" for label, value in references or [])
    return f"{metric} against the optimizer step\n\n" + "\n".join(lines) + "\n" + notes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", metavar="NAME=RUN_DIR[+RUN_DIR...]")
    parser.add_argument("--metric", default="val/normal_angle_deg")
    parser.add_argument(
        "--reference", action="append", default=[], metavar="LABEL=VALUE", help="a line to draw; repeatable"
    )
    parser.add_argument("--out", type=Path, required=True, help="output path without suffix (.md and .png)")
    args = parser.parse_args(argv)
    curves: dict[str, dict[int, float]] = {}
    try:
        for spec in args.runs:
            name, sep, folder = spec.partition("=")
            if not sep or not name or not folder:
                raise ValueError(f"{spec!r}: expected NAME=RUN_DIR")
            curves[name] = staged_curve([Path(stage) for stage in folder.split("+")], args.metric)
        references = [parse_reference(spec) for spec in args.reference]
    except (FileNotFoundError, KeyError, ValueError) as error:
        print(f"learning_curve: {error}", file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    table = write_text_atomic(args.out.with_suffix(".md"), markdown_table(curves, args.metric, references))
    figure, axes = plt.subplots(figsize=(6, 4), dpi=100)
    for name, curve in curves.items():
        steps = sorted(curve)
        axes.plot(steps, [curve[step] for step in steps], marker="o", label=name)
    for (label, value), style in zip(references, itertools.cycle(["--", ":", "-."])):
        axes.axhline(value, color="grey", linestyle=style, label=label)
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
