"""Data loading benchmark: samples/s that ShardDataModule's train loader delivers, per worker
count and shard format (``png`` and ``u16z``, :mod:`brdfgan.data.storage.shards`).

Writes a small temporary dataset per resolution and format, the same samples in each (smooth
procedural-looking maps with a little noise, photographed with the torch flash renderer and
auto-exposed, plus simulated sensor noise, so the 16-bit planes compress like real renders and
not like white noise), then streams it through the train DataLoader (shuffle buffer, decoding,
batching) and times the steady state after the first batch. Prints Markdown tables (one of them
png against u16z per worker, with the ratio) and how many workers feed a GPU at the paper's
configuration.

    python -m benchmarks.bench_datamodule [--workers 0,1,2] [--batches 12] [--samples 32]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import tempfile
import time
from pathlib import Path

import torch

from brdfgan.core.exposure import auto_expose
from brdfgan.core.render import render_flash
from brdfgan.core.svbrdf import join_maps, linear_to_srgb, normalize_normal
from brdfgan.data.loading.datamodule import ShardDataModule
from brdfgan.data.storage.shards import (
    FORMAT_MEMBERS,
    SHARD_FORMATS,
    Sample,
    decode_sample,
    encode_sample,
    shard_path,
    write_shard,
)

RESOLUTIONS = (512, 256)
FORMATS = ("png", "u16z")  # old against new; the GPU feeding estimate uses NEW_FORMAT
NEW_FORMAT = "u16z"
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


def _make_datasets(root: Path, size: int, samples: int) -> dict[str, dict[str, float]]:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # 2-thread OpenMP collapses when the machine is shared
    try:
        return _write_datasets(root, size, samples)
    finally:
        torch.set_num_threads(threads)


def _write_datasets(root: Path, size: int, samples: int) -> dict[str, dict[str, float]]:
    """The same samples as one dataset per format, at ``root/<format>``; per format: MB per
    sample on disk, render and encode+write seconds per sample."""
    per_shard = math.ceil(samples / SHARDS)
    render_s = 0.0
    total_bytes = dict.fromkeys(FORMATS, 0)
    write_s = dict.fromkeys(FORMATS, 0.0)
    for shard in range(SHARDS):
        start = time.perf_counter()
        batch = [_sample(i, size) for i in range(shard * per_shard, min(samples, (shard + 1) * per_shard))]
        render_s += time.perf_counter() - start
        for shard_format in FORMATS:
            start = time.perf_counter()
            path = shard_path(root / shard_format, "train", shard)
            total_bytes[shard_format] += write_shard(path, batch, shard_format=shard_format).bytes
            write_s[shard_format] += time.perf_counter() - start
    return {
        shard_format: {
            "mb_per_sample": total_bytes[shard_format] / samples / 2**20,
            "render_s": render_s / samples,
            "write_s": write_s[shard_format] / samples,
        }
        for shard_format in FORMATS
    }


def _decode_time(size: int, shard_format: str, samples: int = 3, repeats: int = 5) -> float:
    """Median seconds per decode_sample with one torch thread, as in a DataLoader worker."""
    records = [
        {"__key__": f"bench-{i:05d}", **encode_sample(_sample(i, size), shard_format)} for i in range(samples)
    ]
    assert all(set(r) - {"__key__"} == set(FORMAT_MEMBERS[shard_format]) for r in records)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        decode_sample(records[0])
        times = []
        for _ in range(repeats):
            for record in records:
                start = time.perf_counter()
                decode_sample(record)
                times.append(time.perf_counter() - start)
        return statistics.median(times)
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
    start, cpu_start = time.perf_counter(), time.process_time()
    delivered = sum(len(batch["key"]) for batch in iterator)
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    del iterator
    dm.teardown()  # stop the persistent workers before the next case forks its own
    # Per CPU second of this process: with workers=0 the whole loader's work, whatever else the
    # machine runs meanwhile.
    return {
        "samples_per_s": delivered / elapsed,
        "samples_per_cpu_s": delivered / cpu,
        "first_batch_s": first,
    }


def _single_thread_stream(root: Path, batches: int) -> dict[str, float]:
    """The train loader in this process with one torch thread: one worker's work, decoding to
    batches, without the transfer to the training process."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _throughput(root, 0, batches)
    finally:
        torch.set_num_threads(threads)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", default="0,1,2", help="comma-separated DataLoader worker counts")
    parser.add_argument("--batches", type=int, default=12, help="timed batches per case (after the first)")
    parser.add_argument("--samples", type=int, default=32, help="samples in each temporary dataset")
    args = parser.parse_args()
    worker_counts = [int(w) for w in args.workers.split(",")]
    assert set(FORMATS) == set(SHARD_FORMATS)

    rows, datasets, per_worker = [], {}, {}
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench-datamodule-") as tmp:
        for size in RESOLUTIONS:
            made = _make_datasets(Path(tmp) / str(size), size, args.samples)
            for shard_format in FORMATS:
                root = Path(tmp) / str(size) / shard_format
                stream = _single_thread_stream(root, args.batches)
                datasets[size, shard_format] = {
                    **made[shard_format],
                    "decode_ms": 1000 * _decode_time(size, shard_format),
                    "stream_per_s": stream["samples_per_s"],
                    "stream_per_cpu_s": stream["samples_per_cpu_s"],
                }
                for workers in worker_counts:
                    m = _throughput(root, workers, args.batches)
                    rows.append((size, shard_format, workers, m))
                    if workers == 1:
                        per_worker[size, shard_format] = m["samples_per_s"]

    print(
        f"\nShardDataModule train loader, batch {TRAIN_BATCH}, {os.cpu_count()} CPU cores, "
        f"torch {torch.__version__} ({torch.get_num_threads()} threads in the main process), "
        f"{args.batches} timed batches after the first, {args.samples} samples in {SHARDS} shards, "
        f"1-min load average {load_before:.1f} before / {os.getloadavg()[0]:.1f} after\n"
    )
    header = "resolution format workers samples/s samples/s-per-worker ms-per-batch first-batch-s"
    print("| " + " | ".join(header.split()) + " |")
    print("|" + "---|" * len(header.split()))
    for size, shard_format, workers, m in rows:
        rate = m["samples_per_s"]
        cells = [
            f"{size}²", shard_format, str(workers), f"{rate:.1f}", f"{rate / max(1, workers):.1f}",
            f"{1000 * TRAIN_BATCH / rate:.0f}", f"{m['first_batch_s']:.2f}",
        ]  # fmt: skip
        print("| " + " | ".join(cells) + " |")

    print(
        "\n| resolution | format | MB/sample on disk | render s/sample | encode+write s/sample "
        "| decode_sample ms (1 thread) |"
    )
    print("|---|---|---|---|---|---|")
    for (size, shard_format), d in datasets.items():
        print(
            f"| {size}² | {shard_format} | {d['mb_per_sample']:.2f} | {d['render_s']:.2f} "
            f"| {d['write_s']:.3f} | {d['decode_ms']:.1f} |"
        )

    old, new = FORMATS
    print(f"\nSamples/s per worker, {old} vs {new} (the same samples in each):\n")
    print(f"| resolution | what is timed | {old} | {new} | ratio |")
    print("|---|---|---|---|---|")
    for size in RESOLUTIONS:
        measures = [
            ("decode_sample alone, 1 torch thread", [1000 / datasets[size, f]["decode_ms"] for f in FORMATS]),
            (
                "train loader in-process, 1 torch thread (tar read, shuffle, decode, batch)",
                [datasets[size, f]["stream_per_s"] for f in FORMATS],
            ),
            ("... per CPU second of it", [datasets[size, f]["stream_per_cpu_s"] for f in FORMATS]),
        ]
        if (size, old) in per_worker:
            measures.append(
                ("DataLoader, 1 worker process (+ transfer)", [per_worker[size, f] for f in FORMATS])
            )
        for what, (rate_old, rate_new) in measures:
            print(f"| {size}² | {what} | {rate_old:.1f} | {rate_new:.1f} | {rate_new / rate_old:.1f}× |")

    needed = TRAIN_BATCH / ASSUMED_GPU_STEP_S
    print(
        f"\nFeeding the paper's configuration: batch {TRAIN_BATCH} at 512², assuming ~{ASSUMED_GPU_STEP_S} s "
        "per GAN step (generator + two discriminators, forward+backward) on an A100-class GPU "
        f"(an assumption, not measured) → ≥ {needed:.0f} samples/s per GPU."
    )
    # At 256² the step costs ~4× fewer FLOPs (docs/conventions.md#generator-cost: 106 vs 424 GFLOP
    # per image).
    for size, rate_needed in ((512, needed), (256, needed * 4)):
        if (size, NEW_FORMAT) in per_worker:
            rate = per_worker[size, NEW_FORMAT]
            workers = math.ceil(rate_needed / rate)
            print(
                f"- {size}² (≥ {rate_needed:.0f} samples/s): one worker delivers {rate:.1f} samples/s "
                f"from {NEW_FORMAT} shards on this CPU → ≥ {workers} workers per GPU, plus a core for the "
                "training process (if the GPU host's cores are as fast and workers scale linearly)."
            )


if __name__ == "__main__":
    main()
