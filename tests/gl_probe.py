"""Whether this test process can make an EGL OpenGL context, tried once per process (each
pytest-xdist worker is a process of its own, with its own context): shared by conftest's `gl`
marker and the daemon harness, so a test that starts a rendering `wxsky` process skips with
the reason where there is no EGL, marked or not."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from wxsky.errors import RenderError

if TYPE_CHECKING:
    import moderngl

# This process's one GL context, or why there is none: made on the first call.
_gl: dict[str, moderngl.Context | str] = {}


def gl_context() -> moderngl.Context | str:
    """The process's context, or the reason it cannot be made (tried once)."""
    if not _gl:
        from wxsky.render.context import create_context

        try:
            _gl["ctx"] = create_context()
        except RenderError as exc:
            _gl["ctx"] = str(exc)
    return _gl["ctx"]


def skip_without_gl() -> None:
    """Skip the running test, saying why, where no EGL OpenGL context can be made."""
    ctx = gl_context()
    if isinstance(ctx, str):
        pytest.skip(f"no EGL OpenGL context: {ctx}")


def release() -> None:
    """Release the context, if one was made (at the end of the session)."""
    ctx = _gl.pop("ctx", None)
    if ctx is not None and not isinstance(ctx, str):
        ctx.release()
