"""The one place a GL context is created: headless, through EGL.

EGL runs on Mesa's llvmpipe on CPU-only machines and on NVIDIA's driver on GPU machines, so
the same code path renders in CI and on a workstation.
"""

from __future__ import annotations

import ctypes
import logging
import os
from collections.abc import Callable

import moderngl

from wxsky.errors import RenderError

log = logging.getLogger(__name__)

GL_VERSION = 330
# llvmpipe rasterises with one thread per core, and a frame waits for the last of them: on
# cores the daemon shares (its own threads, its ring worker, a simulator), a thread kept off
# its core for a moment holds the whole frame. With twice as many threads as cores the tiles
# are shared out finer. The same frame drawn 300 times on 2 cores: p95 1.25-1.56 times the
# median with 2 threads, 1.08-1.47 with 4, the median the same (docs/performance.md).
RASTER_THREADS_PER_CORE = 2


def cpu_raster_threads() -> int | None:
    """Set llvmpipe's thread count (LP_NUM_THREADS) for this process, unless the user has:
    read once, when the driver starts, so before the first context. Returns the count now in
    force, None where llvmpipe keeps its own (a single core, or no count set). Other drivers
    ignore it."""
    if "LP_NUM_THREADS" not in os.environ:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
        if cores < 2:
            return None
        os.environ["LP_NUM_THREADS"] = str(cores * RASTER_THREADS_PER_CORE)
    try:
        return int(os.environ["LP_NUM_THREADS"])
    except ValueError:
        return None


def create_context() -> moderngl.Context:
    """A standalone OpenGL 3.3+ core context with no window. Raises RenderError saying why not."""
    threads = cpu_raster_threads()
    try:
        ctx = moderngl.create_context(
            standalone=True,
            require=GL_VERSION,
            backend="egl",  # type: ignore[arg-type]
        )
    except Exception as exc:
        raise RenderError(
            f"cannot create a headless EGL OpenGL {GL_VERSION // 100}.{GL_VERSION // 10 % 10} "
            f"context: {exc} (on Debian install libegl1, libegl-mesa0 and libgl1-mesa-dri)"
        ) from exc
    renderer = str(ctx.info["GL_RENDERER"])
    drawing = f", {threads} raster threads" if threads and "llvmpipe" in renderer else ""
    log.info("GL context: %s (%s)%s", renderer, ctx.info["GL_VERSION"], drawing)
    return ctx


def describe(ctx: moderngl.Context) -> str:
    return f"{ctx.info['GL_RENDERER']} / {ctx.info['GL_VERSION']}"


def gil_free_finish(ctx: moderngl.Context) -> Callable[[], None]:
    """A glFinish that lets other Python threads run while it waits.

    moderngl holds the GIL through every GL call, and on a CPU renderer a call that has to wait
    for rasterisation (rewriting a buffer a queued draw still reads, reading pixels back) waits
    for tens of milliseconds: with the GIL held, the daemon's event loop and the cockpit
    readers stall with it. ctypes releases the GIL around a foreign call, so finishing the
    queued work through it first leaves the following moderngl call nothing to wait for.
    glvnd's libOpenGL dispatches to the context current on this thread; without it, the
    ordinary (GIL-holding) finish still keeps the results correct."""
    for name in ("libOpenGL.so.0", "libGL.so.1"):
        try:
            finish: Callable[[], None] = ctypes.CDLL(name).glFinish
        except (OSError, AttributeError):
            continue
        finish.restype = None  # type: ignore[attr-defined]
        return finish
    log.info("no libOpenGL for a GIL-free glFinish; other threads wait while GL works")
    return ctx.finish


def release_framebuffer(fbo: moderngl.Framebuffer) -> None:
    """Release `fbo` with the default framebuffer bound first. moderngl re-binds the last
    framebuffer it bound after creating any new one: were that one released, GL reports
    INVALID_OPERATION at the next framebuffer made on the context, far from the cause (on a
    shared context, in whichever renderer comes next)."""
    fbo.ctx.detect_framebuffer(0).use()
    fbo.release()
