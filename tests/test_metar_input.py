"""From feed to one METAR patch: ingest real corpora, pick stations, report problems."""

from __future__ import annotations

import asyncio
import gzip
import json
import logging
import os
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from metar_helpers import gzip_bomb

from wxsky.cli import main
from wxsky.inputs.feed_sources import MAX_FEED_BYTES, SETTLE_S, Fetched, FileSource
from wxsky.inputs.metar_input import Ingested, MetarFeedInput, MetarSettings, ingest, select
from wxsky.inputs.station_table import StationPosition, station_table
from wxsky.inputs.stats import InputStats
from wxsky.weather import metar as metar_module
from wxsky.weather.feeds import parse_feed, read_feed
from wxsky.weather.state import CloudType, WeatherPatch

DATA = Path(__file__).parent / "data" / "metar"
CYCLE = DATA / "noaa_cycle_2025-07-26_okay_weather_HEAD1500.txt.gz"
AWC_2014 = DATA / "awc_cache_2014-09-26_etms-visualization.csv.gz"


def test_station_table_has_positions_from_the_corpora() -> None:
    table = station_table()
    assert len(table) > 5000
    lszh = table["LSZH"]
    assert lszh.lat_deg == pytest.approx(47.48, abs=0.01) and lszh.elevation_m == 424.0


def test_ingest_a_world_cache_keeps_one_report_per_station() -> None:
    result = ingest(read_feed(AWC_2014))
    assert result.reports == 4336 and result.internal_errors == ()
    # Every row but the three junk rows and the rows without a position gives a station.
    assert 4200 < len(result.stations) <= 4336
    assert any("PART 1 OF 2" in p or "no time" in p or "station" in p for p in result.problems)
    jfk = result.stations["KJFK"]
    assert jfk.observed_utc is not None
    assert (jfk.observed_utc.year, jfk.observed_utc.month) == (2014, 9)


def test_ingest_a_cycle_file_uses_the_station_table_for_positions() -> None:
    feed = read_feed(CYCLE)
    result = ingest(feed)
    assert result.duplicates == 946 and result.reports == 554 and result.internal_errors == ()
    unknown = {p.split(": ")[1] for p in result.problems if "position unknown" in p}
    # No report lost: every station is either placed or named as unplaceable.
    named = {r.raw.split()[0] for r in feed.reports}
    assert set(result.stations) | unknown == named and not set(result.stations) & unknown
    assert all(":" in p for p in result.problems)  # each names where it came from


def test_newest_report_per_station_wins_and_corrections_replace() -> None:
    text = (
        "LSZH 261550Z 24008KT 9999 FEW040 18/09 Q1016\n"
        "LSZH 261520Z 24008KT 9999 OVC010 18/09 Q1016\n"
    )
    ref = datetime(2025, 7, 26, 16, 0, tzinfo=UTC)
    first = ingest(parse_feed(text, format="lines", reference_utc=ref))
    assert first.stations["LSZH"].observed_utc == datetime(2025, 7, 26, 15, 50, tzinfo=UTC)
    layers = first.stations["LSZH"].patch.layers
    assert layers is not None and layers[0].cover_oktas == 2
    cor = "LSZH 261550Z COR 24008KT 9999 BKN040 18/09 Q1016\n"
    second = ingest(parse_feed(cor, format="lines", reference_utc=ref), first.stations)
    layers = second.stations["LSZH"].patch.layers
    assert layers is not None and layers[0].cover_oktas == 6


def test_garbage_reports_become_problems_not_exceptions() -> None:
    text = "LSZH 261550Z 24008KT 9999 FEW040 18/09 Q1016\nPART 1 OF 2\nZZZZ 261550Z 9999\n"
    ref = datetime(2025, 7, 26, 16, 0, tzinfo=UTC)
    result = ingest(parse_feed(text, format="lines", reference_utc=ref))
    assert set(result.stations) == {"LSZH"}
    assert any("ZZZZ: position unknown" in p for p in result.problems)
    assert any("PART" in p for p in result.problems)


def test_select_picks_the_nearest_fresh_station_or_says_why_not() -> None:
    ref = datetime(2025, 7, 26, 16, 0, tzinfo=UTC)
    text = "LSZH 261550Z 24008KT 9999 OVC010 18/09 Q1016\nLSGG 261320Z 24008KT 9999 FEW050 Q1016\n"
    positions = {
        "LSZH": StationPosition(47.48, 8.53, 424.0),
        "LSGG": StationPosition(46.24, 6.11, 411.0),
    }
    stations = ingest(parse_feed(text, format="lines", reference_utc=ref), None, positions)
    settings = MetarSettings(max_age_s=90 * 60.0)
    near_geneva = select(stations.stations, 46.3, 6.2, settings, now_utc=ref)
    # Geneva's report is 2 h 40 min old: Zurich, 220 km away, is beyond the 200 km limit.
    assert near_geneva.patch is None and near_geneva.stale
    assert "older than 90 min" in near_geneva.reason and near_geneva.stale_stations == ("LSGG",)
    zurich = select(stations.stations, 47.4, 8.5, settings, now_utc=ref)
    assert zurich.patch is not None and zurich.used[0][0] == "LSZH"
    assert zurich.patch.layers is not None and zurich.patch.layers[0].type == CloudType.STRATUS
    pinned = select(stations.stations, 46.3, 6.2, MetarSettings(station="LSZH"), now_utc=ref)
    assert pinned.used[0][0] == "LSZH"
    # Against the feed's own newest report, the archive is fresh.
    archive = select(stations.stations, 46.3, 6.2, MetarSettings(age_reference="feed"))
    assert archive.patch is None  # LSGG is still 2.5 h older than LSZH's report


def test_cli_decode_file_prints_json_lines(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["metar", "decode", "--file", str(CYCLE), "--json"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 554
    first = json.loads(lines[0])
    assert first["station"] == "KTGI" and first["time_utc"] == "2025-07-26T15:55:00Z"
    assert first["sky_clear"] == "CLR" and first["clouds"] == []


def test_cli_fetch_shows_what_the_daemon_would_take(capsys: pytest.CaptureFixture[str]) -> None:
    args = ["metar", "fetch", str(CYCLE), "--lat", "40.64", "--lon", "-73.78", "--json"]
    assert main([*args, "--age-reference", "feed"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["format"] == "tgftp" and out["using"][0]["station"] == "KJFK"
    assert out["weather"]["qnh_hpa"] > 1000
    # Against today's clock the 2025 reports are all stale: the daemon would keep its weather.
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["weather"] is None and "older than 90 min" in out["reason"]


def test_cli_fetch_of_an_html_page_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    page = tmp_path / "oops.txt"
    page.write_text("<!DOCTYPE html>\n<html><body>Service unavailable</body></html>\n")
    assert main(["metar", "fetch", str(page)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "oops.txt" in err and "HTML" in err


# --- impossible observation times: kept for their station -----------------------------------

REF = datetime(2025, 7, 26, 16, 0, tzinfo=UTC)
ZURICH = {"LSZH": StationPosition(47.48, 8.53, 424.0), "LSGG": StationPosition(46.24, 6.11, 411.0)}


def _ingest(text: str, fmt: str = "lines", known: Ingested | None = None) -> Ingested:
    feed = parse_feed(text, format=fmt, reference_utc=REF)
    return ingest(feed, None if known is None else known.stations, ZURICH)


def test_minute_60_report_is_used_and_fresh() -> None:
    result = _ingest("LSZH 261560Z 24008KT 9999 OVC010 18/09 Q1016\n")
    zurich = result.stations["LSZH"]
    assert zurich.observed_utc == datetime(2025, 7, 26, 16, 0, tzinfo=UTC)
    assert result.partial == 1 and result.accepted == 1
    choice = select(result.stations, 47.4, 8.5, MetarSettings(), now_utc=REF)
    assert choice.used[0][0] == "LSZH" and choice.patch is not None


def test_day_32_report_is_dated_by_the_feed_where_it_can_be() -> None:
    text = "2025/07/26 15:50\nLSZH 321550Z 24008KT 9999 OVC010 18/09 Q1016\n"
    result = _ingest(text, "tgftp")
    zurich = result.stations["LSZH"]
    assert zurich.observed_utc == datetime(2025, 7, 26, 15, 50, tzinfo=UTC)  # the stamp
    layers = zurich.patch.layers
    assert layers is not None and layers[0].cover_oktas == 8  # the body was decoded
    assert result.problems == (
        "<feed>:2: impossible time group (day 32 is not a day of any month): 'LSZH 321550Z "
        "24008KT 9999 OVC010 18/09 Q1016'",
        "<feed>:2: LSZH: group 2 '321550Z': day 32 is not a day of any month; observation time "
        "unknown; dated by the feed",
    )
    choice = select(result.stations, 47.4, 8.5, MetarSettings(), now_utc=REF)
    assert choice.used[0][0] == "LSZH"


def test_day_32_report_without_a_feed_time_is_kept_but_never_fresh() -> None:
    result = _ingest("LSZH 321550Z 24008KT 9999 OVC010 18/09 Q1016\n")
    assert result.stations["LSZH"].observed_utc is None
    assert result.problems[-1].endswith(
        "observation time unknown; kept without a time, so never fresh"
    )
    for settings in (
        MetarSettings(),
        MetarSettings(age_reference="feed"),
        MetarSettings(station="LSZH"),
    ):
        choice = select(result.stations, 47.4, 8.5, settings, now_utc=REF)
        assert choice.patch is None and choice.stale and choice.stale_stations == ("LSZH",)


def test_report_of_unknown_time_never_replaces_one_of_known_time() -> None:
    good = _ingest("LSZH 261520Z 24008KT 9999 FEW040 18/09 Q1016\n")
    bad = _ingest("LSZH 321550Z 24008KT 9999 OVC010 18/09 Q1016\n", known=good)
    assert bad.stations["LSZH"] == good.stations["LSZH"] and bad.accepted == 1
    # The other way round, the report with a time takes over.
    first = _ingest("LSZH 321550Z 24008KT 9999 OVC010 18/09 Q1016\n")
    second = _ingest("LSZH 261520Z 24008KT 9999 FEW040 18/09 Q1016\n", known=first)
    assert second.stations["LSZH"].observed_utc == datetime(2025, 7, 26, 15, 20, tzinfo=UTC)


def test_age_against_the_feed_skips_reports_of_unknown_time() -> None:
    text = "LSZH 321550Z 24008KT 9999 OVC010 18/09 Q1016\nLSGG 261320Z 24008KT 9999 FEW050 Q1016\n"
    result = _ingest(text)
    choice = select(result.stations, 46.3, 6.2, MetarSettings(age_reference="feed"))
    assert choice.used[0][0] == "LSGG"  # aged against its own report, the newest with a time


def test_text_without_a_time_group_is_no_report_for_station_choice() -> None:
    result = _ingest("LSZH 24008KT 9999 OVC010 18/09 Q1016\nLSGG M01/M01 RMK T10081010\n")
    assert result.stations == {} and len(result.problems) == 4  # the loader's two, ingest's two


# --- a decoder defect is no bad report -------------------------------------------------------


def test_a_decoder_defect_is_kept_apart_from_the_feeds_problems(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def fault(*args: object) -> int:
        raise RuntimeError("injected")

    monkeypatch.setitem(metar_module._MATCH_HANDLERS, "sky", fault)
    text = "LSZH 261550Z 24008KT 9999 OVC010 18/09 Q1016\nLSGG 261550Z 24008KT 9999 NCD Q1016\n"
    result = _ingest(text)
    assert set(result.stations) == {"LSGG"}  # the other report is still used
    assert result.problems == ()
    (defect,) = result.internal_errors
    assert defect.startswith("<feed>:1: METAR decoder defect: the sky handler failed on group 5")


def test_a_decoder_defect_is_logged_as_an_error_by_the_input(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def fault(*args: object) -> int:
        raise RuntimeError("injected")

    monkeypatch.setitem(metar_module._MATCH_HANDLERS, "sky", fault)
    stats = InputStats("test", "metar")
    feed_input = MetarFeedInput(
        _NoSource(), MetarSettings(), stats, lambda patch: None, lambda: (47.4, 8.5), ZURICH
    )
    data = b"LSZH 261550Z 24008KT 9999 OVC010 18/09 Q1016\n"
    with caplog.at_level(logging.ERROR, logger="wxsky.inputs.metar"):
        feed_input._ingest(Fetched(data, REF))
    assert stats.detail["internal_errors"] == 1
    (record,) = [r for r in caplog.records if r.levelno == logging.ERROR]
    assert "a wxsky defect" in record.getMessage() and "sky handler" in record.getMessage()


class _NoSource:
    name = "test"

    async def fetch(self) -> Fetched | None:
        return None

    def close(self) -> None:
        pass


# --- metar decode REPORT -----------------------------------------------------------------------


def _decode_cli(capsys: pytest.CaptureFixture[str], *args: str) -> dict[str, object]:
    assert main(["metar", "decode", *args, "--json"]) == 0
    data: dict[str, object] = json.loads(capsys.readouterr().out)
    return data


def test_cli_decode_without_year_and_month_is_never_in_the_future(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(metar_module, "_utc_now", lambda: datetime(2026, 12, 1, 0, 10, tzinfo=UTC))
    for group, when in (
        ("302350Z", "2026-11-30T23:50:00Z"),
        ("312350Z", "2026-10-31T23:50:00Z"),
        ("012350Z", "2026-11-01T23:50:00Z"),
        ("010005Z", "2026-12-01T00:05:00Z"),
    ):
        assert _decode_cli(capsys, f"KXYZ {group} 27010KT")["time_utc"] == when
    explicit = _decode_cli(capsys, "KXYZ 012350Z 27010KT", "--year", "2026", "--month", "12")
    assert explicit["time_utc"] == "2026-12-01T23:50:00Z"  # as given, even in the future
    month_only = _decode_cli(capsys, "KXYZ 152350Z 27010KT", "--month", "12")
    assert month_only["time_utc"] == "2025-12-15T23:50:00Z"


def test_cli_decode_prints_a_report_with_an_impossible_time(
    capsys: pytest.CaptureFixture[str],
) -> None:
    d = _decode_cli(capsys, "KXYZ 321550Z 27010KT 9999 FEW030 20/10 Q1015")
    assert (d["time_utc"], d["time_group"], d["partial"]) == (None, "321550Z", True)
    assert d["errors"] == [
        "group 2 '321550Z': day 32 is not a day of any month; observation time unknown"
    ]
    assert main(["metar", "decode", "KXYZ 321550Z 27010KT"]) == 0
    text = capsys.readouterr().out
    assert "time n/a" in text and "day 32" in text
    # Text with no time group at all is still refused.
    assert main(["metar", "decode", "KXYZ 27010KT 9999"]) == 2
    assert "no valid observation time" in capsys.readouterr().err


def test_cli_fetch_shows_a_decoder_defect_apart_from_the_problems(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def fault(*args: object) -> int:
        raise RuntimeError("injected")

    monkeypatch.setitem(metar_module._MATCH_HANDLERS, "sky", fault)
    # The feed is still shown, but a wxsky bug is no success.
    assert main(["metar", "fetch", str(CYCLE), "--lat", "40.64", "--lon", "-73.78", "--json"]) == 1
    out, err = capsys.readouterr()
    summary = json.loads(out)
    assert summary["internal_errors"] and not any("defect" in p for p in summary["problems"])
    assert err.count("wxsky: internal error: ") == len(summary["internal_errors"])


# --- reports that say nothing, ok that follows the content, a task that cannot die ----------


def test_a_report_with_nothing_after_its_time_is_a_problem_not_weather() -> None:
    good = _ingest("LSZH 261520Z 24008KT 9999 FEW040 18/09 Q1016\n")
    for cut in ("LSZH 261731Z", "LSZH 261731Z AUTO", "LSZH 261731Z COR=", "LSZH 261731Z NOSIG"):
        later = _ingest(f"{cut}\n", known=good)
        # Counted, not applied: the station keeps its last good report.
        assert later.stations["LSZH"] == good.stations["LSZH"] and later.accepted == 0, cut
        assert later.problems == (
            "<feed>:1: LSZH: nothing after the time group (cut off?); not used",
        ), cut
    garbled = _ingest("LSZH 261731Z 24008K\n", known=good)
    assert garbled.stations["LSZH"] == good.stations["LSZH"] and garbled.accepted == 0
    assert garbled.problems[-1].startswith("<feed>:1: LSZH: no weather after the time group (")
    # One group of weather is a report.
    assert _ingest("LSZH 261731Z 24008KT\n", known=good).stations["LSZH"] != good.stations["LSZH"]


GOOD = b"LSZH 261550Z 24008KT 9999 FEW040 18/09 Q1016\n"
T0 = 1_700_000_000  # feed files dated long ago: nothing is held back as being written


def _put(path: Path, data: bytes, mtime_s: int) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_bytes(data)
    os.utime(tmp, (mtime_s, mtime_s))
    os.replace(tmp, path)


def _file_input(path: Path, applied: list[WeatherPatch], **settings: Any) -> MetarFeedInput:
    # Ages against the feed's own newest report: the 2025 reports stay fresh.
    return MetarFeedInput(
        FileSource(path),
        MetarSettings(age_reference="feed", **settings),
        InputStats(f"metar:{path}", "metar"),
        applied.append,
        lambda: (47.4, 8.5),
        ZURICH,
    )


def _poll(feed_input: MetarFeedInput) -> float:
    wait = asyncio.run(feed_input.poll_once())
    feed_input.reselect()
    return wait


@pytest.mark.parametrize(
    ("bad", "why"),
    [
        (b"<!DOCTYPE html><html><body>502 Bad Gateway</body></html>\n", "HTML page"),
        (b"LSZH 261731Z\n", "LSZH: nothing after the time group"),
        (b"LSZH 261731Z AUTO\n", "LSZH: nothing after the time group"),
        (b"LSZH 261550Z NIL\n", "no usable report in the feed"),
        (gzip.compress(GOOD)[:20], "broken gzip data"),
        (gzip_bomb(MAX_FEED_BYTES + 1), f"{MAX_FEED_BYTES}-byte limit"),
    ],
    ids=["html", "cut-after-time", "auto-only", "nil-only", "broken-gzip", "gzip-bomb"],
)
def test_ok_stays_false_while_the_file_stays_bad(tmp_path: Path, bad: bytes, why: str) -> None:
    path = tmp_path / "metar.txt"
    applied: list[WeatherPatch] = []
    feed_input = _file_input(path, applied)
    stats = feed_input.stats
    _put(path, GOOD, T0)
    _poll(feed_input)
    assert stats.ok and len(applied) == 1
    _put(path, bad, T0 + 60)
    for poll in range(3):  # the first poll reads the bad file, the others find it unchanged
        _poll(feed_input)
        assert not stats.ok, poll
        assert why in stats.last_error and str(path) in stats.last_error
    assert stats.detail["fetches"] == 4
    assert stats.detail["oversize"] == (1 if why.endswith("limit") else 0)
    assert len(applied) == 1 and stats.detail["using"][0]["station"] == "LSZH"  # weather kept
    _put(path, GOOD.replace(b"261550Z", b"261620Z").replace(b"FEW040", b"BKN040"), T0 + 120)
    _poll(feed_input)
    assert stats.ok
    layers = applied[-1].layers
    assert layers is not None and layers[0].cover_oktas == 6


def test_a_missing_file_that_comes_back_unchanged_is_read_again(tmp_path: Path) -> None:
    path = tmp_path / "metar.txt"
    applied: list[WeatherPatch] = []
    feed_input = _file_input(path, applied)
    _put(path, GOOD, T0)
    _poll(feed_input)
    moved = tmp_path / "away.txt"
    path.rename(moved)
    _poll(feed_input)
    assert not feed_input.stats.ok and "no such file" in feed_input.stats.last_error
    moved.rename(path)  # the same inode, size and mtime as before
    _poll(feed_input)
    assert feed_input.stats.ok


def test_a_file_being_written_is_read_again_shortly_not_taken_half(tmp_path: Path) -> None:
    path = tmp_path / "metar.txt"
    applied: list[WeatherPatch] = []
    feed_input = _file_input(path, applied, poll_interval_s=60.0)
    _put(path, GOOD, T0)
    _poll(feed_input)
    # The writer has written the station and time when the poll comes.
    with open(path, "wb") as writer:
        writer.write(b"LSZH 261620Z")
        writer.flush()
        os.utime(path)  # now, in case the file system's clock lags this one
        wait = _poll(feed_input)
        assert wait == SETTLE_S  # soon, not a whole poll interval later
        assert feed_input.stats.detail["held_back"] == 1 and feed_input.stats.ok
        assert feed_input.stats.errors == 0 and len(applied) == 1
        writer.write(b" 24008KT 9999 OVC010 18/09 Q1016\n")
    while len(applied) == 1:  # held back until it stands still, then read whole
        assert feed_input.stats.detail["fetches"] < 100
        wait = _poll(feed_input)
        if len(applied) == 1:
            time.sleep(wait)
    layers = applied[-1].layers
    assert layers is not None and layers[0].cover_oktas == 8 and feed_input.stats.ok
    assert feed_input.stats.errors == 0


class _FailsFirst:
    """A real file source whose first fetches fail as if memory had run out."""

    def __init__(self, path: Path, failures: int) -> None:
        self.inner = FileSource(path)
        self.name = self.inner.name
        self.failures = failures

    async def fetch(self) -> Fetched | None:
        if self.failures:
            self.failures -= 1
            raise MemoryError
        return await self.inner.fetch()

    def forget(self) -> None:
        self.inner.forget()

    def close(self) -> None:
        pass


def _supervise(feed_input: MetarFeedInput, applied: list[WeatherPatch]) -> list[tuple]:
    """Runs the input supervised until it has applied weather; returns what its status said
    at each restart, seen at every step of the loop, so that no restart goes unseen."""
    seen: list[tuple] = []

    async def main() -> None:
        stop = asyncio.Event()
        task = asyncio.create_task(feed_input.run_supervised(stop, first_backoff_s=0.01))
        while not applied:
            d, stats = feed_input.stats.detail, feed_input.stats
            if d["state"] == "restarting" and (not seen or seen[-1][0] != d["restarts"]):
                seen.append((d["restarts"], stats.ok, d["restart_in_s"], stats.last_error))
            assert not task.done()
            await asyncio.sleep(0)
        stop.set()
        await task

    asyncio.run(asyncio.wait_for(main(), timeout=30.0))  # a guard against hanging only
    return seen


def test_a_failing_feed_task_is_restarted_with_back_off(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "metar.txt"
    _put(path, GOOD, T0)
    applied: list[WeatherPatch] = []
    stats = InputStats("metar:test", "metar")
    feed_input = MetarFeedInput(
        _FailsFirst(path, failures=3),
        MetarSettings(age_reference="feed", max_backoff_s=0.02),
        stats,
        applied.append,
        lambda: (47.4, 8.5),
        ZURICH,
    )
    with caplog.at_level(logging.DEBUG, logger="wxsky.inputs.metar"):
        seen = _supervise(feed_input, applied)
    failed = f"{path}: the METAR feed task failed (MemoryError); restarting in"
    assert [(n, ok, wait) for n, ok, wait, _ in seen] == [
        (1, False, 0.01),
        (2, False, 0.02),
        (3, False, 0.02),  # doubled, up to max_backoff_s
    ]
    assert all(error.startswith(failed) for *_, error in seen)
    # The good report read after the restarts, and the status back to normal.
    layers = applied[0].layers
    assert layers is not None and layers[0].cover_oktas == 2
    assert stats.ok and stats.detail["state"] == "running" and stats.detail["restarts"] == 3
    assert "restart_in_s" not in stats.detail
    # One line said so (the rest held back by the rate limit), the traceback only at debug.
    errors = [r for r in caplog.records if r.levelno == logging.ERROR]
    assert [r.getMessage() for r in errors] == [f"{failed} 0.01 s"]
    assert any(r.exc_info and r.levelno == logging.DEBUG for r in caplog.records)


def test_weather_whose_apply_failed_is_applied_after_the_restart(tmp_path: Path) -> None:
    path = tmp_path / "metar.txt"
    _put(path, GOOD, T0)
    applied: list[WeatherPatch] = []
    calls = []

    def apply(patch: WeatherPatch) -> None:
        calls.append(patch)
        if len(calls) == 1:
            raise RuntimeError("engine refused it")
        applied.append(patch)

    stats = InputStats("metar:test", "metar")
    feed_input = MetarFeedInput(
        FileSource(path),
        MetarSettings(age_reference="feed"),
        stats,
        apply,
        lambda: (47.4, 8.5),
        ZURICH,
    )
    seen = _supervise(feed_input, applied)
    assert [(n, ok) for n, ok, *_ in seen] == [(1, False)]
    assert "RuntimeError: engine refused it" in seen[0][3]
    # The same report, read again after the restart although the file did not change.
    assert calls[0] == applied[0] and stats.ok


class _TableFailingOnce(dict[str, StationPosition]):
    """The station table, whose first look-up fails as if memory had run out."""

    failed = False

    def get(self, key: str, default: Any = None) -> Any:
        if not self.failed:
            self.failed = True
            raise MemoryError
        return super().get(key, default)


def test_a_file_whose_ingest_failed_is_read_again_after_the_restart(tmp_path: Path) -> None:
    path = tmp_path / "metar.txt"
    _put(path, GOOD, T0)
    applied: list[WeatherPatch] = []
    stats = InputStats("metar:test", "metar")
    feed_input = MetarFeedInput(
        FileSource(path),
        MetarSettings(age_reference="feed"),
        stats,
        applied.append,
        lambda: (47.4, 8.5),
        _TableFailingOnce(ZURICH),
    )
    seen = _supervise(feed_input, applied)
    # The source had marked the file seen when the ingest failed; unchanged, it is read again.
    assert [(n, ok) for n, ok, *_ in seen] == [(1, False)] and stats.ok
    layers = applied[0].layers
    assert layers is not None and layers[0].cover_oktas == 2


def test_a_feed_line_cut_mid_group_is_not_applied_and_is_warned_about(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Issue 40: `LSZH ... 9999 OVC0` with no newline was applied (as `OVC0` skipped: no
    overcast) once the longest hold ran out, with no warning. Now the line is left out, the
    weather stays what the last whole report said, and one warning names station and file."""
    path = tmp_path / "metar.txt"
    applied: list[WeatherPatch] = []
    feed_input = MetarFeedInput(
        FileSource(path, settle_s=0.01, max_settle_s=0.0),  # held back at most once
        MetarSettings(age_reference="feed"),
        InputStats(f"metar:{path}", "metar"),
        applied.append,
        lambda: (47.4, 8.5),
        ZURICH,
    )
    _put(path, GOOD, T0)
    _poll(feed_input)
    assert len(applied) == 1
    _put(path, b"LSZH 261620Z 24008KT 9999 OVC0", T0 + 60)
    with caplog.at_level(logging.WARNING):
        for _ in range(3):  # held back once, then read: the cut line left out
            _poll(feed_input)
    assert len(applied) == 1, [a.layers for a in applied]
    stats = feed_input.stats
    assert stats.detail["using"][0]["station"] == "LSZH"
    assert not stats.ok
    assert "LSZH: the last line ends mid-group" in stats.last_error
    assert str(path) in stats.last_error
    lines = [r.getMessage() for r in caplog.records if "mid-group" in r.getMessage()]
    assert len(lines) == 1 and "LSZH" in lines[0] and str(path) in lines[0], lines
