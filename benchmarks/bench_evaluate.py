"""Evaluation throughput: generator forward + every metric of the evaluator, per model.

Random valid photos and maps at 256² (batch 4), after one warm-up batch; the metric collection is
the one ``evaluate.py`` uses (per-map RMSE, downscaled RMSE skipped at 256², normal angle, 16
re-render configurations).

    python -m benchmarks.bench_evaluate [--batches N]
"""

from __future__ import annotations

import argparse
import time

import torch


def _models() -> dict[str, torch.nn.Module]:
    from brdfgan.models.deschaintre2018 import Deschaintre2018
    from brdfgan.models.generator import Generator

    return {
        "ours, CPU preset (width 16, 4 blocks)": Generator(width=16, residual_blocks=4),
        "ours, paper (45.6 M)": Generator(),
        "deschaintre2018 baseline (CPU config)": Deschaintre2018(width=16),
    }


def main() -> None:
    from tests.conftest import random_maps

    from brdfgan.metrics import SVBRDFMetrics

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, default=3)
    args = parser.parse_args()
    torch.manual_seed(0)
    photos = torch.rand(4, 3, 256, 256)
    truth = random_maps(256, 256, batch=(4,))
    rows = []
    for name, model in _models().items():
        model.eval()
        metrics = SVBRDFMetrics(downscale_to=256)
        with torch.no_grad():
            metrics.update(model(photos), truth)  # warm-up
            start = time.perf_counter()
            forward = 0.0
            for _ in range(args.batches):
                t = time.perf_counter()
                pred = model(photos)
                forward += time.perf_counter() - t
                metrics.update(pred, truth)
            metrics.compute()
            total = time.perf_counter() - start
        samples = args.batches * photos.shape[0]
        rows.append((name, samples / total, forward / total))
    threads = torch.get_num_threads()
    print(f"\nEvaluation throughput at 256², batch 4, {threads} threads; ratio against the first row\n")
    print("| model | samples/s | share in the generator | ratio |")
    print("|---|---|---|---|")
    for name, rate, share in rows:
        print(f"| {name} | {rate:.2f} | {share:.0%} | {rate / rows[0][1]:.2f}× |")


if __name__ == "__main__":
    main()
