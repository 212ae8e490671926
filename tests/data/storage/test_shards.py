from __future__ import annotations

import hashlib
import io
import json
import tarfile
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from brdfgan.core.svbrdf import NORMAL, validate_maps
from brdfgan.data.storage.shards import (
    SAMPLE_MEMBERS,
    Sample,
    ShardError,
    decode_sample,
    digest_path,
    encode_sample,
    list_shards,
    read_digest,
    read_manifest,
    sha256_file,
    shard_differences,
    shard_path,
    verify_shard,
    write_digest,
    write_manifest,
    write_shard,
)
from tests.conftest import random_maps

QUANTUM = 1.0 / 65535.0


def make_sample(index: int, height: int = 12, width: int = 10) -> Sample:
    generator = torch.Generator().manual_seed(index)
    photo = torch.rand(3, height, width, generator=generator)
    photo[:, 0, 0] = torch.tensor([0.0, 1.0, 0.5])  # the range ends must survive
    meta = {
        "family": "wood",
        "seed": index,
        "flash": {"intensity": 1.5, "temperature_k": 5500.0},
        "ids": [1, 2],
    }
    return Sample(key=f"s-{index:04d}", photo=photo, maps=random_maps(height, width, seed=index), meta=meta)


def record_of(sample: Sample) -> dict[str, object]:
    return {"__key__": sample.key, **encode_sample(sample)}


def shard_members(path: Path) -> dict[str, bytes]:
    with tarfile.open(path) as tar:
        return {info.name: tar.extractfile(info).read() for info in tar}


def write_raw_shard(path: Path, members: dict[str, bytes]) -> None:
    """A structurally valid shard with arbitrary member contents."""
    with tarfile.open(path, "w", format=tarfile.USTAR_FORMAT) as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))


# ---------------------------------------------------------------------------------------------
# Samples


def test_round_trip_values_key_meta() -> None:
    sample = make_sample(3)
    decoded = decode_sample(record_of(sample))
    assert decoded.key == sample.key
    assert decoded.meta == sample.meta
    assert decoded.photo.dtype == decoded.maps.dtype == torch.float32
    assert decoded.photo.shape == (3, 12, 10) and decoded.maps.shape == (8, 12, 10)
    validate_maps(decoded.maps, normal_tolerance=1e-5)
    # Rounding to the nearest 16-bit level: half a quantum (plus float32 rounding).
    assert (decoded.photo - sample.photo).abs().max() <= 0.5 * QUANTUM + 1e-7
    others = torch.ones(8, dtype=torch.bool)
    others[NORMAL] = False
    assert (decoded.maps[others] - sample.maps[others]).abs().max() <= 0.5 * QUANTUM + 1e-7
    # Normals: a quantum in (n + 1)/2 is two in n, then renormalisation.
    assert (decoded.maps[NORMAL] - sample.maps[NORMAL]).abs().max() <= 2.0 * QUANTUM
    assert torch.allclose(
        torch.linalg.vector_norm(decoded.maps[NORMAL], dim=0), torch.ones(12, 10), atol=1e-6
    )


def test_encoded_members_are_16_bit_png_and_compact_json() -> None:
    sample = make_sample(0)
    files = encode_sample(sample)
    assert tuple(files) == SAMPLE_MEMBERS
    channels = {"input.png": 3, "basecolor.png": 3, "normal.png": 3, "roughness.png": 1, "metallic.png": 1}
    for name, count in channels.items():
        image = cv2.imdecode(np.frombuffer(files[name], np.uint8), cv2.IMREAD_UNCHANGED)
        assert image.dtype == np.uint16
        assert (1 if image.ndim == 2 else image.shape[2]) == count
    # RGB order in the file: OpenCV's BGR channel 2 is the photo's red.
    image = cv2.imdecode(np.frombuffer(files["input.png"], np.uint8), cv2.IMREAD_UNCHANGED)
    assert image[0, 0].tolist() == [32768, 65535, 0]
    assert files["meta.json"] == json.dumps(sample.meta, sort_keys=True, separators=(",", ":")).encode()
    assert encode_sample(sample) == files  # deterministic


def test_normals_are_stored_encoded() -> None:
    sample = make_sample(1)
    image = cv2.imdecode(np.frombuffer(encode_sample(sample)["normal.png"], np.uint8), cv2.IMREAD_UNCHANGED)
    z = image[:, :, 0].astype(np.float64) / 65535.0  # BGR: channel 0 is Z
    expected = (sample.maps[5].double().numpy() + 1.0) / 2.0
    assert np.abs(z - expected).max() <= 0.5 * QUANTUM + 1e-12


def test_corrupt_member_names_the_key() -> None:
    record = record_of(make_sample(2))
    record["normal.png"] = b"\x89PNG garbage"
    with pytest.raises(ShardError, match=r"'s-0002'.*normal\.png"):
        decode_sample(record)


def test_decode_rejects_missing_members_wrong_depth_and_bad_json() -> None:
    good = record_of(make_sample(2))
    missing = {k: v for k, v in good.items() if k != "metallic.png"}
    with pytest.raises(ShardError, match=r"missing member.*metallic\.png"):
        decode_sample(missing)
    eight_bit = dict(
        good, **{"roughness.png": cv2.imencode(".png", np.zeros((12, 10), np.uint8))[1].tobytes()}
    )
    with pytest.raises(ShardError, match="16-bit"):
        decode_sample(eight_bit)
    wrong_size = dict(
        good, **{"metallic.png": cv2.imencode(".png", np.zeros((4, 4), np.uint16))[1].tobytes()}
    )
    with pytest.raises(ShardError, match="differ in size"):
        decode_sample(wrong_size)
    inward = dict(good, **{"normal.png": cv2.imencode(".png", np.zeros((12, 10, 3), np.uint16))[1].tobytes()})
    with pytest.raises(ShardError, match="into the surface"):
        decode_sample(inward)
    with pytest.raises(ShardError, match=r"meta\.json"):
        decode_sample(dict(good, **{"meta.json": b"{not json"}))
    with pytest.raises(ShardError, match="JSON object"):
        decode_sample(dict(good, **{"meta.json": b"[1, 2]"}))


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"key": "a.b"}, "invalid sample key"),
        ({"key": "a/b"}, "invalid sample key"),
        ({"key": ""}, "invalid sample key"),
        ({"photo": torch.rand(4, 12, 10)}, r"\(3, H, W\)"),
        ({"photo": torch.rand(3, 12, 10) * 2.0}, r"\[0, 1\]"),
        ({"photo": torch.zeros(3, 12, 10, dtype=torch.int64)}, "floating point"),
        ({"photo": torch.rand(3, 6, 10)}, "differ in size"),
        ({"maps": torch.rand(7, 12, 10)}, r"\(8, H, W\)"),
        ({"maps": random_maps(12, 10) * 2.0}, "must lie in"),
        ({"meta": [1, 2]}, "mapping"),
    ],
)
def test_sample_validation(change: dict[str, object], message: str) -> None:
    fields = {"key": "ok", "photo": torch.rand(3, 12, 10), "maps": random_maps(12, 10), "meta": {}}
    with pytest.raises(ShardError, match=message):
        Sample(**{**fields, **change})


def test_meta_must_be_json() -> None:
    sample = make_sample(0)
    for meta in ({"x": object()}, {"x": float("nan")}):
        bad = Sample(key="bad", photo=sample.photo, maps=sample.maps, meta=meta)
        with pytest.raises(ShardError, match=r"'bad'.*JSON"):
            encode_sample(bad)


# ---------------------------------------------------------------------------------------------
# Shards


def test_write_shard_layout_and_info(tmp_path: Path) -> None:
    samples = [make_sample(i) for i in range(3)]
    info = write_shard(shard_path(tmp_path, "train", 7), samples)
    assert info.path == tmp_path / "train" / "train-000007.tar"
    assert info.count == 3
    data = info.path.read_bytes()
    assert info.bytes == len(data)
    assert info.sha256 == hashlib.sha256(data).hexdigest()
    with tarfile.open(info.path) as tar:
        members = tar.getmembers()
    assert [m.name for m in members] == [f"{s.key}.{name}" for s in samples for name in SAMPLE_MEMBERS]
    for m in members:
        assert (m.mtime, m.uid, m.gid, m.uname, m.gname, m.mode) == (0, 0, 0, "", "", 0o644)
        assert m.isreg() and not m.pax_headers
    assert verify_shard(info.path) == 3


def test_digest_records_sit_beside_the_shard_in_sha256sum_format(tmp_path: Path) -> None:
    info = write_shard(shard_path(tmp_path, "train", 3), [make_sample(0)])
    assert read_digest(info.path) is None  # nothing recorded yet
    record = write_digest(info.path, sha256_file(info.path))
    assert record == digest_path(info.path) == tmp_path / "train" / "train-000003.tar.sha256"
    assert record.read_text() == f"{info.sha256}  train-000003.tar\n"  # `sha256sum -c` reads this
    assert read_digest(info.path) == info.sha256
    assert list_shards(tmp_path, "train") == [info.path]  # the record is not a shard
    with pytest.raises(ValueError, match="not a lowercase hex SHA-256"):
        write_digest(info.path, "abc")


@pytest.mark.parametrize(
    "text", ["garbage\n", f"{'0' * 64}  train-000004.tar\n", f"{'0' * 63}  train-000003.tar\n", ""]
)
def test_a_malformed_digest_record_names_itself(tmp_path: Path, text: str) -> None:
    shard = shard_path(tmp_path, "train", 3)
    shard.parent.mkdir(parents=True)
    digest_path(shard).write_text(text)
    with pytest.raises(ShardError, match=r"train-000003\.tar\.sha256: malformed checksum record"):
        read_digest(shard)


def test_write_shard_is_byte_deterministic(tmp_path: Path) -> None:
    first = write_shard(tmp_path / "a" / "x-000000.tar", [make_sample(i) for i in range(3)])
    second = write_shard(tmp_path / "b" / "x-000000.tar", [make_sample(i) for i in range(3)])
    assert first.sha256 == second.sha256
    assert first.path.read_bytes() == second.path.read_bytes()
    different = write_shard(tmp_path / "c" / "x-000000.tar", [make_sample(i) for i in (0, 2, 1)])
    assert different.sha256 != first.sha256


def test_shard_round_trip_through_members(tmp_path: Path) -> None:
    samples = [make_sample(i) for i in range(2)]
    info = write_shard(tmp_path / "s.tar", samples)
    members = shard_members(info.path)
    for sample in samples:
        record = {"__key__": sample.key, **{n: members[f"{sample.key}.{n}"] for n in SAMPLE_MEMBERS}}
        decoded = decode_sample(record)
        assert decoded.meta == sample.meta
        assert torch.allclose(decoded.photo, sample.photo, atol=QUANTUM)


def test_failed_write_leaves_nothing_and_keeps_existing_shard(tmp_path: Path) -> None:
    path = shard_path(tmp_path, "train", 0)

    def failing() -> Iterator[Sample]:
        yield make_sample(0)
        yield make_sample(1)
        raise RuntimeError("renderer crashed")

    with pytest.raises(RuntimeError, match="renderer crashed"):
        write_shard(path, failing())
    assert list(path.parent.iterdir()) == []

    old = write_shard(path, [make_sample(5)])
    with pytest.raises(RuntimeError):
        write_shard(path, failing())
    assert sorted(p.name for p in path.parent.iterdir()) == [path.name]
    assert hashlib.sha256(path.read_bytes()).hexdigest() == old.sha256


def test_duplicate_keys_are_rejected(tmp_path: Path) -> None:
    sample = make_sample(0)
    with pytest.raises(ShardError, match="duplicate sample key 's-0000'"):
        write_shard(tmp_path / "d.tar", [sample, make_sample(1), sample])
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ShardError, match="Sample objects"):
        write_shard(tmp_path / "d.tar", [{"key": "x"}])  # type: ignore[list-item]


def test_shard_naming_and_listing(tmp_path: Path) -> None:
    assert shard_path("/data", "val", 12) == Path("/data/val/val-000012.tar")
    with pytest.raises(ValueError):
        shard_path(tmp_path, "train", -1)
    for index in (2, 0, 10):
        write_shard(shard_path(tmp_path, "train", index), [make_sample(index)])
    (tmp_path / "train" / ".train-000003.tar.abc.tmp").write_bytes(b"partial")
    (tmp_path / "train" / "notes.tar").write_bytes(b"")
    (tmp_path / "train" / "val-000001.tar").write_bytes(b"")
    assert [p.name for p in list_shards(tmp_path, "train")] == [
        "train-000000.tar",
        "train-000002.tar",
        "train-000010.tar",
    ]
    assert list_shards(tmp_path, "missing") == []


# ---------------------------------------------------------------------------------------------
# verify_shard


@pytest.fixture
def good_shard(tmp_path: Path) -> Path:
    return write_shard(tmp_path / "good-000000.tar", [make_sample(i) for i in range(3)]).path


def test_verify_detects_truncation(good_shard: Path, tmp_path: Path) -> None:
    data = good_shard.read_bytes()
    half = tmp_path / "half.tar"
    half.write_bytes(data[: len(data) // 2])
    with pytest.raises(ShardError, match=r"half\.tar.*truncated"):
        verify_shard(half)
    # Cut exactly between two members: every header that remains is intact.
    with tarfile.open(good_shard) as tar:
        boundary = tar.getmembers()[len(SAMPLE_MEMBERS)].offset
    cut = tmp_path / "cut.tar"
    cut.write_bytes(data[:boundary])
    with pytest.raises(ShardError, match=r"cut\.tar.*truncated"):
        verify_shard(cut)
    # End-of-archive marker lost.
    with tarfile.open(good_shard) as tar:
        for _ in tar:
            pass
        end = tar.offset
    no_marker = tmp_path / "nomarker.tar"
    no_marker.write_bytes(data[:end])
    with pytest.raises(ShardError, match="truncated"):
        verify_shard(no_marker)


def test_verify_detects_garbage(good_shard: Path, tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.tar"
    garbage.write_bytes(np.random.default_rng(0).integers(0, 256, 20_000, dtype=np.uint8).tobytes())
    with pytest.raises(ShardError, match=r"garbage\.tar"):
        verify_shard(garbage)
    empty = tmp_path / "empty.tar"
    empty.write_bytes(b"")
    with pytest.raises(ShardError, match=r"empty\.tar"):
        verify_shard(empty)
    with pytest.raises(ShardError, match=r"missing\.tar"):
        verify_shard(tmp_path / "missing.tar")
    # A damaged header in the middle: tarfile alone would stop there without complaint.
    data = bytearray(good_shard.read_bytes())
    with tarfile.open(good_shard) as tar:
        offset = tar.getmembers()[8].offset
    data[offset + 20] ^= 0xFF
    damaged = tmp_path / "damaged.tar"
    damaged.write_bytes(bytes(data))
    with pytest.raises(ShardError, match=r"damaged\.tar"):
        verify_shard(damaged)


def test_verify_checks_the_sample_layout(tmp_path: Path) -> None:
    files = encode_sample(make_sample(0))
    incomplete = tmp_path / "incomplete.tar"
    write_raw_shard(incomplete, {f"k.{n}": files[n] for n in SAMPLE_MEMBERS if n != "meta.json"})
    with pytest.raises(ShardError, match=r"'k' lacks member.*meta\.json"):
        verify_shard(incomplete)
    stranger = tmp_path / "stranger.tar"
    write_raw_shard(stranger, {**{f"k.{n}": files[n] for n in SAMPLE_MEMBERS}, "k.depth.png": b"x"})
    with pytest.raises(ShardError, match=r"unexpected member 'k\.depth\.png'"):
        verify_shard(stranger)
    interleaved = tmp_path / "interleaved.tar"
    members = {f"a.{n}": files[n] for n in SAMPLE_MEMBERS}
    members |= {f"b.{n}": files[n] for n in SAMPLE_MEMBERS}
    members["a.meta.json"] = members.pop("a.meta.json")  # moves a's last member after b's
    write_raw_shard(interleaved, members)
    with pytest.raises(ShardError, match=r"interleaved\.tar"):
        verify_shard(interleaved)


def test_verify_decode_catches_corrupt_images(tmp_path: Path) -> None:
    files = encode_sample(make_sample(0))
    files["basecolor.png"] = b"\x89PNG\r\n\x1a\n" + b"\x00" * 64
    path = tmp_path / "badpng.tar"
    write_raw_shard(path, {f"k.{n}": files[n] for n in SAMPLE_MEMBERS})
    assert verify_shard(path) == 1  # the structure is fine
    with pytest.raises(ShardError, match=r"'k'.*badpng\.tar basecolor\.png"):
        verify_shard(path, decode=True)


# ---------------------------------------------------------------------------------------------
# Manifest


def test_manifest_round_trip(tmp_path: Path) -> None:
    manifest = {"samples": 12, "code_version": "abc", "config": {"resolution": 256, "families": ["wood"]}}
    path = write_manifest(tmp_path, "train", manifest)
    assert path == tmp_path / "train" / "manifest.json"
    assert read_manifest(tmp_path, "train") == manifest
    text = path.read_text()
    assert text == json.dumps(manifest, sort_keys=True, indent=2) + "\n"
    assert [p.name for p in path.parent.iterdir()] == ["manifest.json"]
    with pytest.raises(ShardError, match="JSON"):
        write_manifest(tmp_path, "train", {"bad": float("inf")})
    assert read_manifest(tmp_path, "train") == manifest  # untouched by the failed write


def test_read_manifest_errors(tmp_path: Path) -> None:
    with pytest.raises(ShardError, match="not found"):
        read_manifest(tmp_path, "val")
    (tmp_path / "val").mkdir()
    (tmp_path / "val" / "manifest.json").write_text("[1]")
    with pytest.raises(ShardError, match="JSON object"):
        read_manifest(tmp_path, "val")
    (tmp_path / "val" / "manifest.json").write_text("{oops")
    with pytest.raises(ShardError, match="unreadable"):
        read_manifest(tmp_path, "val")


def test_two_generations_agree_when_photos_are_within_one_code_and_not_beyond(tmp_path: Path) -> None:
    # Mitsuba's LLVM renders move a rare pixel by one 16-bit code between runs: such shards differ
    # in bytes and SHA-256 but hold the same samples; two codes, other maps or metadata do not.
    samples = [make_sample(0), make_sample(1)]

    def nudged(sample: Sample, codes: int, **changes: object) -> Sample:
        photo = sample.photo.clone()
        photo[1, 3, 4] = (round(float(photo[1, 3, 4]) * 65535) + codes) / 65535  # away from the ends
        fields = {"key": sample.key, "photo": photo, "maps": sample.maps, "meta": sample.meta, **changes}
        return Sample(**fields)  # type: ignore[arg-type]

    reference = write_shard(tmp_path / "a.tar", samples)
    one_code = write_shard(tmp_path / "b.tar", [nudged(samples[0], 1), samples[1]])
    assert one_code.sha256 != reference.sha256
    assert shard_differences(reference.path, one_code.path) == []
    two_codes = write_shard(tmp_path / "c.tar", [nudged(samples[0], 2), samples[1]])
    assert shard_differences(reference.path, two_codes.path) == [
        "sample 's-0000': photos differ by 2 codes (tolerance 1)"
    ]
    other_meta = write_shard(tmp_path / "d.tar", [samples[0], nudged(samples[1], 0, meta={"seed": 9})])
    assert shard_differences(reference.path, other_meta.path) == ["sample 's-0001': metadata differs"]
    other_maps = write_shard(
        tmp_path / "e.tar", [nudged(samples[0], 0, maps=random_maps(12, 10, seed=7)), samples[1]]
    )
    assert shard_differences(reference.path, other_maps.path) == ["sample 's-0000': maps differ"]
    fewer = write_shard(tmp_path / "f.tar", samples[:1])
    assert shard_differences(reference.path, fewer.path) == [
        f"{reference.path} and {fewer.path} hold different samples"
    ]
