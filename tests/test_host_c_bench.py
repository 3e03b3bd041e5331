"""The C host kit's benchmark program (plugins/host-c/tests/wxsky_gl_bench.c, driven by
tools/bench/bench_host_c.py) against a real daemon: a short run reports every stage and the
set_camera latency with sane numbers, and the latency's frame had the camera it sent. No
timing is asserted."""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import running_daemon
from host_kit import gl_program, gl_sanitizer_env, host_kit, host_kit_sanitized  # noqa: F401

pytestmark = pytest.mark.gl

STAGES = (
    "read",
    "upload_plain",
    "composite_plain",
    "upload_pbo",
    "composite_pbo",
    "host_plain",
    "host_pbo",
    "upload_rings_plain",
    "background_plain",
)
PROGRAM = "wxsky_gl_bench"  # OpenGL 3.3 core
PROGRAM_GLES = "wxsky_gles_bench"  # the same on OpenGL ES 3.0
ARGS = ("--frames", "3", "--warmup", "1", "--latency", "3")
SMALL = "[camera]\nwidth = 320\nheight = 180\n"


def run_bench(
    folder: Path, tmp_path: Path, env: dict[str, str] | None = None, exe_name: str = PROGRAM
) -> dict[str, Any]:
    exe = gl_program(folder, exe_name)
    with running_daemon(tmp_path, extra_config=SMALL) as d:
        proc = subprocess.run(
            [str(exe), d.shm_name, *ARGS, "--control", d.address],
            capture_output=True,
            text=True,
            timeout=180,
            env=env,
        )
    if proc.returncode == 2:
        pytest.skip(f"no headless EGL context: {proc.stdout.strip()}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    result: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def check(result: dict[str, Any], frames: int, rounds: int) -> None:
    assert (result["width"], result["height"]) == (320, 180)
    assert result["frames"] == frames
    assert result["renderer"]
    assert set(result["stages"]) == set(STAGES)
    for name, figures in [
        *result["stages"].items(),
        ("latency", result["latency"]),
        ("latency_wait", result["latency_wait"]),
    ]:
        assert figures["n"] == (rounds if name.startswith("latency") else frames), name
        for key in ("median_ms", "p95_ms", "mean_ms", "max_ms"):
            value = figures[key]
            assert math.isfinite(value) and value > 0.0, (name, key, value)
        assert figures["median_ms"] <= figures["p95_ms"] <= figures["max_ms"], name
    assert result["latency_camera_matched"] is True
    # the frame composited for the camera came after the send: at least one published since
    assert result["latency_frames_waited_mean"] >= 1.0
    assert result["latency_wait"]["median_ms"] <= result["latency"]["median_ms"]


@pytest.mark.parametrize("exe_name", [PROGRAM, PROGRAM_GLES], ids=["gl", "gles"])
def test_the_benchmark_reports_every_stage_and_the_camera_latency(
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
    exe_name: str,
) -> None:
    check(run_bench(host_kit, tmp_path, exe_name=exe_name), frames=3, rounds=3)


def test_the_benchmark_runs_clean_under_the_sanitizers(
    host_kit_sanitized: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    env = gl_sanitizer_env()
    check(run_bench(host_kit_sanitized, tmp_path, env=env), frames=3, rounds=3)
