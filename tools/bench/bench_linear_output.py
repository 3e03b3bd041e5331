"""What the exposure and tone map cost a frame's drawing (issue 41, item 4): one plan drawn by
four renderers in turn, in one process, on one GL context:

- `main`: the shaders of another checkout (default /work/main: before issue 41),
- `default`: this checkout's default renderer (EV 0 only: the legacy round trip compiled out),
- `ev+1`: a renderer made with variable_exposure at EV +1 (from_legacy and display per fragment),
- `linear`: the linear renderer (RGBA16F targets, from_legacy per fragment).

Each draw is measured in CPU seconds of the whole process (llvmpipe rasterises on threads of
its own), which a machine shared with other work disturbs far less than wall time; renderers
alternate in rounds. Two figures: the near layer with the sky kept (a camera flying straight),
and the whole sky drawn again (a turn, a clock step).

    PYTHONPATH=$PWD .venv/bin/python tools/bench/bench_linear_output.py overcast-stratus
"""

from __future__ import annotations

import argparse
import re
import resource
import statistics
from pathlib import Path
from typing import Any

import moderngl

import wxsky.render.renderer as renderer_module
from wxsky.engine.stages import SkyEngine
from wxsky.render import shaders
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.settings.config import DaemonConfig
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


def _cpu_s() -> float:
    use = resource.getrusage(resource.RUSAGE_SELF)
    return use.ru_utime + use.ru_stime


def _library_from(root: Path) -> type[shaders.ShaderLibrary]:
    """A shader library that reads its files from another checkout's shaders folder (this
    one's for a file that checkout lacks: the meter, which a frame never draws)."""

    def source(name: str) -> str:
        path = root / name
        if not path.exists():
            return shaders.shader_source(name)
        text = path.read_text("utf-8")
        return _INCLUDE.sub(lambda m: source(m.group(1)), text)

    class Library(shaders.ShaderLibrary):
        def _compile(self, name: str, defines: dict[str, str]) -> moderngl.Program:
            body = source(name)
            head = "#version 330 core\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items())
            vertex, fragment = (
                f"{head}#define {stage} 1\n#line 1\n{body}"
                for stage in ("VERTEX_SHADER", "FRAGMENT_SHADER")
            )
            return self._ctx.program(vertex_shader=vertex, fragment_shader=fragment)

    return Library


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("preset")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--main", type=Path, default=Path("/work/main"))
    args = parser.parse_args()
    state = WeatherState().apply(load_preset(args.preset, ()))
    settings = DaemonConfig().scene.settings()
    cam = Camera(
        position_m=(0.0, 0.0, 1500.0), heading_deg=90.0, width_px=1280, height_px=720
    )  # the bench's default path: 1,500 m, heading 090
    with SkyEngine(state, cam, settings, clock_rate=0.0, render_mode="ring") as engine:
        plan = engine.advance(0.0)
    default = Renderer(settings.ring_texture_px)
    kept = renderer_module.ShaderLibrary
    renderer_module.ShaderLibrary = _library_from(args.main / "wxsky/render/shaders")  # type: ignore[misc]
    try:
        main_r = Renderer(settings.ring_texture_px, ctx=default.ctx)
    finally:
        renderer_module.ShaderLibrary = kept  # type: ignore[misc]
    ev = Renderer(settings.ring_texture_px, ctx=default.ctx, variable_exposure=True)
    ev.exposure = 2.0
    linear = Renderer(settings.ring_texture_px, ctx=default.ctx, output="linear")
    renderers = {"main": main_r, "default": default, "ev+1": ev, "linear": linear}
    near: dict[str, list[float]] = {k: [] for k in renderers}
    sky: dict[str, list[float]] = {k: [] for k in renderers}
    for r in renderers.values():
        r.render_ring(plan.ring)
        r.render_frame(plan.frame)
        r.finish()
    for _ in range(args.rounds):
        for name, r in renderers.items():
            for _ in range(8):
                start = _cpu_s()
                r.render_frame(plan.frame)
                r.finish()
                near[name].append(_cpu_s() - start)
            for _ in range(2):
                held: Any = r._sky_drawn  # forget the kept sky: draw it whole
                held.clear()
                start = _cpu_s()
                r._draw_sky("sky", plan.frame.camera, plan.frame.sky)
                r.finish()
                sky[name].append(_cpu_s() - start)
    for label, times in (("near layer", near), ("whole sky", sky)):
        ms = {k: statistics.mean(v) * 1000.0 for k, v in times.items()}
        cells = " | ".join(f"{k} {v:.1f} ({v / ms['main'] - 1.0:+.0%})" for k, v in ms.items())
        print(f"{args.preset}, {label}, CPU ms per draw: {cells}")


if __name__ == "__main__":
    main()
