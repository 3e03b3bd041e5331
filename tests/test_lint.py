"""The code stays ruff-clean and mypy-strict-clean: checked with the pinned tools."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool(name: str) -> str:
    path = Path(sys.executable).with_name(name)
    found = str(path) if path.exists() else shutil.which(name)
    if found is None:
        pytest.skip(f"{name} is not installed (pip install -e '.[dev]')")
    return found


def _run(*cmd: str) -> None:
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_ruff_check() -> None:
    _run(_tool("ruff"), "check", "wxsky", "tests", "tools", "plugins")


def test_ruff_format() -> None:
    _run(_tool("ruff"), "format", "--check", "wxsky", "tests", "tools", "plugins")


def test_mypy_strict() -> None:
    _run(_tool("mypy"), "wxsky", "plugins/reference-host/reference_host.py")
