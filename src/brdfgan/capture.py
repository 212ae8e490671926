"""What a capture is: the photos one sample of a surface holds, and what each is for.

One type for every kind of capture, read by every stage that handles photos, so that a new kind
(the flash + no-flash pair, :data:`PAIR`, was one) is one entry in :data:`CAPTURE_KINDS` plus the
code that uses its new photos — not a hunt through the package:

- ``brdfgan predict`` groups its inputs into captures of one kind
  (:func:`brdfgan.inference.dispatch.group_captures`) and runs the kind's pipeline from one table
  (:data:`brdfgan.inference.dispatch.CAPTURE_PIPELINES`);
- the generator's input channels are the channels of the photos the network sees
  (:attr:`CaptureKind.network_channels`; :data:`brdfgan.models.heads.PHOTO_CHANNELS`);
- a shard's photo members and a batch's photo keys are the photos' ``member`` and ``batch_key``
  (:data:`brdfgan.data.storage.shards.FORMAT_MEMBERS`, the datamodules' batches, the evaluators).

A capture holds a fixed list of photos (:attr:`CaptureKind.photos`, the first the reference every
other one is registered to) and, for kinds like ``views``, up to :attr:`CaptureKind.more_views`
further photos of one role. This module imports nothing heavy: command-line parsing and config
checks read it cheaply.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum

from brdfgan.errors import UserError

# Colour channels of one photo (linear RGB).
CHANNELS_PER_PHOTO = 3


class PhotoRole(StrEnum):
    """What a photo of a capture shows."""

    FLASH = "flash"  # the flash on, at the lens, square on: the photo every capture starts from
    VIEW = "view"  # another flash photo of the same surface, from a little to the side
    NO_FLASH = "no_flash"  # the same framing with the flash off: the room light alone


@dataclass(frozen=True)
class CapturePhoto:
    """One photo a capture holds, and where it lives in each stage.

    ``member`` is the stem of its shard member (``<member>.u16z`` or ``<member>.png``) and
    ``batch_key`` its key in a training or evaluation batch; ``network`` says whether the
    generator sees it as input channels (a view or a no-flash photo may serve a fit instead)."""

    role: PhotoRole
    member: str
    batch_key: str
    network: bool = True


@dataclass(frozen=True)
class CaptureKind:
    """A kind of capture: its photos and how ``brdfgan predict`` takes it.

    ``flag`` is predict's option that selects it (``None``: the default, one capture per photo);
    ``flag_value``, for a flag that may name a photo, is that photo's placeholder in ``--help``
    (``--no-flash NOFLASH``: the second photo of the run's one capture; the flag given bare pairs
    a run's files by name instead, :func:`brdfgan.inference.dispatch.pair_by_name`);
    ``more_views`` is ``(least, most)`` further photos of role ``VIEW`` after :attr:`photos`
    (``None``: none); ``refines`` says whether ``--refine`` applies (a kind with a fit of its own
    says why not in ``no_refine_reason``)."""

    name: str
    photos: tuple[CapturePhoto, ...]
    description: str
    flag: str | None = None
    flag_value: str | None = None
    more_views: tuple[int, int] | None = None
    refines: bool = True
    no_refine_reason: str = ""

    def __post_init__(self) -> None:
        if self.flag_value is not None and (self.flag is None or len(self.photos) != 2 or self.more_views):
            raise ValueError(f"capture kind {self.name!r}: only a flag of a two-photo kind names a photo")
        if not self.photos or self.photos[0].role is not PhotoRole.FLASH:
            raise ValueError(f"capture kind {self.name!r}: its first photo must be the flash photo")
        for attribute in ("member", "batch_key"):
            names = [getattr(photo, attribute) for photo in self.photos]
            if len(set(names)) != len(names):
                raise ValueError(f"capture kind {self.name!r}: repeated {attribute} in {names}")

    @property
    def reference(self) -> CapturePhoto:
        """The flash photo the others are registered to (and the one a single photo is)."""
        return self.photos[0]

    @property
    def network_photos(self) -> tuple[CapturePhoto, ...]:
        return tuple(photo for photo in self.photos if photo.network)

    @property
    def network_channels(self) -> int:
        """The generator's input channels: every photo it sees, stacked in :attr:`photos`' order."""
        return CHANNELS_PER_PHOTO * len(self.network_photos)

    @property
    def most_photos(self) -> int:
        return len(self.photos) + (self.more_views[1] if self.more_views else 0)

    def shard_members(self, extension: str) -> tuple[str, ...]:
        """The photos' shard member names for a format's file ``extension`` (``u16z``, ``png``)."""
        return tuple(f"{photo.member}.{extension}" for photo in self.photos)

    def roles(self, count: int) -> tuple[PhotoRole, ...]:
        """The roles of ``count`` photos of this kind, in order.

        Raises:
            UserError: ``count`` is more than the kind takes (fewer is each pipeline's to handle:
                a views capture of one photo is that photo's single-photo prediction).
        """
        if count > self.most_photos:
            command = self.flag or "predict"
            raise UserError(f"{command} takes at most {self.most_photos} photos of one surface, got {count}")
        fixed = tuple(photo.role for photo in self.photos[:count])
        return fixed + (PhotoRole.VIEW,) * (count - len(fixed))


FLASH_PHOTO = CapturePhoto(PhotoRole.FLASH, member="input", batch_key="photo")
# The flash + no-flash pair's second photo: what a fit reads (the room light to subtract, its
# side-lit shading); the shipped generator does not see it.
NO_FLASH_PHOTO = CapturePhoto(
    PhotoRole.NO_FLASH, member="input_noflash", batch_key="photo_noflash", network=False
)
# A folder run's no-flash photo is named for its flash photo: wood.jpg and wood_noflash.jpg (any
# format predict reads, any case).
NO_FLASH_SUFFIX = "_noflash"

SINGLE_PHOTO = CaptureKind(
    "single",
    (FLASH_PHOTO,),
    "one flash photo, square on (the default: each input is a capture of its own)",
)

VIEWS = CaptureKind(
    "views",
    (FLASH_PHOTO,),
    "2-12 flash photos of one flat surface, the first square on, the others 5-15° to the side",
    flag="--views",
    # 12 photos in all: each view adds a render to every step of the fit (docs/views.md).
    more_views=(1, 11),
    refines=False,
    no_refine_reason="the multi-view fit refines the maps",
)

PAIR = CaptureKind(
    "pair",
    (FLASH_PHOTO, NO_FLASH_PHOTO),
    "a flash photo and a no-flash photo of one surface, taken from the same spot (docs/predict.md)",
    flag="--no-flash",
    flag_value="NOFLASH",
    refines=False,
    no_refine_reason="the pair fit refines the maps",
)

# Every kind, by name: predict's dispatch table and the evaluators are keyed by these names.
CAPTURE_KINDS: Mapping[str, CaptureKind] = {kind.name: kind for kind in (SINGLE_PHOTO, VIEWS, PAIR)}

# The kind the training data, the shipped generator and the evaluators read today.
TRAINING_CAPTURE = SINGLE_PHOTO


def capture_kind(name: str) -> CaptureKind:
    """The kind called ``name``, or a one-line error naming the choices."""
    try:
        return CAPTURE_KINDS[name]
    except KeyError:
        raise UserError(f"capture kind {name!r}: expected one of {', '.join(CAPTURE_KINDS)}") from None


def known_shard_members(extension: str) -> frozenset[str]:
    """Every photo member a shard of any kind may hold in a format (a reader accepts them all)."""
    return frozenset(name for kind in CAPTURE_KINDS.values() for name in kind.shard_members(extension))
