#!/usr/bin/env python3
"""Pictures of issue 43's precipitation for docs/gallery/:

    .venv/bin/python tools/gallery/precip_gallery.py [--out-dir docs/gallery]

- `thunderstorm-curtains.png`: the thunderstorm preset from the ground at noon and at dusk
  (in its rain: the curtains all round); its cumulonimbus alone at 2/8 in 20 km visibility
  from 5 and 20 km, and in 80 km visibility from 50 km, out of the rain (the shafts hanging
  from their bases), at noon (middle row) and at dusk (bottom row);
- `precip-at-eye.png`: rain (top) and snow (bottom) about the eye at -, moderate and +, flying
  north at 60 m/s under a nimbostratus (the streaks run from the motion through the air).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tools.bench import storm_look  # noqa: E402
from wxsky.app.snapshot import picture, take_snapshot  # noqa: E402
from wxsky.engine.stages import SkyEngine  # noqa: E402
from wxsky.png import write_png  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.weather.state import CloudLayer, CloudType, WeatherState  # noqa: E402

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
    """Under the storm (the preset itself) at noon and dusk, then its cumulonimbus alone at
    2/8 in 20 km visibility from 5, 20 and 50 km, at noon and at dusk."""
    under = []
    for when in ("noon", "dusk"):
        state = storm_look.storm_state(when)
        cam = Camera(
            (0.0, 0.0, state.observer.alt_m + 2.0),
            pitch_deg=10.0,
            width_px=TILE[0],
            height_px=TILE[1],
        )
        under.append(take_snapshot(state, cam, SceneSettings(), renderer=renderer).image)
    rows = [[*under, _blank()]]
    for when in ("noon", "dusk"):
        found = storm_look.shaft_camera(storm_look.storm_state(when))
        assert found is not None
        state = found[1]
        centre = storm_look.storm_centre(state)
        assert centre is not None
        row = []
        for distance_m in FAR_M:
            if distance_m > 30_000.0:  # in 20 km a storm 50 km off is gone
                state = dataclasses.replace(state, visibility_m=80_000.0)
            eye = storm_look.dry_eye(state, centre, distance_m, state.observer.alt_m + 2.0)
            x, y, z = eye
            heading = math.degrees(math.atan2(centre[0] - x, centre[1] - y))
            view = Camera(
                (x, y, z),
                heading_deg=heading,
                pitch_deg=8.0 if distance_m > 10_000.0 else 12.0,
                fov_deg=60.0,
                width_px=TILE[0],
                height_px=TILE[1],
            )
            row.append(take_snapshot(state, view, SceneSettings(), renderer=renderer).image)
        rows.append(row)
    return rows


FAR_M = (5000.0, 20_000.0, 50_000.0)


def _blank() -> npt.NDArray[np.uint8]:
    return np.full((TILE[1], TILE[0], 4), 255, np.uint8)


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
