"""What a model reads of relief, material by material: the per-material table of
research/notes/2026-12-v5-candidate.md ("What the network reads of relief").

    python -m research.relief_by_material data/procedural_and_scans_test_scans \
        v4=logs/v5/v4.safetensors height=logs/v5/ablation/rendered_height/checkpoints/last.ckpt

Each sample of the folder's ``test`` split (Mitsuba photos through the evaluation sensor, as
``evaluate.py data=procedural_and_scans data.data_dir=FOLDER`` reads them), grouped by its
material's family (a scan set's name for scans): the flat map's angle, each model's normal angle
and the cosine of its slopes with the true ones, pooled over the group's texels (+1: the relief
the right way round, −1: inside out, 0: unrelated), and the RMS of its slopes over the truth's
(the evaluator's :class:`~brdfgan.metrics.SlopeAgreement`, per material).
Markdown on stdout.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import hydra
import torch
from hydra import compose, initialize_config_dir

from brdfgan.core.svbrdf import flat_maps
from brdfgan.evaluation.config import register_configs
from brdfgan.metrics.svbrdf_metrics import NormalAngularError, SlopeAgreement
from brdfgan.runs import load_generator

CONF = Path(__file__).resolve().parents[1] / "conf"
FLAT = "flat map"


def material_rows(
    folder: Path, models: dict[str, torch.nn.Module]
) -> dict[str, dict[str, tuple[float, ...]]]:
    """Per family: per model (and the flat map) its angle, slope cosine, RMS ratio and sample count."""
    register_configs()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            config_name="evaluate",
            overrides=[
                "data=procedural_and_scans",
                f"data.data_dir={folder}",
                "data.prepare=null",
                "ckpt=none",
            ],
        )
    datamodule = hydra.utils.instantiate(cfg.data, _convert_="all")
    datamodule.splits["test"] = "test"
    datamodule.setup("test")
    angles: dict[tuple[str, str], NormalAngularError] = defaultdict(NormalAngularError)
    slopes: dict[tuple[str, str], SlopeAgreement] = defaultdict(SlopeAgreement)
    counts: dict[str, int] = defaultdict(int)
    with torch.no_grad():
        for batch in datamodule.test_dataloader():
            truth = batch["maps"]
            predictions = {name: model(batch["photo"], batch.get("flash")) for name, model in models.items()}
            predictions[FLAT] = flat_maps(truth.shape[-2], truth.shape[-1], batch=(truth.shape[0],))
            for i, meta in enumerate(batch["meta"]):
                family = str(meta["family"]).removeprefix("scanned/")
                counts[family] += 1
                for name, pred in predictions.items():
                    angles[family, name].update(pred[i : i + 1], truth[i : i + 1])
                    slopes[family, name].update(pred[i : i + 1], truth[i : i + 1])
    rows: dict[str, dict[str, tuple[float, ...]]] = {}
    for family in sorted(counts):
        rows[family] = {}
        for name in [FLAT, *models]:
            agreement = slopes[family, name].compute()
            rows[family][name] = (
                float(angles[family, name].compute()),
                float(agreement["normal_slope_cosine"]),
                float(agreement["normal_slope_ratio"]),
                counts[family],
            )
    return rows


def markdown(rows: dict[str, dict[str, tuple[float, ...]]]) -> str:
    names = [name for name in next(iter(rows.values())) if name != FLAT]
    header = "| material | photos | flat map ° | " + " | ".join(
        f"{name}: ° (/ flat), cosine, RMS ratio" for name in names
    )
    lines = [header + " |", "|---|---|---|" + "---|" * len(names)]
    for family, values in rows.items():
        flat = values[FLAT][0]
        cells = [f"{a:.3f} ({a / flat:.2f}), {c:+.2f}, {r:.2f}" for a, c, r, _ in (values[n] for n in names)]
        lines.append(f"| {family} | {values[FLAT][3]} | {flat:.3f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("folder", type=Path, help="a dataset folder with a test split (e.g. a source subset)")
    parser.add_argument("models", nargs="+", help="NAME=PATH of a checkpoint or weights file")
    args = parser.parse_args(argv)
    models = {}
    for item in args.models:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            parser.error(f"{item!r}: expected NAME=PATH")
        models[name] = load_generator(path)[0].eval()
    print(markdown(material_rows(args.folder, models)))


if __name__ == "__main__":
    main()
