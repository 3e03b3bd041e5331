#!/usr/bin/env python3
"""Build the cloud texture sheet shipped in wxsky/render/data/ and its preview.

    .venv/bin/python tools/generate/build_sprite_sheet.py          # the sheet and the preview
    .venv/bin/python tools/generate/build_sprite_sheet.py --check  # exit 1: shipped PNGs drift

Writes wxsky/render/data/cloud_sheet_{512,256,128,64,32}.png (Wang's 16 textures and their
mip chain, straight-alpha RGBA8) from the one generator, `wxsky.render.sheet_textures`, with
the fixed seed `SHEET_SEED`; and docs/gallery/texture-sheet.png, every level composited on a
grey-blue sky so a person can judge the clouds. `--check` regenerates in memory and
compares the shipped PNGs' pixels (not the preview), so CI catches a generator change whose
sheet was not rebuilt. After rebuilding, regenerate the goldens (tools/generate/regen_goldens.py):
the clouds are drawn with these textures.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run from a checkout without installing; `tools.*` too
    sys.path.insert(0, str(ROOT))

from tools.generate.shipped_files import shown, write_or_check  # noqa: E402
from wxsky.png import write_png  # noqa: E402
from wxsky.render.sheet_textures import build_levels  # noqa: E402
from wxsky.render.sprite_sheet import (  # noqa: E402
    DATA_DIR,
    MIP_LEVELS,
    SHEET_PX,
    SHEET_SEED,
    level_filename,
)

DATA = ROOT / "wxsky" / "render" / DATA_DIR
PREVIEW = ROOT / "docs" / "gallery" / "texture-sheet.png"
BACKGROUND = (0.42, 0.52, 0.66)  # a hazy mid-day sky: white and grey both read against it
GAP = 8

U8 = npt.NDArray[np.uint8]


def preview(levels: list[U8]) -> U8:
    """Level 0 on the left, the smaller levels stacked on the right, over a sky colour, with
    faint lines on the cell borders."""
    width = SHEET_PX + GAP + (SHEET_PX >> 1)
    out = np.empty((SHEET_PX, width, 3))
    out[:] = BACKGROUND
    y = 0
    for i, img in enumerate(levels):
        x = 0 if i == 0 else SHEET_PX + GAP
        size = img.shape[0]
        rgba = img.astype(np.float64) / 255.0
        a = rgba[..., 3:]
        tile = out[y : y + size, x : x + size]
        tile[:] = rgba[..., :3] * a + tile * (1.0 - a)
        cell = size // 4
        if cell >= 16:
            for k in range(1, 4):
                tile[k * cell, :] *= 0.85
                tile[:, k * cell] *= 0.85
        if i > 0:
            y += size + GAP
    rgb8 = np.round(out * 255.0).astype(np.uint8)
    return np.concatenate([rgb8, np.full((*rgb8.shape[:2], 1), 255, np.uint8)], axis=2)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--check", action="store_true", help="compare with the shipped files, write nothing"
    )
    args = parser.parse_args(argv)
    levels = build_levels(SHEET_SEED)
    images = {level_filename(i): img for i, img in enumerate(levels)}
    assert len(images) == MIP_LEVELS
    status = write_or_check(
        images, DATA, check=args.check, tool="tools/generate/build_sprite_sheet.py"
    )
    if status or args.check:
        return status
    write_png(PREVIEW, preview(levels))
    print(f"wrote {shown(PREVIEW)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
