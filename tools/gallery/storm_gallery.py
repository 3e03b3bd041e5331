#!/usr/bin/env python3
"""Pictures of rain and snow shafts (issue 17): a cumulonimbus with heavy rain seen from about
20 km, and the same storm shedding snow, for docs/gallery/.

    .venv/bin/python tools/gallery/storm_gallery.py [--out docs/gallery/cb-rain-shaft.png]
    .venv/bin/python tools/gallery/storm_gallery.py --ring-radius-m 24000 \
        --out docs/gallery/cb-tower-rain-shaft.png

With `--ring-radius-m 24000` the storms 20 km off are in the near layer, so the nearest grow as
cumulonimbus towers (docs/towers.md) instead of the ring's sprite clouds.

The thunderstorm preset's cumulonimbus layer alone at 1/8, in clear air (80 km visibility, so
a storm 20 km off is not lost in the haze), from 2,500 m looking a little down: the shafts
hang from the bases to the ground, seen against it.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from wxsky.app.snapshot import take_snapshot
from wxsky.png import write_png
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.settings.presets import load_preset
from wxsky.weather.state import CloudType, WeatherState

HEADING_DEG = 90.0  # toward a storm about 20 km east of Zurich with this seed


def storm(present_weather: tuple[str, ...]) -> WeatherState:
    state = WeatherState().apply(load_preset("thunderstorm"))
    cb = next(lay for lay in state.layers if lay.type == CloudType.CUMULONIMBUS)
    return dataclasses.replace(
        state,
        layers=(dataclasses.replace(cb, cover_oktas=1.0),),
        visibility_m=80_000.0,
        present_weather=present_weather,
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/gallery/cb-rain-shaft.png"))
    parser.add_argument("--size", default="640x360")
    parser.add_argument("--ring-radius-m", type=float, default=SceneSettings().ring_radius_m)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    camera = Camera(
        position_m=(0.0, 0.0, 2500.0),
        heading_deg=HEADING_DEG,
        pitch_deg=-2.0,
        fov_deg=50.0,
        width_px=width,
        height_px=height,
    )
    tiles = []
    with Renderer(SceneSettings().ring_texture_px) as renderer:
        for weather in (("+TSRA",), ("+SHSN",), ()):
            settings = SceneSettings(ring_radius_m=args.ring_radius_m)
            tiles.append(take_snapshot(storm(weather), camera, settings, renderer).image)
    gap = np.full((height, 4, 4), 255, np.uint8)
    image = np.concatenate([tiles[0], gap, tiles[1], gap, tiles[2]], axis=1)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_png(args.out, image)
    print(f"wrote {args.out}: heavy rain, heavy snow, nothing falling")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
