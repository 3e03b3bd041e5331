"""Per-pass profile of the renderer: time, fragments written and how far each pass is from
what this machine's rasteriser can fill (`wxsky bench --profile`).

A profiled pass ends with the GPU idle (glFinish), so its wall time is its own, and counts the
samples it wrote with an occlusion query. Fragments a shader discards (a sprite's transparent
texels) are not written, so a pass's Mpix/s counts useful pixels only: work spent on discarded
ones shows as a lower ratio to the limit.

The limits are measured on the context at hand (`measure_fill_limits`): full-screen triangles
drawn over and over at the size of the frame, with the same blend and filtering as the passes
they bound. They are what this machine fills at best, not a GPU's data sheet.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import moderngl
import numpy as np

from wxsky.render.context import release_framebuffer

# Which limit bounds which pass: sprites sample the mip-mapped sheet (trilinear; small ones,
# the far band and impostors, bilinearly from one level) and blend;
# the sky computes its colour and writes without blending (its texture reads are few and
# small); an upsample is one bilinear read and a write.
LIMIT_OF_PASS = {
    "sprites": "trilinear_blend",
    "small_sprites": "bilinear_blend",
    "sky": "untextured",
    "upsample": "bilinear",
    # A tower's impostor: up to MARCH_STEPS reads a texel (render/towers.py), against the
    # limit for one.
    "volume": "bilinear",
}

_FILL_SHADERS = {
    "untextured": "f_colour = vec4(0.25, 0.3, 0.35, 0.5);",
    "bilinear": "f_colour = texture(u_tex, v_uv);",
    "bilinear_blend": "f_colour = texture(u_tex, v_uv);",
    "trilinear_blend": "f_colour = texture(u_tex, v_uv);",
}


@dataclass
class PassStats:
    kind: str  # a key of LIMIT_OF_PASS
    seconds: list[float] = field(default_factory=list)
    samples: list[int] = field(default_factory=list)


class PassProfiler:
    """Collects every profiled pass by name; `frame_done()` closes a frame."""

    def __init__(self, ctx: moderngl.Context, finish: Callable[[], None]) -> None:
        self._ctx = ctx
        self._finish = finish
        self._query = ctx.query(samples=True)
        self.passes: dict[str, PassStats] = {}
        self.frames = 0

    @contextmanager
    def measure(self, name: str, kind: str) -> Iterator[None]:
        self._finish()
        t0 = time.perf_counter()
        with self._query:
            yield
        self._finish()
        elapsed = time.perf_counter() - t0
        stats = self.passes.setdefault(name, PassStats(kind))
        stats.seconds.append(elapsed)
        stats.samples.append(int(self._query.samples))

    def frame_done(self) -> None:
        self.frames += 1

    def rows(self, limits: dict[str, float]) -> list[dict[str, float | str | int]]:
        """One row per pass: calls per frame, median ms and Mpix per call, Mpix/s over all
        calls, the limit it is held to and the ratio to it."""
        out: list[dict[str, float | str | int]] = []
        for name, s in self.passes.items():
            total_s = sum(s.seconds)
            total_px = sum(s.samples)
            rate = total_px / total_s / 1e6 if total_s > 0 else 0.0
            limit_name = LIMIT_OF_PASS[s.kind]
            limit = limits.get(limit_name, 0.0)
            out.append(
                {
                    "pass": name,
                    "calls_per_frame": len(s.seconds) / max(self.frames, 1),
                    "median_ms": 1000.0 * statistics.median(s.seconds),
                    "total_ms_per_frame": 1000.0 * total_s / max(self.frames, 1),
                    "mpix_per_call": total_px / len(s.samples) / 1e6,
                    "mpix_per_s": rate,
                    "limit": limit_name,
                    "limit_mpix_per_s": limit,
                    "ratio": rate / limit if limit > 0 else 0.0,
                }
            )
        out.sort(key=lambda r: -float(r["total_ms_per_frame"]))
        return out


BATCH_S = 0.004  # a timed draw of the fill probe lasts at least this long
MAX_LAYERS = 4096


def measure_fill_limits(
    ctx: moderngl.Context,
    size: tuple[int, int],
    finish: Callable[[], None],
    repeats: int = 12,
) -> dict[str, float]:
    """Mpix/s this context fills at `size` with full-screen triangles: no texture, one
    bilinear sample, one bilinear sample blended (premultiplied over), one trilinear sample
    of a mip-mapped RGBA8 texture blended. The median of `repeats` draws of each, a draw
    being as many screens as take BATCH_S (one on a CPU renderer, thousands on a GPU)."""
    w, h = size
    tex_px = 512
    rng = np.random.default_rng(7)
    pixels = rng.integers(0, 256, (tex_px, tex_px, 4), dtype=np.uint8)
    tex = ctx.texture((tex_px, tex_px), 4, pixels.tobytes())
    tex.build_mipmaps()
    colour = ctx.texture((w, h), 4)
    fbo = ctx.framebuffer(color_attachments=[colour])
    limits: dict[str, float] = {}
    try:
        for name, body in _FILL_SHADERS.items():
            prog = ctx.program(vertex_shader=_FILL_VERTEX, fragment_shader=_fill_fragment(body))
            vao = ctx.vertex_array(prog, [])
            tex.filter = (
                (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
                if name.startswith("trilinear")
                else (moderngl.LINEAR, moderngl.LINEAR)
            )
            # The texture is drawn minified as sprites far away are: about 2 texels per pixel.
            if "u_scale" in prog:
                prog["u_scale"].value = 2.0 * min(w, h) / tex_px  # type: ignore[union-attr]
            tex.use(0)
            fbo.use()
            if name.endswith("blend"):
                ctx.enable(moderngl.BLEND)
                ctx.blend_func = (moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
            else:
                ctx.disable(moderngl.BLEND)

            def timed(layers: int, vao: moderngl.VertexArray = vao) -> float:
                finish()
                t0 = time.perf_counter()
                vao.render(moderngl.TRIANGLES, vertices=3, instances=layers)
                finish()
                return time.perf_counter() - t0

            # On a GPU one screen takes less than waiting for the GPU does: stack screens
            # until a draw takes BATCH_S, so the figure is the fill and not the round trip.
            layers = 1
            while layers < MAX_LAYERS and timed(layers) < BATCH_S:
                layers *= 2
            times = [timed(layers) for _ in range(repeats)]
            ctx.disable(moderngl.BLEND)
            limits[name] = layers * w * h / statistics.median(times) / 1e6
            vao.release()
            prog.release()
    finally:
        release_framebuffer(fbo)
        colour.release()
        tex.release()
    return limits


_FILL_VERTEX = """#version 330 core
out vec2 v_uv;
uniform float u_scale = 1.0;
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    v_uv = (p * 0.5 + 0.5) * u_scale;
    gl_Position = vec4(p, 0.0, 1.0);
}
"""


def _fill_fragment(body: str) -> str:
    return (
        "#version 330 core\nin vec2 v_uv;\nuniform sampler2D u_tex;\nout vec4 f_colour;\n"
        f"void main() {{ {body} }}\n"
    )
