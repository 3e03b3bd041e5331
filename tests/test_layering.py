"""The import rules of docs/ARCHITECTURE.md: pure packages stay pure, and each third-party
I/O library has exactly one home."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "wxsky"

# Third-party packages and the only modules (or package folders) allowed to import them.
HOMES = {
    "moderngl": ("render/",),
    "msgpack": ("output/wire.py",),
    "serial": ("inputs/serial_link.py",),
    "can": ("inputs/can_link.py",),
}
# Pure packages: stdlib, numpy and these wxsky packages only.
PURE = {
    "weather/": ("wxsky.weather", "wxsky.units", "wxsky.errors"),
    "scene/": ("wxsky.scene", "wxsky.weather", "wxsky.units", "wxsky.errors"),
    "protocols/": ("wxsky.protocols", "wxsky.weather", "wxsky.units", "wxsky.errors"),
}


def imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
    return names


MODULES = sorted(PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_third_party_io_libraries_have_one_home(path: Path) -> None:
    rel = path.relative_to(PACKAGE).as_posix()
    for name in imports(path):
        top = name.split(".")[0]
        if top in HOMES:
            assert rel.startswith(HOMES[top]), f"{rel} imports {name}; only {HOMES[top]} may"


@pytest.mark.parametrize(
    "path",
    [p for p in MODULES if p.relative_to(PACKAGE).as_posix().startswith(tuple(PURE))],
    ids=lambda p: str(p.relative_to(PACKAGE)),
)
def test_pure_packages_import_only_stdlib_numpy_and_their_allies(path: Path) -> None:
    rel = path.relative_to(PACKAGE).as_posix()
    allowed = next(v for k, v in PURE.items() if rel.startswith(k))
    for name in imports(path):
        top = name.split(".")[0]
        if top == "wxsky":
            assert name.startswith(allowed), f"{rel} imports {name}"
        elif top != "numpy" and top != "__future__":
            assert top in sys.stdlib_module_names, f"{rel} imports {name}, not stdlib"


def test_the_rules_see_real_imports() -> None:
    # Guards the test itself: it must find the homes it protects.
    assert "moderngl" in imports(PACKAGE / "render" / "context.py")
    assert "can" in imports(PACKAGE / "inputs" / "can_link.py")
    assert "serial" in imports(PACKAGE / "inputs" / "serial_link.py")
