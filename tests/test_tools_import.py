"""Every tool in tools/ starts as a user starts it, sits in a folder by its purpose and has its
line in tools/README.md: a rename in the package or a move breaks a tool here, not the day
someone next runs it (tools/gallery/build_gallery.py imported a name the sky module had given
up)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOOLS = ROOT / "tools"
# tools/README.md has a section for each; a new tool goes in one of these (or a new folder here
# and there).
FOLDERS = ("bench", "emulators", "fuzz", "gallery", "generate", "soak")
SCRIPTS = sorted(
    p.relative_to(TOOLS).as_posix() for p in TOOLS.rglob("*.py") if p.name != "__init__.py"
)


def _is_command(rel: str) -> bool:
    """A tool run as a script; the rest are its siblings' libraries."""
    return 'if __name__ == "__main__":' in (TOOLS / rel).read_text()


# One process for all of them (a tool's imports are most of its cost, and they share them).
# Each command runs as `python tools/FOLDER/NAME.py --help` would: its own folder first on the
# path and the checkout's root not on it (a tool must put it there itself to import its
# siblings as `tools.*`), no `tools` module loaded yet; wxsky is the checkout's, loaded once.
# Each library is imported by the name its siblings use.
_START_ALL = """
import contextlib, importlib, io, json, os, runpy, sys, traceback
root = os.path.realpath(os.getcwd())
import wxsky
base = [p for p in sys.path if p and os.path.realpath(p) != root]
failed = {}
for rel, command in json.loads(sys.argv[1]):
    for name in [m for m in sys.modules if m == "tools" or m.startswith("tools.")]:
        del sys.modules[name]
    path = os.path.join(root, "tools", rel)
    out = io.StringIO()
    try:
        if command:
            sys.path[:] = [os.path.dirname(path), *base]
            sys.argv = [path, "--help"]
            code = "no exit"
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
                try:
                    runpy.run_path(path, run_name="__main__")
                except SystemExit as exc:
                    code = exc.code
            if code not in (0, None) or "usage:" not in out.getvalue():
                failed[rel] = f"--help: exit {code!r}: {out.getvalue()[-400:]}"
        else:
            sys.path[:] = [root, *base]
            importlib.import_module("tools." + rel[:-3].replace("/", "."))
    except BaseException as exc:  # a tool's SystemExit at import is a failure too
        failed[rel] = traceback.format_exception_only(type(exc), exc)[-1].strip()
print(json.dumps(failed))
"""


def test_there_are_tools() -> None:
    assert "generate/regen_goldens.py" in SCRIPTS and "bench/bench_presets.py" in SCRIPTS
    assert "emulators/cockpit_daemon.py" in SCRIPTS and not _is_command(
        "emulators/cockpit_daemon.py"
    )


def test_every_tool_is_in_a_folder_by_purpose() -> None:
    misplaced = [rel for rel in SCRIPTS if rel.split("/")[0] not in FOLDERS or rel.count("/") != 1]
    assert misplaced == [], "put each tool in one of tools/{" + ",".join(FOLDERS) + "}/"
    # A package each, so that tools import each other as `tools.FOLDER.NAME`.
    for folder in ("", *FOLDERS):
        assert (TOOLS / folder / "__init__.py").is_file(), folder
    # Tests load tools by folder and name; a name in two folders would read as the wrong one.
    names = [rel.split("/")[1] for rel in SCRIPTS]
    assert sorted(set(names)) == sorted(names)


def test_the_readme_has_one_line_for_each_tool() -> None:
    readme = (TOOLS / "README.md").read_text()
    # A tool's line is a list item that starts with its path (and, for a command, how to run it).
    listed = re.findall(r"^- `tools/([a-z_]+/[a-z_0-9]+\.py)", readme, flags=re.MULTILINE)
    missing = sorted(set(SCRIPTS) - set(listed))
    assert missing == [], "tools/README.md has no line for these tools"
    assert sorted(set(listed) - set(SCRIPTS)) == [], "tools/README.md lists tools that are gone"
    assert len(listed) == len(set(listed)), "tools/README.md lists a tool twice"
    assert "- `tools/setup`" in readme


def test_every_tool_starts() -> None:
    todo = [(rel, _is_command(rel)) for rel in SCRIPTS]
    assert sum(command for _, command in todo) >= 40  # most tools are commands
    done = subprocess.run(
        [sys.executable, "-c", _START_ALL, json.dumps(todo)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
        check=True,
    )
    failed = json.loads(done.stdout.strip().splitlines()[-1])
    assert failed == {}
