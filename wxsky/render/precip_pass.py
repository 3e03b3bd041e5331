"""Precipitation drawn into the near layers (issue 43, items 1, 2 and 4; precip.glsl): the rain
curtains under the near storms before the near sprites (the clouds above and in front of
them cover them), and after the sprites the drops or flakes about the eye and lightning's
cloud-to-ground channels, as streaks. What is drawn comes from `scene/precip_view.py` and
`scene/lightning.py`; the geometry of the streaks is made here with numpy, a frame's worth in
well under a millisecond.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import moderngl
import numpy as np
import numpy.typing as npt

from wxsky.render.shaders import ShaderLibrary
from wxsky.render.uniforms import set_uniform as _set
from wxsky.render.uniforms import write_uniform as _write
from wxsky.scene.camera import Camera
from wxsky.scene.lightning import FLASH_RGB, Flash
from wxsky.scene.precip_view import (
    DROP_BOX_M,
    DROP_FALL_MPS,
    MAX_CURTAINS,
    MAX_DROPS,
    EyeDrops,
    PrecipView,
)
from wxsky.scene.sky import SkyParams

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]

# The rain's colour under a storm: the air's grey, darkened (the light under the base is
# what the storm lets through); snow is whiter than the air around it.
RAIN_SHADE = 0.8
SNOW_SHADE = 1.08
VEIL_SHADE = 0.85
# Streaks: drops catch the bright sky (lighter than what is behind them), flakes are white.
DROP_LIGHT = 1.25
DROP_ALPHA = {False: 0.42, True: 0.8}
DROP_WIDTH_PX = {False: 1.2, True: 2.2}  # at the near layer's scale
DROP_NEAREST_M = 0.6  # a drop nearer than this is on the windshield, not in the air
# Lightning's channel: a bright core and a wider glow about it, crooked in steps of 5-10 %
# of its height, with a branch or two.
CHANNEL_SEGMENTS = 18
CHANNEL_WIDTH_PX = (2.0, 9.0)  # core, glow
CHANNEL_ALPHA = (1.0, 0.35)
_LINE_FLOATS = 3 + 3 + 4 + 1


class PrecipPass:
    """The curtains' program and the streaks' (a quad per instance, its instance data
    written each frame into one growing buffer)."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        self._curtains = shaders.program(
            "precip.glsl", {"CURTAINS": "1", "MAX_CURTAINS": str(MAX_CURTAINS)}
        )
        self._lines = shaders.program("precip.glsl", {"LINES": "1"})
        self._curtain_vao = ctx.vertex_array(self._curtains, [])
        self._buffer = ctx.buffer(reserve=4096 * _LINE_FLOATS * 4, dynamic=True)
        self._lines_vao = ctx.vertex_array(
            self._lines,
            [
                (
                    self._buffer,
                    "3f 3f 4f 1f/i",
                    "in_head",
                    "in_tail",
                    "in_rgba",
                    "in_width_px",
                )
            ],
        )
        self._closed = False

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for obj in (self._curtain_vao, self._lines_vao, self._buffer):
            obj.release()

    def draw_curtains(
        self, view: PrecipView, cam: Camera, sky: SkyParams, size: tuple[int, int], exposure: float
    ) -> None:
        """The curtains (and a nimbostratus's rain) over the bound framebuffer (`size`
        pixels); the caller draws only a view that has some (`PrecipView.drawn`)."""
        shown = view.curtains[:MAX_CURTAINS]
        eye = cam.position_m
        prog = self._curtains
        right, up, fwd = cam.basis()
        axis = np.zeros((MAX_CURTAINS, 4), np.float32)
        span = np.zeros((MAX_CURTAINS, 4), np.float32)
        base = np.zeros((MAX_CURTAINS, 4), np.float32)
        offsets = np.zeros((3, len(shown)))
        for i, c in enumerate(shown):
            axis[i] = (c.axis_m[0] - eye[0], c.axis_m[1] - eye[1], c.radius_m, c.extinction_per_m)
            virga = c.bottom_m > sky.ground_m + 1.0
            span[i] = (c.top_m, c.bottom_m, 1.0 if virga else 0.0, (c.axis_m[0] * 0.013) % 97.0)
            offsets[:, i] = (axis[i, 0], axis[i, 1], 0.5 * (c.top_m + c.bottom_m) - eye[2])
            base[i, 0] = c.base_radius_m
        air = np.zeros((MAX_CURTAINS, 3), np.float32)
        if shown:
            air[: len(shown)] = sky.haze_toward(offsets, eye[2]).T
        # Rain seen through kilometres of itself is its own grey: the air's, a little dimmed.
        haze = np.asarray(sky.haze_rgb, np.float64)
        veil_rgb = VEIL_SHADE * (0.6 * float(haze @ [0.2126, 0.7152, 0.0722]) + 0.4 * haze)
        body = np.zeros((MAX_CURTAINS, 3), np.float32)
        for i, c in enumerate(shown):
            luma = float(air[i] @ np.array([0.2126, 0.7152, 0.0722], np.float32))
            if c.snow:
                body[i] = np.minimum(SNOW_SHADE * (0.6 * luma + 0.4 * air[i]), 1.0)
            else:
                body[i] = RAIN_SHADE * (0.7 * luma + 0.3 * air[i])
        values: dict[str, object] = {
            "u_rect": (-1.0, -1.0, 1.0, 1.0),
            "u_right": tuple(float(v) for v in right),
            "u_up": tuple(float(v) for v in up),
            "u_forward": tuple(float(v) for v in fwd),
            "u_tan_half_fov": (cam.tan_half_fov_x, cam.tan_half_fov_y),
            "u_target_size": (float(size[0]), float(size[1])),
            "u_eye_z": float(eye[2]),
            "u_pixel_rad": 2.0 * cam.tan_half_fov_x / max(size[0], 1),
            "u_clip_top_m": float(min(view.clip_top_m, 1e6)),
            "u_veil": (view.veil_per_m, view.veil_top_m, view.ground_m),
            "u_veil_rgb": tuple(float(v) for v in veil_rgb),
            "u_count": len(shown),
            "u_inv_haze_m": 0.0 if not math.isfinite(sky.haze_m) else 1.0 / sky.haze_m,
            "u_fall_m": float(view.time_s * DROP_FALL_MPS[False] % 14_000.0),
            "u_exposure": exposure,
        }
        for name, value in values.items():
            _set(prog, name, value)
        _write(prog, "u_axis", axis.tobytes())
        _write(prog, "u_span", span.tobytes())
        _write(prog, "u_base", base.tobytes())
        _write(prog, "u_body", body.tobytes())
        _write(prog, "u_air", air.tobytes())
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = (moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        self._curtain_vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        self.ctx.disable(moderngl.BLEND)

    def draw_streaks(
        self,
        view: PrecipView | None,
        flashes: Sequence[tuple[Flash, float]],
        cam: Camera,
        sky: SkyParams,
        size: tuple[int, int],
        exposure: float,
    ) -> int:
        """The drops about the eye and the lit cloud-to-ground channels over the bound
        framebuffer; returns how many streaks were drawn."""
        parts = []
        if view is not None and view.drops is not None:
            parts.append(drop_lines(view.drops, view.time_s, cam.position_m, sky))
        for flash, glow in flashes:
            if flash.kind == "cloud_to_ground" and glow > 0.0:
                parts.append(channel_lines(flash, glow, cam.position_m, sky))
        if not parts:
            return 0
        data = np.concatenate(parts).astype(np.float32)
        if not len(data):
            return 0
        raw = data.tobytes()
        if len(raw) > self._buffer.size:
            self._buffer.orphan(len(raw) * 2)
        self._buffer.write(raw)
        view_proj = cam.projection_matrix() @ _view_rotation(cam)
        prog = self._lines
        _write(prog, "u_view_proj", np.ascontiguousarray(view_proj.T, np.float32).tobytes())
        _set(prog, "u_target_size", (float(size[0]), float(size[1])))
        _set(prog, "u_exposure", exposure)
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = (moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        self._lines_vao.render(moderngl.TRIANGLES, vertices=6, instances=len(data))
        self.ctx.disable(moderngl.BLEND)
        return len(data)


def _view_rotation(cam: Camera) -> F64:
    """The camera's view matrix without its translation (the streaks are eye-relative)."""
    view = np.array(cam.view_matrix(), np.float64)
    view[:3, 3] = 0.0
    return view


@functools.cache
def _all_drop_seeds() -> F64:
    """(MAX_DROPS, 3) where each drop sits in its box, 0..1 (the same every frame and
    channel; a frame takes as many as its rate asks, the first ones)."""
    return np.random.default_rng(0x5EED_D80).random((MAX_DROPS, 3))


def _drop_seeds(count: int) -> F64:
    return _all_drop_seeds()[:count]


def drop_lines(drops: EyeDrops, time_s: float, eye_m: Sequence[float], sky: SkyParams) -> F32:
    """(N, 11) streaks (head, tail eye-relative ENU; RGBA; width px) of the drops about the
    eye: each drop fixed in air that moves with the wind and falls, wrapped into a box of
    DROP_BOX_M about the eye, its streak the way it moved relative to the eye in the
    exposure (tail behind)."""
    rel = np.asarray(drops.relative_mps, np.float64)
    box = DROP_BOX_M
    # Where the box's drops have got to: the air's motion less the eye's, in float64 and
    # wrapped before it reaches the GPU (the eye may be 100 km from the origin).
    shift = np.mod(rel * (time_s % 3600.0) - np.mod(np.asarray(eye_m, np.float64), box), box)
    head = np.mod(_drop_seeds(drops.count) * box + shift, box) - 0.5 * box
    dist = np.linalg.norm(head, axis=1)
    keep = dist > DROP_NEAREST_M
    head, dist = head[keep], dist[keep]
    tail = head - rel * drops.streak_s
    luma = float(np.asarray(sky.haze_rgb) @ np.array([0.2126, 0.7152, 0.0722]))
    if drops.snow:
        rgb = np.array([0.95, 0.96, 1.0]) * max(min(1.0, 1.15 * luma + 0.2), 0.15)
    else:
        rgb = np.clip(np.asarray(sky.haze_rgb) * DROP_LIGHT, 0.0, 1.0)
    # Farther drops fade: the box's edge is no wall.
    fade = np.clip(1.0 - dist / (0.5 * box), 0.0, 1.0) ** 1.5
    out = np.empty((len(head), _LINE_FLOATS), np.float32)
    out[:, 0:3] = head
    out[:, 3:6] = tail
    out[:, 6:9] = rgb
    out[:, 9] = DROP_ALPHA[drops.snow] * fade
    out[:, 10] = DROP_WIDTH_PX[drops.snow]
    return out


def channel_lines(flash: Flash, glow: float, eye_m: Sequence[float], sky: SkyParams) -> F32:
    """(N, 11) streaks of a cloud-to-ground flash's channel at its glow: a crooked line from
    where it leaves the cloud to the ground, and a branch, as a glow and a core; the same
    shape for the same flash on every channel (its id seeds it)."""
    rng = np.random.default_rng(flash.id & 0xFFFF_FFFF)
    x, y, z = flash.position_m
    height = max(z - flash.ground_m, 1.0)
    zs = np.linspace(z, flash.ground_m, CHANNEL_SEGMENTS + 1)
    steps = rng.normal(0.0, 0.06 * height / math.sqrt(CHANNEL_SEGMENTS), (CHANNEL_SEGMENTS, 2))
    xy = np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)]) + np.array([x, y])
    points = np.column_stack([xy, zs]) - np.asarray(eye_m, np.float64)
    heads, tails = [points[:-1]], [points[1:]]
    fork = int(rng.integers(3, CHANNEL_SEGMENTS // 2))
    length = int(rng.integers(3, 6))
    direction = rng.normal(0.0, 1.0, 2)
    direction /= max(float(np.linalg.norm(direction)), 1e-6)
    bz = np.linspace(zs[fork], zs[fork] - 0.4 * height * length / CHANNEL_SEGMENTS, length + 1)
    bxy = xy[fork] + np.outer(np.arange(length + 1), direction * 0.05 * height)
    branch = np.column_stack([bxy, bz]) - np.asarray(eye_m, np.float64)
    heads.append(branch[:-1])
    tails.append(branch[1:])
    head = np.concatenate(heads)
    tail = np.concatenate(tails)
    n_main = CHANNEL_SEGMENTS
    # Through haze a channel dims as a cloud does; it never lights up the air in front of it.
    dist = np.linalg.norm(0.5 * (head + tail), axis=1)
    seen = np.exp(-dist / max(sky.haze_m, 1.0)) if math.isfinite(sky.haze_m) else np.ones(len(dist))
    brightness = min(1.0, glow * 1.4) * seen
    brightness[n_main:] *= 0.6  # the branch is fainter than the channel
    rows = []
    for width, alpha in zip(CHANNEL_WIDTH_PX, CHANNEL_ALPHA, strict=True):
        part = np.empty((len(head), _LINE_FLOATS), np.float32)
        part[:, 0:3] = head
        part[:, 3:6] = tail
        part[:, 6:9] = FLASH_RGB
        part[:, 9] = alpha * brightness
        part[:, 10] = width
        rows.append(part)
    return np.concatenate([rows[1], rows[0]])  # the glow first, the core over it
