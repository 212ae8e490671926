"""Distribution statistics of map sets (brdfgan.data.tools.statistics, `brdfgan dataset-stats`)."""

from __future__ import annotations

import math
from functools import partial
from pathlib import Path

import pytest
import torch

from brdfgan.cli import main
from brdfgan.data.generation.generation import run_generation
from brdfgan.data.materials.source import ScanSampling
from brdfgan.data.phone.conditions import CaptureSampling
from brdfgan.data.storage.shards import Sample, shard_path, write_shard
from brdfgan.data.tools.statistics import (
    CAPTURE_QUANTITIES,
    MapStatistics,
    dataset_report,
    dataset_statistics,
    meta_number,
    percentiles,
    split_statistics,
    statistics_table,
)
from brdfgan.errors import UserError
from tests.conftest import random_maps, tilted_plane
from tests.data.generation.test_generation import tiny_spec, torch_photographer
from tests.data.spec.test_ood import _write_scanned_set

# Uniform 16² planes of roughness 0.4 whose normals all lean 30° from +Z, in a given colour.
_plane = partial(
    tilted_plane, 16, (math.sin(math.radians(30.0)), 0.0, math.cos(math.radians(30.0))), roughness=0.4
)


def test_golden_figures_of_known_maps() -> None:
    stats = MapStatistics("toy")
    stats.add(_plane(basecolor=(0.8, 0.1, 0.1)), "red")  # saturated red dielectric
    stats.add(_plane(basecolor=(0.5, 0.5, 0.5), metallic=1.0), "grey", mixed=True)  # grey metal
    row = stats.row()
    assert row["samples"] == 2 and row["metallic_share"] == pytest.approx(0.5)
    assert row["coloured_share"] == pytest.approx(0.5)
    assert row["hue_evenness"] == pytest.approx(0.0)  # every coloured texel is red
    assert row["roughness_p50"] == pytest.approx(0.4)
    assert row["relief_deg"] == pytest.approx(30.0, abs=1e-3)
    stats.add(_plane(basecolor=(0.1, 0.8, 0.1)), "green")
    stats.add(_plane(basecolor=(0.1, 0.1, 0.8)), "blue")
    # Three of six hue sectors equally full: entropy log 3 / log 6.
    assert stats.row()["hue_evenness"] == pytest.approx(math.log(3) / math.log(6), abs=1e-6)
    table = statistics_table([stats])
    assert (
        "| toy | 4 | 25.0% |" in table and "green 1, grey 1, red 1" in table and "mixed materials: 1" in table
    )


@pytest.mark.integration
def test_dataset_statistics_and_cli(tiny_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tiny_data / "data" / "tiny"
    stats = dataset_statistics(data, "train")
    assert stats.samples > 0 and sum(stats.families.values()) == stats.samples
    assert main(["dataset-stats", str(data)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("| data | samples | metallic |") and f"| tiny/train | {stats.samples} |" in out
    assert main(["dataset-stats", str(data / "nowhere")]) == 2
    assert "no train shards" in capsys.readouterr().err


# ----------------------------------------------------------------------------- scans and captures

FOVS = [20.0 + 5.0 * i for i in range(11)]  # 20, 25, …, 70: p10 25, p50 45, p90 65 (linear)


def _meta(index: int, family: str, **extra: object) -> dict[str, object]:
    return {
        "family": family,
        "capture": {"fov_deg": FOVS[index], "flash_offset": 0.01 * index, "tilt_deg": 0.5 * index,
                    "exposure_ev": -1.0 + 0.2 * index},
        "flash": {"intensity_w_sr": 1.0, "temperature_k": 4000.0 + 100.0 * index},
        "crop": {"index": 0, "center": [0.5, 0.5], "scale": 0.25, "angle": 0.0},
        **extra,
    }  # fmt: skip


def _sample(key: str, maps: torch.Tensor, meta: dict[str, object]) -> Sample:
    return Sample(key, torch.full((3, *maps.shape[1:]), 0.5), maps, meta)


@pytest.fixture
def mixed_dataset(tmp_path: Path) -> Path:
    """``mixed/train``: 8 procedural red dielectrics (fov 20–55°; two mirrored, one recoloured, one
    mixed) and 3 scans of grey metal from 2 sets (fov 60–70°), over two shards; ``mixed/val``: 2
    samples whose meta predates the capture, flash and crop records."""
    root = tmp_path / "mixed"
    samples = []
    for i in range(11):
        if i < 8:
            extra: dict[str, object] = {"recolor": {"hue_shift": 0.1}} if i == 3 else {}
            extra |= {"mix": {"partner_index": 0}} if i == 4 else {}
            meta = _meta(i, "bricks" if i % 2 else "wood", **extra)
            if i < 2:
                meta["crop"] = {**meta["crop"], "mirror": True}  # type: ignore[dict-item]
            samples.append(_sample(f"train-m{i}", _plane(basecolor=(0.8, 0.1, 0.1)), meta))
        else:
            family = "scanned/SetA" if i < 10 else "scanned/SetB"
            samples.append(
                _sample(f"train-m{i}", _plane(basecolor=(0.5, 0.5, 0.5), metallic=1.0), _meta(i, family))
            )
    write_shard(shard_path(root, "train", 0), samples[:5])
    write_shard(shard_path(root, "train", 1), samples[5:])
    old = [_sample(f"val-m{i}", _plane(basecolor=(0.1, 0.8, 0.1)), {"family": "bricks"}) for i in range(2)]
    write_shard(shard_path(root, "val", 0), old)
    return root


def _table(text: str, header: str) -> dict[str, list[str]]:
    """The rows of the markdown table whose header starts with ``| header |``: name → cells."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"| {header} |"))
    rows: dict[str, list[str]] = {}
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        name, *cells = [cell.strip() for cell in line.strip("|").split("|")]
        rows[name] = cells
    return rows


def test_percentiles_and_meta_numbers() -> None:
    assert percentiles(FOVS) == pytest.approx((20.0, 25.0, 45.0, 65.0, 70.0))
    assert percentiles([]) is None and percentiles([3.0]) == pytest.approx((3.0,) * 5)
    meta = {"capture": {"fov_deg": 50, "flag": True, "name": "x"}}
    assert meta_number(meta, ("capture", "fov_deg")) == 50.0
    assert meta_number(meta, ("capture", "tilt_deg")) is None
    assert meta_number(meta, ("flash", "temperature_k")) is None
    assert meta_number(meta, ("capture", "flag")) is None and meta_number(meta, ("capture", "name")) is None


def test_a_split_is_summarised_by_part_and_its_captures(mixed_dataset: Path) -> None:
    stats = split_statistics(mixed_dataset, "train")
    assert stats.mixes_scans and [s.name for s in stats.map_rows()] == [
        "mixed/train", "mixed/train (procedural)", "mixed/train (scans)",
    ]  # fmt: skip
    assert stats.maps["procedural"].samples == 8 and stats.maps["scans"].samples == 3
    whole = stats.whole
    assert whole.samples == 11 and whole.scanned_sets == 2 and whole.mixed == 1
    assert whole.row()["metallic_share"] == pytest.approx(3 / 11)
    assert stats.maps["scans"].row()["metallic_share"] == pytest.approx(1.0)
    assert stats.maps["procedural"].row()["metallic_share"] == pytest.approx(0.0)
    assert dataset_statistics(mixed_dataset, "train").samples == 11  # the old entry point: the whole

    captures = {c.name: c.row() for c in stats.capture_rows()}
    train = captures["mixed/train"]
    assert train["samples"] == 11 and train["fov_deg"] == pytest.approx((20.0, 25.0, 45.0, 65.0, 70.0))
    # Eight procedural (20–55°) and three scans (60–70°), linearly interpolated.
    assert captures["mixed/train (procedural)"]["fov_deg"] == pytest.approx((20.0, 23.5, 37.5, 51.5, 55.0))
    assert captures["mixed/train (scans)"]["fov_deg"] == pytest.approx((60.0, 61.0, 65.0, 69.0, 70.0))
    assert train["temperature_k"][0] == pytest.approx(4000.0) and train["temperature_k"][-1] == pytest.approx(
        5000.0
    )
    assert train["crop_scale"] == pytest.approx((0.25,) * 5)
    assert train["mirrored"] == pytest.approx(2 / 11) and train["recoloured"] == pytest.approx(1 / 11)
    assert captures["mixed/train (procedural)"]["mixed"] == pytest.approx(1 / 8)
    assert captures["mixed/train (scans)"]["mixed"] == 0.0

    old = split_statistics(mixed_dataset, "val")
    assert not old.mixes_scans and [s.name for s in old.map_rows()] == ["mixed/val"]
    row = old.capture_rows()[0].row()
    assert row["fov_deg"] is None and row["crop_scale"] is None and row["mirrored"] is None
    assert row["recoloured"] == 0.0 and row["mixed"] == 0.0


def test_dataset_report_tables(mixed_dataset: Path) -> None:
    text = dataset_report(mixed_dataset, ["train", "val", "train"])  # a repeated split counts once
    maps = _table(text, "data")
    assert list(maps) == ["mixed/train", "mixed/train (procedural)", "mixed/train (scans)", "mixed/val"]
    assert [cells[0] for cells in maps.values()] == ["11", "8", "3", "2"]
    assert maps["mixed/train"][1] == "27.3%" and maps["mixed/train (scans)"][1] == "100.0%"
    # Families are listed for the whole split only, the scanned sets counted together.
    assert (
        "mixed/train samples per family: bricks 4, wood 4; scanned: 2 sets, 3 samples; mixed materials: 1"
        in text
    )
    assert "(procedural) samples per family" not in text and "mixed/val samples per family: bricks 2" in text

    captures = _table(text, "capture")
    header = next(line for line in text.splitlines() if line.startswith("| capture |"))
    assert header == (
        "| capture | samples | field of view ° | flash offset | tilt ° | exposure EV | flash K | crop scale "
        "| mirrored | recoloured | mixed |"
    )
    assert list(captures) == list(maps)
    train = captures["mixed/train"]
    assert train[0] == "11" and train[1] == "20.0 / 25.0 / 45.0 / 65.0 / 70.0"
    assert train[2] == "0.000 / 0.010 / 0.050 / 0.090 / 0.100" and train[4].startswith("-1.00 / ")
    assert (
        train[5] == "4000 / 4100 / 4500 / 4900 / 5000" and train[6] == "0.250 / 0.250 / 0.250 / 0.250 / 0.250"
    )
    assert train[7:] == ["18.2%", "9.1%", "9.1%"]
    assert captures["mixed/val"] == ["2", "–", "–", "–", "–", "–", "–", "–", "0.0%", "0.0%"]


def test_dataset_stats_cli_with_splits_scans_and_errors(
    mixed_dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scans = tmp_path / "ood"
    _write_scanned_set(scans / "a_stone", random_maps(32, 32, seed=1), metallic=False)
    _write_scanned_set(scans / "b_metal", random_maps(32, 32, seed=2), metallic=True)
    assert (
        main(["dataset-stats", str(mixed_dataset), "--split", "train", "val", "--scanned", str(scans)]) == 0
    )
    out = capsys.readouterr().out
    assert out.startswith("| data | samples | metallic |")
    assert list(_table(out, "data")) == [
        "mixed/train", "mixed/train (procedural)", "mixed/train (scans)", "mixed/val", "ood",
    ]  # fmt: skip
    assert "ood samples per family: scanned: 2 sets, 2 samples" in out
    assert list(_table(out, "capture")) == ["mixed/train", "mixed/train (procedural)", "mixed/train (scans)",
                                            "mixed/val"]  # fmt: skip
    assert main(["dataset-stats", str(mixed_dataset)]) == 0  # the default split alone
    assert list(_table(capsys.readouterr().out, "data"))[-1] == "mixed/train (scans)"

    # One-line errors, before anything is read.
    assert main(["dataset-stats", str(mixed_dataset), "--split", "train", "test"]) == 2
    err = capsys.readouterr().err
    assert (
        f"{mixed_dataset}: no test shards (shards found for: train, val)" in err
        and len(err.splitlines()) == 1
    )
    assert main(["dataset-stats", str(tmp_path / "missing")]) == 2
    assert f"{tmp_path / 'missing'}: no train shards (no such directory)" in capsys.readouterr().err
    assert main(["dataset-stats", str(mixed_dataset), "--scanned", str(tmp_path / "none")]) == 2
    assert str(tmp_path / "none") in capsys.readouterr().err
    with pytest.raises(UserError, match="no val shards"):
        dataset_report(tmp_path / "empty", ["val"])


def test_a_generated_dataset_with_scans_has_every_capture_record(tmp_path: Path) -> None:
    """The keys read are the ones generation writes: no "–" for a dataset made today."""
    scans = tmp_path / "scans"
    for index in range(4):
        _write_scanned_set(
            scans / f"set{index}", random_maps(48, 48, seed=10 + index), metallic=index % 2 == 0
        )
    spec = tiny_spec(
        materials=8,
        scans=ScanSampling(folder=str(scans), fraction=0.6, val_sets=1, test_sets=1, resolution=48),
        capture=CaptureSampling(fov_min_deg=20.0, fov_max_deg=75.0, flash_offset_min=0.01,
                                flash_offset_max=0.08, tilt_max_deg=3.0, exposure_ev_min=-1.5,
                                exposure_ev_max=1.0),
    )  # fmt: skip
    run_generation(spec, tmp_path / "data", progress=False, photographer=torch_photographer)
    stats = split_statistics(tmp_path / "data", "train")
    families = [f for s in stats.maps.values() for f in s.families]
    assert stats.whole.scanned_sets == len({f for f in families if f.startswith("scanned/")}) > 0
    for capture in stats.capture_rows():
        if not capture.samples:
            continue
        row = capture.row()
        assert all(row[key] is not None for key, *_ in CAPTURE_QUANTITIES), row
        assert 20.0 <= row["fov_deg"][0] <= row["fov_deg"][-1] <= 75.0
        assert 0.01 <= row["flash_offset"][0] <= row["flash_offset"][-1] <= 0.08
        assert -1.5 <= row["exposure_ev"][0] <= row["exposure_ev"][-1] <= 1.0
    text = dataset_report(tmp_path / "data", ["train", "val", "test"])
    assert "| data/train |" in text and "| data/test |" in text


def test_source_subsets_splits_a_split_into_its_scanned_and_procedural_photos(
    mixed_dataset: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from scripts import source_subsets

    from brdfgan.data.storage.shards import iter_shard, list_shards

    monkeypatch.setattr("sys.argv", ["source_subsets", str(mixed_dataset), "--split", "train"])
    source_subsets.main()
    original = {s.key: s for shard in list_shards(mixed_dataset, "train") for s in iter_shard(shard)}
    parts = {}
    for name in ("scans", "procedural"):
        folder = mixed_dataset.with_name(f"mixed_train_{name}")
        parts[name] = [s for shard in list_shards(folder, "test") for s in iter_shard(shard)]
        for sample in parts[name]:  # copied as they were
            assert (
                torch.equal(sample.maps, original[sample.key].maps)
                and sample.meta == original[sample.key].meta
            )
    assert len(parts["scans"]) == 3 and len(parts["procedural"]) == 8
    assert all(str(s.meta["family"]).startswith("scanned/") for s in parts["scans"])
    assert not any(str(s.meta["family"]).startswith("scanned/") for s in parts["procedural"])
    assert not list(mixed_dataset.parent.glob(".*partial"))  # no temporary folder left


def test_source_subsets_writes_a_dataset_with_a_chosen_share_of_scans(
    mixed_dataset: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from scripts import source_subsets

    from brdfgan.data.storage.shards import iter_shard, list_shards

    monkeypatch.setattr(
        "sys.argv", ["source_subsets", str(mixed_dataset), "--split", "train", "--scan-share", "0.6"]
    )
    source_subsets.main()
    out = mixed_dataset.with_name("mixed_scans60")
    train = [s for shard in list_shards(out, "train") for s in iter_shard(shard)]
    scanned = [s for s in train if str(s.meta["family"]).startswith("scanned/")]
    assert len(scanned) == 3 and len(train) == 5  # every scan, and 2 of the 8 procedural photos
    assert (out / "val").is_symlink() and (out / "val").resolve() == (mixed_dataset / "val").resolve()
    monkeypatch.setattr("sys.argv", ["source_subsets", str(mixed_dataset), "--scan-share", "1.5"])
    with pytest.raises(SystemExit, match=r"--scan-share 1\.5"):
        source_subsets.main()
