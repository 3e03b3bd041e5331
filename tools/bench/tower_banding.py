"""Shelves in a tower: the banding measure within a growing tower's box, minute by minute.

    .venv/bin/python tools/bench/tower_banding.py [--minutes 10,20,30] [--json FILE] [--png FILE]

Issue 42's "towers" check. The towering-cumulus preset's growth strip
(`tools/gallery/tower_sky_strip.py`): the eye 600 m over the field, drifting with the layer
so one tower 5 km or more away stays in view, looking 20 deg up at it, 480x400. In each
picture the tower's box (its volume's grid, projected) is found, and over the pixels inside
it the luma's vertical differences' energy is set against its horizontal differences' (the
far-field measure, `banding.py`): stacked slices of the volume, shelves up the tower, read
high; one column read near 1. The issue's bar: under half of the figure before it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from collections.abc import Sequence
from datetime import timedelta
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tools.bench.banding import LUMA  # noqa: E402
from tools.gallery.tower_sky_strip import SETTINGS, watched_cell  # noqa: E402
from wxsky.app.snapshot import picture  # noqa: E402
from wxsky.engine.stages import SkyEngine  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

SIZE = (480, 400)
PITCH_DEG = 20.0


def box_rect(
    camera: Camera, centre: npt.NDArray[np.float64], size: tuple[float, ...]
) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) pixels of the box's corners' bounds in the picture, clipped."""
    right, up, fwd = camera.basis()
    tan_x = camera.tan_half_fov_x
    tan_y = tan_x * camera.height_px / camera.width_px
    xs, ys = [], []
    for sx in (-0.5, 0.5):
        for sy in (-0.5, 0.5):
            for sz in (-0.5, 0.5):
                rel = (
                    centre
                    + np.array([sx * size[0], sy * size[1], sz * size[2]])
                    - np.asarray(camera.position_m)
                )
                ahead = float(rel @ fwd)
                xs.append((float(rel @ right) / ahead / tan_x + 1.0) / 2.0 * camera.width_px)
                ys.append((1.0 - float(rel @ up) / ahead / tan_y) / 2.0 * camera.height_px)
    x0, x1 = max(0, int(min(xs))), min(camera.width_px, math.ceil(max(xs)))
    y0, y1 = max(0, int(min(ys))), min(camera.height_px, math.ceil(max(ys)))
    return x0, y0, x1, y1


def banding(rgb: npt.NDArray[np.uint8]) -> float:
    luma = (rgb[..., :3].astype(np.float64) / 255.0) @ LUMA
    down, across = np.diff(luma, axis=0), np.diff(luma, axis=1)
    return float(np.sum(down * down) / max(float(np.sum(across * across)), 1e-12))


def periodic_steps(rgb: npt.NDArray[np.uint8], half_width_px: int = 4) -> float:
    """How periodic the steps are in the vertical luminance profile through the middle of
    `rgb` (its middle columns averaged): over lags k of 3 pixels up to a quarter of the
    height, the largest of the smaller of the autocorrelations at k and 2k of the profile's
    row to row differences. Slices or shelves stacked at an even spacing repeat their steps
    at one and two spacings; any two edges (a cloud's top and its base) match at one lag
    only, and cloud's own texture at none."""
    luma = (rgb[..., :3].astype(np.float64) / 255.0) @ LUMA
    mid = luma.shape[1] // 2
    profile = luma[:, max(0, mid - half_width_px) : mid + half_width_px + 1].mean(axis=1)
    steps = np.diff(profile)
    steps -= steps.mean()
    energy = float(steps @ steps)
    if energy <= 1e-12 or len(steps) < 12:
        return 0.0

    def r(k: int) -> float:
        return float(steps[:-k] @ steps[k:]) / energy

    return max(0.0, *(min(r(k), r(2 * k)) for k in range(3, max(4, len(steps) // 4))))


def run(minutes: Sequence[float]) -> list[tuple[float, float, float, npt.NDArray[np.uint8]]]:
    """(minutes, figure, periodic steps, the picture with the box outlined) per moment."""
    base = WeatherState().apply(load_preset("towering-cumulus"))
    eye0 = (0.0, 0.0, base.observer.alt_m + 600.0)
    watch = watched_cell(base, eye0, minutes[0])
    offset = np.asarray(watch.centre_m) - np.asarray(eye0)
    heading = math.degrees(math.atan2(offset[0], offset[1]))
    out = []
    with Renderer(SETTINGS.ring_texture_px) as renderer:
        for m in minutes:
            state = dataclasses.replace(base, time_utc=base.time_utc + timedelta(minutes=m))
            with SkyEngine(state, Camera(eye0), SETTINGS, clock_rate=1.0) as engine:
                engine.drift_for(60.0 * m)
                dx, dy = engine.drift[watch.layer]
                cx, cy, cz = watch.spec.box_centre_m
                eye = (cx + dx - offset[0], cy + dy - offset[1], eye0[2])
                camera = Camera(
                    eye, heading, PITCH_DEG, fov_deg=60.0, width_px=SIZE[0], height_px=SIZE[1]
                )
                engine.set_camera(camera)
                image = picture(renderer, engine.advance(0.0)).image
            x0, y0, x1, y1 = box_rect(
                camera, np.array([cx + dx, cy + dy, cz]), watch.spec.box_size_m
            )
            figure = banding(image[y0:y1, x0:x1])
            periodic = periodic_steps(image[y0:y1, x0:x1])
            marked = image.copy()
            marked[[y0, max(y0, y1 - 1)], x0:x1, :3] = (255, 60, 60)
            marked[y0:y1, [x0, max(x0, x1 - 1)], :3] = (255, 60, 60)
            out.append((m, figure, periodic, marked))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", default="10,20,30")
    p.add_argument("--json", type=Path)
    p.add_argument("--png", type=Path, help="the pictures side by side, boxes outlined")
    args = p.parse_args(argv)
    found = run([float(v) for v in args.minutes.split(",")])
    print("tower banding: vertical / horizontal gradient energy inside the watched tower's box;")
    print("periodic steps: the most the profile's steps repeat, down the box's middle")
    for m, figure, periodic, _ in found:
        print(f"  {m:5.0f} min  {figure:6.2f}  periodic steps {periodic:5.2f}")
    if args.json is not None:
        args.json.write_text(
            json.dumps([{"minutes": m, "banding": f, "periodic": p} for m, f, p, _ in found])
        )
    if args.png is not None:
        from wxsky.png import write_png

        write_png(args.png, np.concatenate([im for _, _, _, im in found], axis=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
