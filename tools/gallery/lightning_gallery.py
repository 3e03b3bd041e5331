#!/usr/bin/env python3
"""Lightning frames (issue 43, items 4 and 6): the thunderstorm preset with heavy rain and
thunder (+TSRA) in 20 km visibility, from 300 m over the field, at 14:40 and at 21:40 UTC: the
frame before a flash and the frame it lights, side by side.

    .venv/bin/python tools/gallery/lightning_gallery.py [--out docs/gallery/lightning.png]

Each row steps the engine (`SkyEngine.advance`, 20 frames a second of simulated time) to the
first flash that lights the clouds at 0.9 or more of its intensity, then draws that moment and
1.5 s before it, looking at the flash 15° up with a 70° field.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from datetime import timedelta
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from wxsky.app.snapshot import take_snapshot  # noqa: E402
from wxsky.engine.stages import SkyEngine  # noqa: E402
from wxsky.png import write_png  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState, parse_time_utc  # noqa: E402

TIMES = ("2026-07-22T14:40:00Z", "2026-07-22T21:40:00Z")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/gallery/lightning.png"))
    args = parser.parse_args()
    settings = SceneSettings(max_towers=2)
    rows = []
    with Renderer(settings.ring_texture_px) as renderer:
        for when in TIMES:
            state = dataclasses.replace(
                WeatherState().apply(load_preset("thunderstorm")),
                present_weather=("+TSRA",),
                visibility_m=20_000.0,
                time_utc=parse_time_utc(when),
            )
            eye = (0.0, 0.0, state.observer.alt_m + 300.0)
            found = None
            with SkyEngine(state, Camera(eye), settings, clock_rate=1.0) as engine:
                for _ in range(2400):
                    plan = engine.advance(0.05)
                    bright = [f for f, g in plan.frame.flashes if g > 0.9]
                    if bright:
                        found = (plan.state.time_utc, bright[0])
                        break
            if found is None:
                raise SystemExit(f"no flash within two minutes from {when}")
            moment, flash = found
            x, y, _ = flash.position_m
            heading = math.degrees(math.atan2(x - eye[0], y - eye[1]))
            cam = Camera(eye, heading, 15.0, fov_deg=70.0, width_px=480, height_px=270)
            before = dataclasses.replace(state, time_utc=moment - timedelta(seconds=1.5))
            lit = dataclasses.replace(state, time_utc=moment)
            tiles = [take_snapshot(s, cam, settings, renderer).image for s in (before, lit)]
            gap = np.full((270, 4, 4), 255, np.uint8)
            rows.append(np.concatenate([tiles[0], gap, tiles[1]], axis=1))
            print(f"{when}: {flash.kind} {math.dist(flash.position_m[:2], eye[:2]) / 1000:.1f} km")
    band = np.full((4, rows[0].shape[1], 4), 255, np.uint8)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_png(args.out, np.concatenate([rows[0], band, rows[1]], axis=0))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
