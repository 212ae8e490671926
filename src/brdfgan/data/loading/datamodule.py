"""Streaming ``LightningDataModule`` over the WebDataset shards of :mod:`brdfgan.data.storage.shards`.
What a batch holds, epochs, shuffling, resuming, validation subsets, fewer shards than workers,
the simulated phone and skipped data: docs/data.md#loading.

The contract: every rank yields exactly :attr:`ShardDataModule.train_batches_per_epoch` full
batches per training epoch, so DDP ranks never wait on each other; the training stream is a pure
function of ``(seed, epoch, rank, worker)``, so a resumed run sees the samples an uninterrupted one
would, in the same order; validation and test read every sample once, in a fixed order. Damaged
shards and samples are skipped with a :class:`ShardWarning` and counted in
:attr:`ShardDataModule.skipped`, across worker processes.
"""

from __future__ import annotations

import hashlib
import logging
import multiprocessing
import random
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass
from itertools import count, islice
from pathlib import Path
from typing import Any, cast

import lightning as L
import torch
import webdataset as wds
from lightning.pytorch.loops.progress import _ProcessedTracker
from torch.utils.data import DataLoader, IterableDataset, get_worker_info

from brdfgan.capture import NO_FLASH_PHOTO, TRAINING_CAPTURE
from brdfgan.core.flash_geometry import pixel_scale
from brdfgan.core.render import FlashCapture
from brdfgan.data.phone.conditions import sample_as_photographed
from brdfgan.data.phone.pairs import pair_batch, pair_record, sensed_pair_meta, twin_sensor
from brdfgan.data.phone.sensor import SensorEffects
from brdfgan.data.storage.shards import (
    MANIFEST_NAME,
    Sample,
    ShardError,
    decode_sample,
    list_shards,
    read_manifest,
    verify_shard,
)
from brdfgan.data.storage.spec_checks import DatasetConfigError
from brdfgan.metrics import hotspot_centres, stored_photo_size

__all__ = [
    "EpochStream",
    "ShardDataModule",
    "ShardStream",
    "ShardWarning",
    "SkipStats",
    "collate_samples",
    "sensed_sample",
]

log = logging.getLogger(__name__)

# Samples collected before the shuffle buffer starts yielding (webdataset's default is 100).
SHUFFLE_INITIAL = 100
_KINDS = ("train", "val", "test")


class ShardWarning(UserWarning):
    """A shard or sample was skipped, or the shard count does not suit the ranks and workers."""


@dataclass(frozen=True)
class SkipStats:
    """What was skipped so far: ``shards`` excluded by the structural check in ``setup``,
    ``samples`` that failed to decode while streaming, and other streaming ``errors`` (read
    failures in shards that passed the check; one damaged shard may report more than one)."""

    shards: int = 0
    samples: int = 0
    errors: int = 0

    @property
    def total(self) -> int:
        return self.shards + self.samples + self.errors


@dataclass(frozen=True)
class _SplitIndex:
    """The valid shards of a split (as strings for webdataset) and their sample counts."""

    urls: tuple[str, ...]
    counts: tuple[int, ...]

    @property
    def total(self) -> int:
        return sum(self.counts)


class _SkipCounter:
    """Skip counts shared with DataLoader worker processes.

    Shared memory without a lock: every (loader, worker) pair writes only its own slot, so no
    increment races; the main process sums the slots.
    """

    def __init__(self, num_workers: int) -> None:
        self._slots = num_workers + 1  # slot 0: the main process (num_workers = 0)
        self._values = multiprocessing.RawArray("q", len(_KINDS) * self._slots * 2)

    def add(self, kind: str, field: int, amount: int = 1) -> None:
        info = get_worker_info()
        slot = 0 if info is None else min(1 + info.id, self._slots - 1)
        self._values[(_KINDS.index(kind) * self._slots + slot) * 2 + field] += amount

    def totals(self) -> tuple[int, int]:
        return sum(self._values[0::2]), sum(self._values[1::2])


_SAMPLES, _ERRORS = 0, 1


def collate_samples(samples: Sequence[Sample]) -> dict[str, Any]:
    """Stack samples into a batch dict; ``meta`` stays a list of dicts. When every sample has a
    no-flash twin, the batch holds the pair too: the twins under ``NO_FLASH_PHOTO.batch_key``
    (``photo_noflash``) and :func:`~brdfgan.data.phone.pairs.pair_batch`'s tensors; otherwise
    (any single photo among them) it is the single-photo batch.

    Shape:
        - output["photo"]: ``(B, 3, H, W)`` float32; output["maps"]: ``(B, 8, H, W)`` float32
        - output["key"]: list of B str; output["meta"]: list of B dict
        - pairs: output["photo_noflash"]: ``(B, 3, H, W)`` float32; output["exposure_ratio"]:
          ``(B,)``; output["white_balance"]: ``(B, 2, 3)`` (flash shot, no-flash shot)
    """
    if not samples:
        raise ValueError("cannot collate an empty list of samples")
    sizes = {tuple(sample.photo.shape[1:]) for sample in samples}
    if len(sizes) != 1:
        keys = ", ".join(sample.key for sample in samples)
        raise ShardError(
            f"samples of different sizes {sorted(sizes)} in one batch ({keys}); regenerate the data"
        )
    meta = [dict(sample.meta) for sample in samples]
    height, width = samples[0].photo.shape[-2:]
    batch = {
        # The flash photo under its batch key (brdfgan.capture: what a batch of the capture holds).
        TRAINING_CAPTURE.reference.batch_key: torch.stack([sample.photo for sample in samples]).float(),
        "maps": torch.stack([sample.maps for sample in samples]).float(),
        "flash": flash_frames(meta, height, width),
        "key": [sample.key for sample in samples],
        "meta": meta,
    }
    twins = [sample.no_flash for sample in samples if sample.no_flash is not None]
    if len(twins) == len(samples):
        batch[NO_FLASH_PHOTO.batch_key] = torch.stack(twins).float()
        batch.update(pair_batch(meta, [sample.key for sample in samples]))
    return batch


# Samples without meta["capture"] come from datasets made before the capture randomisation, all
# photographed by the nominal FlashCapture (camera centred, flash at the lens).
LEGACY_FOV_DEG = FlashCapture().fov_deg


def flash_frames(meta: Sequence[Mapping[str, Any]], height: int, width: int) -> torch.Tensor:
    """The :mod:`flash frame <brdfgan.core.flash_geometry>` of every sample of a batch.

    The hotspot is :func:`~brdfgan.metrics.hotspot_centres` (the recorded ``hotspot_px``, shifted by
    a ``train_crop``); the scale comes from the recorded ``capture.fov_deg`` (else the nominal
    capture's) across the stored photo's width (:func:`~brdfgan.metrics.stored_photo_size`).

    Shape:
        - output: ``(B, 3)`` float32
    """
    centres = hotspot_centres(meta, height, width)
    scales = []
    for index, sample in enumerate(meta):
        capture = sample.get("capture")
        fov = capture.get("fov_deg", LEGACY_FOV_DEG) if isinstance(capture, Mapping) else LEGACY_FOV_DEG
        photo_width, _ = stored_photo_size(sample, index, height, width)
        scales.append(pixel_scale(float(fov), photo_width))
    return torch.cat([centres, torch.tensor(scales, dtype=torch.float64)[:, None]], dim=1).float()


def sensed_sample(sample: Sample, sensor: SensorEffects, seed: int) -> Sample:
    """The sample with ``sensor`` applied to its photo, seeded by ``seed``, under the flash colour
    its meta records (for the auto white balance; ``None`` if it records none); what was drawn in
    ``meta["sensor"]``.

    A no-flash twin gets the sensor too, seeded from ``seed`` on its own, through the flash shot's
    lens and file type (:func:`~brdfgan.data.phone.pairs.twin_sensor`) and without the auto white
    balance to the flash (it shows no flash); what was drawn goes in ``meta["sensor_noflash"]`` and
    ``meta["pair"]`` takes the sensor's exposures and gains in
    (:func:`~brdfgan.data.phone.pairs.sensed_pair_meta`)."""
    photo, record = sensor.apply(
        sample.photo,
        torch.Generator().manual_seed(seed),
        illuminant_rgb=sensor.flash_illuminant(sample.meta),
    )
    meta = {**sample.meta, "sensor": record}
    no_flash = sample.no_flash
    if no_flash is not None:
        no_flash, twin_record = twin_sensor(sensor, record).apply(
            no_flash, torch.Generator().manual_seed(_mix(seed, "no_flash"))
        )
        meta["sensor_noflash"] = twin_record
        meta["pair"] = sensed_pair_meta(pair_record(sample.meta, sample.key), record, twin_record)
    return Sample(sample.key, photo, sample.maps, meta, check=False, no_flash=no_flash)


class EpochStream(IterableDataset):
    """An iterable dataset that counts its passes, so that each pass is an epoch of its own.

    ``epoch`` counts the iterations of this copy of the dataset: in the main process (no workers)
    or in a persistent worker, which keeps its copy between epochs. ``skip_batches`` is how many
    batches of the next epoch were already trained on (a resumed run); it applies once.
    """

    def __init__(self) -> None:
        super().__init__()
        self.epoch = 0
        self.skip_batches = 0

    def _begin_epoch(self) -> tuple[int, int, int, int]:
        """``(worker, num_workers, epoch, skip)`` of the pass now starting; counts it."""
        info = get_worker_info()
        worker, num_workers = (0, 1) if info is None else (info.id, info.num_workers)
        epoch, skip = self.epoch, self.skip_batches
        self.epoch += 1
        self.skip_batches = 0
        return worker, num_workers, epoch, skip


class ShardStream(EpochStream):
    """Batches of one split for one rank; the splitting rules: docs/data.md#loading.

    ``kind="train"``: infinite shuffled stream cut to ``batches_per_epoch`` full batches per
    epoch (summed over the DataLoader workers). ``"val"``/``"test"``: one pass in shard order,
    the last batch of each worker may be partial, at most ``max_samples`` samples over all ranks.

    ``len()`` is the number of batches the DataLoader yields per epoch (so progress bars show a
    total); ``num_workers`` must be the DataLoader's (``max(1, DataLoader num_workers)``). For
    val/test it comes from the per-shard counts taken in ``setup``: samples skipped while
    streaming (corrupt or unreadable) make the real count smaller, so it is then an upper bound.

    Shape:
        - each item: the dict of :func:`collate_samples` with ``B <= batch_size``
    """

    def __init__(
        self,
        index: _SplitIndex,
        *,
        kind: str,
        batch_size: int,
        rank: int,
        world_size: int,
        seed: int,
        counter: _SkipCounter,
        shuffle_buffer: int = 0,
        batches_per_epoch: int | None = None,
        max_samples: int | None = None,
        crop: int | None = None,
        sensor: SensorEffects | None = None,
        align_maps: bool = True,
        num_workers: int = 1,
    ) -> None:
        super().__init__()
        if kind not in _KINDS:
            raise ValueError(f"kind must be one of {_KINDS}, got {kind!r}")
        if kind == "train" and batches_per_epoch is None:
            raise ValueError("a train stream needs batches_per_epoch")
        self.index = index
        self.kind = kind
        self.batch_size = batch_size
        self.rank = rank
        self.world_size = world_size
        self.seed = seed
        self.counter = counter
        self.shuffle_buffer = shuffle_buffer
        self.batches_per_epoch = batches_per_epoch
        self.max_samples = max_samples
        self.crop = crop
        self.sensor = sensor if sensor is not None and sensor.enabled else None
        self.align_maps = align_maps
        # Only for __len__: the iteration reads the worker count from the DataLoader's workers.
        self.num_workers = num_workers

    def __len__(self) -> int:
        if self.kind == "train":
            # Exact for every epoch but the first after a resume, which skips the batches already
            # trained on; Lightning's bar then starts at the restored batch index, so the total
            # it shows stays right.
            assert self.batches_per_epoch is not None
            return self.batches_per_epoch
        # Each worker batches its own samples, so each may end with a partial batch.
        return sum(-(-samples // self.batch_size) for samples in self._eval_samples(self.num_workers))

    def __iter__(self) -> Iterator[dict[str, Any]]:
        worker, num_workers, epoch, skip = self._begin_epoch()
        if self.kind == "train":
            return self._train_batches(epoch, worker, num_workers, skip)
        return self._eval_batches(worker, num_workers)

    # -- train ----------------------------------------------------------------------------

    def _train_batches(
        self, epoch: int, worker: int, num_workers: int, skip: int = 0
    ) -> Iterator[dict[str, Any]]:
        """This worker's batches of ``epoch``, after the first ``skip`` batches the DataLoader
        would have yielded (over all its workers) this epoch."""
        assert self.batches_per_epoch is not None
        split = len(self.index.urls) >= self.world_size * num_workers
        if split:
            # This rank's batches go to its workers in proportion to the samples they hold.
            order = _permuted(self.index, _mix(self.seed, epoch, 0))
            held = [
                sum(_take(order.counts, self.rank, self.world_size, w, num_workers))
                for w in range(num_workers)
            ]
        else:
            held = [1] * num_workers
        quotas = _apportion(self.batches_per_epoch, held)
        samples = self._train_samples(epoch, worker, num_workers, split)
        batches = islice(_batches(samples, self.batch_size, partial=False), quotas[worker])
        # The batches are produced (not just counted) so the shuffle buffer and crop draws
        # reach the same state as in the uninterrupted run.
        return islice(batches, _round_robin_share(quotas, skip)[worker], None)

    def _train_samples(self, epoch: int, worker: int, num_workers: int, split: bool) -> Iterator[Sample]:
        for repeat in count():
            if split:  # same permutation everywhere, so the split stays a partition
                order = _permuted(self.index, _mix(self.seed, epoch, repeat))
            else:  # every worker reads everything, each in its own order
                order = _permuted(self.index, _mix(self.seed, epoch, repeat, self.rank, worker))
            records = self._records(order.urls, split_ranks=split, split_workers=split)
            if self.shuffle_buffer > 1:
                rng = random.Random(_mix(self.seed, epoch, repeat, self.rank, worker, 1))
                initial = min(SHUFFLE_INITIAL, self.shuffle_buffer)
                records = wds.shuffle(self.shuffle_buffer, initial, rng=rng)(records)
            delivered = 0
            crop_rng = random.Random(_mix(self.seed, epoch, repeat, self.rank, worker, 2))
            for sample in self._decode(records):
                delivered += 1
                if self.sensor is not None:
                    sample = self._sensed(sample, _mix(self.seed, "sensor", epoch, repeat, sample.key))
                yield sample if self.crop is None else random_crop(sample, self.crop, crop_rng)
            if delivered == 0:
                warnings.warn(
                    f"train worker {worker} of rank {self.rank} got no readable sample from its shards; "
                    "it stops early and this epoch is shorter",
                    ShardWarning,
                    stacklevel=1,
                )
                return

    # -- val / test -----------------------------------------------------------------------

    @property
    def _eval_split_ranks(self) -> bool:
        """Whether the ranks split the shards (else every rank evaluates all of them)."""
        return len(self.index.urls) >= self.world_size

    def _eval_samples(self, num_workers: int) -> list[int]:
        """The samples each of this rank's ``num_workers`` workers streams in one val/test pass,
        from the per-shard counts of ``setup`` (fewer if some fail to decode)."""
        rank, world_size = (self.rank, self.world_size) if self._eval_split_ranks else (0, 1)
        held = [
            sum(_take(self.index.counts, r, world_size, w, num_workers))
            for r in range(world_size)
            for w in range(num_workers)
        ]
        if self.max_samples is not None:
            # Quotas over all ranks' workers, computed the same way everywhere: a fixed subset.
            held = _fill(self.max_samples, held)
        return held[rank * num_workers : (rank + 1) * num_workers]

    def _eval_batches(self, worker: int, num_workers: int) -> Iterator[dict[str, Any]]:
        records = self._records(self.index.urls, split_ranks=self._eval_split_ranks, split_workers=True)
        samples = self._decode(records)
        if self.max_samples is not None:
            samples = islice(samples, self._eval_samples(num_workers)[worker])
        if self.sensor is not None:  # the same draws every epoch: comparable metrics
            # Seeded by the key alone: runs of every seed are measured on the same photos.
            samples = (self._sensed(sample, _mix("sensor", sample.key)) for sample in samples)
        return _batches(samples, self.batch_size, partial=True)

    # -- shared ---------------------------------------------------------------------------

    def _records(self, urls: Sequence[str], *, split_ranks: bool, split_workers: bool) -> Iterator[dict]:
        dataset = wds.WebDataset(
            list(urls),
            handler=self._stream_error,
            # The list comes permuted (train) or in order (val/test); webdataset's own shuffle
            # would permute after the split, with the same seed every epoch.
            shardshuffle=False,
            nodesplitter=self._split_by_rank if split_ranks else None,
            workersplitter=wds.split_by_worker if split_workers else None,
            # A rank or worker left without a shard yields nothing instead of raising "No samples
            # found in dataset": too few shards are handled (and warned about) by the caller.
            empty_check=False,
        )
        return iter(dataset)

    def _split_by_rank(self, source: Iterator[dict]) -> Iterator[dict]:
        # Like wds.split_by_node, but with the rank stored at setup: split_by_node asks
        # torch.distributed inside the worker, which spawned workers have not initialised, so
        # every rank would read every shard.
        yield from islice(source, self.rank, None, self.world_size)

    def _stream_error(self, error: Exception) -> bool:
        shard = next((arg for arg in error.args if isinstance(arg, str) and arg.endswith(".tar")), "a shard")
        detail = error.args[0] if error.args else ""
        warnings.warn(
            f"skipping unreadable data in {shard}: {type(error).__name__}: {detail}",
            ShardWarning,
            stacklevel=1,
        )
        self.counter.add(self.kind, _ERRORS)
        return True  # continue with the next member or shard

    def _sensed(self, sample: Sample, seed: int) -> Sample:
        assert self.sensor is not None
        return sensed_sample(sample, self.sensor, seed)

    def _decode(self, records: Iterator[dict]) -> Iterator[Sample]:
        for record in records:
            try:
                sample = decode_sample(record)
            except ShardError as error:
                warnings.warn(f"skipping a corrupt sample: {error}", ShardWarning, stacklevel=1)
                self.counter.add(self.kind, _SAMPLES)
                continue
            yield sample_as_photographed(sample) if self.align_maps else sample


def random_crop(sample: Sample, size: int, rng: random.Random) -> Sample:
    """A ``size``² window of a sample at a uniformly random position (photo and maps alike).

    The generator is fully convolutional, so training on crops of the rendered photos is
    training on smaller photos with the flash hotspot anywhere in (or outside) the window.
    ``meta["train_crop"]`` records the window as ``[x, y, size]`` and ``meta["photo_size"]`` the
    sample's ``[width, height]`` before the crop (the flash frame's scale needs it). A no-flash
    twin is cut at the same window.

    Shape:
        - sample.photo: ``(3, H, W)``, sample.maps: ``(8, H, W)`` with ``H, W >= size``
        - output: the same with ``H = W = size``
    """
    height, width = sample.photo.shape[-2:]
    if size > min(height, width):
        raise ShardError(f"train crop {size} is larger than sample {sample.key} ({height}x{width})")
    y = rng.randrange(height - size + 1)
    x = rng.randrange(width - size + 1)
    window = (..., slice(y, y + size), slice(x, x + size))
    meta = {**sample.meta, "train_crop": [x, y, size], "photo_size": [width, height]}
    no_flash = None if sample.no_flash is None else sample.no_flash[window]
    return Sample(sample.key, sample.photo[window], sample.maps[window], meta, check=False, no_flash=no_flash)


def _batches(samples: Iterator[Sample], batch_size: int, *, partial: bool) -> Iterator[dict[str, Any]]:
    while batch := list(islice(samples, batch_size)):
        if len(batch) < batch_size and not partial:
            return
        yield collate_samples(batch)


def _round_robin_share(quotas: Sequence[int], first: int) -> list[int]:
    """How many of the DataLoader's first ``first`` batches come from each worker.

    A DataLoader takes batches from its workers in turn, leaving out a worker once it is
    exhausted; worker ``w`` yields ``quotas[w]`` batches.
    """
    taken = [0] * len(quotas)
    remaining = first
    for turn in range(max(quotas, default=0)):
        for worker, quota in enumerate(quotas):
            if remaining == 0:
                return taken
            if turn < quota:
                taken[worker] += 1
                remaining -= 1
    return taken


def _mix(*parts: int | str) -> int:
    """A 64-bit seed from integers and strings, stable across processes and Python versions."""
    return int.from_bytes(hashlib.sha256(repr(parts).encode()).digest()[:8], "little")


def _permuted(index: _SplitIndex, seed: int) -> _SplitIndex:
    order = list(range(len(index.urls)))
    random.Random(seed).shuffle(order)
    return _SplitIndex(tuple(index.urls[i] for i in order), tuple(index.counts[i] for i in order))


def _take(items: Sequence[int], rank: int, world_size: int, worker: int, num_workers: int) -> Sequence[int]:
    """The items rank ``rank``'s worker ``worker`` gets: webdataset's two ``islice`` splits."""
    return items[rank::world_size][worker::num_workers]


def _apportion(total: int, weights: Sequence[int]) -> list[int]:
    """Split ``total`` into integers proportional to ``weights`` (largest remainder)."""
    weight_sum = sum(weights)
    if weight_sum == 0:
        return [0] * len(weights)
    exact = [total * w / weight_sum for w in weights]
    shares = [int(x) for x in exact]
    by_remainder = sorted(range(len(weights)), key=lambda i: (shares[i] - exact[i], i))
    for i in by_remainder[: total - sum(shares)]:
        shares[i] += 1
    return shares


def _fill(total: int, capacities: Sequence[int]) -> list[int]:
    """Spread ``total`` as evenly as possible over bins of the given capacities (water filling)."""
    quotas = [0] * len(capacities)
    left = min(total, sum(capacities))
    open_bins = [i for i, c in enumerate(capacities) if c > 0]
    while left > 0:
        share = max(1, left // len(open_bins))
        for i in list(open_bins):
            take = min(share, capacities[i] - quotas[i], left)
            quotas[i] += take
            left -= take
            if quotas[i] == capacities[i]:
                open_bins.remove(i)
            if left == 0:
                break
    return quotas


class ShardDataModule(L.LightningDataModule):
    """Train/val/test loaders streaming ``data_dir/<split>/<split>-NNNNNN.tar`` shards.

    Args:
        data_dir: dataset root holding one folder per split.
        batch_size: samples per batch (per rank).
        num_workers: DataLoader worker processes per rank.
        shuffle_buffer: undecoded samples each train worker shuffles among (0 or 1: no shuffle).
        train_split, val_split, test_split: folder names; ``None`` disables that split.
        val_samples: cap on validation samples (a fixed subset), ``None`` for all.
        seed: seed of the shard permutations and shuffle buffers (mixed with epoch, rank, worker).
        pin_memory: DataLoader ``pin_memory`` (page-locked batches: faster, asynchronous copies
            to a GPU; nothing to gain on CPU).
        prefetch_factor: batches each worker decodes ahead (DataLoader ``prefetch_factor``; only
            with workers, ``None``: PyTorch's default of 2).
        epoch_samples: samples per training epoch over all ranks; default: the valid samples in
            the train split (counted in ``setup``).
        train_crop: train on random ``train_crop``² windows of each sample (see
            :func:`random_crop`), e.g. 128² crops of 256² data for 4× cheaper steps; validation
            and test always see whole samples. ``None``: whole samples.
        prepare: called by :meth:`prepare_data` (rank 0 only), e.g. to generate a missing dataset.
        sensor: simulated phone sensor and file effects on the photos (docs/data.md#loading);
            ``None`` or ``enabled: false``: the stored photos as they are.
        sensor_splits: the splits ``sensor`` applies to, among ``"train"``, ``"val"``, ``"test"``.
        eval_sensor: applied to the splits not in ``sensor_splits`` (``None``: stored photos).
        align_maps: resample each sample's maps into its photo's pixels (the recorded camera,
            :func:`~brdfgan.data.phone.conditions.maps_as_photographed`), for training and evaluation alike;
            ``False`` reads them in texture space as stored (how models before v4 were trained and
            measured).

    After :meth:`setup`, :attr:`skipped` reports skipped shards and samples.
    """

    def __init__(
        self,
        data_dir: str,
        batch_size: int = 8,
        num_workers: int = 0,
        shuffle_buffer: int = 256,
        train_split: str | None = "train",
        val_split: str | None = "val",
        test_split: str | None = "test",
        val_samples: int | None = None,
        seed: int = 0,
        pin_memory: bool = False,
        prefetch_factor: int | None = None,
        epoch_samples: int | None = None,
        train_crop: int | None = None,
        prepare: Callable[..., object] | None = None,
        sensor: SensorEffects | None = None,
        sensor_splits: Sequence[str] = ("train",),
        eval_sensor: SensorEffects | None = None,
        align_maps: bool = True,
    ) -> None:
        super().__init__()
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        if num_workers < 0:
            raise ValueError(f"num_workers must be >= 0, got {num_workers}")
        if shuffle_buffer < 0:
            raise ValueError(f"shuffle_buffer must be >= 0, got {shuffle_buffer}")
        named = (
            ("val_samples", val_samples),
            ("epoch_samples", epoch_samples),
            ("train_crop", train_crop),
            ("prefetch_factor", prefetch_factor),
        )
        for name, value in named:
            if value is not None and value < 1:
                raise ValueError(f"{name} must be >= 1 or None, got {value}")
        unknown = sorted(set(sensor_splits) - set(_KINDS))
        if isinstance(sensor_splits, str) or unknown:
            raise DatasetConfigError(
                f"data.sensor_splits={sensor_splits!r}: must be a list of {', '.join(_KINDS)}"
            )
        # In the checkpoint only: the trackers get the whole run config once (brdfgan.tracking).
        self.save_hyperparameters(ignore=["prepare", "sensor", "eval_sensor"], logger=False)
        # As plain values: checkpoints are read with torch.load(weights_only=True).
        self.hparams["sensor"] = None if sensor is None else asdict(sensor)
        self.hparams["eval_sensor"] = None if eval_sensor is None else asdict(eval_sensor)
        self.data_dir = Path(data_dir)
        self.batch_size = batch_size
        self.num_workers = num_workers
        self.prefetch_factor = prefetch_factor
        self.shuffle_buffer = shuffle_buffer
        self.splits = {"train": train_split, "val": val_split, "test": test_split}
        self.val_samples = val_samples
        self.seed = seed
        self.pin_memory = pin_memory
        self.epoch_samples = epoch_samples
        self.train_crop = train_crop
        self.sensor = sensor
        self.sensor_splits = tuple(sensor_splits)
        self.eval_sensor = eval_sensor
        self.align_maps = align_maps
        self._prepare = prepare
        self._indices: dict[str, _SplitIndex] = {}
        self._skipped_shards = 0
        self._counter: _SkipCounter | None = None
        self._rank, self._world_size = 0, 1
        self._train_loader: DataLoader | None = None

    # -- Lightning hooks ------------------------------------------------------------------

    def check_data(self, stage: str = "fit") -> None:
        """Raise :class:`DatasetConfigError` now if the data path can neither be read nor
        generated for ``stage`` (what ``prepare_data`` would raise, without generating): a run
        calls it before building its model and trainer, so a mistyped path is its first output
        line."""
        if self._prepare is not None:
            self._prepare(check_only=True, **self._prepare_arguments(stage))
        elif not self.data_dir.is_dir():
            raise DatasetConfigError(f"data.data_dir={self.data_dir}: no such folder")

    def _prepare_arguments(self, stage: str | None) -> dict[str, Any]:
        """What ``prepare`` is called with for ``stage`` (``None``: the trainer's) besides
        ``check_only``: nothing, all splits."""
        return {}

    def prepare_data(self) -> None:
        if self._prepare is not None:
            self._prepare(**self._prepare_arguments(None))

    def setup(self, stage: str | None = None) -> None:
        kinds = {"fit": ("train", "val"), "validate": ("val",), "test": ("test",), "predict": ("test",)}.get(
            stage or "", _KINDS
        )
        self._rank, self._world_size = self._distributed()
        if self._counter is None:  # created here, not in __init__, so the module pickles for ddp_spawn
            self._counter = _SkipCounter(self.num_workers)
        for kind in kinds:
            split = self.splits[kind]
            if kind == "val" and split is not None and self._declared_empty(split):
                # A dataset generated with val_fraction = 0: validation is off, not an error.
                log.info("split %r holds no samples (its manifest says so): validation disabled", split)
                self.splits["val"] = split = None
            if split is not None and kind not in self._indices:
                self._indices[kind] = self._scan(split)

    def train_dataloader(self) -> DataLoader:
        index = self._index("train")
        workers = max(1, self.num_workers)
        if len(index.urls) < self._world_size * workers:
            warnings.warn(
                f"{len(index.urls)} train shard(s) for {self._world_size} rank(s) × {workers} worker(s): "
                "every worker streams all shards in its own order (samples repeat within an epoch); "
                "write at least that many shards for exact epochs",
                ShardWarning,
                stacklevel=2,
            )
        stream = self._stream("train", index, shuffle_buffer=self.shuffle_buffer, crop=self.train_crop)
        stream.epoch, stream.skip_batches = self._train_position()
        self.teardown("fit")  # a previous train loader's workers are not needed any more
        self._train_loader = self._loader(stream, persistent=self.num_workers > 0)
        return self._train_loader

    def val_dataloader(self) -> DataLoader | list:
        if self.splits["val"] is None:
            return []
        index = self._index("val")
        self._warn_eval_split("val", index)
        return self._loader(self._stream("val", index, max_samples=self.val_samples), persistent=False)

    def test_dataloader(self) -> DataLoader | list:
        if self.splits["test"] is None:
            return []
        index = self._index("test")
        self._warn_eval_split("test", index)
        return self._loader(self._stream("test", index), persistent=False)

    def teardown(self, stage: str | None = None) -> None:
        """Stop the persistent train workers now (Lightning's fit loop also does at its end).

        Outside Lightning, call it when done with a train loader: a forgotten one is shut down
        whenever the garbage collector finds it, and a DataLoader forked meanwhile can make
        that take seconds.
        """
        if stage in (None, "fit") and self._train_loader is not None:
            iterator = getattr(self._train_loader, "_iterator", None)
            if iterator is not None and hasattr(iterator, "_shutdown_workers"):
                # What Lightning does too; a later iteration then starts fresh workers.
                iterator._shutdown_workers()
                self._train_loader._iterator = None
            self._train_loader = None

    # -- accessors ------------------------------------------------------------------------

    @property
    def skipped(self) -> SkipStats:
        """Shards skipped by the check in :meth:`setup` plus samples/errors skipped while streaming."""
        samples, errors = self._counter.totals() if self._counter is not None else (0, 0)
        return SkipStats(shards=self._skipped_shards, samples=samples, errors=errors)

    def num_samples(self, kind: str = "train") -> int:
        """Valid samples counted in ``setup`` for ``kind`` in ``("train", "val", "test")``."""
        return self._index(kind).total

    @property
    def train_batches_per_epoch(self) -> int:
        """Full batches every rank yields per training epoch (at least 1)."""
        samples = self.epoch_samples if self.epoch_samples is not None else self._index("train").total
        return max(1, samples // (self._world_size * self.batch_size))

    # -- internals ------------------------------------------------------------------------

    def _train_position(self) -> tuple[int, int]:
        """``(epoch, batches of it already trained)`` where the fit loop stands: ``(0, 0)`` for a
        new run; for a run restored from a checkpoint, the position the checkpoint recorded."""
        if self.trainer is None:
            return 0, 0
        # Batches the loop has trained over the whole run, as restored from a checkpoint (a save
        # at a batch's end counts that batch as processed). Every epoch has exactly
        # train_batches_per_epoch batches, so this alone fixes the epoch and the offset in it —
        # Lightning's own epoch counter still says the previous epoch after an epoch-end save.
        # (``total`` is a processed-counting tracker in a batch progress; its static type is the
        # base class of every progress.)
        total = cast(_ProcessedTracker, self.trainer.fit_loop.epoch_loop.batch_progress.total)
        done = total.processed
        return divmod(done, self.train_batches_per_epoch)

    def _distributed(self) -> tuple[int, int]:
        if self.trainer is not None:
            return self.trainer.global_rank, self.trainer.world_size
        if torch.distributed.is_available() and torch.distributed.is_initialized():
            return torch.distributed.get_rank(), torch.distributed.get_world_size()
        return 0, 1

    def _declared_empty(self, split: str) -> bool:
        if not (self.data_dir / split / MANIFEST_NAME).exists():
            return False
        return read_manifest(self.data_dir, split).get("samples") == 0

    def _scan(self, split: str) -> _SplitIndex:
        directory = self.data_dir / split
        shards = list_shards(self.data_dir, split)
        if not shards:
            raise ShardError(
                f"no shards in {directory} (expected {split}-000000.tar, …); generate the dataset first"
            )
        urls, counts = [], []
        for path in shards:
            try:
                samples = verify_shard(path)
            except ShardError as error:
                self._skipped_shards += 1
                warnings.warn(f"skipping shard: {error}", ShardWarning, stacklevel=3)
                log.warning("skipping shard: %s", error)
                continue
            if samples > 0:
                urls.append(str(path))
                counts.append(samples)
        if not urls:
            raise ShardError(f"no readable samples in the {len(shards)} shard(s) of {directory}")
        return _SplitIndex(tuple(urls), tuple(counts))

    def _index(self, kind: str) -> _SplitIndex:
        if kind not in self._indices:
            if self.splits[kind] is None:
                raise ShardError(f"the {kind} split is disabled ({kind}_split=None)")
            raise RuntimeError(f"call setup() for the {kind} split before asking for its data")
        return self._indices[kind]

    def _stream(self, kind: str, index: _SplitIndex, **options: Any) -> ShardStream:
        assert self._counter is not None
        return ShardStream(
            index,
            kind=kind,
            batch_size=self.batch_size,
            rank=self._rank,
            world_size=self._world_size,
            seed=self.seed,
            counter=self._counter,
            batches_per_epoch=self.train_batches_per_epoch if kind == "train" else None,
            sensor=self.sensor if kind in self.sensor_splits else self.eval_sensor,
            align_maps=self.align_maps,
            num_workers=max(1, self.num_workers),  # a loader without workers iterates as one
            **options,
        )

    def _loader(self, stream: EpochStream, *, persistent: bool) -> DataLoader:
        return DataLoader(
            stream,
            # Batches are formed in the workers: one shared-memory transfer per batch, and the
            # number of batches per rank is this module's to fix (exact epochs).
            batch_size=None,
            num_workers=self.num_workers,
            pin_memory=self.pin_memory,
            persistent_workers=persistent,
            prefetch_factor=self.prefetch_factor if self.num_workers > 0 else None,
        )

    def _warn_eval_split(self, kind: str, index: _SplitIndex) -> None:
        shards = len(index.urls)
        if self._world_size > 1 and shards < self._world_size:
            warnings.warn(
                f"{shards} {kind} shard(s) for {self._world_size} ranks: "
                "every rank evaluates the whole split",
                ShardWarning,
                stacklevel=3,
            )
        elif shards < self._world_size * self.num_workers:
            warnings.warn(
                f"{shards} {kind} shard(s) for {self._world_size} rank(s) × {self.num_workers} workers: "
                "some workers stay idle",
                ShardWarning,
                stacklevel=3,
            )
