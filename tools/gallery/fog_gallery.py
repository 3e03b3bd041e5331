#!/usr/bin/env python3
"""Patchy fog along a runway (issue 43, items 3 and 6): a METAR with fog patches and two RVR
groups (`5000 BCFG R14/0400 R32/1200`) over Zurich's field, at noon and at dusk, seen from a
cockpit lined up on runway 14's threshold (5 m up, looking down the runway) and from 300 m, 4 km
out on its extended centre line, looking 7° down at the field, side by side; it prints the RVR
wxsky answers at the touchdown zones and along the runway.

    .venv/bin/python tools/gallery/fog_gallery.py [--out docs/gallery/patchy-fog-runway.png]

The runway is wxsky's (docs/fog.md): 3 km on the field's middle along the designator's heading.
wxsky draws no ground texture or runway: the fog lies over the sky pass's ground.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from wxsky.app.snapshot import take_snapshot  # noqa: E402
from wxsky.inputs.station_table import report_patch  # noqa: E402
from wxsky.png import write_png  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.fog import fog_field, runway  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.weather.metar import decode  # noqa: E402
from wxsky.weather.state import WeatherState, parse_time_utc  # noqa: E402

REPORT = "LSZH 061050Z 00000KT 5000 BCFG R14/0400 R32/1200 FEW015 04/04 Q1025"
TIMES = ("2026-12-06T11:20:00Z", "2026-12-06T15:25:00Z")
SIZE = (480, 270)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("docs/gallery/patchy-fog-runway.png"))
    args = parser.parse_args()
    settings = SceneSettings()
    rwy = runway("14")
    heading = math.degrees(math.atan2(*rwy.direction)) % 360.0
    rows = []
    with Renderer(settings.ring_texture_px) as renderer:
        for when in TIMES:
            decoded = decode(REPORT, year=2026, month=12)
            state = WeatherState(time_utc=parse_time_utc(when)).apply(report_patch(decoded))
            field = fog_field(state)
            assert field is not None
            ground = state.observer.alt_m
            (te, tn), (de, dn) = rwy.threshold_m, rwy.direction
            views = (
                ((te, tn, ground + 5.0), -1.0),
                ((te - 4000.0 * de, tn - 4000.0 * dn, ground + 300.0), -7.0),
            )
            tiles = []
            for eye, pitch in views:
                cam = Camera(eye, heading, pitch, fov_deg=60.0, width_px=SIZE[0], height_px=SIZE[1])
                tiles.append(take_snapshot(state, cam, settings, renderer).image)
            gap = np.full((SIZE[1], 4, 4), 255, np.uint8)
            rows.append(np.concatenate([tiles[0], gap, tiles[1]], axis=1))
            points = rwy.points_m(10)
            along = field.rvr_m(points[:, 0], points[:, 1])
            rvr14, rvr32 = field.runway_rvr_m("14"), field.runway_rvr_m("32")
            print(
                f"{when}: RVR 14 {rvr14:.0f} m, 32 {rvr32:.0f} m; "
                f"along the runway {along.min():.0f}-{along.max():.0f} m"
            )
    band = np.full((4, rows[0].shape[1], 4), 255, np.uint8)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_png(args.out, np.concatenate([rows[0], band, rows[1]], axis=0))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
