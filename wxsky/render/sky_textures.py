"""The sky pass's textures and the per-frame values that index them (Roden & Parberry).

The textures are made procedurally from fixed seeds by one generator,
`wxsky.render.sky_texture_gen.build_sky_textures`, and shipped as package data:
`tools/generate/build_sky_textures.py` writes its output to `data/sky_*.png` (`--check` there, and
tests/test_sky_texture_files.py, keep the files equal to it), and the renderer only loads them,
once per process (`star_texture`, `galaxy_texture`, `dome_noise_texture`, `sunset_texture`).
Every file is 8-bit RGBA, so all are stored losslessly:

- stars: one RGBA8 cell per direction on an equi-angular cube map of the celestial sphere,
  six faces of STAR_FACE_PX² stacked vertically. Most cells are black (no star); a star's
  cell holds R = mean intensity, G = flicker rate, B = variance, A = phase, and the shader
  makes its brightness R + B·sin(2π·(G·STAR_RATE_SCALE_HZ·t + A)). A star sits at its cell
  centre moved by a hash of the cell (up to STAR_JITTER cells), so the grid never shows, and is
  drawn as a small Gaussian of constant on-screen size. `sky_stars.png`: the six faces as one
  vertical strip, (6·256) x 256, exactly the texture's bytes.
- galaxy: the Milky Way's glow on an equirectangular map in galactic longitude and latitude,
  with a bulge towards Sagittarius and a dark rift. Stars are denser inside it and the shader
  brightens them there as well. It is one 8-bit channel; `sky_galaxy.png` (512 x 256) holds it
  in R, G and B alike with A = 255, and loading keeps R.
- dome noise: four tileable noise fields (RGBA8, mipmapped): two cloud-shape layers (the
  first is the moon's maria too), a detail layer and cirrus fibres (the detail drawn out along
  x, read in the same fetch). `sky_dome_noise.png` (256 x 256): the texture's bytes.
- sunset: the paper's sunset gradient, the dome cloud's tint at dusk (RGB; A = 255), linearly
  filtered and clamped. Columns run along the `sunset` control (0 golden late afternoon, 1 the
  sun on the horizon), rows up the sky as sqrt(sin elevation) (row 0 the horizon): golden-yellow
  at low sunset; at full sunset deep red-orange low down, orange above, pink-magenta high up.
  `sky_sunset.png` (64 x 32): the texture's bytes.

`SkyPass` uploads them, picks the compiled variant of sky.glsl a frame needs (`features`)
and gives its uniforms (`frame_uniforms`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from importlib import resources
from typing import ClassVar

import moderngl
import numpy as np
import numpy.typing as npt

from wxsky.png import read_png
from wxsky.render.shaders import ShaderLibrary
from wxsky.render.sky_texture_gen import (
    DOME_FILE,
    DOME_NOISE_PX,
    FIBRE_ACROSS,
    GALACTIC_FROM_EQUATORIAL,
    GALAXY_FILE,
    GALAXY_SIZE_PX,
    STAR_FACE_PX,
    STAR_FILE,
    SUNSET_FILE,
    SUNSET_SIZE_PX,
)
from wxsky.scene.atmosphere import (
    SUN_ANGULAR_RADIUS_RAD,
    AtmosphereLuts,
    sky_irradiance,
    sky_view_v,
    sun_irradiance,
)
from wxsky.scene.camera import Camera, camera_basis
from wxsky.scene.exposure import display
from wxsky.scene.sky import (
    CLEAR_AIR_HAZE_M,
    DOME_MAX_WIND_MPS,
    DOME_TOP_M,
    HAZE_MIN_ELEVATION_DEG,
    SUN_EXACT_BLEND_DEG,
    SUN_EXACT_DEG,
    SkyParams,
    aureole,
    deck_share,
    display_sky_view,
    display_veil,
    layer_reaches_horizon,
    scene_exposure,
)

U8 = npt.NDArray[np.uint8]
F64 = npt.NDArray[np.float64]
Rect = tuple[float, float, float, float]  # NDC x0, y0, x1, y1
FULL_RECT: Rect = (-1.0, -1.0, 1.0, 1.0)
MOON_RECT_GRID_PX = 8

STAR_JITTER = 0.3  # greatest offset of a star from its cell centre, in cells
# A flicker rate of G = k/255 makes k/255 * 2.55 = k/100 cycles per second, so every star's
# sine repeats after exactly 100 s: the shader's clock can wrap there without a jump while
# keeping float32 precision.
STAR_RATE_SCALE_HZ = 2.55
STAR_CLOCK_PERIOD_S = 100.0
# Stars are drawn as Gaussians this wide, in pixels: one star lights 3 x 3 pixels whatever
# the field of view, unless a pixel is too wide to keep the Gaussian inside its 2 x 2 cells.
STAR_SIGMA_PX = 0.6
STAR_SIGMA_MAX_CELLS = (1.0 - STAR_JITTER) / 3.0
# Starlight (R + B·sin) lost against a sky that is not yet dark: at SkyParams.stars = s the
# stars fainter than this * (1 - s) are gone, so twilight and haze take the faint ones first.
STAR_FLOOR_AT_DAY = 0.4
# Size on the cloud-dome plane of one repeat of the cloud-shape and the detail noise.
DOME_TILE_M = 14_000.0
DOME_DETAIL_TILE_M = 3_500.0
# Below this height above the eye the dome would be a deck the eye is in or above: not drawn.
EARTH_RADIUS_M = 6_371_000.0
EARTHSHINE = 0.05  # of the sunlit face's brightness, on the dark part of a crescent at night
LUMA_WEIGHTS = (0.2126, 0.7152, 0.0722)  # Rec. 709
# On level ground under a clear sky, the sun's irradiance over the sky's is about this times
# sin(sun elevation): near 1 with the sun 5° up (40-50 W/m² each), 6 to 10 at noon.
SUN_OVER_SKY_LIGHT = 12.0

# The shipped files: wxsky/render/data/, written by tools/generate/build_sky_textures.py.
DATA_PACKAGE = "wxsky.render"
DATA_DIR = "data"
# The 22 deg halo over a cirrostratus veil (sky.glsl `halo`): its ring's peak as a share of
# the sun's light, and how much darker the veil is inside the ring, as a share of its own.
HALO_GAIN = 0.45
HALO_DARK_INSIDE = 0.08
# How far from the sun (or moon) the halo is drawn at all: its outer tail is under 1 % there.
HALO_REACH_DEG = 32.0
# The moon's halo: its light on the veil as a share of its disc's (`SkyParams.moon_rgb`, a
# near-white disc at full moon). At night the veil is lit by the sky's ambient alone, some 3
# levels of 255; at 0.4 the ring of a three-quarter moon stands some 5 levels over it, plain
# to an eye used to the dark as a moon's halo is, and as faint as the moon's phase makes it.
MOON_HALO_GAIN = 0.4
# A cirrostratus veil's opacity where it lies (sky.glsl cloud_dome): a milky film.
VEIL_ALPHA = 0.35
# ... and how much fainter the dome's patches are where all the high cover is veil.
VEIL_PATCHES = 0.7
# Cirrus fibres on the dome (sky.glsl cloud_dome): the dome noise's A channel, the detail
# drawn out along the wind (`sky_texture_gen.FIBRE_ACROSS`), its rows bent by FIBRE_BEND of a
# tile (in the fibres' own finer rows) where the broad shape changes.
FIBRE_BEND = 0.3


def shader_defines(feats: SkyFeatures) -> dict[str, str]:
    """The constants sky.glsl shares with this module, and its feature switches."""
    return {
        "STAR_FACE_PX": str(STAR_FACE_PX),
        "STAR_JITTER": f"{STAR_JITTER:.6f}",
        "STAR_RATE_SCALE_HZ": f"{STAR_RATE_SCALE_HZ:.6f}",
        "HALO_GAIN": f"{HALO_GAIN:.6f}",
        "FIBRE_ACROSS": f"{float(FIBRE_ACROSS):.6f}",
        "FIBRE_BEND": f"{FIBRE_BEND:.6f}",
        "HALO_DARK_INSIDE": f"{HALO_DARK_INSIDE:.6f}",
        "HALO_COS_REACH": f"{math.cos(math.radians(HALO_REACH_DEG)):.6f}",
        "VEIL_ALPHA": f"{VEIL_ALPHA:.6f}",
        "VEIL_PATCHES": f"{VEIL_PATCHES:.6f}",
        "SKY_STARS": str(int(feats.stars)),
        "SKY_MOON": str(int(feats.moon)),
        "SKY_DOME": str(int(feats.dome)),
        "SKY_PHYSICAL": str(int(feats.physical)),
        "SKY_SCENE_LINEAR": str(int(feats.scene_linear)),
        "SKY_SUN": str(int(feats.sun)),
        "SKY_DECK": str(int(feats.deck)),
        "SKY_HALO": str(int(feats.halo)),
    }


# -- textures --------------------------------------------------------------------------------


@functools.cache
def star_texture() -> U8:
    """(6·N, N, 4) star cells, faces stacked (face f's row j at f·N + j, column i); shipped,
    read-only."""
    n = STAR_FACE_PX
    return _load(STAR_FILE, (6 * n, n, 4))


@functools.cache
def galaxy_texture() -> U8:
    """(H, W) glow of the Milky Way: columns are galactic longitude -180°..180°, rows
    latitude -90°..90° (row 0 at -90°); shipped, read-only."""
    w, h = GALAXY_SIZE_PX
    img = _load(GALAXY_FILE, (h, w, 4))
    out = np.ascontiguousarray(img[..., 0])
    out.flags.writeable = False
    return out


@functools.cache
def dome_noise_texture() -> U8:
    """(N, N, 4) tileable noise: R, G cloud shapes (R the moon's maria too); B detail; A
    cirrus fibres; shipped, read-only."""
    return _load(DOME_FILE, (DOME_NOISE_PX, DOME_NOISE_PX, 4))


@functools.cache
def sunset_texture() -> U8:
    """(H, W, 4) the dome cloud's sunset tint: columns are the sunset control 0..1, rows
    sqrt(sin elevation) 0..1 (row 0 at the horizon); RGB tint, A = 255; shipped, read-only."""
    w, h = SUNSET_SIZE_PX
    return _load(SUNSET_FILE, (h, w, 4))


def _load(name: str, shape: tuple[int, int, int]) -> U8:
    root = resources.files(DATA_PACKAGE).joinpath(DATA_DIR)
    with resources.as_file(root.joinpath(name)) as path:
        img = read_png(path)
    if img.shape != shape:
        raise ValueError(f"{name}: expected {shape[1]}x{shape[0]} RGBA, got {img.shape}")
    img.flags.writeable = False  # shared by every caller through the cache
    return img


@dataclass(frozen=True)
class SkyFeatures:
    """What a frame's sky pass draws beyond the gradient and the sun: each is a compiled
    variant of sky.glsl, because a CPU renderer pays for code it branches around."""

    stars: bool
    moon: bool
    dome: bool
    # The physical atmosphere's sky-view table instead of Roden & Parberry's gradient.
    physical: bool = False
    # With `physical`: the radiance itself (kcd/m^2) into a float target, no exposure or tone
    # map (tests/test_atmosphere.py reads it back; the hook for scene-linear render targets).
    scene_linear: bool = False
    # With `physical`, in display values: the sky near the sun per pixel (its disc and the
    # aureole's core), which the other variants take from the baked table.
    sun: bool = False
    # With `physical` and `dome`: under a deck the dome's band fades toward the slab of haze
    # under it (`deck_share` > 0): a second look-up a pixel, compiled out where there is no
    # deck (high cirrus redraws its whole dome every frame; the look-up was 7 % of it).
    deck: bool = False
    # With `dome`: the 22° halo round the sun or moon over a cirrostratus veil, drawn as its
    # own part over the ring's rectangle only (`halo_rect_ndc`): the halo's code in the dome
    # variant, though it drew nothing past 32° from its light, cost high cirrus's dome a tenth
    # of its time on llvmpipe (issue 42's cost check).
    halo: bool = False


class SkyPass:
    """The sky pass's GL objects: the four textures (units 1-4; the sprite sheet keeps unit
    0) and one program and vertex array per feature set, compiled on first use."""

    UNITS: ClassVar[dict[str, int]] = {
        "u_star_tex": 1,
        "u_galaxy_tex": 2,
        "u_dome_tex": 3,
        "u_sunset_tex": 4,
        "u_sky_view": 5,
        "u_sky_display": 6,
    }

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self._ctx = ctx
        self._shaders = shaders
        self._variants: dict[SkyFeatures, tuple[moderngl.Program, moderngl.VertexArray]] = {}
        stars = star_texture()
        self.stars = ctx.texture((stars.shape[1], stars.shape[0]), 4, stars.tobytes())
        # Cells are fetched one by one, never filtered.
        self.stars.filter = (moderngl.NEAREST, moderngl.NEAREST)
        galaxy = galaxy_texture()
        self.galaxy = ctx.texture((galaxy.shape[1], galaxy.shape[0]), 1, galaxy.tobytes())
        self.galaxy.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.galaxy.repeat_x, self.galaxy.repeat_y = True, False
        dome = dome_noise_texture()
        self.dome = ctx.texture((dome.shape[1], dome.shape[0]), 4, dome.tobytes())
        self.dome.build_mipmaps()
        self.dome.filter = (moderngl.LINEAR_MIPMAP_NEAREST, moderngl.LINEAR)
        self.dome.repeat_x = self.dome.repeat_y = True
        sunset = sunset_texture()
        self.sunset = ctx.texture((sunset.shape[1], sunset.shape[0]), 4, sunset.tobytes())
        # A gradient read between texel centres: its ends must not wrap into each other.
        self.sunset.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.sunset.repeat_x = self.sunset.repeat_y = False
        # The physical sky's table (`use_atmosphere`), and the serial of the tables it holds.
        self.sky_view: moderngl.Texture | None = None
        self._sky_view_serial = -1
        # ... and what the display variants show of it (scene.sky.display_sky_view), with the
        # table's serial and the overcast veil it was baked with.
        self.sky_display: moderngl.Texture | None = None
        self._sky_display_key: tuple[int, tuple[float, float]] = (-1, (0.0, 0.0))

    def use_atmosphere(self, luts: AtmosphereLuts | None, cover: float = 0.0) -> None:
        """Upload the sky-view table of `luts` (RGB float, kcd/m^2) when it is a new one, and
        its display values under `cover` (`display_sky_view`) when either changed; the
        textures keep the last tables until then."""
        if luts is None:
            return
        key = (luts.serial, display_veil(cover))
        if key != self._sky_display_key:
            self.sky_display = self._upload(self.sky_display, display_sky_view(luts, cover), 1.0)
            self._sky_display_key = key
        if luts.serial == self._sky_view_serial:
            return
        rgb = np.nan_to_num(luts.sky_view_radiance(), nan=0.0, posinf=0.0)
        # Half floats, four channels: llvmpipe filters them faster than RGB32F, and 11 bits of
        # mantissa are finer than any display step (the radiance spans 1e-6..1e3 kcd/m^2).
        # Scaled by a power of two so the brightest texel is near 1024 (`sky_view_scale`): a
        # night's 1e-7 kcd/m^2 would be lost below half floats' normal range.
        self.sky_view = self._upload(self.sky_view, rgb, sky_view_scale(luts))
        self._sky_view_serial = luts.serial

    def _upload(
        self, texture: moderngl.Texture | None, rgb: npt.NDArray[np.floating], scale: float
    ) -> moderngl.Texture:
        """`rgb` / `scale` into `texture` (made anew when missing or another size): half floats,
        four channels, filtered, clamped at the edges."""
        rows, cols = rgb.shape[:2]
        table = np.ones((rows, cols, 4), np.float16)
        table[..., :3] = np.minimum(rgb / scale, 60_000.0)
        if texture is None or texture.size != (cols, rows):
            if texture is not None:
                texture.release()
            texture = self._ctx.texture((cols, rows), 4, dtype="f2")
            texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            texture.repeat_x = texture.repeat_y = False
        texture.write(table.tobytes())
        return texture

    def prepare(self, feats: SkyFeatures) -> tuple[moderngl.Program, moderngl.VertexArray]:
        """The program and vertex array that draw `feats` (some of this frame's `features`),
        with the textures bound; `frame_uniforms` gives the uniforms they need beyond the
        camera, gradient and sun."""
        variant = self._variants.get(feats)
        if variant is None:
            prog = self._shaders.program("sky.glsl", shader_defines(feats))
            variant = (prog, self._ctx.vertex_array(prog, []))
            self._variants[feats] = variant
        self.stars.use(self.UNITS["u_star_tex"])
        self.galaxy.use(self.UNITS["u_galaxy_tex"])
        self.dome.use(self.UNITS["u_dome_tex"])
        self.sunset.use(self.UNITS["u_sunset_tex"])
        if feats.physical and self.sky_view is not None:
            self.sky_view.use(self.UNITS["u_sky_view"])
        if feats.physical and self.sky_display is not None:
            self.sky_display.use(self.UNITS["u_sky_display"])
        return variant

    def release(self) -> None:
        for _prog, vao in self._variants.values():
            vao.release()  # the programs belong to the shader library
        self._variants.clear()
        for tex in (self.stars, self.galaxy, self.dome, self.sunset):
            tex.release()
        for table in (self.sky_view, self.sky_display):
            if table is not None:
                table.release()
        self.sky_view = self.sky_display = None


# -- per-frame values ------------------------------------------------------------------------


def features(cam: Camera, sky: SkyParams) -> SkyFeatures:
    """Which parts of the sky this frame shows: stars once the sky is dark enough, the moon
    when it is up and inside the view, the dome when there is cover above the eye."""
    moon = sky.moon
    fwd = cam.basis()[2]
    # Inside the cone around the view axis that holds the whole picture, plus the disc.
    half_diagonal_rad = math.atan(math.hypot(cam.tan_half_fov_x, cam.tan_half_fov_y))
    reach_rad = half_diagonal_rad + 2.0 * math.radians(moon.angular_radius_deg)
    cos_off_axis = float(np.dot(fwd, moon.direction_enu))
    moon_in_view = max(sky.moon_rgb) > 0.0 and cos_off_axis >= math.cos(min(reach_rad, math.pi))
    dome = dome_frame(sky, cam.position_m[2]).height_m > 0.0
    physical = sky.atmosphere is not None
    return SkyFeatures(
        stars=sky.stars > 0.0,
        moon=moon_in_view,
        dome=dome,
        physical=physical,
        sun=physical and _sun_near_view(cam, sky, half_diagonal_rad),
        deck=physical and dome and deck_share(sky, cam.position_m[2]) > 0.0,
        halo=dome and halo_rect_ndc(cam, sky) is not None,
    )


def halo_lights(sky: SkyParams) -> list[tuple[float, float, float]]:
    """The directions of the lights that ring a halo on the dome's veil now (sky.glsl
    `halo`): none without a veil; the sun unless it is below the horizon, the moon while
    its halo has light (`moon_halo_rgb`)."""
    if sky.dome.veil <= 0.0:
        return []
    out = []
    if sky.sun.direction_enu[2] >= -0.01:
        out.append(sky.sun.direction_enu)
    if moon_halo_rgb(sky)[0] > 0.0 and sky.moon.direction_enu[2] >= -0.01:
        out.append(sky.moon.direction_enu)
    return out


def halo_rect_ndc(cam: Camera, sky: SkyParams) -> Rect | None:
    """The rectangle (as `moon_rect_ndc`) holding every pixel within HALO_REACH_DEG of a
    light that rings a halo (`halo_lights`); None when no halo shows in the picture."""
    reach_rad = math.radians(HALO_REACH_DEG) + 3.0 * pixel_rad(cam)
    # Past the cone holding the picture no pixel is near enough (the rectangle alone would
    # be the whole picture whenever the ring reaches behind the eye).
    half_diagonal_rad = math.atan(math.hypot(cam.tan_half_fov_x, cam.tan_half_fov_y))
    cos_limit = math.cos(min(half_diagonal_rad + reach_rad, math.pi))
    fwd = cam.basis()[2]
    rects = [
        r
        for d in halo_lights(sky)
        if float(np.dot(fwd, d)) >= cos_limit
        and (r := _disc_rect_ndc(cam, d, reach_rad, SUN_RECT_GRID_PX)) is not None
    ]
    if not rects:
        return None
    return (
        min(r[0] for r in rects),
        min(r[1] for r in rects),
        max(r[2] for r in rects),
        max(r[3] for r in rects),
    )


def _sun_near_view(cam: Camera, sky: SkyParams, half_diagonal_rad: float) -> bool:
    """Whether the physical sky's sun part (SUN_EXACT_DEG round the sun, above the horizon)
    can show in the picture."""
    luts = sky.atmosphere
    assert luts is not None
    exact_rad = math.radians(SUN_EXACT_DEG)
    if math.radians(sky.sun.elevation_deg) < luts.horizon_rad - exact_rad:
        return False
    cos_off_axis = float(np.dot(cam.basis()[2], sky.sun.direction_enu))
    return cos_off_axis >= math.cos(min(half_diagonal_rad + exact_rad, math.pi))


# The sun part's rectangle (`sun_rect_ndc`) on a grid of this many pixels: it moves a cell (and
# the kept sky is drawn whole) about once a minute and a half at 60 deg across 1280 pixels.
SUN_RECT_GRID_PX = 16


def sun_rect_ndc(cam: Camera, sky: SkyParams) -> Rect | None:
    """The rectangle (as `moon_rect_ndc`) holding every pixel within SUN_EXACT_DEG of the
    sun, where the sun part draws the sky per pixel."""
    reach_rad = math.radians(SUN_EXACT_DEG) + 3.0 * pixel_rad(cam)
    return _disc_rect_ndc(cam, sky.sun.direction_enu, reach_rad, SUN_RECT_GRID_PX)


def moon_rect_ndc(cam: Camera, sky: SkyParams) -> Rect | None:
    """The rectangle (NDC x0, y0, x1, y1, y down the picture as the sky shader's quad) that
    holds every pixel the moon's disc touches, with its anti-aliased edge; the whole picture
    when the disc is too near the side of the eye to project safely; None when it is out of
    the picture."""
    # Out to where the shader's coverage is zero: the disc plus half a pixel, and a margin.
    reach_rad = math.radians(sky.moon.angular_radius_deg) + 3.0 * pixel_rad(cam)
    return _disc_rect_ndc(cam, sky.moon.direction_enu, reach_rad, MOON_RECT_GRID_PX)


def _disc_rect_ndc(
    cam: Camera, direction_enu: tuple[float, float, float], reach_rad: float, grid_px: int
) -> Rect | None:
    """The rectangle (on a grid of `grid_px` pixels) holding the circle of `reach_rad` round
    `direction_enu`; the whole picture when it comes near the side of the eye."""
    right, up, fwd = cam.basis()
    moon = np.asarray(direction_enu, np.float64)
    side = np.cross(moon, fwd)
    if float(np.dot(side, side)) < 1e-12:
        side = right
    side = side / np.linalg.norm(side)
    other = np.cross(moon, side)
    angles = np.linspace(0.0, 2.0 * math.pi, 24, endpoint=False)
    rim = math.cos(reach_rad) * moon + math.sin(reach_rad) * (
        np.cos(angles)[:, None] * side + np.sin(angles)[:, None] * other
    )
    depth = rim @ fwd
    if float(depth.min()) < 0.05:
        return FULL_RECT
    # The circle through 24 points is inside their polygon's bounding box scaled by
    # 1/cos(7.5°); the pixel margin above covers that and more.
    x = (rim @ right) / depth / cam.tan_half_fov_x
    y = -(rim @ up) / depth / cam.tan_half_fov_y
    pad_x, pad_y = 2.0 / cam.width_px, 2.0 / cam.height_px
    # Out to a grid of pixels, so that the rectangle stays put while the disc crosses a cell
    # (a minute and more) and a kept sky layer needs only the disc's part again.
    step_x = 2.0 * grid_px / cam.width_px
    step_y = 2.0 * grid_px / cam.height_px
    return _clip_rect(
        math.floor((float(x.min()) - pad_x) / step_x) * step_x,
        math.floor((float(y.min()) - pad_y) / step_y) * step_y,
        math.ceil((float(x.max()) + pad_x) / step_x) * step_x,
        math.ceil((float(y.max()) + pad_y) / step_y) * step_y,
    )


def dome_band(sky: SkyParams) -> tuple[float, float]:
    """sin(elevation) below which the dome's distant band is full, and above which it is gone.
    The band is full up to a third of the sprites' edge and gone at twice it: a long fade,
    because the sprites themselves fade out over their last quarter of range."""
    horizon_deg = sky.dome.horizon_deg
    return (
        math.sin(math.radians(0.3 * horizon_deg)),
        math.sin(math.radians(2.0 * horizon_deg + 0.5)),
    )


def dome_rect_ndc(cam: Camera, sky: SkyParams) -> Rect | None:
    """The rectangle (as `moon_rect_ndc`) that holds every pixel where the dome can show: above
    the horizon, and below the top of its distant band unless there is high cover. None when
    no pixel of the picture is there.

    Elevation across the picture is smooth: it is sampled on a grid of cells about 10 pixels
    wide, a cell is in when its corners reach into the range, and one cell of margin on every
    side stands for what lies between the corners. Kept for the last few views: a view held
    steady (a straight flight) asks for the same every frame, and a grid of 9,000 rays was a
    third of the sky's planning."""
    hi_z = 1.0 if sky.dome.high_cover > 0.0 else dome_band(sky)[1]
    return _dome_rect(
        cam.heading_deg, cam.pitch_deg, cam.roll_deg, cam.fov_deg, cam.width_px, cam.height_px, hi_z
    )


@functools.lru_cache(maxsize=8)
def _dome_rect(
    heading_deg: float,
    pitch_deg: float,
    roll_deg: float,
    fov_deg: float,
    width_px: int,
    height_px: int,
    hi_z: float,
) -> Rect | None:
    cam = Camera((0.0, 0.0, 0.0), heading_deg, pitch_deg, roll_deg, fov_deg, width_px, height_px)
    lo_z = 0.0
    right, up, fwd = cam.basis()
    nx = max(2, round(cam.width_px / 10.0) + 1)
    ny = max(2, round(cam.height_px / 10.0) + 1)
    xs = np.linspace(-1.0, 1.0, nx)
    ys = np.linspace(-1.0, 1.0, ny)
    gx, gy = np.meshgrid(xs * cam.tan_half_fov_x, ys * cam.tan_half_fov_y)
    ray = fwd + gx[..., None] * right - gy[..., None] * up
    z = ray[..., 2] / np.linalg.norm(ray, axis=-1)
    corners = np.stack([z[:-1, :-1], z[:-1, 1:], z[1:, :-1], z[1:, 1:]])
    inside = (corners.max(axis=0) > lo_z) & (corners.min(axis=0) < hi_z)
    rows = np.flatnonzero(inside.any(axis=1))
    cols = np.flatnonzero(inside.any(axis=0))
    if rows.size == 0:
        return None
    return _clip_rect(
        float(xs[max(cols[0] - 1, 0)]),
        float(ys[max(rows[0] - 1, 0)]),
        float(xs[min(cols[-1] + 2, nx - 1)]),
        float(ys[min(rows[-1] + 2, ny - 1)]),
    )


def _clip_rect(x0: float, y0: float, x1: float, y1: float) -> Rect | None:
    x0, y0, x1, y1 = max(x0, -1.0), max(y0, -1.0), min(x1, 1.0), min(y1, 1.0)
    if x0 >= x1 or y0 >= y1:
        return None
    return (x0, y0, x1, y1)


def frame_uniforms(cam: Camera, sky: SkyParams, feats: SkyFeatures) -> dict[str, object]:
    """The sky pass's uniforms for the night sky, moon and cloud dome, those of the features
    drawn (the camera, gradient and sun ones are set by the renderer)."""
    out: dict[str, object] = {}
    if feats.physical and sky.atmosphere is not None:
        out.update(physical_uniforms(sky.atmosphere))
        out["u_overcast"] = display_veil(sky.cover)
        # The scene's exposure: the sky's, adapted to the cover's dimming.
        out["u_sky_scale"] = scene_exposure(sky.atmosphere, sky.cover)
        if not feats.scene_linear:
            out.update(display_uniforms(cam, sky))
            if not feats.sun:
                # Baked into the display table: only the sun part looks at the radiance.
                for name in _EXACT_ONLY:
                    del out[name]
    if not (feats.physical and feats.scene_linear):
        # The ground band, in display values (the scene-linear sky keeps its table's ground).
        out.update(ground_uniforms(cam, sky))
        if feats.physical:
            del out["u_horizon_air"]  # the physical sky's air is its table's (u_air_floor)
    if feats.stars:
        sigma, gain = star_sigma(cam)
        out.update(
            {
                "u_star_tex": SkyPass.UNITS["u_star_tex"],
                "u_galaxy_tex": SkyPass.UNITS["u_galaxy_tex"],
                "u_stars": sky.stars,
                "u_celestial_from_enu": column_major(sky.celestial_from_enu),
                "u_galactic_from_celestial": column_major(GALACTIC_FROM_EQUATORIAL),
                "u_star_clock_s": flicker_clock_s(sky.sky_time_s),
                "u_star_sigma_gain": (sigma, gain),
                "u_star_floor": STAR_FLOOR_AT_DAY * (1.0 - sky.stars),
            }
        )
    if feats.moon:
        moon = sky.moon
        earthshine = EARTHSHINE * (1.0 - moon.illuminated_fraction) * sky.stars
        out.update(
            {
                "u_dome_tex": SkyPass.UNITS["u_dome_tex"],
                "u_pixel_rad": pixel_rad(cam),
                "u_moon_dir": moon.direction_enu,
                "u_moon_sin_radius": math.sin(math.radians(moon.angular_radius_deg)),
                "u_moon_rgb": sky.moon_rgb,
                "u_earthshine_rgb": tuple(earthshine * v for v in (0.85, 0.9, 1.0)),
            }
        )
    if feats.dome:
        dome = sky.dome
        frame = dome_frame(sky, cam.position_m[2])
        band_lo, band_hi = dome_band(sky)
        out.update(
            {
                "u_dome_tex": SkyPass.UNITS["u_dome_tex"],
                "u_sunset_tex": SkyPass.UNITS["u_sunset_tex"],
                "u_dome_height_m": frame.height_m,
                "u_dome_controls": (dome.high_cover, dome.cover, dome.density, dome.sunset),
                "u_dome_veil": dome.veil,
                "u_dome_band": (band_lo, band_hi),
                "u_dome_m0": frame.matrices[0],
                "u_dome_m1": frame.matrices[1],
                "u_dome_m2": frame.matrices[2],
                "u_dome_off0": frame.offsets[0],
                "u_dome_off1": frame.offsets[1],
                "u_dome_off2": frame.offsets[2],
                "u_dome_rgb": tuple(float(v) for v in dome_light_rgb(sky)),
                "u_haze_m": sky.haze_m,
                # The dome is high cloud: only the part of its ray in the hazy layer is hazy.
                "u_haze_depth_m": min(
                    max(sky.haze_top_m - cam.position_m[2], 0.0), max(frame.height_m, 0.0)
                ),
                "u_clear_haze_m": CLEAR_AIR_HAZE_M,
            }
        )
        if not feats.physical or feats.scene_linear:
            # The physical sky's dome fades into the air behind it, direction by direction
            # (sky.glsl `baked_sky`), as the sprites do (SkyParams.haze_toward); the
            # gradient's into the one haze colour.
            out["u_dome_haze_rgb"] = sky.haze_rgb
    if feats.halo:
        out.update(
            {
                "u_moon_halo_dir": sky.moon.direction_enu,
                "u_moon_halo_rgb": moon_halo_rgb(sky),
            }
        )
    return out


@dataclass(frozen=True)
class DomeFrame:
    """Where the dome's textures sit this frame: each layer maps a point on the dome plane
    (east, north metres) to texture coordinates by a 2 x 2 matrix and an offset."""

    height_m: float  # of the dome plane above the eye; 0 = not drawn
    matrices: tuple[tuple[float, float, float, float], ...]  # 3 layers, column-major mat2
    offsets: tuple[tuple[float, float], ...]  # 3 layers, wrapped into 0..1


# The last frame's dome, by its sky (identity) and eye altitude: a frame asks for it four
# times (features, uniforms of two parts, the reuse tolerance).
_last_dome: tuple[SkyParams, float, DomeFrame] | None = None


def dome_frame(sky: SkyParams, eye_alt_m: float) -> DomeFrame:
    """Roden & Parberry's "height" and "speed" controls turned into texture coordinates: the
    two shape layers drift with the wind aloft in slightly different directions and at
    slightly different speeds, so the clouds change shape as they go; thin ice cloud is
    stretched along the wind into streaks."""
    global _last_dome
    last = _last_dome  # one read: another thread's renderer may replace it
    if last is not None and last[0] is sky and last[1] == eye_alt_m:
        return last[2]
    made = _dome_frame(sky, eye_alt_m)
    _last_dome = (sky, eye_alt_m, made)
    return made


def _dome_frame(sky: SkyParams, eye_alt_m: float) -> DomeFrame:
    dome = sky.dome
    clearance_m = dome.height * DOME_TOP_M - eye_alt_m
    visible = layer_reaches_horizon(sky, eye_alt_m)
    if not visible:
        none = (1.0, 0.0, 0.0, 1.0)
        return DomeFrame(0.0, (none, none, none), ((0.0, 0.0),) * 3)
    speed_mps = dome.speed * DOME_MAX_WIND_MPS
    toward = math.radians(dome.drift_toward_deg)
    stretch = 1.0 + 4.0 * (1.0 - min(1.0, dome.density / 0.5))
    layers = (
        (DOME_TILE_M, 0.0, 1.0, stretch),
        (DOME_TILE_M * 0.8, math.radians(9.0), 1.15, stretch),
        (DOME_DETAIL_TILE_M, math.radians(-6.0), 0.9, 1.0 + 1.5 * (stretch - 1.0)),
    )
    matrices = []
    offsets = []
    for tile_m, turn_rad, speed_k, stretch_k in layers:
        angle = toward + turn_rad
        # Rows: along the wind (compressed by the stretch, so features lengthen), across it.
        along = np.array([math.sin(angle), math.cos(angle)]) / (tile_m * stretch_k)
        across = np.array([math.cos(angle), -math.sin(angle)]) / tile_m
        m = np.stack([along, across])
        velocity = speed_k * speed_mps * np.array([math.sin(angle), math.cos(angle)])
        # The texture moves with the air: sample where the air now overhead was at time 0.
        offset = (m @ (-velocity * sky.sky_time_s)) % 1.0
        matrices.append((float(m[0, 0]), float(m[1, 0]), float(m[0, 1]), float(m[1, 1])))
        offsets.append((float(offset[0]), float(offset[1])))
    return DomeFrame(clearance_m, tuple(matrices), tuple(offsets))


def moon_halo_rgb(sky: SkyParams) -> tuple[float, float, float]:
    """The moon's light for its 22° halo over a cirrostratus veil (sky.glsl `halo`), in
    the units the sun's is: its disc's light (`SkyParams.moon_rgb`, reddened low down) as it
    reaches the veil (not dimmed by the cloud it shines through to the eye), times its lit
    share, MOON_HALO_GAIN of it, and only once the sun is down (by day the moon's halo drowns
    in the sun's light on the veil)."""
    night = 1.0 - _smoothstep(-8.0, -2.0, sky.sun.elevation_deg)
    veiled = max(sky.moon_seen, 1e-3)
    gain = MOON_HALO_GAIN * sky.moon.illuminated_fraction * night / veiled
    r, g, b = (float(c) * gain for c in sky.moon_rgb)
    return r, g, b


def dome_light_rgb(sky: SkyParams) -> F64:
    """Roden & Parberry's "amount of sunlight" on the dome: the sky's ambient level on a
    near-white cloud plus direct sun. The dome's cloud is high, so it sees the sun after
    sunset (by the dip of the horizon from its height, 3° at 9 km), red at first."""
    height_m = sky.dome.height * DOME_TOP_M
    dip_deg = math.degrees(math.acos(EARTH_RADIUS_M / (EARTH_RADIUS_M + max(height_m, 0.0))))
    sun_el = sky.sun.elevation_deg + dip_deg
    sunlit = _smoothstep(-1.0, 3.0, sun_el)
    redness = 1.0 - _smoothstep(0.0, 14.0, sun_el)
    sun_rgb = np.array([1.0, 0.97, 0.92]) + redness * (
        np.array([1.0, 0.5, 0.3]) - [1.0, 0.97, 0.92]
    )
    ambient_rgb = np.array([0.9, 0.92, 0.97]) * (0.45 * sky.ambient)
    result: F64 = ambient_rgb + 0.6 * sunlit * sun_rgb
    return result


def _smoothstep(lo: float, hi: float, x: float) -> float:
    t = min(1.0, max(0.0, (x - lo) / (hi - lo)))
    return t * t * (3.0 - 2.0 * t)


def star_sigma(cam: Camera) -> tuple[float, float]:
    """(sigma in radians, gain) of a star's Gaussian: STAR_SIGMA_PX of the camera's centre
    pixel, or the widest the cell grid allows, made brighter to keep its light the same."""
    pixel_rad = 2.0 * cam.tan_half_fov_x / cam.width_px
    wanted = STAR_SIGMA_PX * pixel_rad
    limit = STAR_SIGMA_MAX_CELLS * (math.pi / 2.0) / STAR_FACE_PX
    sigma = min(wanted, limit)
    return sigma, min(4.0, (wanted / sigma) ** 2)


def pixel_rad(cam: Camera) -> float:
    return 2.0 * cam.tan_half_fov_x / cam.width_px


def view_top_sin(cam: Camera) -> float:
    """The sine of the highest elevation the picture shows (1 with the zenith in it): how far
    off the nearest point of a layer above the eye that it can see is (`sky_layer`
    `dome_offset_tolerance`). Not below the true top: the picture's border is sampled and each
    sample raised by the step to its neighbour."""
    return _view_top_sin(cam.pitch_deg, cam.roll_deg, cam.tan_half_fov_x, cam.tan_half_fov_y)


@functools.lru_cache(maxsize=8)  # per frame; the heading does not change it
def _view_top_sin(pitch_deg: float, roll_deg: float, tan_x: float, tan_y: float) -> float:
    right, up, fwd = camera_basis(0.0, pitch_deg, roll_deg)
    # The ray through (a, b) of the picture (a right, b down, -1..1): fwd + a tx right - b ty up.
    if fwd[2] > 0.0:
        a = right[2] / (tan_x * fwd[2])
        b = -up[2] / (tan_y * fwd[2])
        if abs(a) <= 1.0 and abs(b) <= 1.0:
            return 1.0
    t = np.linspace(-1.0, 1.0, 257)
    one = np.ones_like(t)
    edges = [(t, -one), (t, one), (-one, t), (one, t)]
    top = -1.0
    for a, b in edges:
        rays = fwd[:, None] + a * tan_x * right[:, None] - b * tan_y * up[:, None]
        z = rays[2] / np.linalg.norm(rays, axis=0)
        top = max(top, float(z.max() + np.abs(np.diff(z)).max()))
    return min(top, 1.0)


def column_major(m: tuple[tuple[float, float, float], ...] | F64) -> tuple[float, ...]:
    """A row-major 3 x 3 as GLSL's mat3 takes it."""
    a = np.asarray(m, dtype=np.float64)
    return tuple(float(v) for v in a.T.ravel())


def flicker_clock_s(sky_time_s: float) -> float:
    """The shader's flicker clock: the sky time wrapped at the flicker period (see
    STAR_RATE_SCALE_HZ), which keeps every star's phase and float32 precision."""
    return sky_time_s % STAR_CLOCK_PERIOD_S


# The physical uniforms only the exact sky (scene-linear, or the sun part) reads.
_EXACT_ONLY = (
    "u_sky_view",
    "u_sky_view_scale",
    "u_sky_scale",
    "u_sun_radiance",
    "u_limb_darkening",
    "u_aureole",
    "u_sun_exact",
)


def display_uniforms(cam: Camera, sky: SkyParams) -> dict[str, object]:
    """The physical sky's display variants' own uniforms: the baked table's unit, the sun's
    azimuth, the floor of the air the ground and the dome's band fade into (sin elevation,
    its table row, and how far the air under the cover is one slab: `deck_share`), and the
    sun part's blend into the table."""
    luts = sky.atmosphere
    assert luts is not None
    sun = sky.sun.direction_enu
    flat = math.hypot(sun[0] + 1e-6, sun[1])
    layer_reaches = layer_reaches_horizon(sky, cam.position_m[2])
    floor_rad = luts.horizon_rad + math.radians(HAZE_MIN_ELEVATION_DEG) if layer_reaches else 0.0
    return {
        "u_sky_display": SkyPass.UNITS["u_sky_display"],
        "u_flat_sun": ((sun[0] + 1e-6) / flat, sun[1] / flat),
        "u_air_floor": (
            math.sin(floor_rad),
            float(sky_view_v(np.array(floor_rad), luts.horizon_rad)),
            deck_share(sky, cam.position_m[2]),
        ),
        "u_sun_exact": (
            math.cos(math.radians(SUN_EXACT_BLEND_DEG)),
            math.cos(math.radians(SUN_EXACT_DEG)),
        ),
    }


def ground_uniforms(cam: Camera, sky: SkyParams) -> dict[str, object]:
    """The ground band's uniforms (sky.glsl `ground_band`), the same in every variant of the
    sky pass: below the horizon the variants must agree to the bit, so the air the ground
    hazes into is the dome's haze wherever the dome is drawn this frame (its distant band
    reaches the horizon, opaque), whether or not this variant draws the dome: in the gradient
    mode the one haze colour (u_horizon_air.rgb; .a says a layer reaches); the physical sky
    drops u_horizon_air and takes its air from its baked table (`display_uniforms`)."""
    dome = sky.dome
    eye_agl_m = cam.position_m[2] - dome.ground_m
    hazy_m = max(min(sky.haze_top_m - dome.ground_m, 1e6), 0.0)
    surface_haze_m = dome.surface_haze_m if dome.surface_haze_m > 0.0 else sky.haze_m
    layer_reaches = layer_reaches_horizon(sky, cam.position_m[2])
    return {
        "u_pixel_rad": pixel_rad(cam),
        "u_ground_air": (eye_agl_m, surface_haze_m, hazy_m, CLEAR_AIR_HAZE_M),
        "u_horizon_air": (*sky.haze_rgb, 1.0 if layer_reaches else 0.0),
        "u_ground_tint": ground_tint(sky) if sky.atmosphere is None else physical_ground_tint(sky),
    }


# The diffuse share of the light a cloud deck lets through to the ground (stratus and
# stratocumulus of optical depth 10-20 transmit 0.3-0.4 of what falls on their tops).
DECK_TRANSMITTANCE = 0.35
GROUND_ALBEDO_PHYSICAL = 0.12  # fields, woods and towns; the atmosphere model's ground is 0.1


def physical_ground_tint(sky: SkyParams) -> tuple[float, float, float]:
    """With the physical sky: the factor on the ground's colour (`SkyParams.ground_rgb`) that
    makes it the ground's lit radiance as the sky pass shows it: an albedo of
    GROUND_ALBEDO_PHYSICAL, in the ground's hue, lit by the atmosphere's sun on a level
    surface and its sky from above at the ground, through the cloud cover (what a deck covers
    gets DECK_TRANSMITTANCE of it), at the sky's exposure. The ground so darkens with the
    light, as the sky and the clouds do, instead of keeping the gradient's brightness: under
    a deck at a low sun it was brighter than the deck over it (issue 41)."""
    luts = sky.atmosphere
    assert luts is not None
    # Per frame, for every part of the sky pass: made once for each table, cover, ground and
    # sun to the 0.01 deg (a fifth of a percent of a 5 deg sun's light; the sun takes 2.4 s
    # to move that far). Made afresh each call it was a third of clear's CPU frame.
    el = round(float(sky.sun.elevation_deg), 2)
    return _physical_ground_tint(luts, el, float(sky.cover), tuple(sky.ground_rgb))


@functools.lru_cache(maxsize=16)
def _physical_ground_tint(
    luts: AtmosphereLuts, el: float, cover: float, ground_rgb: tuple[float, ...]
) -> tuple[float, float, float]:
    sun_h = sun_irradiance(luts, 0.0, el) * max(math.sin(math.radians(el)), 0.0)
    above, _ = sky_irradiance(luts, 0.0, el)
    open_share = 1.0 - cover * (1.0 - DECK_TRANSMITTANCE)
    light_klx = (np.asarray(sun_h) + np.asarray(above)) * open_share
    ground = np.asarray(ground_rgb, np.float64)
    luma = float(ground @ np.asarray(LUMA_WEIGHTS))
    albedo = GROUND_ALBEDO_PHYSICAL * ground / max(luma, 1e-6)
    radiance = albedo * light_klx / math.pi  # klx -> kcd/m^2 off a Lambertian surface
    shown = display(radiance, scene_exposure(luts, cover))
    r, g, b = (float(v) for v in shown / np.maximum(ground, 1e-6))
    return (r, g, b)


def ground_tint(sky: SkyParams) -> tuple[float, float, float]:
    """The colour of the light on the ground, at the luminance of white: the sun's on a level
    surface through the clear share of the sky, and the diffuse light from above. Under open
    sky a level surface gets the cosine-weighted mean of the sky's gradient (sky_colour: horizon
    to zenith by sqrt(elevation)), which lies 0.8 of the way to the zenith's colour; under
    cloud, the light of the air under it (SkyParams.haze_rgb: the horizon's, greyed under a
    deck, what the clouds fade into). The ground's own colour (SkyParams.ground_rgb) keeps its
    brightness and takes this tint: warm where a low sun lights it, grey under an overcast."""
    sun_z = max(sky.sun.direction_enu[2], 0.0)
    direct = SUN_OVER_SKY_LIGHT * sun_z * (1.0 - sky.cover)
    open_sky = np.asarray(sky.horizon_rgb) + 0.8 * (
        np.asarray(sky.zenith_rgb) - np.asarray(sky.horizon_rgb)
    )
    diffuse = open_sky + sky.cover * (np.asarray(sky.haze_rgb) - open_sky)
    light = diffuse + direct * np.asarray(sky.sun_rgb, np.float64)
    luma = float(light @ np.asarray(LUMA_WEIGHTS))
    if not luma > 1e-6:
        return (1.0, 1.0, 1.0)
    r, g, b = (float(v) for v in light / luma)
    return (r, g, b)


# -- the physical sky ------------------------------------------------------------------------

# Limb darkening of the sun's disc, I(mu) = 1 - u (1 - mu) (u about 0.6 in the visible): the
# disc's mean is 1 - u / 3 of its centre.
LIMB_DARKENING = 0.6


@functools.lru_cache(maxsize=4)
def sky_view_scale(luts: AtmosphereLuts) -> float:
    """What the sky-view texture's values are multiplied by in the shader (a power of two:
    the texture holds radiance / this, its brightest texel near 1024)."""
    peak = float(np.max(luts.sky_view_radiance()))
    if not math.isfinite(peak) or peak <= 0.0:
        return 1.0
    return float(2.0 ** round(math.log2(peak / 1024.0)))


def physical_uniforms(luts: AtmosphereLuts) -> dict[str, object]:
    """`_physical_uniforms`, made once per set of tables (a frame asks for them per part)."""
    return dict(_physical_uniforms(luts))


@functools.lru_cache(maxsize=4)
def _physical_uniforms(luts: AtmosphereLuts) -> dict[str, object]:
    """The physical sky's uniforms that come with a set of tables: its unit and horizon, the
    sun's disc (radiance at its centre, kcd/m^2, transmitted to the eye) and the aureole
    (scene.sky's `aureole`: strength and g, both from the aerosol's optical depth toward the
    sun). The exposure (u_sky_scale) depends on the cover too: `frame_uniforms` sets it."""
    # The table's own (quantised) sun, not this frame's: these change with the table only,
    # as a jump that redraws the kept layer whole, never as a drift every sky step.
    el = luts.sun_elevation_deg
    eye_m = luts.eye_alt_m
    sun_klx = sun_irradiance(luts, eye_m, el)
    solid_angle = math.pi * SUN_ANGULAR_RADIUS_RAD**2
    centre = sun_klx / (solid_angle * (1.0 - LIMB_DARKENING / 3.0))
    strength, g = aureole(luts)
    return {
        "u_sky_view": SkyPass.UNITS["u_sky_view"],
        "u_horizon_rad": luts.horizon_rad,
        "u_sky_view_scale": sky_view_scale(luts),
        "u_sun_radiance": tuple(float(v) for v in centre),
        "u_limb_darkening": LIMB_DARKENING,
        "u_aureole": (*(float(v) for v in strength), g),
        # A new table is a jump for the kept sky layer (sky_layer): it is drawn whole again.
        "u_atmosphere_serial": float(luts.serial % 1_000_000),
    }
