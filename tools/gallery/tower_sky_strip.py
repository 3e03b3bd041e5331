#!/usr/bin/env python3
"""One convective tower of the towering-cumulus preset watched through its life, as a pilot
circling downwind of it sees it (issue 17, item 7): composited pictures at several times, the
eye drifting with the cloud layer so the tower stays in view.

    .venv/bin/python tools/gallery/tower_sky_strip.py --out docs/gallery/towering-cumulus-growth.png
    .venv/bin/python tools/gallery/tower_sky_strip.py \\
        --out docs/gallery/towering-cumulus-decay.png --minutes 30,32,35,40 --clear-at 30

`--clear-at M`: at M minutes the air starts clearing (the layer's cover falls by one okta):
the towers' supply stops and they decay from their edges. Each panel is what `wxsky
snapshot` draws for that moment (the same engine, renderer and compositor).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from datetime import timedelta
from pathlib import Path

import numpy as np

from wxsky.app.snapshot import picture
from wxsky.engine.stages import SkyEngine
from wxsky.png import write_png
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.settings.presets import load_preset
from wxsky.weather.state import Source, WeatherPatch, WeatherState

# Twice the default budget of towers, so that one 5 km off is among those drawn (the daemon's
# own [scene] max_towers can be raised as far).
SETTINGS = SceneSettings(max_towers=12)


def watched_cell(state: WeatherState, eye: tuple[float, float, float], minutes: float):
    """The tower to watch: of those drawn at the first moment, the youngest 5 km or more
    from the eye (nearer ones fill the picture)."""
    later = dataclasses.replace(state, time_utc=state.time_utc + timedelta(minutes=minutes))
    with SkyEngine(later, Camera(eye), SETTINGS, clock_rate=0.0) as e:
        e.drift_for(60.0 * minutes)
        towers = e.advance(0.0).frame.towers
    far = [t for t in towers if t.distance_m >= 5000.0] or list(towers)
    return min(far, key=lambda t: t.age_s)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--minutes", default="0,10,20,30")
    parser.add_argument("--clear-at", type=float, default=None, help="minutes: the air clears")
    parser.add_argument("--size", default="480x400")
    parser.add_argument("--preset", default="towering-cumulus")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    times = [float(m) for m in args.minutes.split(",")]
    base = WeatherState().apply(load_preset(args.preset))
    eye0 = (0.0, 0.0, base.observer.alt_m + 600.0)
    watch = watched_cell(base, eye0, times[0])
    panels = []
    # The eye keeps its offset from the cell, which moves with its layer's drift.
    offset = np.asarray(watch.centre_m) - np.asarray(eye0)
    heading = math.degrees(math.atan2(offset[0], offset[1]))
    with Renderer(256) as renderer:
        for minutes in times:
            clear_at = args.clear_at if args.clear_at is not None else math.inf
            start = min(minutes, clear_at)
            state = dataclasses.replace(base, time_utc=base.time_utc + timedelta(minutes=start))
            with SkyEngine(state, Camera(eye0), SETTINGS, clock_rate=1.0) as engine:
                engine.drift_for(60.0 * start)
                if minutes > start:
                    # The air starts clearing: the layer's cover falls by one okta.
                    thinner = tuple(
                        dataclasses.replace(lay, cover_oktas=max(1, lay.cover_oktas - 1))
                        for lay in state.layers
                    )
                    engine.apply(WeatherPatch(source=Source.CONTROL, layers=thinner))
                    engine.advance(0.0)
                    engine.advance(60.0 * (minutes - start))
                (dx, dy) = engine.drift[watch.layer]
                spec = watch.spec
                cx, cy, _ = spec.box_centre_m
                eye = (cx + dx - offset[0], cy + dy - offset[1], eye0[2])
                engine.set_camera(
                    Camera(
                        eye,
                        heading_deg=heading,
                        pitch_deg=20.0,
                        fov_deg=60.0,
                        width_px=width,
                        height_px=height,
                    )
                )
                snap = picture(renderer, engine.advance(0.0))
            panel = snap.image[..., :3].copy()
            panel[:, -3:] = 255  # a white gap between panels
            panels.append(panel)
            print(
                f"{minutes:g} min: watched cell {watch.spec.cell} of block {watch.spec.block},"
                f" {(60.0 * minutes - watch.spec.born_s) / 60.0:.1f} min old, heading {heading:.0f}"
            )
    image = np.concatenate(panels, axis=1)
    rgba = np.concatenate([image, np.full((*image.shape[:2], 1), 255, np.uint8)], axis=2)
    write_png(args.out, rgba)
    print(f"wrote {args.out} ({rgba.shape[1]}x{rgba.shape[0]}): minutes {args.minutes}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
