"""Data loading benchmark: samples/s that ShardDataModule's train loader delivers, per worker count.

Writes a small temporary dataset per resolution (smooth procedural-looking maps with a little
noise, photographed with the torch flash renderer and auto-exposed, plus simulated sensor noise,
so the 16-bit PNGs compress like real renders and not like white noise), then streams it
through the train DataLoader (shuffle buffer, decoding, batching) and times the steady state
after the first batch. Prints Markdown tables and how many workers feed a GPU at the paper's
configuration.

    python -m benchmarks.bench_datamodule [--workers 0,1,2] [--batches 12] [--samples 48]
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

import torch

from brdfgan.core.exposure import auto_expose
from brdfgan.core.render import render_flash
from brdfgan.core.svbrdf import join_maps, linear_to_srgb, normalize_normal
from brdfgan.data.datamodule import ShardDataModule
from brdfgan.data.shards import SAMPLE_MEMBERS, Sample, decode_sample, encode_sample, shard_path, write_shard

RESOLUTIONS = (512, 256)
SHARDS = 4
# Paper's training configuration and an assumed GPU step time: one G+D step of the 45.6 M-param
# generator and the two PatchGAN discriminators at batch 8, 512², on an A100-class GPU. An
# assumption (not measured here, no GPU): ~0.25 s.
TRAIN_BATCH = 8
ASSUMED_GPU_STEP_S = 0.25


def _field(size: int, generator: torch.Generator, waves: int = 4) -> torch.Tensor:
    """A smooth random field in [0, 1]: a few random sinusoids."""
    y, x = torch.meshgrid(torch.linspace(0, 1, size), torch.linspace(0, 1, size), indexing="ij")
    field = torch.zeros(size, size)
    for _ in range(waves):
        fx, fy, phase = (torch.rand(3, generator=generator) * torch.tensor([12.0, 12.0, 6.28])).tolist()
        field += torch.sin(2 * math.pi * (fx * x + fy * y) + phase)
    return (field / (2 * waves) + 0.5).clamp(0, 1)


def _sample(index: int, size: int) -> Sample:
    g = torch.Generator().manual_seed(index)

    def noisy(field: torch.Tensor, sigma: float = 0.01) -> torch.Tensor:
        return (field + sigma * torch.randn(field.shape, generator=g)).clamp(0, 1)

    tint = torch.rand(3, 1, 1, generator=g) * 0.6 + 0.2
    basecolor = linear_to_srgb(noisy(tint * _field(size, g)[None].expand(3, -1, -1)))
    height = _field(size, g)
    gy, gx = torch.gradient(height * 0.02 * size)
    normal = normalize_normal(
        torch.stack([-gx, gy, torch.ones_like(gx)]) + 0.01 * torch.randn(3, size, size, generator=g)
    )
    roughness = noisy(0.2 + 0.6 * _field(size, g))[None]
    metallic = (_field(size, g) > 0.8).float()[None]
    maps = join_maps(basecolor, normal, roughness, metallic)
    photo, _ = auto_expose(render_flash(maps[None]))
    photo = (photo[0] * (1 + 0.02 * torch.randn(photo.shape[1:], generator=g))).clamp(0, 1)  # render noise
    return Sample(key=f"bench-{index:05d}", photo=photo, maps=maps, meta={"index": index, "size": size})


def _make_dataset(root: Path, size: int, samples: int) -> dict[str, float]:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # 2-thread OpenMP collapses when the machine is shared
    try:
        return _write_dataset(root, size, samples)
    finally:
        torch.set_num_threads(threads)


def _write_dataset(root: Path, size: int, samples: int) -> dict[str, float]:
    start = time.perf_counter()
    per_shard = math.ceil(samples / SHARDS)
    total_bytes = 0
    for shard in range(SHARDS):
        indices = range(shard * per_shard, min(samples, (shard + 1) * per_shard))
        total_bytes += write_shard(
            shard_path(root, "train", shard), (_sample(i, size) for i in indices)
        ).bytes
    return {
        "mb_per_sample": total_bytes / samples / 2**20,
        "write_s": (time.perf_counter() - start) / samples,
    }


def _decode_time(size: int, repeats: int = 5) -> float:
    """Seconds per decode_sample with one torch thread, as in a DataLoader worker."""
    record = {"__key__": "bench-00000", **encode_sample(_sample(0, size))}
    assert set(record) - {"__key__"} == set(SAMPLE_MEMBERS)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        decode_sample(record)
        start = time.perf_counter()
        for _ in range(repeats):
            decode_sample(record)
        return (time.perf_counter() - start) / repeats
    finally:
        torch.set_num_threads(threads)


def _throughput(root: Path, workers: int, batches: int) -> dict[str, float]:
    dm = ShardDataModule(
        str(root), batch_size=TRAIN_BATCH, num_workers=workers, val_split=None, test_split=None
    )
    dm.setup("fit")
    dm.epoch_samples = (batches + 1) * TRAIN_BATCH
    iterator = iter(dm.train_dataloader())
    start = time.perf_counter()
    next(iterator)  # worker start-up and shuffle-buffer fill
    first = time.perf_counter() - start
    start = time.perf_counter()
    delivered = sum(len(batch["key"]) for batch in iterator)
    elapsed = time.perf_counter() - start
    del iterator
    dm.teardown()  # stop the persistent workers before the next case forks its own
    return {"samples_per_s": delivered / elapsed, "first_batch_s": first}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", default="0,1,2", help="comma-separated DataLoader worker counts")
    parser.add_argument("--batches", type=int, default=12, help="timed batches per case (after the first)")
    parser.add_argument("--samples", type=int, default=32, help="samples in each temporary dataset")
    args = parser.parse_args()
    worker_counts = [int(w) for w in args.workers.split(",")]

    rows, datasets, per_worker = [], {}, {}
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench-datamodule-") as tmp:
        for size in RESOLUTIONS:
            root = Path(tmp) / str(size)
            datasets[size] = _make_dataset(root, size, args.samples)
            datasets[size]["decode_ms"] = 1000 * _decode_time(size)
            for workers in worker_counts:
                m = _throughput(root, workers, args.batches)
                rows.append((size, workers, m))
                if workers == 1:
                    per_worker[size] = m["samples_per_s"]

    print(
        f"\nShardDataModule train loader, batch {TRAIN_BATCH}, {os.cpu_count()} CPU cores, "
        f"torch {torch.__version__} ({torch.get_num_threads()} threads in the main process), "
        f"{args.batches} timed batches after the first, {args.samples} samples in {SHARDS} shards, "
        f"1-min load average {load_before:.1f} before / {os.getloadavg()[0]:.1f} after\n"
    )
    header = "resolution workers samples/s samples/s-per-worker ms-per-batch first-batch-s"
    print("| " + " | ".join(header.split()) + " |")
    print("|" + "---|" * len(header.split()))
    for size, workers, m in rows:
        rate = m["samples_per_s"]
        cells = [
            f"{size}²", str(workers), f"{rate:.1f}", f"{rate / max(1, workers):.1f}",
            f"{1000 * TRAIN_BATCH / rate:.0f}", f"{m['first_batch_s']:.2f}",
        ]  # fmt: skip
        print("| " + " | ".join(cells) + " |")

    print(
        "\n| resolution | MB/sample on disk | write s/sample (render+encode) | decode_sample ms (1 thread) |"
    )
    print("|---|---|---|---|")
    for size, d in datasets.items():
        print(f"| {size}² | {d['mb_per_sample']:.2f} | {d['write_s']:.2f} | {d['decode_ms']:.1f} |")

    needed = TRAIN_BATCH / ASSUMED_GPU_STEP_S
    print(
        f"\nFeeding the paper's configuration: batch {TRAIN_BATCH} at 512², assuming ~{ASSUMED_GPU_STEP_S} s "
        "per GAN step (generator + two discriminators, forward+backward) on an A100-class GPU "
        f"(an assumption, not measured) → ≥ {needed:.0f} samples/s per GPU."
    )
    # At 256² the step costs ~4× fewer FLOPs (docs/conventions.md#generator-cost: 106 vs 424 GFLOP
    # per image).
    for size, rate_needed in ((512, needed), (256, needed * 4)):
        if size in per_worker:
            workers = math.ceil(rate_needed / per_worker[size])
            print(
                f"- {size}² (≥ {rate_needed:.0f} samples/s): one worker delivers "
                f"{per_worker[size]:.1f} samples/s on this CPU → ≥ {workers} workers per GPU, "
                "plus a core for the training process (if the GPU host's cores are as fast "
                "and workers scale linearly)."
            )


if __name__ == "__main__":
    main()
