"""Golden outputs of the noise primitives: a fixed seed must keep painting the same field.

The values were recorded from the implementation before the separable-lattice speed-up (full
``(size, size)`` index grids and advanced indexing); that rewrite was checked ``torch.equal``
against it for sizes 32/64/100/1024, cells 1/3/4/7/64 and three seeds. Datasets are regenerated
from seeds, so any change here silently changes every generated material.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
import torch
from torch import Tensor

from brdfgan.data.materials import noise

# Per field: (float64 sum, float64 sum of squares, values at flat indices 0, 777 mod numel, -1).
Golden = tuple[float, float, tuple[float, float, float]]


def _fields(kind: str, size: int, cells: int, seed: int) -> tuple[Tensor, ...]:
    generator = torch.Generator().manual_seed(seed)
    makers: dict[str, Callable[[], tuple[Tensor, ...]]] = {
        "value": lambda: (noise.value_noise(size, cells, generator),),
        "gradient": lambda: (noise.gradient_noise(size, cells, generator),),
        "fbm": lambda: (noise.fbm(size, cells, generator),),
        "worley": lambda: noise.worley(size, cells, generator)[:2],
        "worley_0.7": lambda: noise.worley(size, cells, generator, jitter=0.7)[:2],
    }
    return makers[kind]()


GOLDEN: list[tuple[str, int, int, int, tuple[Golden, ...]]] = [
    (
        "value",
        100,
        7,
        1,
        (
            (
                5176.233499574475,
                3099.5928286989797,
                (0.7574358582496643, 0.5951701402664185, 0.7575327157974243),
            ),
        ),
    ),
    (
        "value",
        64,
        1,
        0,
        (
            (
                2032.6669921875,
                1008.7243899239693,
                (0.49625658988952637, 0.49625658988952637, 0.49625658988952637),
            ),
        ),
    ),
    (
        "value",
        1024,
        64,
        12345,
        (
            (
                518355.46508473787,
                309402.09479288204,
                (0.9815054535865784, 0.25059202313423157, 0.981421709060669),
            ),
        ),
    ),
    (
        "gradient",
        100,
        7,
        1,
        (
            (
                -0.0016455753921036376,
                719.5890680254367,
                (-0.04635319858789444, 0.08611232042312622, 0.04616839066147804),
            ),
        ),
    ),
    (
        "gradient",
        64,
        3,
        12345,
        (
            (
                6.9327128585428e-05,
                261.66131667375845,
                (0.028947751969099045, -0.5987829566001892, -0.02881959266960621),
            ),
        ),
    ),
    (
        "gradient",
        1024,
        64,
        0,
        (
            (
                -1.7009762899533598e-05,
                96090.46221074706,
                (-0.0427798368036747, 0.35216423869132996, 0.04329139366745949),
            ),
        ),
    ),
    (
        "gradient",
        32,
        4,
        0,
        (
            (
                1.1089650797657669e-06,
                79.62728582919439,
                (-0.0892377719283104, 0.21807004511356354, 0.08794915676116943),
            ),
        ),
    ),
    (
        "fbm",
        100,
        3,
        0,
        (
            (
                0.01728897934071938,
                383.3664213965287,
                (-0.012040379457175732, 0.43855077028274536, 0.00611245259642601),
            ),
        ),
    ),
    (
        "worley_0.7",
        100,
        7,
        1,
        (
            (
                4048.357991047902,
                1914.9480378421877,
                (0.5232289433479309, 0.17225030064582825, 0.522081732749939),
            ),
            (
                7046.765950039029,
                5181.075144801402,
                (0.6291629672050476, 0.8789668679237366, 0.5304065346717834),
            ),
        ),
    ),
    (
        "worley",
        64,
        4,
        0,
        (
            (
                1685.7675045998767,
                818.3104913011946,
                (0.6160185933113098, 0.09836004674434662, 0.6132032871246338),
            ),
            (
                2838.8320133686066,
                2056.17229601775,
                (0.7329012751579285, 0.8162359595298767, 0.6646667122840881),
            ),
        ),
    ),
    (
        "worley",
        32,
        64,
        12345,
        (
            (
                473.042616489809,
                264.1756536390613,
                (0.12177359312772751, 0.6681997776031494, 0.6135937571525574),
            ),
            (
                715.9662441313267,
                535.134163618578,
                (0.26422014832496643, 0.8337101936340332, 0.7438308000564575),
            ),
        ),
    ),
    (
        "worley",
        1024,
        3,
        1,
        (
            (
                432105.4371042139,
                211295.7479047113,
                (0.6614447236061096, 0.5833411812782288, 0.6573147773742676),
            ),
            (
                740360.990173161,
                549219.9718684654,
                (0.8055970668792725, 0.8361877799034119, 0.8093591928482056),
            ),
        ),
    ),
]


def _assert_golden(field: Tensor, golden: Golden) -> None:
    total, squares, samples = golden
    flat = field.flatten()
    # Tight tolerances: one lattice value read from the wrong cell moves these far more (> 1e-4),
    # while last-bit float32 differences on another CPU do not fail the test (an AMD EPYC machine
    # put Worley sums 1.5e-9 relative off the goldens made on another; 1e-7 leaves room for that).
    assert field.double().sum().item() == pytest.approx(total, rel=1e-7, abs=1e-6)
    assert field.double().square().sum().item() == pytest.approx(squares, rel=1e-7)
    picked = [flat[0].item(), flat[777 % flat.numel()].item(), flat[-1].item()]
    assert picked == pytest.approx(list(samples), rel=1e-6, abs=1e-9)


@pytest.mark.parametrize(("kind", "size", "cells", "seed", "golden"), GOLDEN)
def test_noise_matches_golden(
    kind: str, size: int, cells: int, seed: int, golden: tuple[Golden, ...]
) -> None:
    fields = _fields(kind, size, cells, seed)
    assert all(f.shape == (size, size) and f.dtype == torch.float32 for f in fields)
    for field, expected in zip(fields, golden, strict=True):
        _assert_golden(field, expected)


@pytest.mark.parametrize(
    ("size", "cells", "seed", "id_sum", "id_samples"),
    [
        (100, 7, 1, 241584, (6, 5, 6)),
        (64, 4, 0, 30595, (12, 0, 12)),
        (32, 64, 12345, 2095226, (0, 3090, 4031)),
        (1024, 3, 1, 4249096, (8, 8, 8)),
    ],
)
def test_worley_cell_ids_match_golden(
    size: int, cells: int, seed: int, id_sum: int, id_samples: tuple[int, int, int]
) -> None:
    jitter = 0.7 if (size, cells) == (100, 7) else 1.0
    cell_id = noise.worley(size, cells, torch.Generator().manual_seed(seed), jitter=jitter)[2]
    assert cell_id.dtype == torch.long and int(cell_id.min()) >= 0 and int(cell_id.max()) < cells * cells
    flat = cell_id.flatten()
    assert int(cell_id.sum()) == id_sum
    assert (int(flat[0]), int(flat[777 % flat.numel()]), int(flat[-1])) == id_samples


def test_random_per_cell_matches_golden_and_lookup() -> None:
    generator = torch.Generator().manual_seed(1)
    cell_id = noise.worley(100, 7, generator)[2]
    values = noise.random_per_cell(cell_id, 49, generator, channels=3)
    assert values.shape == (3, 100, 100)
    _assert_golden(
        values,
        (
            15638.218886315823,
            10875.52693318622,
            (0.8622175455093384, 0.1682094931602478, 0.13814055919647217),
        ),
    )
    # Cross-check against the definition: texel (y, x) holds row cell_id[y, x] of the table.
    table = torch.rand((49, 3), generator=torch.Generator().manual_seed(99))
    generator = torch.Generator().manual_seed(99)
    looked_up = noise.random_per_cell(cell_id, 49, generator, channels=3)
    for y, x in ((0, 0), (13, 57), (99, 99)):
        assert torch.equal(looked_up[:, y, x], table[cell_id[y, x]])


def test_wrapped_upsample_samples_texel_centres_and_wraps() -> None:
    # A ramp along the columns: away from the wrap, output texel k of an ×f upsampling holds the
    # input sampled at coordinate (k + ½)/f − ½, i.e. the ramp value there.
    n, factor = 8, 4
    ramp = torch.arange(n, dtype=torch.float32).expand(n, n).contiguous()
    up = noise.wrapped_upsample(ramp, factor)
    assert up.shape == (n * factor, n * factor)
    k = torch.arange(factor, n * factor - factor, dtype=torch.float32)
    assert torch.allclose(up[3, factor:-factor], (k + 0.5) / factor - 0.5, atol=1e-6)
    # Periodic: shifting the input by one texel shifts the output by one input texel (f texels).
    field = noise.value_noise(n, 3, torch.Generator().manual_seed(4))
    shifted = noise.wrapped_upsample(torch.roll(field, 1, dims=1), factor)
    assert torch.allclose(
        shifted, torch.roll(noise.wrapped_upsample(field, factor), factor, dims=1), atol=1e-6
    )
    assert noise.wrapped_upsample(field, 1) is field
