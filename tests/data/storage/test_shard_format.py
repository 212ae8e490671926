"""The u16z sample format beside PNG: the same 16-bit values, the documented bytes, old shards
still read, damage named, and the dataset_spec.shard_format key."""

from __future__ import annotations

import json
import logging
import shutil
import struct
import tarfile
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
import zstandard
from hydra import compose, initialize_config_dir

from brdfgan.core.svbrdf import encode_normal, split_maps
from brdfgan.data.generation.generation import SPEC_FILE, dataset_ready, run_generation
from brdfgan.data.loading.datamodule import ShardDataModule
from brdfgan.data.spec.dataset_spec import DatasetSpec, spec_from_config
from brdfgan.data.storage.shards import (
    FORMAT_MEMBERS,
    Sample,
    ShardError,
    decode_sample,
    encode_sample,
    iter_shard,
    read_manifest,
    shard_path,
    verify_shard,
    write_shard,
)
from brdfgan.data.storage.spec_checks import DatasetConfigError
from tests.conftest import CONF, random_maps
from tests.data.generation.test_generation import shard_hashes, tiny_spec, torch_photographer
from tests.data.storage.test_shards import write_raw_shard


def make_sample(index: int, height: int = 12, width: int = 10, dtype: torch.dtype = torch.float32) -> Sample:
    generator = torch.Generator().manual_seed(index)
    photo = torch.rand(3, height, width, generator=generator, dtype=dtype)
    photo[:, 0, 0] = torch.tensor([0.0, 1.0, 0.5])  # the range ends and a half level
    maps = random_maps(height, width, seed=index, dtype=dtype)
    return Sample(key=f"s-{index:04d}", photo=photo, maps=maps, meta={"seed": index, "family": "wood"})


def record(sample: Sample, shard_format: str) -> dict[str, object]:
    return {"__key__": sample.key, **encode_sample(sample, shard_format)}


def read_u16z(data: bytes) -> np.ndarray:
    """An independent reader of the layout in brdfgan.data.storage.shards' docstring."""
    magic, version, value_bytes, channels, height, width = struct.unpack_from("<4sBBHII", data)
    assert (magic, version, value_bytes) == (b"U16Z", 1, 2)
    shuffled = np.frombuffer(zstandard.ZstdDecompressor().decompress(data[16:]), np.uint8)
    low, high = shuffled.reshape(2, channels * height * width).astype(np.uint16)
    return (low | (high << 8)).reshape(channels, height, width)


def png_planes(data: bytes) -> np.ndarray:
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert image is not None and image.dtype == np.uint16
    return image[None] if image.ndim == 2 else image.transpose(2, 0, 1)[::-1]  # BGR -> RGB planes


# ---------------------------------------------------------------------------------------------
# Values and bytes


@pytest.mark.parametrize(("height", "width", "dtype"), [(12, 10, torch.float32), (33, 17, torch.float64)])
def test_u16z_decodes_to_the_tensors_png_decodes_to(height: int, width: int, dtype: torch.dtype) -> None:
    for index in range(3):
        sample = make_sample(index, height, width, dtype)
        png, u16z = decode_sample(record(sample, "png")), decode_sample(record(sample, "u16z"))
        assert torch.equal(png.photo, u16z.photo) and torch.equal(png.maps, u16z.maps)
        assert u16z.photo.dtype == u16z.maps.dtype == torch.float32
        assert (u16z.key, u16z.meta) == (sample.key, sample.meta)
        assert (u16z.photo - sample.photo).abs().max() <= 0.5 / 65535 + 1e-7  # nearest level


def test_u16z_members_hold_the_png_pixel_values_in_the_documented_layout() -> None:
    sample = make_sample(4)
    png, u16z = encode_sample(sample, "png"), encode_sample(sample, "u16z")
    assert tuple(u16z) == FORMAT_MEMBERS["u16z"] == ("input.u16z", "maps.u16z", "meta.json")
    photo, maps = read_u16z(u16z["input.u16z"]), read_u16z(u16z["maps.u16z"])
    assert photo.shape == (3, 12, 10) and maps.shape == (8, 12, 10)
    np.testing.assert_array_equal(photo, png_planes(png["input.png"]))
    stored = np.concatenate(
        [png_planes(png[f"{name}.png"]) for name in ("basecolor", "normal", "roughness", "metallic")]
    )
    np.testing.assert_array_equal(maps, stored)
    # Channel order and encoding, from the sample itself: photo R first, normals as (n + 1) / 2.
    assert photo[:, 0, 0].tolist() == [0, 65535, 32768]
    normal = encode_normal(split_maps(sample.maps).normal).double().numpy()
    np.testing.assert_array_equal(maps[3:6], np.rint(normal * 65535))
    assert u16z["meta.json"] == png["meta.json"]


def test_u16z_encoding_and_shards_are_byte_deterministic(tmp_path: Path) -> None:
    samples = [make_sample(i) for i in range(3)]
    assert encode_sample(samples[0], "u16z") == encode_sample(make_sample(0), "u16z")
    first = write_shard(tmp_path / "a" / "x-000000.tar", samples, shard_format="u16z")
    second = write_shard(
        tmp_path / "b" / "x-000000.tar", [make_sample(i) for i in range(3)], shard_format="u16z"
    )
    assert first.path.read_bytes() == second.path.read_bytes() and first.sha256 == second.sha256
    png = write_shard(tmp_path / "c" / "x-000000.tar", samples)
    assert png.sha256 != first.sha256
    with tarfile.open(first.path) as tar:
        assert [m.name for m in tar] == [f"{s.key}.{n}" for s in samples for n in FORMAT_MEMBERS["u16z"]]


# ---------------------------------------------------------------------------------------------
# Reading old, new and mixed shards


def test_png_and_u16z_samples_of_one_shard_both_decode(tmp_path: Path) -> None:
    old, new = make_sample(0), make_sample(1)
    members = {f"{old.key}.{n}": data for n, data in encode_sample(old).items()}  # png: the default
    members |= {f"{new.key}.{n}": data for n, data in encode_sample(new, "u16z").items()}
    path = tmp_path / "mixed.tar"
    write_raw_shard(path, members)
    assert verify_shard(path, decode=True) == 2
    decoded = list(iter_shard(path))
    assert [s.key for s in decoded] == [old.key, new.key]
    for sample, expected in zip(decoded, (old, new), strict=True):
        assert torch.equal(sample.photo, decode_sample(record(expected, "png")).photo)


def test_the_loader_yields_the_same_batches_from_either_format(tmp_path: Path) -> None:
    samples = [make_sample(i) for i in range(4)]
    batches = {}
    for shard_format in ("png", "u16z"):
        write_shard(shard_path(tmp_path / shard_format, "test", 0), samples, shard_format=shard_format)
        dm = ShardDataModule(str(tmp_path / shard_format), batch_size=4, val_split=None)
        dm.setup("test")
        batches[shard_format] = next(iter(dm.test_dataloader()))
    assert batches["png"]["key"] == batches["u16z"]["key"] == [s.key for s in samples]
    assert torch.equal(batches["png"]["photo"], batches["u16z"]["photo"])
    assert torch.equal(batches["png"]["maps"], batches["u16z"]["maps"])


def test_verify_refuses_a_sample_that_mixes_formats(tmp_path: Path) -> None:
    png, u16z = encode_sample(make_sample(0)), encode_sample(make_sample(0), "u16z")
    path = tmp_path / "halfway.tar"
    write_raw_shard(
        path, {"k.input.png": png["input.png"], "k.maps.u16z": u16z["maps.u16z"], "k.meta.json": b"{}"}
    )
    with pytest.raises(ShardError, match=r"halfway\.tar: sample 'k' mixes formats \(input\.png"):
        verify_shard(path)
    lacking = tmp_path / "lacking.tar"
    write_raw_shard(lacking, {"k.input.u16z": u16z["input.u16z"], "k.meta.json": b"{}"})
    with pytest.raises(ShardError, match=r"'k' lacks member.*maps\.u16z"):
        verify_shard(lacking)


# ---------------------------------------------------------------------------------------------
# Damage


def _flip_middle(data: bytes) -> bytes:
    middle = len(data) // 2
    return data[:middle] + bytes(b ^ 0xFF for b in data[middle : middle + 8]) + data[middle + 8 :]


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (_flip_middle, r"corrupt u16z \(.*checksum"),
        (lambda data: data[: len(data) - 7], "corrupt u16z"),  # cut short
        (lambda data: data[:10], r"corrupt u16z \(truncated header"),
        (lambda data: b"", r"corrupt u16z \(truncated header"),
        (lambda data: b"PNG!" + data[4:], r"corrupt u16z \(not a version 1 uint16 header"),
        (lambda data: data[:6] + struct.pack("<H", 3) + data[8:], r"expected 8 channel\(s\), got 3"),
        (
            lambda data: data[:8] + struct.pack("<I", 13) + data[12:],
            r"corrupt u16z \(payload size does not match 8x13x10",
        ),
    ],
)
def test_a_damaged_u16z_member_names_the_shard_sample_and_member(
    tmp_path: Path, damage: Callable[[bytes], bytes], message: str
) -> None:
    files = encode_sample(make_sample(0), "u16z")
    files["maps.u16z"] = damage(files["maps.u16z"])
    path = tmp_path / "bad.tar"
    write_raw_shard(path, {f"k.{name}": data for name, data in files.items()})
    assert verify_shard(path) == 1  # the tar structure is fine
    with pytest.raises(ShardError, match=rf"^sample 'k' in {path} maps\.u16z: {message}") as raised:
        verify_shard(path, decode=True)
    assert "\n" not in str(raised.value)


def test_a_u16z_photo_of_another_size_is_refused() -> None:
    files = record(make_sample(0), "u16z")
    files["input.u16z"] = encode_sample(make_sample(1, height=6), "u16z")["input.u16z"]
    with pytest.raises(ShardError, match="'s-0000': member images differ in size"):
        decode_sample(files)


def test_unknown_formats_are_refused_when_writing(tmp_path: Path) -> None:
    with pytest.raises(ShardError, match="unknown shard format 'jpeg': expected one of u16z, png"):
        write_shard(tmp_path / "x.tar", [make_sample(0)], shard_format="jpeg")
    assert not list(tmp_path.iterdir())
    with pytest.raises(ShardError, match="unknown shard format"):
        encode_sample(make_sample(0), "raw")


# ---------------------------------------------------------------------------------------------
# dataset_spec.shard_format


@pytest.mark.integration
def test_the_config_key_is_validated_naming_it() -> None:
    with pytest.raises(
        DatasetConfigError, match=r"^dataset_spec\.shard_format='jpeg': must be one of u16z, png$"
    ):
        DatasetSpec(shard_format="jpeg")
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        good = compose(config_name="generate", overrides=["dataset_spec=tiny"])
        bad = compose(
            config_name="generate", overrides=["dataset_spec=tiny", "dataset_spec.shard_format=tar"]
        )
    assert spec_from_config(good.dataset_spec).shard_format == "u16z"  # new datasets
    assert DatasetSpec().shard_format == "png"  # a spec without the key: every older dataset
    with pytest.raises(DatasetConfigError, match=r"^dataset_spec\.shard_format='tar'"):
        spec_from_config(bad.dataset_spec)


def test_generation_writes_and_records_the_format_and_an_old_dataset_keeps_its_own(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    small = {"materials": 3, "test_fraction": 0.34, "val_fraction": 0.0, "crops_per_material": 1}
    spec, u16z_spec = tiny_spec(**small), tiny_spec(**small, shard_format="u16z")
    assert spec.shard_format == "png"
    new, old = tmp_path / "new", tmp_path / "old"
    run_generation(u16z_spec, new, progress=False, photographer=torch_photographer)
    run_generation(spec, old, progress=False, photographer=torch_photographer)
    assert json.loads((new / SPEC_FILE).read_text())["shard_format"] == "u16z"
    assert read_manifest(new, "train")["spec"]["shard_format"] == "u16z"
    with tarfile.open(shard_path(new, "train", 0)) as tar:
        assert {m.name.partition(".")[2] for m in tar} == set(FORMAT_MEMBERS["u16z"])
    for split in ("train", "test"):  # the same tensors either way
        for a, b in zip(
            iter_shard(shard_path(new, split, 0)), iter_shard(shard_path(old, split, 0)), strict=True
        ):
            assert a.key == b.key and torch.equal(a.photo, b.photo) and torch.equal(a.maps, b.maps)

    # An old dataset (its dataset.json predates the key) is the dataset of the u16z config: ready,
    # and a lost shard is rewritten in png, byte for byte.
    clean = shard_hashes(old)
    spec_file = json.loads((old / SPEC_FILE).read_text())
    del spec_file["shard_format"]
    (old / SPEC_FILE).write_text(json.dumps(spec_file))
    assert dataset_ready(u16z_spec, old)
    shard_path(old, "train", 0).unlink()
    shutil.rmtree(new)
    with caplog.at_level(logging.WARNING, logger="brdfgan.data.generation.generation"):
        summary = run_generation(u16z_spec, old, progress=False, photographer=torch_photographer)
    assert summary.written == [shard_path(old, "train", 0)]
    assert shard_hashes(old) == clean
    assert any("holds png shards: continuing in png" in r.getMessage() for r in caplog.records)
    assert read_manifest(old, "train")["spec"]["shard_format"] == "png"
