"""A live METAR feed as a daemon input: fetch -> parse -> decode -> newest report per
station -> the station(s) for the observer's position -> one METAR-sourced patch.

Bad input never stops it: a malformed report, a junk row or a failed fetch is counted in the
input's status and logged (rate-limited) with its station and reason, and the weather stays
what it was. When no report near the observer is fresh enough the last good weather stays and
the status says `stale`.

A report whose observation time is impossible (day 32, hour 25) still counts for its station: it
is dated by the feed's own time for it (AWC observation_time, the tgftp timestamp line) and, where
the feed has none, kept without a time, which makes it always stale (`stations.split_by_age`).
A report whose time group disagrees with the feed's own observation time for it (AWC's
observation_time, by more than `FEED_TIME_SLACK_S`) is dated by the feed's time too: a station's
wrong day (`PTSA 022350Z` in a file of 1-2 May 00:40) would otherwise be the feed's newest
report, and against it (`age_reference = "feed"`) every other station would be stale.
Text without a time group at all is no report (`PART 1 OF 2`) and is only named as a problem.

A defect of the decoder (`MetarInternalError`) is not bad input: it is kept apart from the
feed's problems (`Ingested.internal_errors`) and logged as an error, and the other reports of
the feed are still used. A report that says nothing after its time (`LSZH 011731Z`, a file
caught half-written) is a problem and never replaces its station's last good report.

Status (`InputStats`): `ok` says whether the feed's current content is usable: false from a
failed fetch, a refused feed (not a METAR feed, over the size limit, a gzip bomb) or a file or
HTTP feed with no usable report, until good data arrives; an unchanged source keeps what its
content gave. The detail adds `state` ("running", "restarting" while waiting to restart the
task after a failure, "ended" once a stream ends), `restarts` (task restarts), `restart_in_s`
(while restarting: the back-off), `fetches` (fetch attempts), `oversize` (feeds refused as over
the size limit) and `held_back` (reads put off because the file was being written).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import TYPE_CHECKING

from wxsky.errors import FeedChanging, FeedError, FeedTooLarge, FeedUnavailable
from wxsky.inputs.feed_sources import FeedSource, Fetched, StreamSource
from wxsky.inputs.station_table import (
    StationPosition,
    field_elevation_m,
    report_patch,
    station_table,
)
from wxsky.inputs.stats import InputStats
from wxsky.logs import RateLimitedLog, clip
from wxsky.weather.feeds import Feed, parse_feed
from wxsky.weather.metar import MetarInternalError, decode
from wxsky.weather.state import CLOCK_YEARS, WeatherPatch, time_in_range
from wxsky.weather.stations import StationWeather, blend, nearest, split_by_age

if TYPE_CHECKING:
    from wxsky.settings.config import MetarSection

log = logging.getLogger("wxsky.inputs.metar")

RESELECT_S = 5.0  # how often the station choice follows the observer between fetches
STREAM_POLL_S = 0.25
# The first wait before restarting a failed feed task; it doubles up to max_backoff_s.
RESTART_FIRST_S = 1.0
# A report's own time and the feed's observation time for it (AWC) agree to the minute in
# every row of the four AWC corpora but three, which are hours or a day apart: beyond this
# the report's day group is taken to be wrong and the feed's time dates it.
FEED_TIME_SLACK_S = 30 * 60.0


@dataclass(frozen=True)
class MetarSettings:
    format: str = "auto"
    poll_interval_s: float = 60.0
    max_backoff_s: float = 900.0
    max_age_s: float = 90 * 60.0
    age_reference: str = "clock"  # or "feed": ages against the newest report in the feed
    station: str = ""  # pinned station; empty picks by position
    blend_stations: int = 1
    max_distance_m: float = 200_000.0

    @classmethod
    def from_section(cls, m: MetarSection) -> MetarSettings:
        """The input's view of the config's [metar] section, in SI units."""
        return cls(
            format=m.format,
            poll_interval_s=m.poll_interval_s,
            max_backoff_s=m.max_backoff_s,
            max_age_s=m.max_age_min * 60.0,
            age_reference=m.age_reference,
            station=m.station,
            blend_stations=m.blend_stations,
            max_distance_m=m.max_station_distance_km * 1000.0,
        )


@dataclass(frozen=True)
class Ingested:
    stations: Mapping[str, StationWeather]
    reports: int = 0
    accepted: int = 0  # reports that decoded to a usable station and time
    partial: int = 0
    nil: int = 0
    duplicates: int = 0
    problems: tuple[str, ...] = ()
    internal_errors: tuple[str, ...] = ()  # decoder defects, one per report (module docstring)


@dataclass(frozen=True)
class Selection:
    patch: WeatherPatch | None  # None: nothing usable; keep the last weather
    used: tuple[tuple[str, float], ...] = ()  # (station, distance_m)
    stale: bool = False
    reason: str = ""
    fresh: int = 0
    stale_count: int = 0
    stale_stations: tuple[str, ...] = field(default=(), compare=False)
    blended: tuple[StationWeather, ...] = field(default=(), compare=False)  # when more than one


def ingest(
    feed: Feed,
    known: Mapping[str, StationWeather] | None = None,
    positions: Mapping[str, StationPosition] | None = None,
    history: History | None = None,
) -> Ingested:
    """Decode every report of a feed and keep the newest usable one per station; with
    `history` (a replay), every usable report of known time is kept there too, by station."""
    positions = station_table() if positions is None else positions
    stations: dict[str, StationWeather] = dict(known or {})
    problems = [f"{p.where}: {p.reason}" for p in feed.problems]
    internal: list[str] = []
    partial = nil = accepted = 0
    for report in feed.reports:
        try:
            metar = decode(report.raw, year=report.year, month=report.month)
        except MetarInternalError as exc:
            internal.append(f"{report.where}: {exc}")
            continue
        station = metar.station or report.station
        where = f"{report.where}: {station or '?'}"
        if station is None or metar.time_group is None:
            reason = metar.errors[0] if metar.errors else "no station or time group"
            problems.append(f"{where}: {reason}")
            continue
        if metar.nil:
            nil += 1
            continue
        if metar.observes_nothing:
            # Usually a file caught half-written: applied, it would clear the station's sky.
            if metar.errors:
                problems.append(f"{where}: no weather after the time group ({metar.errors[0]})")
            else:
                problems.append(f"{where}: nothing after the time group (cut off?); not used")
            continue
        partial += metar.partial
        observed = metar.time_utc
        if observed is None:
            observed = report.observed_utc
            trouble = next((e for e in metar.errors if repr(metar.time_group) in e), "no time")
            kept = "dated by the feed" if observed else "kept without a time, so never fresh"
            problems.append(f"{where}: {trouble}; {kept}")
        elif report.feed_utc is not None and _disagree(observed, report.feed_utc):
            # A station's wrong day group (`PTSA 022350Z` in a feed of 1 May 23:50): dated by
            # its day it would be the feed's newest report, and every other station would be
            # aged against it (age_reference "feed").
            problems.append(
                f"{where}: time group {metar.time_group} says {_iso(observed)}, the feed's "
                f"observation time {_iso(report.feed_utc)}; dated by the feed"
            )
            observed = report.feed_utc
        if observed is not None and not time_in_range(observed):
            # Ages and the feed's newest time are worked out from it: kept, a report of year
            # 9999 would make every other station stale.
            problems.append(
                f"{where}: report time {_iso(observed)} is outside the clock's years "
                f"{CLOCK_YEARS}; not used"
            )
            continue
        pos = _position(report.lat_deg, report.lon_deg, report.elevation_m)
        pos = pos or positions.get(station)
        if pos is None:
            problems.append(f"{where}: position unknown (not in the feed or the station table)")
            continue
        old = stations.get(station)
        # Same time is a correction (COR, or a feed file rewritten): the later read wins. A
        # report of unknown time never replaces one of known time.
        if _superseded(old, observed) and history is None:
            accepted += 1  # a good report, only superseded
            continue
        # The field every other path reads this station's reports at (the table's, before
        # the feed's own figure), so the feed's clouds are the command line's.
        elevation_m = field_elevation_m(station, feed_m=pos.elevation_m, positions=positions)
        try:
            patch = report_patch(metar, elevation_m)
        except ValueError as exc:
            problems.append(f"{where}: {exc}")
            continue
        accepted += 1
        weather = StationWeather(station, pos.lat_deg, pos.lon_deg, elevation_m, observed, patch)
        if history is not None and observed is not None:
            history.add(weather)
        if not _superseded(old, observed):
            stations[station] = weather
    return Ingested(
        stations=stations,
        reports=len(feed.reports),
        accepted=accepted,
        partial=partial,
        nil=nil,
        duplicates=feed.duplicates,
        problems=tuple(problems),
        internal_errors=tuple(internal),
    )


def _summed(results: list[Ingested]) -> Ingested:
    """One ingest's figures for a directory's files, read one after another."""
    if len(results) == 1:
        return results[0]
    return Ingested(
        stations=results[-1].stations,
        reports=sum(r.reports for r in results),
        accepted=sum(r.accepted for r in results),
        partial=sum(r.partial for r in results),
        nil=sum(r.nil for r in results),
        duplicates=sum(r.duplicates for r in results),
        problems=tuple(p for r in results for p in r.problems),
        internal_errors=tuple(e for r in results for e in r.internal_errors),
    )


class History:
    """Every report of each station, in time order, for replaying an archive: the weather at
    a moment is each station's latest report not after it. Bounded: a station keeps its
    newest `per_station` reports."""

    def __init__(self, per_station: int = 24 * 12) -> None:
        self.per_station = per_station
        self._by_station: dict[str, list[StationWeather]] = {}

    def add(self, weather: StationWeather) -> None:
        assert weather.observed_utc is not None
        reports = self._by_station.setdefault(weather.station, [])
        reports[:] = [r for r in reports if r.observed_utc != weather.observed_utc]
        reports.append(weather)
        reports.sort(key=lambda r: r.observed_utc or datetime.min.replace(tzinfo=UTC))
        del reports[: max(0, len(reports) - self.per_station)]

    def at(self, when: datetime) -> dict[str, StationWeather]:
        """Each station's latest report observed at or before `when`."""
        out = {}
        for station, reports in self._by_station.items():
            before = [r for r in reports if r.observed_utc is not None and r.observed_utc <= when]
            if before:
                out[station] = before[-1]
        return out

    def __len__(self) -> int:
        return sum(len(r) for r in self._by_station.values())


def _disagree(report_utc: datetime, feed_utc: datetime) -> bool:
    return abs((report_utc - feed_utc).total_seconds()) > FEED_TIME_SLACK_S


def _iso(time: datetime) -> str:
    return f"{time:%Y-%m-%dT%H:%M}Z"


def _superseded(old: StationWeather | None, observed: datetime | None) -> bool:
    if old is None or old.observed_utc is None:
        return False
    return observed is None or old.observed_utc > observed


def _position(
    lat: float | None, lon: float | None, elevation: float | None
) -> StationPosition | None:
    if lat is None or lon is None or elevation is None:
        return None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and -500.0 <= elevation <= 9000.0):
        return None
    return StationPosition(lat, lon, elevation)


def select(
    stations: Mapping[str, StationWeather],
    lat_deg: float,
    lon_deg: float,
    settings: MetarSettings,
    now_utc: datetime | None = None,
) -> Selection:
    """The weather for a position from the stations' newest reports."""
    if not stations:
        return Selection(None, reason="no usable report yet")
    if settings.age_reference == "feed":
        known = (s.observed_utc for s in stations.values() if s.observed_utc is not None)
        now_utc = max(known, default=None)
    if now_utc is None:  # the clock; also for a feed none of whose reports has a time
        now_utc = datetime.now(UTC)
    candidates = list(stations.values())
    if settings.station:
        candidates = [s for s in candidates if s.station == settings.station]
        if not candidates:
            return Selection(None, reason=f"no report from station {settings.station}")
    fresh, stale = split_by_age(candidates, now_utc, settings.max_age_s)
    limit = math.inf if settings.station else settings.max_distance_m
    chosen = nearest(fresh, lat_deg, lon_deg, settings.blend_stations, limit)
    if not chosen:
        near_stale = nearest(stale, lat_deg, lon_deg, 3, limit)
        names = tuple(s.station for s, _ in near_stale)
        age = f"older than {settings.max_age_s / 60:.0f} min" if near_stale else "none in range"
        return Selection(
            None,
            stale=True,
            reason=(
                f"no fresh report from station {settings.station} ({age})"
                if settings.station  # any distance: no limit to name
                else f"no fresh report within {limit / 1000:.0f} km ({age})"
            ),
            fresh=len(fresh),
            stale_count=len(stale),
            stale_stations=names,
        )
    return Selection(
        blend(chosen),
        used=tuple((s.station, d) for s, d in chosen),
        fresh=len(fresh),
        stale_count=len(stale),
        blended=tuple(s for s, _ in chosen) if len(chosen) > 1 else (),
    )


class MetarFeedInput:
    """Runs one feed source inside the daemon's event loop."""

    def __init__(
        self,
        source: FeedSource,
        settings: MetarSettings,
        stats: InputStats,
        apply: Callable[[WeatherPatch], object],
        position: Callable[[], tuple[float, float]],
        positions: Mapping[str, StationPosition] | None = None,
        replay_clock: Callable[[], datetime] | None = None,
    ) -> None:
        """`replay_clock` (a replay of archived reports, `wxsky run --replay`): the sim
        clock, against which reports are aged and chosen (each station's latest not after
        it), instead of the wall clock and each station's newest."""
        self.source = source
        self._replay_clock = replay_clock
        self._history = History() if replay_clock is not None else None
        self.settings = settings
        self.stats = stats
        self._apply = apply
        self._position = position
        self._positions = positions
        self._stations: Mapping[str, StationWeather] = {}
        self._last_patch: WeatherPatch | None = None
        # The stations blended into the weather (more than one), each with its own report:
        # a CIGI source sends them as regions.
        self.blended: tuple[StationWeather, ...] = ()
        # The nearest station in use and its distance: how much the METAR counts against
        # model data (weather.model_blend); None while the feed gives no weather here.
        self.nearest: tuple[StationWeather, float] | None = None
        self._warn = RateLimitedLog(log)
        self._failures = 0
        self._content_ok = True  # what the source's current content gave (module docstring)
        self._had_good_poll = False  # since the task last (re)started
        stats.detail.update(
            stale=False,
            stations=0,
            using=[],
            partial=0,
            format=None,
            state="running",
            restarts=0,
            fetches=0,
            oversize=0,
            held_back=0,
        )

    async def run_supervised(
        self, stop: asyncio.Event, *, first_backoff_s: float = RESTART_FIRST_S
    ) -> None:
        """`run`, restarted after any failure escaping it (a wxsky defect, MemoryError), so
        the feed never dies silently: one log line, `ok` false with `state` "restarting" and
        `restarts` counted, then a restart after a back-off that doubles from
        `first_backoff_s` to `max_backoff_s` (back to the first after a run that got good
        data). Returns when `stop` is set or a stream ends."""
        d = self.stats.detail
        backoff = first_backoff_s
        while not stop.is_set():
            d["state"] = "running"
            self._had_good_poll = False
            try:
                await self.run(stop)
                return
            except Exception as exc:  # whatever it was, the feed must come back
                if self._had_good_poll:
                    backoff = first_backoff_s
                what = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                message = (
                    f"{self.source.name}: the METAR feed task failed ({clip(what)}); "
                    f"restarting in {backoff:g} s"
                )
                log.debug("%s", message, exc_info=True)
            d["restarts"] += 1
            d["state"] = "restarting"
            d["restart_in_s"] = backoff
            self.stats.ok = False
            self.stats.error(message)
            # Until a poll after the restart says otherwise, the content is what failed.
            self._content_ok = False
            self._warn.log(logging.ERROR, "task", message)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), timeout=backoff)
            backoff = min(self.settings.max_backoff_s, backoff * 2.0)
            d.pop("restart_in_s", None)
            # What failed may have been marked seen: read it again, it may now go through.
            self.source.forget()

    async def run(self, stop: asyncio.Event) -> None:
        loop = asyncio.get_running_loop()
        next_fetch = loop.time()
        while not stop.is_set():
            if loop.time() >= next_fetch:
                next_fetch = loop.time() + await self.poll_once()
                if isinstance(self.source, StreamSource) and self.source.eof:
                    log.info("%s: end of input; keeping the last weather", self.source.name)
                    self.stats.detail.update(eof=True, state="ended")
                    return
            self.reselect()
            wait = min(RESELECT_S, max(0.0, next_fetch - loop.time()))
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), timeout=wait)

    async def poll_once(self) -> float:
        """Fetch and ingest once; returns the seconds until the next fetch (backing off)."""
        interval = self.settings.poll_interval_s
        if isinstance(self.source, StreamSource):
            interval = min(interval, STREAM_POLL_S)
        self.stats.detail["fetches"] += 1
        try:
            fetched = await self.source.fetch()
            if fetched is not None:
                self._content_ok = await asyncio.to_thread(self._ingest, fetched)
        except FeedChanging as exc:
            # No failure: the writer is not done. `ok` stays what the last content gave.
            self.stats.detail["held_back"] += 1
            log.debug("METAR feed %s", exc)
            return min(interval, exc.retry_in_s)
        except FeedError as exc:
            self._failures += 1
            if not isinstance(exc, FeedUnavailable):
                # The content itself was refused: an unchanged source stays refused.
                self._content_ok = False
            if isinstance(exc, FeedTooLarge):
                self.stats.detail["oversize"] += 1
            self.stats.ok = False
            self.stats.error(str(exc))
            self._warn.warning("fetch", f"METAR feed {exc}")
            return float(min(self.settings.max_backoff_s, interval * 2.0**self._failures))
        self._failures = 0
        self.stats.ok = self._content_ok
        self._had_good_poll |= self._content_ok
        return interval

    def _ingest(self, fetched: Fetched) -> bool:
        """Ingests one fetch; returns whether the feed's content is usable now."""
        if fetched.dropped is not None:
            self.stats.error(fetched.dropped)
            self._warn.warning("cut", f"METAR feed {fetched.dropped}")
        fmt = self.settings.format if fetched.format == "auto" else fetched.format
        # An archive's reports name only their day: in a replay, the month is the sim clock's.
        reference = fetched.reference_utc if self._replay_clock is None else self._replay_clock()
        parts = fetched.files or ((self.source.name, fetched.data),)
        results = []
        for name, data in parts:
            feed = parse_feed(data, format=fmt, name=name, reference_utc=reference)
            results.append(ingest(feed, self._stations, self._positions, self._history))
            self._stations = results[-1].stations
        result = _summed(results)
        self.stats.message(result.accepted)
        if result.problems:
            self.stats.error(result.problems[-1], len(result.problems))
            for problem in result.problems:
                self._warn.warning("report", f"METAR {problem}")
        if result.internal_errors:
            # A wxsky bug, not the feed's: an error, once per fetch, with what reproduces it.
            count = len(result.internal_errors)
            self.stats.error(result.internal_errors[-1], count)
            log.error(
                "%s: the METAR decoder failed on %d report(s), a wxsky defect; first: %s",
                self.source.name,
                count,
                result.internal_errors[0],
            )
        d = self.stats.detail
        d["format"] = feed.format
        d["stations"] = len(result.stations)
        if self._history is not None:
            d["replay_reports"] = len(self._history)
        d["partial"] = d.get("partial", 0) + result.partial
        d["duplicates"] = d.get("duplicates", 0) + result.duplicates
        if result.internal_errors:
            d["internal_errors"] = d.get("internal_errors", 0) + len(result.internal_errors)
        if result.accepted:
            return True
        if isinstance(self.source, StreamSource):
            # Lines are messages: one without a usable report leaves the input as it was.
            return self._content_ok
        if not result.problems:
            self.stats.error(f"{self.source.name}: no usable report in the feed")
        return False

    def reselect(self) -> None:
        lat, lon = self._position()
        if self._replay_clock is not None and self._history is not None:
            now = self._replay_clock()
            choice = select(self._history.at(now), lat, lon, self.settings, now_utc=now)
        else:
            choice = select(self._stations, lat, lon, self.settings)
        d = self.stats.detail
        d["stale"] = choice.stale
        if choice.patch is None:
            self.nearest = None
            if choice.stale:
                self._warn.warning("stale", f"METAR {self.source.name}: {choice.reason}")
            d["reason"] = choice.reason
            return
        d.pop("reason", None)
        self.blended = choice.blended
        name, distance = choice.used[0]
        at = self._stations.get(name)
        self.nearest = (at, distance) if at is not None else None
        d["using"] = [{"station": s, "distance_km": round(m / 1000.0, 1)} for s, m in choice.used]
        if choice.patch != self._last_patch:
            # Remembered only once applied: after a failure here the restarted task applies it.
            self._apply(choice.patch)
            self._last_patch = choice.patch

    def close(self) -> None:
        self.source.close()
