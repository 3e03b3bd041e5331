"""The clock's valid range (issue 40, attack 1): `weather.state.EARLIEST_UTC` (1900-01-01)
up to `LATEST_UTC` (2200-01-01, exclusive), checked at every input that sets time, and
clamped wherever the clock is computed ahead or behind.

Before, a clock at 9999-12-31T23:59:58Z killed the daemon (`ValueError: year 10000 is out of
range` from the sun and moon smoothing, which looks 2 s ahead) from control `set_time`, a CIGI
Celestial Sphere Control and a FlightGear pose. Here each time input gets the range's ends and
just beyond, against a real daemon where it has one: control, CIGI over UDP, FlightGear's pose
over UDP with the clock following FlightGear, NMEA over a pty, a preset file; CAN's date and
METAR report times through their decoders. The daemon refuses each bad time with one line,
keeps its clock, counts the error on that input, and keeps publishing frames."""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Callable, Iterator
from datetime import UTC, date, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from cockpit_helpers import Pty
from daemon_harness import HANG_S, RunningDaemon, running_daemon

from wxsky.host.client import RemoteError
from wxsky.inputs.cigi_link import CigiHostSocket
from wxsky.protocols.cigi import encode_datagram, make
from wxsky.protocols.nmea import sentence
from wxsky.weather.state import EARLIEST_UTC, LATEST_UTC, parse_time_utc, time_in_range

END = "9999-12-31T23:59:58Z"  # the attack: 2 s before datetime's last second
LAST_GOOD = "2199-12-31T23:59:59Z"
FIRST_BAD = "2200-01-01T00:00:00Z"
NORMAL = "2026-06-21T12:00:00Z"


def _until(check: Callable[[], bool], what: str, timeout_s: float = HANG_S) -> None:
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


# -- the range and what computes ahead --------------------------------------------------------


def test_the_range_has_two_ends_and_every_parsed_time_is_inside_it() -> None:
    from wxsky.weather.state import LAST_UTC

    assert time_in_range(EARLIEST_UTC) and time_in_range(LAST_UTC)
    assert not time_in_range(LATEST_UTC)
    assert not time_in_range(EARLIEST_UTC - timedelta(microseconds=1))
    assert parse_time_utc("1900-01-01T00:00:00Z") == EARLIEST_UTC
    assert parse_time_utc(LAST_GOOD) == datetime(2199, 12, 31, 23, 59, 59, tzinfo=UTC)
    for text in (END, FIRST_BAD, "1899-12-31T23:59:59Z", "0001-01-01T00:00:00Z"):
        with pytest.raises(ValueError, match="outside the clock's range") as info:
            parse_time_utc(text)
        assert "\n" not in str(info.value)


def test_what_computes_ahead_or_behind_stays_inside_the_range() -> None:
    from wxsky.weather.state import LAST_UTC, clamped_time

    assert clamped_time(LAST_UTC, 2.0) == LAST_UTC
    assert clamped_time(EARLIEST_UTC, -2.0) == EARLIEST_UTC
    assert clamped_time(EARLIEST_UTC, 1e300) == LAST_UTC
    assert clamped_time(LAST_UTC, -1e300) == EARLIEST_UTC
    assert clamped_time(LAST_UTC, float("inf")) == LAST_UTC
    assert clamped_time(LAST_UTC, float("-inf")) == EARLIEST_UTC
    assert clamped_time(LAST_UTC, float("nan")) == LAST_UTC
    start = datetime(2026, 1, 1, tzinfo=UTC)
    assert clamped_time(start, 60.0) == start + timedelta(seconds=60)


def test_the_sun_and_moon_smoothing_never_looks_past_datetimes_years() -> None:
    """It worked out exact places every 2 s and interpolated: 9999-12-31T23:59:58.5Z asked for
    year 10000. Near either end of datetime's years it now works the moment out exactly."""
    from wxsky.scene.ephemeris import sun_and_moon, sun_and_moon_smooth

    for when in (
        datetime(9999, 12, 31, 23, 59, 58, 500_000, tzinfo=UTC),
        datetime(9999, 12, 31, 23, 59, 59, 999_999, tzinfo=UTC),
        datetime(1, 1, 1, 0, 0, 0, 500_000, tzinfo=UTC),
    ):
        sun, moon = sun_and_moon_smooth(when, 47.46, 8.55)
        exact_sun, exact_moon = sun_and_moon(when, 47.46, 8.55)
        assert sun.elevation_deg == pytest.approx(exact_sun.elevation_deg)
        assert moon.azimuth_deg == pytest.approx(exact_moon.azimuth_deg)


def test_the_engine_refuses_a_time_outside_and_its_clock_stops_at_the_end(
    caplog: pytest.LogCaptureFixture,
) -> None:
    from wxsky.engine.stages import SkyEngine
    from wxsky.scene.camera import Camera
    from wxsky.scene.layout import SceneSettings
    from wxsky.weather.state import LAST_UTC, WeatherState

    with SkyEngine(WeatherState(), Camera((0.0, 0.0, 500.0)), SceneSettings(), 0.0) as engine:
        before = engine.state.time_utc
        for text in (END, FIRST_BAD):
            with pytest.raises(ValueError, match="outside the clock's range"):
                engine.set_time(datetime.fromisoformat(text))
            assert engine.state.time_utc == before
        engine.set_time(parse_time_utc(LAST_GOOD), rate=10_000.0)
        with caplog.at_level("WARNING", logger="wxsky.engine.stages"):
            engine.run_weather(3.0)  # 30,000 s of sim time asked for: 1 s was left
            engine.run_weather(3.0)
        assert engine.state.time_utc == LAST_UTC and engine.clock_at_end
        ends = [r for r in caplog.records if "end of its range" in r.getMessage()]
        assert len(ends) == 1  # one line, not one a frame
        # The towers' epochs are moved back by a drift as long as you like, and stay inside.
        engine.drift_for(1e15)
        engine.set_time(parse_time_utc(NORMAL), rate=1.0)
        engine.run_weather(1.0)
        assert engine.state.time_utc == parse_time_utc(NORMAL) + timedelta(seconds=1)


# -- decoders without a daemon here: CAN's date, NMEA's, METAR report times --------------------


def test_a_can_date_outside_the_range_is_rejected_with_one_line() -> None:
    from wxsky.protocols.canaerospace import DATE_ID, CanasDecoder, encode_date

    cases = (
        (date(9999, 12, 31), False),
        (date(2200, 1, 1), False),
        (date(1899, 12, 31), False),
        (date(2199, 12, 31), True),
        (date(1900, 1, 1), True),
    )
    for day, ok in cases:
        got = CanasDecoder().decode(DATE_ID, encode_date(day))
        if ok:
            assert got.update is not None and got.update.date_utc == day
        else:
            assert got.update is None and got.error
            assert "outside the clock's years 1900..2199" in got.error
            assert "\n" not in got.error


def test_a_cockpit_time_of_day_past_the_end_leaves_the_clock() -> None:
    """A time of day alone lands on the day nearest the sky's clock: just after midnight
    with the clock at the range's last second is the day after the range's last."""
    from wxsky.weather.cockpit import CockpitUpdate, clock_target

    sky = parse_time_utc(LAST_GOOD)
    assert clock_target(sky, CockpitUpdate(time_of_day_s=10.0, time_resolution_s=1.0)) is None
    # Earlier that day it is taken as usual.
    assert clock_target(sky, CockpitUpdate(time_of_day_s=86_000.0)) == datetime(
        2199, 12, 31, 23, 53, 20, tzinfo=UTC
    )


def test_a_metar_report_dated_outside_the_range_is_not_used() -> None:
    from wxsky.inputs.metar_input import ingest
    from wxsky.weather.feeds import parse_feed

    xml = (
        "<response><data><METAR><raw_text>LSZH 311200Z 27010KT 9999 FEW030 15/05 Q1013"
        "</raw_text><station_id>LSZH</station_id><observation_time>{t}</observation_time>"
        "</METAR></data></response>"
    )
    for stamp, used in (("9999-12-31T12:00:00Z", False), ("2199-12-31T12:00:00Z", True)):
        feed = parse_feed(xml.format(t=stamp), format="awc-xml", name="test.xml")
        got = ingest(feed, {})
        assert (got.accepted == 1) is used, got.problems
        if not used:
            assert any("outside the clock's years" in p for p in got.problems)
            assert got.stations == {}


@pytest.mark.parametrize("command", ["sun", "snapshot"])
@pytest.mark.parametrize("when", [END, FIRST_BAD, "1899-12-31T23:59:59Z"])
def test_a_command_line_time_outside_the_range_is_a_usage_error(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, command: str, when: str
) -> None:
    from wxsky.cli import main

    args = {
        "sun": ["sun", "--lat", "47.46", "--lon", "8.55", "--time", when],
        "snapshot": [
            "snapshot",
            "--preset",
            "clear",
            "--time",
            when,
            "--out",
            str(tmp_path / "x.png"),
        ],
    }[command]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("wxsky: error: --time"), err
    assert "outside the clock's range" in err[0]
    assert not (tmp_path / "x.png").exists()


def test_allow_from_is_checked_by_the_settings_checker(tmp_path: Path) -> None:
    """[flightgear] allow_from (new) and [cigi] allow_from (before: only when the daemon
    opened its socket) name the file, line and key of an item that is no address."""
    from wxsky.errors import ConfigError
    from wxsky.settings.config import FlightGearSection, load_config

    path = tmp_path / "wxsky.toml"
    for table in ("flightgear", "cigi"):
        path.write_text(f'[{table}]\nallow_from = ["127.0.0.1/32", "10.0.0.300"]\n')
        with pytest.raises(ConfigError) as info:
            load_config(path)
        message = str(info.value)
        assert f"{path}:2: {table}.allow_from" in message and "'10.0.0.300'" in message
    path.write_text('[flightgear]\nallow_from = ["192.0.2.0/24", "::1"]\n')
    assert load_config(path).flightgear.allow_from == ("192.0.2.0/24", "::1")
    assert FlightGearSection().allow_from == ("127.0.0.0/8", "::1")  # loopback by default


# -- a real daemon: control, CIGI, FlightGear, NMEA, a preset file ----------------------------

pytestmark = pytest.mark.xdist_group("time_range")  # one daemon for the module's tests

FAR_PRESET = """
description = "A day at the end of the clock's range"
time_utc = "{time}"
layers = []
"""


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@pytest.fixture(scope="module")
def pty() -> Iterator[Pty]:
    p = Pty()
    yield p
    p.close()


@pytest.fixture(scope="module")
def daemon(tmp_path_factory: pytest.TempPathFactory, pty: Pty) -> Iterator[RunningDaemon]:
    tmp = tmp_path_factory.mktemp("time_range")
    presets = tmp / "presets"
    presets.mkdir()
    (presets / "end-of-days.toml").write_text(FAR_PRESET.format(time=END))
    (presets / "first-bad.toml").write_text(FAR_PRESET.format(time=FIRST_BAD))
    (presets / "last-good.toml").write_text(FAR_PRESET.format(time=LAST_GOOD))
    pose_port = _free_udp_port()
    config = f"""
[camera]
width = 320
height = 180
[presets]
dirs = ["{presets}"]
[flightgear]
pose = "udp:127.0.0.1:{pose_port}"
clock = "flightgear"
allow_from = ["127.0.0.1/32"]
"""
    args = ("--preset", "clear", "--cigi", "udp:127.0.0.1:0", "--serial", pty.path)
    with running_daemon(tmp, config, args) as d:
        yield d


def _status(d: RunningDaemon) -> dict[str, Any]:
    with d.client() as c:
        result: dict[str, Any] = c.call("status")
    return result


def _input(st: dict[str, Any], kind: str) -> dict[str, Any]:
    found = [i for i in st["inputs"] if i["kind"] == kind and not i["name"].endswith("weather")]
    assert len(found) == 1, st["inputs"]
    return found[0]


def _call(d: RunningDaemon, method: str, params: dict[str, Any]) -> Any:
    with d.client() as c:
        return c.call(method, params)


def _refused(d: RunningDaemon, method: str, params: dict[str, Any]) -> str:
    with pytest.raises(RemoteError) as info:
        _call(d, method, params)
    message = str(info.value)
    assert "\n" not in message
    return message


def _set_normal_clock(d: RunningDaemon) -> None:
    _call(d, "set_time", {"time_utc": NORMAL, "rate": 1.0})


def _frames_go_on(d: RunningDaemon, count: int = 10) -> None:
    start = _status(d)["frames_published"]
    _until(lambda: _status(d)["frames_published"] >= start + count, f"{count} more frames")
    assert d.proc.poll() is None, d.log()


@pytest.mark.gl
def test_control_set_time_at_the_ends_of_the_range(daemon: RunningDaemon) -> None:
    _set_normal_clock(daemon)
    errors = _input(_status(daemon), "control")["errors"]
    for text in (END, FIRST_BAD, "1899-12-31T23:59:59Z"):
        message = _refused(daemon, "set_time", {"time_utc": text})
        assert message.startswith("set_time: time_utc:") and "outside the clock's range" in message
    st = _status(daemon)
    assert st["weather"]["time_utc"].startswith("2026-06-21")
    control = _input(st, "control")
    assert control["errors"] == errors + 3 and "1899-12-31" in control["last_error"]
    _frames_go_on(daemon)
    # The last second of the range is taken, and a clock at the highest rate runs up to the
    # end and stops there, one log line, while the frames go on.
    ends = daemon.log().count("reached the end of its range")
    _call(daemon, "set_time", {"time_utc": LAST_GOOD, "rate": 10_000.0})
    _until(
        lambda: daemon.log().count("reached the end of its range") > ends, "the clock at the end"
    )
    _frames_go_on(daemon, 30)
    st = _status(daemon)
    assert st["weather"]["time_utc"] == LAST_GOOD  # 2199-12-31T23:59:59.999999
    assert st["clock_at_end"] is True and st["clock_rate"] == 10_000.0
    assert daemon.log().count("reached the end of its range") == ends + 1
    _set_normal_clock(daemon)
    assert _status(daemon)["clock_at_end"] is False
    _frames_go_on(daemon)


@pytest.mark.gl
def test_a_preset_file_with_a_time_outside_the_range(daemon: RunningDaemon) -> None:
    _set_normal_clock(daemon)
    for name in ("end-of-days", "first-bad"):
        message = _refused(daemon, "apply_preset", {"name": name, "keep_site": False})
        assert "time_utc" in message and "outside the clock's range" in message, message
    assert _status(daemon)["weather"]["time_utc"].startswith("2026-06-21")
    _call(daemon, "apply_preset", {"name": "last-good", "keep_site": False, "now": True})
    _until(
        lambda: _status(daemon)["weather"]["time_utc"].startswith("2199-12-31"),
        "the preset's time",
    )
    _frames_go_on(daemon)
    _call(daemon, "apply_preset", {"name": "clear", "keep_site": False, "now": True})
    _set_normal_clock(daemon)


@pytest.mark.gl
def test_a_cigi_celestial_sphere_control_dated_31_december_9999(daemon: RunningDaemon) -> None:
    _set_normal_clock(daemon)
    cigi = _input(_status(daemon), "cigi")
    host, port = cigi["listen"].rsplit(":", 1)
    before_messages, before_errors = cigi["messages"], cigi["errors"]
    # wxsky's encoder refuses the date as its decoder does: the packet is made with the
    # range's last day, then given 31 December 9999 byte by byte, as a hostile host would.
    celestial = make(
        "celestial_sphere_control",
        hour=23,
        minute=59,
        date_time_valid=1,
        ephemeris_enable=1,
        date_mmddyyyy=12_31_2199,
    )
    data = bytearray(
        encode_datagram([make("ig_control", ig_mode=1, host_frame_number=1), celestial], "big")
    )
    at = 24  # after IG Control
    assert data[at] == 9 and struct.unpack_from(">I", data, at + 8) == (12_31_2199,)
    struct.pack_into(">I", data, at + 8, 12_31_9999)
    with CigiHostSocket((host, int(port))) as ig_host:
        ig_host.send_bytes(bytes(data))

        def counted() -> bool:
            now = _input(_status(daemon), "cigi")
            return bool(now["messages"] > before_messages and now["errors"] > before_errors)

        _until(counted, "the CIGI datagram taken and its date counted as an error")
    st = _status(daemon)
    cigi = _input(st, "cigi")
    assert "year 9999 is outside the clock's years 1900..2199" in cigi["last_error"]
    assert cigi["dropped"].get("out_of_range", 0) >= 1
    assert st["weather"]["time_utc"].startswith("2026-06-21")
    _frames_go_on(daemon, 30)


def _pose_line(gmt: str) -> bytes:
    return (
        "47.4647000,8.5492000,1500.00,90.000,0.000,0.000,0.000,-5.000,55.00,1400.0,"
        f"47.4647000,8.5492000,1500.00,1,{gmt}\n"
    ).encode()


def _pose_port(d: RunningDaemon) -> int:
    text = d.log()
    marker = "FlightGear pose stream on udp:127.0.0.1:"
    assert marker in text, text
    return int(text.split(marker, 1)[1].split()[0])


@pytest.mark.gl
def test_a_flightgear_pose_with_a_gmt_outside_the_range(daemon: RunningDaemon) -> None:
    """With the clock following FlightGear: before, a pose with gmt 9999-12-31T23:59:58
    ended the daemon within a second."""
    _set_normal_clock(daemon)
    port = _pose_port(daemon)
    before = _input(_status(daemon), "flightgear")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        out.sendto(_pose_line(END[:-1]), ("127.0.0.1", port))
        out.sendto(_pose_line(FIRST_BAD[:-1]), ("127.0.0.1", port))
        _until(
            lambda: _input(_status(daemon), "flightgear")["errors"] >= before["errors"] + 2,
            "both poses counted as errors",
        )
        pose = _input(_status(daemon), "flightgear")
        assert "pose gmt 2200-01-01T00:00:00 is outside the clock's range" in pose["last_error"]
        assert pose["messages"] == before["messages"]
        assert _status(daemon)["weather"]["time_utc"].startswith("2026-06-21")
        _frames_go_on(daemon)
        # The range's last second is FlightGear's to set.
        out.sendto(_pose_line(LAST_GOOD[:-1]), ("127.0.0.1", port))
        _until(
            lambda: _status(daemon)["weather"]["time_utc"].startswith("2199-12-31T23:59:5"),
            "FlightGear's clock taken",
        )
    _frames_go_on(daemon)
    _set_normal_clock(daemon)


@pytest.mark.gl
def test_a_pose_from_an_address_outside_allow_from_is_dropped_and_counted(
    daemon: RunningDaemon,
) -> None:
    """allow_from = ["127.0.0.1/32"]: 127.0.0.2 is loopback too, yet not allowed."""
    _set_normal_clock(daemon)
    port = _pose_port(daemon)
    before = _input(_status(daemon), "flightgear")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
        try:
            stranger.bind(("127.0.0.2", 0))
        except OSError as exc:
            pytest.skip(f"cannot bind 127.0.0.2 here: {exc}")
        stranger.sendto(_pose_line("2100-01-01T00:00:00"), ("127.0.0.1", port))
        _until(
            lambda: _input(_status(daemon), "flightgear")["not_allowed"] > before["not_allowed"],
            "the stranger's datagram counted",
        )
    pose = _input(_status(daemon), "flightgear")
    assert pose["messages"] == before["messages"]
    assert pose["errors"] == before["errors"] + 1
    assert "from 127.0.0.2:" in pose["last_error"] and "not in allow_from" in pose["last_error"]
    assert _status(daemon)["weather"]["time_utc"].startswith("2026-06-21")  # not 2100


@pytest.mark.gl
def test_nmea_zda_dates_outside_the_range(daemon: RunningDaemon, pty: Pty) -> None:
    """ZDA carries a four-digit year; RMC's two digits always land within 50 years of the
    reference year, inside the range."""
    _set_normal_clock(daemon)
    before = _input(_status(daemon), "serial")
    pty.write(sentence("GPZDA,235958.00,31,12,9999,00,00"))
    pty.write(sentence("GPZDA,000000.00,01,01,2200,00,00"))
    pty.write(sentence("GPZDA,235959.00,31,12,1899,00,00"))
    _until(
        lambda: _input(_status(daemon), "serial")["errors"] >= before["errors"] + 3,
        "three dates counted as errors",
    )
    serial = _input(_status(daemon), "serial")
    assert "1899-12-31 is outside the clock's years 1900..2199" in serial["last_error"]
    assert _status(daemon)["weather"]["time_utc"].startswith("2026-06-21")
    pty.write(sentence("GPZDA,235959.00,31,12,2199,00,00"))
    _until(
        lambda: _status(daemon)["weather"]["time_utc"].startswith("2199-12-31T23:59:5"),
        "the cockpit's last good second taken",
    )
    _frames_go_on(daemon)
    _set_normal_clock(daemon)
