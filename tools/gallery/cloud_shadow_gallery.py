"""The cloud-shadow map of scattered-cumulus at noon and at dusk: docs/gallery/cloud-shadow-map.png.

    .venv/bin/python tools/gallery/cloud_shadow_gallery.py [--px 512] [--view 384] [--time-only]

Each row is one moment: on the left the map the daemon publishes as its `shadow` layer
(docs/protocol.md §3.3; north up, 2 ring radii = 16 km across, black = full shadow), on the
right the same 16 km seen straight down from 14 km: the snapshot's clouds over the reference
host's flat ground, lit through the map (wxsky/host/compositor.py, `Ground`). At noon the
shadows lie under their clouds; at dusk (sun 7° up in the west-north-west) they stretch
kilometres to the east-south-east, cast by clouds up to 40 km away. Also prints the time the
map takes at --px (the kernel alone, warm block cache, best of 5).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.app.snapshot import take_snapshot  # noqa: E402
from wxsky.host.compositor import Ground, ShadowMap, composite, layers_from_images  # noqa: E402
from wxsky.png import write_png  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.cloud_shadow import cloud_shadow  # noqa: E402
from wxsky.scene.gather import zero_drift  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.scene.sky import sky_params  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import Source, WeatherPatch, WeatherState, parse_time_utc  # noqa: E402

OUT = ROOT / "docs" / "gallery" / "cloud-shadow-map.png"
MOMENTS = (("noon", "2026-07-08T11:30:00Z"), ("dusk", "2026-07-08T18:05:00Z"))
ALTITUDE_M = 14_000.0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--px", type=int, default=512, help="shadow map texels per side")
    p.add_argument("--view", type=int, default=384, help="pixels per side of each panel")
    p.add_argument("--time-only", action="store_true", help="only time the map")
    args = p.parse_args()
    settings = SceneSettings(shadow_map_px=args.px)
    base = WeatherState().apply(load_preset("scattered-cumulus"))
    rows = []
    for label, when in MOMENTS:
        state = base.apply(WeatherPatch(source=Source.CONTROL, time_utc=parse_time_utc(when)))
        sky = sky_params(state, ALTITUDE_M)
        ms = time_map(state, sky.sun.direction_enu, settings)
        print(
            f"{label}: sun {sky.sun.elevation_deg:.1f} deg up at {sky.sun.azimuth_deg:.0f} deg; "
            f"{args.px}x{args.px} map in {ms:.1f} ms (best of 5)"
        )
        if not args.time_only:
            rows.append(row(state, settings, args.view))
    if rows:
        gap = np.full((rows[0].shape[0] // 40, rows[0].shape[1], 4), 255, np.uint8)
        write_png(OUT, np.concatenate([rows[0], gap, rows[1]], axis=0))
        print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


def time_map(
    state: WeatherState, sun: tuple[float, float, float], settings: SceneSettings
) -> float:
    """Milliseconds for one map over the ring's area, as build_ring makes it."""
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        cloud_shadow(
            state,
            zero_drift(state),
            (0.0, 0.0, ALTITUDE_M),
            sun,
            2.0 * settings.ring_radius_m,
            settings.shadow_map_px,
            settings.max_range_m,
        )
        best = min(best, time.perf_counter() - t0)
    return best * 1000.0


def row(state: WeatherState, settings: SceneSettings, view_px: int) -> np.ndarray:
    """The map and the view from above, side by side."""
    # Straight down, north up (heading 0: the image's up is north, its right east), the
    # field of view spanning the map's 16 km on the ground.
    span_m = 2.0 * settings.ring_radius_m
    fov_deg = float(np.degrees(2.0 * np.arctan(0.5 * span_m / (ALTITUDE_M - state.observer.alt_m))))
    camera = Camera((0.0, 0.0, ALTITUDE_M), 0.0, -90.0, 0.0, fov_deg, view_px, view_px)
    shot = take_snapshot(state, camera, settings)
    shadow = shot.shadow
    assert shadow is not None
    placement = (shadow.centre_m, shadow.size_m, shadow.sun_direction_enu)
    layers = layers_from_images(shot.layers, shot.ring_quads_m, shadow=placement)
    sun = sky_params(state, ALTITUDE_M).sun.direction_enu
    view = composite(layers, camera, Ground(state.observer.alt_m, sun))
    grey = shot.layers["shadow"]
    # The map at the panel's size, sampled as a host would (the same bilinear).
    k = (np.arange(view_px) + 0.5) / view_px
    east, north = np.meshgrid(
        shadow.centre_m[0] + (k - 0.5) * span_m, shadow.centre_m[1] + (0.5 - k) * span_m
    )
    points = np.stack([east, north, np.full_like(east, shadow.centre_m[2])], axis=-1)
    t = ShadowMap(grey, *placement).transmittance(points)
    panel = np.empty((view_px, view_px, 4), np.uint8)
    panel[..., :3] = np.round(t * 255.0)[..., None].astype(np.uint8)
    panel[..., 3] = 255
    gap = np.full((view_px, view_px // 40, 4), 255, np.uint8)
    out: np.ndarray = np.concatenate([panel, gap, view], axis=1)
    return out


if __name__ == "__main__":
    raise SystemExit(main())
