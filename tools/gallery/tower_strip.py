#!/usr/bin/env python3
"""Pictures of one convective tower's volume through its life, to look at while building the
towers (issue 17): side views at several ages, each the automaton's smoothed density lit by
slice lighting and composited along the view.

    .venv/bin/python tools/gallery/tower_strip.py --out docs/gallery/tower-growth.png \\
        [--ages-min 0,10,20,30] [--cut-min M] [--grid 64] [--seed 2026]

This is the volume alone, orthographic, before the towers are drawn in the sky: a check of
the automaton, the ellipsoids and the lighting (as the sprite clouds are lit, under the
towering-cumulus preset's sky), not the picture a pilot sees.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from wxsky.png import write_png
from wxsky.scene.ephemeris import SunPosition
from wxsky.scene.sky import SkyParams, sky_params
from wxsky.scene.tower_shading import tower_colours
from wxsky.settings.presets import load_preset
from wxsky.towers.lighting import EXTINCTION_PER_CELL
from wxsky.towers.volume import TowerSpec, TowerVolume
from wxsky.weather.state import WeatherState

SCALE = 3  # pixels per cell


def side_view(
    density: np.ndarray, sky: SkyParams, view_dir: tuple[float, float, float]
) -> np.ndarray:
    """(nz, nx, 3) colour of the volume seen along +y (north) over the sky's colour behind it,
    the cells lit as the sprite clouds are (`scene.tower_shading`)."""
    colours = tower_colours(density, sky, view_dir)
    nz, ny, nx = density.shape
    behind = np.asarray(sky.zenith_rgb) * 0.6 + np.asarray(sky.horizon_rgb) * 0.4
    colour = np.broadcast_to(behind, (nz, nx, 3)).copy()
    # Back to front: the far side (high y) first.
    for j in range(ny - 1, -1, -1):
        alpha = 1.0 - np.exp(-EXTINCTION_PER_CELL * density[:, j, :])
        colour = colour * (1.0 - alpha[..., None]) + colours[:, j, :, :] * alpha[..., None]
    return colour[::-1]  # top row first


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--ages-min", default="0,10,20,30")
    parser.add_argument("--cut-min", type=float, default=math.inf, help="supply cut at this age")
    parser.add_argument("--grid", type=int, default=64)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--mature-min", type=float, default=30.0)
    args = parser.parse_args()
    spec = TowerSpec(
        weather_seed=args.seed,
        block=(0, 0),
        cell=0,
        grid=args.grid,
        mature_s=60.0 * args.mature_min,
        supplied_s=60.0 * args.cut_min,
    )
    tower = TowerVolume(spec)
    # The towering-cumulus preset's afternoon sky, the sun from the west 35 degrees up: from
    # the viewer's left, looking north.
    state = WeatherState().apply(load_preset("towering-cumulus"))
    sky = dataclasses.replace(sky_params(state), sun=SunPosition(35.0, 270.0))
    panels = []
    for age in (float(a) for a in args.ages_min.split(",")):
        view = side_view(tower.density_at(60.0 * age), sky, (0.0, 1.0, 0.0))
        panel = np.repeat(np.repeat(view, SCALE, axis=0), SCALE, axis=1)
        panel[:, -2:] = 1.0  # a white gap between panels
        panels.append(panel)
    image = np.concatenate(panels, axis=1)
    rgba = np.concatenate(
        [
            np.clip(image * 255.0 + 0.5, 0, 255).astype(np.uint8),
            np.full((*image.shape[:2], 1), 255, np.uint8),
        ],
        axis=2,
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_png(args.out, rgba)
    print(f"wrote {args.out} ({rgba.shape[1]}x{rgba.shape[0]}): ages {args.ages_min} min")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
