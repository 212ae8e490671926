"""The registry of material families: name → :class:`~brdfgan.data.materials.base.MaterialFamily`.

Each module in this package exports one ``FAMILY``; the registry is the single list the data
generator, configs and tests draw from. Its order is the round-robin order of a dataset's
materials (material ``i`` is family ``i mod len``), so new families go at the end.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType

from brdfgan.data.materials.base import MaterialFamily
from brdfgan.data.materials.families import (
    anodized_metal,
    asphalt,
    bricks,
    brushed_metal,
    concrete,
    fabric,
    ground,
    leather,
    leaves,
    marble,
    metallic_paint,
    mosaic,
    painted_wood,
    paper,
    pavers,
    plaster,
    plastic,
    polished_metal,
    relief_tiles,
    rusted_metal,
    stone,
    terrazzo,
    tiles,
    tread_plate,
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
            # Added for coverage of real surfaces (issue 15); each module says which gap it fills.
            polished_metal,
            metallic_paint,
            anodized_metal,
            tread_plate,
            mosaic,
            relief_tiles,
            painted_wood,
            plastic,
            fabric,
            paper,
            plaster,
            terrazzo,
            pavers,
            asphalt,
            leaves,
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
