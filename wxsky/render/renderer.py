"""Draws the layers a host composites: the sky, the near sprites, and the 8 ring impostors.

Every layer is premultiplied alpha, top row first: RGBA8 display values (exposed and
tone-mapped, shaders/display.glsl) from a display renderer, RGBA16F scene-linear colour from a
linear one (`output="linear"`: `snapshot --linear-out`). One Renderer owns one GL context
and must be used from the thread that created it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import logging
import math
from dataclasses import dataclass

import moderngl
import numpy as np
import numpy.typing as npt

from wxsky.errors import RenderError
from wxsky.render import sky_layer, sky_textures
from wxsky.render.context import create_context, gil_free_finish, release_framebuffer
from wxsky.render.fog_pass import FogPass
from wxsky.render.precip_pass import PrecipPass
from wxsky.render.profile import PassProfiler
from wxsky.render.shaders import ShaderLibrary
from wxsky.render.sprite_sheet import (
    CELL_PX,
    SUPPORT_LEVELS,
    cell_shades,
    load_sheet,
    support_polygons,
)
from wxsky.render.towers import Drawable, TowerPass
from wxsky.render.uniforms import set_uniform as _set
from wxsky.render.uniforms import write_uniform as _write
from wxsky.scene import exposure
from wxsky.scene.camera import Camera
from wxsky.scene.layout import FrameScene, RingScene, SpriteDraw
from wxsky.scene.precip_view import PrecipView
from wxsky.scene.ring import RING_SIZE, ring_target_name
from wxsky.scene.sky import CLEAR_AIR_HAZE_M, SkyParams
from wxsky.scene.texture_slots import SHEET_CELLS, TEX_FLAT_BOTTOM, TEX_FOG
from wxsky.scene.tower_field import TowerShow


def _set_if_read(prog: moderngl.Program, name: str, value: object) -> None:
    """A uniform the program may lack (the sprite depth variants: their compiler drops what
    only the colour reads)."""
    if isinstance(prog.get(name, None), moderngl.Uniform):
        _set(prog, name, value)


def _write_if_read(prog: moderngl.Program, name: str, data: bytes) -> None:
    if isinstance(prog.get(name, None), moderngl.Uniform):
        _write(prog, name, data)


log = logging.getLogger(__name__)

SUN_RADIUS_DEG = 0.27
# The automatic exposure meters the frame at this many points (Renderer.meter_log_average).
METER_SIZE = (64, 36)
# The near sprites are drawn at this fraction of the viewport and stretched over it by the
# host as it draws the layer: fill rate is what limits a CPU renderer, soft sprites look the
# same, and a host uploads a quarter of the pixels.
NEAR_SCALE = 0.5
# The near layer's far band (FrameScene.near_far_count) is drawn at this many pixels a degree
# (256 over 45°, what the ring's impostors held before they were drawn at the picture's
# density), unless that would save less than FAR_BAND_MAX_SCALE of its size.
FAR_BAND_PX_PER_DEG = 256.0 / 45.0
FAR_BAND_MAX_SCALE = 0.8
# Impostor texels are drawn at most this many times finer down than across (`impostor_rows`).
# Square: finer rows than columns blur a distant cloud sideways and not down once the host
# stretches the impostor over its view, so every lobe and base becomes a horizontal streak
# (docs/cloud-form.md: at 2, the far field's vertical gradient energy rose by a tenth to a
# quarter against square texels).
IMPOSTOR_TEXEL_ASPECT = 1.0
IMPOSTOR_MIN_ROWS = 8
IMPOSTOR_SHAPE = "quad"
FAR_BAND_SHAPE = "quad"
# A flat-bottomed sprite turns into the round one as the sine of the angle it is seen at from
# below or above goes from ROUND_FROM to ROUND_TO (sprites.glsl).
ROUND_FROM = 0.45
ROUND_TO = 0.75
# A sprite's cut at its cloud's flat base (SpriteBatch.base_m) is one pixel sharp while the
# sine of the angle it is seen at from below is under BASE_SOFT_FROM, and fades in over half
# the sprite above the base from BASE_SOFT_TO (sprites.glsl): seen steeply, each sprite's
# straight cut would show as its own edge across the base's outline.
BASE_SOFT_FROM = 0.2
BASE_SOFT_TO = 0.45
# A cloud's base is no plane: it is ragged by tens of metres (each thermal's condensation
# level) and thin at its lowest. Seen edge-on, a ray just above the base runs through bumps
# at every depth of the cloud and is only partly in cloud, so a far base is a ramp over its
# lowest tens of metres; near, the sprites' own textured edges draw the bumps, and a ramp
# would blur the crisp base a pilot sees close by. So the cut fades in over BASE_FEATHER_M
# above the base, from none of it at BASE_FEATHER_FROM_M away to all at BASE_FEATHER_TO_M.
# Cut one pixel sharp at every distance, the far field's bases were stacked horizontal edges
# (docs/cloud-form.md: the banding of fair and towering cumulus, 1.57-2.02, falls to
# 1.32-1.57 with it, the bases still on their line).
BASE_FEATHER_M = 90.0
BASE_FEATHER_FROM_M = 2000.0
BASE_FEATHER_TO_M = 8000.0
# A flat-based sprite's texels are dimmed to BASE_DIM at the base, back to their own colour
# BASE_SHADE_DEPTH of the sprite's size above it: the base lies in the whole cloud's shadow.
BASE_DIM = 0.55
# The rain curtains are drawn at this share of the near layer's width and height
# (precip.glsl): their sheets run down them, fine across and long, so a few rows do.
CURTAIN_SCALE = (0.5, 0.125)
BASE_SHADE_DEPTH = 0.5
# ... at full strength where the sine of the angle the sprite is seen at from below is at
# least BASE_DIM_TO (the underside shows), none under BASE_DIM_FROM (the lower side does).
BASE_DIM_FROM = 0.1
BASE_DIM_TO = 0.3
# A stratiform deck's base seen from below: darker and lighter patches, at these scales and
# strengths (a share of the colour, each), in the deck's drifting frame (sprites.glsl
# deck_relief). The haze between the eye and the base takes most of it (4 km visibility
# under an 830 m deck, seen 30 deg up, leaves a fifth): at half these, the base at sun +5,
# its light half of noon's, was an even grey (tools/bench/deck_structure.py).
DECK_SCALES_M = (400.0, 120.0, 40.0)
DECK_RELIEF = (0.25, 0.50, 0.40)
# Turns this close to none or complete are drawn as such: at most 1/40 of a colour level.
ROUND_SNAP = 1e-4
# Sprites at least this many pixels across read no level coarser than the support polygons'
# fine set holds (trilinear filtering reads level log2(CELL_PX / pixels) and the next), with
# half as much again to spare; smaller ones are drawn as the polygons that hold every level.
FINE_MIN_PX = 1.5 * CELL_PX / 2.0 ** (SUPPORT_LEVELS - 1)
# centre (3) + size + rotation + texture + rgba (4) + normal (3) + rim (3) + base + deck (3),
# float32
_INSTANCE_FLOATS = 20
_INSTANCE_LAYOUT = (
    ("in_centre", "3f", 0),
    ("in_size", "f", 3),
    ("in_rotation", "f", 4),
    ("in_texture", "f", 5),
    ("in_rgba", "4f", 6),
    ("in_normal", "3f", 10),
    ("in_rim", "3f", 13),
    ("in_base", "f", 16),
    ("in_deck", "3f", 17),
)
_RELIEF_PERIOD_M = 65536.0
# Sprite shader variants (bits of the code `_variants` gives each sprite).
_MIXING = 1
_DECK = 2
_FLAT_BASE = 4
_SPRITE_VARIANTS = 8
_NEAR_DEPTH = 8  # the depth pass's variant of each of the above (sprites.glsl NEAR_DEPTH)
# The `near_depth` layer (near_depth.glsl): a sprite counts at a pixel where it shows at 8 bits;
# distances as log2(1 + d) over this range (2^18 m, 262 km: past the far plane), in 24 bits.
NEAR_DEPTH_ALPHA = 1.0 / 255.0
NEAR_DEPTH_LOG2_RANGE = 18.0
NEAR_DEPTH_NONE = 1e9  # the float target's clear: no sprite here
NEAR_DEPTH_DIVISOR = 2  # the layer is this much smaller than `near` each way
# A draw whose sprites change variant more often than this (layers of decks, sheets and
# heaped clouds interleaved back to front: the thunderstorm's far band made 410 draws of 950
# sprites, a third of its frame) draws them all with the variant holding every feature any
# of them needs, each sprite's own data switching off what it lacks (no base: NO_BASE_M
# under it; no deck: 0), at the cost of the features' arithmetic in every fragment.
MAX_VARIANT_RUNS = 16
# The flat base of a sprite that has none, over the eye: so far below that nothing is cut.
NO_BASE_M = -1.0e9


@dataclass
class _Target:
    name: str
    texture: moderngl.Texture
    fbo: moderngl.Framebuffer

    @property
    def size(self) -> tuple[int, int]:
        w, h = self.texture.size
        return (int(w), int(h))

    def release(self) -> None:
        release_framebuffer(self.fbo)
        self.texture.release()


class Renderer:
    """Owns the GL context and every GL object; `close()` releases them."""

    def __init__(
        self,
        ring_texture_px: int = 256,
        ctx: moderngl.Context | None = None,
        near_scale: float = NEAR_SCALE,
        split_sky: bool = True,
        output: str = "display",
        variable_exposure: bool = False,
        near_depth: bool = False,
    ) -> None:
        """`split_sky=False` draws every sky feature a frame shows over the whole picture in
        one pass: the slow reference the split passes are tested against. `output`: "display"
        (RGBA8 layers, the default) or "linear" (RGBA16F scene-linear layers; `exposure` has no
        effect on them). `variable_exposure`: a display renderer that may draw at exposures
        other than EV 0 (display.glsl: the legacy colours' round trip costs fragment work, so
        a renderer that never needs it compiles it out and keeps EV 0). `near_depth`: draw
        the `near_depth` layer too (the distance of the nearest cloud at each pixel of `near`,
        for hosts that composite it against their own geometry: `_draw_near_depth`)."""
        self._own_ctx = ctx is None
        self.near_depth = near_depth
        self.ctx = ctx if ctx is not None else create_context()
        self._closed = False
        self.ring_px = ring_texture_px
        self.near_scale = near_scale
        self.split_sky = split_sky
        self.shaders = ShaderLibrary(self.ctx, output, variable_exposure)
        self.output = output
        self.variable_exposure = variable_exposure or output == "linear"
        # The scale on scene-linear colour (exposure.py); LEGACY_EXPOSURE is today's look.
        self._exposure = exposure.LEGACY_EXPOSURE
        defines = {
            "SHEET_CELLS": str(SHEET_CELLS),
            "FLAT_BOTTOM_SLOT": str(TEX_FLAT_BOTTOM[0]),
            "ROUND_SLOT": str(TEX_FOG[0]),
            "ROUND_FROM": repr(ROUND_FROM),
            "ROUND_TO": repr(ROUND_TO),
            "BASE_SOFT_FROM": repr(BASE_SOFT_FROM),
            "BASE_SOFT_TO": repr(BASE_SOFT_TO),
            "BASE_FEATHER_M": repr(BASE_FEATHER_M),
            "BASE_FEATHER_FROM_M": repr(BASE_FEATHER_FROM_M),
            "BASE_FEATHER_TO_M": repr(BASE_FEATHER_TO_M),
            "BASE_DIM": repr(BASE_DIM),
            "BASE_SHADE_DEPTH": repr(BASE_SHADE_DEPTH),
            "BASE_DIM_FROM": repr(BASE_DIM_FROM),
            "BASE_DIM_TO": repr(BASE_DIM_TO),
            "FINE_MIN_PX": repr(FINE_MIN_PX),
            "DECK_SCALES_M": _glsl_floats(DECK_SCALES_M),
            "DECK_RELIEF": _glsl_floats(DECK_RELIEF),
            "NEAR_DEPTH_ALPHA": repr(NEAR_DEPTH_ALPHA),
        }
        self._sky = sky_textures.SkyPass(self.ctx, self.shaders)
        # One read of the sheet per fragment, and two for the sprites turning round; the
        # base of a deck seen from below (DECK) with its relief; the flat base of heaped
        # clouds (FLAT_BASE): variant codes (`_variants`), each compiled out where not drawn.
        # Made at their first draw (`_sprite_variant`; the daemon's warm_up makes them all):
        # a test's renderer draws one or two of the eight.
        self._sprite_defines = defines
        self._sprite_progs: dict[int, moderngl.Program] = {}
        self._sprite_vaos: dict[int, moderngl.VertexArray] = {}
        self._upsample_prog = self.shaders.program("upsample.glsl")
        levels = load_sheet()  # 512 down to 32, as Wang's sheet
        size = (levels[0].shape[1], levels[0].shape[0])
        self._sheet = self.ctx.texture(size, 4, levels[0].tobytes())
        # This allocates the chain and stops it at 32 px; the shipped levels then replace GL's,
        # which average straight colour and would darken the soft edges.
        self._sheet.build_mipmaps(0, len(levels) - 1)
        for i, level in enumerate(levels[1:], start=1):
            self._sheet.write(level.tobytes(), level=i)
        self._sheet.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self._sheet.repeat_x = self._sheet.repeat_y = False
        self._corner_buf = self.ctx.buffer(
            np.concatenate([np.zeros((8, 2), np.float32), _QUAD_STRIP]).tobytes()
        )
        turning = (TEX_FLAT_BOTTOM[0], TEX_FOG[0])
        fine = support_polygons(None, turning)  # of the shipped sheet, as `levels` is
        coarse = support_polygons(None, turning, depth=len(levels))
        # Each set's polygons' bounding boxes, for quads, as the polygons are chosen.
        boxes = np.concatenate(
            [np.concatenate([p.min(axis=1), p.max(axis=1)], axis=1) for p in (fine, coarse)]
        )
        # What every variant is given once, when it is made.
        self._sprite_constants = (
            np.concatenate([fine, coarse]).tobytes(),
            boxes.tobytes(),
            cell_shades(levels).tobytes(),
        )
        self._instance_buf = self.ctx.buffer(reserve=_INSTANCE_FLOATS * 4 * 1024, dynamic=True)
        self._upsample_vao = self.ctx.vertex_array(self._upsample_prog, [])
        self._near_depth_prog = self.shaders.program(
            "near_depth.glsl",
            {
                "NEAR_DEPTH_NONE": repr(NEAR_DEPTH_NONE),
                "NEAR_DEPTH_LOG2_RANGE": repr(NEAR_DEPTH_LOG2_RANGE),
            },
        )
        self._near_depth_vao = self.ctx.vertex_array(self._near_depth_prog, [])
        self._meter_prog = self.shaders.program("meter.glsl")
        self._meter_vao = self.ctx.vertex_array(self._meter_prog, [])
        self._targets: dict[str, _Target] = {}
        self._finish = gil_free_finish(self.ctx)
        self._clear_ring_sets: set[int] = set()  # ring sets whose 8 images are all clear
        # A CPU renderer (llvmpipe) rasterises when the next GL call switches targets or
        # rewrites a buffer, with the calling thread waiting, and so with the GIL held: finish
        # after each draw instead. A GPU works asynchronously; there only the read-back waits.
        renderer_name = str(self.ctx.info.get("GL_RENDERER", "")).lower()
        self._finish_each_draw = any(cpu in renderer_name for cpu in ("llvmpipe", "softpipe"))
        self._profiler: PassProfiler | None = None
        self._sky_drawn: dict[str, sky_layer.SkyLayerState] = {}  # by layer: what it holds
        self._towers = TowerPass(self.ctx, self.shaders)
        self._precip = PrecipPass(self.ctx, self.shaders)
        self._fog = FogPass(self.ctx, self.shaders)  # ground fog, drawn as a frame has it
        self._check("initialising the renderer")

    @property
    def towers(self) -> TowerPass:
        """The convective towers' pass: its `budget` of impostors a frame (None: every one a
        frame needs, as a snapshot wants; the daemon draws one a frame) and counts."""
        return self._towers

    # -- public API -------------------------------------------------------------------

    @property
    def exposure(self) -> float:
        """The scale on scene-linear colour the display layers are drawn with."""
        return self._exposure

    @exposure.setter
    def exposure(self, scale: float) -> None:
        """ValueError, and the exposure kept, for a scale that is not finite or outside
        exposure.EXPOSURE_EV: NaN and inf never reach a shader. The kept sky layer is drawn
        again (its uniforms change); ring impostors keep the exposure they were drawn with
        until they are drawn again. A renderer made without `variable_exposure` takes only
        LEGACY_EXPOSURE (ValueError otherwise)."""
        checked = exposure.check_scale(scale)
        if not self.variable_exposure and checked != exposure.LEGACY_EXPOSURE:
            raise ValueError(
                "exposure scale: this renderer draws at EV 0 only (made without "
                f"variable_exposure), got {scale!r}"
            )
        self._exposure = checked

    def warm_up(self, frame: FrameScene) -> None:
        """Draw `frame` (`SkyEngine.warm_up`) at startup: a CPU renderer compiles each
        shader's machine code for the state it is drawn with at its first draw, and the kept
        sky layer is drawn whole the first time; both made the first frame the slowest."""
        self.render_frame(frame)
        self._warm_sky_variants(frame.camera, frame.sky)
        for code in range(_SPRITE_VARIANTS):  # a deck or a flat base may come later
            self._sprite_variant(code)
            if self.near_depth:
                self._sprite_variant(code | _NEAR_DEPTH)
        self.finish()

    def _warm_sky_variants(self, cam: Camera, sky: SkyParams) -> None:
        """Draw every variant of the sky pass once, into a scratch target: llvmpipe makes a
        program's machine code at its first draw (a night sky with the moon and the dome:
        about 0.1 s), and a clock set or the evening would otherwise pay it in a frame."""
        scratch = self._target("sky_warm_up", 16, 16)
        scratch.fbo.use()
        self.ctx.disable(moderngl.BLEND)
        physical = sky.atmosphere is not None  # the frame's sky mode: its variants only
        self._sky.use_atmosphere(sky.atmosphere, sky.cover)
        for stars, moon, dome, sun, deck, halo in itertools.product((False, True), repeat=6):
            if (sun and not physical) or (deck and not (physical and dome)) or (halo and not dome):
                continue
            feats = sky_textures.SkyFeatures(
                stars=stars, moon=moon, dome=dome, physical=physical, sun=sun, deck=deck, halo=halo
            )
            uniforms = self._sky_uniforms(cam, sky, feats, sky_textures.FULL_RECT)
            self._sky_draw("sky warm-up", feats, uniforms)

    def render_frame(self, frame: FrameScene) -> None:
        """Draw the sky and the near layer for the frame's camera, and the near_front layer
        when the frame is split at the host's aircraft."""
        cam = frame.camera
        self._fog.fog = frame.fog
        self._draw_sky("sky", cam, frame.sky)
        self._draw_near(
            "near",
            frame.near,
            cam,
            frame.veil_rgba,
            frame.near_far_count,
            frame.towers,
            frame.sky,
            precip=frame.precip,
        )
        if self.near_depth:
            self._draw_near_depth(frame)
        if frame.near_front is not None:
            # Its sprites were hazed with the frame's sky: their detail fades by it too.
            self._draw_near(
                "near_front", frame.near_front, cam, (0.0, 0.0, 0.0, 0.0), sky=frame.sky
            )
        # The drops about the eye and the lightning's channels, in front of every cloud (and
        # of the host's aircraft, in the layer over it).
        front = "near_front" if frame.near_front is not None else "near"
        if (frame.precip is not None and frame.precip.drops is not None) or frame.flashes:
            target = self._targets[front]
            target.fbo.use()
            with self._pass(f"streaks {front}", "small_sprites"):
                self._precip.draw_streaks(
                    frame.precip, frame.flashes, cam, frame.sky, target.size, self._exposure
                )
        self._check("rendering a frame")

    def _draw_near(
        self,
        name: str,
        draw: SpriteDraw,
        cam: Camera,
        clear_rgba: tuple[float, float, float, float],
        far_count: int = 0,
        towers: tuple[TowerShow, ...] = (),
        sky: SkyParams | None = None,
        precip: PrecipView | None = None,
    ) -> None:
        """Near sprites into layer `name` at near_scale of the picture (fill rate is what
        near sprites cost; a host stretches the layer over its viewport, bilinearly, as it
        draws it). The first `far_count` sprites (the far band, drawn first as the draw is back
        to front) go at the ring impostors' texel density where that is coarser, and are
        upsampled under the rest. `towers` go between the sprites at their distances, those in
        the far band into it."""
        size = near_layer_size(cam, self.near_scale)
        clear_rgba = self._legacy_clear(clear_rgba)
        shown: list[Drawable] = []
        if towers and sky is not None:
            with self._pass("tower impostors", "volume"):
                shown = self._towers.prepare(towers, cam, sky, size[0])
        target = self._target(name, *size)
        far_count = min(far_count, len(draw))
        w, h = target.size
        far_size = far_band_size(target.size, cam)
        rest = shown
        if far_count > 0 and far_size is not None:
            far = self._target(f"{name}_far", *far_size)
            far.fbo.use()
            far.fbo.clear(*clear_rgba)
            # Towers as far as the far band go into it, at its resolution, as its sprites do.
            in_far = [item for item in shown if item.tower.insert_at <= far_count]
            rest = shown[len(in_far) :]
            self._draw_run(far, draw, 0, far_count, in_far, cam, sky, FAR_BAND_SHAPE)
            self._upsample(far, target)
            start = far_count
        else:
            target.fbo.use()
            target.fbo.clear(*clear_rgba)
            start = 0
        self._draw_run(target, draw, start, len(draw), rest, cam, sky, "polygon")
        if precip is not None and precip.drawn and sky is not None:
            # The rain curtains over the sprites, below the lowest cloud base (from under it):
            # the rain stands between the eye and the clouds it falls through. Drawn at
            # CURTAIN_SCALE of the layer and stretched over it: every pixel of them walks
            # every curtain in view.
            small = self._target(
                f"{name}_curtains",
                max(1, math.ceil(w * CURTAIN_SCALE[0])),
                max(1, math.ceil(h * CURTAIN_SCALE[1])),
            )
            small.fbo.use()
            small.fbo.clear(0.0, 0.0, 0.0, 0.0)
            with self._pass(f"curtains {name}", "sky"):
                self._precip.draw_curtains(precip, cam, sky, small.size, self._exposure)
            self._upsample(small, target, over=True)
        # Fog over the ground last: it is the lowest thing in the sky, so what of it a ray
        # crosses lies before any cloud the ray reaches (from in it or above it alike).
        self._fog.draw(name, target.fbo, target.size, cam, sky, self._exposure)

    def _draw_near_depth(self, frame: FrameScene) -> None:
        """The `near_depth` layer, at `near`'s size: at each pixel the distance to the nearest
        of the frame's near sprites that shows there, as near_depth.glsl encodes it. The
        towers, curtains and fog the layer also holds have none (their pixels read as no
        sprite): a host places those at the frame's near_distance_m (scene/near_depth.py)."""
        cam = frame.camera
        w, h = near_depth_size(self._targets["near"].size)
        metres = self._target("near_depth_m", w, h, components=1, dtype="f4")
        draw = frame.near
        view, proj = cam.view_matrix(), cam.projection_matrix()
        # The far band (most of the sprites, the farthest) at its own coarse resolution, as
        # `_draw_near` draws its colour: the depth of its clouds, stretched (nearest) under the
        # rest's. Drawn at the depth layer's size it cost as much as the whole near pass.
        far_count = min(frame.near_far_count, len(draw))
        far_size = far_band_size(self._targets["near"].size, cam)
        metres.fbo.use()
        metres.fbo.clear(NEAR_DEPTH_NONE, 0.0, 0.0, 0.0)
        start = 0
        if far_count > 0 and far_size is not None:
            fw, fh = far_size
            if fw < w and fh < h:
                far = self._target("near_depth_far_m", fw, fh, components=1, dtype="f4")
                far.fbo.use()
                far.fbo.clear(NEAR_DEPTH_NONE, 0.0, 0.0, 0.0)
                band = draw.slice(0, far_count)
                self._draw_sprites(
                    far, band, cam.position_m, view, proj, None, FAR_BAND_SHAPE, depth=True
                )
                self._upsample(far, metres, nearest=True)
            else:  # the band's resolution is finer than the layer's: straight into it
                band = draw.slice(0, far_count)
                self._draw_sprites(
                    metres, band, cam.position_m, view, proj, None, FAR_BAND_SHAPE, depth=True
                )
            start = far_count
        if start < len(draw):
            part = draw if start == 0 else draw.slice(start, len(draw))
            self._draw_sprites(
                metres, part, cam.position_m, view, proj, None, "polygon", depth=True
            )
        out = self._target("near_depth", w, h, dtype="f1")
        out.fbo.use()
        self.ctx.disable(moderngl.BLEND)
        metres.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        metres.texture.use(0)
        _set(self._near_depth_prog, "u_depth", 0)
        with self._pass("near depth encode", "upsample"):
            self._near_depth_vao.render(moderngl.TRIANGLES, vertices=3)

    def _legacy_clear(
        self, rgba: tuple[float, float, float, float]
    ) -> tuple[float, float, float, float]:
        """A premultiplied display-referred legacy colour (the in-cloud veil) as the layer
        holds it: what display.glsl's legacy_output makes of it."""
        alpha = float(rgba[3])
        if alpha <= 0.0 or (
            self.output == "display" and self._exposure == exposure.LEGACY_EXPOSURE
        ):
            return rgba
        straight = exposure.from_legacy(np.asarray(rgba[:3], np.float64) / alpha)
        if self.output == "display":
            straight = exposure.display(straight, self._exposure)
        r, g, b = (float(v) * alpha for v in straight)
        return (r, g, b, alpha)

    def _draw_run(
        self,
        target: _Target,
        draw: SpriteDraw,
        start: int,
        stop: int,
        towers: list[Drawable],
        cam: Camera,
        sky: SkyParams | None,
        shape: str,
    ) -> None:
        """Sprites start..stop of `draw` over what `target` holds, each of `towers` (back to
        front) after the sprites farther than it."""
        view, proj = cam.view_matrix(), cam.projection_matrix()
        eye = cam.position_m
        haze_m = math.inf if sky is None else sky.haze_m
        haze_top_m = math.inf if sky is None else sky.haze_top_m
        if not towers or sky is None:
            part = draw if (start, stop) == (0, len(draw)) else draw.slice(start, stop)
            self._draw_sprites(target, part, eye, view, proj, None, shape, haze_m, haze_top_m)
            return
        view_rot = np.ascontiguousarray(view[:3, :3].T, dtype=np.float32).tobytes()
        projection = np.ascontiguousarray(proj.T, dtype=np.float32).tobytes()
        for item in towers:
            cut = max(start, min(item.tower.insert_at, stop))
            self._draw_sprites(
                target, draw.slice(start, cut), eye, view, proj, None, shape, haze_m, haze_top_m
            )
            target.fbo.use()
            _set(self.shaders.program("tower_quad.glsl"), "u_exposure", self._exposure)
            with self._pass(f"towers {_sprite_pass_name(target.name)}", "small_sprites"):
                self._towers.draw(item, cam, view_rot, projection, sky)
            start = cut
        self._draw_sprites(
            target, draw.slice(start, stop), eye, view, proj, None, shape, haze_m, haze_top_m
        )

    def render_ring(
        self,
        ring: RingScene,
        indices: range | list[int] | tuple[int, ...] | None = None,
        ring_set: int = 0,
    ) -> None:
        """Draw ring impostors (all 8 unless given), each from the ring centre, into texture
        set 0 or 1 (`ring_target_name`): a new ring is drawn into the set not on show."""
        chosen = list(indices if indices is not None else range(RING_SIZE))
        empty = all(len(ring.impostors[i]) == 0 for i in chosen)
        if empty and len(chosen) == RING_SIZE and ring_set in self._clear_ring_sets:
            return  # already all clear: an empty ring (before the first, or direct mode)
        if empty and len(chosen) == RING_SIZE:
            self._clear_ring_sets.add(ring_set)
        else:
            self._clear_ring_sets.discard(ring_set)
        for i in chosen:
            self._draw_impostor(ring, i, ring_set, 0, len(ring.impostors[i]))
        self._check("rendering the impostor ring")

    def render_impostor_slice(
        self, ring: RingScene, index: int, start: int, stop: int, ring_set: int
    ) -> None:
        """Draw sprites start..stop of impostor `index` (back to front) over the ones drawn
        before, for a rebuild spread over frames (`ring_schedule.ImpostorSlice`): start 0
        begins the impostor, stop at its last sprite completes it. One impostor at a time per
        ring set, its slices in order."""
        self._clear_ring_sets.discard(ring_set)
        self._draw_impostor(ring, index, ring_set, start, stop)
        self._check("rendering an impostor slice")

    def _draw_impostor(self, ring: RingScene, i: int, ring_set: int, start: int, stop: int) -> None:
        geo = ring.geometry
        draw = ring.impostors[i]
        target = self._target(ring_target_name(i, ring_set), self.ring_px, self.ring_px)
        rows = impostor_rows(self.ring_px, geo.top_m[i] - geo.bottom_m[i], geo.half_width_m)
        work = (
            target
            if rows >= self.ring_px
            else self._target(f"impostor_{ring_set}", self.ring_px, rows)
        )
        self._draw_sprites(
            work,
            draw if (start, stop) == (0, len(draw)) else draw.slice(start, stop),
            geo.centre_m,
            geo.view_matrix(i),
            geo.projection_matrix(i),
            clear_rgba=(0.0, 0.0, 0.0, 0.0) if start == 0 else None,
            shape=IMPOSTOR_SHAPE,
            haze_m=ring.haze_m,
            haze_top_m=ring.haze_top_m,
        )
        if work is not target and stop >= len(draw):
            self._upsample(work, target)

    def start_profile(self) -> PassProfiler:
        """Time and count the fragments of every pass from now on (each pass then waits for
        the GPU: a profiled frame is slower than a plain one)."""
        if self._profiler is None:
            self._profiler = PassProfiler(self.ctx, self._finish)
        return self._profiler

    def stop_profile(self) -> None:
        """Profile no more passes."""
        self._profiler = None

    def finish(self) -> None:
        """Wait for every GL command issued so far (GIL-free): a benchmark's stage ends here."""
        self._finish()

    def layer_size(self, name: str) -> tuple[int, int]:
        return self._targets[name].size

    @property
    def layer_format(self) -> str:
        """The segment format (`output/shm.py` LAYER_FORMATS) of this renderer's layers:
        "rgba8" for a display renderer, "rgba16f" (half floats) for a linear one."""
        return "rgba16f" if self.output == "linear" else "rgba8"

    def read_into(self, name: str, buffer: memoryview, rows: tuple[int, int] | None = None) -> None:
        """Copy a layer's pixels, top row first, into a writable buffer of w*h*B bytes (B = 4
        for a display renderer's RGBA8, 8 for a linear one's RGBA16F half floats, as they are
        held: `read_linear` widened to float32 is exactly them); `rows` (first, stop): only
        those rows, into their place in the buffer."""
        self._finish()  # wait for the drawing GIL-free, so the read itself only copies
        fbo = self._targets[name].fbo
        if self.output == "linear" and name != "near_depth":  # (that one is RGBA8 in both)
            dtype, pixel_bytes = "f2", 8
        else:
            dtype, pixel_bytes = "f1", 4
        if rows is None:
            fbo.read_into(buffer, components=4, alignment=1, dtype=dtype)
            return
        width = self.layer_size(name)[0]
        first, stop = rows
        part = buffer[first * width * pixel_bytes : stop * width * pixel_bytes]
        fbo.read_into(
            part, viewport=(0, first, width, stop - first), components=4, alignment=1, dtype=dtype
        )

    def target_framebuffer(self, name: str) -> moderngl.Framebuffer:
        """The framebuffer of a drawn layer, exactly its size (for the zero-copy slot copies,
        `texture_export.SlotTextures.copy`)."""
        return self._targets[name].fbo

    def read(self, name: str) -> npt.NDArray[np.uint8]:
        """A display layer as a (H, W, 4) uint8 array."""
        if self.output != "display":
            raise RenderError(f"read: this renderer's layers are {self.output}: use read_linear")
        w, h = self.layer_size(name)
        data = self._targets[name].fbo.read(components=4, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(h, w, 4).copy()

    def read_linear(self, name: str) -> npt.NDArray[np.float32]:
        """A linear renderer's layer as a (H, W, 4) float32 array of premultiplied
        scene-linear colour (the half floats it holds, widened)."""
        if self.output != "linear":
            raise RenderError(f"read_linear: this renderer's layers are {self.output}")
        w, h = self.layer_size(name)
        data = self._targets[name].fbo.read(components=4, alignment=2, dtype="f2")
        return np.frombuffer(data, np.float16).reshape(h, w, 4).astype(np.float32)

    def meter_log_average(self) -> float:
        """The log-average scene-linear luminance of the last frame's sky with its near layer
        over it (exposure.log_average_luminance), from a METER_SIZE grid of point samples
        drawn into a small target and read back (a few kilobytes); a display renderer's values
        are turned back into scene-linear colour at the exposure they were drawn with. For the
        automatic exposure (exposure.AutoExposure), after `render_frame`."""
        sky, near = self._targets["sky"], self._targets["near"]
        meter = self._target("meter", *METER_SIZE)
        meter.fbo.use()
        self.ctx.disable(moderngl.BLEND)
        for unit, source in enumerate((sky, near)):
            source.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            source.texture.use(unit)
        _set(self._meter_prog, "u_sky", 0)
        _set(self._meter_prog, "u_near", 1)
        _set(self._meter_prog, "u_target_size", (float(METER_SIZE[0]), float(METER_SIZE[1])))
        with self._pass("meter", "upsample"):
            self._meter_vao.render(moderngl.TRIANGLES, vertices=3)
        w, h = METER_SIZE
        if self.output == "linear":
            rgb = self.read_linear("meter")[..., :3].astype(np.float64)
        else:
            display_rgb = self.read("meter")[..., :3].astype(np.float64) / 255.0
            rgb = exposure.display_inverse(display_rgb, self._exposure)
        return exposure.log_average_luminance(rgb.reshape(h, w, 3))

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for target in self._targets.values():
            target.release()
        self._targets.clear()
        for vao in self._sprite_vaos.values():
            vao.release()
        self._sky.release()
        self._towers.release()
        self._precip.close()
        self._fog.release()
        self._upsample_vao.release()
        self._near_depth_vao.release()
        self._meter_vao.release()
        self._instance_buf.release()
        self._corner_buf.release()
        self._sheet.release()
        self.shaders.release()
        if self._own_ctx:
            self.ctx.release()

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- passes -----------------------------------------------------------------------

    def _draw_sky(self, name: str, cam: Camera, sky: SkyParams) -> None:
        """The sky without the moon and dome over the whole picture, then the variant with
        the dome over where it can show, and the one with everything over the moon's disc
        (sky.glsl: outside a feature the variants agree bit for bit); only what moved since
        the layer was drawn, a strip at a time while it drifts (`sky_layer.plan_sky`)."""
        target = self._target(name, cam.width_px, cam.height_px)
        feats = sky_textures.features(cam, sky)
        # A new physical table or overcast veil, when there is one.
        self._sky.use_atmosphere(sky.atmosphere, sky.cover)
        if not self.split_sky:
            parts = [("sky", feats, sky_textures.FULL_RECT)]
        else:
            parts = [
                (
                    "sky",
                    dataclasses.replace(
                        feats, moon=False, dome=False, sun=False, deck=False, halo=False
                    ),
                    sky_textures.FULL_RECT,
                )
            ]
            if feats.dome:
                rect = sky_textures.dome_rect_ndc(cam, sky)
                if rect is not None:
                    parts.append(
                        (
                            "sky dome",
                            dataclasses.replace(feats, moon=False, sun=False, halo=False),
                            rect,
                        )
                    )
            if feats.halo:
                rect = sky_textures.halo_rect_ndc(cam, sky)
                if rect is not None:
                    parts.append(
                        ("sky halo", dataclasses.replace(feats, moon=False, sun=False), rect)
                    )
            if feats.moon:
                rect = sky_textures.moon_rect_ndc(cam, sky)
                if rect is not None:
                    parts.append(("sky moon", dataclasses.replace(feats, sun=False), rect))
            if feats.sun:
                rect = sky_textures.sun_rect_ndc(cam, sky)
                if rect is not None:
                    parts.append(("sky sun", feats, rect))
        tolerances: dict[str, float] = {}
        if feats.dome:
            tol = sky_layer.dome_offset_tolerance(
                sky_textures.pixel_rad(cam),
                sky,
                cam.position_m[2],
                sky_textures.view_top_sin(cam),
            )
            tolerances = {f"u_dome_off{i}": tol for i in range(3)}
        new = [
            sky_layer.SkyPart.of(
                pass_name, part, rect, self._sky_uniforms(cam, sky, part, rect), tolerances
            )
            for pass_name, part, rect in parts
        ]
        draws, holds = sky_layer.plan_sky(self._sky_drawn.get(name), target.texture.glo, new)
        self._sky_drawn[name] = holds
        if not draws:
            return
        target.fbo.use()
        self.ctx.disable(moderngl.BLEND)
        for part, rect in draws:
            self._sky_draw(part.pass_name, part.feats, part.uniforms | {"u_rect": rect})

    def layer_bands(self, name: str) -> tuple[tuple[int, int, int], ...] | None:
        """For layers kept from frame to frame while nothing they show moves (the sky), the
        bands of rows they are drawn in, each (first row, stop row, serial; row 0 the top as
        the layer is read) with a serial that changes whenever the band is drawn again: a
        publisher names a band's pixels by it (`FrameWriter.keep_layer`) and copies only the
        bands drawn since its copy. Bands may share a row. None for layers drawn every frame."""
        drawn = self._sky_drawn.get(name)
        if drawn is None:
            return None
        firsts, stops = sky_layer.strip_columns(drawn.strip_rows(self.layer_size(name)[1]))
        return tuple(zip(firsts, stops, drawn.strip_serials, strict=True))

    def _sky_uniforms(
        self,
        cam: Camera,
        sky: SkyParams,
        feats: sky_textures.SkyFeatures,
        rect: sky_textures.Rect,
    ) -> dict[str, object]:
        right, up, fwd = cam.basis()
        camera = {
            "u_rect": rect,
            "u_target_size": (float(cam.width_px), float(cam.height_px)),
            "u_right": tuple(right),
            "u_up": tuple(up),
            "u_forward": tuple(fwd),
            "u_tan_half_fov": (cam.tan_half_fov_x, cam.tan_half_fov_y),
            "u_sun_dir": sky.sun.direction_enu,
            "u_zenith": sky.zenith_rgb,
            "u_horizon": sky.horizon_rgb,
            "u_ground": sky.ground_rgb,
            "u_sun_rgb": sky.sun_rgb,
            "u_sun_cos_radius": math.cos(math.radians(SUN_RADIUS_DEG)),
            "u_exposure": self._exposure,
        }
        if feats.physical:
            # The physical sky has no gradient; the dome fades into the haze's colour
            # (u_dome_haze_rgb) and glows with the sun's; the ground band (display values
            # only) keeps the ground's colour.
            for gone in (
                ("u_zenith", "u_horizon")
                + (("u_ground",) if feats.scene_linear else ())
                + (() if feats.dome else ("u_sun_rgb",))
                # The display variants' disc is the sun part's (the baked table has none).
                + (() if feats.scene_linear or feats.sun else ("u_sun_cos_radius",))
                + (
                    ()
                    if feats.scene_linear or feats.sun or feats.dome or feats.moon
                    else ("u_sun_dir",)
                )
            ):
                del camera[gone]
        return camera | sky_textures.frame_uniforms(cam, sky, feats)

    def _sky_draw(
        self, pass_name: str, feats: sky_textures.SkyFeatures, uniforms: dict[str, object]
    ) -> None:
        prog, vao = self._sky.prepare(feats)
        for uniform, value in uniforms.items():
            _set(prog, uniform, value)
        with self._pass(pass_name, "sky"):
            vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        if self._finish_each_draw:
            self._finish()

    def _upsample(
        self, source: _Target, dest: _Target, over: bool = False, nearest: bool = False
    ) -> None:
        """`source` stretched over `dest` (bilinear, or with `nearest` each pixel its source
        texel's: distances do not blend): in its place, or with `over`, composited over what
        `dest` holds (premultiplied)."""
        dest.fbo.use()
        if over:
            self.ctx.enable(moderngl.BLEND)
            self.ctx.blend_func = (moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        else:
            self.ctx.disable(moderngl.BLEND)
        filt = moderngl.NEAREST if nearest else moderngl.LINEAR
        source.texture.filter = (filt, filt)
        source.texture.repeat_x = source.texture.repeat_y = False
        source.texture.use(0)
        _set(self._upsample_prog, "u_source", 0)
        _set(self._upsample_prog, "u_target_size", (float(dest.size[0]), float(dest.size[1])))
        with self._pass(f"upsample {_sprite_pass_name(source.name)}", "upsample"):
            self._upsample_vao.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.disable(moderngl.BLEND)

    def _draw_sprites(
        self,
        target: _Target,
        draw: SpriteDraw,
        eye_m: tuple[float, float, float],
        view: npt.NDArray[np.float64],
        proj: npt.NDArray[np.float64],
        clear_rgba: tuple[float, float, float, float] | None = (0.0, 0.0, 0.0, 0.0),
        shape: str = "polygon",
        haze_m: float = math.inf,
        haze_top_m: float = math.inf,
        depth: bool = False,
    ) -> None:
        """`clear_rgba`: premultiplied colour under the sprites (the in-cloud fog veil); None
        draws over what the target holds. `shape`: "polygon" (fewest fragments) or "quad"
        (fewest triangles, for sprites a few pixels wide). `haze_m`, `haze_top_m`: the haze
        distance the sprites' colours were faded with and the top of its layer, MSL
        (SkyParams.haze_m, haze_top_m; `sky.haze_share`), by which their flat bases' shade
        fades too. `depth`: each fragment's distance instead of its colour, MIN-blended
        (the NEAR_DEPTH variants, `_draw_near_depth`)."""
        target.fbo.use()
        if clear_rgba is not None:
            target.fbo.clear(*clear_rgba)
        n = len(draw)
        if n == 0:
            return
        s = draw.sprites
        inst = np.empty((n, _INSTANCE_FLOATS), np.float32)
        inst[:, 0:3] = s.centre_m - np.asarray(eye_m)
        inst[:, 3] = s.size_m
        inst[:, 4] = s.rotation_rad
        inst[:, 5] = s.texture
        inst[:, 6:10] = draw.rgba[:, :4]
        # A zero normal is a sprite that faces the camera; others keep their own orientation.
        inst[:, 10:13] = 0.0 if draw.normals is None else draw.normals
        # The colour of the sprite's thin outer texels (SpriteDraw.rgba); negative: none.
        inst[:, 13:16] = draw.rgba[:, 4:7] if draw.rgba.shape[1] > 4 else -1.0
        # The flat base the sprite is cut at, over the eye (SpriteBatch.base_m).
        base = s.base_m
        based = ~np.isnan(base)  # (only the FLAT_BASE variant reads it)
        inst[:, 16] = np.where(based, base - np.float32(eye_m[2]), NO_BASE_M)
        # A deck's base over the eye, for its relief seen from below (0: not drawn so), and
        # where the deck has drifted to from the eye: its relief drifts with it (mod 64 km,
        # so float32 keeps a centimetre of it).
        deck = s.slab_m[:, 0] - np.float32(eye_m[2])
        under_deck = deck > 0.0  # NaN (no deck) compares False
        inst[:, 17:20] = 0.0
        if under_deck.any():  # (the drift is read, and cut, only for a deck's sprites)
            inst[under_deck, 17] = deck[under_deck]
            inst[under_deck, 18:20] = np.mod(
                np.asarray(eye_m[:2], np.float64) - s.drift_m[under_deck], _RELIEF_PERIOD_M
            )
        data = inst.tobytes()
        if len(data) > self._instance_buf.size:
            self._instance_buf.orphan(len(data) * 2)
        self._instance_buf.write(data)
        # GLSL matrices are column-major: hand it the transpose of numpy's row-major layout.
        view_rot = np.ascontiguousarray(view[:3, :3].T, dtype=np.float32).tobytes()
        projection = np.ascontiguousarray(proj.T, dtype=np.float32).tobytes()
        runs = _variant_runs(_variants(draw, eye_m, under_deck, based))
        if depth:
            runs = [(start, stop, code | _NEAR_DEPTH) for start, stop, code in runs]
        # The depth variants read none of the colour's uniforms, which their compiler drops.
        put, put_bytes = (_set_if_read, _write_if_read) if depth else (_set, _write)
        for code in {code for _, _, code in runs}:
            prog = self._sprite_variant(code)[0]
            put_bytes(prog, "u_view_rot", view_rot)
            put_bytes(prog, "u_proj", projection)
            put(prog, "u_sheet", 0)
            put(prog, "u_viewport_px", float(target.size[0]))
            put(prog, "u_exposure", self._exposure)
            # The shader takes 1/haze (0: no haze) so an endless one needs no infinity.
            put(prog, "u_inv_haze_m", 0.0 if not math.isfinite(haze_m) else 1.0 / haze_m)
            clear_m = max(haze_m, CLEAR_AIR_HAZE_M)
            put(prog, "u_inv_clear_haze_m", 0.0 if not math.isfinite(clear_m) else 1.0 / clear_m)
            top_up = haze_top_m - float(eye_m[2])
            put(prog, "u_haze_top_up_m", top_up if math.isfinite(top_up) else 1e9)
        self._sheet.filter = (_SHAPES[shape][2], moderngl.LINEAR)
        self._sheet.use(0)
        self.ctx.enable(moderngl.BLEND)
        if depth:
            self.ctx.blend_equation = (moderngl.MIN, moderngl.MIN)
            self.ctx.blend_func = (moderngl.ONE, moderngl.ONE)
        else:
            self.ctx.blend_func = (moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        kind = "sprites" if shape == "polygon" else "small_sprites"
        with self._pass("near depth" if depth else _sprite_pass_name(target.name), kind):
            # In order, each run of sprites with the variant it needs (back to front holds).
            for start, stop, code in runs:
                prog, vao = self._sprite_variant(code)
                self._bind_instances(vao, prog, start)
                vao.render(
                    moderngl.TRIANGLE_STRIP,
                    vertices=_SHAPES[shape][1],
                    first=_SHAPES[shape][0],
                    instances=stop - start,
                )
        self.ctx.disable(moderngl.BLEND)
        if depth:
            self.ctx.blend_equation = (moderngl.FUNC_ADD, moderngl.FUNC_ADD)
        # Wait for this draw here, GIL-free, rather than inside the next GL call with the GIL
        # held (see gil_free_finish).
        if self._finish_each_draw:
            self._finish()

    # -- plumbing ---------------------------------------------------------------------

    def _sprite_variant(self, code: int) -> tuple[moderngl.Program, moderngl.VertexArray]:
        """The sprite program of a variant code (`_variants`) and its vertex array, made and
        given its constants at the first call."""
        prog = self._sprite_progs.get(code)
        if prog is None:
            prog = self.shaders.program(
                "sprites.glsl",
                self._sprite_defines
                | {
                    "ROUND_MIX": str(int(bool(code & _MIXING))),
                    "DECK": str(int(bool(code & _DECK))),
                    "FLAT_BASE": str(int(bool(code & _FLAT_BASE))),
                    "NEAR_DEPTH": str(int(bool(code & _NEAR_DEPTH))),
                },
            )
            polygons, boxes, shades = self._sprite_constants
            put = _write_if_read if code & _NEAR_DEPTH else _write
            put(prog, "u_polygon", polygons)
            put(prog, "u_box", boxes)
            put(prog, "u_cell_shade", shades)
            self._sprite_progs[code] = prog
            self._sprite_vaos[code] = self._make_sprite_vao(prog)
        return prog, self._sprite_vaos[code]

    def _make_sprite_vao(self, prog: moderngl.Program) -> moderngl.VertexArray:
        vao = self.ctx.vertex_array(prog, [(self._corner_buf, "2f", "in_corner")])
        self._bind_instances(vao, prog, 0)
        return vao

    def _bind_instances(
        self, vao: moderngl.VertexArray, prog: moderngl.Program, first: int
    ) -> None:
        """Point the per-instance attributes at instance `first` of the instance buffer (GL
        3.3 has no base instance)."""
        stride = _INSTANCE_FLOATS * 4
        for name, fmt, offset in _INSTANCE_LAYOUT:
            member = prog.get(name, None)
            if member is None:
                continue  # a variant that never reads it (in_deck outside DECK)
            assert isinstance(member, moderngl.Attribute)
            vao.bind(
                member.location,
                "f",
                self._instance_buf,
                fmt,
                offset=first * stride + offset * 4,
                stride=stride,
                divisor=1,
            )

    def _target(
        self, name: str, width: int, height: int, components: int = 4, dtype: str | None = None
    ) -> _Target:
        """A drawing target; `dtype` None: the picture layers' (the renderer's output)."""
        target = self._targets.get(name)
        if target is not None and target.size == (width, height):
            return target
        if target is not None:
            target.release()
        # Float layers hold scene-linear colour, beyond 1 (half floats: to 65504).
        if dtype is None:
            dtype = "f2" if self.output == "linear" else "f1"
        tex = self.ctx.texture((width, height), components, dtype=dtype)
        target = _Target(name, tex, self.ctx.framebuffer(color_attachments=[tex]))
        self._targets[name] = target
        return target

    def _pass(self, name: str, kind: str) -> contextlib.AbstractContextManager[None]:
        if self._profiler is None:
            return contextlib.nullcontext()
        return self._profiler.measure(name, kind)

    def _check(self, what: str) -> None:
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            raise RenderError(f"GL error while {what}: {err}")


def far_band_size(near_px: tuple[int, int], cam: Camera) -> tuple[int, int] | None:
    """The far band's target for a near layer of `near_px` (FAR_BAND_PX_PER_DEG), or None
    where it would save less than FAR_BAND_MAX_SCALE (the band is then drawn at full size)."""
    w, h = near_px
    scale = FAR_BAND_PX_PER_DEG / (w / cam.fov_deg)
    if scale > FAR_BAND_MAX_SCALE:
        return None
    return max(1, round(w * scale)), max(1, round(h * scale))


def near_depth_size(near_px: tuple[int, int]) -> tuple[int, int]:
    """The `near_depth` layer's size: half the near layer's each way (rounded up). The depth
    of soft clouds changes slowly across the picture; its fill would cost as much as the
    near layer's own at full size."""
    w, h = near_px
    return max(1, (w + 1) // NEAR_DEPTH_DIVISOR), max(1, (h + 1) // NEAR_DEPTH_DIVISOR)


def near_layer_size(cam: Camera, near_scale: float = NEAR_SCALE) -> tuple[int, int]:
    """The near layers' size for a camera: its picture's at near_scale (at most 1)."""
    scale = min(near_scale, 1.0)
    return max(1, round(cam.width_px * scale)), max(1, round(cam.height_px * scale))


def impostor_rows(ring_px: int, window_height_m: float, half_width_m: float) -> int:
    """Rows to draw an impostor at before it is stretched to ring_px square: its window is
    usually much wider than tall (a layer seen edge-on), and drawn square its texels would be
    4 to 8 times finer down than across, every sprite a sliver that costs its vertex work
    and more fragments than it shows. IMPOSTOR_TEXEL_ASPECT times the rows of square texels,
    at most ring_px."""
    square_rows = ring_px * window_height_m / (2.0 * half_width_m)
    return max(IMPOSTOR_MIN_ROWS, min(ring_px, math.ceil(IMPOSTOR_TEXEL_ASPECT * square_rows)))


def turning_round(draw: SpriteDraw, eye_m: tuple[float, float, float]) -> npt.NDArray[np.bool_]:
    """Per sprite, whether it is a flat-bottomed one part-way through turning into the round
    one (sprites.glsl's round_mix strictly between 0 and 1): those need the second read."""
    s = draw.sprites
    flat = np.abs(s.texture - TEX_FLAT_BOTTOM[0]) < 0.5
    if draw.normals is not None:  # a sprite with a fixed orientation never turns
        flat &= np.einsum("ij,ij->i", draw.normals, draw.normals) <= 0.25
    if not flat.any():
        return flat
    rel = s.centre_m[flat] - np.asarray(eye_m)
    sine = np.abs(rel[:, 2]) / np.maximum(np.linalg.norm(rel, axis=1), 1e-3)
    t = np.clip((sine - ROUND_FROM) / (ROUND_TO - ROUND_FROM), 0.0, 1.0)
    mix = t * t * (3.0 - 2.0 * t)
    out = np.zeros(len(s), np.bool_)
    out[flat] = (mix > ROUND_SNAP) & (mix < 1.0 - ROUND_SNAP)
    return out


def _glsl_floats(values: tuple[float, ...]) -> str:
    """A GLSL float array constructor of the values, for a define."""
    return f"float[{len(values)}](" + ", ".join(repr(float(v)) for v in values) + ")"


def _variants(
    draw: SpriteDraw,
    eye_m: tuple[float, float, float],
    under_deck: npt.NDArray[np.bool_],
    based: npt.NDArray[np.bool_],
) -> npt.NDArray[np.int8]:
    """(N,) each sprite's shader variant: _MIXING for the second read of a flat-bottomed
    sprite turning round, _DECK for a deck's sprite seen from under its base, _FLAT_BASE for
    a heaped cloud's sprite cut at its flat base."""
    codes = turning_round(draw, eye_m).astype(np.int8)
    if under_deck.any():
        codes |= under_deck.astype(np.int8) * np.int8(_DECK)
    if based.any():
        codes |= based.astype(np.int8) * np.int8(_FLAT_BASE)
    return codes


def _variant_runs(codes: npt.NDArray[np.int8]) -> list[tuple[int, int, int]]:
    """(start, stop, variant) for each run of one variant, in order; past MAX_VARIANT_RUNS,
    the runs of the variant holding every deck and flat-base feature any sprite needs (the
    second texture read of a turning sprite stays its own: few sprites need it)."""
    n = len(codes)
    if n == 0 or not codes.any():
        return [(0, n, 0)]
    edges = np.flatnonzero(np.diff(codes)) + 1
    if len(edges) >= MAX_VARIANT_RUNS:
        shared = np.bitwise_or.reduce(codes) & np.int8(_DECK | _FLAT_BASE)
        codes = codes | shared
        edges = np.flatnonzero(np.diff(codes)) + 1
    starts = np.concatenate(([0], edges))
    stops = np.concatenate((edges, [n]))
    return [(int(a), int(b), int(codes[a])) for a, b in zip(starts, stops, strict=True)]


def _sprite_pass_name(target: str) -> str:
    if target.startswith(("ring_", "impostor_")):
        return "impostor"
    return target


# The corner buffer: 8 vertices for a texture's support polygon (sprites.glsl takes their
# corners from its u_polygon by gl_VertexID), then the corners of its bounding box as a
# triangle strip.
_QUAD_STRIP = np.array([[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]], np.float32)
# Per sprite shape: (first vertex, vertices) in the corner buffer, and how the sheet is read.
# Polygons are for sprites many pixels wide, read trilinearly; quads for sprites a few pixels
# wide (the far band, impostors), read from one mip level bilinearly: about a fifth less time
# for those passes, and no difference to the eye side by side (tools/gallery/compare_frames.py).
_SHAPES = {
    "polygon": (0, 8, moderngl.LINEAR_MIPMAP_LINEAR),
    "quad": (8, 4, moderngl.LINEAR_MIPMAP_NEAREST),
}
