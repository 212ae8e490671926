"""`brdfgan predict` end to end at 256², 512², 1024², 2048², 4096² and at its default resolution
(the crop's side, capped at 2048²): wall time, peak memory, generator share; and against v3's
architecture at 256², 1024², 2048².

Each resolution runs in a fresh subprocess (so its peak RSS is its own) on a synthetic 4000×3000
flash photo (JPEG), with the shipped default weights when they are installed, else a randomly
initialised generator of the same architecture (timings do not depend on the values); v3's
architecture (the paper's generator at width 16) always randomly initialised. Above 1024²
the generator runs tiled (1024² tiles, frozen statistics), so its memory stays that of one tile.
The generator's share is the time spent inside ``Predictor.maps``; the rest is decoding, hotspot
search, resizing, encoding seven textures, the .glb and the preview.

It also measures the sgemm rate of this machine (4096³ fp32 matmul) and reports the paper
generator's 512² forward against the floor that rate implies (424 GFLOP, docs/conventions.md#generator-cost).

    python -m benchmarks.bench_predict [--sizes 256 512 … default] [--v3-sizes 256 1024 2048]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

PAPER_GFLOP_512 = 424.0


def _photo(path: Path) -> Path:
    import cv2
    import numpy as np

    height, width = 3000, 4000
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    texture = 0.2 + 0.15 * rng.random((height, width, 1), dtype=np.float32) * np.array(
        [1.0, 0.8, 0.6], np.float32
    )
    flash = 0.7 * np.exp(-((xx - 2100) ** 2 + (yy - 1450) ** 2) / (2 * 600.0**2))[..., None]
    srgb = np.clip(texture + flash, 0, 1) ** (1 / 2.2)
    cv2.imwrite(str(path), (srgb * 255).astype(np.uint8)[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 92])
    return path


def _weights(directory: Path) -> Path:
    from brdfgan.inference.model.weights import default_weights_path

    shipped = default_weights_path()
    if shipped.is_file():
        return shipped
    from brdfgan.models.anchored import AnchoredUNet

    return _random_weights(
        directory / "random.safetensors", AnchoredUNet(), "brdfgan.models.anchored.AnchoredUNet"
    )


def _v3_weights(directory: Path) -> Path:
    """v3's architecture (the paper's generator at width 16, 3 downsamplings, 4 residual blocks,
    the unit-z normal head), randomly initialised: the timings do not depend on the values."""
    from brdfgan.models.generator import Generator

    generator = Generator(width=16, downsamplings=3, residual_blocks=4, normal_head="unit_z")
    return _random_weights(directory / "v3.safetensors", generator, "brdfgan.models.generator.Generator")


def _random_weights(path: Path, generator: torch.nn.Module, target: str) -> Path:
    from brdfgan.runs import save_weights

    return save_weights(
        path,
        generator,
        target=target,
        config=generator.config(),  # type: ignore[operator]
        model_id=f"{path.stem} architecture, random weights",
        extra={"resolution": 256},
    )


def run_one(photo: Path, weights: Path, size: int | None, out: Path) -> dict[str, Any]:
    """One predict call in this process (``size`` None: predict's default); returns seconds,
    peak RSS (MiB) and the output side."""
    from brdfgan.inference.model.weights import load_model
    from brdfgan.inference.pipeline import PredictOptions, Predictor, predict_photo

    spent = {"generator": 0.0}
    original = Predictor.maps

    def timed(self: Predictor, *args: Any) -> Any:
        start = time.perf_counter()
        result = original(self, *args)
        spent["generator"] += time.perf_counter() - start
        return result

    Predictor.maps = timed  # type: ignore[method-assign]  # timing only, in this throwaway process
    model = load_model(weights)
    start = time.perf_counter()
    result = predict_photo(photo, out / f"p{size}", Predictor.create(model, PredictOptions(resolution=size)))
    total = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    side = json.loads((result.output / "material.json").read_text())["resolution"]
    folder_mib = sum(f.stat().st_size for f in result.output.iterdir()) / 2**20
    page_mib = (result.output / "index.html").stat().st_size / 2**20
    return {
        "total": total,
        "generator": spent["generator"],
        "peak_mib": peak,
        "model": model.model_id,
        "side": side,
        "folder_mib": folder_mib,
        "page_mib": page_mib,
    }


def sgemm_gflops(size: int = 4096, repeats: int = 3) -> float:
    a, b = torch.randn(size, size), torch.randn(size, size)
    a @ b
    start = time.perf_counter()
    for _ in range(repeats):
        a @ b
    return 2 * size**3 * repeats / (time.perf_counter() - start) / 1e9


def paper_forward_512() -> float:
    from brdfgan.models.generator import Generator

    generator = Generator().eval()
    photo = torch.rand(1, 3, 512, 512)
    with torch.inference_mode():
        generator(photo)
        start = time.perf_counter()
        generator(photo)
    return time.perf_counter() - start


def _child(photo: Path, weights: Path, size: str, directory: Path) -> dict[str, Any] | None:
    """One predict call in a fresh subprocess (its own peak RSS); None when it failed."""
    command = [
        sys.executable,
        "-m",
        "benchmarks.bench_predict",
        "--child",
        str(photo),
        str(weights),
        size,
        str(directory),
    ]
    result = subprocess.run(command, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        print(f"{size}² ({weights.name}): failed: {result.stderr.strip().splitlines()[-1:]}")
        return None
    return json.loads(result.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["256", "512", "1024", "2048", "4096", "default"])
    parser.add_argument(
        "--v3-sizes",
        nargs="*",
        default=["256", "1024", "2048"],
        help="also time v3's architecture at these sizes (random weights)",
    )
    parser.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        photo, weights, size, out = args.child
        print(
            json.dumps(
                run_one(Path(photo), Path(weights), None if size == "default" else int(size), Path(out))
            )
        )
        return
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp)
        photo = _photo(directory / "flash.jpg")
        weights, v3 = _weights(directory), _v3_weights(directory)
        rows = [(size, row) for size in args.sizes if (row := _child(photo, weights, size, directory))]
        v3_rows = {size: row for size in args.v3_sizes if (row := _child(photo, v3, size, directory))}
    threads = torch.get_num_threads()
    model = rows[0][1]["model"] if rows else "?"
    print(
        f"\nbrdfgan predict on a 4000×3000 JPEG, model: {model}, {threads} threads; "
        "ratios against the first size\n"
    )
    print(
        "| resolution | wall s | generator s | generator share | peak RSS MiB | time ratio | memory ratio "
        "| output MiB | index.html MiB |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    base = rows[0][1] if rows else {}
    for size, row in rows:
        cells = [
            f"{row['side']}²" + (" (default)" if size == "default" else ""),
            f"{row['total']:.1f}",
            f"{row['generator']:.1f}",
            f"{row['generator'] / row['total']:.0%}",
            f"{row['peak_mib']:.0f}",
            f"{row['total'] / base['total']:.2f}×",
            f"{row['peak_mib'] / base['peak_mib']:.2f}×",
            f"{row['folder_mib']:.1f}",
            f"{row['page_mib']:.1f}",
        ]
        print("| " + " | ".join(cells) + " |")
    if v3_rows:
        print(f"\nAgainst v3's architecture (random weights, same photo and options): {model} / v3\n")
        header = ["resolution", "wall s", "v3 wall s", "wall ratio", "generator s", "v3 generator s",
                  "generator ratio", "peak RSS MiB", "v3 peak RSS MiB"]  # fmt: skip
        print("| " + " | ".join(header) + " |")
        print("|---|---|---|---|---|---|---|---|---|")
        for size, row in rows:
            old = v3_rows.get(size)
            if old is None:
                continue
            cells = [
                f"{row['side']}²", f"{row['total']:.1f}", f"{old['total']:.1f}",
                f"{row['total'] / old['total']:.2f}×", f"{row['generator']:.2f}", f"{old['generator']:.2f}",
                f"{row['generator'] / old['generator']:.2f}×",
                f"{row['peak_mib']:.0f}", f"{old['peak_mib']:.0f}",
            ]  # fmt: skip
            print("| " + " | ".join(cells) + " |")
    rate = sgemm_gflops()
    forward = paper_forward_512()
    floor = PAPER_GFLOP_512 / rate
    print(
        f"\nsgemm 4096³: {rate:.0f} GFLOP/s; paper generator at 512²: {forward:.2f} s fp32 eager, "
        f"floor {floor:.2f} s ({PAPER_GFLOP_512:.0f} GFLOP) → {forward / floor:.2f}× the floor"
    )


if __name__ == "__main__":
    main()
