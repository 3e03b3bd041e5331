"""Build wxsky/inputs/stations.csv (station, lat_deg, lon_deg, elevation_m) from the AWC cache
files in tests/data/metar/, whose rows carry each station's position and elevation. Feeds
that give only report text (tgftp, VATSIM, plain lines) find station positions there.

    .venv/bin/python tools/generate/build_station_table.py [FEED ...]

With no arguments it reads every AWC CSV fixture; the newest row of a station wins.
"""

from __future__ import annotations

import argparse
import csv
import sys
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.weather.feeds import read_reports  # noqa: E402

OUT = ROOT / "wxsky" / "inputs" / "stations.csv"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("feeds", nargs="*", type=Path)
    args = p.parse_args()
    feeds = args.feeds or sorted((ROOT / "tests" / "data" / "metar").glob("awc_cache_*.csv.gz"))
    table: dict[str, tuple[datetime, float, float, float]] = {}
    for path in feeds:
        for r in read_reports(path):
            if None in (r.station, r.lat_deg, r.lon_deg, r.elevation_m):
                continue
            when = r.observed_utc or datetime(r.year, r.month, 1, tzinfo=UTC)
            assert r.station and r.lat_deg is not None and r.lon_deg is not None
            assert r.elevation_m is not None
            old = table.get(r.station)
            if old is None or when >= old[0]:
                table[r.station] = (when, r.lat_deg, r.lon_deg, r.elevation_m)
    with OUT.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["station", "lat_deg", "lon_deg", "elevation_m"])
        for station in sorted(table):
            _, lat, lon, elev = table[station]
            w.writerow([station, f"{lat:.4f}", f"{lon:.4f}", f"{elev:.0f}"])
    print(f"wrote {OUT.relative_to(ROOT)}: {len(table)} stations from {len(feeds)} feeds")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
