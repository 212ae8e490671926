from __future__ import annotations

import io
import tarfile
import warnings
from collections import Counter
from pathlib import Path
from typing import Any

import lightning as L
import pytest
import torch

from brdfgan.data.loading.datamodule import ShardDataModule, ShardWarning, SkipStats, collate_samples
from brdfgan.data.storage.shards import (
    SAMPLE_MEMBERS,
    Sample,
    ShardError,
    encode_sample,
    shard_path,
    write_shard,
)
from tests.conftest import random_maps

SIZE = 8


def make_sample(key: str, seed: int) -> Sample:
    photo = torch.rand(3, SIZE, SIZE, generator=torch.Generator().manual_seed(seed))
    return Sample(key=key, photo=photo, maps=random_maps(SIZE, SIZE, seed=seed), meta={"seed": seed})


def make_split(root: Path, split: str, shard_sizes: list[int]) -> list[str]:
    """Write shards of the given sizes; return all keys."""
    keys = []
    for index, size in enumerate(shard_sizes):
        samples = [make_sample(f"{split}-{index}-{i}", 1000 * index + i) for i in range(size)]
        write_shard(shard_path(root, split, index), samples)
        keys += [s.key for s in samples]
    return keys


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, list[str]]]:
    root = tmp_path_factory.mktemp("dataset")
    keys = {
        "train": make_split(root, "train", [4, 4, 4, 4]),
        "val": make_split(root, "val", [3, 3, 2]),
        "test": make_split(root, "test", [3, 2]),
    }
    return root, keys


def loaded_keys(loader: Any) -> list[str]:
    return [key for batch in loader for key in batch["key"]]


def test_batches_have_the_documented_layout(dataset: tuple[Path, dict[str, list[str]]]) -> None:
    root, keys = dataset
    dm = ShardDataModule(str(root), batch_size=3)
    dm.setup("fit")
    batch = next(iter(dm.train_dataloader()))
    assert batch["photo"].shape == (3, 3, SIZE, SIZE) and batch["photo"].dtype == torch.float32
    assert batch["maps"].shape == (3, 8, SIZE, SIZE) and batch["maps"].dtype == torch.float32
    assert len(batch["key"]) == 3 and all(k in keys["train"] for k in batch["key"])
    assert [m["seed"] for m in batch["meta"]] == [
        int(k.split("-")[1]) * 1000 + int(k.split("-")[2]) for k in batch["key"]
    ]
    val = list(dm.val_dataloader())
    assert [len(b["key"]) for b in val] == [3, 3, 2]  # one worker: partial last batch only
    assert dm.num_samples("train") == 16 and dm.num_samples("val") == 8
    assert dm.skipped == SkipStats()


@pytest.mark.parametrize("num_workers", [0, 2])
def test_val_and_test_see_every_sample_once(
    dataset: tuple[Path, dict[str, list[str]]], num_workers: int
) -> None:
    root, keys = dataset
    dm = ShardDataModule(str(root), batch_size=2, num_workers=num_workers)
    dm.setup("fit")
    dm.setup("test")
    for _ in range(2):  # and again in the next epoch
        val = loaded_keys(dm.val_dataloader())
        assert sorted(val) == sorted(keys["val"])
    test = loaded_keys(dm.test_dataloader())
    assert sorted(test) == sorted(keys["test"])


@pytest.mark.parametrize("num_workers", [0, 2])
def test_val_samples_caps_to_a_fixed_subset(
    dataset: tuple[Path, dict[str, list[str]]], num_workers: int
) -> None:
    root, keys = dataset
    dm = ShardDataModule(str(root), batch_size=2, num_workers=num_workers, val_samples=5)
    dm.setup("validate")
    first = loaded_keys(dm.val_dataloader())
    assert len(first) == len(set(first)) == 5 and set(first) <= set(keys["val"])
    assert loaded_keys(dm.val_dataloader()) == first


@pytest.mark.parametrize("num_workers", [0, 2])
def test_train_epochs_are_exact_and_reshuffled(
    dataset: tuple[Path, dict[str, list[str]]], num_workers: int
) -> None:
    root, keys = dataset
    dm = ShardDataModule(str(root), batch_size=4, num_workers=num_workers, shuffle_buffer=8, seed=3)
    dm.setup("fit")
    assert dm.train_batches_per_epoch == 4
    loader = dm.train_dataloader()
    epochs = []
    for _ in range(2):
        batches = list(loader)
        assert [len(b["key"]) for b in batches] == [4, 4, 4, 4]
        epochs.append([k for b in batches for k in b["key"]])
    # 4 equal shards split over the workers: one epoch is one pass, every sample exactly once.
    assert sorted(epochs[0]) == sorted(epochs[1]) == sorted(keys["train"])
    assert epochs[0] != epochs[1]
    # Same seed, same stream.
    again = ShardDataModule(str(root), batch_size=4, num_workers=num_workers, shuffle_buffer=8, seed=3)
    again.setup("fit")
    assert loaded_keys(again.train_dataloader()) == epochs[0]
    dm.teardown()
    again.teardown()


def test_teardown_stops_train_workers_and_the_loader_still_works(
    dataset: tuple[Path, dict[str, list[str]]],
) -> None:
    root, keys = dataset
    dm = ShardDataModule(str(root), batch_size=4, num_workers=2)
    dm.setup("fit")
    loader = dm.train_dataloader()
    first = loaded_keys(loader)
    workers = list(loader._iterator._workers)
    assert all(w.is_alive() for w in workers)  # persistent between epochs
    dm.teardown("fit")
    assert not any(w.is_alive() for w in workers)
    assert sorted(loaded_keys(loader)) == sorted(first) == sorted(keys["train"])
    loader._iterator._shutdown_workers()


def test_epoch_samples_sets_the_epoch_length(dataset: tuple[Path, dict[str, list[str]]]) -> None:
    root, keys = dataset
    dm = ShardDataModule(str(root), batch_size=4, epoch_samples=40, shuffle_buffer=0)
    dm.setup("fit")
    assert dm.train_batches_per_epoch == 10
    seen = loaded_keys(dm.train_dataloader())
    assert len(seen) == 40
    # The stream repeats: 16 samples, 40 drawn, every sample at least twice.
    assert set(seen) == set(keys["train"]) and min(Counter(seen).values()) >= 2


def test_fewer_shards_than_workers_warns_and_keeps_epoch_length(tmp_path: Path) -> None:
    keys = make_split(tmp_path, "train", [6])
    dm = ShardDataModule(str(tmp_path), batch_size=2, num_workers=2, val_split=None)
    dm.setup("fit")
    with pytest.warns(ShardWarning, match="1 train shard"):
        loader = dm.train_dataloader()
    seen = loaded_keys(loader)
    dm.teardown("fit")
    assert len(seen) == 6 and set(seen) <= set(keys)
    assert dm.val_dataloader() == []


def test_corrupt_shard_is_skipped_with_a_warning(tmp_path: Path) -> None:
    keys = make_split(tmp_path, "val", [3, 3, 3])
    bad = shard_path(tmp_path, "val", 1)
    data = bad.read_bytes()
    bad.write_bytes(data[: len(data) // 2])
    dm = ShardDataModule(str(tmp_path), batch_size=2, num_workers=2)
    with pytest.warns(ShardWarning, match=r"val-000001\.tar"):
        dm.setup("validate")
    assert dm.skipped == SkipStats(shards=1)
    assert dm.skipped.total == 1
    assert sorted(loaded_keys(dm.val_dataloader())) == sorted(k for k in keys if not k.startswith("val-1-"))


def write_shard_with_bad_member(path: Path, samples: list[Sample], bad_key: str) -> None:
    """A structurally valid shard in which one sample's normal map is not a PNG."""
    with tarfile.open(path, "w", format=tarfile.USTAR_FORMAT) as tar:
        for sample in samples:
            files = encode_sample(sample)
            if sample.key == bad_key:
                files["normal.png"] = b"\x89PNG\r\n\x1a\n not really"
            for name in SAMPLE_MEMBERS:
                info = tarfile.TarInfo(f"{sample.key}.{name}")
                info.size = len(files[name])
                tar.addfile(info, io.BytesIO(files[name]))


@pytest.mark.parametrize("num_workers", [0, 2])
def test_corrupt_sample_is_skipped_while_streaming(tmp_path: Path, num_workers: int) -> None:
    keys = make_split(tmp_path, "test", [3, 3])
    samples = [make_sample(f"test-1-{i}", 1000 + i) for i in range(3)]
    write_shard_with_bad_member(shard_path(tmp_path, "test", 1), samples, bad_key="test-1-1")
    dm = ShardDataModule(str(tmp_path), batch_size=2, num_workers=num_workers)
    dm.setup("test")  # the structure is fine: nothing skipped yet
    assert dm.skipped == SkipStats()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        seen = loaded_keys(dm.test_dataloader())
    assert sorted(seen) == sorted(k for k in keys if k != "test-1-1")
    assert dm.skipped == SkipStats(samples=1)
    if num_workers == 0:  # worker processes print their warnings to stderr instead
        assert any("'test-1-1'" in str(w.message) and w.category is ShardWarning for w in caught)


def test_missing_or_empty_split_raises(tmp_path: Path) -> None:
    dm = ShardDataModule(str(tmp_path))
    with pytest.raises(ShardError, match=r"no shards in .*train"):
        dm.setup("fit")
    (tmp_path / "test").mkdir()
    (tmp_path / "test" / ".test-000000.tar.x.tmp").write_bytes(b"partial")
    with pytest.raises(ShardError, match=r"no shards in .*test"):
        dm.setup("test")
    (tmp_path / "val").mkdir()
    (tmp_path / "val" / "val-000000.tar").write_bytes(b"garbage" * 100)
    with pytest.warns(ShardWarning), pytest.raises(ShardError, match="no readable samples"):
        dm.setup("validate")


def test_loaders_need_setup_and_arguments_are_checked(dataset: tuple[Path, dict[str, list[str]]]) -> None:
    root, _ = dataset
    with pytest.raises(RuntimeError, match="setup"):
        ShardDataModule(str(root)).train_dataloader()
    for bad in ({"batch_size": 0}, {"num_workers": -1}, {"shuffle_buffer": -1}, {"val_samples": 0}):
        with pytest.raises(ValueError):
            ShardDataModule(str(root), **bad)


def test_prepare_hook_runs_in_prepare_data(tmp_path: Path) -> None:
    calls = []

    def prepare() -> None:
        calls.append(True)
        make_split(tmp_path, "train", [2])

    dm = ShardDataModule(str(tmp_path), batch_size=2, val_split=None, prepare=prepare)
    dm.prepare_data()
    dm.setup("fit")
    assert calls == [True] and dm.num_samples() == 2


def test_collate_rejects_mixed_sizes() -> None:
    small = make_sample("a", 0)
    large = Sample(key="b", photo=torch.rand(3, 4, 4), maps=random_maps(4, 4), meta={})
    with pytest.raises(ShardError, match="different sizes"):
        collate_samples([small, large])


class _KeyRecorder(L.LightningModule):
    def __init__(self) -> None:
        super().__init__()
        self.layer = torch.nn.Conv2d(3, 8, 1)
        self.train_keys: list[str] = []
        self.val_keys: list[str] = []

    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor:
        self.train_keys += batch["key"]
        return (self.layer(batch["photo"]) - batch["maps"]).abs().mean()

    def validation_step(self, batch: dict[str, Any], batch_idx: int) -> None:
        self.val_keys += batch["key"]
        self.log(
            "val/l1", (self.layer(batch["photo"]) - batch["maps"]).abs().mean(), batch_size=len(batch["key"])
        )

    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.SGD(self.parameters(), lr=0.01)


@pytest.mark.integration
def test_lightning_fit_consumes_the_datamodule(dataset: tuple[Path, dict[str, list[str]]]) -> None:
    root, keys = dataset
    dm = ShardDataModule(str(root), batch_size=4, shuffle_buffer=4)
    model = _KeyRecorder()
    trainer = L.Trainer(
        max_epochs=2,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        num_sanity_val_steps=0,
    )
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*does not have many workers.*")
        warnings.filterwarnings("ignore", message=".*`IterableDataset` has `__len__` defined.*")
        trainer.fit(model, datamodule=dm)
    assert len(model.train_keys) == 2 * 16 and set(model.train_keys) == set(keys["train"])
    assert sorted(model.val_keys) == sorted(keys["val"] * 2)
    assert trainer.global_step == 2 * dm.train_batches_per_epoch
    # The progress bars' totals: 16 samples in 4 full batches; 8 val samples in 2 (no workers).
    assert trainer.num_training_batches == dm.train_batches_per_epoch == 4
    assert trainer.num_val_batches == [2]


def rank_module(
    root: Path, rank: int, world_size: int, monkeypatch: pytest.MonkeyPatch, **options: Any
) -> ShardDataModule:
    """A datamodule that believes it is rank ``rank`` of ``world_size`` (as a DDP trainer would say)."""
    dm = ShardDataModule(str(root), **options)
    monkeypatch.setattr(dm, "_distributed", lambda: (rank, world_size))
    dm.setup("fit")
    return dm


@pytest.mark.parametrize("num_workers", [0, 2])
def test_ranks_partition_the_data(
    dataset: tuple[Path, dict[str, list[str]]], monkeypatch: pytest.MonkeyPatch, num_workers: int
) -> None:
    root, keys = dataset
    ranks = [rank_module(root, r, 2, monkeypatch, batch_size=4, num_workers=num_workers) for r in range(2)]
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", ".*some workers stay idle", ShardWarning)  # rank 1 holds one shard
        val = [loaded_keys(dm.val_dataloader()) for dm in ranks]
    assert not set(val[0]) & set(val[1]) and sorted(val[0] + val[1]) == sorted(keys["val"])
    train = [[b["key"] for b in dm.train_dataloader()] for dm in ranks]
    for dm in ranks:
        dm.teardown()
    # Same number of full batches on every rank (no DDP rank waits); one epoch is one pass.
    assert [len(t) for t in train] == [2, 2] and all(len(b) == 4 for t in train for b in t)
    assert sorted(k for t in train for b in t for k in b) == sorted(keys["train"])
    capped = [rank_module(root, r, 2, monkeypatch, batch_size=2, val_samples=5) for r in range(2)]
    subset = [k for dm in capped for k in loaded_keys(dm.val_dataloader())]
    assert len(subset) == len(set(subset)) == 5


def test_fewer_eval_shards_than_ranks_evaluates_everything_everywhere(
    dataset: tuple[Path, dict[str, list[str]]], monkeypatch: pytest.MonkeyPatch
) -> None:
    root, keys = dataset
    dm = rank_module(root, 3, 4, monkeypatch, batch_size=4)  # 3 val shards, 4 ranks
    with pytest.warns(ShardWarning, match="every rank evaluates the whole split"):
        loader = dm.val_dataloader()
    assert sorted(loaded_keys(loader)) == sorted(keys["val"])


def test_train_crop_takes_matching_windows_and_eval_stays_whole(
    dataset: tuple[Path, dict[str, list[str]]],
) -> None:
    root, _ = dataset
    dm = ShardDataModule(str(root), batch_size=4, train_crop=5, shuffle_buffer=0)
    dm.setup("fit")
    windows = set()
    for batch in dm.train_dataloader():
        assert batch["photo"].shape == (4, 3, 5, 5) and batch["maps"].shape == (4, 8, 5, 5)
        for photo, maps, key, meta in zip(
            batch["photo"], batch["maps"], batch["key"], batch["meta"], strict=True
        ):
            x, y, size = meta["train_crop"]
            _, shard, i = key.split("-")
            whole = make_sample(key, 1000 * int(shard) + int(i))
            # Photo and maps are cut from the same window of the stored sample.
            assert torch.allclose(photo, whole.photo[:, y : y + size, x : x + size], atol=1 / 65535)
            assert torch.allclose(maps[:3], whole.maps[:3, y : y + size, x : x + size], atol=2 / 65535)
            windows.add((x, y))
    assert len(windows) > 1  # positions vary
    assert next(iter(dm.val_dataloader()))["photo"].shape[-1] == SIZE
    with pytest.raises(ValueError, match="train_crop"):
        ShardDataModule(str(root), train_crop=0)
    too_big = ShardDataModule(str(root), batch_size=1, train_crop=SIZE + 1)
    too_big.setup("fit")
    with pytest.raises(ShardError, match="larger than sample"):
        next(iter(too_big.train_dataloader()))


# -- len(loader): the progress bars' totals ----------------------------------------------------


def counted_batches(loader: Any) -> list[list[str]]:
    """The keys of every batch of one pass, checking that ``len(loader)`` announced that many."""
    announced = len(loader)  # asked first, as Lightning does (torch then warns on an overrun)
    batches = [batch["key"] for batch in loader]
    assert announced == len(batches)
    return batches


@pytest.mark.parametrize("val_samples", [None, 5])
@pytest.mark.parametrize("num_workers", [0, 2])
def test_loader_len_is_the_number_of_batches(
    dataset: tuple[Path, dict[str, list[str]]], num_workers: int, val_samples: int | None
) -> None:
    root, keys = dataset
    dm = ShardDataModule(str(root), batch_size=2, num_workers=num_workers, val_samples=val_samples)
    dm.setup("fit")
    dm.setup("test")
    train = dm.train_dataloader()
    for _ in range(2):  # the persistent workers' second epoch too
        assert len(counted_batches(train)) == dm.train_batches_per_epoch == 8
    dm.teardown()
    val = counted_batches(dm.val_dataloader())
    assert sum(len(b) for b in val) == (val_samples or len(keys["val"]))
    test = counted_batches(dm.test_dataloader())
    assert sum(len(b) for b in test) == len(keys["test"])


def test_loader_len_with_more_workers_than_shards(tmp_path: Path) -> None:
    make_split(tmp_path, "train", [6])
    make_split(tmp_path, "val", [3])
    make_split(tmp_path, "test", [5])
    dm = ShardDataModule(str(tmp_path), batch_size=2, num_workers=2)
    dm.setup("fit")
    dm.setup("test")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ShardWarning)  # every train worker streams everything; idle workers
        train = counted_batches(dm.train_dataloader())
        dm.teardown()
        val = counted_batches(dm.val_dataloader())
        test = counted_batches(dm.test_dataloader())
    # One shard per split: every train worker streams it, one val/test worker reads it, one idles.
    assert len(train) == 3 and [len(b) for b in val] == [2, 1] and [len(b) for b in test] == [2, 2, 1]


@pytest.mark.parametrize(("world_size", "val_samples"), [(2, None), (2, 5), (3, None), (4, 3)])
def test_loader_len_on_every_rank(
    dataset: tuple[Path, dict[str, list[str]]],
    monkeypatch: pytest.MonkeyPatch,
    world_size: int,
    val_samples: int | None,
) -> None:
    root, keys = dataset
    totals = Counter[str]()
    for rank in range(world_size):
        dm = rank_module(
            root, rank, world_size, monkeypatch, batch_size=2, num_workers=2, val_samples=val_samples
        )
        dm.setup("test")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ShardWarning)  # too few shards for some of these worlds
            train = counted_batches(dm.train_dataloader())
            dm.teardown()
            val = counted_batches(dm.val_dataloader())
            test = counted_batches(dm.test_dataloader())
        assert len(train) == dm.train_batches_per_epoch
        totals["val"] += sum(len(b) for b in val)
        totals["test"] += sum(len(b) for b in test)
    # With fewer shards than ranks (3 val, 2 test shards) every rank evaluates the whole split,
    # val_samples capping each rank's pass.
    val_ranks = 1 if world_size <= 3 else world_size
    test_ranks = 1 if world_size <= 2 else world_size
    assert totals["val"] == val_ranks * (val_samples or len(keys["val"]))
    assert totals["test"] == test_ranks * len(keys["test"])
