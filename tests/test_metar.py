"""The single-report METAR decoder: every group kind, the error policy, and real corpora."""

from __future__ import annotations

import csv
import json
import random
import re
from datetime import UTC, datetime
from pathlib import Path

import pytest

from wxsky.errors import MetarError
from wxsky.units import INHG_TO_HPA, KT_TO_MPS, STATUTE_MILE_TO_M, mps_to_kt
from wxsky.weather.metar import MetarReport, MetarSkyGroup, decode_metar
from wxsky.weather.state import MAX_LAYERS, CloudType, Source, WeatherState

DATA_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "metar"
CYCLE_FILE = "noaa_cycle_2025-07-26_okay_weather_HEAD1500.txt"
CSV_FILES = {
    # file name -> rows the data README says it holds
    "awc_cache_2014-09-26_etms-visualization.csv": 4336,
    "awc_cache_2020-05-02_luasamples.csv": 4678,
    "awc_cache_2022-10-23_HackGT-2022.csv": 4911,
    "awc_cache_2026-03-20_meteo473_EXCERPT.csv": 9,
}
needs_corpus = pytest.mark.skipif(
    not DATA_DIR.is_dir(), reason=f"shared METAR corpus not found at {DATA_DIR}"
)

FT = 0.3048
SM = STATUTE_MILE_TO_M


def body(groups: str) -> MetarReport:
    """Decodes groups placed after a fixed header, so each test names only what it checks."""
    return decode_metar(f"KXYZ 261550Z {groups}")


# --- header -----------------------------------------------------------------------------------


def test_header_fields() -> None:
    r = decode_metar("METAR KBDN 262135Z AUTO 36007KT 10SM CLR 16/03 A3008 RMK AO2")
    assert (r.station, r.kind, r.day, r.hour, r.minute) == ("KBDN", "METAR", 26, 21, 35)
    assert r.issued_ddhhmm == (26, 21, 35)
    assert r.auto and not r.cor and not r.nil
    assert r.warnings == ()


def test_speci_prefix_and_bare_report() -> None:
    assert decode_metar("SPECI CYBW 201519Z 15006KT 1SM OVC002 00/00 A2978").kind == "SPECI"
    bare = decode_metar("EGLL 010000Z 23008KT 9999 NCD 18/13 Q1018")
    assert (bare.kind, bare.auto) == ("METAR", False)


@pytest.mark.parametrize(
    "text",
    [
        "MRLB COR 262100Z 09010KT 9999 FEW020 30/22 Q1012",
        "CYWH 262126Z CCA 15002KT 3SM -SHRA BR SCT004 BKN010 OVC022",
        "METAR COR LFPG 261200Z 24010KT CAVOK 20/10 Q1015",
        "KXYZ 261555Z AUTO COR 27010KT 10SM CLR 20/10 A3000",
    ],
)
def test_correction_flag_before_or_after_time(text: str) -> None:
    r = decode_metar(text)
    assert r.cor
    assert r.wind is not None and r.visibility_m is not None
    assert r.warnings == ()


def test_nil_report() -> None:
    r = decode_metar("KXYZ 261555Z NIL")
    assert r.nil and r.wind is None and r.visibility_m is None
    patch = r.to_patch()
    assert patch.source is Source.METAR
    assert (patch.layers, patch.wind, patch.present_weather, patch.qnh_hpa) == (None,) * 4


def test_issued_at_takes_year_and_month_from_the_feed() -> None:
    r = decode_metar("KXYZ 311550Z 27010KT 10SM CLR 20/10 A3000")
    assert r.issued_at(2025, 7) == datetime(2025, 7, 31, 15, 50, tzinfo=UTC)
    with pytest.raises(MetarError, match="day 31 does not exist in 2025-06"):
        r.issued_at(2025, 6)


def test_time_group_without_z_is_accepted_with_a_warning() -> None:
    r = decode_metar("HAAB 261600 18005KT 9999 FEW030 18/12 Q1025")
    assert (r.day, r.hour, r.minute) == (26, 16, 0)
    assert r.warnings == ("group 2 '261600': time group without its Z",)


# --- wind -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("group", "direction", "variable", "speed_mps", "gust_mps"),
    [
        ("27015KT", 270.0, False, 15 * KT_TO_MPS, None),
        ("27015G25KT", 270.0, False, 15 * KT_TO_MPS, 25 * KT_TO_MPS),
        ("090105G130KT", 90.0, False, 105 * KT_TO_MPS, 130 * KT_TO_MPS),
        ("VRB03KT", None, True, 3 * KT_TO_MPS, None),
        ("VRB04G11KT", None, True, 4 * KT_TO_MPS, 11 * KT_TO_MPS),
        ("00000KT", 0.0, False, 0.0, None),
        ("///05KT", None, False, 5 * KT_TO_MPS, None),
        ("270P99KT", 270.0, False, 99 * KT_TO_MPS, None),
        ("24008MPS", 240.0, False, 8.0, None),
        ("17006G11MPS", 170.0, False, 6.0, 11.0),
        ("36036KMH", 360.0, False, 10.0, None),
        ("36036G54KMH", 360.0, False, 10.0, 15.0),
    ],
)
def test_wind_groups(
    group: str, direction: float | None, variable: bool, speed_mps: float, gust_mps: float | None
) -> None:
    r = body(f"{group} 9999 FEW030 20/10 Q1015")
    assert r.warnings == ()
    w = r.wind
    assert w is not None
    assert w.dir_from_deg == direction
    assert w.variable is variable
    assert w.speed_mps == pytest.approx(speed_mps)
    assert w.gust_mps == (None if gust_mps is None else pytest.approx(gust_mps))


def test_wind_unit_conversions() -> None:
    kt, mps, kmh = (body(f"180{v}").wind for v in ("10KT", "10MPS", "10KMH"))
    assert kt is not None and mps is not None and kmh is not None
    assert kt.speed_mps == pytest.approx(5.144444, abs=1e-6)  # 10 kt = 18.52 km/h
    assert mps.speed_mps == 10.0
    assert kmh.speed_mps == pytest.approx(2.777778, abs=1e-6)
    assert mps_to_kt(mps.speed_mps) == pytest.approx(19.438445, abs=1e-6)


def test_calm_and_missing_wind() -> None:
    calm = body("00000KT 9999").wind
    assert calm is not None and calm.calm and calm.speed_mps == 0.0
    missing = body("/////KT 9999")
    assert missing.wind is None and missing.warnings == ()


def test_variable_wind_sector() -> None:
    w = body("24012G25KT 200V280 CAVOK").wind
    assert w is not None
    assert (w.dir_from_deg, w.variable_from_deg, w.variable_to_deg) == (240.0, 200.0, 280.0)


def test_wind_without_unit_is_read_as_knots_with_a_warning() -> None:
    r = decode_metar("HSPN 231100Z 04014 9999 SCT030 32/23 Q1013")
    assert r.wind is not None
    assert r.wind.speed_mps == pytest.approx(14 * KT_TO_MPS)
    assert r.warnings == ("group 3 '04014': wind group without a unit, read as knots",)


@pytest.mark.parametrize(
    ("group", "reason"),
    [
        ("E00000KT", "malformed wind group"),
        ("NE-04KT", "malformed wind group"),
        ("4.62500005KT", "malformed wind group"),
        ("12O45KT", "malformed wind group"),
        ("25005KY", "unrecognised group"),
    ],
)
def test_malformed_wind_is_a_warning(group: str, reason: str) -> None:
    r = body(f"{group} 9999 20/10 Q1015")
    assert r.wind is None
    assert r.warnings == (f"group 3 {group!r}: {reason}",)
    assert (r.visibility_m, r.temperature_c, r.qnh_hpa) == (10_000.0, 20.0, 1015.0)


# --- visibility -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("groups", "metres"),
    [
        ("9999", 10_000.0),
        ("0800", 800.0),
        ("0000", 0.0),
        ("4000NDV", 4000.0),
        ("M0400", 400.0),
        ("10KM", 10_000.0),
        ("10SM", 10 * SM),
        ("7SM", 7 * SM),
        ("P6SM", 6 * SM),
        ("1 1/2SM", 1.5 * SM),
        ("2 3/4SM", 2.75 * SM),
        ("1/4SM", 0.25 * SM),
        ("M1/4SM", 0.25 * SM),
        ("1/16SM", SM / 16),
        ("3/16SM", 3 * SM / 16),
        ("5/16SM", 5 * SM / 16),
        ("11/2SM", 1.5 * SM),  # the space of "1 1/2SM" lost
        ("////", None),
        ("////SM", None),
    ],
)
def test_visibility_groups(groups: str, metres: float | None) -> None:
    r = body(f"27010KT {groups} FEW030 20/10 Q1015")
    assert r.warnings == ()
    assert r.visibility_m == (None if metres is None else pytest.approx(metres))
    assert not r.cavok


def test_directional_minimum_does_not_replace_prevailing_visibility() -> None:
    r = body("27010KT 9999 4000SE FEW030")
    assert r.visibility_m == 10_000.0 and r.warnings == ()


def test_cavok_means_ten_km_and_no_cloud() -> None:
    r = decode_metar("EVGA 201520Z 36008KT CAVOK 08/M02 Q1019 NOSIG")
    assert r.cavok and r.visibility_m == 10_000.0
    assert r.sky == () and r.sky_clear is None
    patch = r.to_patch(field_elevation_m=100.0)
    assert patch.layers == ()
    assert patch.visibility_m == 10_000.0


# --- weather ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "code",
    ["-RA", "+TSRA", "BR", "VCSH", "FZFG", "-SHRASN", "+FC", "BCFG", "TS", "VCTS", "-DZ", "HZ"],
)
def test_present_weather_groups(code: str) -> None:
    r = body(f"27010KT 5000 {code} BKN010 15/14 Q1010")
    assert r.weather == (code,)
    assert r.warnings == ()


def test_several_weather_groups_keep_their_order() -> None:
    r = body("27010KT 1SM -RA BR VV002 00/00 A2978")
    assert r.weather == ("-RA", "BR")
    assert r.to_patch().present_weather == ("-RA", "BR")


@pytest.mark.parametrize("group", ["RERA", "RETSRA", "RE//", "NSW", "//"])
def test_recognised_weather_groups_that_add_nothing(group: str) -> None:
    r = body(f"27010KT 9999 FEW030 20/10 Q1015 {group}")
    assert r.weather == () and r.warnings == ()


def test_malformed_weather_is_a_warning() -> None:
    r = decode_metar("KUNV 261553Z 00000KT 10SM VCTS-RA OVC026 25/23 A3013")
    assert r.weather == ()
    assert r.warnings == ("group 5 'VCTS-RA': unrecognised group",)
    assert r.sky == (MetarSkyGroup("OVC", 2600 * FT),)


# --- sky --------------------------------------------------------------------------------------


def test_cloud_groups_with_heights_in_metres() -> None:
    r = body("27010KT 9999 FEW020 SCT035 BKN100 OVC250 20/10 Q1015")
    assert [s.cover for s in r.sky] == ["FEW", "SCT", "BKN", "OVC"]
    assert [s.base_m for s in r.sky] == pytest.approx([609.6, 1066.8, 3048.0, 7620.0])
    assert r.sky_clear is None


def test_cb_and_tcu_flags() -> None:
    r = body("27010KT 9999 FEW008 BKN045CB SCT030TCU FEW040///")
    assert [(s.cover, s.cb, s.tcu) for s in r.sky] == [
        ("FEW", False, False),
        ("BKN", True, False),
        ("SCT", False, True),
        ("FEW", False, False),
    ]


def test_detached_cb_joins_the_cloud_group_before_it() -> None:
    r = body("27010KT 9999 SCT030 CB 20/10 Q1015")
    assert r.sky == (MetarSkyGroup("SCT", 3000 * FT, cb=True),)
    assert r.warnings == ()


def test_vertical_visibility() -> None:
    r = decode_metar("KSTF 231135Z AUTO 00000KT 1/2SM FG VV005 10/10 A3011 RMK AO2")
    assert [s.cover for s in r.sky] == ["VV"]
    assert r.sky[0].base_m == pytest.approx(152.4)
    unknown = body("00000KT 0100 FG VV///")
    assert unknown.sky == (MetarSkyGroup("VV", None),)


def test_cloud_without_base() -> None:
    r = decode_metar("RJSN 262100Z 18005KT 9999 FEW050 SCT190 BKN/// 22/18 Q1010")
    assert r.sky[-1] == MetarSkyGroup("BKN", None)
    assert len(r.to_patch().layers or ()) == 2


@pytest.mark.parametrize("code", ["CLR", "SKC", "NSC", "NCD"])
def test_explicit_clear_sky(code: str) -> None:
    r = body(f"27010KT 9999 {code} 20/10 Q1015")
    assert r.sky_clear == code and r.sky == ()
    assert r.to_patch().layers == ()


def test_no_sky_group_leaves_layers_unknown() -> None:
    r = decode_metar("K1EM 261555Z AUTO 27012KT 10SM M 19/14 A3000")
    assert r.sky == () and r.sky_clear is None and r.warnings == ()
    assert r.to_patch().layers is None


def test_truncated_cloud_group_is_a_warning() -> None:
    r = decode_metar("TLPC 262100Z 13007KT 9999 FEW02 BKN290 29/23 Q1012")
    assert r.warnings == ("group 5 'FEW02': malformed cloud group",)
    assert [s.cover for s in r.sky] == ["BKN"]
    assert r.sky[0].base_m == pytest.approx(29000 * FT)


# --- temperature and pressure -----------------------------------------------------------------


@pytest.mark.parametrize(
    ("group", "temperature", "dewpoint"),
    [
        ("12/10", 12.0, 10.0),
        ("M05/M12", -5.0, -12.0),
        ("03/M01", 3.0, -1.0),
        ("M00/M01", 0.0, -1.0),
        ("M05/", -5.0, None),
        ("23/", 23.0, None),
        ("//////", None, None),
        ("XX/XX", None, None),
        ("M/M", None, None),
    ],
)
def test_temperature_groups(group: str, temperature: float | None, dewpoint: float | None) -> None:
    r = body(f"27010KT 9999 FEW030 {group} Q1015")
    assert (r.temperature_c, r.dewpoint_c) == (temperature, dewpoint)
    assert r.warnings == ()


def test_missing_temperature_group_does_not_block_a_later_one() -> None:
    r = decode_metar("CWRH 262100Z AUTO ///// M04/ A2970 RMK SLP091")
    assert r.temperature_c == -4.0 and r.warnings == ()


def test_remark_t_group_refines_temperatures_to_tenths() -> None:
    r = decode_metar("KLQK 262135Z AUTO 05007KT 10SM OVC023 21/18 A3018 RMK AO2 T02070175")
    assert (r.temperature_c, r.dewpoint_c) == (20.7, 17.5)
    neg = decode_metar("KW31 262115Z AUTO 01004KT 10SM CLR M39/M44 A3018 RMK AO1 T13861440")
    assert (neg.temperature_c, neg.dewpoint_c) == (-38.6, -44.0)
    no_dew = decode_metar("KSEF 231115Z AUTO 35005KT 10SM CLR 17/ A3009 RMK AO2 T0171////")
    assert (no_dew.temperature_c, no_dew.dewpoint_c) == (17.1, None)


def test_remark_t_group_that_disagrees_with_the_body_is_ignored() -> None:
    # A real report whose body and remark disagree by 1.3 °C: the body group is kept.
    r = decode_metar("KBYY 020035Z AUTO 15006KT 10SM CLR 23/17 A3000 RMK AO2 T02430174")
    assert (r.temperature_c, r.dewpoint_c) == (23.0, 17.4)


@pytest.mark.parametrize(
    ("group", "hpa"),
    [
        ("Q1013", 1013.0),
        ("Q0998", 998.0),
        ("Q1010.3", 1010.3),
        ("QNH1021", 1021.0),
        ("A2992", 29.92 * INHG_TO_HPA),
        ("A3008", 30.08 * INHG_TO_HPA),
        ("Q////", None),
        ("A////", None),
    ],
)
def test_pressure_groups(group: str, hpa: float | None) -> None:
    r = body(f"27010KT 9999 FEW030 20/10 {group}")
    assert r.qnh_hpa == (None if hpa is None else pytest.approx(hpa))
    assert r.warnings == ()


def test_altimeter_conversion_reference_value() -> None:
    r = body("A2992")
    assert r.qnh_hpa == pytest.approx(1013.2, abs=0.05)


def test_q_group_wins_over_a_group() -> None:
    assert body("A2989 Q1012").qnh_hpa == 1012.0
    assert body("Q1012 A2989").qnh_hpa == 1012.0
    r = body("Q1012 A3012")  # 1020.0 hPa: the two disagree
    assert r.qnh_hpa == 1012.0
    assert r.warnings == ("group 4 'A3012': disagrees with the other pressure group (1012.0 hPa)",)


# --- report structure -------------------------------------------------------------------------


def test_remarks_are_not_decoded_into_body_fields() -> None:
    r = decode_metar("KXYZ 261550Z 27010KT 10SM CLR 20/10 A3000 RMK AO2 PK WND 27045/1520 36099KT")
    assert r.wind is not None and r.wind.speed_mps == pytest.approx(10 * KT_TO_MPS)
    assert r.remarks == "AO2 PK WND 27045/1520 36099KT"
    assert r.trend == "" and r.warnings == ()


@pytest.mark.parametrize(
    "trend",
    [
        "NOSIG",
        "BECMG 35025KT 2000 +RA",
        "TEMPO 0500 FG OVC001",
        "FM0900 35025KT 2000",
        "INTER 0730/0830 5000 SHRA",
    ],
)
def test_trend_ends_the_body(trend: str) -> None:
    r = decode_metar(f"EGLL 261550Z 24010KT 9999 FEW030 20/10 Q1015 {trend}")
    assert r.trend == trend
    assert r.wind is not None and r.wind.dir_from_deg == 240.0
    assert r.visibility_m == 10_000.0 and r.weather == ()
    assert [s.cover for s in r.sky] == ["FEW"]


def test_trend_and_remarks_together() -> None:
    r = decode_metar("UIBB 262100Z 36003MPS P5000 FEW040CB M03/M06 Q1026 NOSIG RMK QFE726/0968")
    assert (r.trend, r.remarks) == ("NOSIG", "QFE726/0968")
    assert r.visibility_m == 5000.0


def test_end_of_report_mark() -> None:
    r = decode_metar("CWFD 262129Z AUTO 01003KT 1/8SM OVC014 M05/ A2945= KXYZ 261550Z 18099KT")
    assert r.raw == "CWFD 262129Z AUTO 01003KT 1/8SM OVC014 M05/ A2945"
    assert r.wind is not None and r.wind.dir_from_deg == 10.0
    assert r.visibility_m == pytest.approx(SM / 8)


def test_second_report_glued_on_is_cut_off() -> None:
    r = decode_metar("KAAA 261550Z 27010KT 10SM CLR 20/10 A3000 KBBB 261550Z 09050KT 1/4SM")
    assert r.visibility_m == pytest.approx(10 * SM)
    assert r.warnings == ("group 8 'KBBB': a second report starts here; the rest is ignored",)


def test_supplementary_groups_are_recognised() -> None:
    r = body(
        "27010KT 9999 R27/0900V1500U R09/P2000N FEW030 20/10 Q1015 WS R27 W16/S3 R29/290050 "
        "88CLRD95 RF00.0/000.0 BLU+ QFE871.6"
    )
    assert r.warnings == ()
    assert r.rvr == ("R27/0900V1500U", "R09/P2000N")


def test_garbled_group_goes_to_warnings_and_decoding_goes_on() -> None:
    r = decode_metar("METAR KXYZ 261550Z 12O45KT 9999 FEW030 20/10 Q1015")
    assert r.warnings == ("group 4 '12O45KT': malformed wind group",)
    assert r.wind is None
    assert (r.visibility_m, r.temperature_c, r.qnh_hpa) == (10_000.0, 20.0, 1015.0)


def test_duplicate_group_is_a_warning_and_the_first_wins() -> None:
    r = body("27010KT 9999 20/10 18/09 Q1015")
    assert r.temperature_c == 20.0
    assert r.warnings == ("group 6 '18/09': second temperature group ignored",)


# --- out-of-range values: skipped with a warning ---------------------------------------------


@pytest.mark.parametrize(
    ("group", "field", "reason"),
    [
        ("270300KT", "wind", "wind speed 300 kt is above 250 kt"),
        ("090140MPS", "wind", "wind speed 272 kt is above 250 kt"),
        ("27010G260KT", "wind", "gust 260 kt is above 250 kt"),
        ("140MPS", None, None),  # no direction: not a wind group at all
        ("37010KT", "wind", "wind direction 370° is above 360°"),
        ("65/10", "temperature_c", "temperature 65 °C outside -90..60"),
        ("M95/M99", "temperature_c", "temperature -95 °C outside -90..60"),
        ("Q0800", "qnh_hpa", "QNH 800.0 hPa outside 850..1100"),
        ("Q1200", "qnh_hpa", "QNH 1200.0 hPa outside 850..1100"),
        ("A3500", "qnh_hpa", "QNH 1185.2 hPa outside 850..1100"),
        ("999SM", "visibility_m", "visibility 1608 km is above 1000 km"),
    ],
)
def test_out_of_range_values_are_skipped_with_a_warning(
    group: str, field: str | None, reason: str | None
) -> None:
    r = body(group)
    assert len(r.warnings) == 1
    assert r.warnings[0].startswith(f"group 3 {group!r}: ")
    if field is not None:
        assert getattr(r, field) is None
        assert r.warnings[0] == f"group 3 {group!r}: {reason}; group skipped"


def test_negative_visibility_is_not_a_visibility() -> None:
    r = body("27010KT -1SM FEW030")
    assert r.visibility_m is None
    assert r.warnings == ("group 4 '-1SM': malformed visibility group",)


# --- fatal errors -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty METAR report"),
        ("   \n\t ", "empty METAR report"),
        ("=", "empty METAR report"),
        ("METAR", "METAR report has no station group"),
        ("KXYZ", "METAR report has no time group (ddhhmmZ) after station 'KXYZ'"),
        (
            "UTO8 M M M 205/06/-05/2817/M/ PK WND 2825 2009Z 3001 80MM",
            "METAR group 2 'M': expected the time group (ddhhmmZ) after station 'UTO8'",
        ),
        (
            "PART 1 OF 2 ",
            "METAR group 2 '1': expected the time group (ddhhmmZ) after station 'PART'",
        ),
        (
            "CWND M01/M01 RMK T10081010",
            "METAR group 2 'M01/M01': expected the time group (ddhhmmZ) after station 'CWND'",
        ),
        ("12345 261550Z", "METAR group 1 '12345': expected a 4-character station identifier"),
        ("kxyz 261550Z 27010KT", "METAR group 1 'kxyz': expected a 4-character station identifier"),
        (
            "KXYZ 322460Z 27010KT",
            "METAR group 2 '322460Z': day 32, 24:60 is not a valid day and UTC time",
        ),
        (
            "KXYZ 261550Z 27010KT 10SM CLR 20°/10",
            "METAR report has a non-ASCII or control character '°' at offset 32",
        ),
        (
            "\x01KXYZ 261550Z",
            "METAR report has a non-ASCII or control character '\\x01' at offset 0",
        ),
    ],
)
def test_fatal_errors_name_what_and_where(text: str, message: str) -> None:
    with pytest.raises(MetarError) as err:
        decode_metar(text)
    assert str(err.value) == message
    assert "\n" not in str(err.value)


# --- to_patch ---------------------------------------------------------------------------------


def test_patch_cloud_mapping_oktas_types_and_msl_bases() -> None:
    r = body("27010KT 9999 FEW020 SCT040 BKN060 OVC090 FEW100 SCT120 BKN220 OVC250")
    layers = r.to_patch(field_elevation_m=500.0).layers
    assert layers is not None and len(layers) == MAX_LAYERS
    got = [(lay.cover_oktas, lay.type, round(lay.base_m, 1)) for lay in layers]
    assert got == [
        (2, CloudType.CUMULUS, round(500 + 2000 * FT, 1)),
        (4, CloudType.CUMULUS, round(500 + 4000 * FT, 1)),
        (6, CloudType.STRATOCUMULUS, round(500 + 6000 * FT, 1)),
        (8, CloudType.ALTOSTRATUS, round(500 + 9000 * FT, 1)),  # 2743 m AGL: mid level
        (2, CloudType.ALTOCUMULUS, round(500 + 10000 * FT, 1)),
        (4, CloudType.ALTOCUMULUS, round(500 + 12000 * FT, 1)),
    ]  # the two highest of eight groups are dropped to keep MAX_LAYERS
    assert all(lay.top_m > lay.base_m for lay in layers)


@pytest.mark.parametrize(
    ("group", "oktas", "cloud_type"),
    [
        ("OVC005", 8, CloudType.STRATUS),
        ("BKN015", 6, CloudType.STRATOCUMULUS),
        ("SCT030", 4, CloudType.CUMULUS),
        ("FEW040", 2, CloudType.CUMULUS),
        ("BKN080", 6, CloudType.ALTOCUMULUS),
        ("OVC120", 8, CloudType.ALTOSTRATUS),
        ("SCT250", 4, CloudType.CIRRUS),
        ("OVC300", 8, CloudType.CIRROSTRATUS),
        ("BKN030CB", 6, CloudType.CUMULONIMBUS),
        ("SCT025TCU", 4, CloudType.CUMULUS),
        ("VV002", 8, CloudType.STRATUS),
    ],
)
def test_patch_cloud_type_per_group(group: str, oktas: int, cloud_type: CloudType) -> None:
    layers = body(group).to_patch().layers
    assert layers is not None and len(layers) == 1
    assert (layers[0].cover_oktas, layers[0].type) == (oktas, cloud_type)


def test_patch_layer_thickness_is_plausible() -> None:
    layers = body("BKN030CB SCT035TCU FEW040 BKN250").to_patch().layers
    assert layers is not None
    depth = {lay.type: lay.thickness_m for lay in layers}
    cb = depth.pop(CloudType.CUMULONIMBUS)
    assert cb >= 6000.0 and cb > max(depth.values())
    tcu, cu = (lay for lay in layers if lay.type is CloudType.CUMULUS)
    assert tcu.thickness_m > cu.thickness_m  # towering cumulus is taller
    assert all(lay.top_m <= 25_000.0 for lay in layers)


def test_patch_wind_layer() -> None:
    patch = body("24012G25KT 9999").to_patch(field_elevation_m=432.0)
    assert patch.wind is not None and len(patch.wind) == 1
    w = patch.wind[0]
    assert (w.alt_m, w.dir_from_deg, w.variable) == (442.0, 240.0, False)
    assert w.speed_mps == pytest.approx(12 * KT_TO_MPS)
    assert w.gust_mps == pytest.approx(25 * KT_TO_MPS)
    vrb = body("VRB03KT 9999").to_patch().wind
    assert vrb is not None
    assert (vrb[0].dir_from_deg, vrb[0].variable, vrb[0].gust_mps) == (0.0, True, 0.0)


def test_patch_passes_values_through_and_leaves_unknowns_none() -> None:
    r = decode_metar("SPECI CYBW 201519Z AUTO 15006KT 1SM -RA BR VV002 00/00 A2978")
    patch = r.to_patch(field_elevation_m=1197.0)
    assert patch.source is Source.METAR
    assert patch.visibility_m == pytest.approx(SM)
    assert (patch.temperature_c, patch.dewpoint_c) == (0.0, 0.0)
    assert patch.qnh_hpa == pytest.approx(29.78 * INHG_TO_HPA)
    assert patch.present_weather == ("-RA", "BR")
    assert patch.layers is not None and patch.layers[0].base_m == pytest.approx(1197 + 200 * FT)
    assert patch.time_utc is None and patch.observer is None and patch.seed is None
    sparse = decode_metar("KXYZ 261550Z AUTO /////KT //// ////// ///// Q////").to_patch()
    assert (sparse.wind, sparse.visibility_m, sparse.layers, sparse.temperature_c) == (None,) * 4
    assert sparse.qnh_hpa is None


def test_patch_applies_to_the_weather_state() -> None:
    r = decode_metar("EGLL 261550Z 24010KT 200V280 9999 -RA FEW012 BKN025CB 18/14 Q1009 NOSIG")
    state = WeatherState().apply(r.to_patch(field_elevation_m=25.0))
    assert state.sources.layers is Source.METAR and state.sources.qnh_hpa is Source.METAR
    assert state.qnh_hpa == 1009.0
    assert [lay.type for lay in state.layers] == [CloudType.CUMULUS, CloudType.CUMULONIMBUS]


def test_patch_rejects_an_impossible_field_elevation() -> None:
    with pytest.raises(ValueError, match="field_elevation_m"):
        body("27010KT").to_patch(field_elevation_m=20_000.0)


# --- to_dict and describe ---------------------------------------------------------------------


def test_to_dict_is_json_ready() -> None:
    r = decode_metar("METAR KXYZ 261550Z AUTO 24012G25KT 200V280 1 1/2SM -RA BKN045CB 12/M01 A2992")
    d = json.loads(json.dumps(r.to_dict()))
    assert d["station"] == "KXYZ" and d["kind"] == "METAR" and d["auto"] is True
    assert (d["day"], d["hour"], d["minute"]) == (26, 15, 50)
    assert d["wind"]["dir_from_deg"] == 240.0 and d["wind"]["variable_from_deg"] == 200.0
    assert d["visibility_m"] == pytest.approx(1.5 * SM)
    assert d["weather"] == ["-RA"]
    assert d["sky"] == [
        {"cover": "BKN", "base_m": pytest.approx(4500 * FT), "cb": True, "tcu": False}
    ]
    assert (d["temperature_c"], d["dewpoint_c"]) == (12.0, -1.0)
    assert d["warnings"] == [] and d["sky_clear"] is None


def test_describe_names_the_decoded_values() -> None:
    text = decode_metar("KXYZ 261550Z 24012KT 9999 FEW030CB 20/10 Q1015 NOSIG RMK X").describe()
    assert text.splitlines()[0] == "METAR KXYZ day 26 15:50Z"
    for part in ("240° 6.2 m/s (12 kt)", "10000 m", "FEW 914 m (3000 ft) CB", "20 °C / 10 °C"):
        assert part in text
    assert "1015.0 hPa" in text and "NOSIG" in text
    garbled = decode_metar("KXYZ 261550Z 12O45KT").describe()
    assert "warning: group 3 '12O45KT': malformed wind group" in garbled


# --- robustness -------------------------------------------------------------------------------

REAL_REPORTS = [
    "KBDN 262135Z AUTO 36007KT 10SM CLR 16/03 A3008 RMK AO2",
    "UKHH 262130Z 01002MPS 6000 NSC 11/09 Q1018 070///65 NOSIG",
    "KSTF 231135Z AUTO 00000KT 1/2SM FG VV005 10/10 A3011 RMK AO2 VIS M1/4V3",
    "OPLA 272225Z 33006KT 4000 FU NSC 11/06 Q1011 NOSIG RMK QFE986 A29.88",
    "METAR KDTA 201520Z AUTO 07010KT 10SM CLR 13/M06 A3031 RMK AO1",
    "SPECI CYBW 201519Z AUTO 15006KT 1SM R35/2800V4000FT/ -RA BR VV002 00/00 A2978 RMK VIS VRB "
    "1/4-2 1/2 ICE PAST HR PRESFR SLP131",
    "EDNY 262125Z AUTO 02002KT 2500 0400/ R24/0900VP2000U BR NSC 09/08 Q1027",
    "YBBN 180755Z 23021KT 9000 TSRA FEW008 BKN045CB BKN100 28/19 Q1008 FM0900 35010KT 9999",
    "PHBK 262119Z AUTO 29004KT 1 1/4SM +RA BR BKN007 OVC014 26/24 A3002 RMK AO2 P0024 T02560244",
    "KPCM 262115Z AUTO 09011G18KT 2SM +RA BKN007 OVC015 24/ A3000 RMK AO2 P0031",
    "SOCA 020030Z AUTO VRB02KT 4300 0900 R08/1200D +RA BCFG SCT025/// ///TCU 26/26 Q1014",
]


def _assert_decodes_or_metar_error(text: str) -> None:
    try:
        r = decode_metar(text)
    except MetarError as e:
        assert str(e) and "\n" not in str(e)
        return
    # Whatever decodes must also make a patch the weather state accepts.
    WeatherState().apply(r.to_patch(field_elevation_m=1000.0))
    json.dumps(r.to_dict())
    r.describe()


@pytest.mark.parametrize("report", REAL_REPORTS)
def test_every_prefix_decodes_or_raises_metar_error(report: str) -> None:
    for end in range(len(report) + 1):
        _assert_decodes_or_metar_error(report[:end])


def test_random_bytes_raise_metar_error() -> None:
    rng = random.Random(1234)
    for _ in range(300):
        text = rng.randbytes(rng.randint(1, 80)).decode("latin-1")
        if all(c.isascii() and c.isprintable() for c in text):
            continue  # vanishingly rare; the ASCII fuzz below covers that case
        with pytest.raises(MetarError):
            decode_metar(text)


def test_random_ascii_token_soup_never_escapes_another_exception() -> None:
    rng = random.Random(99)
    alphabet = "0123456789/ MPSKTVRBGCLROFEWSNQAXZ+-=."
    words = "METAR SPECI KXYZ 261550Z AUTO COR RMK NOSIG TEMPO CAVOK 9999 SM KT VV NIL"
    tokens = words.split(" ")
    for _ in range(3000):
        parts = [
            rng.choice(tokens)
            if rng.random() < 0.3
            else "".join(rng.choice(alphabet) for _ in range(rng.randint(1, 9)))
            for _ in range(rng.randint(0, 12))
        ]
        if rng.random() < 0.5:
            parts[:0] = ["KXYZ", "261550Z"]
        _assert_decodes_or_metar_error(" ".join(parts))


def test_mutated_real_reports_never_escape_another_exception() -> None:
    rng = random.Random(7)
    alphabet = "0123456789/ MPSKTVRBGCLROFEWSNQA"
    for _ in range(3000):
        chars = list(rng.choice(REAL_REPORTS))
        for _ in range(rng.randint(1, 4)):
            pos = rng.randrange(len(chars))
            action = rng.random()
            if action < 0.4:
                chars[pos] = rng.choice(alphabet)
            elif action < 0.7:
                del chars[pos]
            else:
                chars.insert(pos, rng.choice(alphabet))
        _assert_decodes_or_metar_error("".join(chars))


# --- real corpora -----------------------------------------------------------------------------

_TIMESTAMP = re.compile(r"\d{4}/\d\d/\d\d \d\d:\d\d")


def _cycle_reports() -> list[str]:
    lines = (DATA_DIR / CYCLE_FILE).read_text(encoding="latin-1").split("\n")
    return [lines[i + 1] for i, line in enumerate(lines[:-1]) if _TIMESTAMP.fullmatch(line)]


def _csv_rows(name: str) -> list[list[str]]:
    # Line endings vary (\r\r\n in the 2022 file) and the legacy raw_text is unquoted, so a comma
    # inside a report would shift columns: the 43 decoded columns are counted from the right.
    text = (DATA_DIR / name).read_text(encoding="latin-1").replace("\r", "")
    lines = [line for line in text.split("\n") if line]
    header = next(i for i, line in enumerate(lines) if line.startswith("raw_text,"))
    rows = []
    for row in csv.reader(lines[header + 1 :]):
        if len(row) > 44:
            row = [",".join(row[: len(row) - 43]), *row[len(row) - 43 :]]
        rows.append(row)
    return rows


def _decode_all(reports: list[str]) -> tuple[dict[int, MetarReport], list[str]]:
    decoded: dict[int, MetarReport] = {}
    failures: list[str] = []
    for i, text in enumerate(reports):
        try:
            decoded[i] = decode_metar(text)
        except MetarError as e:
            failures.append(f"{text!r}: {e}")
    return decoded, failures


def _assert_decode_rate(
    reports: list[str], decoded: dict[int, MetarReport], failures: list[str]
) -> None:
    rate = len(decoded) / len(reports)
    assert rate >= 0.99, f"decoded {rate:.2%}; first failures: {failures[:10]}"
    for report in decoded.values():
        WeatherState().apply(report.to_patch())


@needs_corpus
def test_noaa_cycle_file_decodes() -> None:
    reports = _cycle_reports()
    assert len(reports) == 1500  # records in the file, duplicates included
    decoded, failures = _decode_all(reports)
    _assert_decode_rate(reports, decoded, failures)
    assert failures == []


@needs_corpus
@pytest.mark.parametrize("name", sorted(CSV_FILES))
def test_awc_cache_csv_decodes_and_agrees_with_awc(name: str) -> None:
    rows = _csv_rows(name)
    assert len(rows) == CSV_FILES[name]
    assert all(len(row) == 44 for row in rows)
    reports = [row[0] for row in rows]
    decoded, failures = _decode_all(reports)
    _assert_decode_rate(reports, decoded, failures)
    if name.startswith("awc_cache_2026"):  # the only vintage whose raw_text names the type
        assert all(r.kind == rows[i][42] for i, r in decoded.items())

    temp_checked = temp_agree = wind_checked = wind_agree = 0
    disagreements: list[str] = []
    for i, report in decoded.items():
        temp_c, wind_kt = rows[i][5], rows[i][8]
        if temp_c and report.temperature_c is not None:
            temp_checked += 1
            if abs(float(temp_c) - report.temperature_c) <= 0.1:
                temp_agree += 1
            else:
                disagreements.append(f"temp {temp_c} vs {report.temperature_c}: {reports[i]}")
        if wind_kt and report.wind is not None:
            wind_checked += 1
            # AWC rounds MPS/KMH winds to whole knots.
            if abs(float(wind_kt) - mps_to_kt(report.wind.speed_mps)) <= 0.5 + 1e-9:
                wind_agree += 1
            else:
                disagreements.append(f"wind {wind_kt} kt vs {report.wind}: {reports[i]}")
    assert temp_checked >= 0.8 * len(rows) and wind_checked >= 0.8 * len(rows)
    assert temp_agree >= 0.98 * temp_checked, disagreements[:10]
    assert wind_agree >= 0.98 * wind_checked, disagreements[:10]
