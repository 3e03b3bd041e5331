"""Shared fixtures. GL tests use one headless renderer for the whole session (llvmpipe is
enough); they are skipped, with the reason, only where no EGL OpenGL 3.3 context can be made.

Every test that needs GL carries the `gl` marker, whether it draws in this process or starts
a `wxsky` process that does (a snapshot, the daemon). The context is tried once, on the first
such test, and where it cannot be made every `gl` test is skipped with the error: the rest of
the suite still runs on a machine without EGL."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest

from wxsky.errors import RenderError

if TYPE_CHECKING:
    import moderngl

    from wxsky.render.renderer import Renderer

# Ring impostor texture size for GL tests and golden images: small keeps llvmpipe fast.
GL_RING_PX = 128

# The session's one GL context, or why there is none: made on the first `gl` test's setup.
_gl: dict[str, moderngl.Context | str] = {}


def _gl_context() -> moderngl.Context | str:
    """The session's context, or the reason it cannot be made (tried once per session)."""
    if not _gl:
        from wxsky.render.context import create_context

        try:
            _gl["ctx"] = create_context()
        except RenderError as exc:
            _gl["ctx"] = str(exc)
    return _gl["ctx"]


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A test that takes the renderer draws with GL, so it is a `gl` test whether or not it
    says so (`pytest -m "not gl"` leaves them out)."""
    for item in items:
        if "gl_renderer" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.gl)


def pytest_runtest_setup(item: pytest.Item) -> None:
    if item.get_closest_marker("gl") is None:
        return
    ctx = _gl_context()
    if isinstance(ctx, str):
        pytest.skip(f"no EGL OpenGL context: {ctx}")


def pytest_sessionfinish(session: pytest.Session) -> None:
    ctx = _gl.pop("ctx", None)
    if ctx is not None and not isinstance(ctx, str):
        ctx.release()


@pytest.fixture(scope="session")
def gl_renderer() -> Iterator[Renderer]:
    from wxsky.render.renderer import Renderer

    ctx = _gl_context()
    if isinstance(ctx, str):
        # Only reached from a test the marker check missed; say why all the same.
        pytest.skip(f"no EGL OpenGL context: {ctx}")
    # An earlier `gl` test may have made and released a context of its own on this thread
    # since the session's was made: the renderer's objects must go into the session's.
    ctx.__enter__()
    renderer = Renderer(ring_texture_px=GL_RING_PX, ctx=ctx)
    try:
        yield renderer
    finally:
        renderer.close()


@pytest.fixture
def renderer(gl_renderer: Renderer) -> Iterator[Renderer]:
    """The session renderer, checked for a clean GL error state after each test."""
    ctx = gl_renderer.ctx
    # A test may have made (and released) a context of its own on this thread: make the
    # session's current again, or every GL call here would go to no context at all.
    ctx.__enter__()
    before = ctx.error  # reading it clears it
    assert before == "GL_NO_ERROR", f"GL error left over from an earlier test: {before}"
    yield gl_renderer
    after = ctx.error
    assert after == "GL_NO_ERROR", f"GL error after the test: {after}"


@pytest.fixture
def shm_name() -> Iterator[str]:
    """A segment name no other test uses; the segment, if the test left one, is removed."""
    import contextlib
    import uuid

    from wxsky.output import shm

    segment = f"wxsky-test-{uuid.uuid4().hex[:12]}"
    yield segment
    with contextlib.suppress(FileNotFoundError):
        shm._shm_unlink(segment)
