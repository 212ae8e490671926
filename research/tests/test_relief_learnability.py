"""The learnability harness's pair inputs (research.relief_learnability, issue 59)."""

from __future__ import annotations

import torch

from brdfgan.core.flash_geometry import centred_flash_frame
from brdfgan.models.anchored import AnchoredUNet
from research.relief_learnability import PairInputUNet, network_inputs, warm_started


def pair_batch() -> dict[str, torch.Tensor]:
    generator = torch.Generator().manual_seed(0)
    room = 0.1 + 0.2 * torch.rand(2, 3, 32, 32, generator=generator)
    flash_only = 0.1 + 0.5 * torch.rand(2, 3, 32, 32, generator=generator)
    gains = torch.tensor([[[1.1, 1.0, 0.9], [0.95, 1.0, 1.05]]]).expand(2, 2, 3)
    ratio = torch.tensor([2.0, 0.5])
    return {
        # The flash shot is balanced by its gains, the twin by its own and exposed 1/ratio as bright.
        "photo": (flash_only + room) * gains[:, 0, :, None, None],
        "photo_noflash": room / ratio[:, None, None, None] * gains[:, 1, :, None, None],
        "exposure_ratio": ratio,
        "white_balance": gains,
        "flash": centred_flash_frame(2, 32, 32, fov_deg=50.0),
        "truth_flash_only": flash_only,
        "truth_room": room,
    }


def test_the_inputs_undo_the_pair() -> None:
    batch = pair_batch()
    photo, extra = network_inputs(batch, "flash")
    assert photo is batch["photo"] and extra is None
    flash_only, extra = network_inputs(batch, "flash_only")
    truth = batch["truth_flash_only"]
    assert extra is None and flash_only.max() <= 1.0
    # Auto-exposed: the flash-only image up to one scale per photo.
    scale = (flash_only / truth).flatten(1)
    assert torch.allclose(scale, scale[:, :1].expand_as(scale), rtol=1e-4)
    photo, extra = network_inputs(batch, "ratio")
    assert extra is not None
    expected = (batch["truth_room"] / (batch["truth_flash_only"] + batch["truth_room"])).log()
    assert torch.allclose(extra, expected, atol=1e-5)
    photo, extra = network_inputs(batch, "pair")
    assert extra is not None and torch.allclose(extra.exp(), batch["photo_noflash"], rtol=1e-5)


def test_the_widened_network_is_v4_when_its_extra_weights_are_zero() -> None:
    torch.manual_seed(0)
    base = AnchoredUNet(width=4, depth=2).eval()
    with torch.no_grad():  # the heads start at zero: random weights make every input count
        for parameter in base.parameters():
            parameter.normal_(0.0, 0.1)
    widened = warm_started(PairInputUNet(3, width=4, depth=2), base.state_dict()).eval()
    batch = pair_batch()
    photo, channels = network_inputs(batch, "ratio")
    assert channels is not None
    with torch.no_grad():
        assert torch.allclose(
            widened.predict(photo, batch["flash"], channels), base(photo, batch["flash"]), atol=1e-6
        )
        widened.state_dict()["encoder.0.0.weight"][:, -3:] = 0.1  # the extra channels' weights
        assert not torch.allclose(
            widened.predict(photo, batch["flash"], channels), base(photo, batch["flash"])
        )
