"""The dataset_spec and data configs compose and build what they say (no data is generated)."""

from __future__ import annotations

import copy
import dataclasses
import re
import typing

import hydra
import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import InstantiationException
from omegaconf import DictConfig, OmegaConf

from brdfgan.data.generation.generation import plan_shards
from brdfgan.data.loading.datamodule import ShardDataModule
from brdfgan.data.spec.dataset_spec import DatasetSpec, spec_from_config
from brdfgan.data.storage.spec_checks import DatasetConfigError
from tests.conftest import CONF, SHARED

# The configs that mix in the real scans need them (../shared/scans, as the configs default to).
SCANS = SHARED / "scans"
OOD = SHARED / "ood" / "ambientcg"
NEEDS_SCANS = pytest.mark.skipif(
    not (SCANS.is_dir() and OOD.is_dir()),
    reason="the scanned materials (../shared/scans, ../shared/ood) are not here",
)

WITH_SCANS = pytest.param("procedural_and_scans", marks=NEEDS_SCANS)
CLOSE_OOD = pytest.param("ood_close", marks=NEEDS_SCANS)


def _compose(overrides: list[str], config_name: str = "generate"):  # type: ignore[no-untyped-def]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name=config_name, overrides=overrides)


@pytest.mark.integration
@pytest.mark.parametrize("name", ["default", "tiny", "paper", WITH_SCANS, CLOSE_OOD])
def test_every_dataset_config_builds_a_valid_spec(name: str) -> None:
    spec = hydra.utils.instantiate(_compose([f"dataset_spec={name}"]).dataset_spec, _convert_="all")
    assert isinstance(spec, DatasetSpec)
    assert plan_shards(spec)


@pytest.mark.integration
def test_paper_dataset_follows_the_paper_protocol() -> None:
    spec = hydra.utils.instantiate(_compose(["dataset_spec=paper"]).dataset_spec, _convert_="all")
    assert (spec.material_resolution, spec.resolution, spec.spp) == (2048, 512, 196)
    assert (spec.crops_per_material, spec.train_renders, spec.eval_renders) == (7, 3, 1)
    assert spec.test_fraction == 0.2
    assert (spec.lighting.train_count, spec.lighting.test_count) == (20, 6)
    train_samples = sum(j.sample_count(spec) for j in plan_shards(spec) if j.split == "train")
    assert abs(train_samples - 40544) / 40544 < 0.01  # the paper's training-set size


@pytest.mark.integration
@pytest.mark.parametrize("name", ["default", "tiny", "paper", "deschaintre", WITH_SCANS, CLOSE_OOD])
def test_data_configs_instantiate_a_datamodule(name: str) -> None:
    cfg = _compose([f"data={name}"], config_name="train")
    module = hydra.utils.instantiate(cfg.data, _convert_="all")
    assert isinstance(module, ShardDataModule)
    if name in ("paper", "deschaintre"):
        assert module._prepare is None  # too big to make on the fly / converted, not generated
        return
    # The prepare hook generates exactly the dataset generate.py makes for the same name.
    prepare = module._prepare
    assert prepare is not None and prepare.keywords["out_dir"] == f"./data/{name}"
    # Generated on first use there, inside paths.data_dir; nowhere else unless data.prepare.generate=true.
    assert prepare.keywords["generate_under"] == "./data" and prepare.keywords["generate"] is False
    generated = hydra.utils.instantiate(_compose([f"dataset_spec={name}"]).dataset_spec, _convert_="all")
    assert prepare.keywords["spec"] == generated


def _numeric_keys(node: DictConfig, prefix: str) -> list[str]:
    """Every int/float leaf under ``node`` as typed on the command line (bools are not numbers)."""
    keys = []
    for name, value in node.items():
        key = f"{prefix}.{name}"
        if isinstance(value, DictConfig):
            keys += _numeric_keys(value, key)
        elif isinstance(value, int | float) and not isinstance(value, bool):
            keys.append(key)
    return keys


# Composed once; each case edits a copy, as a command-line override would.
BASE = _compose(["dataset_spec=default"])
# Any integer is a usable seed; every other number of the spec has a range.
NUMERIC_KEYS = [key for key in _numeric_keys(BASE.dataset_spec, "dataset_spec") if key != "dataset_spec.seed"]


def _spec_with(**values: object) -> DatasetSpec:
    cfg = copy.deepcopy(BASE)
    for key, value in values.items():
        OmegaConf.update(cfg, key, value)
    return spec_from_config(cfg.dataset_spec)


def _spec_numeric_fields(cls: type, prefix: str) -> set[str]:
    hints = typing.get_type_hints(cls)
    keys = set()
    for field in dataclasses.fields(cls):
        kind = hints[field.name]
        if kind in (int, float) or int in typing.get_args(kind):  # a number, or a number or names
            keys.add(f"{prefix}.{field.name}")
        elif dataclasses.is_dataclass(kind):
            keys |= _spec_numeric_fields(kind, f"{prefix}.{field.name}")
    return keys


def test_the_config_walk_covers_every_numeric_field_of_the_spec_classes() -> None:
    assert set(NUMERIC_KEYS) == _spec_numeric_fields(DatasetSpec, "dataset_spec") - {"dataset_spec.seed"}


# Signed values, where -1 is a valid setting: their out-of-range example instead.
OUT_OF_RANGE = {"dataset_spec.capture.exposure_ev_min": -5}


@pytest.mark.parametrize("key", NUMERIC_KEYS)
@pytest.mark.parametrize("bad", [-1, "abc"])
def test_every_numeric_value_is_checked_at_composition_naming_its_key(key: str, bad: object) -> None:
    # -1 is out of range for every one of them but the signed ones; 'abc' is a typo that must not
    # reach a comparison.
    bad = OUT_OF_RANGE.get(key, bad) if bad == -1 else bad
    with pytest.raises(DatasetConfigError, match=re.escape(f"{key}={bad!r}")):
        _spec_with(**{key: bad})


@pytest.mark.parametrize("low_key", [key for key in NUMERIC_KEYS if key.endswith(("_min", "_min_k"))])
def test_an_inverted_min_max_pair_is_refused(low_key: str) -> None:
    high_key = low_key.replace("_min", "_max")
    high = OmegaConf.select(BASE, high_key)
    low = high * 1.5 if high > 0 else high + 0.25  # above its maximum (a maximum of 0: switched off)
    message = f"{low_key}={low:g} > {high_key}={high:g}"
    with pytest.raises(DatasetConfigError, match=re.escape(message)):
        _spec_with(**{low_key: low})


def test_the_issue_example_names_both_keys() -> None:
    with pytest.raises(DatasetConfigError) as error:
        _spec_with(
            **{"dataset_spec.flash.temperature_min_k": 9000, "dataset_spec.flash.temperature_max_k": 1000}
        )
    assert str(error.value).startswith(
        "dataset_spec.flash.temperature_min_k=9000 > dataset_spec.flash.temperature_max_k=1000"
    )


def test_other_instantiation_errors_keep_hydras_message() -> None:
    # An unknown key inside a nested spec is not a value error: Hydra's message (naming the key) stays.
    cfg = copy.deepcopy(BASE)
    OmegaConf.set_struct(cfg, False)
    cfg.dataset_spec.flash.no_such_key = 1
    with pytest.raises(InstantiationException, match="no_such_key"):
        spec_from_config(cfg.dataset_spec)


@pytest.mark.integration
@NEEDS_SCANS
def test_the_phone_delivered_data_configs() -> None:
    # Training photos and their validation/test photos go through the phone's white balance and
    # look; the close-range OOD benchmark's test photos too, its standard variant keeps predict's
    # intake alone (its numbers stay comparable with earlier models').
    scans = hydra.utils.instantiate(_compose(["data=procedural_and_scans"], "train").data, _convert_="all")
    assert scans.sensor.auto_white_balance and scans.sensor.tone_curve_probability > 0
    assert scans.eval_sensor.auto_white_balance and scans.eval_sensor.noise_probability == 0
    spec = scans._prepare.keywords["spec"]
    assert spec.scans.enabled and (spec.capture.fov_min_deg, spec.capture.fov_max_deg) == (20.0, 75.0)
    close = hydra.utils.instantiate(_compose(["data=ood_close"], "train").data, _convert_="all")
    standard = hydra.utils.instantiate(_compose(["data=ood"], "train").data, _convert_="all")
    assert close.eval_sensor == scans.eval_sensor and not standard.eval_sensor.auto_white_balance
    close_spec, standard_spec = close._prepare.keywords["spec"], standard._prepare.keywords["spec"]
    assert (close_spec.capture.fov_min_deg, close_spec.capture.fov_max_deg) == (20.0, 30.0)
    assert (
        dataclasses.replace(close_spec, capture=standard_spec.capture) == standard_spec
    )  # only the FOV differs


@pytest.mark.integration
@NEEDS_SCANS
def test_the_ood_benchmarks_make_pairs_and_the_other_datasets_do_not() -> None:
    # Issue 59: the OOD variants hold each photo's no-flash twin; every other dataset keeps its
    # identity (pairs is recorded only when on).
    for name, pairs in (("ood", True), ("ood_close", True), ("default", False), ("tiny", False)):
        spec = spec_from_config(_compose([f"dataset_spec={name}"]).dataset_spec)
        assert spec.pairs is pairs and ("pairs" in spec.to_json()) is pairs, name
    data = hydra.utils.instantiate(_compose(["data=ood_close"], "train").data, _convert_="all")
    assert data._prepare.keywords["spec"].pairs
