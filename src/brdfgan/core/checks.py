"""Shape checks: the one helper that every ``(…, 8, H, W)``-style argument check goes through.

Modelled on kornia's ``KORNIA_CHECK_SHAPE``: a pattern such as ``"B 8 H W"`` lists one token per
dimension. An integer must match exactly; a name matches any size and binds it, so a name used
twice (``"3 S S"``, a square image) must see the same size both times, and ``dims`` binds names
in advance (a second tensor's batch, a known resolution). A leading ``*`` matches any number of
leading dimensions, none included.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
from torch import Tensor


def _tokens(pattern: str) -> list[str]:
    """The pattern's tokens; a ``ValueError`` for a malformed pattern (a bug in the caller)."""
    tokens = pattern.split()
    for index, token in enumerate(tokens):
        valid = token.isdecimal() or token.isidentifier() or (token == "*" and index == 0)
        if not valid:
            raise ValueError(f"bad shape pattern {pattern!r}: token {token!r}")
    return tokens


def check_shape(
    tensor: Tensor | np.ndarray,
    pattern: str,
    *,
    name: str = "tensor",
    dims: Mapping[str, int] | None = None,
    error: Callable[[str], Exception] = ValueError,
) -> dict[str, int]:
    """Raise ``error`` unless ``tensor``'s shape matches ``pattern``; return the bound sizes.

    The message is one line, ``<name> must have shape (<pattern>), got <shape>``, with the
    names bound through ``dims`` shown as their sizes. ``error`` makes the exception from that
    message: an exception class (a :class:`~brdfgan.errors.UserError` subclass where the tensor
    comes from the user) or e.g. ``functools.partial(PhotoError, path)``.

    Shape:
        - tensor: any, checked against ``pattern``
        - output: ``{name: size}`` for every name in ``pattern`` and ``dims``

    Example:
        >>> import torch
        >>> check_shape(torch.zeros(2, 8, 4, 5), "B 8 H W", name="maps")
        {'B': 2, 'H': 4, 'W': 5}
        >>> check_shape(torch.zeros(8, 4, 4), "* 8 S S", name="maps")
        {'S': 4}
        >>> check_shape(torch.zeros(3, 4, 4), "B 8 H W", name="maps")
        Traceback (most recent call last):
            ...
        ValueError: maps must have shape (B, 8, H, W), got (3, 4, 4)
    """
    tokens = _tokens(pattern)
    bound = dict(dims or {})
    shape = tuple(int(size) for size in tensor.shape)
    if not _matches(shape, tokens, bound):
        shown = ", ".join(str(dims[token]) if dims and token in dims else token for token in tokens)
        raise error(f"{name} must have shape ({shown}), got {shape}")
    return bound


def _matches(shape: tuple[int, ...], tokens: list[str], bound: dict[str, int]) -> bool:
    """Whether ``shape`` fits ``tokens``, binding names into ``bound`` on the way."""
    if tokens[:1] == ["*"]:
        tokens = tokens[1:]
        if len(shape) < len(tokens):
            return False
    elif len(shape) != len(tokens):
        return False
    for token, size in zip(tokens, shape[len(shape) - len(tokens) :], strict=True):
        expected = int(token) if token.isdecimal() else bound.setdefault(token, size)
        if size != expected:
            return False
    return True
