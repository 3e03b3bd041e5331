"""Shared fixtures. GL tests use one headless renderer for the whole session (llvmpipe is
enough); they are skipped, with the reason, only where no EGL OpenGL 3.3 context can be made."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest

from wxsky.errors import RenderError

if TYPE_CHECKING:
    from wxsky.render.renderer import Renderer

# Ring impostor texture size for GL tests and golden images: small keeps llvmpipe fast.
GL_RING_PX = 128


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Tests that draw with GL carry the `gl` marker (`pytest -m "not gl"` leaves them out)."""
    for item in items:
        if "gl_renderer" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.gl)


@pytest.fixture(scope="session")
def gl_renderer() -> Iterator[Renderer]:
    from wxsky.render.context import create_context
    from wxsky.render.renderer import Renderer

    try:
        ctx = create_context()
    except RenderError as exc:
        pytest.skip(f"GL tests need a headless EGL OpenGL 3.3 context: {exc}")
    renderer = Renderer(ring_texture_px=GL_RING_PX, ctx=ctx)
    try:
        yield renderer
    finally:
        renderer.close()
        ctx.release()


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
