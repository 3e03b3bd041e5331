"""`wxsky sun`: where the sun and moon stand for an observer, as the sky pass draws them."""

from __future__ import annotations

import argparse
import json
import math
from datetime import UTC, datetime

from wxsky.cli.common import Subparsers


def add_commands(sub: Subparsers) -> None:
    sun = sub.add_parser(
        "sun",
        help="sun and moon azimuth/elevation for an observer",
        description="Apparent topocentric positions (parallax and refraction applied) and the "
        "moon's phase, from wxsky.scene.ephemeris.",
    )
    sun.add_argument("--lat", type=float, required=True, help="observer latitude, degrees")
    sun.add_argument("--lon", type=float, required=True, help="observer longitude, degrees east")
    sun.add_argument("--time", help="ISO 8601 time (UTC unless it says); default: now")
    sun.add_argument("--alt-m", type=float, default=0.0, help="observer height, metres")
    sun.add_argument("--json", action="store_true", help="print one JSON object")
    sun.set_defaults(func=_cmd_sun)


def _cmd_sun(args: argparse.Namespace) -> int:
    from wxsky.scene.ephemeris import sun_and_moon
    from wxsky.weather.state import format_time_utc, parse_time_utc

    _check("--lat", args.lat, -90.0, 90.0)
    _check("--lon", args.lon, -180.0, 360.0)
    _check("--alt-m", args.alt_m, -500.0, 30_000.0)
    when = parse_time_utc(args.time) if args.time else datetime.now(UTC)
    lon_deg = (args.lon + 180.0) % 360.0 - 180.0
    sun, moon = sun_and_moon(when, args.lat, lon_deg, args.alt_m)
    result = {
        "time_utc": format_time_utc(when),
        "lat_deg": args.lat,
        "lon_deg": lon_deg,
        "sun": {"azimuth_deg": sun.azimuth_deg, "elevation_deg": sun.elevation_deg},
        "moon": {
            "azimuth_deg": moon.azimuth_deg,
            "elevation_deg": moon.elevation_deg,
            "illuminated_fraction": moon.illuminated_fraction,
            "bright_limb_angle_deg": moon.bright_limb_angle_deg,
            "distance_km": moon.distance_km,
        },
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"time {result['time_utc']}  lat {args.lat:.4f}  lon {lon_deg:.4f}")
    print(f"sun   azimuth_deg {sun.azimuth_deg:7.2f}  elevation_deg {sun.elevation_deg:6.2f}")
    print(
        f"moon  azimuth_deg {moon.azimuth_deg:7.2f}  elevation_deg {moon.elevation_deg:6.2f}  "
        f"illuminated_fraction {moon.illuminated_fraction:.3f}  "
        f"bright_limb_angle_deg {moon.bright_limb_angle_deg:.1f}"
    )
    return 0


def _check(flag: str, value: float, lo: float, hi: float) -> None:
    if not math.isfinite(value) or not lo <= value <= hi:
        raise ValueError(f"{flag} {value:g} is outside {lo:g}..{hi:g}")
