"""From feed to one METAR patch: ingest real corpora, pick stations, report problems."""

from __future__ import annotations

import json
import logging
from datetime import UTC, datetime
from pathlib import Path

import pytest

from wxsky.cli import main
from wxsky.inputs.feed_sources import Fetched
from wxsky.inputs.metar_input import Ingested, MetarFeedInput, MetarSettings, ingest, select
from wxsky.inputs.station_table import StationPosition, station_table
from wxsky.inputs.stats import InputStats
from wxsky.weather import metar as metar_module
from wxsky.weather.feeds import parse_feed, read_feed
from wxsky.weather.state import CloudType

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
