"""The on-disk dataset format: WebDataset tar shards of (flash photo, ground-truth maps, metadata,
and optionally the photo's no-flash twin), with a ``manifest.json`` per split and each shard's
SHA-256 beside it. The layout, the two sample formats (``u16z``, ``png``) and the ``.u16z`` byte
layout: docs/data.md#the-shard-format.

Both formats store the same 16-bit values, so a sample decodes to bit-identical tensors from
either; readers tell them apart per sample by the member names (:data:`FORMAT_MEMBERS`). Writing
is byte-deterministic and atomic (a temporary file moved into place), so a reader never sees a
partial shard; the recorded SHA-256 (:func:`write_digest`) catches a member corrupted in place,
which the tar headers :func:`verify_shard` reads cannot.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import struct
import tarfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import InitVar, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
import zstandard
from torch import Tensor

from brdfgan.capture import NO_FLASH_PHOTO, TRAINING_CAPTURE, known_shard_members
from brdfgan.core.checks import check_shape
from brdfgan.core.svbrdf import (
    NORMAL,
    NORMAL_UNIT_TOLERANCE,
    NUM_CHANNELS,
    InvalidMapsError,
    decode_normal,
    encode_normal,
    split_maps,
    validate_maps,
)
from brdfgan.errors import UserError
from brdfgan.io.atomic import atomic_replace, write_text_atomic

__all__ = [
    "FORMAT_MEMBERS",
    "LEGACY_SHARD_FORMAT",
    "MANIFEST_NAME",
    "OPTIONAL_MEMBERS",
    "PHOTO_CODE_TOLERANCE",
    "PNG_COMPRESSION",
    "SAMPLE_MEMBERS",
    "SHARD_FORMATS",
    "Sample",
    "ShardError",
    "ShardInfo",
    "decode_maps",
    "decode_sample",
    "digest_path",
    "encode_maps",
    "encode_sample",
    "list_shards",
    "read_digest",
    "read_manifest",
    "sample_format",
    "sha256_file",
    "shard_differences",
    "shard_path",
    "verify_shard",
    "write_digest",
    "write_manifest",
    "write_shard",
]

SHARD_FORMATS: tuple[str, ...] = ("u16z", "png")
# The format of a dataset that records none: every dataset made before u16z existed.
LEGACY_SHARD_FORMAT = "png"
# The one definition of a sample's files per format, in their order inside a shard.
# The photos' members come from the capture the data holds (brdfgan.capture: the flash photo's is
# ``input``); a member of another kind's photo is known, so that a reader accepts it.
_PHOTO = TRAINING_CAPTURE.reference.member
FORMAT_MEMBERS: Mapping[str, tuple[str, ...]] = {
    "u16z": (*TRAINING_CAPTURE.shard_members("u16z"), "maps.u16z", "meta.json"),
    "png": (
        *TRAINING_CAPTURE.shard_members("png"),
        "basecolor.png",
        "normal.png",
        "roughness.png",
        "metallic.png",
        "meta.json",
    ),
}
# The no-flash twin of a flash + no-flash pair (``dataset_spec.pairs``): a member of its own after
# the flash photo's, only in samples that have one, so a dataset without pairs keeps its bytes and
# a reader of such a dataset never looks for it.
_TWIN = NO_FLASH_PHOTO.member
OPTIONAL_MEMBERS: Mapping[str, tuple[str, ...]] = {
    extension: (f"{_TWIN}.{extension}",) for extension in SHARD_FORMATS
}
# The members of a PNG sample (the only format before u16z; kept under its old name).
SAMPLE_MEMBERS: tuple[str, ...] = FORMAT_MEMBERS["png"]
# Every kind's photos (the twin's among them) and the maps and metadata.
_KNOWN_MEMBERS = frozenset(name for names in FORMAT_MEMBERS.values() for name in names).union(
    *(known_shard_members(extension) for extension in SHARD_FORMATS)
)
MANIFEST_NAME = "manifest.json"
# Two generations of one spec write the same maps and metadata, but Mitsuba's LLVM variant renders
# a rare pixel one 16-bit code apart from run to run (the order of its parallel sums), so a shard's
# SHA-256 can differ: photos are compared within this many codes (docs/data.md#determinism).
PHOTO_CODE_TOLERANCE = 1
DIGEST_SUFFIX = ".sha256"
_HEX_DIGEST = re.compile(r"[0-9a-f]{64}")
# zlib level 1: noisy 16-bit renders barely compress further at higher levels, which encode slower
# and decode no faster (research/notes/2026-12-training-data.md has the measurements).
PNG_COMPRESSION = 1
# Run-length matching only (Z_RLE) after the Paeth row filter on every row: the filter does the
# work, long matches are rare in noisy renders, and encoding is about twice as fast as zlib's
# default matching after libpng's per-row filter search (measured: research/notes/2026-12-training-data.md).
# Lossless.
PNG_STRATEGY = cv2.IMWRITE_PNG_STRATEGY_RLE
PNG_FILTER = cv2.IMWRITE_PNG_FILTER_PAETH
# Zstandard level 1 of the shuffled bytes: the fast-decoding end of the size/speed trade-off
# (research/notes/2026-12-training-data.md compares zlib, lz4 and other levels). Readers do not depend on
# the level (a Zstandard frame describes itself).
U16Z_LEVEL = 1
_U16Z_MAGIC = b"U16Z"
_U16Z_VERSION = 1
_U16Z_HEADER = struct.Struct("<4sBBHII")  # magic, version, bytes per value, channels, height, width
# Keys become tar member names; USTAR allows 100 bytes without a directory prefix, and a dot or
# slash would confuse WebDataset's key/extension split.
KEY_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,80}")
_SCALE16 = 65535.0
_TAR_BLOCK = 512


class ShardError(UserError):
    """A sample or shard is malformed or corrupt; the message names the sample key or file."""


@dataclass(frozen=True, eq=False)  # eq=False: tensors have no boolean equality
class Sample:
    """One training sample: a flash photo of a material crop and its ground-truth maps.

    ``key`` is the WebDataset ``__key__`` (letters, digits, ``_`` and ``-``; no dots).
    ``meta`` must be JSON-serialisable (family, parameters, seed, environment id, flash
    intensity/temperature, exposure, …). The constructor validates everything; ``check=False``
    skips the tensor checks (:func:`decode_sample` uses it: decoded 16-bit values are finite and
    in [0, 1] by construction, and it checks the rest itself, at a fraction of the cost).
    ``no_flash`` is the photo's no-flash twin of a flash + no-flash pair (the same surface and
    room light with the flash off, exposed on its own; ``meta["pair"]`` says how:
    :mod:`brdfgan.data.phone.pairs`), ``None`` for a single photo.

    Shape:
        - photo: ``(3, H, W)`` floating point, linear LDR in [0, 1]
        - maps: ``(8, H, W)`` floating point, the layout of :mod:`brdfgan.core.svbrdf`
        - no_flash: ``(3, H, W)`` like ``photo``, or ``None``
    """

    key: str
    photo: Tensor
    maps: Tensor
    meta: Mapping[str, Any]
    check: InitVar[bool] = True
    # After ``check``: a positional ``check`` argument keeps its meaning.
    no_flash: Tensor | None = None

    def __post_init__(self, check: bool) -> None:
        if not isinstance(self.key, str) or not KEY_PATTERN.fullmatch(self.key):
            raise ShardError(
                f"invalid sample key {self.key!r}: use 1-80 letters, digits, '_' or '-' (no dots or slashes)"
            )
        where = f"sample {self.key!r}"
        if not isinstance(self.meta, Mapping):
            raise ShardError(f"{where}: meta must be a mapping, got {type(self.meta).__name__}")
        if not check:
            return
        if not isinstance(self.photo, Tensor):
            raise ShardError(f"{where}: photo must be a (3, H, W) tensor, got {type(self.photo).__name__}")
        check_shape(self.photo, "3 H W", name=f"{where}: photo", error=ShardError)
        if not self.photo.is_floating_point():
            raise ShardError(f"{where}: photo must be floating point, got {self.photo.dtype}")
        if not isinstance(self.maps, Tensor):
            name = type(self.maps).__name__
            raise ShardError(f"{where}: maps must be an ({NUM_CHANNELS}, H, W) tensor, got {name}")
        check_shape(self.maps, f"{NUM_CHANNELS} H W", name=f"{where}: maps", error=ShardError)
        if self.photo.shape[1:] != self.maps.shape[1:]:
            raise ShardError(
                f"{where}: photo {tuple(self.photo.shape)} and maps {tuple(self.maps.shape)} differ in size"
            )
        _check_photo(self.photo, f"{where}: photo")
        if self.no_flash is not None:
            if not isinstance(self.no_flash, Tensor) or not self.no_flash.is_floating_point():
                raise ShardError(f"{where}: no_flash must be a floating point (3, H, W) tensor or None")
            if self.no_flash.shape != self.photo.shape:
                shapes = f"{tuple(self.no_flash.shape)} and photo {tuple(self.photo.shape)}"
                raise ShardError(f"{where}: no_flash {shapes} differ in size")
            _check_photo(self.no_flash, f"{where}: no_flash")
        try:
            validate_maps(self.maps)
        except InvalidMapsError as error:
            raise ShardError(f"{where}: {error}") from error


def _check_photo(photo: Tensor, where: str) -> None:
    if not torch.isfinite(photo).all() or photo.min() < 0.0 or photo.max() > 1.0:
        raise ShardError(f"{where} must be finite linear LDR in [0, 1] (clip after exposure)")


@dataclass(frozen=True)
class ShardInfo:
    """What :func:`write_shard` wrote: the final path, sample count, file size and SHA-256 (hex)."""

    path: Path
    count: int
    bytes: int
    sha256: str


# --------------------------------------------------------------------------------------------
# One sample <-> its member files


def encode_sample(sample: Sample, shard_format: str = "png") -> dict[str, bytes]:
    """Encode a sample into its member files, keyed by the names of ``FORMAT_MEMBERS[shard_format]``
    in their order, with the no-flash twin (:data:`OPTIONAL_MEMBERS`) after the photo when the
    sample has one.

    Every channel is rounded to the nearest of 65536 levels, the same in every format, and stored
    as 16-bit PNGs (``png``) or byte-shuffled Zstandard planes (``u16z``, layout in
    docs/data.md#the-shard-format); the JSON has sorted keys and no whitespace so that equal
    metadata gives equal bytes.

    Shape:
        - sample.photo, sample.no_flash: ``(3, H, W)``; sample.maps: ``(8, H, W)``
    """
    if shard_format not in FORMAT_MEMBERS:
        raise ShardError(f"unknown shard format {shard_format!r}: expected one of {', '.join(SHARD_FORMATS)}")
    try:
        meta = json.dumps(
            sample.meta, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False
        ).encode("ascii")
    except (TypeError, ValueError) as error:
        raise ShardError(f"sample {sample.key!r}: meta is not JSON-serialisable ({error})") from error
    photo = _quantise(sample.photo)
    maps = _quantise_maps(sample.maps)
    encode = _encode_u16z if shard_format == "u16z" else _encode_png
    photos = {f"{_PHOTO}.{shard_format}": encode(photo)}
    if sample.no_flash is not None:
        photos[f"{_TWIN}.{shard_format}"] = encode(_quantise(sample.no_flash))
    if shard_format == "u16z":
        return {**photos, "maps.u16z": _encode_u16z(maps), "meta.json": meta}
    return {
        **photos,
        "basecolor.png": _encode_png(maps[0:3]),
        "normal.png": _encode_png(maps[3:6]),
        "roughness.png": _encode_png(maps[6:7]),
        "metallic.png": _encode_png(maps[7:8]),
        "meta.json": meta,
    }


def sample_format(members: Iterable[str]) -> str:
    """The format of a sample from its member names: ``u16z`` if any is a ``.u16z`` member,
    else ``png`` (what a sample of neither is reported as missing)."""
    return "u16z" if any(name.endswith(".u16z") for name in members) else "png"


def decode_sample(record: Mapping[str, Any]) -> Sample:
    """Decode a sample from its member files: the inverse of :func:`encode_sample`, for either format.

    ``record`` maps member names to bytes and ``"__key__"`` to the key, as WebDataset groups a
    sample (``"__url__"``, when present, is only used to name the shard in errors); the format is
    told from the member names (:func:`sample_format`). Normals are renormalised after
    quantisation; what decoding cannot guarantee (images of one size, normals pointing out of the
    surface, the key) is validated again, the rest holds by construction. The no-flash twin is
    read when the record holds it (``output.no_flash``; ``None`` otherwise, as for every sample
    written before pairs existed).

    Shape:
        - output.photo, output.no_flash: ``(3, H, W)`` float32; output.maps: ``(8, H, W)`` float32
    """
    key = record.get("__key__")
    where = f"sample {key!r}" + (f" in {record['__url__']}" if "__url__" in record else "")
    shard_format = sample_format(name for name in record if not name.startswith("__"))
    members = FORMAT_MEMBERS[shard_format]
    missing = [name for name in members if not isinstance(record.get(name), bytes | bytearray)]
    if missing:
        raise ShardError(f"{where}: missing member(s) {', '.join(missing)}")
    if shard_format == "u16z":
        photo = _decode_u16z(record[f"{_PHOTO}.u16z"], 3, f"{where} {_PHOTO}.u16z")
        maps = _decode_u16z(record["maps.u16z"], NUM_CHANNELS, f"{where} maps.u16z")
        images = [photo, maps]
    else:
        images = [
            _decode_png(record[name], count, f"{where} {name}")
            for name, count in zip(members[:5], (3, 3, 3, 1, 1), strict=True)
        ]
    twin_member = f"{_TWIN}.{shard_format}"
    twin = record.get(twin_member)
    no_flash = None
    if twin is not None:
        if not isinstance(twin, bytes | bytearray):
            raise ShardError(f"{where}: member {twin_member} is not bytes")
        decode = _decode_u16z if shard_format == "u16z" else _decode_png
        no_flash = decode(bytes(twin), 3, f"{where} {twin_member}")
    sizes = {image.shape[1:] for image in (*images, *([] if no_flash is None else [no_flash]))}
    if len(sizes) != 1:
        raise ShardError(f"{where}: member images differ in size {sorted(sizes)}")
    if shard_format == "png":
        photo, maps = images[0], np.concatenate(images[1:])
    try:
        meta = json.loads(record["meta.json"])
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ShardError(f"{where} meta.json: invalid JSON ({error})") from error
    if not isinstance(meta, dict):
        raise ShardError(f"{where} meta.json: expected a JSON object, got {type(meta).__name__}")
    unit_maps = _maps_from_quantised(
        maps, f"{where} {'maps.u16z' if shard_format == 'u16z' else 'normal.png'}"
    )
    try:
        return Sample(
            key=str(key),
            photo=_unit_float(photo),
            maps=unit_maps,
            meta=meta,
            check=False,
            no_flash=None if no_flash is None else _unit_float(no_flash),
        )
    except ShardError as error:
        raise ShardError(f"{where}: {error}") from error


def _quantise(image: Tensor) -> np.ndarray:
    """Values in [0, 1] rounded to the nearest of 65536 levels (the stored values of every format).

    Shape:
        - image: ``(C, H, W)``; output: ``(C, H, W)`` uint16
    """
    # float64 before scaling so that rounding to the nearest 16-bit level is exact.
    array = image.detach().to("cpu", torch.float64).numpy()
    return np.rint(np.clip(array, 0.0, 1.0) * _SCALE16).astype(np.uint16)


def _quantise_maps(maps: Tensor) -> np.ndarray:
    """The 16-bit values a map set is stored as, normals as ``(n + 1) / 2`` (one quantisation for
    every format, so their values are identical).

    Shape:
        - maps: ``(8, H, W)``; output: ``(8, H, W)`` uint16
    """
    parts = split_maps(maps)
    return _quantise(
        torch.cat([parts.basecolor, encode_normal(parts.normal), parts.roughness, parts.metallic])
    )


def _maps_from_quantised(planes: np.ndarray, where: str) -> Tensor:
    """Stored 16-bit map planes back to a map set, normals decoded and renormalised; ``where``
    names the member in the error raised for normals pointing into the surface.

    Shape:
        - planes: ``(8, H, W)`` uint16; output: ``(8, H, W)`` float32
    """
    unit_maps = _unit_float(planes)
    normal = decode_normal(unit_maps[NORMAL])
    if (normal[2] < -NORMAL_UNIT_TOLERANCE).any():
        raise ShardError(f"{where}: normals point into the surface (z < 0); not a (n + 1) / 2 map?")
    unit_maps[NORMAL] = normal
    return unit_maps


def encode_maps(maps: Tensor) -> bytes:
    """One map set as a ``.u16z`` payload (the ``maps.u16z`` member of a shard sample, alone).

    Shape:
        - maps: ``(8, H, W)``
    """
    return _encode_u16z(_quantise_maps(maps))


def decode_maps(data: bytes, where: str) -> Tensor:
    """The inverse of :func:`encode_maps`; a corrupt payload is a :class:`ShardError` naming ``where``.

    Shape:
        - output: ``(8, H, W)`` float32
    """
    return _maps_from_quantised(_decode_u16z(data, NUM_CHANNELS, where), where)


def _unit_float(planes: np.ndarray) -> Tensor:
    """Stored 16-bit values back to [0, 1] (one conversion pass, one in-place scale; shared by the
    formats so that they decode to the same bits).

    Shape:
        - planes: ``(C, H, W)`` uint16; output: ``(C, H, W)`` float32
    """
    return torch.from_numpy(planes.astype(np.float32)).div_(_SCALE16)


def _encode_png(quantised: np.ndarray) -> bytes:
    if quantised.shape[0] == 1:
        image = quantised[0]
    else:  # CHW RGB -> HWC BGR, OpenCV's channel order
        image = np.ascontiguousarray(quantised.transpose(1, 2, 0)[:, :, ::-1])
    ok, encoded = cv2.imencode(
        ".png",
        image,
        [
            cv2.IMWRITE_PNG_COMPRESSION,
            PNG_COMPRESSION,
            cv2.IMWRITE_PNG_STRATEGY,
            PNG_STRATEGY,
            cv2.IMWRITE_PNG_FILTER,
            PNG_FILTER,
        ],
    )
    if not ok:
        raise ShardError(f"PNG encoding failed for an image of shape {tuple(quantised.shape)}")
    return encoded.tobytes()


def _decode_png(data: bytes, channels: int, where: str) -> np.ndarray:
    """A 16-bit PNG member as ``(channels, H, W)`` uint16 planes in RGB order."""
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    except cv2.error as error:
        raise ShardError(f"{where}: corrupt PNG") from error
    if image is None:
        raise ShardError(f"{where}: corrupt PNG")
    if image.dtype != np.uint16:
        raise ShardError(f"{where}: expected a 16-bit PNG, got {image.dtype}")
    found = 1 if image.ndim == 2 else image.shape[2]
    if found != channels:
        raise ShardError(f"{where}: expected {channels} channel(s), got {found}")
    # cv2.split gives contiguous planes; reversed, BGR becomes RGB.
    return image[None] if image.ndim == 2 else np.stack(cv2.split(image)[::-1])


def _encode_u16z(planes: np.ndarray) -> bytes:
    """``(C, H, W)`` uint16 planes as a ``.u16z`` member (layout: docs/data.md#the-shard-format)."""
    channels, height, width = planes.shape
    value_bytes = np.ascontiguousarray(planes, dtype="<u2").view(np.uint8).reshape(-1, 2)
    shuffled = np.ascontiguousarray(value_bytes.T)  # row 0: every low byte, row 1: every high byte
    header = _U16Z_HEADER.pack(_U16Z_MAGIC, _U16Z_VERSION, 2, channels, height, width)
    compressor = zstandard.ZstdCompressor(level=U16Z_LEVEL, write_checksum=True, write_content_size=True)
    return header + compressor.compress(shuffled.data)


def _decode_u16z(data: bytes, channels: int, where: str) -> np.ndarray:
    """A ``.u16z`` member as ``(channels, H, W)`` uint16 planes."""
    if len(data) < _U16Z_HEADER.size:
        raise ShardError(f"{where}: corrupt u16z (truncated header, {len(data)} bytes)")
    magic, version, value_size, found, height, width = _U16Z_HEADER.unpack_from(data)
    if magic != _U16Z_MAGIC or version != _U16Z_VERSION or value_size != 2:
        raise ShardError(f"{where}: corrupt u16z (not a version {_U16Z_VERSION} uint16 header)")
    if found != channels:
        raise ShardError(f"{where}: expected {channels} channel(s), got {found}")
    expected = 2 * channels * height * width
    payload = memoryview(data)[_U16Z_HEADER.size :]
    try:
        # Checked before decompressing: a damaged header must not ask for gigabytes.
        if zstandard.frame_content_size(payload) != expected or expected == 0:
            raise ShardError(
                f"{where}: corrupt u16z (payload size does not match {channels}x{height}x{width})"
            )
        # A fresh context per call (~10 µs): contexts must not be shared between threads.
        shuffled = zstandard.ZstdDecompressor().decompress(payload)
    except zstandard.ZstdError as error:
        raise ShardError(f"{where}: corrupt u16z ({error})") from error
    halves = np.frombuffer(shuffled, dtype=np.uint8).reshape(2, 1, -1)
    # cv2.merge interleaves the low and high byte rows back into values, far faster than a NumPy
    # transpose copy (docs/data.md#the-shard-format); little-endian pairs viewed as uint16 on a
    # little-endian host.
    values = cv2.merge([halves[0], halves[1]]).view("<u2").reshape(channels, height, width)
    return values.astype(np.uint16, copy=False)


# --------------------------------------------------------------------------------------------
# Shards


def shard_path(root: str | os.PathLike[str], split: str, index: int) -> Path:
    """``root/<split>/<split>-<index:06d>.tar``."""
    if index < 0:
        raise ValueError(f"shard index must be >= 0, got {index}")
    return Path(root) / split / f"{split}-{index:06d}.tar"


def list_shards(root: str | os.PathLike[str], split: str) -> list[Path]:
    """The shards of a split, sorted by name (temporary files are hidden and never listed)."""
    return sorted((Path(root) / split).glob(f"{split}-[0-9][0-9][0-9][0-9][0-9][0-9].tar"))


def write_shard(
    path: str | os.PathLike[str], samples: Iterable[Sample], *, shard_format: str = "png"
) -> ShardInfo:
    """Write ``samples`` to a WebDataset tar shard at ``path``, atomically and byte-deterministically.

    The samples are encoded one at a time in ``shard_format`` (:data:`SHARD_FORMATS`; dataset
    generation passes its spec's, ``u16z`` for new datasets), so the iterable may be a generator
    that renders them. If it raises, nothing is left behind (an existing shard at ``path`` is
    kept). The parent directory is created if needed. Duplicate keys raise :class:`ShardError`.
    """
    if shard_format not in FORMAT_MEMBERS:
        raise ShardError(f"unknown shard format {shard_format!r}: expected one of {', '.join(SHARD_FORMATS)}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    keys: set[str] = set()
    # "x": exclusive create, never clobbers; the mode follows the umask (mkstemp would force 0o600).
    with (
        atomic_replace(path) as temp,
        temp.open("xb") as handle,
        tarfile.open(fileobj=handle, mode="w", format=tarfile.USTAR_FORMAT) as tar,
    ):
        for sample in samples:
            if not isinstance(sample, Sample):
                raise ShardError(f"{path}: expected Sample objects, got {type(sample).__name__}")
            if sample.key in keys:
                raise ShardError(f"{path}: duplicate sample key {sample.key!r}")
            keys.add(sample.key)
            for member, data in encode_sample(sample, shard_format).items():
                _add_member(tar, f"{sample.key}.{member}", data)
    return ShardInfo(path=path, count=len(keys), bytes=path.stat().st_size, sha256=sha256_file(path))


def _add_member(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    # Every header field that could vary between runs or machines is pinned.
    info = tarfile.TarInfo(name)
    info.size = len(data)
    info.mtime = 0
    info.mode = 0o644
    info.uid = info.gid = 0
    info.uname = info.gname = ""
    info.type = tarfile.REGTYPE
    tar.addfile(info, io.BytesIO(data))  # BytesIO shares the bytes, no copy


def sha256_file(path: str | os.PathLike[str]) -> str:
    """The SHA-256 (hex) of a file's bytes, read in 1 MiB chunks."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as handle:
        while chunk := handle.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def digest_path(shard: str | os.PathLike[str]) -> Path:
    """Where a shard's SHA-256 is recorded: ``<shard>.sha256`` beside it."""
    shard = Path(shard)
    return shard.with_name(shard.name + DIGEST_SUFFIX)


def write_digest(shard: str | os.PathLike[str], sha256: str) -> Path:
    """Record ``sha256`` as the digest of ``shard`` (atomically, ``sha256sum``'s line format)."""
    if not _HEX_DIGEST.fullmatch(sha256):
        raise ValueError(f"not a lowercase hex SHA-256: {sha256!r}")
    return write_text_atomic(digest_path(shard), f"{sha256}  {Path(shard).name}\n")


def read_digest(shard: str | os.PathLike[str]) -> str | None:
    """The recorded SHA-256 of ``shard``, or ``None`` when none was recorded.

    Raises:
        ShardError: naming the record, when it is unreadable or not a digest of this shard.
    """
    path = digest_path(shard)
    try:
        text = path.read_text(encoding="ascii")
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as error:
        raise ShardError(f"{path}: unreadable checksum record ({error})") from error
    digest, _, name = text.strip().partition("  ")
    if not _HEX_DIGEST.fullmatch(digest) or name != Path(shard).name:
        raise ShardError(f"{path}: malformed checksum record (expected '<sha256>  {Path(shard).name}')")
    return digest


def verify_shard(path: str | os.PathLike[str], *, decode: bool = False) -> int:
    """Check that a shard is complete and well formed; return its sample count.

    By default only the tar headers are read (seeking over the data, so it is cheap even for
    large shards): every member must be a regular file named ``<key>.<member>`` with a known
    member name, the members of a sample must be contiguous and complete in one format, every member's data
    must lie inside the file, and the archive must end with its end-of-archive marker (so a
    shard cut at a member boundary is caught too). With ``decode=True`` every sample is also
    read and decoded with :func:`decode_sample` (slow; for a one-off integrity check).

    Raises:
        ShardError: naming the file, on truncation, corruption or a malformed layout.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
        with tarfile.open(path, mode="r:") as tar:
            return _scan_members(tar, path, size, decode)
    except (tarfile.TarError, OSError, EOFError) as error:
        raise ShardError(f"{path}: unreadable or corrupt tar ({error})") from error


def iter_shard(path: str | os.PathLike[str]) -> Iterator[Sample]:
    """The decoded samples of one shard, in file order (for tools: contact sheets, converters,
    tests; training streams through :mod:`brdfgan.data.loading.datamodule`).

    Raises:
        ShardError: naming the file, when it is unreadable or a sample is malformed.
    """
    path = Path(path)
    try:
        with tarfile.open(path, mode="r:") as tar:
            key: str | None = None
            record: dict[str, Any] = {}
            for info in tar:
                stem, _, member = info.name.partition(".")
                if stem != key and key is not None:
                    yield decode_sample({"__key__": key, "__url__": str(path), **record})
                    record = {}
                key = stem
                record[member] = _read_member(tar, info, path)
            if key is not None:
                yield decode_sample({"__key__": key, "__url__": str(path), **record})
    except (tarfile.TarError, OSError, EOFError) as error:
        raise ShardError(f"{path}: unreadable or corrupt tar ({error})") from error


def shard_differences(
    first: str | os.PathLike[str], second: str | os.PathLike[str], photo_codes: int = PHOTO_CODE_TOLERANCE
) -> list[str]:
    """How two shards of the same samples differ beyond the generation's tolerance, one line per
    difference (empty when they agree): keys, maps and metadata exactly, photos (and no-flash
    twins, which both must have or lack) within ``photo_codes`` 16-bit codes per channel
    (:data:`PHOTO_CODE_TOLERANCE`).

    Raises:
        ShardError: naming the file, when either is unreadable or a sample is malformed.
    """
    differences: list[str] = []
    ours, theirs = list(iter_shard(first)), list(iter_shard(second))
    if [s.key for s in ours] != [s.key for s in theirs]:
        return [f"{first} and {second} hold different samples"]
    for a, b in zip(ours, theirs, strict=True):
        if dict(a.meta) != dict(b.meta):
            differences.append(f"sample {a.key!r}: metadata differs")
        if a.maps.shape != b.maps.shape or not torch.equal(a.maps, b.maps):
            differences.append(f"sample {a.key!r}: maps differ")
        differences += _photo_difference(a.key, "photos", a.photo, b.photo, photo_codes)
        if (a.no_flash is None) != (b.no_flash is None):
            differences.append(f"sample {a.key!r}: only one has a no-flash twin")
        elif a.no_flash is not None and b.no_flash is not None:
            differences += _photo_difference(a.key, "no-flash twins", a.no_flash, b.no_flash, photo_codes)
    return differences


def _photo_difference(key: str, what: str, first: Tensor, second: Tensor, photo_codes: int) -> list[str]:
    """A line when two photos of sample ``key`` differ in size or by more than ``photo_codes``."""
    if first.shape != second.shape:
        return [f"sample {key!r}: {what} differ in size"]
    codes = np.abs(_quantise(first).astype(np.int32) - _quantise(second).astype(np.int32)).max()
    if codes > photo_codes:
        return [f"sample {key!r}: {what} differ by {codes} codes (tolerance {photo_codes})"]
    return []


def _scan_members(tar: tarfile.TarFile, path: Path, size: int, decode: bool) -> int:
    seen: set[str] = set()
    key: str | None = None
    record: dict[str, Any] = {}
    count = 0
    for info in tar:
        member = _check_member(info, path, size)
        stem = info.name.partition(".")[0]
        if stem != key:
            if key is not None:
                _check_sample(path, key, record, decode)
                count += 1
            if stem in seen:
                raise ShardError(f"{path}: members of sample {stem!r} are not contiguous")
            seen.add(stem)
            key, record = stem, {}
        if member in record:
            raise ShardError(f"{path}: duplicate member {info.name!r}")
        record[member] = _read_member(tar, info, path) if decode else b""
    _check_end_of_archive(tar, path)
    if key is not None:
        _check_sample(path, key, record, decode)
        count += 1
    return count


def _check_member(info: tarfile.TarInfo, path: Path, size: int) -> str:
    """The member name (after the key) of a shard's tar entry, which must be a known member's
    regular file lying inside the file."""
    _, dot, member = info.name.partition(".")
    if not info.isreg() or not dot or member not in _KNOWN_MEMBERS:
        raise ShardError(f"{path}: unexpected member {info.name!r}")
    if info.offset_data + info.size > size:
        raise ShardError(f"{path}: truncated shard (member {info.name!r} extends past the end of file)")
    return member


def _check_sample(path: Path, key: str, record: dict[str, Any], decode: bool) -> None:
    """A sample's members are exactly one format's, its optional ones aside (and decode, with
    ``decode``)."""
    shard_format = sample_format(record)
    members = FORMAT_MEMBERS[shard_format]
    mixed = [name for name in record if name not in members + OPTIONAL_MEMBERS[shard_format]]
    if mixed:
        raise ShardError(f"{path}: sample {key!r} mixes formats ({', '.join(mixed)} beside {members[0]})")
    missing = [name for name in members if name not in record]
    if missing:
        raise ShardError(f"{path}: sample {key!r} lacks member(s) {', '.join(missing)}")
    if decode:
        decode_sample({"__key__": key, "__url__": str(path), **record})


def _check_end_of_archive(tar: tarfile.TarFile, path: Path) -> None:
    # tarfile stops quietly at a damaged header past the first one and at a file cut between
    # members; both leave no end-of-archive marker (two zero blocks) where iteration stopped.
    assert tar.fileobj is not None
    tar.fileobj.seek(tar.offset)
    trailer = tar.fileobj.read(2 * _TAR_BLOCK)
    if len(trailer) < 2 * _TAR_BLOCK or trailer.count(0) != len(trailer):
        raise ShardError(f"{path}: truncated or corrupt shard (no end-of-archive marker after member data)")


def _read_member(tar: tarfile.TarFile, info: tarfile.TarInfo, path: Path) -> bytes:
    handle = tar.extractfile(info)
    if handle is None:
        raise ShardError(f"{path}: cannot read member {info.name!r}")
    return handle.read()


# --------------------------------------------------------------------------------------------
# Manifest


def write_manifest(root: str | os.PathLike[str], split: str, manifest: Mapping[str, Any]) -> Path:
    """Write ``root/<split>/manifest.json`` atomically (sorted keys, indent 2); return its path.

    The content is the caller's (counts, configuration, code version, shard checksums…).
    """
    path = Path(root) / split / MANIFEST_NAME
    try:
        text = json.dumps(manifest, sort_keys=True, indent=2, ensure_ascii=False, allow_nan=False) + "\n"
    except (TypeError, ValueError) as error:
        raise ShardError(f"{path}: manifest is not JSON-serialisable ({error})") from error
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_text_atomic(path, text)


def read_manifest(root: str | os.PathLike[str], split: str) -> dict[str, Any]:
    """Read ``root/<split>/manifest.json``; :class:`ShardError` if it is missing or not a JSON object."""
    path = Path(root) / split / MANIFEST_NAME
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as error:
        raise ShardError(f"{path}: manifest not found") from error
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ShardError(f"{path}: unreadable manifest ({error})") from error
    if not isinstance(manifest, dict):
        raise ShardError(f"{path}: manifest must be a JSON object, got {type(manifest).__name__}")
    return manifest
