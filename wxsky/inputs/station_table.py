"""Station positions shipped with wxsky, for feeds that carry only the report text (NOAA
tgftp, VATSIM, plain lines). Built from the AWC cache corpora by
tools/generate/build_station_table.py.

Also the one way a decoded report becomes weather (`report_patch`): every path that turns a
report into cloud layers (a feed, `wxsky run --metar`, `wxsky snapshot --metar`, `wxsky preset
save --from-metar`, the control channel's `apply_metar`) reads its cloud bases over the same
field, so one report gives the same layers whichever way it came in."""

from __future__ import annotations

import csv
import functools
import io
from collections.abc import Mapping
from importlib import resources
from typing import TYPE_CHECKING, NamedTuple

from wxsky.errors import MetarError

if TYPE_CHECKING:
    from wxsky.weather.metar import Metar
    from wxsky.weather.state import WeatherPatch


class StationPosition(NamedTuple):
    lat_deg: float
    lon_deg: float
    elevation_m: float


@functools.cache
def station_table() -> dict[str, StationPosition]:
    text = resources.files("wxsky.inputs").joinpath("stations.csv").read_text("utf-8")
    table = {}
    for row in csv.DictReader(io.StringIO(text)):
        table[row["station"]] = StationPosition(
            float(row["lat_deg"]), float(row["lon_deg"]), float(row["elevation_m"])
        )
    return table


def field_elevation_m(
    station: str | None,
    given_m: float | None = None,
    *,
    feed_m: float | None = None,
    positions: Mapping[str, StationPosition] | None = None,
    flag: str = "--field-elevation-m",
) -> float:
    """The field elevation (m MSL) a report from `station` is read at: `given_m` where the
    user gave one; else the station table's; else, for a station the table lacks, the feed's
    own figure for it (`feed_m`: an AWC row's elevation_m). The table comes before the feed
    so that a report pasted on the command line and the same report in a feed give the same
    clouds (AWC's figure for a station changes between years: LSZH 432 m in 2020, 424 m in
    2022). MetarError naming `flag` (how the caller's user gives one) when there is none."""
    if given_m is not None:
        return given_m
    table = station_table() if positions is None else positions
    known = table.get(station) if station else None
    if known is not None:
        return known.elevation_m
    if feed_m is not None:
        return feed_m
    raise MetarError(
        f"METAR {station or 'report'}: station not in wxsky's station table, so its field "
        f"elevation is unknown; give it with {flag}"
    )


def report_patch(
    metar: Metar,
    given_m: float | None = None,
    *,
    feed_m: float | None = None,
    positions: Mapping[str, StationPosition] | None = None,
    flag: str = "--field-elevation-m",
) -> WeatherPatch:
    """The weather a decoded report states, cloud bases and wind moved to MSL over its
    station's field (`field_elevation_m`); the one function every path calls."""
    from wxsky.weather.metar_clouds import metar_to_patch

    elevation = field_elevation_m(
        metar.station, given_m, feed_m=feed_m, positions=positions, flag=flag
    )
    return metar_to_patch(metar, field_elevation_m=elevation)
