#!/usr/bin/env python3
"""Pictures of issue 43's precipitation for docs/gallery/:

    .venv/bin/python tools/gallery/precip_gallery.py [--out-dir docs/gallery]

- `thunderstorm-curtains.png`: the thunderstorm preset from the ground at noon and at dusk
  (in its rain: the curtains all round), and its cumulonimbus alone at 2/8 in 20 km
  visibility from 8 and 20 km (a shaft hanging from its base), at noon;
- `precip-at-eye.png`: rain (top) and snow (bottom) about the eye at -, moderate and +, flying
  north at 60 m/s under a nimbostratus (the streaks run from the motion through the air).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tools.bench import storm_look
from wxsky.app.snapshot import picture, take_snapshot
from wxsky.engine.stages import SkyEngine
from wxsky.png import write_png
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

TILE = (480, 270)
GAP = 4


def sheet(tiles: list[list[npt.NDArray[np.uint8]]]) -> npt.NDArray[np.uint8]:
    h, w = tiles[0][0].shape[:2]
    rows, cols = len(tiles), len(tiles[0])
    out = np.full((rows * h + (rows - 1) * GAP, cols * w + (cols - 1) * GAP, 4), 255, np.uint8)
    for r, row in enumerate(tiles):
        for c, tile in enumerate(row):
            out[r * (h + GAP) : r * (h + GAP) + h, c * (w + GAP) : c * (w + GAP) + w] = tile
    return out


def storm_tiles(renderer: Renderer) -> list[list[npt.NDArray[np.uint8]]]:
    tiles = []
    for when in ("noon", "dusk"):
        state = storm_look.storm_state(when)
        cam = Camera(
            (0.0, 0.0, state.observer.alt_m + 2.0),
            pitch_deg=10.0,
            width_px=TILE[0],
            height_px=TILE[1],
        )
        tiles.append(take_snapshot(state, cam, SceneSettings(), renderer=renderer).image)
    found = storm_look.shaft_camera(storm_look.storm_state("noon"))
    assert found is not None
    cam, state = found
    for back_m in (0.0, 12_000.0):
        x, y, z = cam.position_m
        far = dataclasses.replace(
            cam,
            position_m=(x, y - back_m, z),
            width_px=TILE[0],
            height_px=TILE[1],
            pitch_deg=4.0 if back_m else 5.0,
        )
        tiles.append(take_snapshot(state, far, SceneSettings(), renderer=renderer).image)
    return [tiles[:2], tiles[2:]]


def eye_tiles(renderer: Renderer) -> list[list[npt.NDArray[np.uint8]]]:
    ns = CloudLayer(8, 900.0, 3500.0, CloudType.NIMBOSTRATUS)
    rows = []
    for codes in (("-RA", "RA", "+RA"), ("-SN", "SN", "+SN")):
        row = []
        for code in codes:
            state = dataclasses.replace(
                WeatherState(),
                layers=(ns,),
                present_weather=(code,),
                visibility_m=8000.0,
                temperature_c=1.0 if "SN" in code else 12.0,
                dewpoint_c=0.0 if "SN" in code else 10.0,
            )
            cam = Camera((0.0, 0.0, 500.0), pitch_deg=0.0, width_px=TILE[0], height_px=TILE[1])
            with SkyEngine(state, cam, SceneSettings(), clock_rate=0.0) as engine:
                engine.advance(0.0)
                # Flying north at 60 m/s: the engine reads the eye's speed from its moves.
                for k in range(1, 6):
                    engine.set_camera(dataclasses.replace(cam, position_m=(0.0, 2.0 * k, 500.0)))
                    plan = engine.advance(1.0 / 30.0)
                row.append(picture(renderer, plan).image)
        rows.append(row)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out-dir", type=Path, default=Path("docs/gallery"))
    args = parser.parse_args()
    with Renderer(TILE[0]) as renderer:
        write_png(args.out_dir / "thunderstorm-curtains.png", sheet(storm_tiles(renderer)))
        write_png(args.out_dir / "precip-at-eye.png", sheet(eye_tiles(renderer)))
    print(f"wrote {args.out_dir}/thunderstorm-curtains.png and precip-at-eye.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
