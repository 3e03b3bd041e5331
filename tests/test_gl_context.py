"""The one GL context: llvmpipe's raster threads (`context.cpu_raster_threads`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any

import pytest

from wxsky.render import context

# A fresh process (llvmpipe reads its thread count once, when the driver starts): make the
# context, then name the renderer and count the driver's raster threads, which it names
# llvmpipe-0, llvmpipe-1, ... Each thread names itself once it first runs: on a busy machine
# some had not yet (the count came out short once), so the probe waits, until the count
# reaches the one expected (argv) or a time that only a hang exceeds.
_PROBE = """
import json, os, sys, time
from wxsky.render.context import create_context
ctx = create_context()
def count():
    names = []
    for t in os.listdir("/proc/self/task"):
        try:
            names.append(open(f"/proc/self/task/{t}/comm").read().strip())
        except OSError:
            pass
    return sum(n.startswith("llvmpipe-") for n in names)
deadline = time.monotonic() + 30.0
while count() < int(sys.argv[1]) and time.monotonic() < deadline:
    time.sleep(0.05)
print(json.dumps({
    "renderer": ctx.info["GL_RENDERER"],
    "threads": count(),
    "env": os.environ.get("LP_NUM_THREADS"),
}))
"""


def _probe(lp_num_threads: str | None, expected: int) -> dict[str, object]:
    env = {k: v for k, v in os.environ.items() if k != "LP_NUM_THREADS"}
    if lp_num_threads is not None:
        env["LP_NUM_THREADS"] = lp_num_threads
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, str(expected)],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    result: dict[str, object] = json.loads(out.stdout.strip().splitlines()[-1])
    if "llvmpipe" not in str(result["renderer"]):
        pytest.skip(f"the renderer here is {result['renderer']}, not llvmpipe")
    return result


@pytest.mark.gl
def test_llvmpipe_draws_with_twice_as_many_threads_as_cores() -> None:
    cores = len(os.sched_getaffinity(0))
    if cores < 2:
        pytest.skip("one core: llvmpipe keeps its own count")
    result = _probe(None, 2 * cores)
    assert result["env"] == str(2 * cores)
    assert result["threads"] == 2 * cores


@pytest.mark.gl
def test_a_users_thread_count_wins() -> None:
    result = _probe("3", 3)
    assert result["env"] == "3"
    assert result["threads"] == 3


def test_one_core_or_a_count_that_is_no_number_leaves_llvmpipe_its_own(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("LP_NUM_THREADS", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    assert context.cpu_raster_threads() is None
    assert "LP_NUM_THREADS" not in os.environ
    monkeypatch.setenv("LP_NUM_THREADS", "many")
    assert context.cpu_raster_threads() is None
    assert os.environ["LP_NUM_THREADS"] == "many"
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2})
    monkeypatch.delenv("LP_NUM_THREADS")
    assert context.cpu_raster_threads() == 6


@pytest.mark.gl
def test_releasing_the_bound_framebuffer_leaves_the_next_one_clean(renderer: Any) -> None:
    """moderngl binds its last-used framebuffer again after making a new one: released while
    bound, that name is gone and GL reports INVALID_OPERATION at the next framebuffer made
    on the context, far from the cause. `release_framebuffer` binds the default one first."""
    ctx = renderer.ctx  # the session's, made current again by the fixture
    made = []
    for _ in range(2):
        tex = ctx.texture((8, 8), 4)
        fbo = ctx.framebuffer(color_attachments=[tex])
        fbo.use()
        fbo.clear(0.5, 0.5, 0.5, 1.0)
        context.release_framebuffer(fbo)
        made.append(tex)
        assert ctx.error == "GL_NO_ERROR"
    for tex in made:
        tex.release()
