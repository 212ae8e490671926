"""Dataset generation benchmark: samples per hour and where the time goes.

For each case, materials go through the whole production path of
:func:`brdfgan.data.generation.generation.material_samples` — family maps at the material resolution,
crops, captures per crop (environment + flash, Mitsuba, auto exposure) — and every sample is
encoded as it would be written to a shard. The first two cases are the paper-like protocol
(7 crops × 3 captures per material); the last is the procedural dataset (v3's recipe)
(``conf/dataset_spec/procedural.yaml``: 512² materials, 2 crops × 1 capture, mixing,
recolouring, randomised capture), composed from its config file. The time inside
``mi.render`` is Mitsuba's; the rest (material painting, crops, environment building, scene
updates, exposure; PNG encoding, which overlaps the next render on a second thread; the tar
and its SHA-256) is our overhead.

    python -m benchmarks.bench_generate [--materials N]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

# (resolution, spp, material resolution) of the paper-like cases; "recipe" = the v3 recipe.
CASES: list[str] = ["256,64,1024", "512,196,2048", "recipe"]


def _recipe_spec() -> Any:
    from hydra import compose, initialize_config_dir

    from brdfgan.data.generation.generate_config import register_configs
    from brdfgan.data.spec.dataset_spec import spec_from_config

    register_configs()
    with initialize_config_dir(str(Path(__file__).resolve().parents[1] / "conf"), version_base="1.3"):
        cfg = compose("generate", overrides=["dataset_spec=procedural"])
    return spec_from_config(cfg.dataset_spec)


def _measure(case: str, materials: int) -> dict[str, float]:
    from brdfgan.data.spec.determinism import single_torch_thread

    with single_torch_thread():  # as run_generation does
        return _measure_spec(case, materials)


def _measure_spec(case: str, materials: int) -> dict[str, float]:
    from brdfgan.data.generation.generation import MitsubaPhotographer, material_samples
    from brdfgan.data.phone.environments import build_environment_pools, load_environment
    from brdfgan.data.spec.dataset_spec import DatasetSpec
    from brdfgan.data.spec.determinism import derive_seed
    from brdfgan.data.storage.shards import write_shard

    if case == "recipe":
        spec = _recipe_spec()
        # Enough materials per case for the recipe's few photos each to average out.
        materials *= 8
    else:
        resolution, spp, material_resolution = map(int, case.split(","))
        spec = DatasetSpec(
            materials=10 * materials, material_resolution=material_resolution, resolution=resolution, spp=spp
        )
    pools = build_environment_pools(spec.lighting, derive_seed(spec.seed, "lighting"))
    photographer = MitsubaPhotographer(spec)
    # Warm-up: Mitsuba kernel compilation and the environment cache are one-off costs of a run.
    for lighting_spec in pools.train:
        load_environment(lighting_spec, spec.lighting.resolution)
    next(material_samples(spec, "train", 0, pools, photographer))
    photographer.mitsuba_seconds = 0.0

    samples, shard_bytes = 0, 0
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        for material in range(1, materials + 1):
            # As run_generation writes them: encoded on a second thread, tar, atomic rename, SHA-256.
            info = write_shard(Path(folder) / f"train-{material:06d}.tar",
                               material_samples(spec, "train", material, pools, photographer))  # fmt: skip
            samples += info.count
            shard_bytes += info.bytes
        total = time.perf_counter() - start
    return {
        "samples": samples,
        "total_s": total,
        "mitsuba_s": photographer.mitsuba_seconds,
        "bytes_per_sample": shard_bytes / samples,
        "resolution": spec.resolution,
        "spp": spec.spp,
        "material_resolution": spec.material_resolution,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--materials", type=int, default=1, help="materials per case (21 samples each)")
    parser.add_argument("--case", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        print(json.dumps(_measure(args.case, args.materials)))
        return

    rows = []
    for case in CASES:
        command = [sys.executable, "-m", "benchmarks.bench_generate", "--materials", str(args.materials)]
        command += ["--case", case]
        out = subprocess.run(command, check=True, capture_output=True, text=True)
        rows.append((case, json.loads(out.stdout.strip().splitlines()[-1])))

    print(
        f"\nDataset generation, {args.materials} material(s) × 7 crops × 3 captures per paper-like case, "
        f"{8 * args.materials} materials of the v3 recipe (after warm-up); overhead = everything outside "
        "mi.render; ratios against the first row\n"
    )
    header = (
        "case resolution spp material-res samples s/sample samples/h in-mitsuba overhead MB/sample slower"
    )
    print("| " + " | ".join(header.split()) + " |")
    print("|" + "---|" * len(header.split()))
    base = rows[0][1]["total_s"] / rows[0][1]["samples"]
    for case, m in rows:
        per_sample = m["total_s"] / m["samples"]
        cells = [
            "v3 recipe" if case == "recipe" else "paper-like", f"{m['resolution']}²", str(m["spp"]),
            f"{m['material_resolution']}²", str(m["samples"]), f"{per_sample:.2f}",
            f"{3600.0 / per_sample:.0f}", f"{m['mitsuba_s'] / m['total_s']:.0%}",
            f"{1.0 - m['mitsuba_s'] / m['total_s']:.0%}", f"{m['bytes_per_sample'] / 1e6:.2f}",
            f"{per_sample / base:.1f}×",
        ]  # fmt: skip
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
