"""How should ``brdfgan predict`` make maps larger than the model's training resolution?

Measures, on photos rendered at high resolution with ground truth (e.g. the OOD scans rendered
whole at 1024²: ``python generate.py dataset_spec=ood resolution=1024 crops_per_material=2
crop.scale_min=1 crop.scale_max=1 out_dir=data/ood_1024``), the maps of every photo made three ways
at each output size N, each through predict's own intake (the photo written as an 8-bit sRGB PNG,
read, cropped around its hotspot and auto-exposed, no EXIF):

- ``upsampled``: the network at its training resolution, the maps enlarged to N
  (:func:`~brdfgan.core.svbrdf.resize_maps`: bilinear, base colour in linear, normals renormalised);
- ``native``: the network on the N² photo (tiled above the tiling's direct size);
- ``detail``: ``upsampled`` plus the high frequencies of ``native`` (``native`` minus its own
  low-pass at the training resolution): the network's judgement at the scale it was trained for,
  the fine detail it sees at N.

Prints a table of the SVBRDF metrics (full-resolution RMSE per map, the RMSE after downscaling to
256², normal angle, novel-light re-render error) per method and size, with the seconds per photo.

    python scripts/measure_output_resolution.py data/ood_1024 --sizes 512 1024
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch
from torch import Tensor

from brdfgan.core.svbrdf import linear_to_srgb, normalize_normal, resize_maps
from brdfgan.data.capture import sample_as_photographed
from brdfgan.data.shards import iter_shard, list_shards
from brdfgan.inference.intake.lens import crop_field_of_view
from brdfgan.inference.intake.photo import read_photo
from brdfgan.inference.intake.preprocess import preprocess
from brdfgan.inference.model.tiling import TilingConfig, predict_maps
from brdfgan.inference.model.weights import load_model
from brdfgan.io.images import write_image
from brdfgan.metrics import SVBRDFMetrics

METHODS = ("upsampled", "native", "detail")


def with_detail(coarse: Tensor, fine: Tensor, model_size: int) -> Tensor:
    """``coarse`` (enlarged) plus ``fine``'s detail above the model resolution, kept valid."""
    detailed = coarse + (fine - resize_maps(resize_maps(fine, model_size), fine.shape[-1]))
    return torch.cat([detailed[0:3].clamp(0, 1), normalize_normal(detailed[3:6]), detailed[6:8].clamp(0, 1)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", type=Path, help="a dataset folder with a test split")
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024])
    parser.add_argument("--limit", type=int, default=0, help="at most this many photos (0: all)")
    args = parser.parse_args()

    model = load_model(None)
    generator = model.generator.eval()
    tiling = TilingConfig()
    metrics = {(m, n): SVBRDFMetrics(downscale_to=256) for m in METHODS for n in args.sizes}
    seconds = {(m, n): 0.0 for m in METHODS for n in args.sizes}
    count = 0
    with tempfile.TemporaryDirectory() as folder, torch.no_grad():
        for shard in list_shards(args.data, "test"):
            for sample in iter_shard(shard):
                if args.limit and count >= args.limit:
                    break
                sample = sample_as_photographed(sample)
                path = Path(folder) / f"{sample.key}.png"
                write_image(path, linear_to_srgb(sample.photo).permute(1, 2, 0).numpy())
                photo = read_photo(path)
                predicted: dict[int, Tensor] = {}
                for size in [model.resolution, *args.sizes]:
                    started = time.perf_counter()
                    prepared = preprocess(photo, size)
                    fov, _ = crop_field_of_view(photo.lens, photo.width, photo.height, prepared.crop.size)
                    frame = prepared.flash_frame(fov)
                    predicted[size] = predict_maps(generator, prepared.photo[None], tiling, flash=frame)[0]
                    if size != model.resolution:
                        seconds[("native", size)] += time.perf_counter() - started
                for size in args.sizes:
                    truth = resize_maps(sample.maps, size)[None]
                    started = time.perf_counter()
                    coarse = resize_maps(predicted[model.resolution], size)
                    seconds[("upsampled", size)] += time.perf_counter() - started
                    outputs = {
                        "upsampled": coarse,
                        "native": predicted[size],
                        "detail": with_detail(coarse, predicted[size], model.resolution),
                    }
                    for method, maps in outputs.items():
                        metrics[(method, size)].update(maps[None], truth)
                count += 1
    keys = ["rmse/basecolor", "rmse/normal", "rmse/roughness", "rmse/metallic", "rmse256/basecolor",
            "rmse256/normal", "rmse256/roughness", "normal_angle_deg", "rerender_rmse"]  # fmt: skip
    print(f"{count} photos, model {model.model_id} at {model.resolution}²")
    print("| method | N | " + " | ".join(keys) + " | s/photo |")
    print("|---|---|" + "---|" * (len(keys) + 1))
    for (method, size), metric in metrics.items():
        values = metric.compute()
        row = " | ".join(f"{float(values[k]):.4f}" for k in keys)
        print(f"| {method} | {size} | {row} | {seconds[(method, size)] / max(count, 1):.2f} |")


if __name__ == "__main__":
    main()
