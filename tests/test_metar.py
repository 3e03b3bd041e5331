"""The single-report METAR decoder group by group: every group kind and its values.

The API contract (never raises, partial reports, to_dict, the measured defects of other
decoders, corpora) is in test_metar_api.py; cloud layers in test_metar_clouds.py.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime

import pytest

from wxsky.units import INHG_TO_HPA, KT_TO_MPS, STATUTE_MILE_TO_M, mps_to_kt
from wxsky.weather.metar import Metar, MetarSkyGroup, decode
from wxsky.weather.metar_clouds import metar_to_patch
from wxsky.weather.state import Source

FT = 0.3048
SM = STATUTE_MILE_TO_M


def dec(text: str) -> Metar:
    return decode(text, year=2025, month=7)


def body(groups: str) -> Metar:
    """Decodes groups placed after a fixed header, so each test names only what it checks."""
    return dec(f"KXYZ 261550Z {groups}")


# --- header -----------------------------------------------------------------------------------


def test_header_fields() -> None:
    r = dec("METAR KBDN 262135Z AUTO 36007KT 10SM CLR 16/03 A3008 RMK AO2")
    assert (r.station, r.type) == ("KBDN", "METAR")
    assert r.time_utc == datetime(2025, 7, 26, 21, 35, tzinfo=UTC)
    assert r.auto and not r.cor and not r.nil
    assert r.errors == () and not r.partial


def test_speci_prefix_and_bare_report() -> None:
    assert dec("SPECI CYBW 201519Z 15006KT 1SM OVC002 00/00 A2978").type == "SPECI"
    bare = dec("EGLL 010000Z 23008KT 9999 NCD 18/13 Q1018")
    assert (bare.type, bare.auto) == ("METAR", False)


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
    r = dec(text)
    assert r.cor
    assert r.wind is not None and r.visibility_m is not None
    assert r.errors == ()


def test_nil_report() -> None:
    r = dec("KXYZ 261555Z NIL")
    assert r.nil and r.wind is None and r.visibility_m is None
    assert not r.partial and r.trend == "" and r.remarks == ""
    assert dec("KXYZ 261555Z NIL RMK X").remarks == ""
    patch = metar_to_patch(r, field_elevation_m=0.0)
    assert patch.source is Source.METAR
    assert (patch.layers, patch.wind, patch.present_weather, patch.qnh_hpa) == (None,) * 4


def test_time_takes_year_and_month_from_the_caller() -> None:
    text = "KXYZ 311550Z 27010KT 10SM CLR 20/10 A3000"
    assert decode(text, year=2025, month=7).time_utc == datetime(2025, 7, 31, 15, 50, tzinfo=UTC)
    june = decode(text, year=2025, month=6)
    assert june.time_utc is None and june.partial
    assert june.errors == ("group 2 '311550Z': day 31 does not exist in 2025-06",)
    assert june.wind is not None and june.altimeter_hpa is not None  # the body still decodes
    leap = decode("KXYZ 291550Z 27010KT", year=2024, month=2)
    assert leap.time_utc == datetime(2024, 2, 29, 15, 50, tzinfo=UTC)
    assert decode("KXYZ 291550Z 27010KT", year=2025, month=2).time_utc is None


def test_time_group_without_z_is_accepted() -> None:
    r = dec("HAAB 261600 18005KT 9999 FEW030 18/12 Q1025")
    assert r.time_utc == datetime(2025, 7, 26, 16, 0, tzinfo=UTC)
    assert r.errors == ()


@pytest.mark.parametrize(
    ("text", "year", "month", "expected"),
    [
        ("KXYZ 261560Z 27010KT", 2025, 7, datetime(2025, 7, 26, 16, 0)),
        ("KXYZ 262360Z 27010KT", 2025, 7, datetime(2025, 7, 27, 0, 0)),
        ("KXYZ 262400Z 27010KT", 2025, 7, datetime(2025, 7, 27, 0, 0)),
        ("KXYZ 262460Z 27010KT", 2025, 7, datetime(2025, 7, 27, 1, 0)),
        ("KXYZ 302400Z 27010KT", 2025, 6, datetime(2025, 7, 1, 0, 0)),
        ("KXYZ 312400Z 27010KT", 2025, 12, datetime(2026, 1, 1, 0, 0)),
        ("KXYZ 282400Z 27010KT", 2024, 2, datetime(2024, 2, 29, 0, 0)),
        ("KXYZ 261560 27010KT", 2025, 7, datetime(2025, 7, 26, 16, 0)),  # no Z
        ("METAR COR KXYZ AUTO 261560Z 27010KT", 2025, 7, datetime(2025, 7, 26, 16, 0)),
    ],
)
def test_hour_24_and_minute_60_roll_over(
    text: str, year: int, month: int, expected: datetime
) -> None:
    r = decode(text, year=year, month=month)
    assert r.time_utc == expected.replace(tzinfo=UTC)
    group = next(t for t in text.split() if t[:1].isdigit())
    hhmm = f"{group[2:4]}:{group[4:6]}"
    assert r.errors == (
        f"group {text.split().index(group) + 1} {group!r}: {hhmm} read as "
        f"{expected:%Y-%m-%d %H:%M}Z",
    )
    assert r.partial and r.time_group == group
    assert r.wind is not None and r.require_usable() is r


@pytest.mark.parametrize(
    ("group", "reason"),
    [
        ("321550Z", "day 32 is not a day of any month"),
        ("001550Z", "day 00 is not a day of any month"),
        ("992359Z", "day 99 is not a day of any month"),
        ("262500Z", "25:00 is not a UTC time"),
        ("261561Z", "15:61 is not a UTC time"),
        ("262461Z", "24:61 is not a UTC time"),
        ("269999Z", "99:99 is not a UTC time"),
    ],
)
def test_impossible_time_keeps_the_report_and_its_body(group: str, reason: str) -> None:
    r = dec(f"KXYZ {group} 27010KT 9999 FEW030 20/10 Q1015")
    assert (r.station, r.time_utc, r.time_group) == ("KXYZ", None, group)
    assert r.errors == (f"group 2 {group!r}: {reason}; observation time unknown",)
    assert r.wind is not None and r.visibility_m == 10_000.0 and len(r.sky) == 1
    assert (r.temperature_c, r.altimeter_hpa) == (20.0, 1015.0)
    d = r.to_dict()
    assert (d["time_utc"], d["time_group"], d["partial"]) == (None, group, True)
    assert "time n/a" in r.describe()


@pytest.mark.parametrize("group", ["26155Z", "2615500Z", "26I550Z", "261550ZZ", "261550z", "Z"])
def test_a_garbled_time_group_is_no_time_group(group: str) -> None:
    r = dec(f"KXYZ {group} 27010KT 9999")
    assert (r.time_utc, r.time_group, r.wind) == (None, None, None)  # the body is not decoded
    assert r.errors == (
        f"group 2 {group!r}: expected the time group (ddhhmmZ) after station 'KXYZ'; "
        "the rest is not decoded",
    )


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
    assert r.errors == ()
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
    assert missing.wind is None and missing.errors == ()


def test_variable_wind_sector() -> None:
    w = body("24012G25KT 200V280 CAVOK").wind
    assert w is not None
    assert (w.dir_from_deg, w.variable_from_deg, w.variable_to_deg) == (240.0, 200.0, 280.0)


def test_wind_without_unit_only_where_the_wind_group_belongs() -> None:
    r = body("9999 04014 SCT030")  # after the visibility: not a wind group
    assert r.wind is None
    assert r.errors == ("group 4 '04014': unrecognised group",)
    gusty = body("36020G30 9999")
    assert gusty.wind is not None and gusty.wind.gust_mps == pytest.approx(30 * KT_TO_MPS)


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
def test_malformed_wind_is_an_error(group: str, reason: str) -> None:
    r = body(f"{group} 9999 20/10 Q1015")
    assert r.wind is None
    assert r.errors == (f"group 3 {group!r}: {reason}",)
    assert (r.visibility_m, r.temperature_c, r.altimeter_hpa) == (10_000.0, 20.0, 1015.0)


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
    assert r.errors == ()
    assert r.visibility_m == (None if metres is None else pytest.approx(metres))
    assert not r.cavok


@pytest.mark.parametrize(
    ("groups", "minimum_m", "direction"),
    [("9999 4000SE", 4000.0, "SE"), ("6000 1200NW", 1200.0, "NW"), ("4300 0900", 900.0, None)],
)
def test_directional_minimum_is_kept_apart_from_prevailing_visibility(
    groups: str, minimum_m: float, direction: str | None
) -> None:
    r = body(f"27010KT {groups} FEW030")
    assert r.errors == ()
    assert r.visibility_m == float(groups.split()[0].replace("9999", "10000"))
    assert (r.min_visibility_m, r.min_visibility_dir) == (minimum_m, direction)


def test_visibility_group_away_from_the_first_is_an_error() -> None:
    r = body("27010KT 9999 FEW030 4000SE")
    assert r.visibility_m == 10_000.0 and r.min_visibility_m is None
    assert r.errors == ("group 6 '4000SE': second visibility group ignored",)


def test_cavok_means_ten_km_and_no_cloud() -> None:
    r = dec("EVGA 201520Z 36008KT CAVOK 08/M02 Q1019 NOSIG")
    assert r.cavok and r.visibility_m == 10_000.0
    assert r.sky == () and r.sky_clear is None
    patch = metar_to_patch(r, field_elevation_m=100.0)
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
    assert r.errors == ()


def test_several_weather_groups_keep_their_order() -> None:
    r = body("27010KT 1SM -RA BR VV002 00/00 A2978")
    assert r.weather == ("-RA", "BR")
    assert metar_to_patch(r, field_elevation_m=0.0).present_weather == ("-RA", "BR")


@pytest.mark.parametrize("group", ["RERA", "RETSRA", "RE//", "NSW", "//"])
def test_recognised_weather_groups_that_add_nothing(group: str) -> None:
    r = body(f"27010KT 9999 FEW030 20/10 Q1015 {group}")
    assert r.weather == () and r.errors == ()


def test_malformed_weather_is_an_error() -> None:
    r = dec("KUNV 261553Z 00000KT 10SM VCTS-RA OVC026 25/23 A3013")
    assert r.weather == ()
    assert r.errors == ("group 5 'VCTS-RA': unrecognised group",)
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
    assert r.errors == ()


def test_vertical_visibility() -> None:
    r = dec("KSTF 231135Z AUTO 00000KT 1/2SM FG VV005 10/10 A3011 RMK AO2")
    assert [s.cover for s in r.sky] == ["VV"]
    assert r.sky[0].base_m == pytest.approx(152.4)
    unknown = body("00000KT 0100 FG VV///")
    assert unknown.sky == (MetarSkyGroup("VV", None),)


def test_cloud_without_base() -> None:
    r = dec("RJSN 262100Z 18005KT 9999 FEW050 SCT190 BKN/// 22/18 Q1010")
    assert r.sky[-1] == MetarSkyGroup("BKN", None)
    assert len(metar_to_patch(r, field_elevation_m=0.0).layers or ()) == 2


@pytest.mark.parametrize("code", ["CLR", "SKC", "NSC", "NCD"])
def test_explicit_clear_sky(code: str) -> None:
    r = body(f"27010KT 9999 {code} 20/10 Q1015")
    assert r.sky_clear == code and r.sky == ()
    assert metar_to_patch(r, field_elevation_m=0.0).layers == ()


def test_no_sky_group_leaves_layers_unknown() -> None:
    r = dec("K1EM 261555Z AUTO 27012KT 10SM M 19/14 A3000")
    assert r.sky == () and r.sky_clear is None and r.errors == ()
    assert metar_to_patch(r, field_elevation_m=0.0).layers is None


def test_truncated_cloud_group_is_an_error() -> None:
    r = dec("TLPC 262100Z 13007KT 9999 FEW02 BKN290 29/23 Q1012")
    assert r.errors == ("group 5 'FEW02': malformed cloud group",)
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
    assert r.errors == ()


def test_missing_temperature_group_does_not_block_a_later_one() -> None:
    r = dec("CWRH 262100Z AUTO ///// M04/ A2970 RMK SLP091")
    assert r.temperature_c == -4.0 and r.errors == ()


def test_remark_t_group_refines_temperatures_to_tenths() -> None:
    r = dec("KLQK 262135Z AUTO 05007KT 10SM OVC023 21/18 A3018 RMK AO2 T02070175")
    assert (r.temperature_c, r.dewpoint_c) == (20.7, 17.5)
    neg = dec("KW31 262115Z AUTO 01004KT 10SM CLR M39/M44 A3018 RMK AO1 T13861440")
    assert (neg.temperature_c, neg.dewpoint_c) == (-38.6, -44.0)
    no_dew = dec("KSEF 231115Z AUTO 35005KT 10SM CLR 17/ A3009 RMK AO2 T0171////")
    assert (no_dew.temperature_c, no_dew.dewpoint_c) == (17.1, None)


def test_remark_t_group_that_disagrees_with_the_body_is_ignored() -> None:
    # A real report whose body and remark disagree by 1.3 °C: the body group is kept.
    r = dec("KBYY 020035Z AUTO 15006KT 10SM CLR 23/17 A3000 RMK AO2 T02430174")
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
    assert r.altimeter_hpa == (None if hpa is None else pytest.approx(hpa))
    assert r.errors == ()


def test_altimeter_conversion_reference_value() -> None:
    r = body("A2992")
    assert r.altimeter_hpa == pytest.approx(1013.2, abs=0.05)


def test_q_group_wins_over_a_group() -> None:
    assert body("A2989 Q1012").altimeter_hpa == 1012.0
    assert body("Q1012 A2989").altimeter_hpa == 1012.0
    r = body("Q1012 A3012")  # 1020.0 hPa: the two disagree
    assert r.altimeter_hpa == 1012.0
    assert r.errors == ("group 4 'A3012': disagrees with the other pressure group (1012.0 hPa)",)


def test_second_group_of_the_same_pressure_kind_is_an_error() -> None:
    r = body("Q1012 Q1015")
    assert r.altimeter_hpa == 1012.0
    assert r.errors == ("group 4 'Q1015': second altimeter group ignored",)


# --- report structure -------------------------------------------------------------------------


def test_remarks_are_not_decoded_into_body_fields() -> None:
    r = dec("KXYZ 261550Z 27010KT 10SM CLR 20/10 A3000 RMK AO2 PK WND 27045/1520 36099KT")
    assert r.wind is not None and r.wind.speed_mps == pytest.approx(10 * KT_TO_MPS)
    assert r.remarks == "AO2 PK WND 27045/1520 36099KT"
    assert r.trend == "" and r.errors == ()


@pytest.mark.parametrize(
    "trend",
    [
        "NOSIG",
        "BECMG 35025KT 2000 +RA",
        "TEMPO 0500 FG OVC001",
        "FM0900 35025KT 2000",
        "INTER 0730/0830 5000 SHRA",
        "PROB30 TEMPO 1518 TSRA",
        "YLO 23010KT 4000 BR",  # a colour state closes the body
        "BLU BECMG WHT",
    ],
)
def test_trend_ends_the_body(trend: str) -> None:
    r = dec(f"EGLL 261550Z 24010KT 9999 FEW030 20/10 Q1015 {trend}")
    assert r.trend == trend
    assert r.wind is not None and r.wind.dir_from_deg == 240.0
    assert r.visibility_m == 10_000.0 and r.weather == ()
    assert [s.cover for s in r.sky] == ["FEW"]


def test_trend_and_remarks_together() -> None:
    r = dec("UIBB 262100Z 36003MPS P5000 FEW040CB M03/M06 Q1026 NOSIG RMK QFE726/0968")
    assert (r.trend, r.remarks) == ("NOSIG", "QFE726/0968")
    assert r.visibility_m == 5000.0


def test_end_of_report_mark() -> None:
    r = dec("CWFD 262129Z AUTO 01003KT 1/8SM OVC014 M05/ A2945= KXYZ 261550Z 18099KT")
    assert r.raw == "CWFD 262129Z AUTO 01003KT 1/8SM OVC014 M05/ A2945"
    assert r.wind is not None and r.wind.dir_from_deg == 10.0
    assert r.visibility_m == pytest.approx(SM / 8)


def test_second_report_glued_on_is_cut_off() -> None:
    r = dec("KAAA 261550Z 27010KT 10SM CLR 20/10 A3000 KBBB 261550Z 09050KT 1/4SM")
    assert r.visibility_m == pytest.approx(10 * SM)
    assert r.errors == ("group 8 'KBBB': a second report starts here; the rest is ignored",)
    assert r.trend == "" and r.remarks == ""
    typed = dec("MHLE 262100Z 20006KT 9999 SCT022TCU SCT024CB 20/17 METAR ")
    assert typed.temperature_c == 20.0 and typed.trend == ""
    assert typed.errors == ("group 8 'METAR': a second report starts here; the rest is ignored",)


def test_supplementary_groups_are_recognised() -> None:
    r = body(
        "27010KT 9999 R27/0900V1500U R09/P2000N FEW030 20/10 Q1015 WS R27 W16/S3 R29/290050 "
        "88CLRD95 RF00.0/000.0 BLU+ QFE871.6"
    )
    assert r.errors == ()
    assert r.rvr == ("R27/0900V1500U", "R09/P2000N")


def test_garbled_group_goes_to_errors_and_decoding_goes_on() -> None:
    r = dec("METAR KXYZ 261550Z 12O45KT 9999 FEW030 20/10 Q1015")
    assert r.errors == ("group 4 '12O45KT': malformed wind group",)
    assert r.wind is None
    assert (r.visibility_m, r.temperature_c, r.altimeter_hpa) == (10_000.0, 20.0, 1015.0)


def test_duplicate_group_is_an_error_and_the_first_wins() -> None:
    r = body("27010KT 9999 20/10 18/09 Q1015")
    assert r.temperature_c == 20.0
    assert r.errors == ("group 6 '18/09': second temperature group ignored",)


def test_negative_visibility_is_not_a_visibility() -> None:
    r = body("27010KT -1SM FEW030")
    assert r.visibility_m is None
    assert r.errors == ("group 4 '-1SM': malformed visibility group",)


def test_wind_shear_and_qfe_span_their_tokens() -> None:
    r = body("27010KT 9999 FEW030 20/10 Q1015 WS ALL RWY QFE 871.6")
    assert r.errors == ()
    bare = body("27010KT 9999 QFE")
    assert bare.errors == ("group 5 'QFE': unrecognised group",)


# --- describe ---------------------------------------------------------------------------------


def test_describe_names_the_decoded_values() -> None:
    text = dec("KXYZ 261550Z 24012KT 9999 FEW030CB 20/10 Q1015 NOSIG RMK X").describe()
    assert text.splitlines()[0] == "METAR KXYZ 2025-07-26 15:50Z"
    for part in ("240° 6.2 m/s (12 kt)", "10000 m", "FEW 914 m (3000 ft) CB", "20 °C / 10 °C"):
        assert part in text
    assert "1015.0 hPa" in text and "NOSIG" in text
    garbled = dec("KXYZ 261550Z 12O45KT").describe()
    assert "error: group 3 '12O45KT': malformed wind group" in garbled
    assert "minimum 4000 m SE" in body("9999 4000SE").describe()
    assert "(no station) time n/a" in decode("", year=2025, month=7).describe()


def test_to_dict_is_json_serialisable_for_every_group_kind() -> None:
    r = dec(
        "SPECI KXYZ 261550Z AUTO CCA VRB04G11KT 200V280 9999 4000SE R27/0900V1500U -SHRA "
        "FEW010 SCT030TCU BKN045CB VV/// 12/M01 Q1012 A2989 TEMPO 3000 RMK AO2 T01231011"
    )
    d = json.loads(json.dumps(r.to_dict()))
    assert d["type"] == "SPECI" and d["cor"] and d["auto"]
    assert d["rvr"] == ["R27/0900V1500U"]
    assert d["trend"] == "TEMPO 3000" and d["remarks"] == "AO2 T01231011"
    assert (d["temperature_c"], d["dewpoint_c"]) == (12.3, -1.1)
