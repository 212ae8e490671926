"""Shards of flash + no-flash pairs: the twin as an optional member of either format, shards
without it as they were, and the comparison of two generations."""

from __future__ import annotations

import io
import tarfile
from pathlib import Path

import pytest
import torch

from brdfgan.capture import NO_FLASH_PHOTO
from brdfgan.data.phone.pairs import pair_meta
from brdfgan.data.storage.shards import (
    FORMAT_MEMBERS,
    SHARD_FORMATS,
    Sample,
    ShardError,
    decode_sample,
    encode_sample,
    iter_shard,
    shard_differences,
    verify_shard,
    write_shard,
)
from tests.conftest import random_maps

QUANTUM = 1.0 / 65535.0


def pair_sample(index: int, twin: bool = True, height: int = 12, width: int = 10) -> Sample:
    generator = torch.Generator().manual_seed(index)
    photo = torch.rand(3, height, width, generator=generator)
    no_flash = torch.rand(3, height, width, generator=generator) * 0.5 if twin else None
    meta = {
        "seed": index,
        **({"pair": pair_meta(2.0, {"exposure_scale": 5.0, "exposure_ev": 0.0})} if twin else {}),
    }
    maps = random_maps(height, width, seed=index)
    return Sample(key=f"s-{index:04d}", photo=photo, maps=maps, meta=meta, no_flash=no_flash)


def members(path: Path) -> list[str]:
    with tarfile.open(path) as tar:
        return tar.getnames()


@pytest.mark.parametrize("shard_format", SHARD_FORMATS)
def test_a_pair_shard_round_trips_both_photos_and_the_pair_record(tmp_path: Path, shard_format: str) -> None:
    samples = [pair_sample(0), pair_sample(1)]
    path = tmp_path / "pairs.tar"
    write_shard(path, samples, shard_format=shard_format)
    twin = f"{NO_FLASH_PHOTO.member}.{shard_format}"
    names = [name.partition(".")[2] for name in members(path)]
    required = list(FORMAT_MEMBERS[shard_format])
    assert names[: len(required) + 1] == [required[0], twin, *required[1:]]  # the twin after the photo
    assert verify_shard(path, decode=True) == 2
    for written, read in zip(samples, iter_shard(path), strict=True):
        assert read.no_flash is not None and written.no_flash is not None
        assert torch.allclose(read.no_flash, written.no_flash, atol=QUANTUM / 2)
        assert torch.allclose(read.photo, written.photo, atol=QUANTUM / 2)
        assert read.meta == written.meta and read.meta["pair"]["exposure_ratio"] == 0.4


@pytest.mark.parametrize("shard_format", SHARD_FORMATS)
def test_a_sample_without_a_twin_keeps_the_members_and_bytes_it_had(
    tmp_path: Path, shard_format: str
) -> None:
    single = pair_sample(0, twin=False)
    files = encode_sample(single, shard_format)
    assert tuple(files) == FORMAT_MEMBERS[shard_format]
    # The same sample with a twin: the same bytes for every member it had.
    paired = Sample(single.key, single.photo, single.maps, single.meta, no_flash=torch.zeros(3, 12, 10))
    assert {
        name: data for name, data in encode_sample(paired, shard_format).items() if name in files
    } == files
    decoded = decode_sample({"__key__": single.key, **files})
    assert decoded.no_flash is None


def test_old_and_pair_samples_share_a_shard(tmp_path: Path) -> None:
    path = tmp_path / "mixed.tar"
    write_shard(path, [pair_sample(0, twin=False), pair_sample(1)], shard_format="u16z")
    assert verify_shard(path, decode=True) == 2
    assert [sample.no_flash is None for sample in iter_shard(path)] == [True, False]


def test_a_twin_of_another_size_or_format_is_refused(tmp_path: Path) -> None:
    sample = pair_sample(0)
    with pytest.raises(ShardError, match=r"no_flash .* differ in size"):
        Sample(sample.key, sample.photo, sample.maps, sample.meta, no_flash=torch.zeros(3, 4, 4))
    with pytest.raises(ShardError, match="no_flash must be finite linear LDR"):
        Sample(sample.key, sample.photo, sample.maps, sample.meta, no_flash=torch.full((3, 12, 10), 2.0))
    small = encode_sample(pair_sample(0, height=6, width=5), "u16z")
    record = {
        "__key__": "k",
        **encode_sample(sample, "u16z"),
        "input_noflash.u16z": small["input_noflash.u16z"],
    }
    with pytest.raises(ShardError, match="member images differ in size"):
        decode_sample(record)
    # A PNG twin beside u16z members mixes formats.
    png_twin = encode_sample(sample, "png")["input_noflash.png"]
    u16z = {
        f"s-0000.{name}": data for name, data in encode_sample(pair_sample(0, twin=False), "u16z").items()
    }
    path = tmp_path / "mixed.tar"
    with tarfile.open(path, "w", format=tarfile.USTAR_FORMAT) as tar:
        for name, data in {**u16z, "s-0000.input_noflash.png": png_twin}.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    with pytest.raises(ShardError, match=r"mixes formats \(input_noflash\.png"):
        verify_shard(path)


def test_two_generations_compare_their_twins_too(tmp_path: Path) -> None:
    first = pair_sample(0)
    assert first.no_flash is not None
    nudged = first.no_flash.clone()
    nudged[0, 0, 0] = (torch.round(nudged[0, 0, 0] * 65535) + 1) / 65535  # one code: within tolerance
    far = first.no_flash.clone()
    far[0, 0, 0] = (torch.round(far[0, 0, 0] * 65535) + 3) / 65535

    def shard(name: str, no_flash: torch.Tensor | None) -> Path:
        path = tmp_path / f"{name}.tar"
        write_shard(path, [Sample(first.key, first.photo, first.maps, first.meta, no_flash=no_flash)])
        return path

    reference = shard("a", first.no_flash)
    assert shard_differences(reference, shard("b", nudged)) == []
    assert shard_differences(reference, shard("c", far)) == [
        "sample 's-0000': no-flash twins differ by 3 codes (tolerance 1)"
    ]
    assert shard_differences(reference, shard("d", None)) == ["sample 's-0000': only one has a no-flash twin"]
