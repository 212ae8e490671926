"""evaluate's rows on flash + no-flash pairs (evaluation.evaluator.PairRows, issue 59)."""

from __future__ import annotations

import math
from functools import partial

import pytest
import torch
from torch import Tensor, nn

from brdfgan.errors import UserError
from brdfgan.evaluation.evaluator import PairRows, evaluate_models
from brdfgan.metrics import SVBRDFMetrics
from tests.inference.pair.test_relief_fit import FAST, SIZE, pair_of


class FixedMaps(nn.Module):
    """Predicts the same maps whatever the photo; records the photos it was shown."""

    def __init__(self, maps: Tensor) -> None:
        super().__init__()
        self.maps = maps
        self.seen: list[Tensor] = []

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        self.seen.append(photo.clone())
        return self.maps.expand(photo.shape[0], -1, -1, -1).clone()


class ReadsBrightness(FixedMaps):
    """FixedMaps whose roughness follows the photo's mean: its readings of the flash photo and of
    the flash-only image differ."""

    def forward(self, photo: Tensor, flash: Tensor | None = None) -> Tensor:
        maps = super().forward(photo, flash)
        maps[:, 6] = 0.7 + 0.2 * photo.mean(dim=(1, 2, 3)).view(-1, 1, 1)
        return maps


def pair_batch() -> tuple[dict[str, object], Tensor]:
    """A batch of one rendered pair (flash + room light, and the room light alone, at one exposure
    and white balance: ratio 1, unit gains) of a wavy diffuse surface, and the flat-normal maps a
    network reads from it; the truth has the surface's normals."""
    y, x = torch.meshgrid(torch.linspace(0, 1, SIZE), torch.linspace(0, 1, SIZE), indexing="ij")
    height = (2.0 * torch.sin(2 * math.pi * 2 * x) * torch.sin(2 * math.pi * 1.5 * y))[None, None]
    flash_only, room, maps, frame, normal = pair_of(height)
    scale = 0.9 / float((flash_only + room).max())
    truth = maps.clone()
    truth[3:6] = normal
    batch = {
        "photo": ((flash_only + room) * scale)[None],
        "photo_noflash": (room * scale)[None],
        "exposure_ratio": torch.ones(1),
        "white_balance": torch.ones(1, 2, 3),
        "maps": truth[None],
        "flash": frame,
    }
    return batch, maps


def test_the_pair_rows_score_the_flash_only_photo_and_the_fit() -> None:
    batch, maps = pair_batch()
    model = ReadsBrightness(maps[None])
    rows = PairRows(flash_only=("net",), fit=("net",), fit_config=FAST)
    metrics = partial(SVBRDFMetrics, downscale_to=None)
    results = evaluate_models({"net": model}, [batch], metrics, pair_rows=rows)
    assert list(results) == ["net", "net@flash-only", "net+pair-fit"]
    # The flash-only row's network saw the flash photo less the room light, auto-exposed.
    flash_photo, flash_only = model.seen[0], model.seen[1]
    room = batch["photo_noflash"]
    assert isinstance(room, Tensor)
    assert not torch.allclose(flash_photo, flash_only)
    expected = (flash_photo - room).clamp_min(0.0)
    assert torch.allclose(flash_only / flash_only.max(), expected / expected.max(), atol=1e-5)
    # The network's flat normals score as flat; the fit reads the relief the pair shows.
    angle = {name: values["normal_angle_deg"] for name, values in results.items()}
    assert angle["net@flash-only"] == pytest.approx(angle["net"])
    assert angle["net+pair-fit"] < 0.6 * angle["net"]
    assert results["net+pair-fit"]["normal_slope_cosine"] > 0.8
    # The fit's relief goes into the network's reading of the flash photo, as predict writes it.
    roughness = {name: values["rmse/roughness"] for name, values in results.items()}
    assert roughness["net+pair-fit"] == roughness["net"] != roughness["net@flash-only"]


def test_pair_rows_need_pairs_and_evaluated_models() -> None:
    batch, maps = pair_batch()
    single = {key: value for key, value in batch.items() if key != "photo_noflash"}
    metrics = partial(SVBRDFMetrics, downscale_to=None)
    flash_only = PairRows(flash_only=("net",))
    with pytest.raises(UserError, match=r"no no-flash twins.*dataset_spec\.pairs=true"):
        evaluate_models({"net": FixedMaps(maps[None])}, [single], metrics, pair_rows=flash_only)
    with pytest.raises(UserError, match=r"pair_rows.fit: 'other' is not an evaluated model \(one of net\)"):
        evaluate_models({"net": FixedMaps(maps[None])}, [batch], metrics, pair_rows=PairRows(fit=("other",)))
    # Without pair rows, a batch of pairs scores the flash photo alone, as before.
    assert list(evaluate_models({"net": FixedMaps(maps[None])}, [batch], metrics)) == ["net"]
