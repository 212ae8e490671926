"""``brdfgan predict`` by kind of capture: the inputs grouped into captures
(:class:`~brdfgan.capture.CaptureKind`), each run by its kind's pipeline from one table
(:data:`CAPTURE_PIPELINES`), the batch kept going past a failed capture.

A new kind of capture adds one entry here: how files group into its captures, and the function
that turns one capture into a material (reading, registering and fitting its photos, then the
single-photo write-out, :func:`brdfgan.inference.pipeline.write_prediction`).
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from brdfgan.capture import NO_FLASH_SUFFIX, PAIR, SINGLE_PHOTO, VIEWS, CaptureKind, PhotoRole
from brdfgan.errors import UserError, disk_full_message, is_disk_full, one_line
from brdfgan.inference.intake.photo import PHOTO_EXTENSIONS
from brdfgan.inference.pair.pipeline import predict_pair
from brdfgan.inference.pipeline import (
    BatchResult,
    PhotoFailure,
    PhotoResult,
    Predictor,
    clean_up_outputs,
    output_names,
    predict_photo,
)
from brdfgan.inference.views.pipeline import predict_views

log = logging.getLogger(__name__)

# A fit's progress: (what is fitted, e.g. "refining wood.jpg", step, of steps).
StepProgress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class Capture:
    """The photos of one surface a user gave, in their roles, and the output folder's name.
    A :class:`~brdfgan.inference.pipeline.PhotoResult` of a capture has warnings that each name
    their file.

    Each photo's lens and EXIF facts are read with it (:class:`~brdfgan.inference.intake.photo.Photo`);
    the registration of the others to :attr:`reference` is recorded per photo in
    ``material.json`` by the kind's pipeline."""

    kind: CaptureKind
    files: tuple[Path, ...]
    name: str

    @property
    def reference(self) -> Path:
        """The flash photo the others are registered to, and the one failures are reported under."""
        return self.files[0]

    @property
    def roles(self) -> tuple[PhotoRole, ...]:
        return self.kind.roles(len(self.files))


# (capture, its output folder, the predictor, progress of its fit) → the written material.
PredictCapture = Callable[[Capture, Path, Predictor, StepProgress | None], PhotoResult]
# A run's photo files (in the order given) → its captures, each named for its output folder.
GroupCaptures = Callable[[CaptureKind, Sequence[Path]], list[Capture]]


@dataclass(frozen=True)
class CapturePipeline:
    """How one kind of capture is predicted: its files grouped into captures, and one capture run."""

    group: GroupCaptures
    predict: PredictCapture


def each_photo_alone(kind: CaptureKind, photos: Sequence[Path]) -> list[Capture]:
    """One capture per photo, named by its stem (unique within the batch)."""
    return [Capture(kind, (photo,), name) for photo, name in zip(photos, output_names(photos), strict=True)]


def all_photos_together(kind: CaptureKind, photos: Sequence[Path]) -> list[Capture]:
    """One capture of every photo, the first the reference, named by the first's stem.

    Raises:
        UserError: more photos than the kind takes (one line naming its flag).
    """
    kind.roles(len(photos))
    return [Capture(kind, tuple(photos), output_names(photos[:1])[0])]


def pair_by_name(kind: CaptureKind, photos: Sequence[Path]) -> list[Capture]:
    """One capture per flash photo with its no-flash photo, named ``<stem>_noflash`` (any format
    predict reads, any case) in the same folder: among ``photos`` (a folder run), else beside the
    flash photo on disk (``predict wood.jpg --no-flash``). A flash photo with none is a capture of
    one photo (the pair's pipeline warns and gives its single-photo prediction); a no-flash photo
    without its flash photo is left out with a warning. Named by the flash photos' stems.
    """
    suffix = NO_FLASH_SUFFIX.lower()
    flashes: list[Path] = []
    no_flash: dict[tuple[Path, str], list[Path]] = {}
    for photo in photos:
        stem = photo.stem.lower()
        if stem.endswith(suffix) and len(stem) > len(suffix):
            no_flash.setdefault((photo.parent, stem[: -len(suffix)]), []).append(photo)
        else:
            flashes.append(photo)
    paired: set[Path] = set()
    captures = []
    for flash, name in zip(flashes, output_names(flashes), strict=True):
        candidates = no_flash.get((flash.parent, flash.stem.lower())) or _no_flash_beside(flash)
        # The same format first: wood.jpg with wood_noflash.jpg, wood.dng with wood_noflash.dng.
        partner = min(
            candidates,
            key=lambda path: (path.suffix.lower() != flash.suffix.lower(), str(path)),
            default=None,
        )
        if partner is None:
            captures.append(Capture(kind, (flash,), name))
        else:
            paired.add(partner)
            captures.append(Capture(kind, (flash, partner), name))
    for orphans in no_flash.values():
        for orphan in orphans:
            if orphan not in paired:
                log.warning(
                    "%s: no flash photo %s.* beside it: left out",
                    orphan,
                    orphan.parent / orphan.stem[: -len(suffix)],
                )
    return captures


def _no_flash_beside(flash: Path) -> list[Path]:
    """The files ``<stem>_noflash.<a photo extension>`` in the flash photo's folder (any case)."""
    wanted = f"{flash.stem}{NO_FLASH_SUFFIX}".lower()
    try:
        return sorted(
            path
            for path in flash.parent.iterdir()
            if path.stem.lower() == wanted and path.suffix.lower() in PHOTO_EXTENSIONS and path.is_file()
        )
    except OSError:  # a missing or unreadable folder: the flash photo's own read reports it
        return []


def _labelled(on_step: StepProgress | None, label: str) -> Callable[[int, int], None] | None:
    """A pipeline's ``(step, of steps)`` progress reported under ``label``."""
    return None if on_step is None else functools.partial(on_step, label)


def _predict_single(
    capture: Capture, out_dir: Path, predictor: Predictor, on_step: StepProgress | None
) -> PhotoResult:
    steps = _labelled(on_step, f"refining {capture.reference.name}")
    progress = None if steps is None else lambda _photo, step, of: steps(step, of)
    result = predict_photo(capture.reference, out_dir, predictor, progress)
    # A result's warnings name their file, as a capture of several photos must.
    return replace(result, warnings=tuple(f"{capture.reference}: {warning}" for warning in result.warnings))


def _predict_views(
    capture: Capture, out_dir: Path, predictor: Predictor, on_step: StepProgress | None
) -> PhotoResult:
    progress = _labelled(on_step, f"fitting {len(capture.files)} views")
    return predict_views(capture.files, out_dir, predictor, on_fit_step=progress)


def _predict_pair(
    capture: Capture, out_dir: Path, predictor: Predictor, on_step: StepProgress | None
) -> PhotoResult:
    progress = _labelled(on_step, f"fitting the pair of {capture.reference.name}")
    return predict_pair(capture.files, out_dir, predictor, on_fit_step=progress)


# predict's one dispatch table, by capture kind name (brdfgan.capture.CAPTURE_KINDS).
CAPTURE_PIPELINES: Mapping[str, CapturePipeline] = {
    SINGLE_PHOTO.name: CapturePipeline(each_photo_alone, _predict_single),
    VIEWS.name: CapturePipeline(all_photos_together, _predict_views),
    # `--no-flash NOFLASH` names the one flash photo's partner: all_photos_together (brdfgan.cli).
    PAIR.name: CapturePipeline(pair_by_name, _predict_pair),
}


def group_captures(kind: CaptureKind, photos: Sequence[Path]) -> list[Capture]:
    """``photos`` (the files of one run, in order) grouped into captures of ``kind``."""
    return CAPTURE_PIPELINES[kind.name].group(kind, photos)


def predict_capture(
    capture: Capture, out_dir: Path, predictor: Predictor, on_step: StepProgress | None = None
) -> PhotoResult:
    """One capture into ``out_dir`` (replaced atomically) by its kind's pipeline."""
    return CAPTURE_PIPELINES[capture.kind.name].predict(capture, out_dir, predictor, on_step)


def predict_batch(
    captures: Sequence[Capture],
    out_root: Path,
    predictor: Predictor,
    *,
    on_result: Callable[[PhotoResult | PhotoFailure], None] | None = None,
    on_step: StepProgress | None = None,
) -> BatchResult:
    """Predict every capture into ``out_root/<capture.name>/``; a failure is recorded and the
    batch goes on.

    User errors (:class:`~brdfgan.errors.UserError`: unreadable or unsupported files, bad crops,
    unwritable outputs) and OS errors are reported with their one-line message; anything else
    with its exception type, so a bug in one capture never loses the rest of the batch. A full
    disk ends the batch: the result then says so in ``stopped`` (``<path>: no space left on
    device``). Hidden folders left by killed runs in ``out_root`` are cleaned up first.
    Interrupts (``KeyboardInterrupt``) propagate; run inside
    :func:`brdfgan.errors.interrupts_raise` to get the same for SIGTERM.
    """
    succeeded: list[PhotoResult] = []
    failed: list[PhotoFailure] = []
    clean_up_outputs(out_root)
    for capture in captures:
        photo = capture.reference
        result: PhotoResult | PhotoFailure
        try:
            result = predict_capture(capture, out_root / capture.name, predictor, on_step)
            succeeded.append(result)
        except (UserError, OSError) as error:
            result = PhotoFailure(photo, _failure_message(photo, error))
            failed.append(result)
            if is_disk_full(error):
                if on_result is not None:
                    on_result(result)
                return BatchResult(succeeded=succeeded, failed=failed, stopped=result.message)
        except Exception as error:  # keep the batch alive and report the bug
            log.debug("internal error on %s", photo, exc_info=True)
            result = PhotoFailure(photo, f"{photo}: internal error {type(error).__name__}: {one_line(error)}")
            failed.append(result)
        if on_result is not None:
            on_result(result)
    return BatchResult(succeeded=succeeded, failed=failed)


def _failure_message(photo: Path, error: Exception) -> str:
    if is_disk_full(error):
        return disk_full_message(error)
    message = one_line(error)
    return message if str(photo) in message else f"{photo}: {message}"
