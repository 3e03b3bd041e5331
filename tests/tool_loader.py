"""Load a tool from tools/ as a module, for tests of the tools themselves."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]
TOOLS = ROOT / "tools"


def load_tool(path: str) -> ModuleType:
    """tools/<path>.py, e.g. "emulators/cigi_host", imported as `tools.emulators.cigi_host`:
    the name the tools import each other by, so a test and the tool it loads share one copy of
    every sibling module."""
    if not (TOOLS / f"{path}.py").is_file():
        raise FileNotFoundError(f"no tool tools/{path}.py")
    if str(ROOT) not in sys.path:  # pytest puts tests/ on the path, not the checkout's root
        sys.path.append(str(ROOT))
    return importlib.import_module("tools." + path.replace("/", "."))
