from __future__ import annotations

import re
from pathlib import Path

import pytest

from brdfgan.io.maps import read_maps
from brdfgan.renderer_demo import main

pytestmark = [pytest.mark.mitsuba, pytest.mark.integration]


def test_demo_writes_maps_and_agreeing_renders(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--out", str(tmp_path), "--size", "48", "--spp", "64"]) == 0
    assert read_maps(tmp_path / "maps").shape == (8, 48, 48)
    assert (tmp_path / "flash_torch.png").is_file() and (tmp_path / "flash_mitsuba.png").is_file()
    error = float(re.search(r"relative L1 ([0-9.]+) %", capsys.readouterr().out).group(1))
    assert error < 2.0
