"""Convective towers (issue 17, item 4; docs/towers.md): each tower's lit automaton steps
(`tower_field.LitVolume`) as two 3D textures, marched into an impostor of its own
(tower_march.glsl), which the near layer draws as one quad between the sprites at the tower's
distance (tower_quad.glsl).

A CPU renderer cannot march a volume over the screen every frame (a tower a quarter of the
picture high is some five million texture reads), so, as the issue asks of CPU renderers, an
impostor is drawn again only when what it shows changes: the tower reaches its next
automaton step (every 10 s of sim time), the sky's light changes, or the eye has moved round
the tower by more than VIEW_TOLERANCE_DEG or toward it enough to need more texels. Between
steps the impostors of the two steps around the tower's age are cross-faded, so it grows
continuously. `budget` caps how many impostors a frame draws (the daemon: one; a snapshot:
every one it needs); a tower waiting for its turn shows what it showed before.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field

import moderngl
import numpy as np
import numpy.typing as npt

from wxsky.render.context import release_framebuffer
from wxsky.render.shaders import ShaderLibrary
from wxsky.scene.camera import Camera
from wxsky.scene.lightning import FLASH_RGB
from wxsky.scene.shading_harris import EXPOSURE, TOE, WHITEN_FROM, WHITEN_TO, scene_lights
from wxsky.scene.sky import SkyParams
from wxsky.scene.tower_field import MAX_LIGHTS, OCCUPIED_FLOOR, LitVolume, TowerShow
from wxsky.scene.tower_shading import view_weights
from wxsky.towers.volume import STEP_S, TowerSpec

MARCH_STEPS = 40  # samples along a ray through the cloudy part of the box: one in 1-2 cells
VIEW_TOLERANCE_DEG = 10.0
SIZE_TOLERANCE = 1.5  # texels wanted over texels drawn (or under) before drawing it again
IMPOSTOR_MIN_PX = 16
TEXEL_SHARE = 0.6
IMPOSTOR_MAX_PX = 256
# Lit steps kept as textures, bounded by their bytes (2 MiB each at 64^3, 16 MiB at 128^3; on
# llvmpipe they are the process's memory): the least recently drawn go first, keeping at
# least VOLUMES_MIN (a pair for each of the most towers a frame shows, and the next step).
VOLUMES_KEPT_BYTES = 64 << 20
VOLUMES_MIN = 3 * 8
NOISE_TEXELS = 32
# The detail noise repeats every this many of the tower's cells (1.1 km for a congestus's
# 70 m cells): billows a quarter, an eighth and a sixteenth of that (`detail_noise`), lobes
# of 70-280 m on the automaton's bubbles; a cumulonimbus's are as much larger. At 8 cells
# (issue 17) the billows were 70-140 m, a speckle at 5 km where a pilot sees cauliflower.
NOISE_TILE_CELLS = 16.0
EROSION = 0.6
# The view's extinction over the light's, and how sharply thin cloud firms up (the shader's
# smoothstep, 0.15-0.35 of full density): a cumulus tower's edge is a hard, opaque outline a
# cell or two deep, not a fringe fading over a few hundred metres (at 6 and 0-0.5 before
# issue 42 the volumes were soft, see-through blobs beside the sprite clouds' crisp ones).
VIEW_EXTINCTION = 20.0
SHARPEN = 1.0
# The billows' own shade: a point where the detail noise rises over BILLOW_PROBE_M toward the
# key light is on a billow's far side from it, its direct light cut by exp(-BILLOW_SHADOW x
# the rise). The lit cells (40-160 m) hold the tower's shade, not its billows': without it a
# tower's inside is an even blend, a cotton ball where a pilot sees cauliflower.
# (3 and 80 m for the finer billows before; the probe is about half a lobe.)
BILLOW_SHADOW = 5.0
BILLOW_PROBE_M = 160.0
# A new quad covers the cloudy part of the box and this much more of its size on each side,
# so a growing tower keeps its quad (and the image of the step before) for a while.
GROWTH_ROOM = 0.1
# Texels a frame marches in the daemon: about 2-3 ms of a 2-core CPU renderer's time.
SLICE_TEXELS = 4096

F64 = npt.NDArray[np.float64]


@dataclass
class _Quad:
    """An upright quad through the middle of the box part lo..hi (metres from the box's
    middle), facing the eye as it was at `view_dir`, `size` texels."""

    view_dir: F64
    centre_m: F64
    axis_u: F64  # half extents, metres
    axis_v: F64
    lo: F64
    hi: F64
    size: tuple[int, int]


@dataclass
class _Image:
    """One lit step marched onto the quad, row band by row band (`rows_done`)."""

    key: tuple[object, ...]
    step: int
    volume: LitVolume
    eye_rel: F64  # the eye from the box's middle when the image was begun
    texture: moderngl.Texture
    fbo: moderngl.Framebuffer
    rows_done: int = 0

    @property
    def complete(self) -> bool:
        return bool(self.rows_done >= int(self.texture.size[1]))

    def release(self) -> None:
        release_framebuffer(self.fbo)
        self.texture.release()


@dataclass
class _Impostor:
    quad: _Quad
    images: list[_Image] = field(default_factory=list)

    def complete(self) -> list[_Image]:
        return sorted((im for im in self.images if im.complete), key=lambda im: im.step)

    def release(self) -> None:
        for image in self.images:
            image.release()
        self.images.clear()


@dataclass
class Drawable:
    """A tower ready to draw: its quad, the two images to cross-fade and how far."""

    tower: TowerShow
    quad: _Quad
    first: moderngl.Texture
    second: moderngl.Texture
    mix: float


class TowerPass:
    """The towers' textures, impostors and the two programs; `release()` frees them."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        self._shaders = shaders
        # Two marches: Harris's curve under the gradient sky, the shared tone map under the
        # physical one (CLOUD_DISPLAY_SHARED, shading_harris.shown_channels); each made when
        # first drawn with.
        self._marches: dict[bool, tuple[moderngl.Program, moderngl.VertexArray]] = {}
        self._quad = shaders.program("tower_quad.glsl")
        self._quad_vao = ctx.vertex_array(self._quad, [])
        self._volumes: OrderedDict[tuple[object, ...], tuple[moderngl.Texture3D, ...]] = (
            OrderedDict()
        )
        self._volume_bytes = 0  # of the textures in _volumes
        self._noise = ctx.texture3d((NOISE_TEXELS,) * 3, 1, detail_noise(NOISE_TEXELS).tobytes())
        self._noise.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self._shown: dict[TowerSpec, _Impostor] = {}  # what each tower shows
        self._next: dict[TowerSpec, _Impostor] = {}  # a new quad being drawn for it
        # Texels a frame marches at most (None: every one needed at once, as a snapshot
        # wants); the daemon spreads a tower's images over frames (SLICE_TEXELS).
        self.slice_texels: int | None = None
        self.erosion = EROSION  # how much the detail noise eats into thin cloud (0: none)
        # Extinction toward the eye over the slice light's: a cumulus's edge is sharper than
        # its light is soft (1: the same, as numpy's tower colours composite).
        self.view_extinction = VIEW_EXTINCTION
        self.sharpen = SHARPEN  # 0..1: how much thin cloud firms up toward the eye
        self.billow_shadow = BILLOW_SHADOW  # how deep a billow's own shade goes (0: none)
        self.march_steps = MARCH_STEPS
        self.drawn = 0  # images completed, for tests and the bench
        # Towers of the last frame that could not be drawn: no lit step yet, or their first
        # image still being marched (the bench's lead-in waits for none).
        self.behind = 0

    def prepare(
        self, towers: tuple[TowerShow, ...], cam: Camera, sky: SkyParams, layer_width_px: int
    ) -> list[Drawable]:
        """March what the frame's towers need (within `slice_texels`, nearest tower first)
        and return those that can be drawn, back to front as `towers` are. A tower whose new
        images are not complete shows the ones it has."""
        left = math.inf if self.slice_texels is None else float(self.slice_texels)
        eye = np.asarray(cam.position_m, np.float64)
        px_per_rad = layer_width_px / math.radians(cam.fov_deg)
        # Towers with nothing to show first, then the rest; the nearest first in each.
        order = sorted(towers, key=lambda t: (t.spec in self._shown, t.distance_m))
        for tower in order:
            if tower.ready and left > 0:
                left = self._work(tower, eye, sky, px_per_rad, left)
        out = []
        self.behind = 0
        for tower in towers:
            drawable = self._drawable(tower)
            if drawable is not None:
                out.append(drawable)
            else:
                self.behind += 1
        shown = {t.spec for t in towers}
        for table in (self._shown, self._next):
            for spec in [s for s in table if s not in shown]:
                table.pop(spec).release()
        return out

    def draw(
        self, item: Drawable, cam: Camera, view_rot: bytes, projection: bytes, sky: SkyParams
    ) -> None:
        """The tower's quad over what the bound framebuffer holds."""
        item.first.use(0)
        item.second.use(1)
        prog = self._quad
        _write(prog, "u_view_rot", view_rot)
        _write(prog, "u_proj", projection)
        quad = item.quad
        centre = np.asarray(item.tower.centre_m) + quad.centre_m - np.asarray(cam.position_m)
        _set(prog, "u_centre", _vec(centre))
        _set(prog, "u_axis_u", _vec(quad.axis_u))
        _set(prog, "u_axis_v", _vec(quad.axis_v))
        _set(prog, "u_first", 0)
        _set(prog, "u_second", 1)
        _set(prog, "u_mix", float(item.mix))
        _set(prog, "u_haze", float(item.tower.haze))
        _set(prog, "u_haze_rgb", _vec(sky.haze_rgb))
        _set(prog, "u_alpha", float(item.tower.alpha))
        _set(prog, "u_flash_rgb", tuple(float(c) * item.tower.flash for c in FLASH_RGB))
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = (moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        self._quad_vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        self.ctx.disable(moderngl.BLEND)

    def release(self) -> None:
        for table in (self._shown, self._next):
            for imp in table.values():
                imp.release()
            table.clear()
        for textures in self._volumes.values():
            for tex in textures:
                tex.release()
        self._volumes.clear()
        self._volume_bytes = 0
        self._noise.release()
        for _, vao in self._marches.values():
            vao.release()
        self._marches.clear()

    # -- internals ---------------------------------------------------------------------------

    def _textures(self, volume: LitVolume) -> tuple[moderngl.Texture3D, ...]:
        found = self._volumes.get(volume.key)
        if found is not None:
            self._volumes.move_to_end(volume.key)
            return found
        _, nz, ny, nx, _ = volume.texels.shape
        made = []
        for part in volume.texels:
            tex = self.ctx.texture3d((nx, ny, nz), 4, np.ascontiguousarray(part).tobytes())
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = tex.repeat_z = False
            made.append(tex)
        self._volumes[volume.key] = tuple(made)
        self._volume_bytes += volume.texels.nbytes
        while self._volume_bytes > VOLUMES_KEPT_BYTES and len(self._volumes) > VOLUMES_MIN:
            for tex in self._volumes.popitem(last=False)[1]:
                self._volume_bytes -= tex.size[0] * tex.size[1] * tex.size[2] * tex.components
                tex.release()
        return tuple(made)

    def _work(
        self, tower: TowerShow, eye: F64, sky: SkyParams, px_per_rad: float, left: float
    ) -> float:
        """Advance the tower's images by at most `left` texels; returns what is left."""
        spec = tower.spec
        rel = eye - np.asarray(tower.centre_m, np.float64)
        lo, hi = _occupied_m(tower)
        shown = self._shown.get(spec)
        target = self._next.get(spec) or shown
        if target is None or not _fits(target.quad, rel, lo, hi, px_per_rad):
            if target is not None and target is self._next.get(spec):
                self._next.pop(spec).release()
            target = _Impostor(_quad_for(rel, lo, hi, px_per_rad))
            if shown is None:
                self._shown[spec] = target
            else:
                self._next[spec] = target
        wanted = {v.key: v for v in tower.volumes}
        for image in target.images:
            if not image.complete and image.key not in wanted:
                target.images.remove(image)  # begun for a step no longer wanted
                image.release()
        held = {im.key for im in target.images}
        for key, volume in wanted.items():
            if key not in held:
                target.images.append(self._begin(target.quad, volume, rel))
        for image in sorted(target.images, key=lambda im: im.step):
            if left <= 0:
                break
            if not image.complete:
                left = self._march_rows(image, target.quad, tower.spec, sky, left)
        shown = self._shown.get(spec)
        if target is not shown and any(im.complete and im.key in wanted for im in target.images):
            # The new quad has a step to show: it replaces the old one.
            if shown is not None:
                shown.release()
            self._shown[spec] = self._next.pop(spec)
        # Steps before the first one wanted are gone once a wanted one is complete.
        if any(im.complete and im.key in wanted for im in target.images):
            for image in [im for im in target.images if im.complete and im.key not in wanted]:
                target.images.remove(image)
                image.release()
        return left

    def _drawable(self, tower: TowerShow) -> Drawable | None:
        imp = self._shown.get(tower.spec)
        if imp is None:
            return None
        done = imp.complete()
        if not done:
            return None
        wanted = [v.key for v in tower.volumes]
        pair = [im for im in done if im.key in wanted] or done[-1:]
        first, second = pair[0], pair[-1]
        mix = 0.0
        if second.step == first.step + 1:
            mix = min(max(tower.age_s / STEP_S - first.step, 0.0), 1.0)
        return Drawable(tower, imp.quad, first.texture, second.texture, mix)

    def _begin(self, quad: _Quad, volume: LitVolume, eye_rel: F64) -> _Image:
        tex = self.ctx.texture(quad.size, 4)
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        tex.repeat_x = tex.repeat_y = False
        fbo = self.ctx.framebuffer(color_attachments=[tex])
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        return _Image(volume.key, volume.step, volume, eye_rel.copy(), tex, fbo)

    def _march(self, physical: bool) -> tuple[moderngl.Program, moderngl.VertexArray]:
        made = self._marches.get(physical)
        if made is None:
            prog = self._shaders.program(
                "tower_march.glsl",
                {
                    "EXPOSURE": repr(EXPOSURE),
                    "TOE": repr(TOE),
                    "WHITEN_FROM": repr(WHITEN_FROM),
                    "WHITEN_TO": repr(WHITEN_TO),
                    "DENSITY_FLOOR": repr(OCCUPIED_FLOOR),
                    "BILLOW_PROBE_M": repr(BILLOW_PROBE_M),
                    "CLOUD_DISPLAY_SHARED": str(int(physical)),
                },
            )
            made = (prog, self.ctx.vertex_array(prog, []))
            self._marches[physical] = made
        return made

    def _march_rows(
        self, image: _Image, quad: _Quad, spec: TowerSpec, sky: SkyParams, left: float
    ) -> float:
        """March the next rows of `image`, as many as `left` texels allow (one at least)."""
        width, height = quad.size
        rows = height - image.rows_done
        if math.isfinite(left):
            rows = int(min(rows, max(1, left // width)))
        vx, vy, vz = (float(c) for c in quad.view_dir)
        weights, ambient = view_weights(sky, (vx, vy, vz), spec.base_m + 0.5 * spec.height_m)
        padded = np.zeros((MAX_LIGHTS, 3), np.float32)  # lights a sky lacks add nothing
        padded[: len(weights)] = weights
        prog, vao = self._march(sky.atmosphere is not None)
        _set(prog, "u_light0", 0)
        _set(prog, "u_light1", 1)
        _set(prog, "u_noise", 2)
        _set(prog, "u_eye", _vec(image.eye_rel))
        _set(prog, "u_centre", _vec(quad.centre_m))
        _set(prog, "u_axis_u", _vec(quad.axis_u))
        _set(prog, "u_axis_v", _vec(quad.axis_v))
        half = 0.5 * np.asarray(spec.box_size_m)
        _set(prog, "u_half", _vec(half))
        # The rays are marched inside the box only: beyond it the textures' clamped edge
        # would hang the floor's cloud down to the ground.
        _set(prog, "u_lo", _vec(np.maximum(quad.lo, -half)))
        _set(prog, "u_hi", _vec(np.minimum(quad.hi, half)))
        _write(prog, "u_weights", padded.tobytes())
        _set(prog, "u_ambient", _vec(ambient))
        _set(prog, "u_ext_per_m", self.view_extinction * spec.extinction_per_cell / spec.cell_m)
        tile_m = NOISE_TILE_CELLS * spec.cell_m
        _set(prog, "u_noise_per_m", 1.0 / tile_m)
        # Billows finer than two texels of the image would alias into a pattern: the detail
        # fades out as the tower's image gets coarser than an eighth of the tile.
        texel_m = 2.0 * float(np.linalg.norm(quad.axis_u)) / quad.size[0]
        detail = min(1.0, max(0.0, 2.0 - texel_m / (tile_m / 8.0)))
        _set(prog, "u_erosion", float(self.erosion) * detail)
        _set(prog, "u_sharpen", float(self.sharpen))
        key = np.asarray(scene_lights(sky).directions[0], np.float64)
        _set(prog, "u_key_dir", _vec(key / max(float(np.linalg.norm(key)), 1e-9)))
        _set(prog, "u_billow_shadow", float(self.billow_shadow) * detail)
        _set(prog, "u_steps", int(self.march_steps))
        light0, light1 = self._textures(image.volume)
        light0.use(0)
        light1.use(1)
        self._noise.use(2)
        self.ctx.disable(moderngl.BLEND)
        image.fbo.use()
        self.ctx.scissor = (0, image.rows_done, width, rows)
        vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        self.ctx.scissor = None
        image.rows_done += rows
        if image.complete:
            self.drawn += 1
        return left - rows * width


def _occupied_m(tower: TowerShow) -> tuple[F64, F64]:
    """The part of the box the tower's steps fill, metres from the box's middle."""
    box = np.asarray(tower.spec.box_size_m)
    lo = np.min([v.occupied[0] for v in tower.volumes], axis=0)
    hi = np.max([v.occupied[1] for v in tower.volumes], axis=0)
    return (lo - 0.5) * box, (hi - 0.5) * box


def detail_noise(n: int, seed: int = 17) -> npt.NDArray[np.uint8]:
    """(n, n, n) tileable value noise, three octaves (lattices of n/8, n/4 and n/2 cells),
    0..255: the billows that erode a tower's thin edges and shade their own far sides (the
    automaton's cells are 40-80 m; its bubbles hundreds of metres)."""
    rng = np.random.default_rng(seed)
    out = np.zeros((n, n, n), np.float64)
    for cells, gain in ((n // 8, 0.45), (n // 4, 0.3), (n // 2, 0.25)):
        lattice = rng.random((cells, cells, cells))
        x = np.arange(n) * cells / n
        i0 = np.floor(x).astype(int)
        f = x - i0
        f = f * f * (3.0 - 2.0 * f)
        i1 = (i0 + 1) % cells
        # Trilinear between lattice points, wrapping, along each axis in turn.
        a = lattice[i0] * (1 - f)[:, None, None] + lattice[i1] * f[:, None, None]
        a = a[:, i0] * (1 - f)[None, :, None] + a[:, i1] * f[None, :, None]
        a = a[:, :, i0] * (1 - f)[None, None, :] + a[:, :, i1] * f[None, None, :]
        out += gain * a
    lo, hi = out.min(), out.max()
    made: npt.NDArray[np.uint8] = np.clip((out - lo) / (hi - lo) * 255.0 + 0.5, 0, 255).astype(
        np.uint8
    )
    return made


def _vec(v: F64 | npt.ArrayLike) -> tuple[float, ...]:
    return tuple(float(c) for c in np.asarray(v, np.float64))


def _quad_for(eye_rel: F64, lo: F64, hi: F64, px_per_rad: float) -> _Quad:
    """An upright quad through the middle of the box part lo..hi (metres from the box's
    middle) grown by GROWTH_ROOM, facing an eye at `eye_rel`, covering that part as the eye
    sees it, with about the layer's texels."""
    room = GROWTH_ROOM * (hi - lo)
    lo, hi = lo - room, hi + room
    mid = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    rel = eye_rel - mid
    dist = float(np.linalg.norm(rel))
    w = -rel / max(dist, 1e-6)
    right = np.cross(w, (0.0, 0.0, 1.0))
    across = float(np.linalg.norm(right))
    right = right / across if across > 1e-6 else np.array([1.0, 0.0, 0.0])
    up = np.cross(right, w)
    corners = (
        np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64)
        * half
    )
    # Where the ray from the eye through each corner crosses the quad's plane.
    depth = corners @ w + dist
    scale = dist / np.maximum(depth, 0.1 * dist)
    hits = rel + scale[:, None] * (corners - rel)
    ext_u = max(float(np.max(np.abs(hits @ right))), 1.0)
    ext_v = max(float(np.max(np.abs(hits @ up))), 1.0)
    size = (_texels(ext_u, dist, px_per_rad), _texels(ext_v, dist, px_per_rad))
    return _Quad(w, mid, right * ext_u, up * ext_v, lo, hi, size)


def _texels(half_m: float, dist_m: float, px_per_rad: float) -> int:
    """Impostor texels along a side: TEXEL_SHARE of the layer's own resolution (a soft volume
    loses nothing to it), a multiple of 16."""
    px = 2.0 * half_m / max(dist_m, 1.0) * px_per_rad * TEXEL_SHARE
    return int(min(IMPOSTOR_MAX_PX, max(IMPOSTOR_MIN_PX, 16 * math.ceil(px / 16.0))))


def _fits(quad: _Quad, eye_rel: F64, lo: F64, hi: F64, px_per_rad: float) -> bool:
    """The quad still serves: the cloud is inside the part it covers, the eye has not moved
    round by more than VIEW_TOLERANCE_DEG, and it has about the texels the eye needs."""
    if np.any(lo < quad.lo - 1e-6) or np.any(hi > quad.hi + 1e-6):
        return False
    rel = eye_rel - quad.centre_m
    dist = float(np.linalg.norm(rel))
    cos = float(np.clip(-(rel / max(dist, 1e-6)) @ quad.view_dir, -1.0, 1.0))
    if math.degrees(math.acos(cos)) > VIEW_TOLERANCE_DEG:
        return False
    for half, have in zip(
        (float(np.linalg.norm(quad.axis_u)), float(np.linalg.norm(quad.axis_v))),
        quad.size,
        strict=True,
    ):
        want = _texels(half, dist, px_per_rad)
        if want > have * SIZE_TOLERANCE or want * SIZE_TOLERANCE < have:
            return False
    return True


def _set(prog: moderngl.Program, name: str, value: object) -> None:
    member = prog.get(name, None)
    if member is not None:
        assert isinstance(member, moderngl.Uniform)
        member.value = value


def _write(prog: moderngl.Program, name: str, data: bytes) -> None:
    member = prog.get(name, None)
    if member is not None:
        assert isinstance(member, moderngl.Uniform)
        member.write(data)
