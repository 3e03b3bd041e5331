"""Builds the OpenSceneGraph kit (plugins/osg) once per test session, plain and under
AddressSanitizer + UndefinedBehaviorSanitizer, for the tests that run its programs; skips them
where OpenSceneGraph is not installed."""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
KIT = ROOT / "plugins" / "osg"
TOOL = "wxsky-osg-snapshot"


def _build(sanitize: bool) -> Path:
    if shutil.which("make") is None or shutil.which(os.environ.get("CXX", "g++")) is None:
        pytest.skip("no C++ compiler or make (tools/setup installs them on Debian)")
    probe = subprocess.run(
        ["pkg-config", "--exists", "openscenegraph", "egl", "gl", "zlib"], capture_output=True
    )
    if probe.returncode != 0:
        pytest.skip(
            "pkg-config finds no openscenegraph (Debian: libopenscenegraph-dev, which "
            "tools/setup installs)"
        )
    args = ["make", "-s", "-C", str(KIT), f"-j{os.cpu_count() or 2}"]
    if sanitize:
        args.append("SANITIZE=1")
    (KIT / "build").mkdir(exist_ok=True)
    with open(KIT / "build" / ".lock", "w") as lock:  # one make at a time across workers
        fcntl.flock(lock, fcntl.LOCK_EX)
        proc = subprocess.run(args, capture_output=True, text=True, timeout=900)
    # -Werror: a warning fails the build, so a clean exit is a warning-free build
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = KIT / "build" / ("sanitize" if sanitize else "")
    for name in ("osgdb_wxsky.so", "libosgwxsky.so", "libosgwxsky.a", TOOL):
        assert (out / name).exists(), f"make built no {name}"
    return out


@pytest.fixture(scope="session")
def osg_kit() -> Path:
    """The build folder of the plain build."""
    return _build(sanitize=False)


@pytest.fixture(scope="session")
def osg_kit_sanitized() -> Path:
    """The build folder of the sanitizer build."""
    return _build(sanitize=True)
