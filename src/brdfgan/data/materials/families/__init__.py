"""The registry of material families: name → :class:`~brdfgan.data.materials.base.MaterialFamily`.

Each module in this package exports one ``FAMILY``; the registry is the single list the data
generator, configs and tests draw from.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType

from brdfgan.data.materials.base import MaterialFamily
from brdfgan.data.materials.families import (
    bricks,
    brushed_metal,
    concrete,
    ground,
    leather,
    marble,
    rusted_metal,
    stone,
    tiles,
    wood,
)
from brdfgan.errors import UserError

FAMILIES: Mapping[str, MaterialFamily] = MappingProxyType(
    {
        module.FAMILY.name: module.FAMILY
        for module in (
            wood,
            tiles,
            bricks,
            stone,
            marble,
            brushed_metal,
            rusted_metal,
            leather,
            concrete,
            ground,
        )
    }
)


class UnknownFamilyError(UserError):
    """A configured family name is not in the registry."""


def get_family(name: str) -> MaterialFamily:
    """The family registered under ``name``; a one-line error listing the known names otherwise."""
    try:
        return FAMILIES[name]
    except KeyError:
        raise UnknownFamilyError(
            f"unknown material family {name!r}; known: {', '.join(sorted(FAMILIES))}"
        ) from None


def resolve_families(names: Sequence[str] | None) -> tuple[MaterialFamily, ...]:
    """The families to draw from: all registered ones for ``None``/empty, else the named ones
    in the given order (duplicates rejected, so a typo cannot silently reweight the mix)."""
    if not names:
        return tuple(FAMILIES.values())
    duplicates = sorted({n for n in names if list(names).count(n) > 1})
    if duplicates:
        raise UnknownFamilyError(f"material family listed twice: {', '.join(duplicates)}")
    return tuple(get_family(n) for n in names)
