#!/usr/bin/env python3
"""Pictures of one convective tower's volume through its life, to look at while building the
towers (issue 17): side views at several ages, each the automaton's smoothed density lit by
slice lighting and composited along the view.

    .venv/bin/python tools/tower_strip.py --out docs/gallery/tower-growth.png \\
        [--ages-min 0,10,20,30] [--cut-min M] [--grid 64] [--seed 2026]

This is the volume alone, orthographic, before the towers are drawn in the sky: a check of
the automaton, the ellipsoids and the lighting, not the picture a pilot sees.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from wxsky.png import write_png
from wxsky.towers.lighting import EXTINCTION_PER_CELL, slice_light
from wxsky.towers.volume import TowerSpec, TowerVolume

SKY = np.array([0.42, 0.62, 0.90], np.float32)
SUN_RGB = np.array([1.0, 0.97, 0.92], np.float32)
AMBIENT_RGB = np.array([0.30, 0.34, 0.42], np.float32)
SCALE = 3  # pixels per cell


def side_view(density: np.ndarray, light_dir: tuple[float, float, float]) -> np.ndarray:
    """(nz, nx, 3) colour of the volume seen along +y (north) over the sky."""
    light = slice_light(density, light_dir)
    nz, ny, nx = density.shape
    colour = np.broadcast_to(SKY, (nz, nx, 3)).copy()
    # Back to front: the far side (high y) first.
    for j in range(ny - 1, -1, -1):
        alpha = 1.0 - np.exp(-EXTINCTION_PER_CELL * density[:, j, :])
        lit = light[:, j, :, None] * SUN_RGB + AMBIENT_RGB * 0.6
        colour = colour * (1.0 - alpha[..., None]) + np.clip(lit, 0.0, 1.0) * alpha[..., None]
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
    # Afternoon sun from the west, 35 degrees up: from the viewer's left.
    el, az = math.radians(35.0), math.radians(270.0)
    light = (math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el))
    panels = []
    for age in (float(a) for a in args.ages_min.split(",")):
        view = side_view(tower.density_at(60.0 * age), light)
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
