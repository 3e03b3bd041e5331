"""Builds the C host kit (plugins/host-c) once per test session, plain and under
AddressSanitizer + UndefinedBehaviorSanitizer, for the tests that run its programs."""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
KIT = ROOT / "plugins" / "host-c"


def _build(sanitize: bool) -> Path:
    if shutil.which(os.environ.get("CC", "cc")) is None or shutil.which("make") is None:
        pytest.skip("no C compiler or make (tools/setup installs them on Debian)")
    args = ["make", "-s", "-C", str(KIT), f"-j{os.cpu_count() or 2}"]
    if sanitize:
        args.append("SANITIZE=1")
    # Each pytest-xdist worker asks for the build: one make at a time in the kit's folder (the
    # others then find it made), never two writing the same objects and programs at once.
    (KIT / "build").mkdir(exist_ok=True)
    with open(KIT / "build" / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        proc = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return KIT / "build" / ("sanitize" if sanitize else "")


@pytest.fixture(scope="session")
def host_kit() -> Path:
    """The build folder of the plain build."""
    return _build(sanitize=False)


@pytest.fixture(scope="session")
def host_kit_sanitized() -> Path:
    """The build folder of the sanitizer build (its programs abort on the first finding)."""
    return _build(sanitize=True)


def sanitizer_env() -> dict[str, str]:
    """The environment for a sanitized program: any finding is a failure, leaks included."""
    return {
        **os.environ,
        "ASAN_OPTIONS": "abort_on_error=0:halt_on_error=1:detect_leaks=1:exitcode=99",
        "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1:exitcode=98",
    }


def gl_sanitizer_env() -> dict[str, str]:
    """The sanitizer environment for a program that makes a GL context: Mesa's llvmpipe keeps
    allocations for the life of the process (its shader cache and screen), which
    LeakSanitizer reports at exit from its unloaded driver, so no suppression can name them.
    Leaks are not checked for these programs; every other finding still fails them."""
    env = sanitizer_env()
    env["ASAN_OPTIONS"] = env["ASAN_OPTIONS"].replace("detect_leaks=1", "detect_leaks=0")
    return env


def gl_program(folder: Path, name: str) -> Path:
    """A GL test program of a build; skips when the Makefile did not build it (no EGL/GL, or
    no GLES for the `wxsky_gles_*` ones, found by pkg-config)."""
    path = folder / name
    if not path.exists():
        what = "glesv2" if name.startswith("wxsky_gles_") else "egl and gl"
        pytest.skip(f"{name} was not built (pkg-config finds no {what})")
    return path
