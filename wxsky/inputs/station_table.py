"""Station positions shipped with wxsky, for feeds that carry only the report text (NOAA
tgftp, VATSIM, plain lines). Built from the AWC cache corpora by
tools/generate/build_station_table.py."""

from __future__ import annotations

import csv
import functools
import io
from importlib import resources
from typing import NamedTuple


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
