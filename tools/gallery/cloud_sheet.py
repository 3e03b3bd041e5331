"""Every cloudy preset's clouds close, at 5, 20 and 60 km and in profile, before | after.

    .venv/bin/python tools/gallery/cloud_sheet.py [--before REF] [--preset NAME ...]
        [--sun-deg 20] [--size 384x216] [--jobs 1] [--palette]
        [--out-dir docs/gallery] [--cache-dir build/cloud-sheet]

Issue 42's picture sheet (item 7). For each preset with clouds, one row per view of its
lowest layer, each a `wxsky snapshot` with the sun `--sun-deg` up on the preset's own
morning, facing away from the sun (the clouds' lit sides toward the eye):

- **close**: from the ground, 35 deg up with a 75 deg field of view: the clouds overhead and
  within a few km, bases from below;
- **5 km**, **20 km**, **60 km**: from the ground, aimed at the layer's middle that far away
  (the Earth's curvature taken off) with a field of view that spans about 8 km there (at
  most 60 deg): one cloud, a few, a whole row receding into haze;
- **profile**: the eye 500 m below the layer's base (at least 50 m above the ground), level,
  60 deg: a line of flat bases receding into the distance.

Each row is the `--before` revision (default 712da9a, main before issue 42's changes) |
this checkout, drawn by their own code in their own worktree, cached by their `wxsky/` tree
(`light_sheet.py`'s machinery). Writes `cloud-sheet-PRESET.png` per preset and
`cloud-sheet.md` (the index) into `--out-dir`.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tools.gallery import light_sheet as sheet  # noqa: E402
from wxsky.cli.common import parse_size  # noqa: E402
from wxsky.settings.presets import list_presets, load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

ISSUE_42_START = "712da9a"
EARTH_RADIUS_M = 6_371_000.0
SPAN_M = 8_000.0  # what a distant view's field of view spans at its distance
CLOSE = (35.0, 75.0)  # pitch, fov
PROFILE_BELOW_M = 500.0
DISTANCES_KM = (5.0, 20.0, 60.0)
VIEWS = ("close", *(f"{d:g} km" for d in DISTANCES_KM), "profile")
FACING = "away from the sun"


def aim(height_m: float, distance_m: float) -> tuple[float, float]:
    """(pitch, fov) from the ground at a point height_m up and distance_m away, the Earth's
    curvature taken off its height, the fov spanning SPAN_M there."""
    drop = distance_m * distance_m / (2.0 * EARTH_RADIUS_M)
    pitch = math.degrees(math.atan2(height_m - drop, distance_m))
    fov = min(60.0, math.degrees(2.0 * math.atan(SPAN_M / 2.0 / distance_m)))
    return pitch, fov


def preset_cells(
    name: str, sun_deg: float, size: tuple[int, int]
) -> tuple[list[sheet.Cell], str] | None:
    """The preset's cells in VIEWS order and a line on its lowest layer; None if clear."""
    state = WeatherState().apply(load_preset(name, ()))
    if not state.layers:
        return None
    obs = state.observer
    layer = min(state.layers, key=lambda lay: lay.base_m)
    sun = sheet.sun_time(state.time_utc, obs.lat_deg, obs.lon_deg, sun_deg)
    heading = sun.azimuth_deg + 180.0
    ground = obs.alt_m + sheet.GROUND_EYE_AGL_M
    middle = 0.5 * (layer.base_m + layer.top_m) - obs.alt_m

    def cell(view: str, pitch: float, alt_m: float, fov: float) -> sheet.Cell:
        return sheet.Cell(
            name, view, FACING, "ground", sun.time_utc, heading, pitch, alt_m, size, fov
        )

    cells = [cell("close", CLOSE[0], ground, CLOSE[1])]
    for km in DISTANCES_KM:
        pitch, fov = aim(middle, km * 1000.0)
        cells.append(cell(f"{km:g} km", pitch, ground, fov))
    profile_alt = max(layer.base_m - PROFILE_BELOW_M, obs.alt_m + 50.0)
    cells.append(cell("profile", 0.0, profile_alt, 60.0))
    about = (
        f"{layer.type.name.lower()} {layer.cover_oktas:g}/8, base {layer.base_m:.0f} m, top "
        f"{layer.top_m:.0f} m MSL; sun {sun.elevation_deg:+.0f} at {sun.time_utc:%H:%M}Z"
    )
    return cells, about


def preset_sheet(
    name: str,
    about: str,
    cells: Sequence[sheet.Cell],
    before: dict[sheet.Cell, Path | str],
    after: dict[sheet.Cell, Path | str],
    size: tuple[int, int],
    titles: tuple[str, str],
) -> np.ndarray:
    w, h = size
    label_w = sheet.LABEL_W_PX
    width = label_w + 2 * w + sheet.GAP_PX
    height = sheet.HEADER_H_PX + len(cells) * (h + sheet.GAP_PX)
    out = np.full((height, width, 4), sheet.BACKGROUND, np.uint8)
    sheet._label(out, [titles[0]], label_w, 2, 11)
    sheet._label(out, [titles[1]], label_w + w + sheet.GAP_PX, 2, 11)
    sheet._label(out, [about], label_w, 18, 11)
    for r, cell in enumerate(cells):
        y = sheet.HEADER_H_PX + r * (h + sheet.GAP_PX)
        lines = [name, cell.moment, f"pitch {cell.pitch_deg:+.2f}", f"fov {cell.fov_deg:.1f}"]
        if cell.moment == "profile":
            lines.append(f"eye {cell.alt_m:.0f} m MSL")
        sheet._label(out, lines, 4, y + 4, 11)
        out[y : y + h, label_w : label_w + w] = sheet._tile(before[cell], size)
        out[y : y + h, label_w + w + sheet.GAP_PX : width] = sheet._tile(after[cell], size)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", default=ISSUE_42_START, metavar="REF")
    p.add_argument("--preset", action="append", help="only these presets (repeatable)")
    p.add_argument("--sun-deg", type=float, default=20.0, help="the sun's elevation (20)")
    p.add_argument("--size", default="384x216", help="each cell, WxH (default 384x216)")
    p.add_argument("--palette", action="store_true", help="256-colour dithered PNGs (smaller)")
    p.add_argument("--jobs", type=int, default=1, help="snapshots at once (default 1)")
    p.add_argument("--out-dir", type=Path, default=ROOT / "docs" / "gallery")
    p.add_argument("--cache-dir", type=Path, default=ROOT / "build" / "cloud-sheet")
    args = p.parse_args(argv)
    size = parse_size(args.size)
    started = time.monotonic()
    names = args.preset or [e.name for e in list_presets(()) if e.origin == "builtin"]
    per: dict[str, tuple[list[sheet.Cell], str]] = {}
    for name in names:
        got = preset_cells(name, args.sun_deg, size)
        if got is None:
            print(f"{name}: no clouds, skipped")
        else:
            per[name] = got
    every = [c for cells, _ in per.values() for c in cells]
    before, after, titles = sheet.render_sides(args.before, every, args.cache_dir, args.jobs)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, (cells, about) in per.items():
        image = preset_sheet(name, about, cells, before, after, size, titles)
        sheet.write_sheet(args.out_dir / f"cloud-sheet-{name}.png", image, args.palette)
        rows.append(f"| {name} | {about} | [cloud-sheet-{name}.png](cloud-sheet-{name}.png) |")
    command = "tools/gallery/cloud_sheet.py " + " ".join(argv or sys.argv[1:])
    text = "\n".join(
        [
            "# Cloud sheet: every cloudy preset close, at 5, 20 and 60 km and in profile",
            "",
            f"Made by `{command.strip()}` (issue 42 item 7) in "
            f"{time.monotonic() - started:.0f} s, drawing {sum(sheet.DRAWN)} cells (the rest "
            "cached). Each row: **before** (left) | **after** (right); views in "
            "tools/gallery/cloud_sheet.py's docstring, all facing away from the sun.",
            "",
            "| preset | lowest layer, sun | sheet |",
            "|---|---|---|",
            *rows,
        ]
    )
    (args.out_dir / "cloud-sheet.md").write_text(text + "\n")
    print(f"wrote {len(rows)} sheets to {args.out_dir} in {time.monotonic() - started:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
