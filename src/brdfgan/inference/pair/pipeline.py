"""A flash photo and a no-flash photo of one surface → one material (``brdfgan predict --no-flash``).

::

    read_photo both (the flash photo's failure, or the no-flash photo's, is the capture's one-line error)
      → preprocess the flash photo: its crop on the flash hotspot, the crop's field of view and flash frame
      → the network on the flash photo's crop (the single-photo prediction, where the pair cannot serve)
      → the exposure ratio r (EXIF or --exposure-ratio); the no-flash photo not too dark nor blurred
      → the no-flash photo registered to the flash photo and checked: one surface (pair.intake)
      → in the crop at the output side: the registered no-flash photo, the white balance G, the room
        light's share r·G·no-flash, the flash-only image and its valid pixels; the flash strong
        enough against the room light
      → the network on the flash-only crop, auto-exposed as preprocessing exposes a photo
      → fit_pair: the relief from the two lights (pair.relief_fit), read with the flash-only
        image's maps and written into the flash photo's (their base colour, roughness and metallic
        were the better on validation pairs; the fit's settings were chosen with the flash-only ones)
      → the single-photo write-out (pipeline.write_prediction: atomic, nothing half-written),
        material.json with ``pair`` (files, exposures, ratio, registration, gains, flash-to-room)
        and ``pair_fit``

Where the pair cannot serve (no exposure ratio, a dark or blurred no-flash photo, no registration,
two surfaces, too little seen, the flash too weak), one warning line names both files and says
why, and the flash photo gets the single-photo prediction; ``material.json``'s ``pair`` records the
reason (``fallback``) and what was measured.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, Protocol

from torch import Tensor

from brdfgan.capture import NO_FLASH_SUFFIX
from brdfgan.core.exposure import auto_expose
from brdfgan.errors import UserError
from brdfgan.inference.intake.lens import crop_field_of_view
from brdfgan.inference.intake.photo import Photo, PhotoError, read_photo
from brdfgan.inference.intake.preprocess import Preprocessed, preprocess
from brdfgan.inference.pair.intake import (
    PairImages,
    exposure_ratio,
    no_flash_problem,
    pair_images,
    pair_problem,
    register_no_flash,
    registration_record,
)
from brdfgan.inference.pair.relief_fit import PairFitConfig, PairFitResult, fit_pair
from brdfgan.inference.pipeline import (
    PhotoResult,
    Predictor,
    StageClock,
    network_reference,
    write_prediction,
)

FitProgress = Callable[[int, int], None]  # (step, of steps)


class PairFit(Protocol):
    """:func:`~brdfgan.inference.pair.relief_fit.fit_pair`'s signature (tests pass their own)."""

    def __call__(
        self,
        flash_only: Tensor,
        room: Tensor,
        valid: Tensor,
        maps: Tensor,
        frame: Tensor,
        config: PairFitConfig | None = None,
        on_step: FitProgress | None = None,
        *,
        written: Tensor | None = None,
    ) -> PairFitResult: ...


def predict_pair(
    paths: Sequence[Path],
    out_dir: Path,
    predictor: Predictor,
    on_fit_step: FitProgress | None = None,
    *,
    fit: PairFit | None = None,
) -> PhotoResult:
    """The material of a flash photo and its no-flash photo, ``paths`` in that order, written to
    ``out_dir`` (replaced atomically; module docstring). A lone flash photo (no no-flash photo was
    found for it) gets the single-photo prediction with a warning. The result's warnings are one
    line each and name their file. ``fit``: the pair fit (default
    :func:`~brdfgan.inference.pair.relief_fit.fit_pair`, looked up when called; tests pass their own).

    Raises:
        UserError: either photo cannot be read, or the flash photo cannot be used (one line, naming
            the file).
    """
    clock = StageClock({})
    flash_path = paths[0]
    options = predictor.options
    with clock("read"):
        flash = read_photo(flash_path, options.colorspace)
        no_flash = _read_no_flash(flash_path, paths[1], options.colorspace) if len(paths) > 1 else None
    with clock("preprocess"):
        prepared = preprocess(flash, predictor.resolution, options.crop)
    fov_deg, fov_source = crop_field_of_view(
        flash.lens, flash.width, flash.height, prepared.crop.size, options.field_of_view
    )
    frame = prepared.flash_frame(fov_deg)
    warnings = [f"{flash_path}: {warning}" for warning in flash.warnings + prepared.warnings]
    # The flash photo's maps: the single-photo prediction, or what the pair fit writes its relief into.
    reference = network_reference(flash, prepared, fov_deg, fov_source, frame, predictor, clock)
    if no_flash is None:
        warnings.append(
            f"{flash_path}: no no-flash photo ({flash_path.stem}{NO_FLASH_SUFFIX}.*) was found for it: "
            "the single-photo prediction"
        )
        records: dict[str, Any] = {"refinement": None, "pair": None, "pair_fit": None}
        return write_prediction(
            reference, reference.maps, out_dir, predictor, clock, records=records, warnings=tuple(warnings)
        )
    warnings += [f"{no_flash.path}: {warning}" for warning in no_flash.warnings]
    record = _start_record(flash, no_flash)
    with clock("pair"):
        outcome = _pair_images(flash, no_flash, prepared, frame, options.exposure_ratio, record)
    if isinstance(outcome, str):
        record["fallback"] = outcome
        warnings.append(
            f"{flash_path}: its no-flash photo {no_flash.path} cannot serve ({outcome}): "
            "the single-photo prediction"
        )
        records = {"refinement": None, "pair": _json(record), "pair_fit": None}
        return write_prediction(
            reference, reference.maps, out_dir, predictor, clock, records=records, warnings=tuple(warnings)
        )
    record["used"] = True
    # The network sees the flash-only crop exposed as preprocessing exposes a photo; the room light
    # is gone from it, and where the no-flash photo does not see, it is the flash photo's.
    ldr, scale = auto_expose(outcome.flash_only.clamp(min=0.0))
    flash_only = replace(
        prepared,
        photo=ldr.contiguous(),
        exposure_scale=float(scale),
        stats={
            **prepared.stats,
            "exposure_scale": float(scale),
            "output_clipped_fraction": float((ldr >= 1.0).any(dim=0).float().mean()),
        },
    )
    read = network_reference(flash, flash_only, fov_deg, fov_source, frame, predictor, clock)
    with clock("fit"):
        fitted = (fit or fit_pair)(
            outcome.flash_only.clamp(min=0.0),
            outcome.room,
            outcome.valid,
            read.maps,
            frame,
            on_step=on_fit_step,
            written=reference.maps,
        )
    records = {"refinement": None, "pair": _json(record), "pair_fit": fitted.to_json()}
    return write_prediction(
        reference, fitted.maps, out_dir, predictor, clock, records=records, warnings=tuple(warnings)
    )


def _read_no_flash(flash_path: Path, path: Path, colorspace: Any) -> Photo:
    """The no-flash photo; a failure is the capture's, one line naming both files."""
    try:
        return read_photo(path, colorspace)
    except PhotoError as error:
        raise UserError(f"{flash_path}: its no-flash photo {error}") from error


def _start_record(flash: Photo, no_flash: Photo) -> dict[str, Any]:
    """``material.json``'s ``pair`` before anything is measured: nothing used yet."""
    return {
        "flash": {
            "file": str(flash.path),
            "exposure": None if flash.exposure is None else flash.exposure.to_json(),
        },
        "no_flash": no_flash.to_json(),
        "exposure_ratio": None,
        "no_flash_check": None,
        "registration": None,
        "white_balance": None,
        "flash_to_room": None,
        "valid_fraction": None,
        "used": False,
        "fallback": None,
    }


def _pair_images(
    flash: Photo,
    no_flash: Photo,
    prepared: Preprocessed,
    frame: Tensor,
    given_ratio: float | None,
    record: dict[str, Any],
) -> PairImages | str:
    """The pair's images in the flash photo's crop, or the one-line reason it cannot serve; what is
    measured on the way goes into ``record``. Cheapest checks first."""
    ratio = exposure_ratio(flash.exposure, no_flash.exposure, given_ratio)
    if isinstance(ratio, str):
        return ratio
    record["exposure_ratio"] = ratio.to_json()
    measures, problem = no_flash_problem(flash, no_flash)
    record["no_flash_check"] = measures
    if problem is not None:
        return problem
    registration = register_no_flash(flash, no_flash, prepared.crop)
    if isinstance(registration, str):
        return f"it does not register to the flash photo: {registration}"
    record["registration"] = registration_record(registration)
    side = int(prepared.photo.shape[-1])
    images = pair_images(flash, no_flash, registration, prepared.crop, side, ratio.value, frame)
    record["white_balance"] = images.white_balance.to_json()
    record["flash_to_room"] = images.flash_to_room
    record["valid_fraction"] = images.valid_fraction
    problem = pair_problem(images)
    return images if problem is None else problem


def _json(value: Any) -> Any:
    """JSON has no NaN or infinity: a measure that could not be taken is ``null``."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {key: _json(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_json(item) for item in value]
    return value
