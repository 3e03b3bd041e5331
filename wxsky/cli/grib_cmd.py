"""`wxsky grib ...`: model data (docs/weather-aloft.md).

- `wxsky grib show SOURCE... [--lat --lon] [--time] [--json]`: the column the daemon would
  use at a place and time (levels from the ground up, the freezing level, the tropopause, the
  model's cloud decks) and the cloud layers it would make of it;
- `wxsky grib idx FILE`: a wgrib2-style `.idx` inventory of a file, to publish beside it so
  daemons fetch only the messages they use.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

from wxsky.cli.common import KindRef, NumberArg, Subparsers, UsageError, time_arg
from wxsky.errors import GribError
from wxsky.schema import Number

if TYPE_CHECKING:
    from wxsky.weather.model_profile import ModelProfile

GRIB_LON_DEG = Number(-180.0, 360.0, unit="deg")
HALF_DEG = 3.0  # the window a `show` decodes around its point


def add_commands(sub: Subparsers) -> None:
    grib = sub.add_parser(
        "grib",
        help="GRIB2 model data: the column at a place, inventories",
        description="Read GRIB2 model data (a file, a directory of forecast steps, or an "
        "http(s) URL) as the daemon's [grib] sources do.",
    )
    gsub = grib.add_subparsers(dest="grib_command", metavar="COMMAND", required=True)
    show = gsub.add_parser(
        "show",
        help="the wind, temperature and cloud the daemon would take from the data at a place",
        description="The model's column at a place and time, interpolated as the daemon "
        "does: bilinear in space, linear in time between steps, log-pressure in height.",
    )
    show.add_argument(
        "sources",
        nargs="+",
        metavar="SOURCE",
        help="a GRIB2 file, a directory of forecast steps (one file each), or an http(s) URL",
    )
    show.add_argument(
        "--lat",
        type=NumberArg("--lat", KindRef("wxsky.weather.state:LAT_DEG")),
        default=None,
        metavar="DEG",
        help="latitude (default: the default preset's site)",
    )
    show.add_argument(
        "--lon",
        type=NumberArg("--lon", GRIB_LON_DEG),
        default=None,
        metavar="DEG",
        help="longitude, east (default: the default preset's site)",
    )
    show.add_argument(
        "--time",
        type=time_arg(),
        help="ISO 8601 time, UTC unless it says (default: now; held to the data's first or "
        "last step outside them)",
    )
    show.add_argument(
        "--no-byte-ranges",
        action="store_true",
        help="for a URL, fetch the whole file, not the messages its .idx lists",
    )
    show.add_argument("--json", action="store_true", help="print one JSON object")
    show.set_defaults(func=_cmd_show)
    idx = gsub.add_parser(
        "idx",
        help="print a wgrib2-style .idx inventory of a GRIB2 file",
        description="One line per field, N:OFFSET:d=YYYYMMDDHH:VAR:LEVEL:FORECAST:, as NOAA "
        "publishes beside its files: serve it as FILE.idx for byte-range fetches.",
    )
    idx.add_argument("file", type=Path, metavar="FILE", help="a GRIB2 file")
    idx.set_defaults(func=_cmd_idx)


def _site(args: argparse.Namespace) -> tuple[float, float]:
    if args.lat is not None and args.lon is not None:
        return args.lat, (args.lon + 180.0) % 360.0 - 180.0
    if (args.lat is None) != (args.lon is None):
        raise UsageError("--lat and --lon go together")
    from wxsky.settings.presets import load_preset
    from wxsky.weather.state import WeatherState

    obs = WeatherState().apply(load_preset("scattered-cumulus")).observer
    return obs.lat_deg, obs.lon_deg


def column_at(
    specs: Sequence[str],
    lat: float,
    lon: float,
    when: datetime,
    progress: Callable[[str], object],
    byte_ranges: bool = True,
) -> ModelProfile:
    """The model's column at a place and time from GRIB sources, read once, as the daemon
    reads them (used by `grib show` and `snapshot --grib`)."""
    from wxsky.inputs.grib_decode import Window, decode
    from wxsky.inputs.grib_sources import open_grib_source
    from wxsky.weather.model_fields import merge_steps
    from wxsky.weather.model_profile import profile_at

    window = Window(lat, lon, HALF_DEG)
    fields = []
    names: list[str] = []
    for spec in specs:
        progress(f"reading {spec}")
        source = open_grib_source(spec, byte_ranges=byte_ranges)
        try:
            blobs = source.fetch() or []
        finally:
            source.close()
        for blob in blobs:
            progress(f"decoding {blob.name}")
            fields.extend(decode(blob.data, blob.name, window))
            names.append(blob.name)
    steps = merge_steps(fields, tuple(names))
    profile = profile_at(steps, lat, lon, when)
    if profile is None:
        raise GribError(
            f"{', '.join(specs)}: no step has winds and temperatures on pressure levels at "
            f"{lat:.2f}, {lon:.2f}"
        )
    return profile


def _cmd_show(args: argparse.Namespace) -> int:
    from wxsky.weather.model_clouds import model_layers

    lat, lon = _site(args)
    when = args.time or datetime.now(UTC)
    profile = column_at(
        args.sources, lat, lon, when, args.progress, byte_ranges=not args.no_byte_ranges
    )
    layers = model_layers(profile)
    clouds = [
        {
            "type": lay.type.wire_name,
            "cover_oktas": round(lay.cover_oktas, 2),
            "base_m": round(lay.base_m, 1),
            "top_m": round(lay.top_m, 1),
        }
        for lay in layers
    ]
    if args.json:
        print(json.dumps({**profile.as_json(), "clouds": clouds}))
        return 0
    _print_table(profile.as_json(), clouds)
    return 0


def _print_table(p: dict[str, object], clouds: list[dict[str, object]]) -> None:
    out = sys.stdout
    steps = ", ".join(str(t) for t in p["steps_utc"])  # type: ignore[attr-defined]
    out.write(f"{p['lat_deg']:.3f}, {p['lon_deg']:.3f} at {p['valid_utc']} (steps {steps})\n")
    out.write(
        f"surface {p['surface_m']} m, {p['surface_hpa']} hPa, 2 m {p['t2m_c']} C; "
        f"freezing level {p['freezing_level_m']} m; tropopause {p['tropopause_m']} m "
        f"({p['tropopause_hpa']} hPa); CAPE {p['cape_jkg']} J/kg\n"
    )
    out.write("  hPa   height m   dir  speed m/s   temp C   RH %\n")
    for lev in p["levels"]:  # type: ignore[attr-defined]
        rh = "" if lev["rh_pct"] is None else f"{lev['rh_pct']:5.0f}"
        out.write(
            f"{lev['pressure_hpa']:6.1f} {lev['height_m']:9.0f} {lev['dir_deg']:5.0f} "
            f"{lev['speed_mps']:10.1f} {lev['t_c']:8.1f}  {rh}\n"
        )
    if not clouds:
        out.write("clouds: none\n")
    for c in clouds:
        base, top = c["base_m"], c["top_m"]
        out.write(f"cloud: {c['type']} {c['cover_oktas']} oktas, {base:.0f} to {top:.0f} m\n")


def _cmd_idx(args: argparse.Namespace) -> int:
    from wxsky.inputs.grib_decode import inventory

    try:
        data = args.file.read_bytes()
    except OSError as e:
        raise GribError(f"{args.file}: {e.strerror or e}") from None
    sys.stdout.write(inventory(data))
    return 0
