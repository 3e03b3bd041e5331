"""Horizontal streaks in the far field: vertical against horizontal gradient energy, before | after.

    .venv/bin/python tools/bench/banding.py [--before REF] [--preset NAME ...]
        [--json FILE] [--jobs 1] [--cache-dir build/banding]

Issue 42's "no streaking" measure. Each case is a `wxsky snapshot` at 1280x720, the eye 2 m
above the preset's observer looking 4 deg up with a 60 deg field of view, at the day's noon
and with the sun 5 deg up on the preset's own morning (`tools/gallery/light_sheet.py` finds
the times), facing the sun and facing away. Over the band of pixels whose ray is 0.5 to 8 deg
above level, the picture's luma (Rec. 709 weights on its display values) is differenced
down the rows and across the columns; the case's figure is the energy (sum of squares) of the
vertical differences over that of the horizontal ones. Stacked slices of cloud, stripes, and
a far field of thin flat sprites read high; cloud sides seen at the horizon are not
foreshortened, so real skies sit near 1-1.5; the issue's bar is 1.6.

Both sides are drawn by their own revision's code (`--before`: a temporary detached
worktree), cached by their `wxsky/` tree as the light sheet's cells are. Prints a table; with
`--json`, writes every case's figures.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tools.gallery import light_sheet as sheet  # noqa: E402
from wxsky.png import read_png  # noqa: E402
from wxsky.scene.camera import camera_basis  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

F64 = npt.NDArray[np.float64]

PRESETS = ("fair-cumulus", "scattered-cumulus", "towering-cumulus")
MOMENTS: tuple[tuple[str, float | None], ...] = (("noon", None), ("sun+5", 5.0))
SIZE = (1280, 720)
PITCH_DEG = 4.0
FOV_DEG = 60.0  # `wxsky snapshot`'s default
BAND_DEG = (0.5, 8.0)
BAR = 1.6
LUMA = np.array([0.2126, 0.7152, 0.0722])


def ray_elevation_deg(size: tuple[int, int], pitch_deg: float, fov_deg: float) -> F64:
    """(H, W) the elevation above level of each pixel's ray (row 0 the top), as the renderer
    casts them: through the pixel's centre, level camera roll."""
    width, height = size
    right, up, fwd = camera_basis(0.0, pitch_deg, 0.0)
    tan_x = math.tan(math.radians(fov_deg) / 2.0)
    tan_y = tan_x * height / width
    x = ((np.arange(width) + 0.5) / width * 2.0 - 1.0)[None, :]
    y = ((np.arange(height) + 0.5) / height * 2.0 - 1.0)[:, None]
    rays = [fwd[i] + x * tan_x * right[i] - y * tan_y * up[i] for i in range(3)]
    norm = np.sqrt(rays[0] ** 2 + rays[1] ** 2 + rays[2] ** 2)
    out: F64 = np.degrees(np.arcsin(np.clip(rays[2] / norm, -1.0, 1.0)))
    return out


def banding(rgb: npt.NDArray[np.uint8], elevation_deg: F64, band: tuple[float, float]) -> float:
    """Vertical over horizontal gradient energy of the luma over the pixels whose elevation is
    within `band` (both ends of each difference inside it). inf where the band is flat across
    and not down; nan where it is flat both ways."""
    luma = (rgb[..., :3].astype(np.float64) / 255.0) @ LUMA
    inside = (elevation_deg >= band[0]) & (elevation_deg <= band[1])
    down = np.diff(luma, axis=0)[inside[1:] & inside[:-1]]
    across = np.diff(luma, axis=1)[inside[:, 1:] & inside[:, :-1]]
    vertical, horizontal = float(np.sum(down * down)), float(np.sum(across * across))
    if horizontal == 0.0:
        return math.nan if vertical == 0.0 else math.inf
    return vertical / horizontal


def cases(presets: Sequence[str]) -> list[sheet.Cell]:
    out = []
    for name in presets:
        state = WeatherState().apply(load_preset(name, ()))
        obs = state.observer
        for moment, elevation in MOMENTS:
            sun = sheet.sun_time(state.time_utc, obs.lat_deg, obs.lon_deg, elevation)
            for facing, turn in (("toward the sun", 0.0), ("away from the sun", 180.0)):
                out.append(
                    sheet.Cell(
                        preset=name,
                        moment=moment,
                        facing=facing,
                        eye="ground",
                        time_utc=sun.time_utc,
                        heading_deg=sun.azimuth_deg + turn,
                        pitch_deg=PITCH_DEG,
                        alt_m=obs.alt_m + sheet.GROUND_EYE_AGL_M,
                        size=SIZE,
                    )
                )
    return out


def measure(found: dict[sheet.Cell, Path | str]) -> dict[sheet.Cell, float | str]:
    elevation = ray_elevation_deg(SIZE, PITCH_DEG, FOV_DEG)
    out: dict[sheet.Cell, float | str] = {}
    for cell, path in found.items():
        if isinstance(path, str):
            out[cell] = path
        else:
            out[cell] = banding(read_png(path), elevation, BAND_DEG)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--before", default="", metavar="REF", help="a revision to compare with")
    p.add_argument("--preset", action="append", help=f"only these (default {', '.join(PRESETS)})")
    p.add_argument("--json", type=Path, help="write every case's figures there")
    p.add_argument("--jobs", type=int, default=1, help="snapshots at once (default 1)")
    p.add_argument("--cache-dir", type=Path, default=ROOT / "build" / "banding")
    args = p.parse_args(argv)
    started = time.monotonic()
    todo = cases(args.preset or PRESETS)
    sides: dict[str, dict[sheet.Cell, float | str]] = {}
    labels: dict[str, str] = {}
    if args.before:
        commit, key = sheet.revision_key(args.before)
        with sheet.temporary_worktree(commit) as checkout:
            sides["before"] = measure(
                sheet.render_all(checkout, key, todo, args.cache_dir, args.jobs)
            )
        labels["before"] = f"{args.before} ({commit[:7]})"
    key = sheet.checkout_key(ROOT)
    sides["after"] = measure(sheet.render_all(ROOT, key, todo, args.cache_dir, args.jobs))
    labels["after"] = "this checkout"
    print(
        f"banding: vertical / horizontal gradient energy, {BAND_DEG[0]}-{BAND_DEG[1]} deg up "
        f"(bar {BAR})"
    )
    heads = "".join(f"{s:>12}" for s in sides)
    print(f"{'preset':<20}{'moment':<8}{'facing':<20}{heads}")
    rows = []
    for cell in todo:
        values = {s: sides[s][cell] for s in sides}
        shown = "".join(
            f"{v:>12.2f}" if isinstance(v, float) else f"{'error':>12}" for v in values.values()
        )
        print(f"{cell.preset:<20}{cell.moment:<8}{cell.facing:<20}{shown}")
        rows.append(
            {
                "preset": cell.preset,
                "moment": cell.moment,
                "facing": cell.facing,
                "time_utc": cell.time_utc.isoformat(),
                "heading_deg": cell.heading_deg,
                **{s: v for s, v in values.items()},
            }
        )
    if args.json is not None:
        report = {
            "band_deg": list(BAND_DEG),
            "size": list(SIZE),
            "pitch_deg": PITCH_DEG,
            "fov_deg": FOV_DEG,
            "bar": BAR,
            "sides": labels,
            "cases": rows,
        }
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    print(f"done in {time.monotonic() - started:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
