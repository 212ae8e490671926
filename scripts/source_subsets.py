"""Split one split of a dataset that mixes scanned sets in (``dataset_spec.scans``) into its scanned
and its procedural photos, each written as the ``test`` split of a dataset of its own, so that
``evaluate.py`` scores the two apart (the v4 tables: the scan test set beside the procedural one).

    python -m scripts.source_subsets data/procedural_and_scans --split test
    # -> data/procedural_and_scans_test_scans/test, data/procedural_and_scans_test_procedural/test
    python evaluate.py data=procedural_and_scans data.data_dir=data/procedural_and_scans_test_scans \\
        data.prepare=null ckpt=...

With ``--scan-share S`` it writes instead one dataset whose ``SPLIT`` holds every scanned photo of
the split and a seeded sample of its procedural ones, so that scans make a share S of it (the
other splits linked from the source): the recipe comparison's scan share without a new render.

    python -m scripts.source_subsets data/procedural_and_scans --split train --scan-share 0.6
    # -> data/procedural_and_scans_scans60/{train, val -> …, test -> …}

The shards are copied sample by sample (same keys, same 16-bit payload); each output folder is
written under a temporary name and renamed when complete.
"""

from __future__ import annotations

import argparse
import random
import shutil
from collections.abc import Iterator
from pathlib import Path

from brdfgan.data.materials.source import is_scanned
from brdfgan.data.storage.shards import Sample, iter_shard, list_shards, shard_path, write_shard

SAMPLES_PER_SHARD = 64


def write_subset(
    samples: list[Sample], out: Path, split: str = "test", links: dict[str, Path] | None = None
) -> None:
    """``samples`` as ``out/split``, and ``links`` (split name -> folder) as symbolic links beside
    it (temporary folder, then renamed over any earlier one)."""
    partial = out.with_name(f".{out.name}.partial")
    shutil.rmtree(partial, ignore_errors=True)
    (partial / split).mkdir(parents=True)
    for start in range(0, len(samples), SAMPLES_PER_SHARD):
        chunk: Iterator[Sample] = iter(samples[start : start + SAMPLES_PER_SHARD])
        write_shard(shard_path(partial, split, start // SAMPLES_PER_SHARD), chunk, shard_format="u16z")
    for name, target in (links or {}).items():
        (partial / name).symlink_to(target.resolve())
    shutil.rmtree(out, ignore_errors=True)
    partial.rename(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data_dir", type=Path)
    parser.add_argument("--split", default="test")
    parser.add_argument("--scan-share", type=float, help="one dataset with this share of scanned photos")
    parser.add_argument("--seed", type=int, default=0, help="the procedural photos' sample (--scan-share)")
    args = parser.parse_args()
    if args.scan_share is not None and not 0.0 < args.scan_share < 1.0:
        raise SystemExit(f"error: --scan-share {args.scan_share}: must lie between 0 and 1")
    shards = list_shards(args.data_dir, args.split)
    if not shards:
        raise SystemExit(f"error: {args.data_dir}/{args.split}: no shards")
    samples = [sample for shard in shards for sample in iter_shard(shard)]
    flags = [is_scanned(str(sample.meta.get("family", ""))) for sample in samples]
    scanned = [sample for sample, flag in zip(samples, flags, strict=True) if flag]
    procedural = [sample for sample, flag in zip(samples, flags, strict=True) if not flag]
    if args.scan_share is not None:
        if not scanned:
            raise SystemExit(f"error: {args.data_dir}/{args.split}: no scanned photos to make a share of")
        count = min(len(procedural), round(len(scanned) * (1.0 - args.scan_share) / args.scan_share))
        kept = random.Random(args.seed).sample(procedural, count)
        mixed = sorted(scanned + kept, key=lambda sample: sample.key)
        out = args.data_dir.with_name(f"{args.data_dir.name}_scans{round(100 * args.scan_share)}")
        others = {p.name: p for p in args.data_dir.iterdir() if p.is_dir() and p.name != args.split}
        write_subset(mixed, out, args.split, others)
        print(f"{out}: {len(mixed)} photos, {len(scanned)} scanned")
        return
    for name, subset in (("scans", scanned), ("procedural", procedural)):
        out = args.data_dir.with_name(f"{args.data_dir.name}_{args.split}_{name}")
        write_subset(subset, out)
        print(f"{out}: {len(subset)} photos")


if __name__ == "__main__":
    main()
