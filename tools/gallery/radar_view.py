#!/usr/bin/env python3
"""The weather radar beside the view (issue 43, item 6): what a pilot sees out of the window
and what the radar shows of the same storms, for docs/gallery/.

    .venv/bin/python tools/gallery/radar_view.py [--out docs/gallery/radar-beside-view.png]

The storm gallery's sky (`storm_gallery.py`: the thunderstorm preset's cumulonimbus at 1/8 in
clear air, heavy rain), from 2,500 m looking east with a 50° field; beside it the radar's
picture at 40 NM, level antenna, turned heading-up as a cockpit display shows it, the view's
field of view drawn on it in white and range rings every 10 NM.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tools.gallery.storm_gallery import HEADING_DEG, storm  # noqa: E402
from wxsky.app.snapshot import take_snapshot  # noqa: E402
from wxsky.png import write_png  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.scene.radar import radar_picture  # noqa: E402

RANGE_NM = 40.0
FOV_DEG = 50.0
# The usual weather-radar colours: green from 20 dBZ, yellow 30, red 40, magenta 50.
PALETTE = ((20.0, (0, 150, 0)), (30.0, (230, 220, 0)), (40.0, (230, 30, 0)), (50.0, (220, 0, 220)))


def colour(dbz: npt.NDArray[np.float64]) -> npt.NDArray[np.uint8]:
    out = np.zeros((*dbz.shape, 4), np.uint8)
    out[..., 3] = 255
    for lo, rgb in PALETTE:
        out[dbz >= lo, :3] = rgb
    return out


def heading_up(img: npt.NDArray[np.uint8], heading_deg: float) -> npt.NDArray[np.uint8]:
    """The north-up picture turned so that `heading_deg` points up (nearest pixel)."""
    n = img.shape[0]
    half = n / 2.0
    y, x = np.mgrid[0:n, 0:n] + 0.5
    a = math.radians(heading_deg)
    dx, dy = x - half, half - y  # screen right, up
    east = dx * math.cos(a) + dy * math.sin(a)
    north = -dx * math.sin(a) + dy * math.cos(a)
    cols = np.clip((east + half).astype(int), 0, n - 1)
    rows = np.clip((half - north).astype(int), 0, n - 1)
    return img[rows, cols]


def marks(img: npt.NDArray[np.uint8]) -> None:
    """Range rings every 10 NM and the view's field of view, in place (heading-up)."""
    n = img.shape[0]
    half = n / 2.0
    y, x = np.mgrid[0:n, 0:n] + 0.5
    r = np.hypot(x - half, half - y) / half * RANGE_NM
    for ring in (10.0, 20.0, 30.0, 40.0):
        img[np.abs(r - ring) < 0.12, :3] = (90, 90, 90)
    bearing = np.degrees(np.arctan2(x - half, half - y))
    edge = np.abs(np.abs(bearing) - 0.5 * FOV_DEG) < 0.4
    img[edge & (r < RANGE_NM), :3] = (255, 255, 255)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/gallery/radar-beside-view.png"))
    args = parser.parse_args()
    height = 360
    eye = (0.0, 0.0, 2500.0)
    camera = Camera(eye, HEADING_DEG, -2.0, fov_deg=FOV_DEG, width_px=640, height_px=height)
    state = storm(("+TSRA",))
    settings = SceneSettings(ring_radius_m=24_000.0)
    with Renderer(settings.ring_texture_px) as renderer:
        view = take_snapshot(state, camera, settings, renderer).image
    # The snapshot's own drift is none: the clouds stand where the weather's clock puts
    # them with no wind time, as the radar's do with zero drift.
    pic = radar_picture(state, [(0.0, 0.0)], eye, RANGE_NM, 0.0, height)
    radar = heading_up(colour(pic.dbz), HEADING_DEG)
    marks(radar)
    gap = np.full((height, 4, 4), 255, np.uint8)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_png(args.out, np.concatenate([view, gap, radar], axis=1))
    print(f"wrote {args.out}: the view east and the radar at {RANGE_NM:g} NM, heading-up")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
