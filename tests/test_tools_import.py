"""Every script in tools/ imports: a rename in the package breaks a tool here, not the day
someone next runs it (tools/build_gallery.py imported a name the sky module had given up)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

TOOLS = Path(__file__).resolve().parents[1] / "tools"
SCRIPTS = sorted(p.stem for p in TOOLS.glob("*.py"))

# One process for all of them (a tool's imports are most of its cost, and they share them),
# apart from the tests' own: tools set sys.path and import optional packages. As
# `python tools/NAME.py` runs a tool, its own folder is first on the path.
_IMPORT_ALL = """
import json, sys, traceback
sys.path[:0] = ['tools', 'tests']
sys.argv = ['tool']
from tool_loader import load_tool
failed = {}
for name in json.loads(sys.argv_names):
    try:
        load_tool(name)
    except BaseException as exc:  # a tool's SystemExit at import is a failure too
        failed[name] = traceback.format_exception_only(type(exc), exc)[-1].strip()
print(json.dumps(failed))
"""


def test_there_are_tools() -> None:
    assert "regen_goldens" in SCRIPTS and "bench_presets" in SCRIPTS


def test_every_tool_imports() -> None:
    code = f"import sys; sys.argv_names = {json.dumps(json.dumps(SCRIPTS))}\n" + _IMPORT_ALL
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=TOOLS.parent, check=True
    )
    failed = json.loads(done.stdout.strip().splitlines()[-1])
    assert failed == {}
