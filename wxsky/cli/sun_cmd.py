"""`wxsky sun`: where the sun and moon stand for an observer, as the sky pass draws them."""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime

from wxsky.cli.common import KindRef, NumberArg, Subparsers, time_arg
from wxsky.schema import Number

# Longitudes east of 180 are taken too (0..360 east, as some tables give them).
SUN_LON_DEG = Number(-180.0, 360.0, unit="deg")


def add_commands(sub: Subparsers) -> None:
    sun = sub.add_parser(
        "sun",
        help="sun and moon azimuth/elevation for an observer",
        description="Apparent topocentric positions (parallax and refraction applied) and the "
        "moon's phase, from wxsky.scene.ephemeris.",
    )
    sun.add_argument(
        "--lat",
        type=NumberArg("--lat", KindRef("wxsky.weather.state:LAT_DEG")),
        required=True,
        metavar="DEG",
        help="observer latitude",
    )
    sun.add_argument(
        "--lon",
        type=NumberArg("--lon", SUN_LON_DEG),
        required=True,
        metavar="DEG",
        help="observer longitude, east",
    )
    sun.add_argument(
        "--time", type=time_arg(), help="ISO 8601 time, UTC unless it says (default: now)"
    )
    sun.add_argument(
        "--alt-m",
        type=NumberArg("--alt-m", KindRef("wxsky.weather.state:ALT_M")),
        default=0.0,
        metavar="M",
        help="observer height MSL",
    )
    sun.add_argument("--json", action="store_true", help="print one JSON object")
    sun.set_defaults(func=_cmd_sun)


def _cmd_sun(args: argparse.Namespace) -> int:
    from wxsky.scene.ephemeris import sun_and_moon
    from wxsky.weather.state import format_time_utc

    when = args.time or datetime.now(UTC)
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
