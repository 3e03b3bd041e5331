"""Write generated package data, or check that the shipped copy is what the generator makes.

Shared by the tools that build PNGs shipped in the package (the cloud texture sheet, the sky
textures): writes go through a temporary file and a rename, so an interrupted build never
leaves half a PNG; `check` compares the decoded pixels, so CI catches a generator change
whose files were not rebuilt. Not the file bytes: zlib builds differ between machines in what
they compress the same pixels to, and a file rebuilt elsewhere is no less up to date.
"""

from __future__ import annotations

import struct
import sys
import zlib
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import numpy.typing as npt

from wxsky.png import encode_png, read_png

ROOT = Path(__file__).resolve().parents[2]

U8 = npt.NDArray[np.uint8]


def shown(path: Path) -> str:
    """A path as a person reads it: relative to the checkout when it is inside it."""
    path = path.resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def difference(path: Path, image: U8) -> str | None:
    """Why the PNG at `path` does not hold `image` (RGBA8), or None when its pixels are it."""
    if not path.exists():
        return "missing"
    try:
        shipped = read_png(path)
    except (ValueError, struct.error, zlib.error) as exc:
        return f"unreadable: {exc}"
    if shipped.shape != image.shape:
        return f"{shipped.shape[1]}x{shipped.shape[0]} px, not {image.shape[1]}x{image.shape[0]}"
    differ = int(np.count_nonzero((shipped != image).any(axis=-1)))
    return f"{differ} pixels differ" if differ else None


def write_or_check(images: Mapping[str, U8], folder: Path, *, check: bool, tool: str) -> int:
    """Write `images` (name -> RGBA8 pixels) into `folder` as PNGs, or with `check` compare
    them with the pixels of what is there; returns the exit status (1: a file is missing or
    shows other pixels)."""
    if check:
        stale = [
            f"{name} ({why})"
            for name, image in images.items()
            if (why := difference(folder / name, image)) is not None
        ]
        if stale:
            print(f"out of date: {', '.join(stale)} (run {tool})", file=sys.stderr)
            return 1
        print(f"up to date: {len(images)} files in {shown(folder)}")
        return 0
    folder.mkdir(parents=True, exist_ok=True)
    for name, image in images.items():
        data = encode_png(image)
        tmp = folder / (name + ".tmp")
        tmp.write_bytes(data)
        tmp.replace(folder / name)
        print(f"wrote {shown(folder / name)} ({len(data):,} bytes)")
    return 0
