"""The TensorBoard screenshots of docs/training.md: a tiny sweep's images and HParams pages, taken with
headless Chromium (Debian's, installed by ``make setup`` as root).

    python scripts/dashboard_screenshots.py [--out docs] [--work /tmp/brdfgan-dashboards]

Trains ``loss=full,no_adv`` × ``seed=0,1`` on the tiny dataset for 3 epochs (a minute or two),
serves the sweep with TensorBoard on a free localhost port and writes
``tensorboard_images.png`` and ``tensorboard_hparams.png`` into ``--out``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import cv2

ROOT = Path(__file__).resolve().parents[1]
# What the probe of this machine found Chromium needs headless in a closed network (no
# background fetches, no first-run pages).
CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars",
)  # fmt: skip
PAGES = {"images": "tensorboard_images.png", "hparams": "tensorboard_hparams.png"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs")
    parser.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "brdfgan-dashboards")
    parser.add_argument("--width", type=int, default=1700, help="browser window width in pixels")
    args = parser.parse_args()
    chromium = shutil.which("chromium")
    if chromium is None:
        raise SystemExit("error: chromium not found (make setup installs Debian's as root)")
    sweep = args.work / "sweep"
    shutil.rmtree(sweep, ignore_errors=True)
    env = {**os.environ, "PROJECT_ROOT": str(args.work)}
    subprocess.run(
        [sys.executable, str(ROOT / "train.py"), "-m", "debug=default", "logger=tensorboard",
         "loss=full,no_adv", "seed=0,1", "trainer.max_epochs=3", "test=false", f"hydra.sweep.dir={sweep}"],
        env=env, check=True, stdout=subprocess.DEVNULL,
    )  # fmt: skip
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    tensorboard = Path(sys.executable).with_name("tensorboard")
    server = subprocess.Popen([str(tensorboard), "--logdir", str(sweep), "--host", "127.0.0.1", "--port",
                               str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        url = f"http://127.0.0.1:{port}"
        for _ in range(60):  # until the server has loaded the runs
            try:
                with urllib.request.urlopen(f"{url}/data/plugin/images/tags", timeout=5) as response:
                    if len(response.read()) > 10:
                        break
            except OSError:
                pass
            time.sleep(1)
        args.out.mkdir(parents=True, exist_ok=True)
        for page, name in PAGES.items():
            shot = args.work / name
            subprocess.run(
                [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={args.work / 'chromium'}",
                 f"--window-size={args.width},1000", "--virtual-time-budget=20000",
                 f"--screenshot={shot}", f"{url}/#{page}"],
                check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=180,
            )  # fmt: skip
            image = cv2.imread(str(shot), cv2.IMREAD_COLOR)
            if image is None:
                raise SystemExit(f"error: chromium wrote no readable screenshot {shot}")
            small = cv2.resize(image, None, fx=0.6, fy=0.6, interpolation=cv2.INTER_AREA)
            cv2.imwrite(str(args.out / name), small, [cv2.IMWRITE_PNG_COMPRESSION, 9])
            print(f"{args.out / name}: {small.shape[1]}×{small.shape[0]}")
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    main()
