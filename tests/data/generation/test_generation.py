"""Dataset generation: split before augmentation, determinism, resume, manifests, the CLI."""

from __future__ import annotations

import hashlib
import json
import logging
import re
import shutil
import tarfile
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from brdfgan.core.exposure import auto_expose
from brdfgan.core.render import FlashCapture, render_flash
from brdfgan.data.generation.generation import (
    MitsubaPhotographer,
    PhotographFn,
    dataset_ready,
    ensure_dataset,
    plan_shards,
    run_generation,
)
from brdfgan.data.materials.augment import CropSampling
from brdfgan.data.phone.conditions import CaptureDraw
from brdfgan.data.phone.environments import LightingConfig, LightingDraw, LightingError
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.spec.dataset_spec import SPLITS, DatasetSpec, split_materials
from brdfgan.data.storage.shards import (
    Sample,
    digest_path,
    iter_shard,
    list_shards,
    read_digest,
    read_manifest,
    shard_path,
    verify_shard,
    write_manifest,
)
from brdfgan.data.storage.spec_checks import DatasetConfigError
from brdfgan.io.images import write_image
from tests.conftest import run_python


def tiny_spec(**change: object) -> DatasetSpec:
    base: dict[str, object] = {
        "materials": 6,
        "material_resolution": 64,
        "resolution": 32,
        "crops_per_material": 2,
        "train_renders": 2,
        "eval_renders": 1,
        "test_fraction": 0.34,
        "val_fraction": 0.17,
        "materials_per_shard": 2,
        "spp": 4,
        "crop": CropSampling(0.5, 1.0),
        "lighting": LightingConfig(train_count=3, test_count=2, resolution=8),
    }
    return DatasetSpec(**{**base, **change})  # type: ignore[arg-type]


class TorchPhotographer:
    """A fast stand-in for Mitsuba with the same contract: flash-only torch render + exposure
    (of the drawn field of view and exposure error; it ignores tilt, distance and flash offset).
    Counts calls, and can fail after ``fail_after`` photos to simulate a crash."""

    def __init__(self, spec: DatasetSpec, fail_after: int | None = None) -> None:
        self.calls = 0
        self.fail_after = fail_after

    def __call__(
        self,
        maps: torch.Tensor,
        lighting: LightingDraw,
        intensity: float,
        temperature: float,
        draw: CaptureDraw,
        seed: int,
    ) -> tuple[torch.Tensor, float]:
        if self.fail_after is not None and self.calls >= self.fail_after:
            raise RuntimeError("simulated crash")
        self.calls += 1
        capture = FlashCapture(draw.fov_deg, intensity, blackbody_rgb(temperature))
        ldr, scale = auto_expose(render_flash(maps[None], capture)[0], draw.exposure_ev)
        return ldr, float(scale)


def torch_photographer(spec: DatasetSpec) -> PhotographFn:
    return TorchPhotographer(spec)


def shard_hashes(root: Path) -> dict[str, str]:
    return {
        f"{p.parent.name}/{p.name}": hashlib.sha256(p.read_bytes()).hexdigest()
        for split in SPLITS
        for p in list_shards(root, split)
    }


def all_metas(root: Path) -> dict[str, list[Mapping[str, Any]]]:
    return {split: [s.meta for p in list_shards(root, split) for s in iter_shard(p)] for split in SPLITS}


def test_materials_are_split_before_augmentation() -> None:
    spec = tiny_spec(materials=50, test_fraction=0.2, val_fraction=0.1)
    splits = split_materials(spec)
    assert [len(splits[s]) for s in ("train", "val", "test")] == [35, 5, 10]
    assert sorted(m for ms in splits.values() for m in ms) == list(range(50))
    assert split_materials(spec) == splits  # seeded
    assert split_materials(tiny_spec(materials=50, test_fraction=0.2, val_fraction=0.1, seed=1)) != splits


def test_generated_splits_share_no_material_and_keep_all_crops_together(tmp_path: Path) -> None:
    spec = tiny_spec()
    summary = run_generation(spec, tmp_path, progress=False, photographer=torch_photographer)
    assert len(summary.written) == len(plan_shards(spec)) and not summary.skipped
    metas = all_metas(tmp_path)
    seeds = {split: {m["material_seed"] for m in metas[split]} for split in SPLITS}
    assert seeds["train"] and seeds["val"] and seeds["test"]
    assert not (seeds["train"] & seeds["test"]) and not (seeds["train"] & seeds["val"])
    assert not (seeds["val"] & seeds["test"])
    for split in SPLITS:
        per_material = Counter(m["material_index"] for m in metas[split])
        expected = spec.crops_per_material * spec.renders_per_crop(split)
        assert set(per_material.values()) == {expected}, split
        manifest = read_manifest(tmp_path, split)
        assert manifest["samples"] == len(metas[split])
        assert sorted(manifest["material_indices"]) == sorted(per_material)
        assert manifest["spec"] == spec.to_json() and "git_commit" in manifest["code_version"]
    # The test split sees only test environments, training and validation only training ones.
    env = {split: {m["lighting"]["environment"]["env_id"] for m in metas[split]} for split in SPLITS}
    assert not (env["test"] & (env["train"] | env["val"]))


def test_same_spec_same_bytes_other_seed_other_bytes(tmp_path: Path) -> None:
    spec = tiny_spec(materials=3, test_fraction=0.34, val_fraction=0.0)
    run_generation(spec, tmp_path / "a", progress=False, photographer=torch_photographer)
    run_generation(spec, tmp_path / "b", progress=False, photographer=torch_photographer)
    run_generation(tiny_spec(materials=3, val_fraction=0.0, seed=7), tmp_path / "c", progress=False,
                   photographer=torch_photographer)  # fmt: skip
    a, b, c = (shard_hashes(tmp_path / n) for n in "abc")
    assert a and a == b
    assert a != c


def test_shards_can_be_made_separately_and_in_any_order(tmp_path: Path) -> None:
    spec = tiny_spec()
    jobs = plan_shards(spec)
    run_generation(spec, tmp_path / "whole", progress=False, photographer=torch_photographer)
    for position in reversed(range(len(jobs))):  # as separate processes/machines would
        run_generation(
            spec, tmp_path / "parts", shards=position, progress=False, photographer=torch_photographer
        )
    assert shard_hashes(tmp_path / "whole") == shard_hashes(tmp_path / "parts")
    assert dataset_ready(spec, tmp_path / "parts")


def test_resume_after_a_crash_finishes_without_duplicates(tmp_path: Path) -> None:
    spec = tiny_spec()
    run_generation(spec, tmp_path / "clean", progress=False, photographer=torch_photographer)

    crashed = TorchPhotographer(spec, fail_after=9)  # 8 samples in shard 0, dies inside shard 1
    with pytest.raises(RuntimeError, match="simulated crash"):
        run_generation(spec, tmp_path / "run", progress=False, photographer=lambda _: crashed)
    # What a SIGKILL would leave besides: a stale temp file and a truncated shard.
    stale = shard_path(tmp_path / "run", "test", 0).with_name(".test-000000.tar.0123456789ab.tmp")
    stale.write_bytes(b"partial")
    truncated = shard_path(tmp_path / "run", "val", 0)
    truncated.write_bytes(shard_path(tmp_path / "clean", "val", 0).read_bytes()[:3000])
    assert len(list_shards(tmp_path / "run", "train")) == 1 and not dataset_ready(spec, tmp_path / "run")

    counting = TorchPhotographer(spec)
    summary = run_generation(spec, tmp_path / "run", progress=False, photographer=lambda _: counting)
    assert len(summary.skipped) == 1  # the shard finished before the crash is not redone
    assert counting.calls == sum(j.sample_count(spec) for j in plan_shards(spec)[1:])
    assert shard_hashes(tmp_path / "run") == shard_hashes(tmp_path / "clean")
    assert not list((tmp_path / "run").rglob("*.tmp"))
    keys = [s.key for split in SPLITS for p in list_shards(tmp_path / "run", split) for s in iter_shard(p)]
    assert len(keys) == len(set(keys))
    assert dataset_ready(spec, tmp_path / "run")
    # A third run has nothing to do.
    again = run_generation(spec, tmp_path / "run", progress=False, photographer=torch_photographer)
    assert not again.written and len(again.skipped) == len(plan_shards(spec))


def corrupt_png_in_place(shard: Path) -> str:
    """Flip bytes inside the first photo's PNG data; the tar headers stay intact. Returns the member."""
    with tarfile.open(shard) as tar:
        member = next(info for info in tar if info.name.endswith(".input.png"))
    with shard.open("r+b") as handle:
        handle.seek(member.offset_data + member.size // 2)
        chunk = handle.read(16)
        handle.seek(member.offset_data + member.size // 2)
        handle.write(bytes(b ^ 0xFF for b in chunk))
    return member.name


@pytest.fixture(scope="module")
def made_once(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The dataset of ``tiny_spec()``, generated once; tests that damage it work on a copy."""
    root = tmp_path_factory.mktemp("made_once")
    run_generation(tiny_spec(), root, progress=False, photographer=torch_photographer)
    return root


def test_manifest_and_records_hold_the_sha256_of_every_shard(made_once: Path) -> None:
    tmp_path = made_once
    for split in SPLITS:
        entries = read_manifest(tmp_path, split)["shards"]
        assert [e["name"] for e in entries] == [p.name for p in list_shards(tmp_path, split)]
        for entry in entries:
            shard = tmp_path / split / entry["name"]
            assert entry["sha256"] == hashlib.sha256(shard.read_bytes()).hexdigest()
            assert read_digest(shard) == entry["sha256"]


@pytest.mark.parametrize("record", ["manifest and beside the shard", "manifest only", "beside the shard"])
def test_a_png_corrupted_in_place_is_found_rewritten_and_reported(
    made_once: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture, record: str
) -> None:
    spec = tiny_spec()
    shutil.copytree(made_once, tmp_path, dirs_exist_ok=True)
    clean = shard_hashes(tmp_path)
    shard = shard_path(tmp_path, "train", 1)
    corrupt_png_in_place(shard)
    assert verify_shard(shard) == plan_shards(spec)[1].sample_count(spec)  # the headers cannot tell
    if record == "manifest only":
        digest_path(shard).unlink()
    elif record == "beside the shard":
        (tmp_path / "train" / "manifest.json").unlink()

    counting = TorchPhotographer(spec)
    with caplog.at_level(logging.WARNING, logger="brdfgan.data.generation.generation"):
        summary = run_generation(spec, tmp_path, progress=False, photographer=lambda _: counting)
    assert summary.repaired == [shard] and summary.written == [shard]
    assert counting.calls == plan_shards(spec)[1].sample_count(spec)  # only that shard is redone
    assert any(str(shard) in r.getMessage() and "SHA-256" in r.getMessage() for r in caplog.records)
    assert f"rewrote damaged: {shard.name}" in summary.describe()
    assert shard_hashes(tmp_path) == clean  # seeded: the rewrite is the original, byte for byte
    assert read_digest(shard) == clean[f"train/{shard.name}"]
    assert dataset_ready(spec, tmp_path)


def test_a_dataset_made_before_digests_were_recorded_is_kept_and_protected_from_then_on(
    made_once: Path, tmp_path: Path
) -> None:
    spec = tiny_spec()
    shutil.copytree(made_once, tmp_path, dirs_exist_ok=True)
    clean = shard_hashes(tmp_path)
    for split in SPLITS:  # the layout of older versions: no records, manifests without sha256
        manifest = read_manifest(tmp_path, split)
        manifest["shards"] = [{k: v for k, v in e.items() if k != "sha256"} for e in manifest["shards"]]
        write_manifest(tmp_path, split, manifest)
        for shard in list_shards(tmp_path, split):
            digest_path(shard).unlink()

    counting = TorchPhotographer(spec)
    summary = run_generation(spec, tmp_path, progress=False, photographer=lambda _: counting)
    assert counting.calls == 0 and not summary.repaired  # complete shards are trusted once...
    assert read_manifest(tmp_path, "train")["shards"][0]["sha256"] == clean["train/train-000000.tar"]
    corrupt_png_in_place(shard_path(tmp_path, "val", 0))  # ... and checked from then on
    summary = run_generation(spec, tmp_path, progress=False, photographer=torch_photographer)
    assert summary.repaired == [shard_path(tmp_path, "val", 0)]
    assert shard_hashes(tmp_path) == clean


def test_a_corrupt_environment_file_fails_before_anything_is_written(tmp_path: Path) -> None:
    envs = tmp_path / "envs"
    envs.mkdir()
    for k in range(2):
        write_image(envs / f"good{k}.exr", np.full((8, 16, 3), 0.5, np.float32), exr_precision="float")
    good = (envs / "good0.exr").read_bytes()
    (envs / "bad.exr").write_bytes(good[: len(good) // 2])  # cut short, as by an interrupted copy
    spec = tiny_spec(lighting=LightingConfig(train_count=1, test_count=1, folder=str(envs), resolution=8))
    with pytest.raises(LightingError, match=re.escape(str(envs / "bad.exr"))):
        run_generation(spec, tmp_path / "out", progress=False, photographer=torch_photographer)
    assert not (tmp_path / "out").exists()


def test_a_directory_of_another_spec_is_refused(tmp_path: Path) -> None:
    run_generation(tiny_spec(materials=3, val_fraction=0.0), tmp_path, progress=False,
                   photographer=torch_photographer)  # fmt: skip
    with pytest.raises(DatasetConfigError, match=r"different config \(dataset_spec.spp differs\)"):
        run_generation(tiny_spec(materials=3, val_fraction=0.0, spp=9), tmp_path, progress=False,
                       photographer=torch_photographer)  # fmt: skip


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"materials": 0}, "dataset_spec.materials=0: must be an integer >= 1"),
        ({"spp": 10}, "dataset_spec.spp=10: must be a perfect square"),
        ({"resolution": 128}, "dataset_spec.resolution=128 > dataset_spec.material_resolution=64"),
        ({"test_fraction": 1.5}, r"dataset_spec.test_fraction=1.5: must be in \[0, 1\)"),
        (
            {"test_fraction": 0.5, "val_fraction": 0.5},
            r"dataset_spec.test_fraction=0.5 \+ dataset_spec.val_fraction",
        ),
        ({"spp": "abc"}, "dataset_spec.spp='abc': must be an integer"),
        ({"families": ("wood_planks", "woood")}, "unknown material family 'woood'"),
        ({"materials": 2, "test_fraction": 0.5, "val_fraction": 0.4}, "leaves no training material"),
    ],
)
def test_bad_specs_fail_on_construction_naming_the_key(change: dict[str, object], message: str) -> None:
    # At construction, i.e. when generate.py composes its config: before dataset.json exists.
    with pytest.raises(ValueError, match=message):
        tiny_spec(**change)


def test_unwritable_output_is_a_clear_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(DatasetConfigError, match="exists and is not a directory"):
        run_generation(tiny_spec(), blocker, progress=False, photographer=torch_photographer)
    with pytest.raises(DatasetConfigError, match="not writable"):
        run_generation(tiny_spec(), blocker / "sub", progress=False, photographer=torch_photographer)


@pytest.mark.integration
@pytest.mark.mitsuba
def test_end_to_end_mitsuba_generation_feeds_the_datamodule(tmp_path: Path) -> None:
    from brdfgan.data.loading.datamodule import ShardDataModule

    spec = tiny_spec(materials=3, crops_per_material=1, val_fraction=0.0, materials_per_shard=1)
    data_dir = tmp_path / "data"

    def prepare() -> None:
        ensure_dataset(spec, data_dir, progress=False)

    module = ShardDataModule(str(data_dir), batch_size=2, prepare=prepare)
    module.prepare_data()
    module.setup("fit")
    batch = next(iter(module.train_dataloader()))
    assert batch["photo"].shape == (2, 3, 32, 32) and batch["maps"].shape == (2, 8, 32, 32)
    photo = batch["photo"]
    assert photo.min() >= 0.0 and photo.max() <= 1.0 and photo.mean() > 0.01  # exposed, not black
    meta = all_metas(data_dir)["train"][0]
    assert meta["render"]["spp"] == 4 and meta["exposure_scale"] > 0
    assert {"intensity_w_sr", "temperature_k"} <= set(meta["flash"])
    # The real photographer is what made these: Mitsuba, environment + flash.
    assert isinstance(MitsubaPhotographer(spec).renderer.variant, str)


@pytest.mark.integration
@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("dataset_spec.families=[woood]", "unknown material family 'woood'"),
        ("dataset_spec.materials=-1", "dataset_spec.materials=-1: must be an integer >= 1"),
        ("dataset_spec.flash.intensity_min=-3", "error: dataset_spec.flash.intensity_min=-3: must be > 0"),
        ("dataset_spec.lighting.folder=EMPTY", "EMPTY: no .exr or .hdr environment maps"),
        ("dataset_spec.no_such_key=1", "no_such_key"),
    ],
)
def test_cli_bad_input_is_one_line_and_writes_nothing(tmp_path: Path, override: str, message: str) -> None:
    empty = tmp_path / "empty_envs"
    empty.mkdir()
    override = override.replace("EMPTY", str(empty))
    message = message.replace("EMPTY", str(empty))
    prefix = "+" if "no_such_key" in override else ""
    result = run_python(
        "generate.py",
        "dataset_spec=tiny",
        "progress=false",
        f"out_dir={tmp_path / 'out'}",
        *(prefix + o for o in override.split()),
        cwd=tmp_path,
    )
    assert result.returncode != 0
    errors = [line for line in result.stderr.splitlines() if line.strip()]
    assert any(message in line for line in errors), result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.integration
def test_cli_plan_lists_every_shard(tmp_path: Path) -> None:
    result = run_python("generate.py", "dataset_spec=tiny", "plan=true", "progress=false", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "shards; run them all with: python generate.py -m shard='range(0," in result.stdout
    assert json.dumps("train")[1:-1] in result.stdout


def test_contact_sheet_shows_every_panel_of_random_samples(tmp_path: Path) -> None:
    from brdfgan.cli import main
    from brdfgan.data.tools.contact_sheet import COLUMNS, pick_samples
    from brdfgan.figures import HEADER_HEIGHT
    from brdfgan.io.images import read_image

    spec = tiny_spec()
    run_generation(spec, tmp_path, progress=False, photographer=torch_photographer)
    picked = pick_samples(tmp_path, "train", rows=3, seed=0)
    assert len(picked) == 3 and len({s.key for s in picked}) == 3
    assert [s.key for s in pick_samples(tmp_path, "train", rows=3, seed=0)] == [s.key for s in picked]
    assert main(["contact-sheet", str(tmp_path), "--rows", "3", "--out", str(tmp_path / "sheet.png")]) == 0
    sheet = read_image(tmp_path / "sheet.png")
    assert sheet.shape[1] == len(COLUMNS) * spec.resolution
    assert sheet.shape[0] > 3 * spec.resolution  # rows plus the header
    row = sheet[-spec.resolution :]
    normal_panel = row[:, 2 * spec.resolution : 3 * spec.resolution]
    assert abs(normal_panel[..., 2].mean() - 1.0) < 0.1  # (n+1)/2 of mostly +Z normals is blue
    # A small sheet: every panel area-resized, each row labelled with its family on the input.
    assert (
        main(
            ["contact-sheet", str(tmp_path), "--rows", "3", "--tile", "16", "--out", str(tmp_path / "s.png")]
        )
        == 0
    )
    small = read_image(tmp_path / "s.png")
    assert small.shape[:2] == (HEADER_HEIGHT + 3 * 16, len(COLUMNS) * 16)
    assert main(["contact-sheet", str(tmp_path), "--tile", "4"]) == 2
    from brdfgan.data.tools.contact_sheet import row_label

    mixed = Sample(
        picked[0].key,
        picked[0].photo,
        picked[0].maps,
        {**picked[0].meta, "mix": {"partner_family": "marble"}, "recolor": {}},
    )
    assert row_label(mixed) == f"{picked[0].meta['family']} + marble (recol.)"
