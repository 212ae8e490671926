"""What a researcher sees of a run: labelled prediction grids, a real TensorBoard server's
scalars, images and HParams, an offline W&B run's config, name, tags and images, and a sweep
compared by ``brdfgan report``."""

from __future__ import annotations

import glob
import json
import socket
import struct
import subprocess
import sys
import time
import urllib.parse
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from brdfgan.evaluation.evaluator import GRID_COLUMNS, comparison_grid, fixed_samples
from brdfgan.figures import HEADER_HEIGHT, with_column_header
from brdfgan.models.generator import Generator
from brdfgan.models.reference import ConstantMaps
from brdfgan.tracking import run_identity, with_identity
from tests.conftest import run_python

ROOT = Path(__file__).resolve().parents[1]


def test_column_header_names_every_column_and_refuses_a_mismatch() -> None:
    grid = np.zeros((40, 3 * 50, 3), dtype=np.float32)
    labelled = with_column_header(grid, ["input", "normal\nGT", "normal\npred"])
    assert labelled.shape == (HEADER_HEIGHT + 40, 150, 3)
    header = labelled[:HEADER_HEIGHT]
    for column in range(3):  # every column has dark text pixels on the white header
        assert (header[:, column * 50 : (column + 1) * 50] < 0.5).any()
    second_line = header[HEADER_HEIGHT // 2 :]
    assert not (second_line[:, :50] < 0.5).any() and (second_line[:, 50:] < 0.5).any()
    np.testing.assert_array_equal(labelled[HEADER_HEIGHT:], grid)
    with pytest.raises(ValueError, match="4 labels for a grid 150 px wide"):
        with_column_header(grid, ["a", "b", "c", "d"])


@pytest.mark.integration
@pytest.mark.mitsuba
def test_comparison_grid_has_labelled_columns_and_one_row_per_sample(tiny_data: Path) -> None:
    samples = fixed_samples(tiny_data / "data" / "tiny", "val", 2)
    side = samples[0].photo.shape[-1]
    grid = comparison_grid(Generator(width=8, residual_blocks=1), samples)
    assert (
        len(GRID_COLUMNS) == 11 and GRID_COLUMNS[1] == "basecolor\nGT" and GRID_COLUMNS[-1] == "relit\npred"
    )
    assert grid.shape == (HEADER_HEIGHT + 2 * side, 11 * side, 3)
    # The input column is the photo, sRGB-encoded, below the header.
    photo = samples[0].photo.clamp(0, 1).numpy().transpose(1, 2, 0)
    shown = grid[HEADER_HEIGHT : HEADER_HEIGHT + side, :side]
    assert np.corrcoef(shown.ravel(), photo.ravel())[0, 1] > 0.95
    # A model without parameters (the reference predictors `make ood` scores) gets its grid too:
    # its predicted base colour column is its constant.
    constant = comparison_grid(ConstantMaps(), samples)
    assert constant.shape == grid.shape
    predicted_basecolor = constant[HEADER_HEIGHT:, 2 * side : 3 * side]
    assert float(predicted_basecolor.std()) < 1e-6


def test_run_identity_names_a_run_by_what_it_compares() -> None:
    identity = run_identity(
        "train",
        ["loss=no_adv", "seed=1", "trainer.max_epochs=3", "paths.root_dir=/x", "+logger@logger=wandb"],
        {"loss": "no_adv", "model": "default", "hydra/launcher": "basic", "paths": "default", "debug": None},
        "/logs/train/multiruns/2026-12-02_10-00-00",
    )
    assert identity.name == "loss=no_adv seed=1"
    assert identity.tags == ("loss=no_adv", "model=default", "seed=1")
    assert identity.group == "train/2026-12-02_10-00-00"
    single = run_identity("train")
    assert (single.name, single.tags, single.group) == ("train", (), "train")
    # Only W&B takes them, and only where the config leaves them unset.
    from omegaconf import OmegaConf

    target = "lightning.pytorch.loggers.WandbLogger"
    wandb = OmegaConf.create({"_target_": target, "name": None, "group": "mine", "tags": None})
    filled = with_identity(wandb, identity)
    assert (
        filled.name == "loss=no_adv seed=1"
        and filled.group == "mine"
        and list(filled.tags) == list(identity.tags)
    )
    csv = OmegaConf.create({"_target_": "lightning.pytorch.loggers.CSVLogger", "name": "csv"})
    assert with_identity(csv, identity) == csv


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _get(url: str, body: dict[str, Any] | None = None) -> Any:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(url, data=data, headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as response:
        payload = response.read()
    return payload if url.split("?")[0].endswith("individualImage") else json.loads(payload)


@pytest.fixture
def tensorboard_server(tmp_path: Path) -> Iterator[tuple[str, Path]]:
    """A real TensorBoard server on a free localhost port over ``tmp_path/tb`` (filled by the test)."""
    logdir = tmp_path / "tb"
    logdir.mkdir()
    port = _free_port()
    tensorboard = Path(sys.executable).with_name("tensorboard")
    server = subprocess.Popen(
        [str(tensorboard), "--logdir", str(logdir), "--host", "127.0.0.1", "--port", str(port),
         "--reload_interval", "1"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        yield f"http://127.0.0.1:{port}", logdir
    finally:
        server.terminate()
        server.wait(timeout=30)


@pytest.mark.integration
@pytest.mark.mitsuba
def test_tensorboard_server_shows_scalars_prediction_grids_and_hparams(
    tiny_data: Path, tensorboard_server: tuple[str, Path]
) -> None:
    url, logdir = tensorboard_server
    result = run_python(
        "train.py",
        "debug=default",
        "logger=tensorboard",
        "seed=4",
        f"hydra.run.dir={logdir}/run",
        cwd=tiny_data,
        project_root=tiny_data,
    )
    assert result.returncode == 0, result.stderr[-3000:]

    deadline, tags = time.monotonic() + 90, {}
    while time.monotonic() < deadline:  # the server loads the event files in the background
        try:
            images = _get(f"{url}/data/plugin/images/tags")
            if any("test/grid" in found for found in images.values()):
                tags = images
                break
        except OSError:
            pass
        time.sleep(1)
    assert tags, "TensorBoard never showed the grids"
    (run,) = tags
    assert {"val/grid", "test/grid"} <= set(tags[run])
    scalars = _get(f"{url}/data/plugin/scalars/tags")[run]
    assert {"val/loss", "train/g_total_step", "val/rmse/normal", "test/rmse/diffuse"} <= set(scalars)

    # The validation grid: one picture per validation epoch (2 epochs), labelled columns.
    query = urllib.parse.urlencode({"run": run, "tag": "val/grid"})
    entries = _get(f"{url}/data/plugin/images/images?{query}")
    assert len(entries) == 2
    png = _get(f"{url}/data/plugin/images/individualImage?{entries[-1]['query']}")
    picture = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    side = 64  # the tiny dataset's photos
    rows = len(fixed_samples(tiny_data / "data" / "tiny", "val", 4))  # grid_samples=4, or all there are
    assert picture.shape == (HEADER_HEIGHT + rows * side, 11 * side, 3)
    assert picture[:HEADER_HEIGHT].min() < 128 and picture[HEADER_HEIGHT:].std() > 10

    # HParams: the run config, with the monitored metric read from the run's own scalars.
    experiment = _get(f"{url}/data/plugin/hparams/experiment", {"experimentName": ""})
    hparams = {info["name"] for info in experiment["hparamInfos"]}
    assert {"seed", "loss/switches/adversarial", "model/generator/width", "data/batch_size"} <= hparams
    assert not any(name.startswith(("paths/", "logger/", "callbacks/")) for name in hparams)
    assert [m["name"]["tag"] for m in experiment["metricInfos"]] == ["val/loss"]
    groups = _get(f"{url}/data/plugin/hparams/session_groups", {
        "experimentName": "", "startIndex": 0, "sliceSize": 10, "colParams": [],
        "allowedStatuses": ["STATUS_UNKNOWN", "STATUS_SUCCESS", "STATUS_FAILURE", "STATUS_RUNNING"],
    })["sessionGroups"]  # fmt: skip
    (group,) = groups
    assert group["hparams"]["seed"] == 4
    query = urllib.parse.urlencode({"run": run, "tag": "val/loss"})
    last_val_loss = _get(f"{url}/data/plugin/scalars/scalars?{query}")[-1][2]
    assert group["metricValues"][0]["value"] == pytest.approx(last_val_loss)


def _wandb_records(path: Path) -> Iterator[Any]:
    """The protobuf records of an offline W&B run file (``run-<id>.wandb``): LevelDB's log format
    (32 KiB blocks, 7-byte record headers: CRC, length, FULL/FIRST/MIDDLE/LAST) after W&B's
    7-byte file header."""
    from wandb.proto import wandb_internal_pb2

    data = path.read_bytes()
    assert data[:4] == b":W&B"
    block, position, pieces = 32768, 7, b""
    while position + 7 <= len(data):
        left = block - position % block
        length, kind = struct.unpack("<HB", data[position + 4 : position + 7])
        if left < 7 or (length == 0 and kind == 0):  # a block's zero-filled trailer
            position += left
            continue
        pieces += data[position + 7 : position + 7 + length]
        position += 7 + length
        if kind in (1, 4):  # FULL or LAST: a whole record
            record = wandb_internal_pb2.Record()
            record.ParseFromString(pieces)
            pieces = b""
            yield record


@pytest.mark.integration
@pytest.mark.mitsuba
@pytest.mark.slow  # 13-18 s: kept out of make test's 6 minutes (make test-slow runs it)
def test_sweep_of_a_dozen_overrides_logs_each_job_to_its_own_wandb_run_and_reports_by_loss(
    tiny_data: Path, tmp_path: Path
) -> None:
    sweep = tmp_path / "sweep"
    budget = [
        "trainer.max_epochs=1", "trainer.limit_train_batches=2", "trainer.limit_val_batches=1",
        "trainer.log_every_n_steps=1", "trainer.num_sanity_val_steps=0", "trainer.enable_progress_bar=false",
        "trainer.check_val_every_n_epoch=1", "data.num_workers=0", "grid_samples=2",
        "callbacks.mid_epoch_checkpoint.every_n_train_steps=0", "trainer.accelerator=cpu",
        "trainer.devices=1",
    ]  # fmt: skip
    result = run_python("train.py", "-m", "debug=default", "logger=wandb", "loss=full,no_adv", "seed=0,1",
                        *budget, f"hydra.sweep.dir={sweep}", cwd=tiny_data,
                        project_root=tiny_data)  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    jobs = sorted(path.name for path in sweep.iterdir() if path.is_dir())
    assert jobs == [
        "0_loss-full_seed-0",
        "1_loss-full_seed-1",
        "2_loss-no_adv_seed-0",
        "3_loss-no_adv_seed-1",
    ]

    for job in jobs:  # each job its own W&B run: name, tags, group, config and grids
        (run_file,) = glob.glob(str(sweep / job / "wandb" / "offline-run-*" / "run-*.wandb"))
        records = list(_wandb_records(Path(run_file)))
        (run,) = [r.run for r in records if r.WhichOneof("record_type") == "run"]
        loss, seed = job.split("_loss-")[1].split("_seed-")
        assert run.display_name == f"loss={loss} seed={seed}"
        assert run.run_group == "debug/sweep"
        assert {f"loss={loss}", "model=default", f"seed={seed}"} <= set(run.tags)
        config = {u.key: json.loads(u.value_json) for r in records if r.WhichOneof("record_type") == "config"
                  for u in r.config.update}  # fmt: skip
        assert config["seed"] == int(seed) and config["monitor"] == "val/loss"
        assert config["loss"]["switches"]["adversarial"] == (loss == "full")
        media = Path(run_file).parent / "files" / "media" / "images"
        assert list((media / "val").glob("grid_*.png")) and list((media / "test").glob("grid_*.png"))

    report = run_python("-m", "brdfgan.cli", "report", str(sweep), cwd=tiny_data)
    assert report.returncode == 0, report.stderr[-2000:]
    assert "4 runs grouped by loss" in report.stdout
    lines = report.stdout.splitlines()
    assert lines[0].startswith("| loss | n | diffuse |")
    assert lines[2].startswith("| full | 2 | ") and lines[3].startswith("| no_adv | 2 | ")
    assert (sweep / "ablation.md").is_file()  # only the loss varies: the paper-style table too
