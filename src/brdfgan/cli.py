"""The ``brdfgan`` console: one subcommand per task; ``brdfgan COMMAND --help`` for each.

This module only parses arguments and prints; the work is done by the library function each
command names. Errors a user can fix (:class:`brdfgan.errors.UserError`), Hydra/OmegaConf
configuration errors, a full disk and an interrupt end a command with one line
(:func:`brdfgan.errors.run_reporting_errors`); anything else is a bug and keeps its traceback.
Training, evaluation and dataset generation are the Hydra scripts ``train.py``, ``evaluate.py``
and ``generate.py``.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from brdfgan import __version__
from brdfgan.errors import (
    DISK_FULL_EXIT_CODE,
    USER_ERROR_EXIT_CODE,
    UserError,
    one_line,
    run_reporting_errors,
)
from brdfgan.inference import DEFAULT_REFINE_STEPS

if TYPE_CHECKING:  # imported lazily below: --help must not wait for torch
    import torch

    from brdfgan.capture import CaptureKind
    from brdfgan.inference.dispatch import Capture
    from brdfgan.inference.intake.preprocess import Crop
    from brdfgan.inference.pipeline import BatchResult, PhotoFailure, PhotoResult, PredictOptions, Predictor

    # What ``add_subparsers`` returns: each ``_add_<command>`` adds its subcommand to it.
    Commands = argparse._SubParsersAction[argparse.ArgumentParser]

# Exit status when the command ran but at least one photo of the batch failed.
PARTIAL_FAILURE_EXIT_CODE = 1
PREDICT_INTERRUPTED = "interrupted: finished photos are complete; the one in progress was not written"

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
  brdfgan predict --views top.jpg left.jpg right.jpg --out materials/
      three photos of one surface → one material fitted to all of them, materials/top/
  brdfgan predict wood.jpg --no-flash wood_off.jpg --out materials/
      a flash photo and a no-flash photo from the same spot → the relief fitted to both lights
  brdfgan predict shots/ --no-flash --out materials/
      every <name>.jpg in shots/ with its <name>_noflash.jpg (any format)
"""


def _crop(text: str) -> Crop:
    from brdfgan.inference.intake.preprocess import Crop

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


def _number(text: str, *, minimum: float, inclusive: bool) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    bound = "a number >= " if inclusive else "a number > "
    if not math.isfinite(value) or value < minimum or (value == minimum and not inclusive):
        raise argparse.ArgumentTypeError(f"expected {bound}{minimum:g}, got {text!r}")
    return value


def _non_negative(text: str) -> float:
    return _number(text, minimum=0.0, inclusive=True)


def _positive_float(text: str) -> float:
    return _number(text, minimum=0.0, inclusive=False)


def _field_of_view(text: str) -> float:
    value = _number(text, minimum=0.0, inclusive=False)
    if value >= 180.0:
        raise argparse.ArgumentTypeError(f"expected a field of view in degrees below 180, got {text!r}")
    return value


def _predict_device(choice: str) -> torch.device:
    """``--device``: ``auto`` takes CUDA when there is a device; ``cuda`` without one is an error."""
    import torch

    available = torch.cuda.is_available()
    if choice == "cuda" and not available:
        raise UserError("--device cuda: no CUDA device is available here (use --device cpu or auto)")
    return torch.device("cuda" if choice == "cuda" or (choice == "auto" and available) else "cpu")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="brdfgan", description="SVBRDF estimation from a single flash photo (Boss & Lensch 2019)."
    )
    parser.add_argument("--version", action="version", version=f"brdfgan {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    # In this order in ``brdfgan --help``.
    for add_command in (
        _add_predict,
        _add_export_weights,
        _add_contact_sheet,
        _add_convert_deschaintre,
        _add_report,
        _add_references,
        _add_dataset_stats,
        _add_eval_captures,
    ):
        add_command(commands)
    return parser


def _add_predict(commands: Commands) -> None:
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
    # --help reads in these sections, in this order.
    _add_predict_input(predict)
    _add_predict_output(predict)
    _add_predict_model(predict)
    _add_predict_speed(predict)
    _add_predict_console(predict)
    predict.set_defaults(run=predict_command, interrupted=PREDICT_INTERRUPTED)


def _add_predict_input(predict: argparse.ArgumentParser) -> None:
    group = predict.add_argument_group("input")
    group.add_argument(
        "inputs",
        nargs="+",
        metavar="PHOTO|DIR",
        help="JPEG, PNG, HEIC/HEIF, TIFF (8/16-bit), EXR or camera RAW/DNG files, or folders of them",
    )
    group.add_argument(
        "--views",
        action="store_true",
        help="the photos are views of one flat surface (2-12, flash on; the first is the reference): "
        "one material fitted to all of them, in OUT/<first photo's name>/; a photo that does not "
        "register is left out with a warning (docs/views.md)",
    )
    group.add_argument(
        "--no-flash",
        nargs="?",
        const=True,
        type=Path,
        metavar="NOFLASH",
        help="NOFLASH is a photo of the same surface with the flash off, taken from the same spot as "
        "the one flash photo given: the room light is taken out and the relief fitted to both lights "
        "(docs/predict.md); given bare (after the inputs), each photo is paired with its "
        "<name>_noflash photo (any format; a folder, or beside the photo). Where a pair cannot serve, "
        "a warning says why and the flash photo gets its single-photo prediction",
    )
    group.add_argument(
        "--exposure-ratio",
        type=_positive_float,
        metavar="R",
        help="with --no-flash: the flash photo's exposure over the no-flash photo's "
        "(time × ISO / f-number², e.g. 1/60 s at ISO 400 over 1/15 s at ISO 400: 0.25), for photos "
        "whose EXIF does not state it (default: from the EXIF)",
    )
    group.add_argument(
        "--crop",
        type=_crop,
        metavar="X,Y,SIZE",
        help="use this square (top-left x, y and side, in pixels of the upright photo) "
        "instead of finding the flash hotspot",
    )
    field_of_view = group.add_mutually_exclusive_group()
    field_of_view.add_argument(
        "--fov",
        type=_field_of_view,
        metavar="DEG",
        help="the photo's horizontal field of view in degrees, for photos without EXIF focal length "
        "(screenshots, exported PNGs, rectified crops); the crop's follows from it (default: EXIF, "
        "else 57.5° across the crop)",
    )
    field_of_view.add_argument(
        "--focal-length-35mm",
        type=_positive_float,
        metavar="MM",
        help="the 35 mm equivalent focal length, as EXIF FocalLengthIn35mmFilm states it (a phone's "
        "main camera: ~24-28); the crop's field of view follows as from EXIF",
    )
    group.add_argument(
        "--input-colorspace",
        choices=("srgb", "linear"),
        help="how JPEG/PNG/HEIC/TIFF values are encoded (default srgb; EXR and RAW are always linear)",
    )


def _add_predict_output(predict: argparse.ArgumentParser) -> None:
    group = predict.add_argument_group("output")
    group.add_argument(
        "--out", required=True, type=Path, metavar="DIR", help="output folder (one subfolder per photo)"
    )
    group.add_argument(
        "--resolution",
        type=_positive,
        metavar="N",
        help="output size N×N (default: the crop's size in the photo, at least the model's training "
        "resolution and at most 2048); sizes above the tile (--tile) run tiled",
    )
    group.add_argument(
        "--format",
        choices=("png", "exr"),
        default="png",
        help="texture file format (default png; EXR stores colours linear)",
    )
    group.add_argument("--bit-depth", type=int, choices=(8, 16), default=8, help="PNG bit depth (default 8)")
    group.add_argument(
        "--normal-convention",
        choices=("opengl", "directx"),
        default="opengl",
        help="normal map green channel: opengl (+Y up: Blender, Unity, glTF; default) or directx (Unreal)",
    )
    group.add_argument(
        "--normal-strength",
        type=_non_negative,
        default=1.0,
        metavar="S",
        help="scale the normals' tilt by S (0 flat, 1 as predicted, 2 twice the slope; default 1); "
        "baked into normal.png, normalTexture.scale in material.glb",
    )
    group.add_argument(
        "--height-scale",
        type=_positive_float,
        metavar="S",
        help="height.png value = 0.5 + S·h, h in units of the sample side (default: fill the 16-bit range; "
        "S is recorded in material.json)",
    )
    group.add_argument(
        "--tileable",
        action="store_true",
        help="make every map wrap seamlessly: the flash mark repaired where it leaked into a map; a "
        "material that repeats on a 2-D lattice (tiles, bricks, mosaics) resampled to a whole number of "
        "its cells, any other the maps rolled by about half a side; then each seam cut along a "
        "minimum-error path through their copies, the same cut for all maps; height and occlusion are "
        "then periodic too",
    )
    group.add_argument(
        "--align-pattern",
        action="store_true",
        help="with --tileable, for a material that repeats on a 2-D lattice (tiles, bricks, mosaics): "
        "turn the pattern so that its own rows and columns run along the tile's edges (rectified) "
        "instead of keeping the photo's orientation; either way such a material is tiled by whole cells",
    )
    group.add_argument(
        "--prefix",
        action="store_true",
        help="name the textures <material>_basecolor.png, <material>_normal.png, … (engines' importers "
        "match materials by file name); material.glb/.json keep their names",
    )
    group.add_argument(
        "--animate",
        nargs="?",
        const="gif",
        choices=("gif", "mp4"),
        help="also write a turntable-light preview animation (default gif)",
    )
    group.add_argument("--no-preview", action="store_true", help="do not render preview.png")


def _add_predict_model(predict: argparse.ArgumentParser) -> None:
    group = predict.add_argument_group("model")
    group.add_argument(
        "--weights",
        type=Path,
        metavar="PATH",
        help="a .safetensors weights file (default: the weights shipped with brdfgan)",
    )
    group.add_argument(
        "--refine",
        nargs="?",
        const=DEFAULT_REFINE_STEPS,
        type=_positive,
        metavar="STEPS",
        help="fit one offset per map (base colour, roughness, metallic), the exposure and the ambient "
        "light to the photo with the differentiable renderer: relit views of the photographed light, "
        "not better maps (with the shipped model it does not lower the maps' errors; "
        "docs/refinement.md); STEPS Adam steps "
        f"(default {DEFAULT_REFINE_STEPS} when given bare; ~4 s per photo at 256² on 2 CPU cores)",
    )


def _add_predict_speed(predict: argparse.ArgumentParser) -> None:
    group = predict.add_argument_group("speed and memory")
    group.add_argument(
        "--device",
        choices=("auto", "cpu", "cuda"),
        default="auto",
        help="where the network runs (default auto: a CUDA GPU when there is one, else the CPU)",
    )
    group.add_argument(
        "--tile",
        type=_positive,
        metavar="N",
        help="photos above N² run as N² tiles (default 1024: memory of one 1024² pass, any resolution)",
    )


def _add_predict_console(predict: argparse.ArgumentParser) -> None:
    group = predict.add_argument_group("console")
    chatter = group.add_mutually_exclusive_group()
    chatter.add_argument(
        "--quiet",
        action="store_true",
        help="stderr: errors only (no model line, progress, warnings or summary); "
        "stdout still lists the outputs",
    )
    chatter.add_argument("--verbose", action="store_true", help="also print each photo's time per stage")


def _add_export_weights(commands: Commands) -> None:
    export = commands.add_parser(
        "export-weights",
        help="a training run → a .safetensors weights file that predict can load",
        description="Export a training run's generator (fp16 unless --full-precision) with its "
        "training summary, as RUN_DIR/weights.safetensors (or --out) and <stem>.json.",
    )
    export.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a train.py run folder")
    export.add_argument("--checkpoint", default="last", help="last (default), best, or a .ckpt path")
    export.add_argument("--out", type=Path, help="default: RUN_DIR/weights.safetensors")
    export.add_argument("--model-id", help="default: the run directory's name")
    export.add_argument("--full-precision", action="store_true", help="store fp32 (default fp16)")
    export.add_argument("--hardware", help="what it was trained on, for the summary")
    export.add_argument("--metrics", type=Path, help="an evaluate.py metrics.json to record as test metrics")
    export.add_argument("--metrics-model", help="the model's name in --metrics (default: the only one)")
    export.set_defaults(run=export_weights_command, interrupted="interrupted: no weights file was written")


def _add_contact_sheet(commands: Commands) -> None:
    sheet = commands.add_parser(
        "contact-sheet",
        help="a dataset → a PNG grid of samples (input | base color | normal | roughness | metallic)",
        description="Write a contact sheet of a generated dataset: one seeded random sample per row.",
    )
    sheet.add_argument("data_dir", type=Path, metavar="DATA_DIR", help="a generated dataset")
    sheet.add_argument("--split", default="train", help="default: train")
    sheet.add_argument("--rows", type=int, default=16, help="samples shown (default 16)")
    sheet.add_argument("--seed", type=int, default=0, help="which samples (default 0)")
    sheet.add_argument("--out", type=Path, default=None, help="default: DATA_DIR/contact_sheet_<split>.png")
    sheet.add_argument(
        "--tile", type=int, default=None, metavar="PX", help="resize every panel to PX² (small sheets)"
    )
    sheet.add_argument(
        "--family",
        default=None,
        metavar="PREFIX",
        help="only samples whose family starts with PREFIX (e.g. scanned/ for the real scans mixed in)",
    )
    sheet.set_defaults(run=contact_sheet_command, interrupted="interrupted: no contact sheet was written")


def _add_convert_deschaintre(commands: Commands) -> None:
    convert = commands.add_parser(
        "convert-deschaintre",
        help="a folder of Deschaintre 2018 samples → brdfgan shards (for evaluate.py)",
        description="Convert a folder of Deschaintre 2018 samples (one PNG of five tiles: "
        "input | normal | diffuse | roughness | specular) into brdfgan shards.",
    )
    convert.add_argument("src", help="folder of .png samples")
    convert.add_argument("out", help="dataset root; the split goes to OUT/<split>/")
    convert.add_argument("--split", default="test", help="split name (default: test)")
    convert.add_argument("--samples-per-shard", type=int, default=None, help="default: 64")
    convert.add_argument("--flip-green", action="store_true", help="normal tiles are DirectX (+Y down)")
    convert.add_argument("--crop", type=int, default=None, help="centre-crop every tile to CROP×CROP")
    convert.add_argument(
        "--skip-malformed", action="store_true", help="skip bad files (listed in the manifest)"
    )
    convert.add_argument("--overwrite", action="store_true", help="replace an existing split")
    convert.set_defaults(
        run=convert_deschaintre_command,
        interrupted="interrupted: the split has no manifest yet; run again with --overwrite",
    )


def _add_report(commands: Commands) -> None:
    report = commands.add_parser(
        "report",
        help="training runs compared by what varies across them (runs.md/.csv; ablation.md/.csv)",
        description="Group the runs below RUN_DIR… by every setting that varies across them (seeds "
        "averaged: mean ± std, n), warn about duplicates, and write runs.md/.csv — and the paper's "
        "ablation table when only the loss varies — next to the first directory (or --out).",
    )
    report.add_argument("directories", type=Path, nargs="+", metavar="RUN_DIR")
    report.add_argument("--out", type=Path, default=None, help="default: the first RUN_DIR")
    report.set_defaults(run=report_command, interrupted="interrupted")


def _add_references(commands: Commands) -> None:
    references = commands.add_parser(
        "references",
        help="a dataset → weights of the trivial reference predictors (mean maps, photo as base "
        "colour, de-lit photo)",
        description="Fit the trivial references on the train split of DATA_DIR and write "
        "OUT/mean_maps.safetensors, OUT/photo_basecolor.safetensors and OUT/de_lit.safetensors, which "
        "predict and evaluate.py load like any model.",
    )
    references.add_argument("data_dir", type=Path, metavar="DATA_DIR", help="its train split is used")
    references.add_argument("--out", type=Path, required=True, metavar="DIR")
    references.add_argument(
        "--only", nargs="+", default=None, metavar="NAME", help="some of: mean_maps photo_basecolor de_lit"
    )
    references.set_defaults(run=references_command, interrupted="interrupted")


def _add_dataset_stats(commands: Commands) -> None:
    stats = commands.add_parser(
        "dataset-stats",
        help="dataset splits (and scanned sets) → coverage statistics: families, metallic, HSV, relief, "
        "capture conditions",
        description="Print a markdown table of the maps' distribution in DATA_DIR's splits (a split "
        "mixing scanned sets in also by part: procedural, scans) and, with --scanned, in a folder of "
        "scanned sets (e.g. the out-of-distribution benchmark); then a table of each split's capture "
        "conditions (field of view, flash offset, tilt, exposure error, flash temperature, crop "
        "scale, mirrored, recoloured and mixed shares) from the samples' metadata.",
    )
    stats.add_argument("data_dir", type=Path, metavar="DATA_DIR")
    stats.add_argument(
        "--split", nargs="+", default=["train"], metavar="SPLIT", help="one or more splits; default: train"
    )
    stats.add_argument(
        "--scanned", type=Path, default=None, metavar="DIR", help="scanned sets to compare with"
    )
    stats.set_defaults(run=dataset_stats_command, interrupted="interrupted")


def _add_eval_captures(commands: Commands) -> None:
    captures = commands.add_parser(
        "eval-captures",
        help="real multi-view flash captures (MaterialGAN layout) → relit-view RMSE per model "
        "(captures.md/.csv)",
        description="Predict each capture's maps from its first view (00.png, whole, auto-exposed, "
        "flash frame from the calibration), re-render every other view at its calibrated camera and "
        "flash, and compare with the photos (sRGB RMSE; with one gain fitted on the input view, and "
        "with the calibrated flash power). The weights are compared with the photo-as-base-colour and "
        "de-lit references; writes OUT/captures.md and OUT/captures.csv (per view) and prints the table.",
    )
    captures.add_argument(
        "captures",
        nargs="+",
        type=Path,
        metavar="DIR",
        help="a capture folder (00.png, 01.png, … with parameters.json, or MaterialGAN's camera_pos.txt, "
        "image_size.txt, light_power.txt [, light_pos.txt]) or a folder of capture folders",
    )
    captures.add_argument(
        "--weights", type=Path, metavar="PATH", help="a .safetensors weights file (default: the shipped one)"
    )
    captures.add_argument(
        "--references",
        type=Path,
        metavar="DIR",
        help="folder of photo_basecolor.safetensors and de_lit.safetensors (default: the shipped "
        "references); a missing file is a warning and its row is left out",
    )
    captures.add_argument(
        "--refine",
        nargs="?",
        const=DEFAULT_REFINE_STEPS,
        type=_positive,
        metavar="STEPS",
        help="also score the weights followed by predict's --refine (a row <model>+refine<STEPS>; "
        f"default {DEFAULT_REFINE_STEPS} steps when given bare)",
    )
    captures.add_argument(
        "--resolution",
        type=_positive,
        metavar="N",
        help="the side the input view is resized to for the models (default: each model's training "
        "resolution); the maps are resized back to the capture's",
    )
    captures.add_argument(
        "--fit-views",
        type=_positive,
        default=1,
        metavar="K",
        help="fit each model's maps to the first K views (predict --views's multi-view fit) and relight "
        "the others (rows <model>+fit<K>; with --refine, refined then fitted); every capture needs more "
        "than K views. K = 1 (default): the single-photo protocol, maps from the first view alone",
    )
    captures.add_argument("--out", type=Path, default=None, metavar="DIR", help="default: the first DIR")
    captures.set_defaults(run=eval_captures_command, interrupted="interrupted: no table was written")


def predict_command(args: argparse.Namespace) -> int:
    from brdfgan.inference.pipeline import collect_photos

    kind = _capture_kind(args)
    options, device = _predict_options(args, kind)
    if args.quiet:  # errors only: library warnings (logging) are not errors
        logging.getLogger("brdfgan").setLevel(logging.ERROR)
    predictor = _load_predictor(args.weights, options, device)
    photos = collect_photos(args.inputs)
    if not photos:
        print("error: no photos to process", file=sys.stderr)
        return USER_ERROR_EXIT_CODE
    captures = _group(args, kind, photos)
    if not captures:  # --no-flash given only no-flash photos: each was left out with a warning
        print("error: no flash photos to process", file=sys.stderr)
        return USER_ERROR_EXIT_CODE
    if not args.quiet:
        model = predictor.model
        print(
            f"model {model.model_id} ({model.path}) on {device}; "
            f"{len(photos)} photo(s) at {predictor.describe_resolution()}",
            file=sys.stderr,
        )
    outcome = _predict_batch(args, captures, predictor)
    return _batch_exit_code(outcome, len(captures), kind, out=args.out, quiet=args.quiet)


def _capture_kind(args: argparse.Namespace) -> CaptureKind:
    """The kind of capture predict's flags select (brdfgan.capture.CAPTURE_KINDS); the default
    is one capture per photo."""
    from brdfgan.capture import CAPTURE_KINDS, PAIR, SINGLE_PHOTO

    chosen = [
        kind
        for kind in CAPTURE_KINDS.values()
        if kind.flag and getattr(args, _flag_dest(kind.flag)) not in (None, False)
    ]
    if len(chosen) > 1:
        raise UserError(f"choose one kind of capture: {' or '.join(str(kind.flag) for kind in chosen)}")
    if args.exposure_ratio is not None and chosen != [PAIR]:
        raise UserError(f"--exposure-ratio applies to a flash + no-flash pair ({PAIR.flag})")
    return chosen[0] if chosen else SINGLE_PHOTO


def _group(args: argparse.Namespace, kind: CaptureKind, photos: list[Path]) -> list[Capture]:
    """The run's captures: a flag that names a photo (``--no-flash NOFLASH``) makes the one input
    and it one capture; otherwise the kind's grouping (brdfgan.inference.dispatch.group_captures)."""
    from brdfgan.inference.dispatch import all_photos_together, group_captures

    named = getattr(args, _flag_dest(kind.flag)) if kind.flag_value is not None and kind.flag else None
    if not isinstance(named, Path):
        return group_captures(kind, photos)
    if len(photos) != 1:
        raise UserError(
            f"{kind.flag} {kind.flag_value} goes with one photo, got {len(photos)}; to pair several, "
            f"give {kind.flag} alone after them (each <name> with its <name>_noflash)"
        )
    return all_photos_together(kind, [photos[0], named])


def _flag_dest(flag: str) -> str:
    return flag.lstrip("-").replace("-", "_")


def _predict_options(args: argparse.Namespace, kind: CaptureKind) -> tuple[PredictOptions, torch.device]:
    """predict's options checked against each other and resolved into the pipeline's options and
    the device, before any model or photo is loaded."""
    from brdfgan.inference.intake.lens import FieldOfView
    from brdfgan.inference.model.tiling import TilingConfig
    from brdfgan.inference.outputs.export import ExportOptions
    from brdfgan.inference.pipeline import PredictOptions
    from brdfgan.inference.refine import RefineConfig

    if args.refine is not None and not kind.refines:
        raise UserError(f"--refine cannot be combined with {kind.flag} ({kind.no_refine_reason})")
    if args.align_pattern and not args.tileable:
        raise UserError("--align-pattern applies to tileable maps: add --tileable")
    device = _predict_device(args.device)
    options = PredictOptions(
        resolution=args.resolution,
        crop=args.crop,
        colorspace=args.input_colorspace,
        export=ExportOptions(
            args.format,
            args.bit_depth,
            args.normal_convention,
            normal_strength=args.normal_strength,
            height_scale=args.height_scale,
        ),
        tileable=args.tileable,
        align_pattern=args.align_pattern,
        prefix_files=args.prefix,
        tiling=TilingConfig.for_tile(args.tile),
        preview=not args.no_preview,
        animate=args.animate,
        refine=None if args.refine is None else RefineConfig(steps=args.refine),
        field_of_view=FieldOfView(args.fov, args.focal_length_35mm),
        exposure_ratio=args.exposure_ratio,
    )
    return options, device


def _load_predictor(weights: Path | None, options: PredictOptions, device: torch.device) -> Predictor:
    """The model (``--weights`` or the shipped one) on ``device`` with this run's options."""
    from brdfgan.inference.model.memory import check_memory
    from brdfgan.inference.model.weights import load_model
    from brdfgan.inference.pipeline import Predictor

    model = load_model(weights)
    model.generator.to(device)
    predictor = Predictor.create(model, options)
    # Before any photo is read or anything large allocated.
    check_memory(predictor.model, predictor.largest_resolution, options.tiling)
    return predictor


def _predict_batch(args: argparse.Namespace, captures: list[Capture], predictor: Predictor) -> BatchResult:
    """Every capture into ``OUT/<name>/``, with the batch's progress on stderr."""
    from brdfgan.errors import interrupts_raise
    from brdfgan.inference.dispatch import predict_batch

    fits = args.refine is not None or any(not capture.kind.refines for capture in captures)
    progress = _BatchProgress(len(captures), quiet=args.quiet, verbose=args.verbose, fits=fits)
    try:
        # SIGTERM too: the capture in progress then leaves no hidden staging folder behind.
        with interrupts_raise():
            return predict_batch(
                captures, args.out, predictor, on_result=progress.report, on_step=progress.fit_step
            )
    finally:
        progress.close()


class _BatchProgress:
    """predict's progress on stderr: a bar over the batch's captures, each one's error, warnings
    and (``--verbose``) stage times written above it, and under it the steps of the fit in
    progress (``--refine``, a multi-view fit). ``quiet``: errors only."""

    def __init__(self, capture_count: int, *, quiet: bool, verbose: bool, fits: bool) -> None:
        from tqdm import tqdm

        self.quiet = quiet
        self.verbose = verbose
        # disable=None: tqdm draws only on a terminal.
        self.bar = tqdm(total=capture_count, unit="photo", disable=quiet or None, file=sys.stderr)
        quiet_steps = quiet or not fits
        self.steps_bar = tqdm(
            unit="step", leave=False, position=1, disable=quiet_steps or None, file=sys.stderr
        )

    def fit_step(self, description: str, step: int, steps: int) -> None:
        if step == 1:
            self.steps_bar.reset(total=steps)
            self.steps_bar.set_description(description)
        self.steps_bar.update(1)

    def report(self, result: PhotoResult | PhotoFailure) -> None:
        from brdfgan.inference.pipeline import PhotoFailure

        if isinstance(result, PhotoFailure):
            self.bar.write(f"error: {result.message}", file=sys.stderr)
        else:
            for warning in () if self.quiet else result.warnings:
                self.bar.write(f"warning: {warning}", file=sys.stderr)  # each names its file
            if self.verbose:
                self.bar.write(_describe_timings(result.photo, result.timings), file=sys.stderr)
        self.bar.update(1)

    def close(self) -> None:
        self.steps_bar.close()
        self.bar.close()


def _describe_timings(photo: Path, timings: dict[str, float]) -> str:
    """``--verbose``'s line: the photo's seconds per stage."""
    stages = ", ".join(f"{stage} {seconds:.2f} s" for stage, seconds in timings.items())
    return f"{photo.name}: {stages}"


def _batch_exit_code(
    outcome: BatchResult, capture_count: int, kind: CaptureKind, *, out: Path, quiet: bool
) -> int:
    """Print the batch's outputs (stdout) and its summary (stderr); the exit status: a full disk,
    some captures failed, or 0."""
    unit = "photo(s)" if len(kind.photos) == 1 and kind.more_views is None else "capture(s)"
    for result in outcome.succeeded:  # stdout is the result, also with --quiet (scripts read it)
        print(result.output)
    if outcome.stopped is not None:  # a full disk; its error line was printed as it happened
        print(
            f"stopped: {len(outcome.succeeded)} of {capture_count} {unit} written; free some space and "
            "run again",
            file=sys.stderr,
        )
        return DISK_FULL_EXIT_CODE
    if outcome.failed:
        print(f"{len(outcome.failed)} of {capture_count} {unit} failed:", file=sys.stderr)
        for failure in outcome.failed:
            print(f"  {failure.message}", file=sys.stderr)
        return PARTIAL_FAILURE_EXIT_CODE
    if not quiet:
        print(f"done: {len(outcome.succeeded)} material(s) in {out}", file=sys.stderr)
    return 0


def export_weights_command(args: argparse.Namespace) -> int:
    from brdfgan.inference.model.export_weights import export_weights

    metrics = (args.metrics, args.metrics_model) if args.metrics is not None else None
    out = args.out or args.run_dir / "weights.safetensors"
    export_weights(args.run_dir, out, checkpoint=args.checkpoint, model_id=args.model_id,
                   half=not args.full_precision, hardware=args.hardware, metrics=metrics)  # fmt: skip
    print(out)
    return 0


def contact_sheet_command(args: argparse.Namespace) -> int:
    from brdfgan.data.tools.contact_sheet import write_contact_sheet

    if args.tile is not None and args.tile < 8:
        raise UserError(f"--tile={args.tile}: must be at least 8 pixels")
    print(
        write_contact_sheet(
            args.data_dir,
            args.split,
            rows=args.rows,
            seed=args.seed,
            out=args.out,
            tile=args.tile,
            family=args.family,
        )
    )
    return 0


def convert_deschaintre_command(args: argparse.Namespace) -> int:
    from brdfgan.data.tools.deschaintre_dataset import DEFAULT_SAMPLES_PER_SHARD, convert_deschaintre_folder

    per_shard = DEFAULT_SAMPLES_PER_SHARD if args.samples_per_shard is None else args.samples_per_shard
    summary = convert_deschaintre_folder(
        args.src,
        args.out,
        args.split,
        per_shard,
        flip_green=args.flip_green,
        crop=args.crop,
        skip_malformed=args.skip_malformed,
        overwrite=args.overwrite,
    )
    for name, reason in summary.skipped:
        print(f"skipped {name}: {reason}")
    print(summary.describe())
    return 0


def report_command(args: argparse.Namespace) -> int:
    from brdfgan.report import write_report

    for markdown in write_report(args.directories, args.out):
        print(markdown.read_text())
    return 0


def references_command(args: argparse.Namespace) -> int:
    from brdfgan.reference_weights import REFERENCE_NAMES, write_reference_weights

    for path in write_reference_weights(args.data_dir, args.out, args.only or REFERENCE_NAMES):
        print(path)
    return 0


def dataset_stats_command(args: argparse.Namespace) -> int:
    from brdfgan.data.tools.statistics import dataset_report

    print(dataset_report(args.data_dir, args.split, args.scanned), end="")
    return 0


def eval_captures_command(args: argparse.Namespace) -> int:
    from brdfgan.evaluation.real_captures import (
        capture_models,
        check_fit_views,
        evaluate_captures,
        find_captures,
        write_capture_results,
    )
    from brdfgan.inference.refine import RefineConfig

    captures = find_captures(args.captures)  # every folder checked before any model runs
    check_fit_views(captures, args.fit_views)  # … and its number of views against --fit-views
    refine = None if args.refine is None else RefineConfig(steps=args.refine)
    models = capture_models(args.weights, args.references, refine=refine, resolution=args.resolution)
    fitted = f", maps fitted to the first {args.fit_views} views" if args.fit_views > 1 else ""
    print(
        f"{len(captures)} capture(s), {len(models)} model(s): {', '.join(m.name for m in models)}{fitted}",
        file=sys.stderr,
    )
    results = evaluate_captures(captures, models, fit_views=args.fit_views)
    markdown, _ = write_capture_results(results, args.out or args.captures[0])
    print(markdown.read_text(encoding="utf-8"), end="")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s: %(message)s")
    args = build_parser().parse_args(argv)
    return run_reporting_errors(lambda: args.run(args), interrupted=args.interrupted)


if __name__ == "__main__":  # ``python -m brdfgan.cli`` is the console script too
    sys.exit(main())
