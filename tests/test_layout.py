"""The package layout keeps its promises: pure maths stays pure, the renderer bridge does not
depend on the data pipeline, commands live in one console (issue: one home per concept), and the
product never depends on the lab (``research/``, issue 58)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "brdfgan"


def _imports(path: Path, root: Path = PACKAGE.parent) -> set[str]:
    """Every module a file imports (absolute names; relative imports resolved against its package
    under ``root``), lazily or not."""
    package = ".".join(path.relative_to(root).with_suffix("").parts[:-1])
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                found.add(f"{base}.{node.module}" if node.module else base)
            elif node.module:
                found.add(node.module)
    return found


def _files(subpackage: str) -> list[Path]:
    return sorted((PACKAGE / subpackage).rglob("*.py"))


@pytest.mark.parametrize(
    ("subpackage", "forbidden"),
    [
        ("mitsuba_render", ("brdfgan.data",)),
        ("core", ("lightning", "hydra", "omegaconf", "mitsuba", "brdfgan.data", "brdfgan.inference")),
        ("models", ("lightning", "hydra", "omegaconf", "brdfgan.data", "brdfgan.training")),
    ],
)
def test_imports_stay_inside_their_layer(subpackage: str, forbidden: tuple[str, ...]) -> None:
    offending = [
        f"{path.relative_to(PACKAGE)} imports {name}"
        for path in _files(subpackage)
        for name in sorted(_imports(path))
        if any(name == prefix or name.startswith(prefix + ".") for prefix in forbidden)
    ]
    assert not offending, "; ".join(offending)


@pytest.mark.parametrize("subpackage", ["models", "data", "inference"])
def test_no_command_line_modules_outside_the_console(subpackage: str) -> None:
    mains = [str(p.relative_to(PACKAGE)) for p in _files(subpackage) if "__main__" in p.read_text()]
    assert not mains, f"run these through `brdfgan <command>` instead: {mains}"


# The rooms of data/, bottom to top: a module may import its own room and the levels below it,
# never a room above it nor a sibling on its own level (materials and phone stay independent).
DATA_LAYERS: tuple[tuple[str, ...], ...] = (
    ("storage",),  # the shard format and the spec checks
    ("materials", "phone"),  # what is photographed, and the simulated phone that photographs it
    ("spec",),  # a dataset's spec, its splits, each material's maps, the seeds
    ("loading",),  # what training and evaluation read
    ("generation",),  # writing a dataset
    ("tools",),  # statistics, contact sheets, converters over written datasets
)
DATA_ROOMS = {room for level in DATA_LAYERS for room in level}
# Per-command roles, one per command package (training/, evaluation/, inference/…), named alike on
# purpose; every other module name is unique in the package.
ROLE_NAMES = {"__init__.py", "config.py", "run.py", "pipeline.py"}


def test_data_modules_live_in_a_room_by_concern() -> None:
    data = PACKAGE / "data"
    loose = sorted(p.name for p in data.glob("*.py") if p.name != "__init__.py")
    assert not loose, f"data/ modules belong in one of {sorted(DATA_ROOMS)}: {loose}"
    rooms = {p.name for p in data.iterdir() if p.is_dir() and p.name != "__pycache__"}
    assert rooms == DATA_ROOMS
    for room in rooms:
        assert (data / room / "__init__.py").read_text().startswith('"""'), f"data/{room} says what it holds"


def _data_room(name: str) -> str | None:
    """The data/ room of a dotted module name (``brdfgan.data.<room>…``), or None outside data/."""
    parts = name.split(".")
    return parts[2] if len(parts) > 2 and parts[:2] == ["brdfgan", "data"] else None


def data_imports_up(package: Path = PACKAGE) -> list[str]:
    """Every import of a data/ module that runs up the layers (or across to a sibling room)."""
    level = {room: depth for depth, rooms in enumerate(DATA_LAYERS) for room in rooms}
    offending = []
    for path in sorted((package / "data").rglob("*.py")):
        own = path.relative_to(package / "data").parts[0]
        if own not in level:
            continue  # data/__init__.py
        for name in sorted(_imports(path, package.parent)):
            room = _data_room(name)
            if room is None or room == own:
                continue
            if room not in level or level[room] >= level[own]:
                offending.append(f"data/{path.relative_to(package / 'data')} ({own}) imports {name}")
    return offending


def test_data_rooms_import_only_down() -> None:
    """The shard format and the spec checks are the bottom of data/, writing a dataset is near its
    top (only the tools over written datasets sit above): no import, lazy or not, runs up."""
    assert not data_imports_up(), "; ".join(data_imports_up())


def test_module_names_do_not_collide() -> None:
    seen: dict[str, list[str]] = {}
    for path in PACKAGE.rglob("*.py"):
        if path.name not in ROLE_NAMES:
            seen.setdefault(path.name, []).append(str(path.relative_to(PACKAGE)))
    collisions = {name: paths for name, paths in seen.items() if len(paths) > 1}
    assert not collisions, collisions


RESEARCH = "research"
# A Hydra target in a config: `_target_: research.x.Y` (the product's configs instantiate only brdfgan).
_RESEARCH_TARGET = re.compile(r"_target_\s*[:=]\s*['\"]?research\.", re.M)


def _research_imports(files: list[Path], root: Path) -> list[str]:
    return [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in files
        for name in sorted(_imports(path, root))
        if name == RESEARCH or name.startswith(RESEARCH + ".")
    ]


def test_the_product_never_imports_research() -> None:
    """``research/`` (the lab's one-offs, the modules only they use, their tests) may import the
    package; nothing the product ships or runs imports research: the package, its configs and the
    product's scripts (installers, figures, the shipped model's reproduction)."""
    assert (ROOT / RESEARCH / "__init__.py").is_file()
    offending = _research_imports(sorted(PACKAGE.rglob("*.py")), PACKAGE.parent)
    offending += _research_imports(sorted((ROOT / "scripts").rglob("*.py")), ROOT)
    offending += [
        f"{path.relative_to(ROOT)} targets research"
        for path in sorted((ROOT / "conf").rglob("*.yaml"))
        if _RESEARCH_TARGET.search(path.read_text())
    ]
    assert not offending, "; ".join(offending)
