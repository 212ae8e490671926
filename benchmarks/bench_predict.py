"""`brdfgan predict` end to end at 256², 512², 1024², 2048², 4096² and at its default resolution
(the crop's side, capped at 2048²): wall time, peak memory, the network's share; the default's
guided fast path (the network at a capped side, the maps carried up guided by the photo) against
the exact path at the same side (``--resolution 2048``: the network at 2048², tiled, v4's default
before the fast path) in the same run; and against v3's architecture at 256², 1024², 2048².

Each resolution runs in a fresh subprocess (so its peak RSS is its own) on a synthetic 4000×3000
flash photo (JPEG), with the shipped default weights when they are installed, else a randomly
initialised generator of the same architecture (timings do not depend on the values); v3's
architecture (the paper's generator at width 16) always randomly initialised. Above 1024²
the generator runs tiled (1024² tiles, frozen statistics), so its memory stays that of one tile.
The network's share is predict's own ``network`` stage (``--verbose``), the upsampling its
``upsample`` stage (the fast path only); the rest is decoding, hotspot search, resizing, encoding
seven textures, the .glb and the preview.

``--caps`` also times the default at other network caps (768 unless told). ``--quality``
measures what the fast path costs instead (``quality``): the maps' RMSE against the exact path at
the same side, and the detail measure (:func:`~brdfgan.inference.model.guided.band_detail`: the
base colour's band above half the output's resolution against the de-lit photo's, correlation and
energy ratio) for the exact path, the fast path and the network's maps plainly enlarged; on the
synthetic photo at 2048², the samples at 256² (cap 128) and, with ``--scans DIR …``, flash renders
of scanned material sets at 1024² (also against their true maps).

It also measures the sgemm rate of this machine (4096³ fp32 matmul) and reports the paper
generator's 512² forward against the floor that rate implies (424 GFLOP, docs/conventions.md#generator-cost).

    python -m benchmarks.bench_predict [--sizes 256 512 … default] [--caps 512 768] [--v3-sizes 256 1024 2048]
    python -m benchmarks.bench_predict --quality [--scans ../shared/scans/Wood048 ../shared/ood/ambientcg/*]
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


def run_one(
    photo: Path, weights: Path, size: int | None, out: Path, cap: int | None = None
) -> dict[str, Any]:
    """One predict call in this process (``size`` None: predict's default, its network capped at
    ``cap``, None: predict's own cap); returns seconds (total, network, upsampling), peak RSS
    (MiB), the output side and the network's."""
    from brdfgan.inference.model.weights import load_model
    from brdfgan.inference.pipeline import PredictOptions, Predictor, predict_photo

    model = load_model(weights)
    options = (
        PredictOptions(resolution=size) if cap is None else PredictOptions(resolution=size, network_cap=cap)
    )
    start = time.perf_counter()
    result = predict_photo(photo, out / f"p{size}-{cap}", Predictor.create(model, options))
    total = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    document = json.loads((result.output / "material.json").read_text())
    folder_mib = sum(f.stat().st_size for f in result.output.iterdir()) / 2**20
    page_mib = (result.output / "index.html").stat().st_size / 2**20
    return {
        "total": total,
        "generator": result.timings["network"],
        "upsample": result.timings.get("upsample", 0.0),
        "stages": result.timings,
        "peak_mib": peak,
        "model": model.model_id,
        "side": document["resolution"],
        "network_side": document["inference"]["network_resolution"],
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


def _child(photo: Path, weights: Path, size: str, directory: Path, cap: str = "own") -> dict[str, Any] | None:
    """One predict call in a fresh subprocess (its own peak RSS); None when it failed."""
    command = [sys.executable, "-m", "benchmarks.bench_predict", "--child"]
    command += [str(photo), str(weights), size, str(directory), cap]
    result = subprocess.run(command, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        print(f"{size}² ({weights.name}): failed: {result.stderr.strip().splitlines()[-1:]}")
        return None
    return json.loads(result.stdout.strip().splitlines()[-1])


# --- what the fast path costs in fidelity (--quality) ----------------------------------------------

MAP_SLICES = {
    "base colour": slice(0, 3),
    "normal": slice(3, 6),
    "roughness": slice(6, 7),
    "metallic": slice(7, 8),
}


def _rmse(maps: torch.Tensor, reference: torch.Tensor) -> list[float]:
    return [float((maps[part] - reference[part]).square().mean().sqrt()) for part in MAP_SLICES.values()]


def compare_paths(
    model: Any, photo: torch.Tensor, frame: torch.Tensor, caps: list[int], truth: torch.Tensor | None = None
) -> dict[str, dict[str, Any]]:
    """The exact path, the fast path and the plainly enlarged network maps at each cap, for one
    prepared photo: RMSE per map against the exact path (and ``truth``), the detail measure of
    the base colour in the band above half the photo's side, seconds."""
    from brdfgan.core.svbrdf import resize_maps, srgb_to_linear
    from brdfgan.inference.model.guided import band_detail
    from brdfgan.inference.pipeline import PredictOptions, Predictor

    side = photo.shape[-1]
    with torch.inference_mode():
        anchor = model.generator.anchor(photo[None], frame)

    def measures(maps: torch.Tensor, seconds: float) -> dict[str, Any]:
        detail = band_detail(srgb_to_linear(maps[None, :3]), anchor, side // 2)
        return {
            "rmse_exact": _rmse(maps, exact),
            "rmse_truth": None if truth is None else _rmse(maps, truth),
            "correlation": detail.correlation,
            "energy_ratio": detail.energy_ratio,
            "seconds": seconds,
        }

    start = time.perf_counter()
    exact = Predictor(model, PredictOptions(), side).maps(photo, frame)
    rows = {"exact": measures(exact, time.perf_counter() - start)}
    for cap in caps:
        predictor = Predictor.create(model, PredictOptions(network_cap=cap))
        start = time.perf_counter()
        outputs = predictor.network(photo, frame)
        network = time.perf_counter() - start
        rows[f"fast {cap}"] = measures(predictor.upsample(outputs, photo, frame), time.perf_counter() - start)
        rows[f"enlarged {cap}"] = measures(resize_maps(outputs[:8].clone(), side), network)
    return rows


def _prepared(path: Path, resolution: Any) -> tuple[torch.Tensor, torch.Tensor]:
    from brdfgan.inference.intake.lens import crop_field_of_view
    from brdfgan.inference.intake.photo import read_photo
    from brdfgan.inference.intake.preprocess import preprocess

    photo = read_photo(path)
    prepared = preprocess(photo, resolution)
    fov, _ = crop_field_of_view(photo.lens, photo.width, photo.height, prepared.crop.size)
    return prepared.photo, prepared.flash_frame(fov)


def _rendered(folder: Path, side: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A flash render of a scanned material set at ``side``² (the capture's default field of view),
    auto-exposed as predict would: the photo, its flash frame and the true maps."""
    from brdfgan.core.exposure import auto_expose
    from brdfgan.core.flash_geometry import centred_flash_frame
    from brdfgan.core.render import FlashCapture, render_flash
    from brdfgan.data.materials.scanned import read_scanned_material

    truth = read_scanned_material(folder, side)
    capture = FlashCapture()
    with torch.no_grad():
        photo, _ = auto_expose(render_flash(truth[None], capture)[0])
    return photo.float(), centred_flash_frame(1, side, side, fov_deg=capture.fov_deg), truth


def _print_quality(title: str, results: dict[str, dict[str, dict[str, Any]]]) -> None:
    """Per photo and the mean over photos: RMSE per map against the exact path (and the truth),
    the detail measure."""
    print(f"\n{title}\n")
    with_truth = all(row["rmse_truth"] is not None for rows in results.values() for row in rows.values())
    header = ["photo", "path"] + [f"{name} vs exact" for name in MAP_SLICES]
    header += [f"{name} vs truth" for name in MAP_SLICES] if with_truth else []
    header += ["detail correlation", "detail energy ratio", "s"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    names = list(results) + (["mean"] if len(results) > 1 else [])
    for name in names:
        rows = results[name] if name != "mean" else _mean_rows(list(results.values()))
        for path, row in rows.items():
            cells = [name, path] + [f"{v:.4f}" for v in row["rmse_exact"]]
            cells += [f"{v:.4f}" for v in row["rmse_truth"]] if with_truth else []
            cells += [f"{row['correlation']:.3f}", f"{row['energy_ratio']:.2f}", f"{row['seconds']:.1f}"]
            print("| " + " | ".join(cells) + " |")


def _mean_rows(per_photo: list[dict[str, dict[str, Any]]]) -> dict[str, dict[str, Any]]:
    def mean(values: list[Any]) -> Any:
        if values[0] is None:
            return None
        if isinstance(values[0], list):
            return [sum(column) / len(values) for column in zip(*values, strict=True)]
        return sum(values) / len(values)

    return {
        path: {key: mean([rows[path][key] for rows in per_photo]) for key in per_photo[0][path]}
        for path in per_photo[0]
    }


def quality(photo: Path, weights: Path, scans: list[Path]) -> None:
    """The ``--quality`` tables (module docstring)."""
    from importlib import resources

    from brdfgan.inference.intake.preprocess import CropSized
    from brdfgan.inference.model.guided import anchored_network
    from brdfgan.inference.model.weights import load_model

    model = load_model(weights)
    if anchored_network(model.generator) is None:
        print(f"--quality: {model.model_id} is not photo-anchored: predict keeps the exact path for it")
        return
    big, frame = _prepared(photo, CropSized(model.resolution, 2048))
    _print_quality(
        "Synthetic 12 MP photo at 2048² (crop 3000 px), fast path at each cap against the exact path",
        {"synthetic": compare_paths(model, big, frame, [512, 768, 1024])},
    )
    samples = sorted(Path(str(resources.files("brdfgan") / "samples")).glob("*.jpg"))
    _print_quality(
        "Samples at 256², the network at 128²",
        {
            sample.stem: compare_paths(model, *_prepared(sample, model.resolution), [128])
            for sample in samples
        },
    )
    if scans:
        results = {}
        for folder in scans:
            rendered, rendered_frame, truth = _rendered(folder, 1024)
            results[folder.name] = compare_paths(model, rendered, rendered_frame, [256, 384, 512], truth)
        _print_quality("Flash renders of scanned material sets at 1024², the network at each cap", results)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["256", "512", "1024", "2048", "4096", "default"])
    parser.add_argument(
        "--v3-sizes",
        nargs="*",
        default=["256", "1024", "2048"],
        help="also time v3's architecture at these sizes (random weights)",
    )
    parser.add_argument(
        "--caps", nargs="*", type=int, default=[768], help="also the default at these network caps"
    )
    parser.add_argument("--quality", action="store_true", help="the fast path's fidelity instead of timings")
    parser.add_argument("--scans", nargs="*", type=Path, default=[], help="with --quality: material sets")
    parser.add_argument("--child", nargs=5, help=argparse.SUPPRESS)
    return parser


def main() -> None:
    args = _parser().parse_args()
    if args.child:
        photo, weights, size, out, cap = args.child
        resolution = None if size == "default" else int(size)
        print(
            json.dumps(
                run_one(Path(photo), Path(weights), resolution, Path(out), None if cap == "own" else int(cap))
            )
        )
        return
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp)
        photo = _photo(directory / "flash.jpg")
        weights = _weights(directory)
        if args.quality:
            quality(photo, weights, args.scans)
            return
        v3 = _v3_weights(directory)
        rows = [(size, row) for size in args.sizes if (row := _child(photo, weights, size, directory))]
        rows += [
            (f"default cap {cap}", row)
            for cap in args.caps
            if (row := _child(photo, weights, "default", directory, str(cap)))
        ]
        v3_rows = {size: row for size in args.v3_sizes if (row := _child(photo, v3, size, directory))}
    model = rows[0][1]["model"] if rows else "?"
    _print_timings(rows, model)
    if v3_rows:
        _print_against_v3(rows, v3_rows, model)
    _print_floor()


def _size_label(size: str, row: dict[str, Any]) -> str:
    """The output side, and which default run it was."""
    return f"{row['side']}²" + (f" ({size})" if size.startswith("default") else "")


def _print_timings(rows: list[tuple[str, dict[str, Any]]], model: str) -> None:
    """The timings table, seconds per stage, and the default path against the exact one."""
    threads = torch.get_num_threads()
    print(
        f"\nbrdfgan predict on a 4000×3000 JPEG, model: {model}, {threads} threads; "
        "ratios against the first size\n"
    )
    print(
        "| resolution | network at | wall s | network s | network share | upsample s | peak RSS MiB "
        "| time ratio | memory ratio | output MiB | index.html MiB |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    base = rows[0][1] if rows else {}
    for size, row in rows:
        cells = [
            _size_label(size, row),
            f"{row['network_side']}²",
            f"{row['total']:.1f}",
            f"{row['generator']:.1f}",
            f"{row['generator'] / row['total']:.0%}",
            f"{row['upsample']:.1f}",
            f"{row['peak_mib']:.0f}",
            f"{row['total'] / base['total']:.2f}×",
            f"{row['peak_mib'] / base['peak_mib']:.2f}×",
            f"{row['folder_mib']:.1f}",
            f"{row['page_mib']:.1f}",
        ]
        print("| " + " | ".join(cells) + " |")
    print("\nseconds per stage (predict --verbose):\n")
    for size, row in rows:
        stages = ", ".join(f"{stage} {seconds:.2f}" for stage, seconds in row["stages"].items())
        print(f"- {_size_label(size, row)}: {stages}")
    by_size = dict(rows)
    fast, exact = by_size.get("default"), by_size.get("2048")
    if fast is not None and exact is not None and fast["side"] == exact["side"]:
        print(
            f"\ndefault (network at {fast['network_side']}², guided upsampling) against the exact "
            f"{exact['side']}² path (--resolution {exact['side']}), same run: {fast['total']:.1f} s / "
            f"{exact['total']:.1f} s = {exact['total'] / fast['total']:.1f}× faster; network "
            f"{fast['generator']:.1f} s / {exact['generator']:.1f} s"
        )


def _print_against_v3(
    rows: list[tuple[str, dict[str, Any]]], v3_rows: dict[str, dict[str, Any]], model: str
) -> None:
    """The sizes timed for both architectures, side by side."""
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


def _print_floor() -> None:
    """This machine's sgemm rate against the paper generator's forward pass at 512²."""
    rate = sgemm_gflops()
    forward = paper_forward_512()
    floor = PAPER_GFLOP_512 / rate
    print(
        f"\nsgemm 4096³: {rate:.0f} GFLOP/s; paper generator at 512²: {forward:.2f} s fp32 eager, "
        f"floor {floor:.2f} s ({PAPER_GFLOP_512:.0f} GFLOP) → {forward / floor:.2f}× the floor"
    )


if __name__ == "__main__":
    main()
