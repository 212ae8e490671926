"""The capture seam: one type says what photos a capture holds, and every stage reads it
(predict's dispatch, the shard members, a batch's keys, the generator's input channels)."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
import torch

from brdfgan.capture import (
    CAPTURE_KINDS,
    FLASH_PHOTO,
    NO_FLASH_PHOTO,
    PAIR,
    SINGLE_PHOTO,
    TRAINING_CAPTURE,
    VIEWS,
    CaptureKind,
    CapturePhoto,
    PhotoRole,
    capture_kind,
    known_shard_members,
)
from brdfgan.data.loading.datamodule import collate_samples
from brdfgan.data.storage.shards import FORMAT_MEMBERS, Sample, encode_sample
from brdfgan.errors import UserError
from brdfgan.inference.dispatch import CAPTURE_PIPELINES, Capture, all_photos_together, group_captures
from brdfgan.models import PHOTO_CHANNELS
from brdfgan.models.heads import network_photos
from tests.conftest import random_maps

# A flash + no-flash pair with the generator seeing both (a pair model's kind): the seam derives it
# from one entry.
NETWORK_NO_FLASH = CapturePhoto(PhotoRole.NO_FLASH, member="input_noflash", batch_key="photo_noflash")
NETWORK_PAIR = CaptureKind(
    "network_pair", (FLASH_PHOTO, NETWORK_NO_FLASH), "a flash photo and a no-flash photo", flag="--no-flash"
)


def test_every_kind_has_one_pipeline_and_the_training_capture_is_the_single_photo() -> None:
    assert set(CAPTURE_PIPELINES) == set(CAPTURE_KINDS) == {"single", "views", "pair"}
    assert (
        TRAINING_CAPTURE is SINGLE_PHOTO and capture_kind("views") is VIEWS and capture_kind("pair") is PAIR
    )
    with pytest.raises(UserError, match=r"^capture kind 'stereo': expected one of single, views, pair$"):
        capture_kind("stereo")


def test_the_generator_shard_and_batch_read_the_training_capture() -> None:
    assert PHOTO_CHANNELS == TRAINING_CAPTURE.network_channels == 3
    assert FORMAT_MEMBERS["u16z"][:1] == TRAINING_CAPTURE.shard_members("u16z") == ("input.u16z",)
    assert FORMAT_MEMBERS["png"][:1] == ("input.png",)
    sample = Sample("k", torch.rand(3, 8, 8), random_maps(8, 8, seed=0), {})
    assert set(encode_sample(sample, "u16z")) == set(FORMAT_MEMBERS["u16z"])
    batch = collate_samples([sample])
    assert torch.equal(network_photos(batch), batch[FLASH_PHOTO.batch_key])


def test_a_pair_kind_derives_its_members_keys_and_channels() -> None:
    assert NETWORK_PAIR.shard_members("u16z") == ("input.u16z", "input_noflash.u16z")
    assert NETWORK_PAIR.network_channels == 6
    assert NETWORK_PAIR.roles(2) == (PhotoRole.FLASH, PhotoRole.NO_FLASH)
    flash, no_flash = torch.zeros(2, 3, 4, 4), torch.ones(2, 3, 4, 4)
    stacked = network_photos({"photo": flash, "photo_noflash": no_flash}, NETWORK_PAIR)
    assert stacked.shape == (2, 6, 4, 4) and torch.equal(stacked[:, 3:], no_flash)
    with pytest.raises(UserError, match=r"^--no-flash takes at most 2 photos of one surface, got 3$"):
        NETWORK_PAIR.roles(3)


def test_the_pair_kind_is_the_flash_photo_and_the_no_flash_photo_the_fit_reads() -> None:
    """predict --no-flash: the shipped generator sees the flash(-only) photo, the fit both."""
    assert PAIR.photos == (FLASH_PHOTO, NO_FLASH_PHOTO) and PAIR.network_channels == 3
    assert (PAIR.flag, PAIR.flag_value, PAIR.refines) == ("--no-flash", "NOFLASH", False)
    assert PAIR.roles(1) == (PhotoRole.FLASH,)  # a flash photo whose no-flash photo was not found
    # Shards of every kind's photos are readable: the reader knows their members.
    assert "input_noflash.u16z" in known_shard_members("u16z")
    assert "input_noflash.png" in known_shard_members("png")
    with pytest.raises(ValueError, match="only a flag of a two-photo kind names a photo"):
        CaptureKind("bad", (FLASH_PHOTO,), "", flag="--x", flag_value="X")


@pytest.mark.parametrize(
    ("photos", "message"),
    [
        ((NETWORK_NO_FLASH,), "its first photo must be the flash photo"),
        ((FLASH_PHOTO, CapturePhoto(PhotoRole.NO_FLASH, "input", "b")), "repeated member"),
        ((FLASH_PHOTO, CapturePhoto(PhotoRole.NO_FLASH, "m", "photo")), "repeated batch_key"),
    ],
)
def test_a_malformed_kind_is_refused(photos: tuple[CapturePhoto, ...], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        CaptureKind("bad", photos, "")


def test_photos_group_into_captures_by_kind(tmp_path: Path) -> None:
    photos = [tmp_path / "a" / "wood.jpg", tmp_path / "b" / "wood.png", tmp_path / "tiles.jpg"]
    singles = group_captures(SINGLE_PHOTO, photos)
    assert [(c.files, c.name) for c in singles] == [
        ((photos[0],), "wood"),
        ((photos[1],), "wood-2"),
        ((photos[2],), "tiles"),
    ]
    (views,) = group_captures(VIEWS, photos)
    assert views == Capture(VIEWS, tuple(photos), "wood") and views.reference == photos[0]
    assert views.roles == (PhotoRole.FLASH, PhotoRole.VIEW, PhotoRole.VIEW)
    with pytest.raises(UserError, match=r"^--views takes at most 12 photos of one surface, got 13$"):
        group_captures(VIEWS, photos * 4 + photos[:1])


def test_pairs_group_by_name_or_as_named(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A folder run pairs <stem> with <stem>_noflash; --no-flash NOFLASH names the partner."""
    photos = [tmp_path / name for name in ("wood.jpg", "wood_noflash.png", "tiles.jpg", "lone_noflash.jpg")]
    # An earlier in-process `predict --quiet` may have raised the package logger's level.
    caplog.set_level(logging.WARNING, logger="brdfgan")
    assert group_captures(PAIR, photos) == [
        Capture(PAIR, (photos[0], photos[1]), "wood"),
        Capture(PAIR, (photos[2],), "tiles"),
    ]
    assert any("lone_noflash.jpg: no flash photo" in record.getMessage() for record in caplog.records)
    named = all_photos_together(PAIR, [photos[2], tmp_path / "IMG_0043.jpg"])
    assert named == [Capture(PAIR, (photos[2], tmp_path / "IMG_0043.jpg"), "tiles")]
    assert named[0].roles == (PhotoRole.FLASH, PhotoRole.NO_FLASH)
