"""scripts/learning_curve.py: validation curves read from train.py's CSV logs."""

from __future__ import annotations

from pathlib import Path

import pytest
from PIL import Image
from scripts.learning_curve import main, markdown_table, staged_curve, validation_curve


def _write_version(run: Path, version: int, rows: list[tuple[int, str]]) -> None:
    folder = run / "csv" / f"version_{version}"
    folder.mkdir(parents=True)
    lines = ["epoch,step,train/loss,val/normal_angle_deg"]
    lines += [f"0,{step},0.5,{value}" for step, value in rows]
    (folder / "metrics.csv").write_text("\n".join(lines) + "\n")


def test_a_resumed_runs_versions_are_joined_and_the_later_one_wins(tmp_path: Path) -> None:
    run = tmp_path / "run"
    _write_version(run, 0, [(24, ""), (399, "8.0"), (799, "7.5")])
    _write_version(run, 1, [(799, "7.4"), (1199, "7.1")])  # resumed from step 799's checkpoint
    _write_version(run, 10, [(1599, "6.9")])  # version_10 sorts after version_1
    assert validation_curve(run, "val/normal_angle_deg") == {399: 8.0, 799: 7.4, 1199: 7.1, 1599: 6.9}
    table = markdown_table({"a": {399: 8.0, 799: 7.4}, "b": {799: 7.0}}, "val/normal_angle_deg")
    assert "| 399 | 8 | – |" in table and "| 799 | 7.4 | 7 |" in table


def test_the_script_writes_a_table_and_a_plot_and_refuses_bad_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    _write_version(run, 0, [(399, "8.0"), (799, "7.5")])
    out = tmp_path / "figures" / "curve"
    assert main([f"shading={run}", "--out", str(out)]) == 0
    assert "| 799 | 7.5 |" in out.with_suffix(".md").read_text()
    assert Image.open(out.with_suffix(".png")).size == (600, 400)
    assert sorted(path.name for path in out.parent.iterdir()) == ["curve.md", "curve.png"]  # no temporaries
    assert main([f"none={tmp_path / 'missing'}", "--out", str(out)]) == 2
    assert main([f"shading={run}", "--metric", "val/nothing", "--out", str(out)]) == 2
    assert main([str(run), "--out", str(out)]) == 2
    errors = capsys.readouterr().err.splitlines()
    assert len(errors) == 3 and all(line.startswith("learning_curve: ") for line in errors)
    assert "missing" in errors[0] and "val/nothing" in errors[1] and "NAME=RUN_DIR" in errors[2]


def test_a_staged_run_continues_after_the_previous_stages_last_step(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    stage1, stage2 = tmp_path / "stage1", tmp_path / "stage2"
    _write_version(stage1, 0, [(1999, "7.9"), (5999, "7.8")])
    _write_version(stage2, 0, [(999, "7.7")])  # a warm start: its step count restarts at 0
    assert staged_curve([stage1, stage2], "val/normal_angle_deg") == {1999: 7.9, 5999: 7.8, 6999: 7.7}
    out = tmp_path / "curve"
    assert main([f"two={stage1}+{stage2}", "--reference", "flat map=7.95", "--out", str(out)]) == 0
    table = out.with_suffix(".md").read_text()
    assert "| 6999 | 7.7 |" in table and "flat map: 7.95" in table
    assert main([f"two={stage1}", "--reference", "7.95", "--out", str(out)]) == 2
    assert "--reference '7.95': expected LABEL=VALUE" in capsys.readouterr().err
