"""NMEA 0183 decoding: the reference's checksummed examples, every sentence's fields, heading
sources, the MWD/MDA hold over MWV, wxsky's $PWXCL, and input that is broken in every way a
serial line breaks it (noise, truncation, over-long lines, bad checksums, odd chunking)."""

from __future__ import annotations

import random
from datetime import UTC, date, datetime
from functools import reduce

import numpy as np
import pytest

from wxsky.protocols.nmea import (
    LineSplitter,
    NmeaDecoder,
    NmeaSettings,
    OverlongLine,
    checksum,
    parse_frame,
    sentence,
)
from wxsky.protocols.result import Decoded
from wxsky.weather.cockpit import (
    DEWPOINT,
    QNH,
    TEMPERATURE,
    WIND_DIR,
    WIND_SPEED,
    CockpitUpdate,
    layer_key,
)
from wxsky.weather.state import CloudType

# protocols.md §3.2, with the checksums the reference gives.
MWV = "$WIMWV,270.0,T,12.5,M,A*15"
MWD = "$WIMWD,270.0,T,268.0,M,24.3,N,12.5,M*50"
MDA = "$WIMDA,29.92,I,1.0132,B,15.0,C,,C,65.0,,8.5,C,270.0,T,268.0,M,24.3,N,12.5,M*1B"
ZDA = "$GPZDA,134322.00,12,06,1987,00,00*61"
RMC = "$GPRMC,134322.00,A,4807.038,N,01131.000,E,0.0,0.0,120687,,,A*53"
EXAMPLES = (MWV, MWD, MDA, ZDA, RMC)

YEAR = 2026  # reference year for two-digit years, fixed so the tests do not age


def xor_hex(body: str) -> str:
    """The reference's checksum, independent of the code under test."""
    return f"{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def line(body: str) -> bytes:
    return f"${body}*{xor_hex(body)}\r\n".encode("ascii")


def decoder(**settings: object) -> NmeaDecoder:
    return NmeaDecoder(NmeaSettings(**settings), reference_year=YEAR)  # type: ignore[arg-type]


def decode(body: str, now_s: float = 0.0, **settings: object) -> Decoded:
    return decoder(**settings).decode_line(line(body), now_s)


def update_of(d: Decoded) -> CockpitUpdate:
    assert d.update is not None, f"expected an update, got {d}"
    assert not d.error and not d.ignored
    return d.update


def values_of(d: Decoded) -> dict[str, float | CloudType]:
    return dict(update_of(d).values)


def error_of(d: Decoded) -> str:
    assert d.error, f"expected an error, got {d}"
    assert d.update is None and not d.ignored
    assert "\n" not in d.error
    return d.error


def ignored_of(d: Decoded) -> str:
    assert d.ignored, f"expected ignored, got {d}"
    assert d.update is None and not d.error
    return d.ignored


# -- checksum and encoding --------------------------------------------------------------


@pytest.mark.parametrize("example", [*EXAMPLES, "$PWXCL,1,BKN,1200,600*13"])
def test_checksum_matches_reference_examples(example: str) -> None:
    body, given = example[1:].split("*")
    assert checksum(body) == given


def test_checksum_is_uppercase_two_digits() -> None:
    assert checksum("") == "00"
    assert checksum("A") == "41"
    assert checksum("GPZDA,0") == xor_hex("GPZDA,0")
    assert checksum("z") == "7A"  # upper case hex even for a letter digit


def test_sentence_round_trips() -> None:
    body = "WIMWV,123.4,T,5.6,N,A"
    raw = sentence(body)
    assert raw == f"${body}*{xor_hex(body)}\r\n".encode()
    frame = parse_frame(raw.rstrip(b"\r\n"))
    assert (frame.talker, frame.kind, frame.name) == ("WI", "MWV", "MWV")
    assert frame.fields == ("123.4", "T", "5.6", "N", "A")
    pwxcl = parse_frame(sentence("PWXCL,1,8,,").rstrip())
    assert (pwxcl.talker, pwxcl.kind, pwxcl.name) == ("P", "WXCL", "PWXCL")
    assert pwxcl.fields == ("1", "8", "", "")
    for example in EXAMPLES:
        assert sentence(example[1:].split("*")[0]).decode().rstrip() == example


@pytest.mark.parametrize("body", ["WIMWV,1*2", "WI$MWV", "GPZDA\r\n", "WIMWV,é", "AI!VDM"])
def test_sentence_refuses_reserved_and_non_ascii(body: str) -> None:
    with pytest.raises(ValueError):
        sentence(body)


# -- the reference examples -------------------------------------------------------------


def test_reference_mwv() -> None:
    assert values_of(decode(MWV[1:-3])) == {WIND_DIR: 270.0, WIND_SPEED: 12.5}
    d = decoder().decode_line(MWV, 0.0)
    assert values_of(d) == {WIND_DIR: 270.0, WIND_SPEED: 12.5}


def test_reference_mwv_with_sensor_heading_wraps_to_zero() -> None:
    d = decoder(sensor_heading_deg=90.0).decode_line(MWV, 0.0)
    assert values_of(d) == {WIND_DIR: 0.0, WIND_SPEED: 12.5}


def test_reference_mwd() -> None:
    assert values_of(decoder().decode_line(MWD, 0.0)) == {WIND_DIR: 270.0, WIND_SPEED: 12.5}


def test_reference_mda() -> None:
    v = values_of(decoder().decode_line(MDA, 0.0))
    assert v.keys() == {QNH, TEMPERATURE, DEWPOINT, WIND_DIR, WIND_SPEED}
    assert v[QNH] == pytest.approx(1013.2)  # the bar field wins over inHg (1013.21)
    assert v[TEMPERATURE] == 15.0
    assert v[DEWPOINT] == 8.5
    assert v[WIND_DIR] == 270.0
    assert v[WIND_SPEED] == 12.5


def test_reference_zda() -> None:
    u = update_of(decoder().decode_line(ZDA, 0.0))
    assert u.time_utc == datetime(1987, 6, 12, 13, 43, 22, tzinfo=UTC)
    assert u.time_resolution_s == pytest.approx(0.01)
    assert not u.values and u.position_deg is None


def test_reference_rmc() -> None:
    u = update_of(decoder().decode_line(RMC, 0.0))
    assert u.time_utc == datetime(1987, 6, 12, 13, 43, 22, tzinfo=UTC)
    assert u.position_deg is not None
    lat, lon = u.position_deg
    assert lat == pytest.approx(48 + 7.038 / 60)
    assert lon == pytest.approx(11 + 31.0 / 60)
    assert not u.values


def test_reference_pwxcl_with_cover_name_is_rejected() -> None:
    # The reference's draft gave FEW/SCT/BKN/OVC; the project's sentence takes oktas.
    d = decoder().decode_line("$PWXCL,1,BKN,1200,600*13", 0.0)
    assert error_of(d) == "PWXCL: field 2 (oktas) 'BKN' is not a number"


# -- MWV and headings -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("unit", "speed", "mps"),
    [("M", "12.5", 12.5), ("K", "36", 10.0), ("N", "10", 5.144444), ("S", "10", 4.4704)],
)
def test_mwv_speed_units(unit: str, speed: str, mps: float) -> None:
    v = values_of(decode(f"IIMWV,10,T,{speed},{unit},A"))
    assert v[WIND_SPEED] == pytest.approx(mps, rel=1e-6)
    assert v[WIND_DIR] == 10.0


def test_mwv_unknown_or_missing_speed_unit_is_an_error() -> None:
    assert "field 4 (speed unit) 'X'" in error_of(decode("WIMWV,10,T,5,X,A"))
    assert "field 4 (speed unit) ''" in error_of(decode("WIMWV,10,T,5,,A"))


def test_mwv_fixed_sensor_heading_is_added() -> None:
    assert values_of(decode("WIMWV,300,T,5,M,A", sensor_heading_deg=45.0))[WIND_DIR] == 345.0
    assert values_of(decode("WIMWV,300,T,5,M,A", sensor_heading_deg=90.0))[WIND_DIR] == 30.0


def test_mwv_empty_fields_omit_values() -> None:
    assert values_of(decode("WIMWV,,T,5,M,A")) == {WIND_SPEED: 5.0}
    assert values_of(decode("WIMWV,90,T,,,A")) == {WIND_DIR: 90.0}
    assert "no values" in ignored_of(decode("WIMWV,,T,,M,A"))


def test_mwv_relative_wind_ignored_unless_accepted() -> None:
    assert "relative" in ignored_of(decode("WIMWV,45,R,8,M,A"))
    v = values_of(decode("WIMWV,45,R,8,M,A", accept_relative_wind=True, sensor_heading_deg=10))
    assert v == {WIND_DIR: 55.0, WIND_SPEED: 8.0}


def test_mwv_invalid_status_ignored_and_bad_fields_rejected() -> None:
    assert "status V" in ignored_of(decode("WIMWV,45,T,8,M,V"))
    assert "status V" in ignored_of(decode("WIMWV,,T,,M,V"))  # invalid data is often empty
    assert "field 5 (status) 'X'" in error_of(decode("WIMWV,45,T,8,M,X"))
    assert "field 2 (reference) 'Q'" in error_of(decode("WIMWV,45,Q,8,M,A"))
    assert "field 1 (wind angle) 361°" in error_of(decode("WIMWV,361,T,8,M,A"))
    assert "field 1 (wind angle) -5°" in error_of(decode("WIMWV,-5,T,8,M,A"))
    assert "4 fields, expected at least 5" in error_of(decode("WIMWV,45,T,8,M"))


def test_mwv_with_hdt_heading() -> None:
    d = decoder(heading_source="hdt")
    assert "no HDT heading" in ignored_of(d.decode_line(line("WIMWV,30,T,5,M,A"), 0.0))
    consumed = d.decode_line(line("HEHDT,100.5,T"), 1.0)
    assert consumed == Decoded()
    assert values_of(d.decode_line(line("WIMWV,30,T,5,M,A"), 2.0))[WIND_DIR] == 130.5
    assert values_of(d.decode_line(line("WIMWV,300,T,5,M,A"), 11.0))[WIND_DIR] == 40.5
    # An HDG heading is not the configured source and does not refresh the HDT one.
    assert d.decode_line(line("HCHDG,200,,,,"), 11.0) == Decoded()
    assert "11.5 s old" in ignored_of(d.decode_line(line("WIMWV,30,T,5,M,A"), 12.5))
    d.decode_line(line("GPHDT,10,T"), 13.0)
    assert values_of(d.decode_line(line("WIMWV,30,T,5,M,A"), 13.5))[WIND_DIR] == 40.0
    assert d.stats.consumed == 3


@pytest.mark.parametrize(
    ("hdg", "true_deg"),
    [
        ("HCHDG,100,2,E,3,W", 99.0),
        ("HCHDG,350,,,15,E", 5.0),
        ("HCHDG,10,4.5,W,,", 5.5),
        ("HCHDG,123.4", 123.4),  # deviation and variation absent: 0
        ("HCHDG,5,,,10,W", 355.0),
    ],
)
def test_mwv_with_hdg_heading_deviation_and_variation(hdg: str, true_deg: float) -> None:
    d = decoder(heading_source="hdg")
    assert "no HDG heading" in ignored_of(d.decode_line(line("WIMWV,0,T,5,M,A"), 0.0))
    assert d.decode_line(line(hdg), 1.0) == Decoded()
    assert values_of(d.decode_line(line("WIMWV,0,T,5,M,A"), 1.5))[WIND_DIR] == pytest.approx(
        true_deg
    )


def test_heading_sentence_errors() -> None:
    assert "field 3 (deviation direction) 'X'" in error_of(decode("HCHDG,100,2,X,,"))
    assert "field 5 (variation direction) ''" in error_of(decode("HCHDG,100,,,2,"))
    assert "heading magnetic" in error_of(decode("HCHDG,400,,,,"))
    assert "field 2 (heading true unit) 'M'" in error_of(decode("HEHDT,100,M"))
    assert "no heading" in ignored_of(decode("HEHDT,,T"))


def test_mwv_without_angle_needs_no_heading() -> None:
    assert values_of(decode("WIMWV,,T,5,M,A", heading_source="hdt")) == {WIND_SPEED: 5.0}


def test_mwv_suppressed_after_geographic_wind() -> None:
    d = decoder()
    assert WIND_DIR in values_of(d.decode_line(line("WIMWD,200,T,,M,,N,4,M"), 100.0))
    assert "MWD/MDA gave wind 5.0 s ago" in ignored_of(d.decode_line(MWV, 105.0))
    assert "MWD/MDA" in ignored_of(d.decode_line(MWV, 109.9))
    assert values_of(d.decode_line(MWV, 110.1)) == {WIND_DIR: 270.0, WIND_SPEED: 12.5}
    # MDA wind holds MWV off too; MDA without wind (only pressure) does not.
    assert WIND_SPEED in values_of(d.decode_line(MDA, 200.0))
    assert ignored_of(d.decode_line(MWV, 205.0))
    only_qnh = "WIMDA,,I,1.02,B,,C,,C,,,,C,,T,,M,,N,,M"
    assert values_of(d.decode_line(line(only_qnh), 300.0)) == {QNH: pytest.approx(1020.0)}
    assert values_of(d.decode_line(MWV, 301.0))[WIND_SPEED] == 12.5


def test_geographic_wind_hold_is_a_setting() -> None:
    d = decoder(geographic_wind_hold_s=2.0)
    d.decode_line(MWD, 0.0)
    assert ignored_of(d.decode_line(MWV, 1.9))
    assert update_of(d.decode_line(MWV, 2.0))


# -- MWD and MDA ------------------------------------------------------------------------


def test_mwd_field_choice() -> None:
    # knots only: 19.4 kn
    assert values_of(decode("WIMWD,90,T,,M,19.4,N,,M"))[WIND_SPEED] == pytest.approx(9.98022, 1e-5)
    # m/s wins over knots even when they disagree
    assert values_of(decode("WIMWD,90,T,,M,19.4,N,3.0,M"))[WIND_SPEED] == 3.0
    # magnetic alone gives no direction: the variation is unknown
    assert values_of(decode("WIMWD,,T,80,M,,N,3.0,M")) == {WIND_SPEED: 3.0}
    assert values_of(decode("WIMWD,360,T,,,,,,")) == {WIND_DIR: 0.0}
    assert "no values" in ignored_of(decode("WIMWD,,T,,M,,N,,M"))


def test_mwd_errors() -> None:
    assert "field 7 (wind speed m/s) 'fast'" in error_of(decode("WIMWD,90,T,,M,,N,fast,M"))
    assert "field 8 (wind speed m/s unit) 'N'" in error_of(decode("WIMWD,90,T,,M,,N,3,N"))
    assert "7 fields, expected at least 8" in error_of(decode("WIMWD,90,T,,M,,N,3"))
    assert "wind speed 400 kn (205.778 m/s) out of range 0..150" in error_of(
        decode("WIMWD,90,T,,M,400,N,,M")
    )


def test_mda_field_choice_and_empties() -> None:
    inhg = "WIMDA,29.92,I,,B,,C,,C,,,,C,,T,,M,,N,,M"
    assert values_of(decode(inhg)) == {QNH: pytest.approx(29.92 * 33.8639, rel=1e-5)}
    knots = "WIMDA,,I,,B,-5.5,C,,C,,,-12,C,45,T,,M,10,N,,M"
    v = values_of(decode(knots))
    assert v == {
        TEMPERATURE: -5.5,
        DEWPOINT: -12.0,
        WIND_DIR: 45.0,
        WIND_SPEED: pytest.approx(5.144444, rel=1e-6),
    }
    assert "no values" in ignored_of(decode("WIMDA" + ",,I,,B,,C,,C,,,,C,,T,,M,,N,,M"))
    # a broken humidity field is not read, so it costs nothing
    assert values_of(decode("WIMDA,,I,,B,20,C,,C,wet,,,C,,T,,M,,N,,M")) == {TEMPERATURE: 20.0}


def test_mda_errors() -> None:
    assert "field 2 (pressure inHg unit) 'B'" in error_of(
        decode("WIMDA,29.92,B,,B,,C,,C,,,,C,,T,,M,,N,,M")
    )
    assert "pressure 0.5 bar (500 hPa) out of range 850..1100 hPa" in error_of(
        decode("WIMDA,,I,0.5,B,,C,,C,,,,C,,T,,M,,N,,M")
    )
    assert "air temperature 99 °C out of range -90..60" in error_of(
        decode("WIMDA,,I,,B,99,C,,C,,,,C,,T,,M,,N,,M")
    )
    assert "field 5 (air temperature) 'inf'" in error_of(
        decode("WIMDA,,I,,B,inf,C,,C,,,,C,,T,,M,,N,,M")
    )
    assert "19 fields, expected at least 20" in error_of(decode("WIMDA,,I,,B,,C,,C,,,,C,,T,,M,,N,"))


# -- ZDA and RMC ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("year_field", "reference_year", "year"),
    [
        ("2031", 2026, 2031),
        ("87", 2026, 1987),
        ("26", 2026, 2026),
        ("75", 2026, 2075),
        ("76", 2026, 1976),  # 50 years either way: the past
        ("05", 2090, 2105),
        ("99", 2001, 1999),
    ],
)
def test_zda_years(year_field: str, reference_year: int, year: int) -> None:
    d = NmeaDecoder(reference_year=reference_year)
    u = update_of(d.decode_line(line(f"GPZDA,010203,04,05,{year_field},,"), 0.0))
    assert u.time_utc == datetime(year, 5, 4, 1, 2, 3, tzinfo=UTC)
    assert u.time_resolution_s == 1.0


def test_zda_partial_and_fractional() -> None:
    u = update_of(decode("GPZDA,235959.5,31,12,2026"))
    assert u.time_utc == datetime(2026, 12, 31, 23, 59, 59, 500_000, tzinfo=UTC)
    assert u.time_resolution_s == pytest.approx(0.1)
    u = update_of(decode("GPZDA,120000.25,,,,,"))
    assert u.time_utc is None
    assert u.time_of_day_s == pytest.approx(43200.25)
    assert update_of(decode("GPZDA,,01,02,2027,,")).date_utc == date(2027, 2, 1)
    assert "no values" in ignored_of(decode("GPZDA,,,,,,"))
    assert "partly empty" in error_of(decode("GPZDA,120000,01,,2027,,"))
    assert "not 2 or 4 digits" in error_of(decode("GPZDA,120000,01,01,202,,"))


def test_leap_second_is_clamped() -> None:
    u = update_of(decode("GPZDA,235960,31,12,2016"))
    assert u.time_utc == datetime(2016, 12, 31, 23, 59, 59, 999_000, tzinfo=UTC)


@pytest.mark.parametrize(
    ("body", "reason"),
    [
        ("GPZDA,250000,01,01,2026", "hour 25 out of range 0..23"),
        ("GPZDA,126000,01,01,2026", "minute 60 out of range 0..59"),
        ("GPZDA,120061,01,01,2026", "second 61 out of range 0..60"),
        ("GPZDA,120000,32,01,2026", "day 32 out of range 1..31"),
        ("GPZDA,120000,00,01,2026", "day 0 out of range 1..31"),
        ("GPZDA,120000,01,13,2026", "month 13 out of range 1..12"),
        ("GPZDA,120000,29,02,2027", "2027-02-29 is not a calendar date"),
        ("GPZDA,12:00:00,01,01,2026", "is not hhmmss"),
        ("GPZDA,120000,1e1,01,2026", "field 2 (day) '1e1' is not a whole number"),
        ("GPRMC,250000,A,4807.0,N,01131.0,E,,,120687,,", "hour 25"),
        ("GPRMC,120000,A,4807.0,N,01131.0,E,,,320687,,", "day 32"),
        ("GPRMC,120000,A,4807.0,N,01131.0,E,,,121387,,", "month 13"),
        ("GPRMC,120000,A,4807.0,N,01131.0,E,,,300287,,", "1987-02-30 is not a calendar date"),
        ("GPRMC,120000,A,4807.0,N,01131.0,E,,,12061987,,", "is not ddmmyy"),
        ("GPRMC,120000,A,9100.0,N,01131.0,E,,,120687,,", "(latitude) 91° out of range 0..90"),
        ("GPRMC,120000,A,9000.6,N,01131.0,E,,,120687,,", "(latitude) 90.01°"),
        ("GPRMC,120000,A,4860.0,N,01131.0,E,,,120687,,", "minutes 60 out of range"),
        ("GPRMC,120000,A,4807.0,N,18100.0,E,,,120687,,", "(longitude) 181° out of range 0..180"),
        ("GPRMC,120000,A,4807.0,X,01131.0,E,,,120687,,", "(latitude side) 'X', expected N or S"),
        ("GPRMC,120000,A,4807.0,N,01131.0,,,,120687,,", "(longitude side) '', expected E or W"),
        ("GPRMC,120000,A,4807.0,NS,01131.0,E,,,120687,,", "(latitude side) 'NS'"),
        ("GPRMC,120000,A,4807.0,N,,,,,120687,,", "one is empty"),
        ("GPRMC,120000,A,48N07,N,01131.0,E,,,120687,,", "is not (d)ddmm.mmmm"),
        ("GPRMC,120000,,4807.0,N,01131.0,E,,,120687,,", "field 2 (status) ''"),
        ("GPRMC,120000,A,4807.0,N,01131.0,E,,", "8 fields, expected at least 9"),
    ],
)
def test_time_and_position_errors(body: str, reason: str) -> None:
    error = error_of(decode(body))
    assert error.startswith(body[2:5] + ": ")
    assert reason in error


def test_rmc_hemispheres_and_two_digit_year() -> None:
    u = update_of(decode("GNRMC,235959,A,3352.128,S,15112.558,W,0.1,,010100,12.0,E,A"))
    assert u.time_utc == datetime(2000, 1, 1, 23, 59, 59, tzinfo=UTC)
    assert u.time_resolution_s == 1.0
    assert u.position_deg is not None
    lat_deg, lon_deg = u.position_deg
    assert lat_deg == pytest.approx(-(33 + 52.128 / 60))
    assert lon_deg == pytest.approx(-(151 + 12.558 / 60))
    u = update_of(decode("GPRMC,000000,A,0000.000,N,00000.000,E,,,311299,,"))
    assert u.time_utc == datetime(1999, 12, 31, tzinfo=UTC)
    assert u.position_deg == (0.0, 0.0)


def test_rmc_status_v_ignored_and_empty_position() -> None:
    assert "status V" in ignored_of(decode("GPRMC,134322.00,V,,,,,,,120687,,,N"))
    u = update_of(decode("GPRMC,134322.00,A,,,,,,,120687,,,A"))
    assert u.position_deg is None
    assert u.time_utc == datetime(1987, 6, 12, 13, 43, 22, tzinfo=UTC)


# -- PWXCL ------------------------------------------------------------------------------


def test_pwxcl_full() -> None:
    v = values_of(decode("PWXCL,2,5.5,3000,2000,STRATOCUMULUS"))
    assert v == {
        layer_key(2, "cover_oktas"): 5.5,
        layer_key(2, "base_m"): pytest.approx(914.4),
        layer_key(2, "thickness_m"): pytest.approx(609.6),
        layer_key(2, "type"): CloudType.STRATOCUMULUS,
    }


@pytest.mark.parametrize(
    ("body", "cloud_type"),
    [
        ("PWXCL,1,8,1000,500", CloudType.NONE),
        ("PWXCL,1,8,1000,500,", CloudType.NONE),
        ("PWXCL,1,8,1000,500,cumulonimbus", CloudType.CUMULONIMBUS),
        ("PWXCL,1,8,1000,500,Cirrus", CloudType.CIRRUS),
    ],
)
def test_pwxcl_type(body: str, cloud_type: CloudType) -> None:
    v = values_of(decode(body))
    assert v[layer_key(1, "type")] is cloud_type
    assert v[layer_key(1, "cover_oktas")] == 8.0
    assert v[layer_key(1, "base_m")] == pytest.approx(304.8)
    assert v[layer_key(1, "thickness_m")] == pytest.approx(152.4)


def test_pwxcl_empty_fields_are_not_given() -> None:
    assert values_of(decode("PWXCL,3,,25000,")) == {
        layer_key(3, "base_m"): pytest.approx(7620.0),
        layer_key(3, "type"): CloudType.NONE,
    }
    assert values_of(decode("PWXCL,1,0,,,stratus")) == {
        layer_key(1, "cover_oktas"): 0.0,
        layer_key(1, "type"): CloudType.STRATUS,
    }
    assert values_of(decode("PWXCL,2,,-1000,,")) == {
        layer_key(2, "base_m"): pytest.approx(-304.8),
        layer_key(2, "type"): CloudType.NONE,
    }


@pytest.mark.parametrize(
    ("body", "reason"),
    [
        ("PWXCL,0,4,1000,500", "layer 0 out of range 1..3"),
        ("PWXCL,4,4,1000,500", "layer 4 out of range 1..3"),
        ("PWXCL,7,4,1000,500", "layer 7 out of range 1..3"),
        ("PWXCL,,4,1000,500", "field 1 (layer) is empty"),
        ("PWXCL,1.5,4,1000,500", "field 1 (layer) '1.5' is not a whole number"),
        ("PWXCL,1,9,1000,500", "layer 1 cover 9 oktas out of range 0..8"),
        ("PWXCL,1,-1,1000,500", "layer 1 cover -1 oktas out of range 0..8"),
        ("PWXCL,1,8.01,1000,500", "cover 8.01 oktas out of range"),
        ("PWXCL,1,nan,1000,500", "field 2 (oktas) 'nan' is not a number"),
        ("PWXCL,1,4,inf,500", "field 3 (base ft) 'inf' is not a number"),
        ("PWXCL,1,4,1000,0", "layer 1 thickness 0 ft (0 m) must be more than 0"),
        ("PWXCL,1,4,1000,-100", "thickness -100 ft (-30.48 m) out of range 0..25000 m"),
        ("PWXCL,1,4,90000,500", "layer 1 base 90000 ft (27432 m) out of range -500..25000 m"),
        ("PWXCL,1,4,1000,500,FOG", "field 5 (cloud type): unknown cloud type 'FOG'"),
        ("PWXCL,1,4,1000,500,none", "field 5 (cloud type) NONE"),
        ("PWXCL,1,4,1000", "3 fields, expected at least 4"),
        ("PWXCL,1", "1 fields, expected at least 4"),
        ("PWXCL,1,4,1000,500,CUMULUS,X", "6 fields, expected 4 or 5"),
    ],
)
def test_pwxcl_errors(body: str, reason: str) -> None:
    error = error_of(decode(body))
    assert error.startswith("PWXCL: ")
    assert reason in error


# -- framing ----------------------------------------------------------------------------


@pytest.mark.parametrize("talker", ["WI", "GP", "GN", "II", "HC", "YX"])
def test_any_two_letter_talker(talker: str) -> None:
    assert values_of(decode(f"{talker}MWV,90,T,3,M,A")) == {WIND_DIR: 90.0, WIND_SPEED: 3.0}


def test_unknown_sentences_are_ignored_not_errors() -> None:
    d = decoder()
    for body in ("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,", "PGRMZ,1,f,3"):
        assert "not used by wxsky" in ignored_of(d.decode_line(line(body), 0.0))
    assert "encapsulated" in ignored_of(
        d.decode_line(b"!AIVDM,1,1,,A,13aEOK?P00PD2wVMdLDRhgvL289?,0*26", 0.0)
    )
    assert d.stats.unknown == 3 and d.stats.ignored == 3 and d.stats.errors == 0


def test_checksum_case_and_errors() -> None:
    mda = b"$WIMDA,,I,,B,18,C,,C,,,,C,,T,,M,,N,,M*0"
    assert values_of(decoder().decode_line(mda + b"d", 0.0)) == {TEMPERATURE: 18.0}
    assert values_of(decoder().decode_line(mda + b"D", 0.0)) == {TEMPERATURE: 18.0}
    d = decoder()
    assert "bad checksum *16, computed 15" in error_of(d.decode_line(MWV.replace("*15", "*16"), 0))
    assert "bad checksum" in error_of(d.decode_line(MWV.replace("12.5", "12.6"), 0))
    assert "malformed checksum" in error_of(d.decode_line(MWV + "5", 0))
    assert "malformed checksum" in error_of(d.decode_line(MWV.replace("*15", "*G5"), 0))
    assert "malformed checksum" in error_of(d.decode_line(MWV.replace("*15", "*+5"), 0))
    assert d.stats.bad_checksum == 5 and d.stats.errors == 5


def test_missing_checksum_rejected_unless_allowed() -> None:
    bare = b"$WIMWV,270.0,T,12.5,M,A"
    assert "no checksum" in error_of(decoder().decode_line(bare, 0.0))
    d = decoder(allow_missing_checksum=True)
    assert values_of(d.decode_line(bare, 0.0)) == {WIND_DIR: 270.0, WIND_SPEED: 12.5}
    # A checksum that is there is still checked.
    assert "bad checksum" in error_of(d.decode_line(bare + b"*00", 0.0))


def test_text_before_dollar_is_ignored() -> None:
    d = decoder()
    for prefix in (b"2026-06-21T12:00:00.123Z ", b"[ 17.002] serial0: ", b"\xff\xfe junk", b"$GPZ"):
        assert values_of(d.decode_line(prefix + MWV.encode(), 0.0)) == {
            WIND_DIR: 270.0,
            WIND_SPEED: 12.5,
        }


@pytest.mark.parametrize(
    ("raw", "reason"),
    [
        (b"WIMWV,270.0,T,12.5,M,A*15", "no '$'"),
        (b"", "empty line"),
        (b"$WIMWV,270.0,T,12.\xb5,M,A*15", "byte 0xb5 18 after '$' is not printable ASCII"),
        (b"$WIMWV,270.0,T,12.5\x00,M,A*15", "byte 0x00"),
        (b"$wimwv,1*" + xor_hex("wimwv,1").encode(), "address 'wimwv'"),
        (b"$W1MWV,1*" + xor_hex("W1MWV,1").encode(), "address 'W1MWV'"),
        (b"$*00", "address ''"),
    ],
)
def test_malformed_lines(raw: bytes, reason: str) -> None:
    error = error_of(decoder().decode_line(raw, 0.0))
    assert error.startswith("NMEA: ")
    assert reason in error


def test_decode_line_accepts_str_and_a_trailing_line_end() -> None:
    d = decoder()
    assert values_of(d.decode_line(MWV, 0.0)) == values_of(d.decode_line(MWV + "\r\n", 0.0))
    assert "printable ASCII" in error_of(d.decode_line("$WIMWV,27°,T,12.5,M,A*15", 0.0))
    assert error_of(d.decode_line("$WIMWV,\udcff,T*15", 0.0))  # a lone surrogate


@pytest.mark.parametrize("example", [*EXAMPLES, "$PWXCL,1,8,1000,500,CUMULUS*05"])
def test_every_truncation_is_an_error(example: str) -> None:
    full = decoder().decode_line(example, 0.0)
    assert full.update is not None
    for n in range(len(example)):
        d = decoder().decode_line(example[:n], 0.0)
        assert d.error, f"prefix {example[:n]!r} gave {d}"
        assert d.update is None


@pytest.mark.parametrize("value", ["nan", "NaN", "inf", "-inf", "1e3", "1_0", " 5", "0x10", "--1"])
def test_non_decimal_numbers_rejected(value: str) -> None:
    assert "field 3 (wind speed)" in error_of(decode(f"WIMWV,10,T,{value},M,A"))


def test_out_of_range_wind() -> None:
    assert error_of(decode("WIMWV,10,T,999,M,A")).startswith(
        "MWV: wind speed 999 m/s out of range 0..150"
    )
    assert "wind speed 600 km/h (166.667 m/s) out of range" in error_of(
        decode("WIMWV,10,T,600,K,A")
    )
    assert "wind speed -1 m/s" in error_of(decode("WIMWV,10,T,-1,M,A"))
    big = "9" * 400  # more digits than a float holds
    assert "not a finite number" in error_of(decode(f"WIMWV,10,T,{big},M,A", max_line_bytes=1000))


# -- lines, chunks and noise ------------------------------------------------------------


def test_line_ends_cr_lf_crlf() -> None:
    d = decoder()
    bodies = [ZDA, MWD, MWV, RMC]
    stream = bodies[0] + "\r" + bodies[1] + "\n" + bodies[2] + "\r\n\r\n\n" + bodies[3] + "\n\r"
    out = d.feed(stream.encode(), 0.0)
    # MWV after MWD is held off, so compare with the same sentences decoded one by one.
    one_by_one = decoder()
    assert out == [one_by_one.decode_line(b, 0.0) for b in bodies]
    assert [r.update is not None for r in out] == [True, True, False, True]
    assert "MWD/MDA" in out[2].ignored
    assert d.stats.lines == 4


def test_chunked_feeding_matches_whole() -> None:
    good = [s.encode() + b"\r\n" for s in EXAMPLES]
    noise = [
        b"$WIMWV,1,T,2,M,A*00\n",
        b"garbage\r\n",
        b"x" * 300 + b"\n",
        line("PWXCL,2,6,5000,3000,altostratus"),
        line("HCHDG,10,1,E,2,E"),
        b"\n\n",
        b"ts=5 " + line("GPZDA,010101,01,01,26,,"),
    ]
    stream = b"".join(good + noise) + b"$GPZDA,134322.00,12,06,1987,00,00*61"
    whole = decoder()
    expected = whole.feed(stream, 0.0) + whole.flush()
    assert len(expected) == len(good) + 7  # "\n\n" is no line; the tail is flushed
    assert sum(r.error != "" for r in expected) == 3
    bytewise = decoder()
    got = [r for i in range(len(stream)) for r in bytewise.feed(stream[i : i + 1], 0.0)]
    assert got + bytewise.flush() == expected
    rng = random.Random(7)
    chunked = decoder()
    got, pos = [], 0
    while pos < len(stream):
        size = rng.randint(1, 40)
        got += chunked.feed(stream[pos : pos + size], 0.0)
        pos += size
    assert got + chunked.flush() == expected
    assert chunked.stats == whole.stats


def test_flush_decodes_the_unterminated_rest() -> None:
    d = decoder()
    assert d.feed(MWV.encode(), 5.0) == []
    out = d.flush()
    assert len(out) == 1 and values_of(out[0])[WIND_SPEED] == 12.5
    assert d.flush() == []


def test_ten_kilobyte_line_without_newline_is_one_error() -> None:
    d = decoder()
    out = []
    junk = b"A" * 10_000
    for i in range(0, len(junk), 512):
        out += d.feed(junk[i : i + 512], 0.0)
    assert len(out) == 1
    assert error_of(out[0]) == "NMEA: line longer than 256 bytes dropped"
    assert d.flush() == []  # the rest was discarded, and reported once
    out = d.feed(junk + b"\r\n" + MWV.encode() + b"\r\n", 1.0)
    assert len(out) == 2
    assert error_of(out[0])
    assert values_of(out[1]) == {WIND_DIR: 270.0, WIND_SPEED: 12.5}
    assert d.stats.overlong == 2 and d.stats.errors == 2 and d.stats.updates == 1


def test_line_splitter_never_holds_more_than_the_limit() -> None:
    splitter = LineSplitter(16)
    assert splitter.feed(b"x" * 16) == []
    assert splitter.feed(b"y") == [OverlongLine(16)]
    assert splitter.feed(b"z" * 100_000) == []
    assert splitter.flush() == b""
    assert splitter.feed(b"abc\r\n" + b"q" * 16 + b"\n" + b"r" * 17 + b"\rtail") == [
        b"abc",
        b"q" * 16,
        OverlongLine(16),
    ]
    assert splitter.flush() == b"tail"


def test_line_length_limit_is_a_setting() -> None:
    at_limit = line("PWXCL,1,8,1000,500,CUMULUS")
    n = len(at_limit) - 2
    assert update_of(decoder(max_line_bytes=n).feed(at_limit, 0.0)[0])
    out = decoder(max_line_bytes=n - 1).feed(at_limit, 0.0)
    assert [error_of(r) for r in out] == [f"NMEA: line longer than {n - 1} bytes dropped"]
    assert error_of(decoder(max_line_bytes=n - 1).decode_line(at_limit, 0.0))


def test_random_bytes_never_raise_nor_update() -> None:
    noise = np.random.default_rng(20260621).integers(0, 256, 64 * 1024, dtype=np.uint8).tobytes()
    d = decoder()
    out = []
    for i in range(0, len(noise), 777):
        out += d.feed(noise[i : i + 777], float(i))
    out += d.flush()
    assert len(out) > 200
    assert all(r.update is None and (r.error or r.ignored) for r in out)
    assert d.stats.errors + d.stats.ignored == d.stats.lines == len(out)
    assert d.stats.overlong > 0  # some stretches go 256 bytes without CR or LF
    # And noise does not break the stream: a good sentence after it decodes.
    after = d.feed(b"\n" + MWV.encode() + b"\n", 1e6)
    assert values_of(after[-1]) == {WIND_DIR: 270.0, WIND_SPEED: 12.5}


def test_random_printable_sentences_never_raise() -> None:
    # Noise shaped like sentences reaches the field interpreters, not only the framing.
    rng = random.Random(11)
    alphabet = "0123456789.,-+ABCDEFGHIJKLMNOPQRSTUVWXYZnaif "
    names = ["WIMWV", "WIMWD", "WIMDA", "GPZDA", "GPRMC", "HCHDG", "HEHDT", "PWXCL"]
    d = decoder(heading_source="hdg", accept_relative_wind=True)
    kinds = {"update": 0, "error": 0, "other": 0}
    for i in range(5000):
        body = rng.choice(names) + "," + "".join(rng.choices(alphabet, k=rng.randint(0, 60)))
        r = d.decode_line(line(body), i * 0.1)
        if r.update is not None:
            assert not r.update.empty
            kinds["update"] += 1
        elif r.error:
            kinds["error"] += 1
        else:
            kinds["other"] += 1
    assert kinds["error"] > 4000


def test_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="heading_source"):
        NmeaSettings(heading_source="gyro")
    with pytest.raises(ValueError, match="max_line_bytes"):
        NmeaSettings(max_line_bytes=0)
    with pytest.raises(ValueError, match="sensor_heading_deg"):
        NmeaSettings(sensor_heading_deg=float("nan"))
    with pytest.raises(ValueError, match="geographic_wind_hold_s"):
        NmeaSettings(geographic_wind_hold_s=-1.0)


def test_default_reference_year_is_this_year() -> None:
    this_year = datetime.now(UTC).year
    u = update_of(NmeaDecoder().decode_line(line(f"GPZDA,000000,01,01,{this_year % 100:02d}"), 0))
    assert u.time_utc is not None and u.time_utc.year == this_year
