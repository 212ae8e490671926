"""Sensor simulation benchmark: the time ``SensorEffects.apply`` adds per training photo, for the
data configs' sensors (the v3 recipe's, the phone-delivered one of ``data=procedural_and_scans``
and its evaluation sensor), with the ratio to the v3 recipe's, measured in one run.

The photos are 256² renders of smooth procedural-looking maps (the dataset's stored size; the
DataModule applies the sensor before the 128² training window is cut). One thread, as the
DataModule decodes in the training process. The per-batch cost is for the default model's batch
of 4, the figure to hold against its ~0.3–0.4 s step.

    python -m benchmarks.bench_sensor [--photos 24] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import hydra
import torch
from hydra import compose, initialize_config_dir

from brdfgan.core.exposure import auto_expose
from brdfgan.core.render import render_flash
from brdfgan.data.phone.flash import blackbody_rgb
from brdfgan.data.phone.sensor import SensorEffects
from brdfgan.training.config import register_configs

CONF = Path(__file__).resolve().parents[1] / "conf"
BATCH = 4
# name -> (data config, which sensor)
SENSORS = {
    "v3 recipe (data=procedural), train": ("procedural", "sensor"),
    "phone-delivered (data=procedural_and_scans), train": ("procedural_and_scans", "sensor"),
    "phone-delivered, val/test (conf/sensor/phone_eval)": ("procedural_and_scans", "eval_sensor"),
}


def _sensor(data: str, which: str) -> SensorEffects:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="train", overrides=[f"data={data}"])
    sensor = hydra.utils.instantiate(cfg.data[which], _convert_="all")
    assert isinstance(sensor, SensorEffects)
    return sensor


def _photos(count: int) -> list[torch.Tensor]:
    from tests.conftest import random_maps

    photos = []
    for index in range(count):
        maps = random_maps(256, 256, seed=index)
        photos.append(auto_expose(render_flash(maps[None])[0])[0])
    return photos


def _seconds_per_photo(sensor: SensorEffects, photos: list[torch.Tensor], repeats: int) -> float:
    illuminant = blackbody_rgb(4500.0)
    runs = []
    for repeat in range(repeats):
        start = time.perf_counter()
        for index, photo in enumerate(photos):
            sensor.apply(
                photo, torch.Generator().manual_seed(repeat * 1000 + index), illuminant_rgb=illuminant
            )
        runs.append((time.perf_counter() - start) / len(photos))
    return statistics.median(runs)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--photos", type=int, default=24)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    register_configs()
    photos = _photos(args.photos)
    times = {
        name: _seconds_per_photo(_sensor(*where), photos, args.repeats) for name, where in SENSORS.items()
    }
    reference = times[next(iter(SENSORS))]
    print(
        f"\nSensor simulation per 256² photo (one thread; median of {args.repeats} runs of "
        f"{args.photos} photos):\n"
    )
    print(f"| sensor | ms per photo | ms per batch of {BATCH} | vs the v3 recipe's |")
    print("|---|---|---|---|")
    for name, seconds in times.items():
        print(f"| {name} | {seconds * 1e3:.1f} | {seconds * BATCH * 1e3:.0f} | {seconds / reference:.2f}× |")


if __name__ == "__main__":
    main()
