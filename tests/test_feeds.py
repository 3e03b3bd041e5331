"""METAR feed loaders: the real corpora (counts, vintages, junk rows), every AWC vintage's quirks
on small synthetic files, tgftp and one-per-line feeds, month rollback, and garbage input that
must come back as FeedProblems or FeedError, never as another exception."""

from __future__ import annotations

import gzip
import json
import os
import random
import re
from datetime import UTC, datetime
from pathlib import Path

import pytest

from wxsky.cli import main
from wxsky.errors import FeedError
from wxsky.weather.feed_formats import MAX_PROBLEMS, clean_raw, month_of_day
from wxsky.weather.feeds import (
    FORMATS,
    Feed,
    FeedProblem,
    Report,
    detect_format,
    parse_feed,
    read_feed,
    read_reports,
)
from wxsky.weather.metar_groups import parse_time

DATA = Path(__file__).resolve().parent / "data" / "metar"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "metar"

CYCLE = "noaa_cycle_2025-07-26_okay_weather_HEAD1500.txt.gz"
AWC_2014 = "awc_cache_2014-09-26_etms-visualization.csv.gz"
AWC_2020 = "awc_cache_2020-05-02_luasamples.csv.gz"
AWC_2022 = "awc_cache_2022-10-23_HackGT-2022.csv.gz"
AWC_2026 = "awc_cache_2026-03-20_meteo473_EXCERPT.csv.gz"

# file: (format, reports, duplicates, (year, month), lines of rows without a time group)
CORPORA = {
    AWC_2014: ("awc-csv", 4336, 0, (2014, 9), {394, 1428, 2131}),
    AWC_2020: ("awc-csv", 4678, 0, (2020, 5), {905}),
    AWC_2022: ("awc-csv", 4911, 0, (2022, 10), {1314}),
    AWC_2026: ("awc-csv", 9, 0, (2026, 3), set()),
    # 1,500 records; 650 distinct lines byte for byte, but 96 of those differ from another only
    # by a trailing space, so 554 distinct reports once whitespace is normalised.
    CYCLE: ("tgftp", 554, 946, (2025, 7), set()),
}
# Reports whose own ddhhmmZ disagrees with AWC's observation_time: the feed's column wins.
CLOCK_DISAGREES = {
    AWC_2014: {"PTSA 252120Z", "PKMJ 262258Z"},
    AWC_2020: {"PTSA 022350Z"},
}

HEADER = (
    "raw_text,station_id,observation_time,latitude,longitude,temp_c,dewpoint_c,wind_dir_degrees,"
    "wind_speed_kt,wind_gust_kt,visibility_statute_mi,altim_in_hg,sea_level_pressure_mb,corrected,"
    "auto,auto_station,maintenance_indicator_on,no_signal,lightning_sensor_off,"
    "freezing_rain_sensor_off,present_weather_sensor_off,wx_string,sky_cover,cloud_base_ft_agl,"
    "sky_cover,cloud_base_ft_agl,sky_cover,cloud_base_ft_agl,sky_cover,cloud_base_ft_agl,"
    "flight_category,three_hr_pressure_tendency_mb,maxT_c,minT_c,maxT24hr_c,minT24hr_c,precip_in,"
    "pcp3hr_in,pcp6hr_in,pcp24hr_in,snow_in,vert_vis_ft,metar_type,elevation_m"
)
PREAMBLE = "No errors\nNo warnings\n171 ms\ndata source=metars\n3 results\n"
# Rows copied from the 2014 and 2026 corpora (the formats' reference samples).
ROW_KBDN = (
    "KBDN 262135Z AUTO 36007KT 10SM CLR 16/03 A3008 RMK AO2,KBDN,2014-09-26T21:35:00Z,44.1,-121.2,"
    "16.0,3.0,360,7,,10.0,30.079725,,,TRUE,TRUE,,,,,,,CLR,,,,,,,,VFR,,,,,,,,,,,,SPECI,1055.0"
)
ROW_KSTF = (
    "KSTF 261135Z AUTO 00000KT 1/2SM FG VV005 10/10 A3011 RMK AO2 VIS M1/4V3,KSTF,"
    "2014-09-26T11:35:00Z,33.43,-88.85,10.0,10.0,0,0,,0.5,30.109253,,,TRUE,TRUE,,,,,,FG,OVX,0,"
    ",,,,,,LIFR,,,,,,,,,,,500,METAR,99.0"
)
ROW_CWND = (
    "CWND M01/M01 RMK T10081010,CWND,2014-09-26T00:34:00Z,69.63,-135.43" + "," * 38 + "METAR,12.0"
)
ROW_CYBW = (
    '"SPECI CYBW 201519Z AUTO 15006KT 1SM R35/2800V4000FT/ -RA BR VV002 00/00 A2978 RMK VIS VRB '
    '1/4-2 1/2 ICE PAST HR PRESFR SLP131",CYBW,2026-03-20T15:19:00.000Z,51.1080,-114.3820,0,0,150,'
    "6,,1,29.78,1013.1,,TRUE,,,,,,,-RA BR,OVX,200,,,,,,,LIFR,,,,,,,,,,,2,SPECI,1197"
)
SMALL_CSV = f"{PREAMBLE}{HEADER}\n{ROW_KBDN}\n{ROW_KSTF}\n{ROW_CWND}\n"


def _corpus(name: str) -> Feed:
    return read_feed(DATA / name)


def _tokens_time(raw: str) -> tuple[int, int, int] | None:
    """The report's own time group, found without the loader's header logic."""
    group = next((t for t in raw.split()[:4] if re.fullmatch(r"[0-9]{6}Z?", t)), None)
    return parse_time(group) if group else None


# --- real corpora ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(CORPORA))
def test_corpus_counts_and_vintage(name: str) -> None:
    fmt, count, duplicates, vintage, junk_lines = CORPORA[name]
    feed = _corpus(name)
    assert (feed.format, len(feed.reports), feed.duplicates) == (fmt, count, duplicates)
    assert all(r.raw and r.raw == " ".join(r.raw.split()) for r in feed.reports)
    assert {(r.year, r.month) for r in feed.reports} == {vintage}
    assert all(r.station for r in feed.reports)
    # The junk rows are exactly the problems, and each is still handed on as a report.
    problem_lines = {int(p.where.rsplit(":", 1)[1]) for p in feed.problems}
    assert problem_lines == junk_lines
    assert all("no ddhhmmZ time group" in p.reason for p in feed.problems)
    by_line = {int(r.where.rsplit(":", 1)[1]): r for r in feed.reports}
    assert junk_lines <= by_line.keys()
    # Every report is dated; where the report has a time group it agrees with observed_utc,
    # except the few stations whose own clock is wrong (AWC's column is right there).
    assert all(r.observed_utc is not None for r in feed.reports)
    disagree = set()
    for line, r in by_line.items():
        assert r.observed_utc is not None and r.observed_utc.tzinfo == UTC
        observed = (r.observed_utc.day, r.observed_utc.hour, r.observed_utc.minute)
        if line not in junk_lines and _tokens_time(r.raw) != observed:
            disagree.add(" ".join(r.raw.split()[:2]))
    assert disagree == CLOCK_DISAGREES.get(name, set())


@pytest.mark.parametrize("name", sorted(CORPORA))
def test_decode_file_emits_every_report_of_the_feed(
    name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    # The reports are counted here from the file's own structure, not by the loader: a CSV row
    # is a line after the header; a tgftp record is a timestamp line and the line after it, and
    # records whose text repeats an earlier one (whitespace aside) are one report.
    lines = gzip.decompress((DATA / name).read_bytes()).decode().replace("\r", "").split("\n")
    fmt, count, duplicates = CORPORA[name][:3]
    if fmt == "awc-csv":
        header = next(i for i, line in enumerate(lines) if line.startswith("raw_text,"))
        texts = None
        expected = sum(1 for line in lines[header + 1 :] if line.strip())
    else:
        stamp = re.compile(r"[0-9]{4}/[0-9]{2}/[0-9]{2} [0-9]{2}:[0-9]{2}")
        records = [lines[i + 1] for i, line in enumerate(lines[:-1]) if stamp.fullmatch(line)]
        texts = {" ".join(record.split()) for record in records}
        expected = len(texts)
        assert len(records) - expected == duplicates
    assert expected == count
    assert main(["metar", "decode", "--file", str(DATA / name)]) == 0
    decoded = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(decoded) == expected
    assert len({d["where"] for d in decoded}) == expected  # each once
    if texts is not None:
        assert {d["raw"] for d in decoded} == texts


def test_decode_file_keeps_reports_with_impossible_times(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "cycle.txt"
    path.write_text(
        "2025/07/26 15:60\nKAAA 261600Z 27010KT 10SM CLR 20/10 A3000\n\n"
        "2025/07/26 16:00\nKBBB 261560Z 27010KT 10SM CLR 20/10 A3000\n\n"
        "2025/07/26 16:00\nKCCC 321600Z 27010KT 10SM CLR 20/10 A3000\n\n"
        "2025/07/32 16:00\nKDDD 262400Z 27010KT 10SM CLR 20/10 A3000\n\n"
        "KEEE 261600Z 27010KT 10SM CLR 20/10 A3000\n"
    )
    assert main(["metar", "decode", "--file", str(path)]) == 0
    out, err = capsys.readouterr()
    decoded = {d["station"]: d for d in map(json.loads, out.splitlines())}
    assert list(decoded) == ["KAAA", "KBBB", "KCCC", "KDDD", "KEEE"]
    assert not decoded["KAAA"]["partial"] and decoded["KAAA"]["time_utc"] == "2025-07-26T16:00:00Z"
    assert decoded["KBBB"]["time_utc"] == "2025-07-26T16:00:00Z" and decoded["KBBB"]["partial"]
    assert decoded["KBBB"]["errors"] == ["group 2 '261560Z': 15:60 read as 2025-07-26 16:00Z"]
    assert decoded["KCCC"]["time_utc"] is None and decoded["KCCC"]["time_group"] == "321600Z"
    assert decoded["KCCC"]["wind"]["speed_kt"] == 10.0  # decoded as far as it goes
    assert decoded["KDDD"]["time_utc"] == "2025-07-27T00:00:00Z"
    assert decoded["KEEE"]["time_utc"] == "2025-07-26T16:00:00Z" and not decoded["KEEE"]["partial"]
    assert "15:60" in err and "2025/07/32" in err and "without a timestamp line" in err


@pytest.mark.parametrize("name", sorted(CORPORA))
def test_corpus_format_detected(name: str) -> None:
    text = gzip.decompress((DATA / name).read_bytes()).decode()
    assert detect_format(text) == CORPORA[name][0]


def test_corpus_fixtures_match_shared_files() -> None:
    if not SHARED.is_dir():
        pytest.skip(f"shared corpora not present at {SHARED}")
    for name in CORPORA:
        shared = SHARED / name.removesuffix(".gz")
        assert gzip.decompress((DATA / name).read_bytes()) == shared.read_bytes(), name


def test_corpus_2014_legacy_row_values() -> None:
    first = _corpus(AWC_2014).reports[0]
    assert first.raw == "KBDN 262135Z AUTO 36007KT 10SM CLR 16/03 A3008 RMK AO2"
    assert first.station == "KBDN" and first.kind == "SPECI"  # from metar_type: no prefix
    assert first.observed_utc == datetime(2014, 9, 26, 21, 35, tzinfo=UTC)
    assert (first.lat_deg, first.lon_deg, first.elevation_m) == (44.1, -121.2, 1055.0)
    assert first.where.endswith(f"{AWC_2014}:7")  # 5-line preamble + header
    assert first.awc is not None
    assert first.awc["altim_in_hg"] == "30.079725" and first.awc["sky"] == [("CLR", None)]
    assert first.awc["wind_gust_kt"] is None


def test_corpus_2014_junk_rows_kept_as_reports() -> None:
    feed = _corpus(AWC_2014)
    junk = {r.raw: r for r in feed.reports if r.where.endswith((":394", ":1428", ":2131"))}
    assert set(junk) == {
        "UTO8 M M M 205/06/-05/2817/M/ PK WND 2825 2009Z 3001 80MM",
        "PART 1 OF 2",
        "META CHECK TEXT NEW ENDING ADDED VABBYFYX",
    }
    part = junk["PART 1 OF 2"]
    assert part.station == "PART" and part.lat_deg is None  # the feed's columns, as given
    assert part.observed_utc == datetime(2014, 9, 26, 21, 10, tzinfo=UTC)


def test_corpus_2022_crcrlf_line_numbers() -> None:
    feed = _corpus(AWC_2022)
    assert feed.reports[0].where.endswith(":2") and feed.reports[1].where.endswith(":3")
    assert all("\r" not in r.raw for r in feed.reports)


def test_corpus_2026_current_layout() -> None:
    reports = {r.station: r for r in _corpus(AWC_2026).reports}
    cybw = reports["CYBW"]
    assert cybw.raw.startswith("SPECI CYBW 201519Z AUTO 15006KT 1SM") and cybw.kind == "SPECI"
    assert cybw.observed_utc == datetime(2026, 3, 20, 15, 19, tzinfo=UTC)
    assert (cybw.lat_deg, cybw.lon_deg, cybw.elevation_m) == (51.108, -114.382, 1197.0)
    assert cybw.awc is not None
    assert cybw.awc["sky"] == [("OVX", "200")] and cybw.awc["vert_vis_ft"] == "2"
    assert cybw.awc["wx_string"] == "-RA BR" and cybw.awc["visibility_statute_mi"] == "1"
    assert reports["KDTA"].awc is not None and reports["KDTA"].awc["visibility_statute_mi"] == "10+"
    assert reports["KAXS"].awc is not None and reports["KAXS"].awc["flight_category"] == "null"


def test_corpus_cycle_dedupes_on_normalised_text() -> None:
    feed = _corpus(CYCLE)
    text = gzip.decompress((DATA / CYCLE).read_bytes()).decode()
    lines = text.split("\n")
    records = [lines[i + 1] for i, line in enumerate(lines) if line.startswith("2025/07/26 ")]
    assert len(records) == 1500 and len(set(records)) == 650
    assert len(feed.reports) + feed.duplicates == 1500
    assert [r.raw for r in feed.reports] == list(
        dict.fromkeys(" ".join(r.split()) for r in records)
    )
    first = feed.reports[0]
    assert first.raw == "KTGI 261555Z AUTO 10SM CLR 31/24 A3007 RMK AO1 T03090244"
    assert first.observed_utc == datetime(2025, 7, 26, 15, 55, tzinfo=UTC)
    assert first.where.endswith(":2") and first.kind is None and first.awc is None
    haab = next(r for r in feed.reports if r.station == "HAAB")  # time group without its Z
    assert haab.observed_utc == datetime(2025, 7, 26, 16, 0, tzinfo=UTC)


def test_read_reports_iterates_the_feed() -> None:
    reports = list(read_reports(DATA / AWC_2026))
    assert [r.station for r in reports][:3] == ["KDTA", "SKEJ", "EVGA"]
    assert all(isinstance(r, Report) for r in reports)


# --- AWC CSV variants -----------------------------------------------------------------------------


def test_csv_preamble_or_not_gives_the_same_reports() -> None:
    with_preamble = parse_feed(SMALL_CSV)
    without = parse_feed(SMALL_CSV.removeprefix(PREAMBLE))
    assert with_preamble.format == without.format == "awc-csv"
    assert [r.raw for r in with_preamble.reports] == [r.raw for r in without.reports]
    assert [r.where for r in with_preamble.reports] == ["<feed>:7", "<feed>:8", "<feed>:9"]
    assert [r.where for r in without.reports] == ["<feed>:2", "<feed>:3", "<feed>:4"]
    with_bom = parse_feed(("\ufeff" + SMALL_CSV).encode())
    assert [r.raw for r in with_bom.reports] == [r.raw for r in without.reports]


def test_csv_values_by_position() -> None:
    kstf = parse_feed(SMALL_CSV).reports[1]
    assert kstf.station == "KSTF" and kstf.kind == "METAR"
    assert kstf.observed_utc == datetime(2014, 9, 26, 11, 35, tzinfo=UTC)
    assert kstf.awc is not None
    # The four sky pairs share names in the header; position says which is which.
    assert kstf.awc["sky"] == [("OVX", "0")] and kstf.awc["vert_vis_ft"] == "500"
    assert kstf.awc["visibility_statute_mi"] == "0.5" and kstf.awc["wx_string"] == "FG"
    assert kstf.awc["metar_type"] == "METAR" and kstf.awc["flight_category"] == "LIFR"


def test_csv_row_without_time_group_is_kept_with_a_problem() -> None:
    feed = parse_feed(SMALL_CSV, name="cache.csv")
    cwnd = feed.reports[2]
    assert cwnd.raw == "CWND M01/M01 RMK T10081010" and cwnd.station == "CWND"
    assert cwnd.observed_utc == datetime(2014, 9, 26, 0, 34, tzinfo=UTC)  # the feed's column
    assert [(p.where, "no ddhhmmZ" in p.reason) for p in feed.problems] == [("cache.csv:9", True)]


def test_csv_quoted_with_prefix_and_crcrlf() -> None:
    text = f"{HEADER}\r\r\n{ROW_CYBW}\r\r\n{ROW_KBDN}\r\r\n"
    feed = parse_feed(text.encode())
    assert feed.problems == ()
    cybw, kbdn = feed.reports
    assert cybw.raw.startswith("SPECI CYBW 201519Z") and '"' not in cybw.raw
    assert cybw.station == "CYBW" and cybw.kind == "SPECI"
    assert cybw.where == "<feed>:2" and kbdn.where == "<feed>:3"
    assert kbdn.raw.startswith("KBDN 262135Z")


def test_csv_missing_observation_time_uses_the_files_month() -> None:
    row = ROW_KBDN.replace("2014-09-26T21:35:00Z", "")
    feed = parse_feed(
        f"{HEADER}\n{ROW_KSTF}\n{row}\n", reference_utc=datetime(2030, 1, 1, tzinfo=UTC)
    )
    undated = feed.reports[1]
    assert (undated.year, undated.month) == (2014, 9)
    assert undated.observed_utc == datetime(2014, 9, 26, 21, 35, tzinfo=UTC)


def test_csv_column_count_off_is_a_problem() -> None:
    feed = parse_feed(f"{HEADER}\n{ROW_KBDN},extra\nKXYZ 261200Z 00000KT,KXYZ\n")
    assert len(feed.reports) == 2
    assert [p.reason for p in feed.problems] == [
        "45 columns, expected 44",
        "2 columns, expected 44",
    ]
    short = feed.reports[1]
    assert short.station == "KXYZ" and short.lat_deg is None and short.awc is not None
    assert short.awc["temp_c"] is None and short.awc["sky"] == []
    # Undated by the feed: the report's day in the month of the file's other rows.
    assert short.observed_utc == datetime(2014, 9, 26, 12, 0, tzinfo=UTC)


def test_csv_truncated_anywhere_never_raises() -> None:
    data = SMALL_CSV.encode()
    full = parse_feed(data)
    for cut in range(0, len(data), 50):
        try:
            feed = parse_feed(data[:cut], format="awc-csv")
        except FeedError:  # pragma: no cover - forced format never raises on content
            pytest.fail(f"FeedError at cut {cut}")
        assert len(feed.reports) <= len(full.reports)
        assert all(r.raw for r in feed.reports)
        if cut and not data[:cut].endswith(b"\n") and feed.reports:
            assert feed.problems  # the cut row has too few columns (or no time group)
    with pytest.raises(FeedError):
        parse_feed(data[:0])


# --- AWC XML --------------------------------------------------------------------------------------

XML = """<?xml version="1.0" encoding="UTF-8"?>
<response xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" version="1.2"
          xsi:noNamespaceSchemaLocation="http://aviationweather.gov/adds/schema/metar1_2.xsd">
  <request_index>71</request_index>
  <data_source name="metars" />
  <errors />
  <warnings />
  <time_taken_ms>5</time_taken_ms>
  <data num_results="2">
    <METAR>
      <raw_text>KDEN 261553Z 17010KT 10SM FEW080 SCT150 18/06 A3024</raw_text>
      <station_id>KDEN</station_id>
      <observation_time>2019-04-26T15:53:00Z</observation_time>
      <latitude>39.85</latitude>
      <longitude>-104.65</longitude>
      <temp_c>18.0</temp_c>
      <wind_speed_kt>10</wind_speed_kt>
      <quality_control_flags><auto_station>TRUE</auto_station></quality_control_flags>
      <sky_condition sky_cover="FEW" cloud_base_ft_agl="8000" />
      <sky_condition sky_cover="SCT" cloud_base_ft_agl="15000" />
      <flight_category>VFR</flight_category>
      <metar_type>METAR</metar_type>
      <elevation_m>1640.0</elevation_m>
    </METAR>
    <METAR>
      <raw_text>SPECI KBOS 261554Z 27008KT 10SM CLR 12/M01 A3010</raw_text>
      <station_id>KBOS</station_id>
      <observation_time>2019-04-26T15:54:00.000Z</observation_time>
      <sky_condition sky_cover="CLR" />
    </METAR>
  </data>
</response>
"""


def test_xml_reports() -> None:
    feed = parse_feed(XML.encode(), name="metars.xml")
    assert (feed.format, feed.problems) == ("awc-xml", ())
    den, bos = feed.reports
    assert den.raw == "KDEN 261553Z 17010KT 10SM FEW080 SCT150 18/06 A3024"
    assert den.station == "KDEN" and den.kind == "METAR" and den.where == "metars.xml:11"
    assert den.observed_utc == datetime(2019, 4, 26, 15, 53, tzinfo=UTC)
    assert (den.year, den.month, den.lat_deg, den.lon_deg, den.elevation_m) == (
        2019,
        4,
        39.85,
        -104.65,
        1640.0,
    )
    assert den.awc is not None
    assert den.awc["sky"] == [("FEW", "8000"), ("SCT", "15000")]
    assert den.awc["temp_c"] == "18.0" and den.awc["wind_speed_kt"] == "10"
    assert den.awc["dewpoint_c"] is None and den.awc["flight_category"] == "VFR"
    assert bos.kind == "SPECI" and bos.raw.startswith("SPECI KBOS")
    assert bos.observed_utc == datetime(2019, 4, 26, 15, 54, tzinfo=UTC)
    assert bos.awc is not None and bos.awc["sky"] == [("CLR", None)] and bos.lat_deg is None


def test_xml_truncated_keeps_complete_reports() -> None:
    cut = XML.index("<METAR>", XML.index("</METAR>")) + 30
    feed = parse_feed(XML[:cut].encode(), name="x")
    assert [r.station for r in feed.reports] == ["KDEN"]
    assert len(feed.problems) == 1 and "XML breaks off" in feed.problems[0].reason
    assert feed.problems[0].where.startswith("x:")
    for cut in range(0, len(XML), 23):
        feed = parse_feed(XML[:cut], format="awc-xml")
        assert len(feed.reports) <= 2


def test_xml_mangled_element_loses_only_itself() -> None:
    mangled = XML.replace("<latitude>39.85</latitude>", "<latitude>39.85</lat>")
    feed = parse_feed(mangled)
    assert [r.station for r in feed.reports] == ["KBOS"]
    assert feed.reports[0].where == "<feed>:26"
    assert len(feed.problems) == 1 and "1 after" in feed.problems[0].reason


def test_xml_error_response_is_a_problem() -> None:
    text = '<?xml version="1.0"?>\n<response><errors><error>Invalid station</error></errors>\n'
    feed = parse_feed(text + '<data num_results="0" /></response>\n')
    assert feed.reports == ()
    assert [p.reason for p in feed.problems] == ["the feed reports an error: Invalid station"]


# --- NOAA tgftp -----------------------------------------------------------------------------------


def test_tgftp_station_file() -> None:
    text = "2025/07/26 15:55\nKTGI 261555Z AUTO 10SM CLR 31/24 A3007 RMK AO1 T03090244\n"
    feed = parse_feed(text.encode(), name="KTGI.TXT")
    assert (feed.format, feed.problems, feed.duplicates) == ("tgftp", (), 0)
    (r,) = feed.reports
    assert r.station == "KTGI" and r.where == "KTGI.TXT:2" and (r.year, r.month) == (2025, 7)
    assert r.observed_utc == datetime(2025, 7, 26, 15, 55, tzinfo=UTC)


def test_tgftp_cycle_duplicates_and_trailing_spaces() -> None:
    a = "KOUN 261545Z 18013KT 10SM SCT120 32/19 A2997"
    b = "KHUM 261547Z 19005KT 7SM SCT031 30/27 A3011"
    records = [a, a + " ", b, a, b + "  "]
    text = "".join(f"2025/07/26 15:5{i}\n{raw}\n\n" for i, raw in enumerate(records))
    feed = parse_feed(text)
    assert [r.raw for r in feed.reports] == [a, b] and feed.duplicates == 3
    assert [r.where for r in feed.reports] == ["<feed>:2", "<feed>:8"]


@pytest.mark.parametrize(
    ("stamp", "report_day", "expected"),
    [
        ("2025/08/01 00:05", "31", datetime(2025, 7, 31, 23, 55, tzinfo=UTC)),
        ("2025/01/01 00:05", "31", datetime(2024, 12, 31, 23, 55, tzinfo=UTC)),
        ("2024/03/01 00:02", "29", datetime(2024, 2, 29, 23, 55, tzinfo=UTC)),
        ("2025/07/26 16:00", "26", datetime(2025, 7, 26, 23, 55, tzinfo=UTC)),
    ],
)
def test_tgftp_month_rollback(stamp: str, report_day: str, expected: datetime) -> None:
    feed = parse_feed(f"{stamp}\nKXYZ {report_day}2355Z 00000KT 10SM CLR 20/10 A3000\n")
    (r,) = feed.reports
    assert r.observed_utc == expected and (r.year, r.month) == (expected.year, expected.month)


def test_tgftp_broken_records() -> None:
    text = (
        "KSTRAY 261555Z no timestamp before me\n"
        "2025/07/26 15:55\n"
        "2025/07/26 15:56\n"
        "KTGI 261556Z AUTO 10SM CLR 31/24 A3007\n"
        "2025/13/40 15:55\n"
        "KBAD 261555Z AUTO 10SM CLR 31/24 A3007\n"
        "2025/07/26 15:57\n"
        "NOTIME AT ALL\n"
        "2025/07/26 15:58\n"
    )
    feed = parse_feed(text, format="tgftp", name="c")
    # No report line is lost: without a timestamp line, or after an impossible one, it is dated
    # against the file's good timestamps.
    assert [(r.station, r.where) for r in feed.reports] == [
        (None, "c:1"),
        ("KTGI", "c:4"),
        ("KBAD", "c:6"),
        (None, "c:8"),
    ]
    stray, _, kbad, notime = feed.reports
    assert stray.observed_utc is None and (stray.year, stray.month) == (2025, 7)
    assert kbad.observed_utc == datetime(2025, 7, 26, 15, 55, tzinfo=UTC)  # its own time group
    # A report without a time group is dated by the timestamp line.
    assert notime.observed_utc == datetime(2025, 7, 26, 15, 57, tzinfo=UTC)
    assert [p.where for p in feed.problems] == ["c:1", "c:1", "c:2", "c:5", "c:8", "c:9"]
    assert feed.problems[3].reason == (
        "impossible timestamp '2025/13/40 15:55'; its report is dated by the file"
    )


def test_tgftp_timestamp_hour_24_and_minute_60_roll_over() -> None:
    text = (
        "2025/07/26 15:60\nKXYZ 261600Z 00000KT 10SM CLR 20/10 A3000\n\n"
        "2025/07/31 24:00\nKABC 010000Z 00000KT 10SM CLR 20/10 A3000\n\n"
        "2025/07/26 23:60\nKDEF 00000KT 10SM CLR\n\n"
    )
    feed = parse_feed(text, name="t")
    assert feed.format == "tgftp" and len(feed.reports) == 3
    kxyz, kabc, kdef = feed.reports
    assert kxyz.observed_utc == datetime(2025, 7, 26, 16, 0, tzinfo=UTC)
    # The stamp is 1 August 00:00, so the report's day 1 is August's.
    assert kabc.observed_utc == datetime(2025, 8, 1, 0, 0, tzinfo=UTC)
    assert (kabc.year, kabc.month) == (2025, 8)
    assert kdef.observed_utc == datetime(2025, 7, 27, 0, 0, tzinfo=UTC)  # the stamp's time
    assert [(p.where, p.reason) for p in feed.problems] == [
        ("t:1", "timestamp '2025/07/26 15:60' read as 2025/07/26 16:00"),
        ("t:4", "timestamp '2025/07/31 24:00' read as 2025/08/01 00:00"),
        ("t:7", "timestamp '2025/07/26 23:60' read as 2025/07/27 00:00"),
        ("t:8", "no ddhhmmZ time group: 'KDEF 00000KT 10SM CLR'"),
    ]


@pytest.mark.parametrize(
    "stamp",
    [
        "2025/07/26 15:61",
        "2025/07/26 25:00",
        "2025/07/32 10:00",
        "2025/02/29 10:00",
        "2025/00/10 10:00",
        "0000/01/01 00:00",
        "9999/12/31 24:00",
        "9999/99/99 99:99",
    ],
)
def test_tgftp_impossible_timestamp_keeps_its_report(stamp: str) -> None:
    text = (
        "2025/07/26 15:50\nKAAA 261550Z 00000KT 10SM CLR 20/10 A3000\n\n"
        f"{stamp}\nKBBB 261555Z 00000KT 10SM CLR 20/10 A3000\n\n"
        f"{stamp}\nKCCC 00000KT 10SM CLR 20/10 A3000\n"
    )
    feed = parse_feed(text, format="tgftp", name="t")
    assert [r.station for r in feed.reports] == ["KAAA", "KBBB", "KCCC"]
    kbbb, kccc = feed.reports[1:]
    assert kbbb.observed_utc == datetime(2025, 7, 26, 15, 55, tzinfo=UTC)  # dated by the file
    assert kccc.observed_utc is None and (kccc.year, kccc.month) == (2025, 7)
    assert [p.where for p in feed.problems] == ["t:4", "t:7", "t:8"]
    assert feed.problems[0].reason.startswith(f"impossible timestamp {stamp!r}")


def _tgftp_report_lines(text: str) -> list[str]:
    """What a tgftp file's reports must be, found without the loader's record logic: every
    line that is not a timestamp line, its text cleaned as every loader does, repeats dropped."""
    stamp = re.compile(r"[0-9]{4}/[0-9]{2}/[0-9]{2} [0-9]{2}:[0-9]{2}")
    cleaned = (clean_raw(line) for line in text.split("\n") if not stamp.fullmatch(line.strip()))
    return list(dict.fromkeys(raw for raw in cleaned if raw))


TGFTP_SAMPLE = (
    "2025/07/26 15:55\nKTGI 261555Z AUTO 10SM CLR 31/24 A3007 RMK AO1 T03090244\n\n"
    "2025/07/26 15:60\nKXYZ 261560Z 27010KT 10SM CLR 20/10 A3000\n\n"
    "2025/07/32 15:55\nKBAD 321555Z 27010KT 10SM CLR 20/10 A3000\n\n"
    "2025/07/26 24:00\nKDAY 262400Z 27010KT 10SM CLR 20/10 A3000\n\n"
    "KNOSTAMP 261555Z 27010KT\n"
    "2025/07/26 16:35\nEGLL 261635Z 24010KT 9999 FEW030 20/10 Q1015\n\n"
)


def test_tgftp_truncated_anywhere_loses_no_report_line() -> None:
    for cut in range(len(TGFTP_SAMPLE) + 1):
        text = TGFTP_SAMPLE[:cut]
        feed = parse_feed(text, format="tgftp")
        assert [r.raw for r in feed.reports] == _tgftp_report_lines(text), cut


def test_tgftp_garbled_loses_no_report_line() -> None:
    rng = random.Random(2612)
    alphabet = "0123456789/: \nKZ"
    for _ in range(2000):
        chars = list(TGFTP_SAMPLE)
        for _ in range(rng.randint(1, 6)):
            pos = rng.randrange(len(chars))
            if rng.random() < 0.5:
                chars[pos] = rng.choice(alphabet)
            else:
                chars.insert(pos, rng.choice(alphabet))
        text = "".join(chars)
        feed = parse_feed(text, format="tgftp")
        assert [r.raw for r in feed.reports] == _tgftp_report_lines(text), text


# --- one report per line (VATSIM text) ------------------------------------------------------------


def test_lines_vatsim_text() -> None:
    text = (
        "EGLL 010000Z AUTO 23008KT 9999 NCD 18/13 Q1018\n"
        "\n"
        "METAR LFPG 312330Z 23008KT CAVOK 18/13 Q1018=\n"
        "SPECI KJFK 010010Z 36010KT 10SM FEW250 20/10 A3000 =\n"
    )
    feed = parse_feed(
        text.encode(), name="vatsim", reference_utc=datetime(2025, 8, 1, 0, 20, tzinfo=UTC)
    )
    assert (feed.format, feed.problems) == ("lines", ())
    egll, lfpg, kjfk = feed.reports
    assert egll.observed_utc == datetime(2025, 8, 1, 0, 0, tzinfo=UTC) and egll.kind is None
    assert lfpg.raw == "METAR LFPG 312330Z 23008KT CAVOK 18/13 Q1018" and lfpg.kind == "METAR"
    assert lfpg.observed_utc == datetime(2025, 7, 31, 23, 30, tzinfo=UTC)  # the day before
    assert (lfpg.year, lfpg.month, lfpg.where) == (2025, 7, "vatsim:3")
    assert kjfk.raw.endswith("A3000") and kjfk.kind == "SPECI" and kjfk.station == "KJFK"


def test_lines_without_reference_use_the_current_month() -> None:
    before = datetime.now(UTC)
    (r,) = parse_feed("EGLL 010000Z AUTO 23008KT 9999 NCD 18/13 Q1018\n").reports
    after = datetime.now(UTC)
    assert (r.year, r.month) in {(before.year, before.month), (after.year, after.month)}


def test_lines_bad_lines_are_problems() -> None:
    text = "EGLL 23008KT 9999\nhello there\nEGLL 320000Z 23008KT\nKXYZ 311200Z 00000KT\n"
    feed = parse_feed(text, format="lines", reference_utc=datetime(2025, 7, 1, tzinfo=UTC))
    assert [r.station for r in feed.reports] == ["EGLL", "EGLL", "KXYZ"]
    # No 30 June 31: day 31 on 1 July is May's.
    assert [r.observed_utc for r in feed.reports] == [
        None,
        None,
        datetime(2025, 5, 31, 12, 0, tzinfo=UTC),
    ]
    assert (feed.reports[2].year, feed.reports[2].month) == (2025, 5)
    assert [p.where for p in feed.problems] == ["<feed>:1", "<feed>:2", "<feed>:3"]
    assert feed.problems[2].reason == (
        "impossible time group (day 32 is not a day of any month): 'EGLL 320000Z 23008KT'"
    )


@pytest.mark.parametrize(
    ("line", "observed", "problem"),
    [
        ("KXYZ 261560Z 00000KT", datetime(2025, 7, 26, 16, 0, tzinfo=UTC), None),
        ("KXYZ 262400Z 00000KT", datetime(2025, 7, 27, 0, 0, tzinfo=UTC), None),
        ("KXYZ 262500Z 00000KT", None, "25:00 is not a UTC time"),
        ("KXYZ 261575Z 00000KT", None, "15:75 is not a UTC time"),
        ("KXYZ 001200Z 00000KT", None, "day 00 is not a day of any month"),
        ("KXYZ 991200Z 00000KT", None, "day 99 is not a day of any month"),
    ],
)
def test_lines_out_of_range_times(
    line: str, observed: datetime | None, problem: str | None
) -> None:
    feed = parse_feed(line, format="lines", reference_utc=datetime(2025, 7, 28, tzinfo=UTC))
    (r,) = feed.reports
    assert r.raw == line and r.observed_utc == observed and (r.year, r.month) == (2025, 7)
    assert [p.reason for p in feed.problems] == (
        [] if problem is None else [f"impossible time group ({problem}): {line!r}"]
    )


@pytest.mark.parametrize(
    ("reference", "day", "expected"),
    [
        (datetime(2026, 12, 1, tzinfo=UTC), 1, (2026, 12)),
        (datetime(2026, 12, 1, tzinfo=UTC), 30, (2026, 11)),
        (datetime(2026, 12, 1, tzinfo=UTC), 31, (2026, 10)),  # November has no 31st
        (datetime(2026, 3, 1, tzinfo=UTC), 29, (2026, 1)),
        (datetime(2028, 3, 1, tzinfo=UTC), 29, (2028, 2)),
        (datetime(2026, 3, 1, tzinfo=UTC), 31, (2026, 1)),
        (datetime(2027, 1, 15, tzinfo=UTC), 20, (2026, 12)),
        (datetime(2026, 7, 26, 0, 1, tzinfo=UTC), 26, (2026, 7)),  # later that day: same month
    ],
)
def test_month_of_day(reference: datetime, day: int, expected: tuple[int, int]) -> None:
    assert month_of_day(reference, day) == expected


def test_csv_impossible_time_group() -> None:
    dated = ROW_KBDN.replace("KBDN 262135Z", "KBDN 322135Z")
    undated = ROW_KSTF.replace("KSTF 261135Z", "KSTF 261175Z").replace("2014-09-26T11:35:00Z", "")
    feed = parse_feed(f"{HEADER}\n{dated}\n{undated}\n", name="c")
    kbdn, kstf = feed.reports
    assert kbdn.observed_utc == datetime(2014, 9, 26, 21, 35, tzinfo=UTC)  # AWC's column
    assert kstf.observed_utc is None and (kstf.year, kstf.month) == (2014, 9)
    assert [(p.where, p.reason) for p in feed.problems] == [
        ("c:3", f"impossible time group (11:75 is not a UTC time): {kstf.raw[:60]!r}")
    ]


# --- files, gzip, detection, garbage --------------------------------------------------------------

LINES = "EGLL 010000Z AUTO 23008KT 9999 NCD 18/13 Q1018\nLFPG 292330Z 23008KT CAVOK 18/13 Q1018\n"
MTIME = datetime(2024, 3, 1, 0, 30, tzinfo=UTC)


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    os.utime(path, (MTIME.timestamp(), MTIME.timestamp()))
    return path


@pytest.mark.parametrize("filename", ["metar.txt", "metar.txt.gz", "metar.dat"])
def test_files_gzip_by_magic_and_mtime_as_reference(tmp_path: Path, filename: str) -> None:
    data = LINES.encode()
    if filename != "metar.txt":
        data = gzip.compress(data)  # .dat: gzip found by its magic bytes, not the name
    feed = read_feed(_write(tmp_path / filename, data))
    assert (feed.format, feed.problems) == ("lines", ())
    egll, lfpg = feed.reports
    assert egll.observed_utc == datetime(2024, 3, 1, 0, 0, tzinfo=UTC)
    # Day 29 after a 1 March mtime is February's (2024 is a leap year).
    assert lfpg.observed_utc == datetime(2024, 2, 29, 23, 30, tzinfo=UTC)
    assert (lfpg.year, lfpg.month) == (2024, 2)
    assert egll.where == f"{tmp_path / filename}:1"


def test_truncated_gzip_keeps_what_decompressed(tmp_path: Path) -> None:
    data = gzip.compress(SMALL_CSV.encode() * 20)
    feed = read_feed(_write(tmp_path / "cut.csv.gz", data[: len(data) // 2]))
    assert feed.format == "awc-csv" and feed.reports
    assert any("gzip data ends early" in p.reason for p in feed.problems)


def test_missing_file_is_a_feed_error(tmp_path: Path) -> None:
    with pytest.raises(FeedError, match="cannot read"):
        read_feed(tmp_path / "nope.csv")
    with pytest.raises(FeedError, match="cannot read"):
        read_reports(tmp_path / "nope.csv")


@pytest.mark.parametrize(
    ("data", "what"),
    [
        (b"<!DOCTYPE html>\n<html><body>502 Bad Gateway</body></html>", "HTML page"),
        (b"<html><head><title>Login</title></head></html>", "HTML page"),
        (b'[{"id":"EGLL","metar":"EGLL 010000Z AUTO 23008KT"}]', "JSON"),
        (b'{"error": "rate limited"}', "JSON"),
        (b"", "empty"),
        (b"\n \r\n", "empty"),
        (b"\x00\x01\x02binary\x00" * 50, "binary"),
        (b"just some words\nand more words\n", "not a METAR feed"),
    ],
)
def test_not_a_feed(tmp_path: Path, data: bytes, what: str) -> None:
    path = _write(tmp_path / "feed.bin", data)
    with pytest.raises(FeedError, match=what) as exc:
        read_feed(path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_random_bytes_never_raise_anything_but_feed_error() -> None:
    rng = random.Random(20250726)
    for _ in range(200):
        data = rng.randbytes(rng.randrange(1, 3000))
        with pytest.raises(FeedError):
            parse_feed(data)
        for fmt in FORMATS:
            assert isinstance(parse_feed(data, format=fmt), Feed)
            assert isinstance(
                parse_feed(gzip.compress(data)[: rng.randrange(1, 60)], format=fmt), Feed
            )


@pytest.mark.parametrize("fmt", FORMATS)
def test_wrong_format_forced(fmt: str) -> None:
    for data in (SMALL_CSV, XML, LINES, "2025/07/26 15:55\nKTGI 261555Z AUTO 10SM CLR\n", ""):
        feed = parse_feed(data, format=fmt)
        assert feed.format == fmt
        assert feed.reports or feed.problems or not data


def test_unknown_format_name() -> None:
    with pytest.raises(FeedError, match="unknown feed format"):
        parse_feed(LINES, format="json")


def test_non_utf8_bytes_are_replaced_and_reported() -> None:
    data = f"{HEADER}\n{ROW_KBDN}\n".encode().replace(b"RMK AO2", b"RMK \xe9\xff AO2", 1)
    feed = parse_feed(data, name="latin")
    (r,) = feed.reports
    assert r.station == "KBDN" and "\ufffd" in r.raw
    assert [p.where for p in feed.problems] == ["latin:2"] and "UTF-8" in feed.problems[0].reason


def test_empty_file_forced_format_is_a_problem(tmp_path: Path) -> None:
    feed = read_feed(_write(tmp_path / "empty.txt", b""), format="lines")
    assert feed.reports == () and [p.reason for p in feed.problems] == ["empty feed"]


def test_problems_are_capped() -> None:
    feed = parse_feed("junk line\n" * (MAX_PROBLEMS + 50), format="lines", name="j")
    assert len(feed.problems) == MAX_PROBLEMS + 1
    assert feed.problems[-1] == FeedProblem("j", "50 further problems not listed")


def test_detect_format_variants() -> None:
    assert detect_format("\ufeff" + SMALL_CSV) == "awc-csv"
    assert detect_format("<response version='1.2'><data/></response>") == "awc-xml"
    assert detect_format("\n\n2025/07/26 15:55\nKTGI 261555Z AUTO\n") == "tgftp"
    assert detect_format("METAR EGLL 010000Z AUTO 23008KT=\n") == "lines"
    assert detect_format(LINES) == "lines"
