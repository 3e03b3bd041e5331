"""Setting a program's uniforms, strictly: a uniform the program lacks is a bug (a name
mistyped, or one the compiler dropped because the shader never reads it), so it is an error,
not a silent no-op. The one exception is the exposure, which a program drawing scene-linear
colour or legacy colours at EV 0 never reads (display.glsl)."""

from __future__ import annotations

import moderngl

from wxsky.errors import RenderError

# Uniforms a program may not have: a linear program never reads the exposure (display.glsl).
OPTIONAL_UNIFORMS = frozenset({"u_exposure"})


def uniform(prog: moderngl.Program, name: str) -> moderngl.Uniform:
    member = prog.get(name, None)
    if not isinstance(member, moderngl.Uniform):
        raise RenderError(f"shader uniform {name!r} is missing (optimised away?)")
    return member


def set_uniform(prog: moderngl.Program, name: str, value: object) -> None:
    if name in OPTIONAL_UNIFORMS and not isinstance(prog.get(name, None), moderngl.Uniform):
        return
    uniform(prog, name).value = value


def write_uniform(prog: moderngl.Program, name: str, data: bytes) -> None:
    uniform(prog, name).write(data)
