"""``brdfgan predict --views`` end to end: seconds for 2, 3 and 5 photos at 512² beside one photo
(issue 47's budget: 5 photos at 512² in at most 60 s on the 2-core machine), and where the time goes.

The photos are a synthetic handheld capture (:mod:`research.synthetic_captures`: Mitsuba,
the evaluation sensor, cameras drawn as a hand holds them) of a textured surface, 512 × 512 each,
rendered once before the clock starts. Each case is one in-process call of
:func:`brdfgan.inference.views.pipeline.predict_views` with the shipped weights, maps at 512²
(``--resolution 512``; the fit at its default 128² then 256², carried up to 512²), median of
``--repeats`` calls after one warm-up; the stages are predict's own (read, network, register,
fit, preview, export …). The last column is the time relative to one photo, measured in the same
run.

    python -m benchmarks.bench_views [--repeats N]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path


def _photos(folder: Path, views: int) -> list[Path]:
    from research.synthetic_captures import (
        HandheldSettings,
        render_synthetic_capture,
        write_synthetic_capture,
    )
    from research.tests.test_synthetic_captures import centre_of, eval_sensor, textured_surface

    surface = textured_surface(256)
    settings = HandheldSettings(views=views, width=512, height=512, fill=0.7)
    capture = render_synthetic_capture(centre_of(surface), settings, eval_sensor(), seed=0, surround=surface)
    write_synthetic_capture(capture, centre_of(surface), folder)
    return [folder / "handheld" / f"{index:02d}.png" for index in range(views)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()

    from brdfgan.inference.intake.lens import FieldOfView
    from brdfgan.inference.model.weights import load_model
    from brdfgan.inference.pipeline import PredictOptions, Predictor
    from brdfgan.inference.views.pipeline import predict_views

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        photos = _photos(root / "capture", 5)
        options = PredictOptions(resolution=512, field_of_view=FieldOfView(photo_fov_deg=65.0))
        predictor = Predictor.create(load_model(None), options)
        rows = []
        for count in (1, 2, 3, 5):
            seconds, stages = [], {}
            for repeat in range(args.repeats + 1):  # the first is a warm-up
                start = time.perf_counter()
                result = predict_views(photos[:count], root / f"out{count}-{repeat}", predictor)
                seconds.append(time.perf_counter() - start)
                stages = result.timings
            rows.append((count, statistics.median(seconds[1:]), stages))
        single = rows[0][1]
        print("| photos | seconds | × one photo | stages (last run) |")
        print("|---|---|---|---|")
        for count, total, stages in rows:
            parts = ", ".join(f"{stage} {value:.1f}" for stage, value in stages.items() if value >= 0.05)
            print(f"| {count} | {total:.1f} | {total / single:.1f} | {parts} |")


if __name__ == "__main__":
    main()
