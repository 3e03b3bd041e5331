"""Render every preset at dawn, noon, dusk and night into docs/gallery/, and a contact sheet.

    .venv/bin/python tools/gallery/build_gallery.py [--size 240x135] [--preset NAME ...]

Times come from the sun at the preset's own place and date: dawn and dusk with the sun 4° up
(morning and evening), noon at the day's highest sun, night with the sun 20° down. The camera
stands 2 m above the observer looking 12° up toward the sun's side of the sky (east at dawn,
south at noon, west at dusk); overcast-stratus also from above its top, at dawn, noon and dusk
(overcast-stratus-above.png). Also the night sky, a crescent moon at dusk and the two shading
models side by side (`sky_pictures`). Every picture goes through
`wxsky.app.snapshot.take_snapshot`, the daemon's own stages, so the gallery shows what a host
would get.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.app.snapshot import take_snapshot  # noqa: E402
from wxsky.cli.common import parse_size  # noqa: E402
from wxsky.png import write_png  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.ephemeris import sun_and_moon  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.scene.shading import SHADING_MODELS  # noqa: E402
from wxsky.scene.sky import sun_position  # noqa: E402
from wxsky.settings.config import DaemonConfig  # noqa: E402
from wxsky.settings.presets import list_presets, load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

OUT = ROOT / "docs" / "gallery"
MOMENTS = ("dawn", "noon", "dusk", "night")
TWILIGHT_SUN_DEG = 4.0
NIGHT_SUN_DEG = -20.0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", default="240x135")
    p.add_argument("--preset", action="append", help="only these presets (repeatable)")
    args = p.parse_args()
    width, height = parse_size(args.size)
    config = DaemonConfig()
    names = args.preset or [e.name for e in list_presets(()) if e.origin == "builtin"]
    OUT.mkdir(parents=True, exist_ok=True)
    rows = []
    renderer = Renderer(config.scene.ring_texture_px)
    try:
        for name in names:
            base = WeatherState().apply(load_preset(name, ()))
            row = []
            for moment in MOMENTS:
                when, heading_deg = moment_time(base, moment)
                state = dataclasses.replace(base, time_utc=when)
                settings = config.scene.settings()
                image = shot(renderer, settings, state, heading_deg, 12.0, (width, height))
                write_png(OUT / f"{name}-{moment}.png", image)
                row.append(image)
                print(f"{name} {moment}: {when:%Y-%m-%d %H:%M}Z, heading {heading_deg:.0f}")
            rows.append(np.concatenate(_spaced(row, axis=1), axis=1))
        if "overcast-stratus" in names:
            above = above_the_deck(renderer, config, width, height)
            write_png(OUT / "overcast-stratus-above.png", above)
            print(f"wrote {OUT / 'overcast-stratus-above.png'}")
        if not args.preset:
            for file_name, image in sky_pictures(renderer, config).items():
                write_png(OUT / file_name, image)
                print(f"wrote {OUT / file_name}")
    finally:
        renderer.close()
    sheet = np.concatenate(_spaced(rows, axis=0), axis=0)
    write_png(OUT / "contact-sheet.png", sheet)
    print(f"wrote {len(names) * len(MOMENTS)} pictures and {OUT / 'contact-sheet.png'}")
    return 0


def above_the_deck(renderer: Renderer, config: DaemonConfig, width: int, height: int) -> np.ndarray:
    """overcast-stratus at dawn, noon and dusk from 1,250 m above its top, looking 12° down
    toward the sun's side: the deck's sunlit top under a clear sky."""
    base = WeatherState().apply(load_preset("overcast-stratus", ()))
    eye_m = max(layer.top_m for layer in base.layers) + 1250.0
    row = []
    for moment in ("dawn", "noon", "dusk"):
        when, heading_deg = moment_time(base, moment)
        state = dataclasses.replace(base, time_utc=when)
        settings = config.scene.settings()
        row.append(shot(renderer, settings, state, heading_deg, -12.0, (width, height), eye_m))
    return np.concatenate(_spaced(row, axis=1), axis=1)


def sky_pictures(renderer: Renderer, config: DaemonConfig) -> dict[str, np.ndarray]:
    """The night sky (clear, sun 20° down, looking 60° up to the south), a crescent moon at
    dusk, and fair-cumulus under each shading model at noon and dusk (Wang's left, Harris's
    right)."""
    clear = WeatherState().apply(load_preset("clear", ()))
    settings = config.scene.settings()
    wide, small = (640, 360), (320, 180)
    night, _ = moment_time(clear, "night")
    out = {
        "night-sky.png": shot(
            renderer, settings, dataclasses.replace(clear, time_utc=night), 180.0, 60.0, wide
        )
    }
    when, azimuth = crescent_at_dusk(clear)
    out["dusk-moon.png"] = shot(
        renderer, settings, dataclasses.replace(clear, time_utc=when), azimuth, 8.0, wide
    )
    cumulus = WeatherState().apply(load_preset("fair-cumulus", ()))
    rows = []
    for moment in ("noon", "dusk"):
        when, heading = moment_time(cumulus, moment)
        state = dataclasses.replace(cumulus, time_utc=when)
        rows.append(
            np.concatenate(
                _spaced(
                    [
                        shot(
                            renderer,
                            dataclasses.replace(settings, shading=m),
                            state,
                            heading,
                            12.0,
                            small,
                        )
                        for m in SHADING_MODELS
                    ],
                    1,
                ),
                axis=1,
            )
        )
    out["shading-wang-vs-harris.png"] = np.concatenate(_spaced(rows, axis=0), axis=0)
    return out


def shot(
    renderer: Renderer,
    settings: SceneSettings,
    state: WeatherState,
    heading_deg: float,
    pitch_deg: float,
    size: tuple[int, int],
    eye_alt_m: float | None = None,
) -> np.ndarray:
    """One composited picture; the eye 2 m above the observer unless eye_alt_m (MSL)."""
    alt_m = state.observer.alt_m + 2.0 if eye_alt_m is None else eye_alt_m
    camera = Camera(
        position_m=(0.0, 0.0, alt_m),
        heading_deg=heading_deg,
        pitch_deg=pitch_deg,
        width_px=size[0],
        height_px=size[1],
    )
    return take_snapshot(state, camera, settings, renderer).image


def crescent_at_dusk(state: WeatherState) -> tuple[datetime, float]:
    """The first evening from the preset's date with the sun 5° down and a waxing crescent
    (5-30 % lit) 5-20° up: the time, and the moon's azimuth."""
    obs = state.observer
    for day in range(60):
        midnight = state.time_utc.replace(hour=0, minute=0, second=0, microsecond=0)
        start = midnight + timedelta(days=day, hours=12)
        for minute in range(0, 12 * 60, 4):
            when = start + timedelta(minutes=minute)
            sun, moon = sun_and_moon(when, obs.lat_deg, obs.lon_deg, obs.alt_m)
            if sun.elevation_deg > -5.0:
                continue
            if 0.05 <= moon.illuminated_fraction <= 0.3 and 5.0 <= moon.elevation_deg <= 20.0:
                return when, moon.azimuth_deg
            break  # past dusk this evening: try the next
    raise SystemExit("no crescent moon at dusk within 60 days")


def moment_time(state: WeatherState, moment: str) -> tuple[datetime, float]:
    """The UTC time of a moment on the preset's date at its place, and the heading to face."""
    obs = state.observer
    midnight = state.time_utc.replace(hour=0, minute=0, second=0, microsecond=0)
    minutes = [midnight + timedelta(minutes=m) for m in range(0, 24 * 60, 2)]
    elevation = np.array([sun_position(t, obs.lat_deg, obs.lon_deg).elevation_deg for t in minutes])
    noon_i = int(np.argmax(elevation))
    if moment == "noon":
        return minutes[noon_i], sun_position(minutes[noon_i], obs.lat_deg, obs.lon_deg).azimuth_deg
    if moment == "night":
        lowest = int(np.argmin(elevation))
        # The first time the sun is 20° down after dusk (or the deepest night, if it never is).
        after = [i for i in range(noon_i, len(minutes)) if elevation[i] <= NIGHT_SUN_DEG]
        i = after[0] if after else lowest
        return minutes[i], 180.0
    if moment == "dawn":
        before = [i for i in range(noon_i) if elevation[i] >= TWILIGHT_SUN_DEG]
        i = before[0] if before else 0
    else:
        after = [i for i in range(noon_i, len(minutes)) if elevation[i] >= TWILIGHT_SUN_DEG]
        i = after[-1] if after else len(minutes) - 1
    return minutes[i], sun_position(minutes[i], obs.lat_deg, obs.lon_deg).azimuth_deg


def _spaced(images: list[np.ndarray], axis: int) -> list[np.ndarray]:
    """The images with a 4-pixel white gap between neighbours."""
    out: list[np.ndarray] = []
    for i, image in enumerate(images):
        if i:
            gap_shape = list(image.shape)
            gap_shape[axis] = 4
            out.append(np.full(gap_shape, 255, np.uint8))
        out.append(image)
    return out


if __name__ == "__main__":
    raise SystemExit(main())
