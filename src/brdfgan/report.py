"""Training runs compared by whatever varies across them: ``brdfgan report RUN_DIR…``.

Every run folder below the given directories that holds a ``metrics.json`` (written by
``train.py`` after testing) is read with its settings: the overrides it was started with
(``.hydra/overrides.yaml``), the config groups it chose (``.hydra/hydra.yaml``) and its seed
(``.hydra/config.yaml``). The keys whose values differ between the runs define the groups; seeds
(``seed`` and any ``*.seed``) are what a group averages over. Two runs with the same settings
and seed are duplicates: both are kept and a warning names them.

Written next to the first directory (or ``--out``):

- ``runs.md`` / ``runs.csv``: one row per group — the varying keys, the number of runs ``n``,
  and every metric as mean ± std over them;
- ``ablation.md`` / ``ablation.csv`` when only the ``loss`` choice (and seeds) vary: the
  paper's ablation table — proposed (``loss=full``), −L_r, −L_p, −L_f, −L_a — one row per map,
  with how much worse each ablation is than the proposed loss in percent.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import statistics
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import yaml

from brdfgan.errors import UserError
from brdfgan.io.atomic import write_text_atomic
from brdfgan.runs import RunFolder
from brdfgan.sweep_folders import override_key_value

log = logging.getLogger(__name__)

COLUMNS = (("full", "proposed"), ("no_render", "−L_r"), ("no_param", "−L_p"), ("no_feat", "−L_f"),
           ("no_adv", "−L_a"))  # fmt: skip
ROWS = (("rmse/diffuse", "diffuse"), ("rmse/specular", "specular"), ("rmse/normal", "normal"),
        ("rmse/roughness", "roughness"), ("normal_angle_deg", "normal (°)"),
        ("rerender_rmse", "re-render"))  # fmt: skip
# Columns of the runs table, in this order, where any run has them.
METRICS = (("rmse/diffuse", "diffuse"), ("rmse/specular", "specular"), ("rmse/roughness", "roughness"),
           ("rmse/basecolor", "base colour"), ("rmse/metallic", "metallic"), ("rmse/normal", "normal"),
           ("normal_angle_deg", "normal °"), ("rerender_rmse", "re-render"), ("false_metal", "false metal"),
           ("relief_leak", "relief leak"))  # fmt: skip
UNSET = "–"  # a key a run did not set (its default)


class ReportError(UserError):
    """No usable runs; the message names the directory."""


@dataclass(frozen=True)
class Run:
    path: Path
    settings: dict[str, str]  # override key (or config group) → value, and "seed"
    metrics: dict[str, float]


def is_seed_key(key: str) -> bool:
    """Seeds are averaged over, not grouped by: ``seed``, ``data.seed``, ``loss.seed``, …"""
    return key == "seed" or key.endswith(".seed")


def _settings(run: RunFolder) -> dict[str, str]:
    # Plain YAML reading: a run folder is data; nothing in it is instantiated.
    try:
        config = yaml.safe_load(run.config_path.read_text()) or {}
        hydra_cfg = yaml.safe_load(run.hydra_path.read_text()) if run.hydra_path.is_file() else {}
        overrides = yaml.safe_load(run.overrides_path.read_text()) if run.overrides_path.is_file() else []
        choices = ((hydra_cfg or {}).get("hydra") or {}).get("runtime", {}).get("choices") or {}
        settings = {str(k): str(v) for k, v in choices.items() if not str(k).startswith("hydra")}
        for override in overrides or []:
            key, value = override_key_value(override)
            settings[key] = value
        settings["seed"] = str(config.get("seed", 0))
        return settings
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError, ValueError) as error:
        raise ReportError(f"{run.path}: unreadable run config ({type(error).__name__}: {error})") from None


def collect(directories: Sequence[Path]) -> list[Run]:
    """Every run with a ``metrics.json`` below ``directories``, in path order."""
    runs: list[Run] = []
    for directory in directories:
        if not directory.is_dir():
            raise ReportError(f"{directory}: not a directory")
        for metrics_file in sorted(directory.rglob("metrics.json")):
            run = RunFolder(metrics_file.parent)
            if not run.is_run():
                continue
            try:
                values = json.loads(metrics_file.read_text())
            except (OSError, ValueError) as error:
                raise ReportError(f"{metrics_file}: unreadable metrics ({error})") from None
            # train.py writes {"model": {...}}: one model per run.
            metrics = values["model"] if isinstance(values.get("model"), dict) else values
            runs.append(Run(run.path, _settings(run), {k: float(v) for k, v in metrics.items()}))
    if not runs:
        raise ReportError(f"no training runs with metrics.json below {', '.join(map(str, directories))}")
    return runs


def varying_keys(runs: Sequence[Run]) -> list[str]:
    """The settings that differ between ``runs`` (seeds excluded), sorted."""
    keys = sorted({key for run in runs for key in run.settings if not is_seed_key(key)})
    return [key for key in keys if len({run.settings.get(key, UNSET) for run in runs}) > 1]


def group_runs(runs: Sequence[Run]) -> tuple[list[str], dict[tuple[str, ...], list[Run]]]:
    """The varying keys and the runs of each combination of their values; warns about
    duplicates (same settings and seeds), which stay in their group."""
    keys = varying_keys(runs)
    groups: dict[tuple[str, ...], list[Run]] = defaultdict(list)
    for run in runs:
        groups[tuple(run.settings.get(key, UNSET) for key in keys)].append(run)
    for values, members in groups.items():
        seen: dict[tuple[tuple[str, str], ...], Path] = {}
        for run in members:
            seeds = tuple(sorted((k, v) for k, v in run.settings.items() if is_seed_key(k)))
            if seeds in seen:
                what = " ".join(f"{k}={v}" for k, v in (*zip(keys, values, strict=True), *seeds))
                log.warning(
                    "duplicate runs of %s: %s and %s (both kept in the mean)", what, seen[seeds], run.path
                )
            else:
                seen[seeds] = run.path
    return keys, dict(groups)


def _mean_std(values: Sequence[float]) -> str:
    if not values:
        return UNSET
    cell = f"{statistics.fmean(values):.4f}"
    return cell + (f" ± {statistics.stdev(values):.4f}" if len(values) > 1 else "")


def runs_rows(runs: Sequence[Run]) -> list[list[str]]:
    """Header + one row per group: its varying keys' values, n, mean ± std of every metric."""
    keys, groups = group_runs(runs)
    metrics = [(key, label) for key, label in METRICS if any(key in run.metrics for run in runs)]
    rows = [[*keys, "n", *(label for _, label in metrics)]]
    for values, members in sorted(groups.items()):
        cells = [_mean_std([run.metrics[key] for run in members if key in run.metrics]) for key, _ in metrics]
        rows.append([*values, str(len(members)), *cells])
    return rows


def by_loss_and_seed(runs: Sequence[Run]) -> dict[str, list[dict[str, float]]]:
    """``{loss choice: [metrics of each run]}``."""
    out: dict[str, list[dict[str, float]]] = defaultdict(list)
    for run in runs:
        out[run.settings.get("loss", "full")].append(run.metrics)
    return dict(out)


def is_loss_ablation(runs: Sequence[Run]) -> bool:
    """Only the loss choice varies (besides seeds), and the proposed loss is among the runs."""
    return varying_keys(runs) == ["loss"] and any(run.settings.get("loss") == "full" for run in runs)


def ablation_rows(runs: dict[str, list[dict[str, float]]]) -> list[list[str]]:
    """Header + one row per metric: mean ± std over seeds and % worse than the proposed loss."""
    header = ["metric"] + [label for key, label in COLUMNS if key in runs]
    rows = [header]
    for metric, label in ROWS:
        base = [v[metric] for v in runs.get("full", []) if metric in v]
        base_mean = statistics.fmean(base) if base else None
        row = [label]
        for key, _ in COLUMNS:
            if key not in runs:
                continue
            values = [v[metric] for v in runs[key] if metric in v]
            cell = _mean_std(values)
            if values and key != "full" and base_mean:
                cell += f" ({(statistics.fmean(values) - base_mean) / base_mean:+.1%})"
            row.append(cell)
        rows.append(row)
    return rows


def _write_tables(rows: list[list[str]], note: str, markdown: Path, table: Path) -> None:
    lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    lines += ["| " + " | ".join(r) + " |" for r in rows[1:]]
    write_text_atomic(markdown, "\n".join([*lines, "", note]) + "\n")
    buffer = io.StringIO(newline="")
    csv.writer(buffer).writerows(rows)
    write_text_atomic(table, buffer.getvalue())


def write_report(directories: Sequence[Path], out: Path | None = None) -> list[Path]:
    """Write ``runs.md``/``.csv`` (and ``ablation.md``/``.csv`` for a loss ablation) into ``out``
    (default: the first directory); returns the Markdown files written."""
    runs = collect(directories)
    out = out or directories[0]
    out.mkdir(parents=True, exist_ok=True)
    rows = runs_rows(runs)
    keys = varying_keys(runs)
    note = (
        f"{len(runs)} runs grouped by {', '.join(keys) if keys else 'nothing (all settings equal)'}; "
        "mean ± std over the runs of a group (seeds), n runs each."
    )
    written = [out / "runs.md"]
    _write_tables(rows, note, written[0], out / "runs.csv")
    if is_loss_ablation(runs):
        losses = by_loss_and_seed(runs)
        counts = ", ".join(f"{k} {len(v)}" for k, v in losses.items())
        note = (
            f"Mean ± std over seeds (runs per loss: {counts}); in brackets: change against the "
            "proposed loss (positive = worse)."
        )
        written.append(out / "ablation.md")
        _write_tables(ablation_rows(losses), note, written[1], out / "ablation.csv")
    return written
