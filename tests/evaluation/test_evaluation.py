"""Weights files, evaluate.py outputs and the ablation report."""

from __future__ import annotations

import json
import logging
from functools import partial
from pathlib import Path

import pytest
import torch
import yaml
from safetensors import safe_open
from torch import Tensor, nn

from brdfgan.core.svbrdf import flat_maps
from brdfgan.evaluation.evaluator import evaluate_models, markdown_table, write_results
from brdfgan.inference.model.export_weights import tested_checkpoint as checkpoint_tested_by_train
from brdfgan.inference.model.weights import load_model
from brdfgan.metrics import SVBRDFMetrics, period2_floor
from brdfgan.models.generator import Generator
from brdfgan.report import (
    ReportError,
    ablation_rows,
    by_loss_and_seed,
    collect,
    is_loss_ablation,
    runs_rows,
    varying_keys,
    write_report,
)
from brdfgan.runs import WeightsError, load_generator, load_weights, save_weights
from tests.conftest import run_python

TARGET = "brdfgan.models.generator.Generator"


def tiny_generator() -> tuple[Generator, dict[str, int]]:
    config = {"in_channels": 3, "width": 8, "downsamplings": 2, "residual_blocks": 1}
    torch.manual_seed(0)
    return Generator(**config), config


def test_weights_round_trip_rebuilds_the_architecture(tmp_path: Path) -> None:
    generator, config = tiny_generator()
    photo = torch.rand(1, 3, 32, 32)
    expected = generator.eval()(photo)
    path = save_weights(
        tmp_path / "w.safetensors", generator, target=TARGET, config=config, model_id="tiny-1", extra={"n": 3}
    )
    loaded, meta = load_weights(path)
    assert meta["model_id"] == "tiny-1" and meta["config"] == config and meta["extra"] == {"n": 3}
    torch.testing.assert_close(loaded(photo), expected)
    half = save_weights(tmp_path / "h.safetensors", generator, target=TARGET, config=config, model_id="t",
                        half=True)  # fmt: skip
    assert half.stat().st_size < 0.6 * path.stat().st_size
    torch.testing.assert_close(load_generator(half)[0](photo), expected, atol=5e-3, rtol=0)


def test_bad_weights_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(WeightsError, match="weights file not found"):
        load_weights(tmp_path / "missing.safetensors")
    garbage = tmp_path / "garbage.safetensors"
    garbage.write_bytes(b"not safetensors at all")
    with pytest.raises(WeightsError, match="not a brdfgan safetensors weights file"):
        load_weights(garbage)
    generator, _ = tiny_generator()
    evil = save_weights(tmp_path / "evil.safetensors", generator, target="os.system", config={}, model_id="x")
    with pytest.raises(WeightsError, match=r"evil\.safetensors: not a brdfgan model config \(os\.system\)"):
        load_weights(evil)
    with pytest.raises(WeightsError, match=r"expected a \.safetensors weights file or a \.ckpt"):
        load_generator(tmp_path / "model.pt")


def _fake_run(
    root: Path,
    loss: str,
    seed: int,
    metrics: dict[str, float],
    overrides: tuple[str, ...] = (),
    name: str = "",
) -> Path:
    """A run folder as train.py leaves it: config, Hydra's choices and overrides, metrics."""
    run = root / (name or f"loss-{loss}_seed-{seed}")
    (run / ".hydra").mkdir(parents=True)
    (run / ".hydra" / "config.yaml").write_text(yaml.safe_dump({"seed": seed}))
    choices = {
        "hydra": {"runtime": {"choices": {"loss": loss, "model": "default", "hydra/launcher": "basic"}}}
    }
    (run / ".hydra" / "hydra.yaml").write_text(yaml.safe_dump(choices))
    (run / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump([f"seed={seed}", *overrides]))
    (run / "metrics.json").write_text(json.dumps({"model": metrics}))
    return run


def test_ablation_report_has_the_paper_layout_and_percentages(tmp_path: Path) -> None:
    _fake_run(tmp_path, "full", 0, {"rmse/diffuse": 0.10, "rmse/normal": 0.20})
    _fake_run(tmp_path, "full", 1, {"rmse/diffuse": 0.12, "rmse/normal": 0.20})
    _fake_run(tmp_path, "no_adv", 0, {"rmse/diffuse": 0.121, "rmse/normal": 0.19})
    _fake_run(tmp_path, "no_render", 0, {"rmse/diffuse": 0.143, "rmse/normal": 0.25})
    runs = collect([tmp_path])
    assert is_loss_ablation(runs)
    losses = by_loss_and_seed(runs)
    assert set(losses) == {"full", "no_adv", "no_render"} and len(losses["full"]) == 2
    rows = ablation_rows(losses)
    assert rows[0] == ["metric", "proposed", "−L_r", "−L_a"]
    diffuse = rows[1]
    assert diffuse[1].startswith("0.1100 ± 0.0141")
    assert diffuse[2] == "0.1430 (+30.0%)" and diffuse[3] == "0.1210 (+10.0%)"
    assert rows[3][3] == "0.1900 (-5.0%)"  # normal: better than proposed
    runs_md, ablation_md = write_report([tmp_path], tmp_path / "out")
    assert "| diffuse | 0.1100 ± 0.0141 | 0.1430 (+30.0%) | 0.1210 (+10.0%) |" in ablation_md.read_text()
    assert (tmp_path / "out" / "ablation.csv").read_text().startswith("metric,proposed")
    assert "| full | 2 | 0.1100 ± 0.0141 |" in runs_md.read_text()
    with pytest.raises(ReportError, match="no training runs"):
        collect([tmp_path / "out"])


def test_runs_are_grouped_by_every_key_that_varies_and_duplicates_are_kept(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # Three loss=full seed=0 runs (two duplicates of one setting), one no_adv, and a width sweep:
    # nothing is dropped, the duplicates are named in a warning.
    a = _fake_run(tmp_path, "full", 0, {"rmse/diffuse": 0.10}, name="a")
    b = _fake_run(tmp_path, "full", 0, {"rmse/diffuse": 0.14}, name="b")
    _fake_run(tmp_path, "full", 0, {"rmse/diffuse": 0.20}, ("model.generator.width=32",), name="c")
    _fake_run(tmp_path, "no_adv", 1, {"rmse/diffuse": 0.30}, ("data.seed=1",), name="d")
    runs = collect([tmp_path])
    assert varying_keys(runs) == ["loss", "model.generator.width"]  # seeds are averaged, not keys
    assert not is_loss_ablation(runs)
    with caplog.at_level(logging.WARNING, logger="brdfgan.report"):
        rows = runs_rows(runs)
    assert rows[0] == ["loss", "model.generator.width", "n", "diffuse"]
    assert rows[1:] == [
        ["full", "32", "1", "0.2000"],
        ["full", "–", "2", "0.1200 ± 0.0283"],
        ["no_adv", "–", "1", "0.3000"],
    ]
    assert f"duplicate runs of loss=full model.generator.width=– seed=0: {a} and {b}" in caplog.text
    written = write_report([tmp_path], tmp_path / "out")
    assert [p.name for p in written] == ["runs.md"] and not (tmp_path / "out" / "ablation.md").exists()
    assert "4 runs grouped by loss, model.generator.width" in written[0].read_text()
    assert (tmp_path / "out" / "runs.csv").read_text().splitlines()[
        0
    ] == "loss,model.generator.width,n,diffuse"


@pytest.mark.integration
@pytest.mark.mitsuba
def test_train_then_evaluate_writes_tables_chart_and_grids(tiny_data: Path) -> None:
    trained = run_python("train.py", "debug=default", "task_name=evaltest", cwd=tiny_data)
    assert trained.returncode == 0, trained.stderr[-3000:]
    run = sorted((tiny_data / "logs" / "evaltest" / "runs").iterdir())[-1]
    metrics = json.loads((run / "metrics.json").read_text())["model"]
    assert {"rmse/diffuse", "rmse/normal", "normal_angle_deg", "rerender_rmse"} <= set(metrics)
    ckpt = run / "checkpoints" / "last.ckpt"
    generator, meta = load_generator(ckpt)
    weights = save_weights(tiny_data / "model.safetensors", generator, target=meta["target"],
                           config=meta["config"], model_id="smoke")  # fmt: skip

    result = run_python("evaluate.py", "data=tiny", f"ckpt={{ours: {ckpt}, exported: {weights}}}",
                        "grid_samples=2", "logger=many", cwd=tiny_data)  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    out = sorted((tiny_data / "logs" / "evaluate" / "runs").iterdir())[-1]
    outputs = ("metrics.json", "metrics.csv", "metrics.md", "rmse.png", "grid_ours.png", "grid_exported.png")
    for name in outputs:
        assert (out / name).is_file(), name
    results = json.loads((out / "metrics.json").read_text())
    # The exported weights are the checkpoint's generator: same numbers.
    assert results["ours"]["rmse/diffuse"] == pytest.approx(results["exported"]["rmse/diffuse"], rel=1e-5)
    assert "| ours |" in (out / "metrics.md").read_text()
    # ... and the same numbers and images went to the dashboards (CSV and TensorBoard here).
    logged = next((out / "csv").rglob("metrics.csv")).read_text()
    assert "ours/rmse/diffuse" in logged and "exported/rerender_rmse" in logged
    assert list((out / "tensorboard").rglob("events.out.tfevents.*"))

    bad = run_python("evaluate.py", "data=tiny", "ckpt=/nonexistent.ckpt", cwd=tiny_data)
    assert bad.returncode == 2 and "checkpoint not found" in bad.stderr and "Traceback" not in bad.stderr

    # The run exports to the weights `brdfgan predict` loads: fp16 tensors, architecture and summary.
    shipped = tiny_data / "shipped" / "smoke.safetensors"
    exported = run_python("-m", "brdfgan.cli", "export-weights", str(run), "--out", str(shipped),
                          "--model-id", "smoke-v1", "--hardware", "test CPU", cwd=tiny_data)  # fmt: skip
    assert exported.returncode == 0, exported.stderr[-2000:]
    model = load_model(shipped)
    assert model.model_id == "smoke-v1" and model.resolution == 64  # the tiny dataset's resolution
    summary = json.loads(shipped.with_suffix(".json").read_text())
    assert summary["optimizer_steps"] == torch.load(ckpt, weights_only=True)["global_step"]
    assert summary["loss"] == {"adversarial": True, "feature": True, "parameter": True, "rendering": True}
    assert summary["hardware"] == "test CPU"
    # train.py's metrics are recorded when it tested the exported step (both cases: the unit test below).
    best = checkpoint_tested_by_train(torch.load(ckpt, weights_only=True), "val/loss")
    if best is not None and torch.load(best, weights_only=True)["global_step"] == summary["optimizer_steps"]:
        assert summary["test_metrics"]["rmse/diffuse"] == metrics["rmse/diffuse"]
    else:
        assert "test_metrics" not in summary
    with safe_open(str(shipped), framework="pt") as handle:
        assert all(handle.get_tensor(k).dtype == torch.float16 for k in handle.keys() if "weight" in k)  # noqa: SIM118 (not iterable)
    photo = torch.rand(1, 3, 64, 64)
    assert torch.allclose(model.generator(photo), generator.eval()(photo), atol=2e-2)  # fp16 rounding
    missing = run_python("-m", "brdfgan.cli", "export-weights", str(tiny_data), cwd=tiny_data)
    assert missing.returncode == 2 and "not a training run directory" in missing.stderr


@pytest.mark.integration
@pytest.mark.mitsuba
@pytest.mark.slow  # 13-18 s: kept out of make test's 6 minutes (make test-slow runs it)
def test_baseline_trains_and_is_evaluated_by_the_same_commands(tiny_data: Path) -> None:
    # The baseline trains with the content losses only (no discriminator); 6 levels fit 64² crops.
    baseline = ["model=deschaintre2018", "model.generator.levels=6"]
    baseline += ["loss=no_adv", "loss.switches.feature=false"]
    baseline += ["data=tiny", "trainer.max_epochs=1", "trainer.num_sanity_val_steps=0", "task_name=baseline"]
    trained = run_python("train.py", *baseline, cwd=tiny_data)
    assert trained.returncode == 0, trained.stderr[-3000:]
    run = sorted((tiny_data / "logs" / "baseline" / "runs").iterdir())[-1]
    assert "rmse/diffuse" in json.loads((run / "metrics.json").read_text())["model"]
    ckpt = run / "checkpoints" / "last.ckpt"
    _, meta = load_generator(ckpt)
    assert meta["target"] == "brdfgan.models.deschaintre2018.Deschaintre2018"
    result = run_python("evaluate.py", "data=tiny", f"ckpt={{deschaintre2018: {ckpt}}}", "grid_samples=1",
                  "task_name=baseline_eval", cwd=tiny_data)  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    out = sorted((tiny_data / "logs" / "baseline_eval" / "runs").iterdir())[-1]
    assert "| deschaintre2018 |" in (out / "metrics.md").read_text()


class ConstantBaseColour(nn.Module):
    """Predicts flat maps of one base colour whatever the photo."""

    def __init__(self, basecolor: tuple[float, float, float]) -> None:
        super().__init__()
        self.basecolor = basecolor

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        return flat_maps(*photo.shape[-2:], basecolor=self.basecolor, batch=(photo.shape[0],))


def test_evaluator_tables_report_base_colour_saturation_and_hue(tmp_path: Path) -> None:
    # Teal tiles (sRGB 0.1, 0.6, 0.6: hue 180°, HSV saturation 5/6) predicted grey-brown (0.5, 0.45,
    # 0.4: hue 30°, saturation 0.2), as the shipped model did on phone captures.
    truth = flat_maps(8, 8, basecolor=(0.1, 0.6, 0.6), batch=(2,))
    batches = [
        {"photo": torch.rand(2, 3, 8, 8), "maps": truth},
        {"photo": torch.rand(1, 3, 8, 8), "maps": truth[:1]},
    ]
    models = {"greyed": ConstantBaseColour((0.5, 0.45, 0.4)), "right": ConstantBaseColour((0.1, 0.6, 0.6))}
    results = evaluate_models(models, batches, partial(SVBRDFMetrics, downscale_to=None, rerender_configs=2))
    assert results["greyed"]["basecolor_saturation_ratio"] == pytest.approx(0.24, rel=1e-5)
    assert results["greyed"]["basecolor_hue_error_deg"] == pytest.approx(150.0, rel=1e-5)
    assert results["right"]["basecolor_saturation_ratio"] == pytest.approx(1.0, rel=1e-6)
    assert results["right"]["basecolor_hue_error_deg"] == pytest.approx(0.0, abs=1e-4)

    header, rule, greyed, right = markdown_table(results).splitlines()
    columns = [cell.strip() for cell in header.strip("|").split("|")]
    assert columns[0] == "model" and columns.index("sat ratio") == columns.index("re-render") + 1
    assert columns.index("hue °") == columns.index("sat ratio") + 1
    assert {"diffuse", "normal °", "re-render"} <= set(columns)  # the earlier columns stay
    cells = [cell.strip() for cell in greyed.strip("|").split("|")]
    assert cells[columns.index("sat ratio")] == "0.2400" and cells[columns.index("hue °")] == "150.0000"
    cells = [cell.strip() for cell in right.strip("|").split("|")]
    assert cells[columns.index("sat ratio")] == "1.0000" and cells[columns.index("hue °")] == "0.0000"
    assert rule.count("---") == len(columns)

    write_results(results, tmp_path)
    stored = json.loads((tmp_path / "metrics.json").read_text())
    assert stored["greyed"]["basecolor_saturation_ratio"] == pytest.approx(0.24, rel=1e-5)
    csv_header, csv_greyed, _ = (tmp_path / "metrics.csv").read_text().splitlines()
    names = csv_header.split(",")
    assert {"basecolor_saturation_ratio", "basecolor_hue_error_deg"} <= set(names)
    assert float(csv_greyed.split(",")[names.index("basecolor_hue_error_deg")]) == pytest.approx(
        150.0, rel=1e-5
    )


class CheckeredRoughness(nn.Module):
    """Predicts flat maps with a ±amplitude checkerboard (−1)^(i+j) on roughness."""

    def __init__(self, amplitude: float) -> None:
        super().__init__()
        self.amplitude = amplitude

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        maps = flat_maps(*photo.shape[-2:], batch=(photo.shape[0],))
        rows, cols = torch.meshgrid(torch.arange(maps.shape[-2]), torch.arange(maps.shape[-1]), indexing="ij")
        maps[:, 6] += self.amplitude * (1 - 2 * ((rows + cols) % 2))
        return maps


def test_evaluator_table_reports_checkerboard_ratios(tmp_path: Path) -> None:
    truth = flat_maps(8, 8, batch=(3,))
    batches = [{"photo": torch.rand(3, 3, 8, 8), "maps": truth}]
    models = {"flat": CheckeredRoughness(0.0), "checkered": CheckeredRoughness(0.01)}
    results = evaluate_models(models, batches, partial(SVBRDFMetrics, downscale_to=None, rerender_configs=2))
    floor = period2_floor(8, 8)["roughness"]  # flat truth: the 8-bit quantisation floor only
    assert results["checkered"]["checkerboard/roughness"] == pytest.approx(
        (0.01**2 + floor) / floor, rel=1e-4
    )
    for model in models:
        for name in ("basecolor", "normal", "metallic"):
            assert results[model][f"checkerboard/{name}"] == pytest.approx(1.0, abs=1e-6)
    assert results["flat"]["checkerboard/roughness"] == pytest.approx(1.0, abs=1e-6)

    header, rule, flat, checkered = markdown_table(results).splitlines()
    columns = [cell.strip() for cell in header.strip("|").split("|")]
    checker_columns = ["chk base", "chk normal", "chk rough", "chk metal"]
    start = columns.index("chk base")
    assert columns[start : start + 4] == checker_columns and start == columns.index("hue °") + 1
    assert rule.count("---") == len(columns)
    cells = [cell.strip() for cell in checkered.strip("|").split("|")]
    assert float(cells[columns.index("chk rough")]) == pytest.approx(740.6, rel=1e-3)  # (1e-4 + f) / f
    assert cells[columns.index("chk base")] == "1.0000"
    cells = [cell.strip() for cell in flat.strip("|").split("|")]
    assert [cells[columns.index(label)] for label in checker_columns] == ["1.0000"] * 4
    write_results(results, tmp_path)
    stored = json.loads((tmp_path / "metrics.json").read_text())
    assert {f"checkerboard/{name}" for name in ("basecolor", "normal", "roughness", "metallic")} <= set(
        stored["checkered"]
    )


def test_checkpoint_of_another_architecture_is_a_clear_error(tmp_path: Path) -> None:
    run = tmp_path / "run"
    (run / ".hydra").mkdir(parents=True)
    (run / "checkpoints").mkdir()
    node = {"_target_": TARGET, "in_channels": 3, "width": 16, "downsamplings": 2, "residual_blocks": 1}
    (run / ".hydra" / "config.yaml").write_text(yaml.safe_dump({"model": {"generator": node}}))
    generator, _ = tiny_generator()  # width 8: does not fit the width-16 config
    ckpt = run / "checkpoints" / "last.ckpt"
    torch.save({"state_dict": {f"generator.{k}": v for k, v in generator.state_dict().items()}}, ckpt)
    with pytest.raises(WeightsError, match="does not fit its run's generator"):
        load_generator(ckpt)
    (run / ".hydra" / "config.yaml").unlink()
    with pytest.raises(WeightsError, match="no run config at"):
        load_generator(ckpt)


@pytest.mark.integration
def test_evaluating_an_empty_split_names_the_folder(tmp_path: Path) -> None:
    generator, config = tiny_generator()
    weights = save_weights(tmp_path / "w.safetensors", generator, target=TARGET, config=config, model_id="t")
    result = run_python("evaluate.py", "data=deschaintre", f"ckpt={weights}", cwd=tmp_path)
    assert result.returncode == 2, result.stderr[-2000:]
    assert f"no shards in {tmp_path}/data/deschaintre/test" in result.stderr
    assert "Traceback" not in result.stderr


def _fake_training_run(run_dir: Path, overrides: list[str], epoch: int, step: int) -> Path:
    """A run directory as train.py leaves it: .hydra/config.yaml and checkpoints/last.ckpt."""
    from omegaconf import OmegaConf

    from tests.conftest import compose_train

    (run_dir / ".hydra").mkdir(parents=True)
    OmegaConf.save(compose_train(overrides, run_dir), run_dir / ".hydra" / "config.yaml")
    checkpoint = run_dir / "checkpoints" / "last.ckpt"
    checkpoint.parent.mkdir()
    torch.save({"epoch": epoch, "global_step": step}, checkpoint)
    return checkpoint


@pytest.mark.integration
def test_a_warm_started_run_summarises_the_run_it_began_from(tmp_path: Path) -> None:
    from brdfgan.inference.model.export_weights import training_summary

    gan = _fake_training_run(tmp_path / "gan", ["experiment=procedural", "loss=full"], epoch=6, step=4900)
    content = ["experiment=procedural_finetune", f"init_from={gan}"]
    finetune = _fake_training_run(tmp_path / "finetune", content, epoch=5, step=2100)
    summary = training_summary(tmp_path / "finetune", finetune, "test CPU")
    assert summary["optimizer_steps"] == 2100 and summary["epochs"] == 6
    assert summary["loss"] == {"adversarial": False, "feature": False, "parameter": True, "rendering": True}
    assert summary["metallic_loss"] == "bce"  # v3's recipe (experiment=procedural)
    earlier = summary["init_from"]
    assert earlier["run"] == str(tmp_path / "gan")
    assert earlier["optimizer_steps"] == 4900 and earlier["epochs"] == 7
    assert earlier["loss"]["adversarial"] and "init_from" not in earlier and "hardware" not in earlier
    # The whole recipe: both stages' steps (the wall times are unknown: these runs logged nothing).
    assert summary["recipe"] == {"stages": 2, "optimizer_steps": 7000, "wall_time_s": None}
    # Weights that do not come from a run directory are named only.
    weights = tmp_path / "w.safetensors"
    weights.write_bytes(b"")
    from_weights = ["experiment=procedural_finetune", f"init_from={weights}"]
    other = _fake_training_run(tmp_path / "other", from_weights, epoch=0, step=350)
    from_outside = training_summary(tmp_path / "other", other, None)
    assert from_outside["init_from"] == {"checkpoint": str(weights)}
    assert from_outside["recipe"] == {"stages": 1, "optimizer_steps": 350, "wall_time_s": None}


@pytest.mark.integration
def test_the_summary_says_how_the_training_photos_were_made(tmp_path: Path) -> None:
    from brdfgan.inference.model.export_weights import recipe_totals, training_summary

    relief = ["data.relief.swap_probability=0.25", "data.relief.bump_probability=0.5"]
    v5 = _fake_training_run(tmp_path / "v5", ["experiment=anchored_rendered", *relief], epoch=14, step=6000)
    dataset = training_summary(tmp_path / "v5", v5, None)["dataset"]
    assert dataset["training_photos"] == "rendered on the fly"
    assert dataset["relief"]["swap_probability"] == 0.25 and dataset["relief"]["bump_probability"] == 0.5
    assert dataset["sensor"]["jpeg_quality_min"] == 85 and "_target_" not in dataset["relief"]
    v4 = _fake_training_run(tmp_path / "v4", ["experiment=anchored"], epoch=0, step=10)
    assert training_summary(tmp_path / "v4", v4, None)["dataset"]["training_photos"] == "shards"
    # Known wall times add up over the stages.
    stages = {
        "optimizer_steps": 1000,
        "wall_time_s": 1200.0,
        "init_from": {"optimizer_steps": 6000, "wall_time_s": 4800.5},
    }
    assert recipe_totals(stages) == {"stages": 2, "optimizer_steps": 7000, "wall_time_s": 6000.5}


@pytest.mark.integration
def test_the_summary_of_a_rendered_run_without_shards_reads_its_banks_spec(tmp_path: Path) -> None:
    # data.prepare=null (no shards generated, as on a GPU machine without Mitsuba): the bank's spec
    # says what the materials were.
    from brdfgan.inference.model.export_weights import training_summary

    overrides = [
        "experiment=anchored_rendered",
        "data.prepare=null",
        "+dataset_spec@data.bank.spec=procedural_and_scans",
    ]
    run = _fake_training_run(tmp_path / "gpu", overrides, epoch=0, step=10)
    summary = training_summary(tmp_path / "gpu", run, None)
    assert summary["dataset"]["training_photos"] == "rendered on the fly"
    assert summary["resolution"] == 256 and summary["dataset"]["scans"]["fraction"] == 0.35


@pytest.mark.integration
def test_the_summary_records_the_share_of_scanned_materials(tmp_path: Path) -> None:
    from brdfgan.inference.model.export_weights import training_summary

    v4 = _fake_training_run(tmp_path / "v4", ["experiment=anchored"], epoch=0, step=10)
    scans = training_summary(tmp_path / "v4", v4, None)["dataset"]["scans"]
    assert 0.0 < scans["fraction"] < 1.0
    assert len(scans["val_sets"]) == len(scans["test_sets"]) == 3 and "Metal012" in scans["val_sets"]
    v3 = _fake_training_run(tmp_path / "v3", ["experiment=procedural"], epoch=0, step=10)
    assert "scans" not in training_summary(tmp_path / "v3", v3, None)["dataset"]


@pytest.mark.integration
def test_exported_test_metrics_belong_to_the_exported_checkpoint(tmp_path: Path) -> None:
    from brdfgan.inference.model.export_weights import evaluation_metrics, training_summary

    run = tmp_path / "run"
    last = _fake_training_run(run, ["debug=default"], epoch=5, step=60)
    (run / "metrics.json").write_text(json.dumps({"model": {"rmse/normal": 0.5}}))

    def tested(best: Path, best_step: int) -> None:
        torch.save({"epoch": 1, "global_step": best_step}, best)
        callbacks = {
            "best": {"monitor": "val/loss", "best_model_path": str(best)},
            "last": {"monitor": None, "best_model_path": str(last)},
        }
        torch.save({"epoch": 5, "global_step": 60, "callbacks": callbacks}, last)

    # train.py tested an earlier best epoch: its metrics are not the exported last.ckpt's.
    tested(run / "checkpoints" / "epoch001-step20.ckpt", 20)
    assert "test_metrics" not in training_summary(run, last, None)
    # The best epoch was the last one: same step, same weights, the metrics apply.
    tested(run / "checkpoints" / "epoch005-step60.ckpt", 60)
    assert training_summary(run, last, None)["test_metrics"] == {"rmse/normal": 0.5}
    # Metrics of a separate evaluate.py run, by model name.
    evaluation = tmp_path / "metrics.json"
    evaluation.write_text(json.dumps({"shipped": {"rmse/normal": 0.25}, "baseline": {"rmse/normal": 0.3}}))
    assert evaluation_metrics(evaluation, "shipped") == {"rmse/normal": 0.25}
    with pytest.raises(WeightsError, match=r"no model 'gan' in these metrics \(models: shipped, baseline\)"):
        evaluation_metrics(evaluation, "gan")
    with pytest.raises(WeightsError, match="holds several models; name one with --metrics-model"):
        evaluation_metrics(evaluation)
    evaluation.write_text(json.dumps({"only": {"rmse/normal": 0.2}}))
    assert evaluation_metrics(evaluation) == {"rmse/normal": 0.2}
    evaluation.write_text("not json")
    with pytest.raises(WeightsError, match="cannot read evaluation metrics"):
        evaluation_metrics(evaluation)
