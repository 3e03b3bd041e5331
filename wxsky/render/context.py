"""The one place a GL context is created: headless, through EGL.

EGL runs on Mesa's llvmpipe on CPU-only machines and on NVIDIA's driver on GPU machines, so
the same code path renders in CI and on a workstation.
"""

from __future__ import annotations

import logging

import moderngl

from wxsky.errors import RenderError

log = logging.getLogger(__name__)

GL_VERSION = 330


def create_context() -> moderngl.Context:
    """A standalone OpenGL 3.3+ core context with no window. Raises RenderError saying why not."""
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
    log.info("GL context: %s (%s)", ctx.info["GL_RENDERER"], ctx.info["GL_VERSION"])
    return ctx


def describe(ctx: moderngl.Context) -> str:
    return f"{ctx.info['GL_RENDERER']} / {ctx.info['GL_VERSION']}"
