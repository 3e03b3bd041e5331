#!/usr/bin/env python3
"""Draw what a sprite covers: each texture of the cloud sheet with the octagon around its
support disc (what sprites were drawn as until 2026-12-04) and the support polygons they are
drawn as now, fine (the levels sprites 48 px across and more read) and coarse (every level).

    .venv/bin/python tools/gallery/sprite_polygons.py [--out docs/gallery/sprite-polygons.png]

Each cell is the full-size texture over a dark sky, its empty texels darker still; the
octagon blue, the fine polygon orange, the coarse one yellow, and under each cell the share
of the octagon's area the fine polygon keeps (the fragments a sprite still costs).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

from wxsky.png import write_png  # noqa: E402
from wxsky.render.sprite_sheet import (  # noqa: E402
    CELL_PX,
    load_sheet,
    polygon_area,
    polygon_corners,
    support_polygons,
    support_radii,
)
from wxsky.scene.texture_slots import SHEET_CELLS, TEX_FLAT_BOTTOM, TEX_FOG  # noqa: E402

SCALE = 2  # output pixels per texel
PAD = 12
OCTAGON = (90, 150, 255)
FINE = (255, 150, 40)
COARSE = (250, 230, 60)
SKY = np.array([40, 48, 60], np.float64)
EMPTY = np.array([22, 26, 32], np.float64)
# 3x5 digits for the share under each cell.
_DIGITS = {
    "0": "111101101101111",
    "1": "010110010010111",
    "2": "111001111100111",
    "3": "111001111001111",
    "4": "101101111001001",
    "5": "111100111001111",
    "6": "111100111101111",
    "7": "111001001001001",
    "8": "111101111101111",
    "9": "111101111001111",
    ".": "000000000000010",
}


def _octagon(radius: float) -> npt.NDArray[np.float64]:
    angle = np.radians(22.5 + 45.0 * np.arange(8))
    ring = np.stack([np.cos(angle), np.sin(angle)], axis=1) * radius / math.cos(math.radians(22.5))
    return np.clip(ring, -1.0, 1.0)


def _line(
    img: npt.NDArray[np.uint8],
    a: tuple[float, float],
    b: tuple[float, float],
    rgb: tuple[int, int, int],
) -> None:
    n = int(max(abs(b[0] - a[0]), abs(b[1] - a[1]))) + 1
    xs = np.linspace(a[0], b[0], n).round().astype(int)
    ys = np.linspace(a[1], b[1], n).round().astype(int)
    ok = (xs >= 0) & (xs < img.shape[1]) & (ys >= 0) & (ys < img.shape[0])
    img[ys[ok], xs[ok], :3] = rgb


def _outline(
    img: npt.NDArray[np.uint8],
    ring: npt.NDArray[np.float64],
    x0: int,
    y0: int,
    rgb: tuple[int, int, int],
) -> None:
    size = CELL_PX * SCALE
    pts = [(x0 + (p[0] + 1.0) * 0.5 * size, y0 + (1.0 - p[1]) * 0.5 * size) for p in ring]
    for a, b in zip(pts, pts[1:] + pts[:1], strict=True):
        _line(img, a, b, rgb)


def _text(img: npt.NDArray[np.uint8], text: str, x: int, y: int) -> None:
    for ch in text:
        glyph = np.array([int(c) for c in _DIGITS[ch]], bool).reshape(5, 3)
        block = np.kron(glyph, np.ones((2, 2), bool))
        img[y : y + 10, x : x + 6, :3][block] = 230
        x += 8


def render() -> npt.NDArray[np.uint8]:
    levels = load_sheet()
    turning = (TEX_FLAT_BOTTOM[0], TEX_FOG[0])
    fine = support_polygons(levels, turning)
    coarse = support_polygons(levels, turning, depth=len(levels))
    radii = support_radii(levels)
    size = CELL_PX * SCALE
    step = size + PAD
    img = np.zeros((SHEET_CELLS * (step + 14) + PAD, SHEET_CELLS * step + PAD, 4), np.uint8)
    img[..., :3] = 12
    img[..., 3] = 255
    sheet = levels[0].astype(np.float64) / 255.0
    for slot in range(SHEET_CELLS * SHEET_CELLS):
        row, col = divmod(slot, SHEET_CELLS)
        cell = sheet[row * CELL_PX : (row + 1) * CELL_PX, col * CELL_PX : (col + 1) * CELL_PX]
        alpha = cell[..., 3:4]
        under = np.where(alpha > 0, SKY, EMPTY)
        rgb = cell[..., :3] * 255.0 * alpha + under * (1.0 - alpha)
        big = np.kron(rgb, np.ones((SCALE, SCALE, 1)))
        x0, y0 = PAD + col * step, PAD + row * (step + 14)
        img[y0 : y0 + size, x0 : x0 + size, :3] = big.clip(0, 255).astype(np.uint8)
        octagon = _octagon(radii[slot])
        _outline(img, octagon, x0, y0, OCTAGON)
        _outline(img, polygon_corners(coarse[slot]), x0, y0, COARSE)
        _outline(img, polygon_corners(fine[slot]), x0, y0, FINE)
        share = polygon_area(polygon_corners(fine[slot])) / polygon_area(octagon)
        _text(img, f"{share:.2f}", x0, y0 + size + 3)
    return img


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs/gallery/sprite-polygons.png")
    args = parser.parse_args()
    write_png(args.out, render())
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
