"""``--tileable``'s choice of path (``inference/pipeline.py``'s ``make_tileable``): a periodic
material is tiled by whole lattice cells, a 1-D pattern by whole periods across its stripes,
anything else exactly as before; ``material.json``
records the lattice, its cells and the method, round-trips, and a note says which path an
ambiguous or unusable lattice took; ``--align-pattern`` turns the lattice onto the axes."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest
import torch
from torch import Tensor

import brdfgan.inference.pipeline as pipeline
from brdfgan.cli import main
from brdfgan.core.flash_mark import repair_flash_mark
from brdfgan.core.lattice import Lattice, find_lattice
from brdfgan.core.seamless import make_seamless
from brdfgan.core.svbrdf import validate_maps
from brdfgan.errors import USER_ERROR_EXIT_CODE
from brdfgan.inference.pipeline import TileableRecord, make_tileable, tile_pattern
from tests.core.test_lattice import SIZE, brick_maps, lattice_maps, noise_maps, polar, setts_maps
from tests.core.test_stripes import planks

HOTSPOT = (SIZE / 2, SIZE / 2)


def tiles() -> Tensor:
    return lattice_maps(polar(24.0, 30.0), polar(30.0, 120.0), seed=11)


def round_trip(record: TileableRecord) -> dict[str, object]:
    document = json.loads(json.dumps(record.to_json()))
    assert TileableRecord.from_json(document) == record
    return document


def todays_tile(maps: Tensor) -> Tensor:
    """What ``--tileable`` made of any material before lattices: the repaired maps, cut."""
    return make_seamless(repair_flash_mark(maps, HOTSPOT)[0]).maps


def test_a_periodic_material_is_tiled_by_whole_cells_and_recorded() -> None:
    maps = tiles()
    tiled, record = make_tileable(maps, HOTSPOT)
    validate_maps(tiled)
    assert record.lattice is not None and record.lattice.periodic and record.cells is not None
    assert record.note is None
    document = round_trip(record)
    lattice = document["lattice"]
    assert isinstance(lattice, dict) and lattice["method"] == "autocorrelation"
    assert lattice["cells"]["cells"] == record.cells.cells >= 10
    assert set(lattice["cells"]["counts"]) == {"u", "v"}
    assert "whole lattice cells" in str(document["method"])
    assert min(record.after.copied_fraction.values()) >= 0.85
    assert max(max(pair) for pair in record.after.wrap_ratio.values()) <= 1.2
    assert not torch.equal(tiled, todays_tile(maps))


def test_a_lattice_in_mild_perspective_is_rectified_before_its_cells_are_cut_and_recorded() -> None:
    g = (0.02 / (SIZE / 2), 0.015 / (SIZE / 2))
    maps = lattice_maps(polar(24.0, 30.0), polar(30.0, 120.0), perspective=g, seed=11)
    tiled, record = make_tileable(maps, HOTSPOT)
    validate_maps(tiled)
    assert record.cells is not None and record.perspective is not None
    assert record.perspective.keystone == pytest.approx((0.02, 0.015), abs=0.003)
    document = round_trip(record)
    assert "perspective rectified" in str(document["method"])
    assert document["lattice"]["perspective"]["keystone"] == pytest.approx([0.02, 0.015], abs=0.003)  # type: ignore[index]
    # Square-on tiles are not rectified (the record above says so only when it was).
    assert make_tileable(tiles(), HOTSPOT)[1].perspective is None


def test_a_lattice_found_only_once_rectified_is_tiled_by_cells() -> None:
    g = (0.06 / (SIZE / 2), -0.045 / (SIZE / 2))  # the score falls short before rectification
    maps = lattice_maps(polar(24.0, 30.0), polar(30.0, 120.0), perspective=g, seed=1)
    assert not find_lattice(maps).periodic
    _, record = make_tileable(maps, HOTSPOT)
    assert record.cells is not None and record.perspective is not None
    assert record.lattice is not None and record.lattice.periodic and record.note is None


def test_a_lattice_seen_only_in_the_maps_centre_is_rectified_and_tiled_by_cells() -> None:
    g = (0.08 / (SIZE / 2), -0.06 / (SIZE / 2))  # no lattice over the whole maps, one in their centre
    maps = lattice_maps(polar(24.0, 30.0), polar(30.0, 120.0), perspective=g, seed=1)
    whole = find_lattice(maps)
    assert not (whole.periodic or whole.ambiguous)
    _, record = make_tileable(maps, HOTSPOT)
    assert record.cells is not None and record.perspective is not None
    assert record.perspective.keystone == pytest.approx((0.08, -0.06), abs=0.003)
    assert record.lattice is not None and record.lattice.periodic and record.note is None


def test_a_non_periodic_material_keeps_todays_cut_bit_for_bit() -> None:
    maps = noise_maps(1)
    tiled, record = make_tileable(maps, HOTSPOT)
    assert torch.equal(tiled, todays_tile(maps))
    assert record.lattice is None and record.cells is None and record.note is None
    assert record.shifts == make_seamless(repair_flash_mark(maps, HOTSPOT)[0]).shifts
    document = round_trip(record)
    assert document["lattice"] is None and document["note"] is None
    assert document["method"] == "flash mark repaired, then rolled and cut along minimum-error paths"


def test_an_ambiguous_texture_gets_a_note_saying_which_path_was_taken() -> None:
    # Coarse noise whose autocorrelation has a chance lattice scoring just under the threshold.
    maps = noise_maps(243, sigma=10.0)
    found = find_lattice(maps)
    assert found.ambiguous and not found.periodic, found
    tiled, record = make_tileable(maps, HOTSPOT)
    assert torch.equal(tiled, todays_tile(maps))
    assert (
        record.note is not None
        and "ambiguously periodic" in record.note
        and "minimum-error cut" in record.note
    )
    assert "\n" not in record.note
    round_trip(record)


def test_an_ambiguous_lattice_is_still_tiled_by_cells_with_a_note(monkeypatch: pytest.MonkeyPatch) -> None:
    maps = tiles()
    weak = replace(find_lattice(maps), score=0.12)
    monkeypatch.setattr(pipeline, "find_lattice", lambda _: weak)
    _, record = make_tileable(maps, HOTSPOT)
    assert record.cells is not None and record.lattice == weak
    assert record.note is not None and "tiled by whole lattice cells" in record.note


def test_a_lattice_whose_cells_do_not_fit_keeps_the_cut(monkeypatch: pytest.MonkeyPatch) -> None:
    maps = noise_maps(5)  # no stripes to fall back on either
    coarse = Lattice(
        ((180.0, 0.0), (0.0, 185.0)), 0.3, True, notes="2-D lattice"
    )  # one cell: 96 % of the side
    monkeypatch.setattr(pipeline, "find_lattice", lambda _: coarse)
    tiled, record = make_tileable(maps, HOTSPOT)
    assert torch.equal(tiled, todays_tile(maps))
    assert record.lattice == coarse and record.cells is None and record.stripes is None
    assert record.note is not None and "no whole number of its cells fits" in record.note
    assert round_trip(record)["lattice"] is not None


def test_a_diagonal_lattice_too_turned_for_whole_cells_names_the_flag_that_fits_them(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Two cells a side, 20° off the axes (a checkerboard of slabs at 45°, the phone turned 25°): no
    # whole cells within 15° of the frame, one once the pattern is turned onto its own axes.
    maps = noise_maps(5)
    turned = Lattice((polar(90.0, 20.0), polar(90.0, 110.0)), 0.3, True, notes="2-D lattice")
    monkeypatch.setattr(pipeline, "find_lattice", lambda _: turned)
    tiled, record = make_tileable(maps, HOTSPOT)
    assert torch.equal(tiled, todays_tile(maps)) and record.cells is None
    assert record.note is not None and "within 15° of their axes" in record.note
    assert "--align-pattern turns the pattern onto its own axes, where 1 whole cell(s) fit" in record.note
    _, with_flag = make_tileable(maps, HOTSPOT, align_pattern=True)
    assert with_flag.cells is not None and with_flag.cells.aligned and with_flag.note is None


def test_stripes_are_tiled_by_whole_periods_across_them_and_recorded() -> None:
    maps = planks(11.3, 30.0)
    assert not find_lattice(maps).periodic
    tiled, record = make_tileable(maps, HOTSPOT)
    validate_maps(tiled)
    assert record.stripes is not None and record.cells is not None and record.lattice is None
    assert record.stripes.period == pytest.approx(11.3, rel=0.01) and record.note is None
    document = round_trip(record)
    stripes = document["stripes"]
    assert isinstance(stripes, dict) and stripes["cells"]["cells"] == record.cells.cells
    assert stripes["period_px"] == pytest.approx(11.3, rel=0.01)
    assert "whole periods across its stripes" in str(document["method"])
    assert max(max(pair) for pair in record.after.wrap_ratio.values()) <= 1.2
    assert not torch.equal(tiled, todays_tile(maps))
    # --align-pattern turns the stripes onto an axis.
    _, aligned = make_tileable(maps, HOTSPOT, align_pattern=True)
    assert aligned.cells is not None and aligned.cells.aligned and aligned.note is None
    assert abs(aligned.cells.turn_deg) == pytest.approx(30.0, abs=1.0)


def test_the_flash_is_taken_out_along_stripes_or_from_a_lattice_found_before_the_tile() -> None:
    lattice, along = tile_pattern(planks(11.3, 30.0)).flash_twins()
    assert lattice is None and along is not None
    assert along[1] / along[0] == pytest.approx(math.tan(math.radians(30.0)), abs=0.02)
    lattice, along = tile_pattern(tiles()).flash_twins()
    assert lattice is not None and along is None
    assert tile_pattern(noise_maps(seed=3)).flash_twins() == (None, None)


def test_stripes_in_mild_perspective_are_rectified_before_they_are_tiled() -> None:
    maps = planks(11.3, 30.0, keystone=(0.02, 0.015))
    tiled, record = make_tileable(maps, HOTSPOT)
    validate_maps(tiled)
    assert record.stripes is not None and record.perspective is not None
    assert record.perspective.keystone == pytest.approx((0.02, 0.015), abs=0.005)
    document = round_trip(record)
    assert "perspective rectified" in str(document["method"]) and document["lattice"] is None
    assert document["stripes"]["perspective"]["keystone"] == pytest.approx([0.02, 0.015], abs=0.005)  # type: ignore[index]
    assert make_tileable(planks(11.3, 30.0), HOTSPOT)[1].perspective is None


def test_stripes_with_an_ambiguous_lattice_say_which_path_was_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    maps = planks(11.3, 30.0)
    weak = Lattice(((11.3, 0.0), (0.0, 40.0)), 0.08, False, notes="lattice peaks too weak")
    assert weak.ambiguous
    monkeypatch.setattr(pipeline, "find_lattice", lambda _: weak)
    monkeypatch.setattr(pipeline, "find_perspective", lambda *_: None)
    _, record = make_tileable(maps, HOTSPOT)
    assert record.stripes is not None and record.lattice == weak
    assert record.note is not None and record.note.startswith("the pattern is ambiguously periodic")
    assert "whole periods across its stripes" in record.note and "\n" not in record.note


def test_a_lattice_whose_cells_do_not_fit_falls_back_on_its_rows(monkeypatch: pytest.MonkeyPatch) -> None:
    # Tiles whose cells do not fit still have rows of grout: tiled by whole rows, with a note.
    maps = tiles()
    coarse = Lattice(((180.0, 0.0), (0.0, 185.0)), 0.3, True, notes="2-D lattice")
    monkeypatch.setattr(pipeline, "find_lattice", lambda _: coarse)
    _, record = make_tileable(maps, HOTSPOT)
    assert record.stripes is not None and record.cells is not None and record.lattice == coarse
    assert record.note is not None and "whole periods across its stripes" in record.note
    document = round_trip(record)
    assert document["lattice"]["cells"] is None and document["stripes"]["cells"] is not None  # type: ignore[index]


def test_bricks_two_to_the_maps_fill_the_tile_by_whole_cells_and_say_so() -> None:
    # Whole cells fill the maps (two bricks, six courses): no room for the seam's margin, which is
    # fetched a cell in; recorded, and said in the method.
    maps = brick_maps(96.0, 32.0, 0.0)
    tiled, record = make_tileable(maps, HOTSPOT)
    validate_maps(tiled)
    assert record.lattice is not None and record.cells is not None and record.stripes is None
    assert record.cells.margin_fetched and record.cells.cells == 12 and record.note is None
    document = round_trip(record)
    assert document["lattice"]["cells"]["margin_fetched"] is True  # type: ignore[index]
    assert "fetched a cell in" in str(document["method"])
    assert max(max(pair) for pair in record.after.wrap_ratio.values()) <= 1.2


def test_a_lattice_whose_cells_do_not_match_each_other_is_tiled_by_its_rows(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Cells that match each other keep the lattice, stripes or not (the bricks' bed joints).
    _, kept = make_tileable(brick_maps(40.0, 15.0, 0.0), HOTSPOT)
    assert kept.lattice is not None and kept.stripes is None and kept.cells is not None
    # Setts whose joints wander along the rows, read as a weak lattice (the autocorrelation of a
    # real set, PavingStones010, shows one): its cells differ, its rows repeat.
    maps = setts_maps()
    echo = Lattice(((32.0, 0.0), (16.0, 16.0)), 0.15, True, notes="2-D lattice")
    monkeypatch.setattr(pipeline, "find_lattice", lambda _: echo)
    _, record = make_tileable(maps, HOTSPOT)
    assert record.stripes is not None and record.cells is not None and record.lattice == echo
    assert record.stripes.period == pytest.approx(16.0, rel=0.01)
    assert record.note is not None and "its cells match each other at only" in record.note
    assert "\n" not in record.note and round_trip(record)["lattice"]["cells"] is None  # type: ignore[index]


def test_align_pattern_turns_a_lattice_onto_the_axes_and_says_when_there_is_none() -> None:
    _, record = make_tileable(tiles(), HOTSPOT, align_pattern=True)
    assert record.cells is not None and record.cells.aligned
    assert abs(record.cells.turn_deg) == pytest.approx(30.0, abs=1.0)
    maps = noise_maps(2)
    tiled, plain = make_tileable(maps, HOTSPOT, align_pattern=True)
    assert torch.equal(tiled, todays_tile(maps))
    assert plain.note is not None and plain.note.startswith("--align-pattern: no 2-D lattice")


def test_align_pattern_without_tileable_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import cv2
    import numpy as np

    photo = tmp_path / "p.png"
    cv2.imwrite(str(photo), np.full((64, 64, 3), 128, np.uint8))
    code = main(["predict", str(photo), "--out", str(tmp_path / "o"), "--align-pattern"])
    assert code == USER_ERROR_EXIT_CODE
    assert "--align-pattern applies to tileable maps: add --tileable" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_float32_maps_are_tiled_in_float32() -> None:
    # The pipeline's maps are float32; the whole-cell path resamples and cuts in their precision.
    maps = tiles().float()
    tiled, record = make_tileable(maps, HOTSPOT)
    assert tiled.dtype == torch.float32 and record.cells is not None
    validate_maps(tiled)
