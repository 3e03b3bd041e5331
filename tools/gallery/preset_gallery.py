"""Render every preset from the same camera and tile them into one PNG (docs/presets.png).

    .venv/bin/python tools/gallery/preset_gallery.py [--out docs/presets.png] [--size 320x180]

Each tile is a `wxsky snapshot` of one preset at its own time of day, from the ground,
looking south-south-west 12° up.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wxsky.app.snapshot import take_snapshot
from wxsky.cli.common import parse_size
from wxsky.png import write_png
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.settings.presets import list_presets, load_preset
from wxsky.weather.state import WeatherState

COLUMNS = 4


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("docs/presets.png"))
    p.add_argument("--size", default="320x180")
    args = p.parse_args()
    w, h = parse_size(args.size)
    presets = list_presets()
    rows = -(-len(presets) // COLUMNS)
    sheet = np.full((rows * h, COLUMNS * w, 4), 255, np.uint8)
    settings = SceneSettings()
    with Renderer(settings.ring_texture_px) as renderer:
        for n, info in enumerate(presets):
            state = WeatherState().apply(load_preset(info.name))
            cam = Camera((0.0, 0.0, state.observer.alt_m + 2.0), 200.0, 12.0, 0.0, 70.0, w, h)
            tile = take_snapshot(state, cam, settings, renderer).image
            r, c = divmod(n, COLUMNS)
            sheet[r * h : (r + 1) * h, c * w : (c + 1) * w] = tile
            print(f"{info.name}: {state.summary()}")
    write_png(args.out, sheet)
    print(f"wrote {args.out}: {', '.join(i.name for i in presets)} (row by row)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
