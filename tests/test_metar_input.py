"""From feed to one METAR patch: ingest real corpora, pick stations, report problems."""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path

import pytest

from wxsky.cli import main
from wxsky.inputs.metar_input import MetarSettings, ingest, select
from wxsky.inputs.station_table import StationPosition, station_table
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
    assert result.reports == 4336
    # Every row but the three junk rows and the rows without a position gives a station.
    assert 4200 < len(result.stations) <= 4336
    assert any("PART 1 OF 2" in p or "no time" in p or "station" in p for p in result.problems)
    jfk = result.stations["KJFK"]
    assert jfk.observed_utc.year == 2014 and jfk.observed_utc.month == 9


def test_ingest_a_cycle_file_uses_the_station_table_for_positions() -> None:
    feed = read_feed(CYCLE)
    result = ingest(feed)
    assert result.duplicates == 946 and result.reports == 554
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
