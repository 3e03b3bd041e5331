"""The fog pass (issue 43 item 3, docs/fog.md): the frame's fog field (`scene/fog.py`) marched
along each pixel's view ray by `shaders/fog.glsl` and drawn, premultiplied, over the near layer
after its sprites and curtains (`Renderer._draw_near`): the fog is the lowest thing in the sky.
A frame without fog draws nothing."""

from __future__ import annotations

import moderngl
import numpy as np

from wxsky.render.shaders import ShaderLibrary
from wxsky.render.uniforms import set_uniform, write_uniform
from wxsky.scene.camera import Camera
from wxsky.scene.fog import MAX_BANKS, MAX_RANGE_M, TOP_FADE, FogField
from wxsky.scene.sky import SkyParams

# Steps along each ray; FogField.optical_depth takes the same by default.
FOG_STEPS = 40
# The layer the fog goes into: the main view's near layer, never the layer the host draws over
# its own aircraft.
LAYER = "near"


class FogPass:
    """Draws `fog` (set by the renderer for each frame) into the near layer; the program is
    made at the first frame with fog."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        self._shaders = shaders
        self._vao: moderngl.VertexArray | None = None
        self.fog: FogField | None = None  # the frame's fog (FrameScene.fog)
        self.drawn = 0  # frames the fog was drawn in

    def _program(self) -> tuple[moderngl.Program, moderngl.VertexArray]:
        prog = self._shaders.program(
            "fog.glsl",
            {
                "FOG_BANKS": str(MAX_BANKS),
                "FOG_STEPS": str(FOG_STEPS),
                "TOP_FADE": repr(float(TOP_FADE)),
                "MAX_RANGE_M": repr(float(MAX_RANGE_M)),
            },
        )
        if self._vao is None:
            self._vao = self.ctx.vertex_array(prog, [])
        return prog, self._vao

    def draw(
        self,
        layer: str,
        fbo: moderngl.Framebuffer,
        size: tuple[int, int],
        cam: Camera,
        sky: SkyParams | None,
        exposure: float,
    ) -> None:
        """The fog over what `fbo` (layer `layer`, `size` pixels) holds, seen by `cam`; nothing
        for another layer, a frame without fog or without a sky to light it."""
        fog = self.fog
        if fog is None or layer != LAYER or sky is None:
            return
        prog, vao = self._program()
        for name, value in fog.uniforms().items():
            if isinstance(value, bytes):
                write_uniform(prog, name, value)
            else:
                set_uniform(prog, name, value)
        right, up, fwd = cam.basis()
        e, n, z = cam.position_m
        values: dict[str, object] = {
            "u_eye": (float(e), float(n), float(z - fog.ground_m)),
            "u_right": _vec(right),
            "u_up": _vec(up),
            "u_forward": _vec(fwd),
            "u_tan_half_fov": (cam.tan_half_fov_x, cam.tan_half_fov_y),
            "u_target_size": (float(size[0]), float(size[1])),
            "u_fog_rgb": fog_rgb(sky),
        }
        for name, value in values.items():
            set_uniform(prog, name, value)
        set_uniform(prog, "u_exposure", exposure)  # (a linear program never reads it)
        fbo.use()
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = (moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        vao.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.disable(moderngl.BLEND)
        self.drawn += 1

    def release(self) -> None:
        if self._vao is not None:
            self._vao.release()
            self._vao = None


def _vec(v: object) -> tuple[float, ...]:
    return tuple(float(c) for c in np.asarray(v, np.float64))


# Fog is a cloud on the ground: by day its light is the sun's and the sky's scattered many
# times, brighter than the haze over the horizon, which is as much the dark ground's light
# as the sky's. FOG_LIFT of the way from the haze's colour toward white, by the day's light.
FOG_LIFT = 0.45


def fog_rgb(sky: SkyParams) -> tuple[float, float, float]:
    """The fog's colour (display units): the haze's, lifted toward white by day."""
    lift = FOG_LIFT * max(0.0, min(1.0, sky.ambient))
    r, g, b = sky.haze_rgb
    return (r + (1.0 - r) * lift * r, g + (1.0 - g) * lift * g, b + (1.0 - b) * lift * b)
