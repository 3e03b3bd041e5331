#!/usr/bin/env python3
"""Fly the camera straight through a cloud and picture what the daemon does on the way.

    .venv/bin/python tools/gallery/fly_through.py [--preset fair-cumulus] [--frames 7] \\
        [--out docs/gallery/fly-through.png]

Finds the biggest cloud near the observer in the preset's sky, then flies level through its
middle, east to west of it, with one SkyEngine (so in-cloud facing locks carry frame to frame
as in the daemon). The top row is the composited picture at evenly spaced points; under it
the in-cloud flag and visibility the frame stream would carry there, sampled every few metres,
with the pictured points marked. The frames show the sprites only: the host fogs its own
scene with the visibility in the plot.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.app.snapshot import picture  # noqa: E402
from wxsky.engine.stages import SkyEngine  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.settings.config import DaemonConfig  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

SAMPLES = 240  # points along the path for the visibility plot
SEARCH_M = 4000.0  # look for the cloud within this of the observer


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", default="fair-cumulus")
    p.add_argument("--frames", type=int, default=7)
    p.add_argument("--size", default="256x192")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "gallery" / "fly-through.png")
    args = p.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    state = WeatherState().apply(load_preset(args.preset, ()))
    settings = DaemonConfig().scene.settings()
    ground = Camera(position_m=(0.0, 0.0, state.observer.alt_m + 2.0))
    centre_m, half_m = biggest_cloud(SkyEngine(state, ground, settings, clock_rate=0.0))
    start_x, end_x = centre_m[0] - 1.6 * half_m, centre_m[0] + 1.6 * half_m
    path_x = np.linspace(start_x, end_x, SAMPLES)

    def camera_at(x: float) -> Camera:
        return Camera(
            position_m=(float(x), float(centre_m[1]), float(centre_m[2])),
            heading_deg=90.0,
            pitch_deg=0.0,
            fov_deg=70.0,
            width_px=width,
            height_px=height,
        )

    engine = SkyEngine(state, camera_at(path_x[0]), settings, clock_rate=0.0)
    shot_at = set(np.linspace(0, SAMPLES - 1, args.frames).round().astype(int).tolist())
    visibility = np.full(SAMPLES, np.nan)
    inside = np.zeros(SAMPLES, bool)
    frames = []
    ring_stale = True
    with Renderer(settings.ring_texture_px) as renderer:
        for i, x in enumerate(path_x):
            engine.set_camera(camera_at(x))
            plan = engine.advance(0.0)
            ring_stale = ring_stale or plan.ring_changed
            cloud = plan.frame.in_cloud
            inside[i] = cloud.inside
            if cloud.visibility_m is not None:
                visibility[i] = cloud.visibility_m
            if i in shot_at:
                frames.append((x, picture(renderer, plan, draw_ring=ring_stale).image))
                ring_stale = False
    draw(args.out, args.preset, centre_m[0], path_x, inside, visibility, frames)
    entered = path_x[inside]
    span = (
        f"{entered.min() - centre_m[0]:+.0f} to {entered.max() - centre_m[0]:+.0f} m"
        if len(entered)
        else "never"
    )
    print(
        f"{args.preset}: cloud at {centre_m[0]:.0f}, {centre_m[1]:.0f}, {centre_m[2]:.0f} m "
        f"(half-width {half_m:.0f} m); in cloud {span} from its middle; least visibility "
        f"{np.nanmin(visibility) if inside.any() else float('nan'):.0f} m; wrote {args.out}"
    )
    return 0


def biggest_cloud(engine: SkyEngine) -> tuple[np.ndarray, float]:
    """The sprite-weighted middle of the near cloud with the most sprites, and its half-width."""
    sprites = engine.advance(0.0).frame.near.sprites
    near = np.hypot(sprites.centre_m[:, 0], sprites.centre_m[:, 1]) < SEARCH_M
    ids, counts = np.unique(sprites.cloud_id[near], return_counts=True)
    if not len(ids):
        raise SystemExit(f"no cloud within {SEARCH_M:.0f} m of the observer")
    chosen = sprites.cloud_id == ids[np.argmax(counts)]
    centres = sprites.centre_m[chosen]
    middle = centres.mean(axis=0)
    half = float(np.abs(centres[:, 0] - middle[0]).max() + 0.5 * sprites.size_m[chosen].max())
    return middle, half


def draw(
    out: Path,
    preset: str,
    middle_x: float,
    path_x: np.ndarray,
    inside: np.ndarray,
    visibility: np.ndarray,
    frames: list[tuple[float, np.ndarray]],
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(frames)
    fig = plt.figure(figsize=(2.2 * n, 4.4), dpi=100)
    grid = fig.add_gridspec(2, n, height_ratios=[1.0, 1.1], hspace=0.35, wspace=0.05)
    for k, (x, image) in enumerate(frames):
        ax = fig.add_subplot(grid[0, k])
        ax.imshow(image[..., :3])
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{x - middle_x:+.0f} m", fontsize=9)
    ax = fig.add_subplot(grid[1, :])
    rel = path_x - middle_x
    ax.plot(rel, np.where(inside, visibility, np.nan), color="tab:blue", lw=2)
    ax.fill_between(rel, 0, 1, where=inside, transform=ax.get_xaxis_transform(), color="0.9")
    for x, _ in frames:
        ax.axvline(x - middle_x, color="0.5", lw=0.8, ls=":")
    ax.set_yscale("log")
    ax.set_ylim(20, 1200)
    ax.set_xlim(rel[0], rel[-1])
    ax.set_xlabel("distance from the cloud's middle along the flight (m)")
    ax.set_ylabel("in-cloud visibility (m)")
    ax.set_title(
        f"{preset}: level flight through the biggest nearby cloud; grey = in_cloud true",
        fontsize=10,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, bbox_inches="tight")
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
