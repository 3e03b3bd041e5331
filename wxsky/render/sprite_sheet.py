"""The cloud texture sheet: 16 sprite textures on one 512x512 RGBA sheet (Wang's layout), and
its mip chain down to 32x32, shipped as package data.

Slots, row-major on a 4 x 4 grid as `wxsky.scene.texture_slots` lays them out: 0 flat-bottomed
(cumulus bases), 1-3 foggy (stratus), 4-9 puffy, 10-15 wispy: 10-11 straight fibres and 12 a
hooked mares' tail (the "streaks" of cirrus), 13-15 ragged broken wisps (the "ragged" fringes
and scud of the cloud models, see `wxsky.scene.cloud_model_files`).

The PNGs under `data/` are made by `tools/build_sprite_sheet.py` from the one generator,
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
