"""Shader programs from `.glsl` package files: one file per program, `#include` and injected
`#define`s, each program compiled once per context."""

from __future__ import annotations

import re
from importlib import resources

import moderngl

from wxsky.errors import RenderError

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)
_STAGES = {"vertex_shader": "VERTEX_SHADER", "fragment_shader": "FRAGMENT_SHADER"}


def shader_source(name: str, _depth: int = 0) -> str:
    """The text of `shaders/<name>` with its includes expanded."""
    if _depth > 8:
        raise RenderError(f"shader include nesting too deep at {name}")
    try:
        text = resources.files("wxsky.render").joinpath("shaders", name).read_text("utf-8")
    except FileNotFoundError:
        raise RenderError(f"shader file not found: shaders/{name}") from None
    return _INCLUDE.sub(lambda m: shader_source(m.group(1), _depth + 1), text)


OUTPUTS = ("display", "linear")
"""What a library's programs write into their layers (display.glsl): display values (exposed,
tone-mapped, sRGB-encoded, for RGBA8 layers) or scene-linear colour (for float layers)."""


class ShaderLibrary:
    """Compiles programs on first use and keeps them for the context's life. `output` (OUTPUTS)
    holds for every program the library makes; `variable_exposure`: display programs take
    their exposure from `u_exposure` for legacy colours too (otherwise those are drawn at
    EV 0, as they always were, at no cost)."""

    def __init__(
        self, ctx: moderngl.Context, output: str = "display", variable_exposure: bool = False
    ) -> None:
        if output not in OUTPUTS:
            raise RenderError(f"shader output must be one of {OUTPUTS}, got {output!r}")
        self._ctx = ctx
        self.output = output
        self.variable_exposure = variable_exposure
        self._programs: dict[tuple[str, tuple[tuple[str, str], ...]], moderngl.Program] = {}

    def program(self, name: str, defines: dict[str, str] | None = None) -> moderngl.Program:
        key = (name, tuple(sorted((defines or {}).items())))
        prog = self._programs.get(key)
        if prog is None:
            prog = self._compile(name, defines or {})
            self._programs[key] = prog
        return prog

    def _compile(self, name: str, defines: dict[str, str]) -> moderngl.Program:
        body = shader_source(name)
        if self.output == "linear":
            defines = defines | {"OUTPUT_LINEAR": "1"}
        elif self.variable_exposure:
            defines = defines | {"EXPOSURE_VARIABLE": "1"}
        header = "#version 330 core\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items())
        vertex, fragment = (
            f"{header}#define {macro} 1\n#line 1\n{body}" for macro in _STAGES.values()
        )
        try:
            return self._ctx.program(vertex_shader=vertex, fragment_shader=fragment)
        except moderngl.Error as exc:
            raise RenderError(f"shaders/{name}: {exc}") from exc

    def release(self) -> None:
        for prog in self._programs.values():
            prog.release()
        self._programs.clear()
