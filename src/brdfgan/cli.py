"""The ``brdfgan`` console script. ``brdfgan predict --help`` shows examples."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from brdfgan.errors import DISK_FULL_EXIT_CODE, INTERRUPTED_EXIT_CODE, USER_ERROR_EXIT_CODE, one_line

# Exit status when the command ran but at least one photo of the batch failed.
PARTIAL_FAILURE_EXIT_CODE = 1

PREDICT_EXAMPLES = """\
examples:
  brdfgan predict photo.jpg --out materials/
      sRGB JPEG → materials/photo/{basecolor,normal,roughness,metallic,metallicRoughness,
      diffuse,specular}.png, material.glb, material.json, preview.png
  brdfgan predict shots/ --out materials/ --resolution 2048 --animate
      every photo in shots/ at 2048² (tiled), plus a turntable-light preview.gif
  brdfgan predict IMG_0042.dng --out out/ --format exr --normal-convention directx
      camera RAW (linear demosaic), linear EXR textures, DirectX normal map (Unreal)
  brdfgan predict scan.png --out out/ --input-colorspace linear --crop 120,80,1024 --bit-depth 16
      a linear PNG, a given 1024² square at x=120, y=80, 16-bit PNG textures
"""


def _crop(text: str):  # -> Crop (imported lazily: --help stays fast)
    from brdfgan.inference.preprocess import Crop

    try:
        return Crop.parse(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(one_line(error)) from None


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def tiling_for(tile: int | None):  # -> TilingConfig
    """The default tiling, or with another tile side (overlap and margin shrink for small tiles)."""
    from brdfgan.inference.tiling import TilingConfig

    default = TilingConfig()
    if tile is None:
        return default
    overlap = min(default.overlap, tile // 2)
    margin = min(default.margin, (3 * overlap) // 8)
    return TilingConfig(tile=tile, overlap=overlap, margin=margin, max_direct_pixels=tile * tile)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="brdfgan", description="SVBRDF estimation from a single flash photo (Boss & Lensch 2019)."
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    predict = commands.add_parser(
        "predict",
        help="flash photo(s) → engine-ready PBR textures, material.glb and relit previews",
        description=(
            "Estimate base color, normal, roughness and metallic maps from flash photos (phone held "
            "parallel to the surface, flash on). Each photo is cropped square around the flash "
            "highlight, auto-exposed like the training data, and written to OUT/<name>/."
        ),
        epilog=PREDICT_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    predict.add_argument(
        "inputs",
        nargs="+",
        metavar="PHOTO|DIR",
        help="JPEG, PNG, EXR or camera RAW/DNG files, or folders of them",
    )
    predict.add_argument(
        "--out", required=True, type=Path, metavar="DIR", help="output folder (one subfolder per photo)"
    )
    predict.add_argument(
        "--weights",
        type=Path,
        metavar="PATH",
        help="a .safetensors weights file (default: the weights shipped with brdfgan)",
    )
    predict.add_argument(
        "--resolution",
        type=_positive,
        metavar="N",
        help="output size N×N (default: the model's training resolution); large sizes run tiled",
    )
    predict.add_argument(
        "--crop",
        type=_crop,
        metavar="X,Y,SIZE",
        help="use this square (top-left x, y and side, in pixels of the upright photo) "
        "instead of finding the flash hotspot",
    )
    predict.add_argument(
        "--input-colorspace",
        choices=("srgb", "linear"),
        help="how JPEG/PNG values are encoded (default srgb; EXR and RAW are always linear)",
    )
    predict.add_argument(
        "--format",
        choices=("png", "exr"),
        default="png",
        help="texture file format (default png; EXR stores colours linear)",
    )
    predict.add_argument(
        "--bit-depth", type=int, choices=(8, 16), default=8, help="PNG bit depth (default 8)"
    )
    predict.add_argument(
        "--normal-convention",
        choices=("opengl", "directx"),
        default="opengl",
        help="normal map green channel: opengl (+Y up: Blender, Unity, glTF; default) or directx (Unreal)",
    )
    predict.add_argument(
        "--animate",
        nargs="?",
        const="gif",
        choices=("gif", "mp4"),
        help="also write a turntable-light preview animation (default gif)",
    )
    predict.add_argument("--no-preview", action="store_true", help="do not render preview.png")
    predict.add_argument(
        "--tile",
        type=_positive,
        metavar="N",
        help="photos above N² run as N² tiles (default 1024: memory of one 1024² pass, any resolution)",
    )
    predict.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def predict_command(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from brdfgan.errors import interrupts_raise
    from brdfgan.inference.export import ExportOptions
    from brdfgan.inference.predict import (
        PredictOptions,
        check_memory,
        collect_photos,
        load_model,
        predict_batch,
    )

    try:
        model = load_model(args.weights)
        tiling = tiling_for(args.tile)
        options = PredictOptions(
            resolution=args.resolution,
            crop=args.crop,
            colorspace=args.input_colorspace,
            export=ExportOptions(args.format, args.bit_depth, args.normal_convention),
            tiling=tiling,
            preview=not args.no_preview,
            animate=args.animate,
        )
        check_memory(model, options)  # before any photo is read or anything large allocated
    except ValueError as error:
        print(f"error: {one_line(error)}", file=sys.stderr)
        return USER_ERROR_EXIT_CODE
    photos = collect_photos(args.inputs)
    if not photos:
        print("error: no photos to process", file=sys.stderr)
        return USER_ERROR_EXIT_CODE
    resolution = options.resolution or model.resolution
    print(f"model {model.model_id} ({model.path}); {len(photos)} photo(s) at {resolution}²", file=sys.stderr)
    bar = tqdm(total=len(photos), unit="photo", disable=args.quiet or None, file=sys.stderr)

    def report(result) -> None:
        if isinstance(result, tuple):
            bar.write(f"error: {result[1]}", file=sys.stderr)
        else:
            for warning in result.warnings:
                bar.write(f"warning: {result.photo}: {warning}", file=sys.stderr)
        bar.update(1)

    try:
        # SIGTERM too: the photo in progress then leaves no hidden staging folder behind.
        with interrupts_raise():
            outcome = predict_batch(photos, args.out, model, options, on_result=report)
    except KeyboardInterrupt:
        bar.close()
        print(
            "interrupted: finished photos are complete; the one in progress was not written", file=sys.stderr
        )
        return INTERRUPTED_EXIT_CODE
    bar.close()
    for result in outcome.succeeded:
        print(result.output)
    if outcome.stopped is not None:  # a full disk; its error line was printed as it happened
        print(
            f"stopped: {len(outcome.succeeded)} of {len(photos)} photo(s) written; free some space and "
            "run again",
            file=sys.stderr,
        )
        return DISK_FULL_EXIT_CODE
    if outcome.failed:
        print(f"{len(outcome.failed)} of {len(photos)} photo(s) failed:", file=sys.stderr)
        for _, message in outcome.failed:
            print(f"  {message}", file=sys.stderr)
        return PARTIAL_FAILURE_EXIT_CODE
    print(f"done: {len(outcome.succeeded)} material(s) in {args.out}", file=sys.stderr)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s: %(message)s")
    args = build_parser().parse_args(argv)
    if args.command == "predict":
        return predict_command(args)
    raise AssertionError(f"unhandled command {args.command}")  # argparse rejects unknown commands


if __name__ == "__main__":
    sys.exit(main())
