"""The one generator of the cloud texture sheet (see `wxsky.render.sprite_sheet`).

Wang's artists painted 16 textures; this paints them procedurally, from a fixed seed:

* cumulus (flat-bottomed, puffy): a cauliflower of spherical lobes, each lobe budding smaller
  ones on its upper side. The lobes' front surfaces are lit from above (bright tops, a silver
  rim, darker undersides), creases between lobes are darkened by a blurred-height occlusion
  term, and the lower interior is a little darker overall. Alpha is the union of the lobes,
  its edge softened and billowed by noise. The flat-bottomed one is cut by a crisp base line.
* fog: a nearly uniform bluish-grey patch with a broad, gentle fade and faint texture.
* wisps: strands whose alpha comes from noise stretched along the strand (fibres), either
  straight bundles, hooked mares' tails (tangent angle curling up at the head), or ragged
  patches of elongated blobs eroded by anisotropic noise.

Each texture is painted at 2x and box-filtered to 128 px (anti-aliasing the crisp base and
the fibres), then multiplied by a rounded-square window that is exactly zero in the outer
`MARGIN_PX` of the cell. The mip levels are 2x2 means of premultiplied colour; the 32 px
level's outer texel straddles that margin and is cleared. Transparent texels get the colour
of the nearby cloud (push-pull per cell), so bilinear filtering never blends in black.

Only numpy: PCG64 streams from `SeedSequence([seed, slot])` (so retuning one slot leaves
the others alone) and elementwise float64 maths, quantised to 8 bits at the end, so every
machine produces the same bytes. A libm or SIMD difference in the last bit of exp or sin
could in principle flip one rounding somewhere; `tools/generate/build_sprite_sheet.py --check`
would say so.

The parts live in three modules: `wxsky.render.sheet_primitives` (the grid, window, noise
and blur), `wxsky.render.sheet_painters` (the painters per category and which slot each
fills) and this one (painting each cell, the mip chain, push-pull and quantisation).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from wxsky.render.sheet_painters import painters
from wxsky.render.sheet_primitives import SS, WINDOW
from wxsky.render.sprite_sheet import (
    CELL_PX,
    MIP_LEVELS,
    SHEET_SEED,
    level_margin,
)
from wxsky.scene.texture_slots import SHEET_CELLS

F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]


def paint_cell(slot: int, seed: int = SHEET_SEED) -> tuple[F64, F64]:
    """One texture at 128 px: premultiplied RGB (H, W, 3) and alpha (H, W), float64."""
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, slot])))
    rgb, alpha = painters()[slot](rng)
    alpha = np.clip(alpha, 0.0, 1.0) * WINDOW
    prem = np.concatenate([np.clip(rgb, 0.0, 1.0) * alpha[..., None], alpha[..., None]], axis=-1)
    small = prem.reshape(CELL_PX, SS, CELL_PX, SS, 4).mean(axis=(1, 3))
    return small[..., :3], small[..., 3]


def _halve(cells: F64) -> F64:
    """2x2 means of (rows, cols, S, S, C) per-cell images."""
    r, c, s, _, ch = cells.shape
    out: F64 = cells.reshape(r, c, s // 2, 2, s // 2, 2, ch).mean(axis=(3, 5))
    return out


def _to_sheet(cells: F64) -> F64:
    r, c, s, _, ch = cells.shape
    out: F64 = cells.transpose(0, 2, 1, 3, 4).reshape(r * s, c * s, ch)
    return out


def build_levels(seed: int = SHEET_SEED) -> list[U8]:
    """The sheet's mip chain, 512 px first, as straight-alpha RGBA8 (S, S, 4) arrays."""
    n = SHEET_CELLS
    cells = np.zeros((n, n, CELL_PX, CELL_PX, 4))
    for slot in range(n * n):
        rgb, alpha = paint_cell(slot, seed)
        cells[slot // n, slot % n, ..., :3] = rgb
        cells[slot // n, slot % n, ..., 3] = alpha
    pyramid = [cells]
    while pyramid[-1].shape[2] > 1:
        nxt = _halve(pyramid[-1])
        if len(pyramid) < MIP_LEVELS:
            m = level_margin(len(pyramid))
            ring = np.ones(nxt.shape[2], bool)
            ring[m:-m] = False
            nxt[:, :, ring, :, :] = 0.0
            nxt[:, :, :, ring, :] = 0.0
        pyramid.append(nxt)
    # Push-pull: a transparent texel takes the colour of the coarser level's estimate, so it
    # matches the cloud next to it when bilinear filtering mixes the two.
    top = pyramid[-1]
    fill = top[..., :3] / np.maximum(top[..., 3:], 1e-12)
    fills = [fill]
    for level in reversed(pyramid[:-1]):
        up = fills[-1].repeat(2, axis=2).repeat(2, axis=3)
        fills.append(level[..., :3] + (1.0 - level[..., 3:]) * up)
    fills.reverse()
    out = []
    for level, fill in zip(pyramid[:MIP_LEVELS], fills[:MIP_LEVELS], strict=True):
        a = level[..., 3:]
        a8 = np.round(a * 255.0)
        straight = np.where(a8 > 0, level[..., :3] / np.maximum(a, 1e-12), fill)
        rgba = np.concatenate([np.clip(straight, 0.0, 1.0) * 255.0, a8], axis=-1)
        out.append(np.round(_to_sheet(rgba)).astype(np.uint8))
    return out
