"""The cloud texture sheet: 16 sprite textures on one 512x512 RGBA sheet (Wang's layout).

Generated procedurally from a fixed seed, so every machine builds the same bytes. Slots, in
row-major order on a 4 x 4 grid, as `wxsky.scene.texture_slots` lays them out: 0 flat-bottomed
(cumulus bases), 1-3 foggy (stratus), 4-9 puffy, 10-15 wispy (cirrus; 13-15 more ragged).
Each texture's alpha falls to exactly zero before its cell border, so mip-mapping never
bleeds one cell into the next and a sprite's footprint ends where its quad ends.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from wxsky.scene.texture_slots import SHEET_CELLS, TEX_FLAT_BOTTOM, TEX_FOG, TEX_PUFFY, TEX_WISPY

CELL_PX = 128
SHEET_PX = SHEET_CELLS * CELL_PX
SHEET_SEED = 20040101

F64 = npt.NDArray[np.float64]


def build_sheet(seed: int = SHEET_SEED) -> npt.NDArray[np.uint8]:
    """(512, 512, 4) RGBA8, straight alpha, row 0 at the top of each sprite."""
    rng = np.random.default_rng(seed)
    sheet = np.zeros((SHEET_PX, SHEET_PX, 4), np.float64)
    for slot in range(SHEET_CELLS * SHEET_CELLS):
        if slot in TEX_FLAT_BOTTOM:
            alpha = _puffy(rng, flat_bottom=True)
        elif slot in TEX_FOG:
            alpha = _fog(rng)
        elif slot in TEX_PUFFY:
            alpha = _puffy(rng, flat_bottom=False)
        elif slot in TEX_WISPY[:3]:
            alpha = _wispy(rng)
        else:
            alpha = _ragged(rng)
        detail = _value_noise(rng, CELL_PX, 4) * 0.7 + _value_noise(rng, CELL_PX, 8) * 0.3
        lum = 0.86 + 0.14 * detail
        y, x = divmod(slot, SHEET_CELLS)
        cell = sheet[y * CELL_PX : (y + 1) * CELL_PX, x * CELL_PX : (x + 1) * CELL_PX]
        cell[..., 0] = lum
        cell[..., 1] = lum
        cell[..., 2] = lum * (1.03 if slot in TEX_FOG else 1.0)  # Wang's fog: a bluish tinge
        cell[..., 3] = alpha
    return np.round(np.clip(sheet, 0.0, 1.0) * 255.0).astype(np.uint8)


def _grid() -> tuple[F64, F64]:
    c = (np.arange(CELL_PX) + 0.5) / CELL_PX * 2.0 - 1.0
    yy, xx = np.meshgrid(c, c, indexing="ij")
    return xx, -yy  # y up


def _window(xx: F64, yy: F64) -> F64:
    r = np.hypot(xx, yy)
    return np.clip((0.94 - r) / 0.2, 0.0, 1.0) ** 2


def _value_noise(rng: np.random.Generator, size: int, cells: int) -> F64:
    grid = rng.uniform(size=(cells + 1, cells + 1))
    t = np.linspace(0.0, cells, size, endpoint=False)
    i = t.astype(int)
    f = t - i
    f = f * f * (3.0 - 2.0 * f)
    g00 = grid[np.ix_(i, i)]
    g01 = grid[np.ix_(i, i + 1)]
    g10 = grid[np.ix_(i + 1, i)]
    g11 = grid[np.ix_(i + 1, i + 1)]
    fy, fx = f[:, None], f[None, :]
    out: F64 = (g00 * (1 - fx) + g01 * fx) * (1 - fy) + (g10 * (1 - fx) + g11 * fx) * fy
    return out


def _blobs(rng: np.random.Generator, n: int, spread: float, size: tuple[float, float]) -> F64:
    xx, yy = _grid()
    acc = np.zeros_like(xx)
    for _ in range(n):
        cx, cy = rng.uniform(-spread, spread, size=2)
        s = rng.uniform(*size)
        acc += np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * s * s))
    return acc


def _puffy(rng: np.random.Generator, flat_bottom: bool) -> F64:
    xx, yy = _grid()
    acc = _blobs(rng, 7, 0.35, (0.16, 0.28))
    alpha = np.clip(acc * 0.9, 0.0, 1.0) * (0.75 + 0.25 * _value_noise(rng, CELL_PX, 8))
    if flat_bottom:
        alpha *= np.clip((yy + 0.15) / 0.12, 0.0, 1.0)
    return np.clip(alpha * _window(xx, yy), 0.0, 1.0)


def _fog(rng: np.random.Generator) -> F64:
    xx, yy = _grid()
    r = np.hypot(xx, yy)
    base = np.clip(1.0 - r / 0.9, 0.0, 1.0) ** 0.7
    noise = 0.6 + 0.4 * _value_noise(rng, CELL_PX, 6)
    return np.clip(base * noise * 0.95 * _window(xx, yy), 0.0, 1.0)


def _wispy(rng: np.random.Generator) -> F64:
    xx, yy = _grid()
    acc = np.zeros_like(xx)
    for _ in range(6):
        cy = rng.uniform(-0.4, 0.4)
        w = rng.uniform(0.03, 0.08)
        bend = rng.uniform(-0.3, 0.3)
        acc += np.exp(-((yy - cy - bend * xx * xx) ** 2) / (2 * w * w)) * np.clip(
            1.0 - np.abs(xx) / rng.uniform(0.6, 0.9), 0.0, 1.0
        )
    streaks = 0.5 + 0.5 * _value_noise(rng, CELL_PX, 24)
    return np.clip(acc * streaks * 0.8 * _window(xx, yy), 0.0, 1.0)


def _ragged(rng: np.random.Generator) -> F64:
    xx, yy = _grid()
    acc = _blobs(rng, 10, 0.45, (0.1, 0.2))
    noise = _value_noise(rng, CELL_PX, 12)
    return np.clip(acc * 0.8 * (0.4 + 0.8 * noise) * _window(xx, yy), 0.0, 1.0)
