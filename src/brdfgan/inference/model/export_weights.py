"""Turn a training run into a ``.safetensors`` weights file that ``brdfgan predict`` can load.

    brdfgan export-weights RUN_DIR [--checkpoint last|best|PATH]
        [--out PATH] [--model-id ID] [--full-precision] [--hardware TEXT]
        [--metrics EVAL_DIR/metrics.json [--metrics-model NAME]]

The file holds the generator's tensors (fp16 unless ``--full-precision``), the model id, the
class and its constructor arguments (the architecture is rebuilt without Hydra or pickle), and a
training summary in ``extra``: the resolution the model expects, the training crop, the dataset
and its size, steps, epochs, wall time, hardware, the run a warm-started run began from, and
test metrics (the run's own when it tested the exported step, or ``--metrics``). The same
summary is written beside the file as ``<stem>.json`` for people to read.

Checkpoints are read with ``torch.load(weights_only=True)`` and the generator is built from the
run's stored config only through :func:`brdfgan.runs.network_from_config` (the project's own
network classes, plain arguments): a crafted run folder cannot make this command run code.
"""

from __future__ import annotations

import json
import platform
from datetime import datetime
from pathlib import Path
from typing import Any

import torch
from omegaconf import OmegaConf

from brdfgan.io.atomic import write_text_atomic
from brdfgan.runs import RunFolder, WeightsError, load_checkpoint_generator, read_checkpoint, save_weights


def training_wall_time(run_dir: Path) -> float | None:
    """Seconds of training summed over the run's sessions (a resume starts a new CSV version),
    validation and the final test included: from each version's first file (``hparams.yaml`` is
    written at start but rewritten at the end, so the folder's own time counts too) to its last
    ``metrics.csv`` write."""
    total = 0.0
    for version in sorted((run_dir / "csv").glob("version_*")):
        start, end = version / "hparams.yaml", version / "metrics.csv"
        if start.is_file() and end.is_file():
            began = min(start.stat().st_mtime, version.stat().st_mtime)
            total += max(0.0, end.stat().st_mtime - began)
    return round(total, 1) if total > 0 else None


def tested_checkpoint(state: dict[str, Any], monitor: str) -> Path | None:
    """The checkpoint ``train.py`` tested after fitting (the best by ``monitor``), as recorded by
    the monitoring ``ModelCheckpoint`` in a checkpoint's callback states."""
    for callback in state.get("callbacks", {}).values():
        if (
            isinstance(callback, dict)
            and callback.get("monitor") == monitor
            and callback.get("best_model_path")
        ):
            return Path(callback["best_model_path"])
    return None


def run_test_metrics(
    run_dir: Path, checkpoint: Path, state: dict[str, Any], monitor: str
) -> dict[str, Any] | None:
    """The run's own test metrics (``metrics.json``) when they belong to ``checkpoint``: train.py
    tests the best checkpoint, which may not be the one exported (e.g. ``last``)."""
    metrics, tested = run_dir / "metrics.json", tested_checkpoint(state, monitor)
    if not metrics.is_file() or tested is None or not tested.is_file():
        return None
    # last.ckpt and the best epoch's file hold the same weights when they are the same step.
    same = tested.resolve() == checkpoint.resolve()
    if not same:
        tested_step = read_checkpoint(tested).get("global_step")
        same = tested_step == state.get("global_step")
    return json.loads(metrics.read_text()).get("model", {}) if same else None


def run_overrides(run_dir: Path) -> list[str] | None:
    """The command-line overrides the run was started with (Hydra's ``.hydra/overrides.yaml``)."""
    path = RunFolder(run_dir).hydra_path.with_name("overrides.yaml")
    if not path.is_file():
        return None
    overrides = OmegaConf.load(path)
    return [str(item) for item in overrides] if OmegaConf.is_list(overrides) else None


def training_summary(
    run_dir: Path, checkpoint: Path, hardware: str | None, test_metrics: dict[str, Any] | None = None
) -> dict[str, Any]:
    """What a user of the weights should know about how they were made (JSON-serialisable).

    ``test_metrics``: recorded as given; ``None`` looks for the run's own (:func:`run_test_metrics`).
    """
    config = RunFolder(run_dir).config()
    state = read_checkpoint(checkpoint)
    data = config.data
    # The spec that generated the shards; a rendered run with data.prepare=null (no shards made,
    # as on a machine without Mitsuba) names its bank's own.
    node = OmegaConf.select(data, "prepare.spec", default=None) or OmegaConf.select(
        data, "bank.spec", default=None
    )
    spec = OmegaConf.to_container(node, resolve=False) if node is not None else None
    spec = spec if isinstance(spec, dict) else {}
    summary: dict[str, Any] = {
        "resolution": int(spec.get("resolution", 256)),
        "train_crop": data.get("train_crop"),
        "dataset": {
            "dir": Path(str(data.data_dir)).name,
            "materials": spec.get("materials"),
            "spp": spec.get("spp"),
        },
        "batch_size": int(data.batch_size),
        "loss": {k: bool(v) for k, v in config.loss.switches.items() if not str(k).startswith("_")},
        "metallic_loss": str(config.loss.get("metallic_loss", "l1")),
        "overrides": run_overrides(run_dir),
        "epochs": int(state.get("epoch", -1)) + 1,
        "optimizer_steps": int(state.get("global_step", 0)),
        "checkpoint": checkpoint.name,
        "seed": int(config.seed),
        "wall_time_s": training_wall_time(run_dir),
        "hardware": hardware or f"{platform.machine()} CPU, {torch.get_num_threads()} threads",
        "exported": datetime.now().astimezone().isoformat(timespec="seconds"),
    }
    scans = spec.get("scans")
    if isinstance(scans, dict) and scans.get("fraction"):  # the share painted from scans, sets held out
        summary["dataset"]["scans"] = {key: scans.get(key) for key in ("fraction", "val_sets", "test_sets")}
    # How the training photos were made: read from shards, or rendered on the fly from the spec's
    # materials (data=rendered) with its relief sampling; both through the phone's sensor.
    rendered = str(data.get("_target_", "")).endswith("RenderedDataModule")
    summary["dataset"]["training_photos"] = "rendered on the fly" if rendered else "shards"
    for key in ("relief", "sensor"):
        if key in data:
            options = OmegaConf.to_container(data[key], resolve=True)
            if isinstance(options, dict):
                summary["dataset"][key] = {k: v for k, v in options.items() if not str(k).startswith("_")}
    if test_metrics is None:
        test_metrics = run_test_metrics(run_dir, checkpoint, state, str(config.get("monitor", "val/loss")))
    if test_metrics is not None:
        summary["test_metrics"] = test_metrics
    init_from = OmegaConf.select(config, "init_from", default=None)
    if init_from is not None:
        summary["init_from"] = warm_start_summary(Path(str(init_from)))
        summary["recipe"] = recipe_totals(summary)
    return summary


def recipe_totals(summary: dict[str, Any]) -> dict[str, Any]:
    """The whole recipe of a warm-started run: its stages (this run and those it began from,
    through ``init_from``), their optimizer steps and training seconds summed. The wall time is
    ``None`` when a stage's is unknown (weights from outside a run directory)."""
    stages, steps, seconds = 0, 0, 0.0
    known = True
    stage: dict[str, Any] | None = summary
    while stage is not None:
        if "optimizer_steps" not in stage:  # weights that do not come from a run directory
            known = False
            break
        stages += 1
        steps += int(stage["optimizer_steps"])
        if stage.get("wall_time_s") is None:
            known = False
        else:
            seconds += float(stage["wall_time_s"])
        stage = stage.get("init_from")
    return {"stages": stages, "optimizer_steps": steps, "wall_time_s": round(seconds, 1) if known else None}


def warm_start_summary(checkpoint: Path) -> dict[str, Any]:
    """The run a warm-started run (``init_from``) began from: its own summary when the file is a
    checkpoint inside a run directory (``RUN/checkpoints/*.ckpt``), else just the path."""
    run = RunFolder.of_checkpoint(checkpoint)
    if checkpoint.suffix != ".ckpt" or not checkpoint.is_file() or not run.is_run():
        return {"checkpoint": str(checkpoint)}
    earlier = training_summary(run.path, checkpoint, None)
    for key in ("hardware", "exported"):  # this machine now / this export: not facts of that run
        earlier.pop(key)
    return {"run": str(run.path), **earlier}


def export_weights(
    run_dir: Path,
    out: Path,
    *,
    checkpoint: str = "last",
    model_id: str | None = None,
    half: bool = True,
    hardware: str | None = None,
    metrics: tuple[Path, str | None] | None = None,
) -> Path:
    """Export a run's generator to ``out`` (+ ``out.with_suffix('.json')``); returns ``out``.

    ``metrics``: ``(metrics.json of an evaluate.py run, model name in it or None for its only
    model)`` to record as the test metrics instead of the run's own (which exist only when the
    exported checkpoint was tested).
    """
    run = RunFolder(run_dir)
    if not run.is_run():
        raise WeightsError(f"{run_dir}: not a training run directory (no .hydra/config.yaml)")
    path = run.checkpoint(checkpoint)
    generator, meta = load_checkpoint_generator(path)
    test_metrics = evaluation_metrics(*metrics) if metrics is not None else None
    summary = training_summary(run_dir, path, hardware, test_metrics)
    model_id = model_id or meta["model_id"]
    out.parent.mkdir(parents=True, exist_ok=True)
    save_weights(out, generator, target=meta["target"], config=meta["config"], model_id=model_id,
                 extra=summary, half=half)  # fmt: skip
    card = {"model_id": model_id, "class": meta["target"], "config": meta["config"], **summary}
    write_text_atomic(out.with_suffix(".json"), json.dumps(card, indent=2) + "\n")
    return out


def evaluation_metrics(path: Path, model: str | None = None) -> dict[str, float]:
    """One model's results from an ``evaluate.py`` ``metrics.json`` (``None``: its only model)."""
    try:
        results = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise WeightsError(f"{path}: cannot read evaluation metrics ({error})") from None
    if model is None and isinstance(results, dict) and len(results) == 1:
        model = next(iter(results))
    if model is None:
        raise WeightsError(f"{path}: holds several models; name one with --metrics-model")
    if not isinstance(results, dict) or not isinstance(results.get(model), dict):
        names = ", ".join(results) if isinstance(results, dict) else "none"
        raise WeightsError(f"{path}: no model {model!r} in these metrics (models: {names})")
    return results[model]
