"""Shared fixtures. GL tests use one headless renderer for the whole session (llvmpipe is
enough); they are skipped, with the reason, only where no EGL OpenGL 3.3 context can be made.

Every test that needs GL carries the `gl` marker, whether it draws in this process or starts
a `wxsky` process that does (a snapshot, the daemon). The context is tried once, on the first
such test, and where it cannot be made every `gl` test is skipped with the error: the rest of
the suite still runs on a machine without EGL. (The daemon harness skips the same way, so a
daemon test that lacks the marker skips too rather than failing.)

Under pytest-xdist (the README's command runs the suite on every core) each worker is a
process of its own: "the session" is the worker's, with its own context and renderer. Tests
that share something fixed on the machine (a multicast port, an in-tree build) carry
`pytest.mark.xdist_group`, which keeps them on one worker (`--dist loadgroup`).

The atmosphere's tables made by any process of the suite (the daemons and snapshots it
starts inherit the environment) are kept in build/test-cache, not the user's own cache
(`wxsky/engine/lut_cache.py`): the suite makes each set once, not once a process."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from gl_probe import gl_context, release, skip_without_gl

if TYPE_CHECKING:
    from wxsky.render.renderer import Renderer

os.environ.setdefault(
    "WXSKY_CACHE_DIR", str(Path(__file__).resolve().parents[1] / "build" / "test-cache")
)

# Ring impostor texture size for GL tests and golden images: small keeps llvmpipe fast.
GL_RING_PX = 128


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A test that takes the renderer draws with GL, so it is a `gl` test whether or not it
    says so (`pytest -m "not gl"` leaves them out)."""
    for item in items:
        if "gl_renderer" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.gl)


def pytest_runtest_setup(item: pytest.Item) -> None:
    if item.get_closest_marker("gl") is not None:
        skip_without_gl()


def pytest_sessionfinish(session: pytest.Session) -> None:
    release()


@pytest.fixture(scope="session")
def gl_renderer() -> Iterator[Renderer]:
    from wxsky.render.renderer import Renderer

    ctx = gl_context()
    if isinstance(ctx, str):
        # Only reached from a test the marker check missed; say why all the same.
        pytest.skip(f"no EGL OpenGL context: {ctx}")
    # An earlier `gl` test may have made and released a context of its own on this thread
    # since the session's was made: the renderer's objects must go into the session's.
    ctx.__enter__()
    renderer = Renderer(ring_texture_px=GL_RING_PX, ctx=ctx)
    _SESSION_GL["renderer"] = renderer
    try:
        yield renderer
    finally:
        _SESSION_GL.clear()
        renderer.close()


_SESSION_GL: dict[str, Renderer] = {}


@pytest.fixture(autouse=True)
def _no_released_framebuffer_left_bound() -> Iterator[None]:
    """After each test, the session context's bound framebuffer is one that exists: moderngl
    binds it again whenever a framebuffer is made, and a released one would make the next
    test that makes one fail with GL_INVALID_OPERATION, far from the cause (render.context
    `release_framebuffer` is the way to release one)."""
    yield
    renderer = _SESSION_GL.get("renderer")
    if renderer is None:
        return
    import moderngl

    bound = renderer.ctx.fbo
    if isinstance(bound, moderngl.Framebuffer) and isinstance(bound.mglo, moderngl.InvalidObject):
        pytest.fail("this test left a released framebuffer bound on the session's GL context")


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
