"""Woven and printed fabrics: plain or twill weaves of dyed yarns, with stripes, checks or prints.

Depicts a woven cloth seen close up: vertical warp threads and horizontal weft threads crossing
over and under each other (plain weave 1/1, or a 2/2 twill with its diagonal ribs), each thread
a continuous tube with a rounded cross-section, rising where it floats over the crossing threads
and sinking where it passes under them, with the slanted ridges of the yarn's twist. Colour
comes from the yarns: one colour throughout, a two-tone cloth (dyed warp over an undyed weft,
like denim or chambray), stripes (warp yarns in a repeating colour sequence), checks or plaid
(warp and weft both in a sequence, so the crossings mix them), or a print (dots or five-petal
flowers on a half-drop grid, inked onto the thread crowns more than into the gaps). Threads
differ slightly in shade and sheen; fibres aligned along the crowns give a slight sheen (lower
roughness) there, while the gaps between threads are darker and rougher. Fabric scatters light
widely: roughness 0.6–1.

Why it is in the dataset: the original families contain only a plain-weave mode of the leather
family in one colour; clothes, upholstery, bags and tablecloths are among the most photographed
surfaces, come in every hue and in multi-coloured patterns, and have a fine periodic relief at
the thread scale with a very rough, slightly anisotropic sheen.

Parameters:
    threads: threads per image width, in both directions (rounded to a multiple of 4, so the
        twill repeat tiles).
    weave: < 0.5 plain weave, otherwise 2/2 twill.
    pattern: colour pattern, rounded down: 0 solid, 1 two-tone (dyed warp, undyed weft),
        2 stripes, 3 checks/plaid, 4 printed motifs (uniform: no preferred pattern).
    repeats: pattern repeats per image width (rounded; stripes and checks repeat a sequence of
        four bands, prints use twice as many motifs).
    hue: hue of the main yarn colour, in turns (uniform: any hue).
    accent_hue: hue offset of the accent colour (stripes, checks, prints), in turns (uniform).
    saturation: saturation of the dyed yarns.
    value: brightness of the main yarn colour (sRGB); the accent contrasts with it.
    roughness: perceptual roughness of the thread crowns before their sheen (0.7–1).
    relief: thread height as a fraction of the thread pitch.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch
from torch import Tensor

from brdfgan.core.filtering import smoothstep
from brdfgan.data.materials.albedo import clamp_dielectric_albedo
from brdfgan.data.materials.base import MaterialFamily, MaterialLayers, Parameter
from brdfgan.data.materials.noise import hsv_to_rgb

PATTERNS = ("solid", "two_tone", "stripes", "checks", "print")
# Colour index of each of the four bands of one pattern repeat (0 main, 1 accent, 2 third).
_STRIPE_SEQUENCE = (0, 1, 0, 1)
_PLAID_SEQUENCE = (0, 1, 0, 2)
# Undyed cotton, the weft of two-tone cloth (sRGB).
_UNDYED = hsv_to_rgb(torch.tensor([0.1]), torch.tensor([0.08]), torch.tensor([0.85]))[:, 0]


def _thread_axis(size: int, threads: int) -> tuple[Tensor, Tensor]:
    """Index (as float) of the thread under every texel centre along one axis, and the position
    across that thread in [0, 1). Shape: each ``(size,)``."""
    x = (torch.arange(size, dtype=torch.float32) + 0.5) * (threads / size)
    index = x.floor()
    return index, x - index


def _yarn_colours(
    pattern: str, palette: Tensor, threads: int, repeats: int, index: Tensor, warp: bool
) -> Tensor:
    """Colour of the yarn of every thread index. Shape: palette ``(3, 3)``, index ``(n,)`` → ``(3, n)``."""
    if pattern in ("stripes", "checks") and (warp or pattern == "checks"):
        sequence = torch.tensor(_STRIPE_SEQUENCE if pattern == "stripes" else _PLAID_SEQUENCE)
        band = (index * (4 * repeats) / threads).floor().long() % 4
        return palette[sequence[band]].T
    if pattern == "two_tone" and not warp:
        return _UNDYED.view(3, 1).expand(3, index.numel())
    return palette[0].view(3, 1).expand(3, index.numel())


def _print_mask(size: int, motifs: int, flower: bool) -> Tensor:
    """Coverage in [0, 1] of dots or five-petal flowers on a half-drop grid of ``motifs`` per
    width (even, so the half-drop tiles). Shape: ``(size, size)``."""
    c = (torch.arange(size, dtype=torch.float32) + 0.5) * (motifs / size)
    col = c.floor()
    x = (c - col - 0.5).view(1, size)
    y = c.view(size, 1) + 0.5 * (col % 2).view(1, size)  # odd columns dropped by half a motif
    y = y - y.floor() - 0.5
    r = torch.sqrt(x * x + y * y)
    outline = 0.25 if not flower else 0.17 + 0.09 * torch.cos(5.0 * torch.atan2(y, x))
    return smoothstep(0.0, 0.03, outline - r)


def _generate(params: Mapping[str, float], size: int, generator: torch.Generator) -> MaterialLayers:
    threads = 4 * max(2, round(params["threads"] / 4))
    repeats = min(max(1, round(params["repeats"])), threads // 4)
    pattern = PATTERNS[min(max(int(params["pattern"]), 0), len(PATTERNS) - 1)]
    float_length = 2 if params["weave"] >= 0.5 else 1

    # Warp threads are columns (index i), weft threads rows (index j): per-axis vectors,
    # broadcast to the texel grid only where the weave combines them.
    i, fu = _thread_axis(size, threads)
    j, fv = _thread_axis(size, threads)
    i, fu, j, fv = i.view(1, size), fu.view(1, size), j.view(size, 1), fv.view(size, 1)
    # Every thread is a continuous tube: a rounded cross-section with finite slopes (so the
    # normals do not sharpen with the resolution), at a level that rises over its floats and
    # sinks under the crossing threads, periodic over the weave repeat of 2L threads. Warp i
    # floats over the rows y in [-i, L - i) (mod 2L), weft j over the columns x in [L - j, 2L - j):
    # (i + j) shifts the floats by one each thread, the twill's diagonal. The visible surface is
    # the higher of the two threads at each texel.
    length = float(float_length)
    warp_level = smoothstep(-0.7, 0.7, torch.cos(math.pi * (j + fv + i - 0.5 * length) / length))
    weft_level = smoothstep(-0.7, 0.7, torch.cos(math.pi * (i + fu + j - 1.5 * length) / length))
    # sin^1.5: full round tops, and valleys between threads that flatten at the bottom instead
    # of a V as sharp as the texel grid.
    warp_across, weft_across = torch.sin(math.pi * fu) ** 1.5, torch.sin(math.pi * fv) ** 1.5
    warp_height = warp_across * (0.45 + 0.55 * warp_level)
    weft_height = weft_across * (0.45 + 0.55 * weft_level)
    warp_over = warp_height >= weft_height
    relief = torch.maximum(warp_height, weft_height)
    # The yarn's twist: slanted ridges along each thread, two per thread pitch.
    warp_twist = torch.sin(2.0 * math.pi * (2.0 * fv + fu))
    weft_twist = torch.sin(2.0 * math.pi * (2.0 * fu + fv))
    twist = torch.where(warp_over, warp_twist, weft_twist)
    height = params["relief"] * (size / threads) * (relief + 0.05 * twist * relief)

    # Palette: main yarn, an accent that contrasts in hue and brightness, and a darker third.
    hue, saturation, value = params["hue"], params["saturation"], params["value"]
    accent_hue, accent_value = params["accent_hue"], min(max(1.05 - value, 0.15), 0.92)
    palette = hsv_to_rgb(
        torch.tensor([[hue, hue + accent_hue, hue - accent_hue]]) % 1.0,
        torch.tensor([[saturation, saturation, 0.6 * saturation]]),
        torch.tensor([[value, accent_value, 0.5 * value]]),
    )[:, 0, :].T  # (colour, channel)
    index = torch.arange(threads, dtype=torch.float32)
    warp_yarn = _yarn_colours(pattern, palette, threads, repeats, index, warp=True)
    weft_yarn = _yarn_colours(pattern, palette, threads, repeats, index, warp=False)
    # Every thread its own slight shade and sheen (yarn lots, tension).
    jitter = torch.rand((4, threads), generator=generator)
    warp_yarn = warp_yarn * (0.95 + 0.1 * jitter[0])
    weft_yarn = weft_yarn * (0.95 + 0.1 * jitter[1])
    cols, rows = i.long().view(-1), j.long().view(-1)
    yarn = torch.where(
        warp_over[None], warp_yarn[:, cols].view(3, 1, size), weft_yarn[:, rows].view(3, size, 1)
    )
    if pattern == "print":
        flower = bool(torch.rand((), generator=generator) < 0.5)
        ink = _print_mask(size, 2 * repeats, flower) * (0.75 + 0.25 * relief)
        yarn = yarn + (palette[1].view(3, 1, 1) - yarn) * ink[None]
    # Gaps between threads show the shadowed threads below: darker.
    basecolor = clamp_dielectric_albedo(yarn * (0.7 + 0.3 * relief)[None])

    # Sheen along the crowns (aligned fibres), rough fuzzy gaps, per-thread sheen spread; on
    # average about the roughness parameter.
    sheen = torch.where(warp_over, jitter[2, cols].view(1, size), jitter[3, rows].view(size, 1))
    crown = relief * relief
    roughness = params["roughness"] + 0.03 + 0.08 * (1.0 - relief) - (0.05 + 0.05 * sheen) * crown
    return MaterialLayers.dielectric(basecolor, height, roughness.clamp(0.6, 1.0))


FAMILY = MaterialFamily(
    name="fabric",
    parameters={
        "threads": Parameter(96.0, 32.0, 256.0, "threads per image width (rounded to a multiple of 4)"),
        "weave": Parameter(0.3, 0.0, 1.0, "weave: < 0.5 plain, otherwise 2/2 twill"),
        "pattern": Parameter(
            2.0, 0.0, 4.99, "colours (floor): 0 solid, 1 two-tone, 2 stripes, 3 checks, 4 print", uniform=True
        ),
        "repeats": Parameter(3.0, 1.0, 8.0, "pattern repeats per image width (rounded)"),
        "hue": Parameter(0.5, 0.0, 1.0, "hue of the main yarn colour, in turns", uniform=True),
        "accent_hue": Parameter(0.5, 0.0, 1.0, "hue offset of the accent colour, in turns", uniform=True),
        "saturation": Parameter(0.6, 0.0, 0.95, "saturation of the dyed yarns"),
        "value": Parameter(0.5, 0.1, 0.9, "brightness of the main yarn colour (sRGB)"),
        "roughness": Parameter(0.85, 0.7, 1.0, "perceptual roughness of the thread crowns before sheen"),
        "relief": Parameter(0.3, 0.15, 0.5, "thread height, fraction of the thread pitch"),
    },
    generate=_generate,
    description="Plain or twill weave of dyed yarns: solid, two-tone, striped, checked or printed.",
    tags=("fabric", "textile", "woven", "saturated", "dielectric", "tileable"),
)

__all__ = ["FAMILY", "PATTERNS"]
