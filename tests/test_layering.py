"""The import rules are the room table of docs/ARCHITECTURE.md: this test reads the table and
checks every module of the package against it, so the doc and the rule cannot drift apart."""

from __future__ import annotations

import ast
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "wxsky"
DOC = ROOT / "docs" / "ARCHITECTURE.md"
HEADING = "## Rooms and what each may import"
MAX_ROOT_MODULES = 6


@dataclass(frozen=True)
class Row:
    paths: tuple[str, ...]  # relative to wxsky/: "weather/" (a room) or "output/wire.py"
    allowed: frozenset[str]  # rooms, third-party packages, or "*"


def read_table(text: str) -> list[Row]:
    section = text.split(HEADING, 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or not cells[0].startswith("`wxsky/"):
            continue
        paths = tuple(p.removeprefix("wxsky/") for p in re.findall(r"`([^`]+)`", cells[0]))
        rows.append(Row(paths, frozenset(re.findall(r"`([^`]+)`", cells[2]))))
    return rows


ROWS = read_table(DOC.read_text(encoding="utf-8"))
ROOMS = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
MODULES = sorted(PACKAGE.rglob("*.py"))


def room_of(module: str) -> str:
    """`wxsky.weather.state` -> "weather"; `wxsky.errors` -> "errors"; `wxsky` -> "wxsky"."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "wxsky"


def rule_for(rel: str) -> frozenset[str] | None:
    """What a module (path relative to wxsky/) may import: its folder's row, plus its own."""
    folder = rel.split("/")[0] + "/" if "/" in rel else None
    allowed: set[str] = set()
    found = False
    for row in ROWS:
        if rel in row.paths or (folder is not None and folder in row.paths):
            allowed |= row.allowed
            found = True
    return frozenset(allowed) if found else None


def imports(path: Path) -> list[str]:
    """Every absolute import, at module level or inside functions (lazy ones count too)."""
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
    return names


def violations(rel: str, names: list[str]) -> list[str]:
    allowed = rule_for(rel)
    assert allowed is not None, f"wxsky/{rel} is under no row of the table in {DOC.name}"
    own = rel.split("/")[0] if "/" in rel else rel.removesuffix(".py")
    bad = []
    for name in names:
        top = name.split(".")[0]
        if top == "__future__" or top in sys.stdlib_module_names:
            continue
        if top == "wxsky":
            room = room_of(name)
            if room in (own, "wxsky") or "*" in allowed or room in allowed:
                continue
            bad.append(f"wxsky/{rel} imports {name}: room {room!r} is not in its row")
        elif top not in allowed:
            bad.append(f"wxsky/{rel} imports {name}: {top!r} is not in its row")
    return bad


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_every_module_keeps_to_its_row(path: Path) -> None:
    rel = path.relative_to(PACKAGE).as_posix()
    assert violations(rel, imports(path)) == []


def test_the_table_names_every_room_and_only_real_paths() -> None:
    named = {p for row in ROWS for p in row.paths}
    assert {f"{room}/" for room in ROOMS} <= named
    for p in named:
        assert (PACKAGE / p).exists(), f"the table names wxsky/{p}, which does not exist"
    for row in ROWS:
        rooms = {a for a in row.allowed if a in ROOMS or (PACKAGE / f"{a}.py").exists()}
        third = row.allowed - rooms - {"*"}
        for name in third:
            assert name not in sys.stdlib_module_names, f"{row.paths}: {name} is stdlib"


def test_the_package_root_holds_only_leaves() -> None:
    root_modules = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(root_modules) <= MAX_ROOT_MODULES, root_modules


def test_the_rules_catch_a_violation() -> None:
    # Guards the test itself: a pure room importing the renderer, a second msgpack user, and
    # the real homes of the I/O libraries.
    assert violations("scene/x.py", ["wxsky.render.renderer"])
    assert violations("weather/x.py", ["moderngl"])
    assert violations("output/shm.py", ["msgpack"])
    assert violations("inputs/serial_link.py", ["can"])
    assert not violations("output/wire.py", ["msgpack", "wxsky.scene.camera"])
    assert not violations("cli/x.py", ["wxsky.app.daemon", "wxsky.render.context"])
    assert "moderngl" in imports(PACKAGE / "render" / "context.py")
    assert "can" in imports(PACKAGE / "inputs" / "can_link.py")
    assert "serial" in imports(PACKAGE / "inputs" / "serial_link.py")
