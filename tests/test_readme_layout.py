"""The README stays a front door that tells the truth: short, its ``docs/`` links resolve, every
page of ``docs/`` is linked from it, and its Layout section names what the tree holds.

The Layout block is a tree: an entry line is indented by two spaces per level and starts with one
name or several separated by ``", "`` (a folder ends with ``/``), then two or more spaces and its
description; a line indented by :data:`CONTINUATION_INDENT` spaces or more continues the
description above. The rules checked:

- every path the Layout names exists;
- it names every top-level folder tracked by git, every file of ``scripts/``, every module and
  folder directly under ``src/brdfgan/``, and — in every folder whose modules it lists (it names
  one file there) — every module and subfolder of that folder.

Pure file reading (and ``git ls-files``): no torch import.
"""

from __future__ import annotations

import re
import subprocess
from functools import cache
from pathlib import Path, PurePosixPath

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PACKAGE = PurePosixPath("src/brdfgan")
MAX_LINES = 300
CONTINUATION_INDENT = 20
_NAME = re.compile(r"^[A-Za-z0-9_.\-/]+$")
_LINK = re.compile(r"\]\(((?:docs/)?[^)\s#]*)(#[^)\s]*)?\)")


def _section(text: str, title: str) -> str:
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert match, f"README has no '## {title}' section"
    return match.group(1)


def layout_paths(text: str) -> set[PurePosixPath]:
    """Every path named by the Layout block of README text ``text`` (folders without the slash; a
    path with a slash names its parent folders too)."""
    block = re.search(r"^```\n(.*?)^```", _section(text, "Layout"), re.S | re.M)
    assert block, "the Layout section has no code block"
    parents: list[PurePosixPath] = []  # parents[level]: the folder entries at that level open
    named: set[PurePosixPath] = set()
    for line in block.group(1).splitlines():
        indent = len(line) - len(line.lstrip(" "))
        if not line.strip() or indent >= CONTINUATION_INDENT:
            continue
        assert indent % 2 == 0, f"Layout line indented by an odd number of spaces: {line!r}"
        level = indent // 2
        assert level <= len(parents), f"Layout line indented deeper than its parent allows: {line!r}"
        del parents[level:]
        names = re.split(r"\s{2,}", line.strip(), maxsplit=1)[0].split(", ")
        base = parents[level - 1] if level else PurePosixPath()
        for name in names:
            assert _NAME.match(name), f"not a path in the Layout: {name!r} (line {line!r})"
            path = base / name.rstrip("/")
            named |= {path, *path.parents[:-1]}  # src/brdfgan/ names src/ too
        folder = names[-1]
        if folder.endswith("/"):
            parents.append(base / folder.rstrip("/"))
        else:  # a file line: deeper lines would have no folder to belong to
            parents.append(base / "__file_entry__")
    return named


@cache
def tracked_files() -> tuple[PurePosixPath, ...]:
    try:
        listing = subprocess.run(
            ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, timeout=60
        ).stdout
    except (OSError, subprocess.SubprocessError):
        pytest.skip("not a git checkout: the tracked tree is unknown")
    return tuple(PurePosixPath(p) for p in listing.decode().split("\0") if p)


def _children(folder: PurePosixPath) -> set[PurePosixPath]:
    """Tracked modules (``.py`` but ``__init__.py``) and subfolders directly in ``folder``."""
    found: set[PurePosixPath] = set()
    for path in tracked_files():
        if folder not in path.parents:
            continue
        relative = path.relative_to(folder)
        if len(relative.parts) > 1:
            found.add(folder / relative.parts[0])
        elif path.suffix == ".py" and path.name != "__init__.py":
            found.add(path)
    return found


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(markdown: Path) -> set[str]:
    return {_slug(h) for h in re.findall(r"^#{1,6} (.+)$", markdown.read_text(), re.M)}


def test_readme_is_short() -> None:
    lines = README.read_text().count("\n")
    assert lines <= MAX_LINES, f"README.md has {lines} lines; the front door stays ≤ {MAX_LINES}"


def test_readme_links_resolve() -> None:
    text = README.read_text()
    links = _LINK.findall(text)
    assert any(target.startswith("docs/") for target, _ in links)
    for target, anchor in links:
        if target.startswith(("http:", "https:", "mailto:")):
            continue
        path = ROOT / target if target else README
        assert path.exists(), f"README links to {target}, which does not exist"
        if anchor and path.suffix == ".md":
            assert anchor[1:] in _anchors(path), f"README links to {target}{anchor}: no such heading"


def test_every_docs_page_is_linked() -> None:
    linked = {target for target, _ in _LINK.findall(README.read_text())}
    pages = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md"))
    assert pages
    assert [p for p in pages if p not in linked] == []


def test_layout_names_only_what_exists() -> None:
    missing = sorted(str(p) for p in layout_paths(README.read_text()) if not (ROOT / p).exists())
    assert missing == [], f"the README's Layout names paths that do not exist: {missing}"


def test_layout_names_the_tree() -> None:
    named = layout_paths(README.read_text())
    files = tracked_files()
    required = {PurePosixPath(p.parts[0]) for p in files if len(p.parts) > 1}  # top-level folders
    required |= {p for p in files if p.parent == PurePosixPath("scripts") and p.name != "__init__.py"}
    required |= _children(PACKAGE)
    listed_folders = {p.parent for p in named if p.suffix and PACKAGE in p.parents}
    for folder in listed_folders:
        required |= _children(folder)
    missing = sorted(str(p) for p in required - named)
    assert missing == [], f"the README's Layout does not name: {missing}"


def test_layout_parser() -> None:
    text = (
        "## Layout\n\n```\n"
        "src/brdfgan/\n"
        "  core/                  maths\n"
        "    a.py, b.py           two modules\n"
        "                         a continued description\n"
        "  cli.py                 the console\n"
        "scripts/\n"
        "  x.sh                   a script\n"
        "```\n\n## Next\n"
    )
    assert layout_paths(text) == {
        PurePosixPath(p)
        for p in (
            "src",
            "src/brdfgan",
            "src/brdfgan/core",
            "src/brdfgan/core/a.py",
            "src/brdfgan/core/b.py",
            "src/brdfgan/cli.py",
            "scripts",
            "scripts/x.sh",
        )
    }
