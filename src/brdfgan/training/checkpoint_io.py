"""Checkpoint files that are complete or absent, on any filesystem, and never unpickle code.

Lightning's ``TorchCheckpointIO`` serialises to memory and writes through an fsspec
transaction, which stages the file in ``$TMPDIR`` and moves it into place: across filesystems
the move is a copy, so a kill halfway left a truncated ``last.ckpt`` (the previous one already
gone) and a stray file in ``/tmp``. Here the file is written beside its target under a hidden
temporary name, fsynced and renamed (:func:`brdfgan.io.atomic.atomic_replace`): the previous
checkpoint stays valid until the new one is complete, and a full disk leaves nothing behind.
Loading always uses ``torch.load(weights_only=True)``.
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from lightning.pytorch.plugins.io import TorchCheckpointIO

from brdfgan.io.atomic import atomic_replace


class AtomicCheckpointIO(TorchCheckpointIO):
    """``TorchCheckpointIO`` with same-directory temp + fsync + rename, and safe loading."""

    def save_checkpoint(
        self, checkpoint: dict[str, Any], path: str | os.PathLike[str], storage_options: Any | None = None
    ) -> None:
        if storage_options is not None:
            raise TypeError(f"{type(self).__name__} takes no storage_options, got {storage_options!r}")
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        # Serialised in memory first (as Lightning does): torch.save's zip writer reports a
        # full disk as an opaque RuntimeError, a plain file write as ENOSPC, which
        # atomic_replace turns into a DiskFullError naming the checkpoint.
        buffer = io.BytesIO()
        torch.save(checkpoint, buffer)
        with atomic_replace(path) as temp:
            temp.write_bytes(buffer.getbuffer())

    def load_checkpoint(
        self,
        path: str | os.PathLike[str],
        map_location: Callable[..., Any] | None = lambda storage, loc: storage,
        weights_only: bool | None = None,
    ) -> dict[str, Any]:
        # A checkpoint is data: whatever a caller asks, nothing in it may run code.
        return super().load_checkpoint(Path(path), map_location=map_location, weights_only=True)
