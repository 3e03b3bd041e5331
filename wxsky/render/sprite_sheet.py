"""The cloud texture sheet: 16 sprite textures on one 512x512 RGBA sheet (Wang's layout), and
its mip chain down to 32x32, shipped as package data.

Slots, row-major on a 4 x 4 grid as `wxsky.scene.texture_slots` lays them out: 0 flat-bottomed
(cumulus bases), 1-3 foggy (stratus), 4-9 puffy, 10-15 wispy: 10-11 straight fibres and 12 a
hooked mares' tail (the "streaks" of cirrus), 13-15 ragged broken wisps (the "ragged" fringes
and scud of the cloud models, see `wxsky.scene.cloud_model_files`).

The PNGs under `data/` are made by `tools/generate/build_sprite_sheet.py` from the one generator,
`wxsky.render.sheet_textures`; `--check` there (and tests/test_sprite_sheet.py) keeps them equal
to its output. The renderer only loads them (6 ms; generating takes 1.7 s of numpy).

Every level is straight (not premultiplied) RGBA8, row 0 the top of each sprite, because the
sprite shader multiplies colour by alpha itself. Alpha is exactly zero in the outer
`MARGIN_PX` pixels of each 128 px cell (and the outer texel of each cell on every level), so
filtering and mip-mapping never bleed one cell into the next.
"""

from __future__ import annotations

import functools
from importlib import resources

import numpy as np
import numpy.typing as npt

from wxsky.png import read_png
from wxsky.scene.texture_slots import SHEET_CELLS

CELL_PX = 128
SHEET_PX = SHEET_CELLS * CELL_PX
# 512, 256, 128, 64, 32: Wang's chain. Below 32 px a cell would be under 8 texels.
MIP_LEVELS = 5
# Transparent border of each cell at level 0; one texel of the 16 px cells of level 3.
MARGIN_PX = 8
SHEET_SEED = 20040101
DATA_PACKAGE = "wxsky.render"
DATA_DIR = "data"

U8 = npt.NDArray[np.uint8]
F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
# The fine support polygons hold every texel that is not transparent on the first this many
# levels (a cell 128, 64 and 32 texels across): all that sprites 32 px across or more read.
# Smaller sprites read coarser levels, whose halo reaches further: the renderer draws them
# as the polygons that hold every level (sprites.glsl).
SUPPORT_LEVELS = 3
# The polygons' sides face these directions (degrees, from the cell's x axis), as the sides
# of the octagon around the support disc do.
SUPPORT_SIDES_DEG = tuple(45.0 * k for k in range(8))


def level_size(level: int) -> int:
    return SHEET_PX >> level


def level_filename(level: int) -> str:
    return f"cloud_sheet_{level_size(level)}.png"


def level_margin(level: int) -> int:
    """Texels at the edge of each cell that are transparent on this mip level."""
    return max(1, MARGIN_PX >> level)


def load_sheet() -> list[U8]:
    """The shipped mip chain, level 0 (512 px) first: (S, S, 4) uint8 arrays, read-only."""
    return list(_load_levels())


@functools.cache
def _load_levels() -> tuple[U8, ...]:
    root = resources.files(DATA_PACKAGE).joinpath(DATA_DIR)
    levels = []
    for level in range(MIP_LEVELS):
        with resources.as_file(root.joinpath(level_filename(level))) as path:
            img = read_png(path)
        size = level_size(level)
        if img.shape != (size, size, 4):
            raise ValueError(f"{level_filename(level)}: expected {size}x{size} RGBA, {img.shape}")
        img.flags.writeable = False  # shared by every caller through the cache
        levels.append(img)
    return tuple(levels)


def cell_shades(levels: list[U8] | None = None) -> F32:
    """Each slot's mean shade on the full-size level: the luminance of its colour, weighted
    by its alpha as a sprite shows it (0.86-0.94). The sprite shader divides a texel's colour
    by it, so that a sprite's mean colour is the colour its cloud was shaded and hazed to,
    the texture adding detail, not darkness: before, every cloud came out 6-14 % darker than
    its light and its haze said, and a distant one darker than the sky it should melt into
    (issue 41)."""
    level = (levels if levels is not None else load_sheet())[0].astype(np.float64) / 255.0
    cells = level.shape[0] // CELL_PX
    luma = level[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    out = np.ones(cells * cells, np.float32)
    for slot in range(cells * cells):
        row, col = divmod(slot, cells)
        cut = (slice(row * CELL_PX, (row + 1) * CELL_PX), slice(col * CELL_PX, (col + 1) * CELL_PX))
        alpha = level[cut][..., 3]
        if alpha.sum() > 0.0:
            out[slot] = float((luma[cut] * alpha).sum() / alpha.sum())
    return out


def support_radii(levels: list[U8] | None = None) -> tuple[float, ...]:
    """For each slot, the radius (1 = half the cell) outside which it is transparent on the
    full-size level, with half a texel more for the bilinear filter's reach: a sprite need
    only cover that disc, so it is drawn as an octagon around it instead of its whole square
    (fill rate is what sprites cost). Coarser mip levels spread a faint halo a little beyond;
    far sprites lose it, at most a few levels of alpha."""
    chain = (levels if levels is not None else load_sheet())[:1]
    cells = chain[0].shape[0] // CELL_PX
    out = np.zeros(cells * cells)
    for level in chain:
        cell = level.shape[0] // cells
        centre = (cell - 1) / 2.0
        yy, xx = np.mgrid[0:cell, 0:cell]
        radius = (np.hypot(xx - centre, yy - centre) + 0.5 + 0.5) / (cell / 2.0)
        for slot in range(cells * cells):
            row, col = divmod(slot, cells)
            alpha = level[row * cell : (row + 1) * cell, col * cell : (col + 1) * cell, 3]
            if alpha.any():
                out[slot] = max(out[slot], float(radius[alpha > 0].max()))
    return tuple(float(r) for r in out)


def support_polygons(
    levels: list[U8] | None, turning: tuple[int, int], depth: int = SUPPORT_LEVELS
) -> F32:
    """For each slot, and after them for the union of the two slots of `turning` (a sprite
    part-way from one texture to the other), the convex polygon outside which its texture is
    transparent on the first `depth` levels, half a texel of each level's bilinear reach
    included, within the octagon around its support disc (`support_radii`), which the
    sprites were drawn as before: (slots + 1, 8, 2) corners in the cell's units (1 = half
    the cell, y up the sprite), in triangle-strip order. A sprite drawn as its polygon shows
    what it showed as the octagon: the round textures are about that octagon, a
    flat-bottomed or puffy one 0.6-0.9 of it, a wisp 0.4-0.6.
    The shipped sheet's (`levels` None) are worked out once a process (30 ms) and shared,
    read-only."""
    if levels is None:
        return _shipped_support_polygons(turning, depth)
    return _support_polygons(levels, turning, depth)


@functools.cache
def _shipped_support_polygons(turning: tuple[int, int], depth: int) -> F32:
    out = _support_polygons(load_sheet(), turning, depth)
    out.flags.writeable = False
    return out


def _support_polygons(levels: list[U8], turning: tuple[int, int], depth: int) -> F32:
    """`support_polygons` of these levels."""
    chain = levels[:depth]
    cells = chain[0].shape[0] // CELL_PX
    normals = np.array([[np.cos(np.radians(a)), np.sin(np.radians(a))] for a in SUPPORT_SIDES_DEG])
    reach = np.abs(normals).sum(axis=1)  # a square's half-width along each normal
    slots = cells * cells
    extents = np.full((slots + 1, len(normals)), -np.inf)
    for level in chain:
        cell = level.shape[0] // cells
        texel = 2.0 / cell
        yy, xx = np.mgrid[0:cell, 0:cell]
        # Texel centres in the cell's units, y up (row 0 is the top of the sprite).
        at = np.stack([(xx + 0.5) * texel - 1.0, 1.0 - (yy + 0.5) * texel], axis=-1)
        shown = []
        for slot in range(slots):
            row, col = divmod(slot, cells)
            alpha = level[row * cell : (row + 1) * cell, col * cell : (col + 1) * cell, 3]
            shown.append(alpha > 0)
        shown.append(shown[turning[0]] | shown[turning[1]])
        for k, mask in enumerate(shown):
            if mask.any():
                # Each texel's square (half a texel) and the filter's reach (half more).
                far = (at[mask] @ normals.T).max(axis=0) + texel * reach
                extents[k] = np.maximum(extents[k], far)
    # No larger than the octagon around the disc the sprites were drawn as before: what
    # coarse levels spread beyond it, sprites never showed.
    radii = support_radii(levels)
    disc = [*radii, max(radii[turning[0]], radii[turning[1]])]
    polygons = np.zeros((slots + 1, len(normals), 2), np.float32)
    for k in range(slots + 1):
        limit = np.minimum(extents[k], disc[k])
        limit[0::2] = np.minimum(limit[0::2], 1.0)  # the axis sides: within the cell
        polygons[k] = _strip(_clip_square(normals, limit))
    return polygons


def _clip_square(normals: F64, limits: F64) -> list[F64]:
    """The convex polygon {p : normals @ p <= limits} (counter-clockwise corners), cut from
    the square [-1, 1]^2 one side at a time."""
    poly = [np.array(c, float) for c in ((-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0))]
    for n, limit in zip(normals, limits, strict=True):
        cut = []
        for i, a in enumerate(poly):
            b = poly[(i + 1) % len(poly)]
            da, db = float(n @ a) - limit, float(n @ b) - limit
            if da <= 0.0:
                cut.append(a)
            if (da < 0.0 < db) or (db < 0.0 < da):  # the side crosses the edge between
                cut.append(a + (b - a) * (da / (da - db)))
        poly = cut
    return poly


def _strip(corners: list[F64]) -> F32:
    """Up to 8 counter-clockwise corners of a convex polygon as 8 triangle-strip vertices
    (zig-zag across it; a polygon of fewer corners repeats its last, adding only empty
    triangles)."""
    ring = list(corners)
    if not ring or len(ring) > 8:
        raise ValueError(f"a support polygon has {len(ring)} corners; 1 to 8 fit the strip")
    ring += [ring[-1]] * (8 - len(ring))
    return np.asarray([ring[i] for i in _STRIP_ORDER], np.float32)


def polygon_corners(strip: F32) -> F64:
    """A support polygon's 8 strip vertices (`support_polygons`) back in order round it,
    counter-clockwise."""
    return np.asarray(strip, np.float64)[np.argsort(_STRIP_ORDER)]


def polygon_area(corners: F64) -> float:
    """The area of a polygon from its corners in order round it (`polygon_corners`),
    positive counter-clockwise."""
    x, y = np.asarray(corners, np.float64).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


# Corners round a convex polygon, in the order a triangle strip zig-zags across it.
_STRIP_ORDER = (0, 1, 7, 2, 6, 3, 5, 4)
