"""Type-check Hydra ``_target_`` nodes against the signatures they will be called with.

A composed config is only a tree of strings and numbers until ``hydra.utils.instantiate`` calls
the targets — so ``trainer.max_epochs=abc`` used to surface as a 40-line traceback from deep
inside Lightning, after seconds of imports and data preparation. :func:`check_config` walks the
tree first: every key of a ``_target_`` node must be a parameter of the target, and every plain
value must fit the parameter's annotation. The first mismatch is one :class:`ConfigValueError`
naming the full key, the value and the expected type::

    trainer.max_epochs='abc': expected int | None (lightning.pytorch.trainer.trainer.Trainer)

Annotations that a config value cannot be checked against (a class that only code can make,
an unresolvable forward reference) are accepted rather than guessed; only a value that fits
none of the alternatives is rejected. Values of nested ``_target_`` nodes are checked
recursively instead of against the parameter's annotation.
"""

from __future__ import annotations

import dataclasses
import enum
import inspect
import os
import types
import typing
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import PurePath
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf

from brdfgan.errors import UserError

# Hydra's own keys inside a node: not constructor parameters.
HYDRA_KEYS = frozenset({"_target_", "_partial_", "_convert_", "_recursive_", "_args_"})


class ConfigValueError(UserError):
    """A config value does not fit the parameter it is passed to; the message names the key."""


def check_config(cfg: DictConfig, keys: Iterable[str]) -> None:
    """Check the ``_target_`` nodes under each of ``keys`` of ``cfg`` (missing keys are skipped).

    Raises :class:`ConfigValueError` for an unknown parameter or a value of the wrong type.
    """
    for key in keys:
        node = OmegaConf.select(cfg, key, default=None, throw_on_missing=False)
        if node is not None:
            check_node(node, key)


def check_node(node: Any, key: str) -> None:
    """Check ``node`` (found at ``key``) and everything below it."""
    if isinstance(node, DictConfig):
        if "_target_" in node:
            _check_target_node(node, key)
        else:
            for name in node:
                check_node(node._get_node(str(name)), f"{key}.{name!s}")
    elif isinstance(node, ListConfig):
        for position in range(len(node)):
            check_node(node._get_node(position), f"{key}[{position}]")


def _check_target_node(node: DictConfig, key: str) -> None:
    from hydra._internal.utils import _locate

    target_name = str(node._target_)
    try:
        target = _locate(target_name)
    except Exception as error:  # ImportError, AttributeError, …: all mean "no such target"
        raise ConfigValueError(f"{key}._target_={target_name}: cannot import it ({error})") from None
    parameters, hints, takes_kwargs = signature_of(target)
    for name in node:
        name = str(name)
        if name in HYDRA_KEYS:
            continue
        child_key = f"{key}.{name}"
        if name not in parameters and not takes_kwargs:
            known = ", ".join(p for p in parameters if p not in ("self", "args", "kwargs"))
            raise ConfigValueError(f"{child_key}: not a parameter of {target_name} (parameters: {known})")
        child = node._get_node(name)
        if OmegaConf.is_interpolation(node, name):
            resolved = node[name]
            if isinstance(resolved, DictConfig) and "_target_" in resolved:
                continue  # another node's target (``${data.prepare.spec}``): checked where it is defined
        if isinstance(child, DictConfig | ListConfig):
            check_node(child, child_key)  # nested _target_ nodes, themselves or in lists and mappings
            if isinstance(child, DictConfig) and "_target_" in child:
                continue  # its value is what the target builds: checked as a node, not as a value
        value = OmegaConf.to_container(child, resolve=True) if OmegaConf.is_config(child) else node[name]
        hint = hints.get(name, Any)
        if fits(value, hint) is False:
            raise ConfigValueError(f"{child_key}={value!r}: expected {describe(hint)} ({_qualified(target)})")


def signature_of(target: Any) -> tuple[dict[str, inspect.Parameter], dict[str, Any], bool]:
    """Parameters, resolved annotations (where resolvable) and whether ``**kwargs`` is taken."""
    try:
        signature = inspect.signature(target)
    except (TypeError, ValueError):
        return {}, {}, True  # a builtin without a signature: nothing to check against
    parameters = dict(signature.parameters)
    takes_kwargs = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values())
    function = target.__init__ if inspect.isclass(target) else target
    hints: dict[str, Any] = {}
    for source in (function, target if dataclasses.is_dataclass(target) else None):
        if source is None:
            continue
        try:
            hints = typing.get_type_hints(source)
            break
        except Exception:  # an unresolvable forward reference: check what the signature says
            continue
    if not hints:
        hints = {
            name: p.annotation
            for name, p in parameters.items()
            if p.annotation is not inspect.Parameter.empty and not isinstance(p.annotation, str)
        }
    return parameters, hints, takes_kwargs


def fits(value: Any, hint: Any) -> bool | None:
    """Whether a plain config value (None, bool, int, float, str, list, dict) fits ``hint``:
    ``True``/``False``, or ``None`` when the annotation cannot be checked against config values."""
    if hint is Any or hint is inspect.Parameter.empty or isinstance(hint, typing.TypeVar | str):
        return None
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is typing.Union or isinstance(hint, types.UnionType):
        answers = [fits(value, member) for member in args]
        return True if True in answers else (False if all(a is False for a in answers) else None)
    if origin is typing.Literal:
        return value in args
    if origin is typing.Annotated:
        return fits(value, args[0])
    if hint is None or hint is type(None):
        return value is None
    if value is None:
        return False
    if origin is not None:
        return _fits_generic(value, origin, args)
    if inspect.isclass(hint):
        return _fits_class(value, hint)
    return None


# The config's own scalar types and the plain values that fit each: a bool is an int in Python,
# not in a config.
_SCALAR_FITS: tuple[tuple[type, Callable[[Any], bool]], ...] = (
    (bool, lambda value: isinstance(value, bool)),
    (int, lambda value: isinstance(value, int) and not isinstance(value, bool)),
    (float, lambda value: isinstance(value, int | float) and not isinstance(value, bool)),
    (complex, lambda value: isinstance(value, int | float | complex) and not isinstance(value, bool)),
    (str, lambda value: isinstance(value, str)),
)


def _fits_class(value: Any, hint: type) -> bool | None:
    """:func:`fits` for a plain class: a scalar type, a class a config value stands for (a path, an
    enum, a bare container), or one only code can make."""
    for scalar, check in _SCALAR_FITS:
        if hint is scalar:
            return check(value)
    if issubclass(hint, PurePath) or hint is os.PathLike:
        return isinstance(value, str)
    if issubclass(hint, enum.Enum):
        return value in hint.__members__ or any(value == member.value for member in hint)
    if isinstance(value, hint):
        return True
    if hint in (list, tuple, set, frozenset):
        return isinstance(value, list)
    if hint in (dict,):
        return isinstance(value, dict)
    # A class only code can make (Tensor, Accelerator, …): no plain value is one — but a
    # protocol or ABC such as Sequence or Callable may still be satisfied by one.
    if getattr(hint, "_is_protocol", False):
        return None
    if inspect.isabstract(hint) or hint.__module__ in ("collections.abc", "typing", "numbers"):
        return None
    return False


def _fits_generic(value: Any, origin: Any, args: tuple[Any, ...]) -> bool | None:
    if origin in (list, tuple, set, frozenset) or origin in (Sequence, typing.Sequence):
        if isinstance(value, str):
            return False if origin in (list, tuple, set, frozenset) else None
        if not isinstance(value, list):
            return False
        if origin is tuple and args:
            if len(args) == 2 and args[1] is Ellipsis:
                return _all_fit(value, args[0])
            if len(args) != len(value):
                return False
            answers = [fits(item, hint) for item, hint in zip(value, args, strict=True)]
            return False not in answers
        return _all_fit(value, args[0]) if args else True
    if origin in (dict, Mapping, typing.Mapping):
        if not isinstance(value, dict):
            return False
        if len(args) == 2:
            answers = [fits(item, args[1]) for item in value.values()]
            return False not in answers
        return True
    if origin in (Callable, typing.Callable) or origin is type:
        return False if isinstance(value, int | float | bool | list | dict) else None
    if inspect.isclass(origin):
        return fits(value, origin)
    return None


def _all_fit(values: list[Any], hint: Any) -> bool:
    return all(fits(item, hint) is not False for item in values)


def describe(hint: Any) -> str:
    """A short human form of an annotation: ``int | None``, ``tuple[float, float]``, ``'a' | 'b'``."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is typing.Union or isinstance(hint, types.UnionType):
        return " | ".join(describe(member) for member in args)
    if origin is typing.Literal:
        return " | ".join(repr(arg) for arg in args)
    if origin is typing.Annotated:
        return describe(args[0])
    if hint is None or hint is type(None):
        return "None"
    if origin is not None:
        name = getattr(origin, "__name__", str(origin))
        inner = ", ".join("..." if arg is Ellipsis else describe(arg) for arg in args)
        return f"{name}[{inner}]" if args else name
    return getattr(hint, "__name__", str(hint))


def _qualified(target: Any) -> str:
    return f"{getattr(target, '__module__', '?')}.{getattr(target, '__qualname__', target)}"
