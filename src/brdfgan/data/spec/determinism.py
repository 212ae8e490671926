"""The determinism of a dataset: every random draw comes from a generator seeded by a hash of
names (the dataset seed, a material index, a crop, a render), and torch paints and crops on one
thread, so the bytes of a material, a crop or a shard do not depend on which process made them,
in which order, or on how many cores it had."""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Iterator

import torch


def derive_seed(*parts: int | str) -> int:
    """A 63-bit seed from a hash of ``parts``: independent streams per (dataset, material, …)
    that do not shift when the dataset grows or a shard runs elsewhere."""
    digest = hashlib.blake2b(":".join(map(str, parts)).encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") & (2**63 - 1)


def material_seed(dataset_seed: int, material_index: int) -> int:
    """The seed of one material: every draw for it (family parameters, crops, lighting, flash,
    Mitsuba's sampler) comes from a generator seeded with this."""
    return derive_seed(dataset_seed, "material", material_index)


@contextlib.contextmanager
def single_torch_thread() -> Iterator[None]:
    """Run torch on one intra-op thread inside the block (restored after).

    Generation paints and crops with torch between Mitsuba renders, and Mitsuba runs its own
    thread pool over every core: two torch threads beside it only fought it for the cores
    (docs/benchmarks.md#dataset-generation-and-loading). One thread also makes the bytes of a
    shard independent of the machine's core count, which a parallel float reduction's order would
    otherwise change.
    Scale out with processes instead (``generate.py -m shard=…``).
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
