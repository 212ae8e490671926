"""The paper's ablation table from training runs: ``brdfgan report RUN_DIR…``.

Every run folder below the given directories that holds a ``metrics.json`` (written by
``train.py`` after testing) is grouped by its ``loss`` choice and seed (from the run's
``.hydra/config.yaml`` / ``overrides.yaml``). The table has one row per map and the columns of
the paper's ablation — proposed (``loss=full``), −L_r, −L_p, −L_f, −L_a — with the mean ± std
over seeds and, for every ablation, how much worse it is than the proposed loss in percent.
Written as ``ablation.md`` and ``ablation.csv`` next to the first directory (or ``--out``).
"""

from __future__ import annotations

import csv
import json
import statistics
from collections import defaultdict
from pathlib import Path

import yaml

from brdfgan.errors import UserError
from brdfgan.runs import RunFolder

COLUMNS = (("full", "proposed"), ("no_render", "−L_r"), ("no_param", "−L_p"), ("no_feat", "−L_f"),
           ("no_adv", "−L_a"))  # fmt: skip
ROWS = (("rmse/diffuse", "diffuse"), ("rmse/specular", "specular"), ("rmse/normal", "normal"),
        ("rmse/roughness", "roughness"), ("normal_angle_deg", "normal (°)"),
        ("rerender_rmse", "re-render"))  # fmt: skip


class ReportError(UserError):
    """No usable runs; the message names the directory."""


def _loss_choice(run: RunFolder) -> tuple[str, int]:
    # Plain YAML reading: a run folder is data; nothing in it is instantiated.
    try:
        config = yaml.safe_load(run.config_path.read_text())
        hydra_cfg = yaml.safe_load(run.hydra_path.read_text())
        choice = hydra_cfg["hydra"]["runtime"]["choices"].get("loss", "full")
        return str(choice), int(config.get("seed", 0))
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError, ValueError) as error:
        raise ReportError(f"{run.path}: unreadable run config ({type(error).__name__}: {error})") from None


def collect(directories: list[Path]) -> dict[str, dict[int, dict[str, float]]]:
    """``{loss choice: {seed: metrics}}`` of every run found below ``directories``."""
    runs: dict[str, dict[int, dict[str, float]]] = defaultdict(dict)
    for directory in directories:
        if not directory.is_dir():
            raise ReportError(f"{directory}: not a directory")
        for metrics_file in sorted(directory.rglob("metrics.json")):
            run = RunFolder(metrics_file.parent)
            if not run.is_run():
                continue
            loss, seed = _loss_choice(run)
            try:
                values = json.loads(metrics_file.read_text())
            except (OSError, ValueError) as error:
                raise ReportError(f"{metrics_file}: unreadable metrics ({error})") from None
            # train.py writes {"model": {...}}: one model per run.
            runs[loss][seed] = values["model"] if isinstance(values.get("model"), dict) else values
    if not runs:
        raise ReportError(f"no training runs with metrics.json below {', '.join(map(str, directories))}")
    return runs


def ablation_rows(runs: dict[str, dict[int, dict[str, float]]]) -> list[list[str]]:
    """Header + one row per metric: mean ± std over seeds and % worse than the proposed loss."""
    header = ["metric"] + [label for key, label in COLUMNS if key in runs]
    rows = [header]
    for metric, label in ROWS:
        base = [v[metric] for v in runs.get("full", {}).values() if metric in v]
        base_mean = statistics.fmean(base) if base else None
        row = [label]
        for key, _ in COLUMNS:
            if key not in runs:
                continue
            values = [v[metric] for v in runs[key].values() if metric in v]
            if not values:
                row.append("–")
                continue
            mean = statistics.fmean(values)
            cell = f"{mean:.4f}" + (f" ± {statistics.stdev(values):.4f}" if len(values) > 1 else "")
            if key != "full" and base_mean:
                cell += f" ({(mean - base_mean) / base_mean:+.1%})"
            row.append(cell)
        rows.append(row)
    return rows


def write_report(directories: list[Path], out: Path | None = None) -> tuple[Path, Path]:
    runs = collect(directories)
    rows = ablation_rows(runs)
    out = out or directories[0]
    out.mkdir(parents=True, exist_ok=True)
    seeds = {key: len(v) for key, v in runs.items()}
    lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    lines += ["| " + " | ".join(r) + " |" for r in rows[1:]]
    lines.append("")
    lines.append("Mean ± std over seeds (runs per loss: " + ", ".join(f"{k} {n}" for k, n in seeds.items())
                 + "); in brackets: change against the proposed loss (positive = worse).")  # fmt: skip
    markdown = out / "ablation.md"
    markdown.write_text("\n".join(lines) + "\n")
    table = out / "ablation.csv"
    with table.open("w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    return markdown, table
