"""`make demo-renderer`: one map set photographed with a flash by both renderers, everything saved.

The foundation end to end: a tile-and-grout map set → map files on disk → the flash photo from
the torch renderer and from Mitsuba → auto exposure to linear LDR → PNGs, with their agreement
printed. (`make demo` is `brdfgan predict` on the sample photos.)
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import torch

from brdfgan.core.exposure import auto_expose
from brdfgan.core.render import FlashCapture, render_flash
from brdfgan.core.svbrdf import join_maps, linear_to_srgb, normalize_normal
from brdfgan.io.images import write_image
from brdfgan.io.maps import write_maps
from brdfgan.mitsuba_render.scene import render_flash_mitsuba
from brdfgan.mitsuba_render.variant import select_variant


def tile_maps(size: int, tiles: int = 4, seed: int = 0) -> torch.Tensor:
    """Glazed tiles in rough grout, with slightly tilted tiles: a small showcase map set (8, H, W)."""
    g = torch.Generator().manual_seed(seed)
    coords = (torch.arange(size) + 0.5) / size * tiles
    u, v = coords.view(1, -1).expand(size, size), coords.view(-1, 1).expand(size, size)
    grout = ((u % 1 < 0.06) | (v % 1 < 0.06)).float()[None]
    tile_id = (u.floor() * tiles + v.floor()).long()
    tint = 0.15 * torch.rand((tiles * tiles, 3), generator=g)[tile_id].permute(2, 0, 1)
    basecolor = grout * torch.tensor([0.55, 0.52, 0.48]).view(3, 1, 1) + (1 - grout) * (
        torch.tensor([0.2, 0.35, 0.6]).view(3, 1, 1) + tint
    )
    slope = 0.08 * (torch.rand((tiles * tiles, 2), generator=g) - 0.5)[tile_id].permute(2, 0, 1) * (1 - grout)
    normal = normalize_normal(torch.cat([slope, torch.ones_like(grout)]))
    roughness = 0.85 * grout + 0.18 * (1 - grout)
    return join_maps(basecolor.clamp(0, 1), normal, roughness, torch.zeros_like(grout))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"))
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--spp", type=int, default=64)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")

    variant = select_variant()
    maps = tile_maps(args.size)
    paths = write_maps(args.out / "maps", maps)
    capture = FlashCapture(intensity=8.0)
    ours = render_flash(maps[None], capture, supersample=4)  # box-filtered pixels, like Mitsuba's
    reference = render_flash_mitsuba(maps, capture, spp=args.spp)[None]
    error = ((ours - reference).abs().sum() / reference.abs().sum()).item()
    for name, hdr in (("flash_torch", ours), ("flash_mitsuba", reference)):
        ldr, _ = auto_expose(hdr)
        # Linear LDR is what the network sees; the preview PNG is sRGB-encoded for people.
        write_image(args.out / f"{name}.png", linear_to_srgb(ldr[0]).permute(1, 2, 0).numpy())
    print(f"maps written: {', '.join(str(p) for p in paths.values())}")
    print(
        f"flash photo (torch renderer vs Mitsuba {variant}, {args.spp} spp): relative L1 {100 * error:.2f} %"
    )
    print(f"previews: {args.out / 'flash_torch.png'}, {args.out / 'flash_mitsuba.png'}")
    print("next: `brdfgan predict photo.jpg` turns such a photo into textures once the model issues land.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
