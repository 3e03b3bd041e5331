"""Write generated package data, or check that the shipped copy is what the generator makes.

Shared by the tools that build files shipped in the package (the cloud texture sheet, the
sky textures): writes go through a temporary file and a rename, so an interrupted build never
leaves half a PNG; `check` byte-compares, so CI catches a generator change whose files were
not rebuilt.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def shown(path: Path) -> str:
    """A path as a person reads it: relative to the checkout when it is inside it."""
    path = path.resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def write_or_check(files: Mapping[str, bytes], folder: Path, *, check: bool, tool: str) -> int:
    """Write `files` (name -> bytes) into `folder`, or with `check` compare them with what is
    there; returns the exit status (1: a file is missing or differs)."""
    if check:
        stale = [
            name
            for name, data in files.items()
            if not (folder / name).exists() or (folder / name).read_bytes() != data
        ]
        if stale:
            print(f"out of date: {', '.join(stale)} (run {tool})", file=sys.stderr)
            return 1
        print(f"up to date: {len(files)} files in {shown(folder)}")
        return 0
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        tmp = folder / (name + ".tmp")
        tmp.write_bytes(data)
        tmp.replace(folder / name)
        print(f"wrote {shown(folder / name)} ({len(data):,} bytes)")
    return 0
