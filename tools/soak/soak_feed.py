"""The METAR feed file of tools/soak/soak.py, rewritten once a cycle in one of several ways, each
write recorded with what the daemon must and must not take from it.

Every report is for the observer's station with the current minute as its time. Valid writes
carry a visibility never sent before (1000 m + 10 m per value), which is how the soak sees
each one applied; bad writes carry marker visibilities (ending in 5 m) that must never reach
the weather. The kinds, in turn:

* `lines` (one report per line), `awc-csv` (an AWC cache CSV), `gzip` (the lines gzipped):
  renamed over the old file; must be applied;
* `half-written`: written in place, a random part, a pause longer than the poll, the rest;
  must be applied, and what the part decodes to must not show (the reader holds back a
  last line with no end);
* `truncated`: a valid report cut at a random byte and left so; what it decodes to may show;
* `garbage`: random bytes;
* `gzip-truncated`: a gzipped report with its second half cut off; its values must not show;
* `gzip-bomb`: a small gzip that inflates to `bomb_mib` MiB of zeros;
* `bad-reports`: a report three hours old, one dated day 32, one from a station 6,300 km
  away (all three with markers), and a fresh one whose QNH is 123 hPa (which must not show);
* `missing`: the file removed.
"""

from __future__ import annotations

import gzip
import io
import os
import random
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

KINDS = (
    "lines",
    "garbage",
    "gzip",
    "truncated",
    "half-written",
    "gzip-bomb",
    "awc-csv",
    "bad-reports",
    "gzip-truncated",
    "missing",
)
STATION = "LSZH"  # the default preset's observer (Zurich) is at it
FAR_STATION = ("KJFK", 40.6398, -73.7789, 4)  # 6,300 km away: beyond max_station_distance_km
AWC_HEADER = (
    "raw_text,station_id,observation_time,latitude,longitude,temp_c,dewpoint_c,"
    "wind_dir_degrees,wind_speed_kt,wind_gust_kt,visibility_statute_mi,altim_in_hg,"
    "sea_level_pressure_mb,corrected,auto,auto_station,maintenance_indicator_on,no_signal,"
    "lightning_sensor_off,freezing_rain_sensor_off,present_weather_sensor_off,wx_string,"
    "sky_cover,cloud_base_ft_agl,sky_cover,cloud_base_ft_agl,sky_cover,cloud_base_ft_agl,"
    "sky_cover,cloud_base_ft_agl,flight_category,three_hr_pressure_tendency_mb,maxT_c,minT_c,"
    "maxT24hr_c,minT24hr_c,precip_in,pcp3hr_in,pcp6hr_in,pcp24hr_in,snow_in,vert_vis_ft,"
    "metar_type,elevation_m"
)
LSZH_POSITION = (47.4647, 8.5492, 432)
HALF_WRITTEN_PAUSE_S = 1.5  # longer than the soak's poll interval: the daemon reads the part


@dataclass
class FeedWrite:
    """One rewrite: when, how, and the values it sets (visibility m, QNH hPa)."""

    t: float  # time.monotonic() when the write was complete
    kind: str
    expected: tuple[float, float] | None = None  # must show in the target
    allowed: set[tuple[float, float]] = field(default_factory=set)  # may show
    forbidden_visibility: set[float] = field(default_factory=set)
    forbidden_qnh: set[float] = field(default_factory=set)


class FeedWriter:
    def __init__(self, path: Path, rng: random.Random, bomb_mib: int) -> None:
        self.path = path
        self.rng = rng
        self.bomb_mib = bomb_mib
        self.count = 0
        self.writes: list[FeedWrite] = []
        self._next_value = 0
        self._last_valid: tuple[float, float] | None = None
        self._bomb: bytes | None = None

    def kinds(self) -> tuple[str, ...]:
        return tuple(k for k in KINDS if k != "gzip-bomb" or self.bomb_mib > 0)

    def write_next(self) -> FeedWrite:
        """The next kind in the rotation (a valid one every other write)."""
        kinds = self.kinds()
        kind = kinds[self.count % len(kinds)]
        self.count += 1
        return self.write(kind)

    def write(self, kind: str) -> FeedWrite:
        handler = getattr(self, "_" + kind.replace("-", "_"))
        record: FeedWrite = handler()
        record.t = time.monotonic()
        self.writes.append(record)
        return record

    # -- values -------------------------------------------------------------------------

    def _values(self) -> tuple[float, float]:
        """A visibility never used before and a QNH in the normal range."""
        k = self._next_value
        self._next_value += 1
        return 1000.0 + 10.0 * (k % 899), 990.0 + k % 40

    def _marker(self) -> tuple[float, float]:
        """Values for reports that must not apply: visibilities valid writes never use."""
        vis, _ = self._values()
        return vis + 5.0, 0.0  # 1005, 1015, ...: valid ones end in 0

    @staticmethod
    def report(
        values: tuple[float, float], when: datetime | None = None, station: str = STATION
    ) -> str:
        when = when or datetime.now(UTC)
        vis, qnh = values
        return f"METAR {station} {when:%d%H%M}Z 25004KT {vis:04.0f} FEW045 18/10 Q{qnh:04.0f}"

    # -- the kinds ----------------------------------------------------------------------

    def _lines(self) -> FeedWrite:
        values = self._values()
        self._replace((self.report(values) + "\n").encode())
        return self._valid("lines", values)

    def _awc_csv(self) -> FeedWrite:
        values = self._values()
        now = datetime.now(UTC)
        lat, lon, elev = LSZH_POSITION
        row = f'"{self.report(values, now)}",{STATION},{now:%Y-%m-%dT%H:%M:00Z},{lat},{lon}'
        row += "," * 38 + f"METAR,{elev}"
        head = "No errors\nNo warnings\n3 ms\ndata source=metars\n1 results\n"
        self._replace(f"{head}{AWC_HEADER}\n{row}\n".encode())
        return self._valid("awc-csv", values)

    def _gzip(self) -> FeedWrite:
        values = self._values()
        self._replace(gzip.compress((self.report(values) + "\n").encode()))
        return self._valid("gzip", values)

    def _half_written(self) -> FeedWrite:
        values = self._values()
        data = (self.report(values) + "\n").encode()
        cut = self.rng.randrange(1, len(data))
        with open(self.path, "wb") as f:  # in place, as a naive writer does
            f.write(data[:cut])
            f.flush()
            time.sleep(HALF_WRITTEN_PAUSE_S)
            f.write(data[cut:])
        return self._valid("half-written", values)

    def _truncated(self) -> FeedWrite:
        values = self._values()
        data = (self.report(values) + "\n").encode()
        self._replace(data[: self.rng.randrange(1, len(data) - 1)])
        return FeedWrite(0.0, "truncated", allowed={values})

    def _garbage(self) -> FeedWrite:
        self._replace(bytes(self.rng.getrandbits(8) for _ in range(4096)))
        return FeedWrite(0.0, "garbage")

    def _gzip_truncated(self) -> FeedWrite:
        values = self._marker()
        data = gzip.compress((self.report(values) + "\n").encode() * 20)
        self._replace(data[: len(data) // 2])
        return FeedWrite(0.0, "gzip-truncated", forbidden_visibility={values[0]})

    def _gzip_bomb(self) -> FeedWrite:
        if self._bomb is None:
            out = io.BytesIO()
            with gzip.GzipFile(fileobj=out, mode="wb", compresslevel=9) as f:
                chunk = bytes(1 << 20)
                for _ in range(self.bomb_mib):
                    f.write(chunk)
            self._bomb = out.getvalue()
        self._replace(self._bomb)
        return FeedWrite(0.0, "gzip-bomb")

    def _bad_reports(self) -> FeedWrite:
        now = datetime.now(UTC)
        old, day32, far = self._marker(), self._marker(), self._marker()
        # A fresh report whose only bad group is QNH: the rest of it applies (a partial report),
        # so it carries the last valid visibility and nothing new.
        last = self._last_valid or (1000.0, 1013.0)
        far_station = FAR_STATION[0]
        lines = [
            self.report((old[0], 1013.0), now - timedelta(hours=3)),
            self.report((day32[0], 1013.0), now).replace(f"{now:%d%H%M}Z", f"32{now:%H%M}Z"),
            self.report((far[0], 1013.0), now, station=far_station),
            self.report((last[0], 123.0), now),
        ]
        self._replace(("\n".join(lines) + "\n").encode())
        return FeedWrite(
            0.0,
            "bad-reports",
            allowed={last},
            forbidden_visibility={old[0], day32[0], far[0]},
            forbidden_qnh={123.0},
        )

    def _missing(self) -> FeedWrite:
        self.path.unlink(missing_ok=True)
        return FeedWrite(0.0, "missing")

    # -- helpers ------------------------------------------------------------------------

    def _valid(self, kind: str, values: tuple[float, float]) -> FeedWrite:
        self._last_valid = values
        return FeedWrite(0.0, kind, expected=values, allowed={values})

    def _replace(self, data: bytes) -> None:
        """Write a new file and rename it over the old one, as feed tools do."""
        tmp = self.path.with_suffix(".tmp")
        tmp.write_bytes(data)
        os.replace(tmp, self.path)
