"""Scanned sets as a share of a generated dataset's materials, split by set."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from brdfgan.data.generation.generation import run_generation
from brdfgan.data.materials.augment import CropSampling
from brdfgan.data.materials.recolor import RecolorConfig
from brdfgan.data.materials.source import ScanSampling
from brdfgan.data.spec.dataset_spec import DatasetSpec, scan_materials, split_materials, split_scan_sets
from brdfgan.data.storage.shards import iter_shard, list_shards
from brdfgan.data.storage.spec_checks import DatasetConfigError
from tests.conftest import random_maps
from tests.data.generation.test_generation import tiny_spec, torch_photographer
from tests.data.spec.test_ood import _write_scanned_set


@pytest.fixture
def scan_root(tmp_path: Path) -> Path:
    root = tmp_path / "scans"
    for index in range(6):
        _write_scanned_set(
            root / f"set{index}", random_maps(48, 48, seed=10 + index), metallic=index % 2 == 0
        )
    return root


def _scans(root: Path, **change: object) -> ScanSampling:
    base: dict[str, object] = {"folder": str(root), "fraction": 0.5, "val_sets": 1, "test_sets": 1,
                               "resolution": 48}  # fmt: skip
    return ScanSampling(**{**base, **change})  # type: ignore[arg-type]


def test_scan_sets_are_split_by_set_and_each_split_paints_only_its_own(scan_root: Path) -> None:
    spec = tiny_spec(materials=40, scans=_scans(scan_root))
    sets = split_scan_sets(spec)
    assert sorted(sets["train"] + sets["val"] + sets["test"]) == list(range(6))
    assert len(sets["val"]) == 1 and len(sets["test"]) == 1
    chosen = scan_materials(spec)
    assert 10 < len(chosen) < 30  # about half of 40
    for split, indices in split_materials(spec).items():
        used = {chosen[i] for i in indices if i in chosen}
        assert used <= set(sets[split])
    # Every training set is used (in turn), and the choice is a pure function of the spec.
    train_used = [chosen[i] for i in split_materials(spec)["train"] if i in chosen]
    assert set(train_used) == set(sets["train"])
    assert scan_materials(dataclasses.replace(spec)) == chosen
    # More scans only turn procedural indices into scans: the others stay.
    more = scan_materials(tiny_spec(materials=40, scans=_scans(scan_root, fraction=0.8)))
    assert set(chosen) <= set(more)


def test_a_dataset_with_scans_mixed_in_has_scan_photos_of_the_right_split(
    scan_root: Path, tmp_path: Path
) -> None:
    spec = tiny_spec(
        materials=8, scans=_scans(scan_root, fraction=0.6, recolor_probability=0.5),
        recolor=RecolorConfig(probability=0.0),
    )  # fmt: skip
    run_generation(spec, tmp_path / "data", progress=False, photographer=torch_photographer)
    names = sorted(p.name for p in scan_root.iterdir())
    sets = split_scan_sets(spec)
    scanned = 0
    for split in ("train", "val", "test"):
        for shard in list_shards(tmp_path / "data", split):
            for sample in iter_shard(shard):
                family = sample.meta["family"]
                if not family.startswith("scanned/"):
                    assert "mirror" not in sample.meta["crop"]  # procedural crops as before
                    continue
                scanned += 1
                assert names.index(family.removeprefix("scanned/")) in sets[split]
                crop = sample.meta["crop"]
                assert 0.25 <= crop["scale"] <= 0.5  # the scan's crop sampling, not the spec's
    assert scanned > 0
    recorded = (tmp_path / "data" / "dataset.json").read_text()
    assert '"scans"' in recorded and '"fraction": 0.6' in recorded


def test_a_spec_without_scans_keeps_its_identity(scan_root: Path) -> None:
    plain = tiny_spec().to_json()
    assert "scans" not in plain and "mirror" not in plain["crop"] and "inside" not in plain["crop"]
    assert tiny_spec(scans=ScanSampling(folder=str(scan_root), fraction=0.0)).to_json() == plain
    assert "mirror" in tiny_spec(crop=CropSampling(0.5, 1.0, mirror=True)).to_json()["crop"]


def test_scan_settings_are_checked(scan_root: Path, tmp_path: Path) -> None:
    with pytest.raises(
        DatasetConfigError, match=r"dataset_spec\.scans\.fraction=0\.3 needs dataset_spec\.scans\.folder"
    ):
        ScanSampling(fraction=0.3)
    with pytest.raises(DatasetConfigError, match=r"dataset_spec\.scans\.fraction"):
        ScanSampling(folder=str(scan_root), fraction=1.5)
    with pytest.raises(DatasetConfigError, match=r"6 validation and test sets leave none of the 6 sets"):
        tiny_spec(scans=_scans(scan_root, val_sets=3, test_sets=3))
    with pytest.raises(DatasetConfigError, match=r"dataset_spec\.scans\.folder='.*nowhere'"):
        tiny_spec(scans=_scans(tmp_path / "nowhere"))
    assert isinstance(tiny_spec(scans=_scans(scan_root)), DatasetSpec)


def test_held_out_sets_can_be_named(scan_root: Path) -> None:
    spec = tiny_spec(materials=20, scans=_scans(scan_root, val_sets=["set4"], test_sets=["set1", "set2"]))
    assert split_scan_sets(spec) == {"train": (0, 3, 5), "val": (4,), "test": (1, 2)}
    with pytest.raises(DatasetConfigError, match=r"dataset_spec\.scans\.test_sets: no set 'set9'"):
        tiny_spec(scans=_scans(scan_root, test_sets=["set9"]))
    with pytest.raises(DatasetConfigError, match=r"'set1' is both a validation and a test set"):
        _scans(scan_root, val_sets=["set1"], test_sets=["set1"])
    mixed = split_scan_sets(tiny_spec(scans=_scans(scan_root, val_sets=2, test_sets=["set0"])))
    assert mixed["test"] == (0,) and len(mixed["val"]) == 2 and 0 not in mixed["val"]


def test_a_contact_sheet_of_the_scans_alone(scan_root: Path, tmp_path: Path) -> None:
    from brdfgan.cli import main
    from brdfgan.data.tools.contact_sheet import pick_samples

    spec = tiny_spec(materials=16, scans=_scans(scan_root, fraction=0.5))
    run_generation(spec, tmp_path / "data", progress=False, photographer=torch_photographer)
    scans = pick_samples(tmp_path / "data", "train", rows=100, family="scanned/")
    everything = pick_samples(tmp_path / "data", "train", rows=100)
    assert scans and all(s.meta["family"].startswith("scanned/") for s in scans)
    assert len(scans) < len(everything)
    sheet = tmp_path / "scans.png"
    assert main(["contact-sheet", str(tmp_path / "data"), "--family", "scanned/", "--out", str(sheet)]) == 0
    assert sheet.is_file()
    assert main(["contact-sheet", str(tmp_path / "data"), "--family", "nothing/", "--out", str(sheet)]) == 2
