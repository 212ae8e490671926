"""``brdfgan predict FLASH --no-flash NOFLASH`` on a 12 MP pair against the single flash photo,
in the same run (issue 59's budget: a 12 MP pair in at most 30 s on the 2-core machine).

The pair is the synthetic flat surface of the pair tests (``tests/inference/pair/scene.py``: a
textured albedo under a warm room light, the flash at the lens, the no-flash photo moved by a
handheld shift, its own white balance and exposure, EXIF stating both) enlarged to 4000 × 3000 and
stored as JPEGs. Each case is one ``brdfgan predict --verbose`` in a fresh subprocess with the
shipped weights at the default resolution (the crop's side, capped at 2048²; the network at
1024², photo-guided; the pair fit at 256² and carried up); median of ``--repeats`` runs; the
stages are predict's own (read, pair, network, fit, export …). The last column is the time
relative to the single photo, measured in the same run.

    python -m benchmarks.bench_pair [--repeats N]
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

WIDTH, HEIGHT = 4000, 3000


def _pair(folder: Path) -> tuple[Path, Path]:
    import cv2
    from tests.inference.pair import scene

    pair = scene.make_pair()

    def enlarged(image: object) -> object:
        return cv2.resize(image, (WIDTH, HEIGHT), interpolation=cv2.INTER_CUBIC)  # type: ignore[call-overload]

    flash = scene.save_jpeg(enlarged(pair.flash), folder / "surface.jpg", scene.FLASH_SETTINGS)
    no_flash = scene.save_jpeg(
        enlarged(pair.no_flash), folder / "surface_noflash.jpg", scene.NO_FLASH_SETTINGS
    )
    return flash, no_flash


def _run(arguments: list[str]) -> tuple[float, dict[str, float]]:
    """Seconds of one ``brdfgan predict`` and its stages (``--verbose``)."""
    command = [sys.executable, "-m", "brdfgan.cli", "predict", *arguments, "--verbose", "--no-preview"]
    start = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f"predict failed: {result.stderr.strip().splitlines()[-1]}")
    stages = {name: float(value) for name, value in re.findall(r"(\w[\w ]*?) ([\d.]+) s", result.stderr)}
    return seconds, stages


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        flash, no_flash = _pair(root)
        cases = {
            "flash photo alone": [str(flash), "--out", str(root / "single")],
            "flash + no-flash pair": [str(flash), "--no-flash", str(no_flash), "--out", str(root / "pair")],
        }
        rows = []
        for name, arguments in cases.items():
            runs = [_run(arguments) for _ in range(args.repeats)]
            rows.append((name, statistics.median(seconds for seconds, _ in runs), runs[-1][1]))
    single = rows[0][1]
    print(f"12 MP ({WIDTH} × {HEIGHT}) JPEGs, default resolution, median of {args.repeats} runs\n")
    print("| case | seconds | × the single photo | stages (last run, s) |")
    print("|---|---|---|---|")
    for name, seconds, stages in rows:
        parts = ", ".join(f"{stage} {value:.1f}" for stage, value in stages.items() if value >= 0.05)
        print(f"| {name} | {seconds:.1f} | {seconds / single:.2f} | {parts} |")


if __name__ == "__main__":
    main()
