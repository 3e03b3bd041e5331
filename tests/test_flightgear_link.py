"""The sockets to FlightGear (wxsky/inputs/flightgear_link.py; issue 18), over real loopback
sockets: pose lines in on UDP, counted and dropped as they deserve; the weather out to a
props server as `set` lines, only what changed, everything again after a reconnect, and a
FlightGear that is not there yet (or stops answering) never holding up the caller. The peer
here is a plain socket that records what it is sent; the FlightGear end to end test runs fgfs
itself (tests/test_flightgear_fgfs.py, when it is installed)."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from wxsky.inputs.flightgear_link import FlightGearPose, FlightGearWeather
from wxsky.protocols.flightgear import FgPose, weather_properties
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

GOOD = (
    "21.3245000,-157.9251000,1500.00,90.000,2.500,-1.000,90.000,-5.000,55.00,12.0,"
    "21.3245000,-157.9251000,1504.00,1,2026-07-15T13:30:00"
)


def _until(check: Callable[[], bool], timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_pose_lines_arrive_and_bad_ones_are_counted() -> None:
    got: list[FgPose] = []
    with FlightGearPose("127.0.0.1", 0, got.append) as pose:
        out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            out.sendto(GOOD.encode() + b"\n", pose.address)
            out.sendto(GOOD.replace("21.3245000", "nan").encode(), pose.address)
            out.sendto(b"\x00\xff garbage", pose.address)
            # Two lines in one datagram (FlightGear's frames bunched up).
            later = GOOD.replace("13:30:00", "13:30:01")
            out.sendto(f"{GOOD}\n{later}\n".encode(), pose.address)
            _until(lambda: pose.stats.messages == 3 and pose.stats.errors == 2)
        finally:
            out.close()
        assert [p.time_utc.second for p in got] == [0, 0, 1]
        assert pose.last_pose == got[-1]
        status = pose.stats.to_dict()
        assert status["kind"] == "flightgear" and status["ok"] is True
        assert status["last_pose"]["view_heading_deg"] == 0.0
        assert "not ASCII" in pose.stats.last_error or "fields" in pose.stats.last_error
    pose.close()  # idempotent


class _PropsPeer:
    """A listening TCP socket that records the lines each connection sends."""

    def __init__(self) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.lines: list[list[str]] = []
        self._conn: socket.socket | None = None
        self._thread = threading.Thread(target=self._accept, daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        try:
            conn, _ = self.server.accept()
        except OSError:
            return
        self._conn = conn
        mine: list[str] = []
        self.lines.append(mine)
        buf = b""
        while True:
            try:
                data = conn.recv(65536)
            except OSError:
                return
            if not data:
                return
            buf += data
            *done, buf = buf.split(b"\r\n")
            # FlightGear answers a `get` (the writer's liveness probe) with the value.
            gets = [d for d in done if d.startswith(b"get ")]
            if gets:
                with contextlib.suppress(OSError):
                    conn.sendall(b"12.5\r\n" * len(gets))
            mine.extend(d.decode() for d in done if not d.startswith(b"get "))

    def drop(self) -> None:
        """The connection goes, as when FlightGear quits; a new one is then accepted."""
        assert self._conn is not None
        self._conn.shutdown(socket.SHUT_RDWR)  # the FIN FlightGear's exit sends
        self._conn.close()
        self._thread.join(2.0)
        self._thread = threading.Thread(target=self._accept, daemon=True)
        self._thread.start()

    def close(self) -> None:
        self.server.close()
        if self._conn is not None:
            with contextlib.suppress(OSError):
                self._conn.shutdown(socket.SHUT_RDWR)
            self._conn.close()


@pytest.fixture
def peer():
    p = _PropsPeer()
    yield p
    p.close()


def test_the_weather_is_written_then_only_what_changes(peer: _PropsPeer) -> None:
    state = WeatherState().apply(load_preset("thunderstorm"))
    props = weather_properties(state)
    with FlightGearWeather("127.0.0.1", peer.port, min_interval_s=0.05) as fg:
        fg.offer(state)
        _until(lambda: bool(peer.lines) and len(peer.lines[0]) >= 3 + len(props))
        first = peer.lines[0]
        assert first[:3] == [
            "data",
            "set /environment/params/metar-updates-environment 0",
            "set /environment/config/enabled 0",
        ]
        assert first[3:] == [f"set {p} {v}" for p, v in props]
        _until(lambda: fg.stats.ok)  # at the first answer to its probe
        assert fg.stats.messages == len(props)
        fg.offer(state)  # the same weather: nothing to write
        clearer = dataclasses.replace(state, visibility_m=9000.0)
        fg.offer(clearer)
        _until(lambda: any("9000" in line for line in first[3 + len(props) :]))
        written = first[3 + len(props) :]
        assert all("visibility-m 9000" in line for line in written)
        assert len(written) == 1 + 1 + 3  # the layer's, the boundary's and three aloft
        # FlightGear restarts: the writer reconnects and writes everything again.
        peer.drop()
        fg.offer(clearer)
        _until(lambda: len(peer.lines) == 2 and len(peer.lines[1]) >= 3 + len(props))
        assert peer.lines[1][0] == "data"
        _until(lambda: fg.stats.ok)
    assert fg.stats.detail["last_write"]["properties"] == len(props)


def test_a_props_server_that_reads_nothing_is_not_ok(caplog: pytest.LogCaptureFixture) -> None:
    """Issue 40: a props server that accepts and then reads nothing took every write into
    the socket buffers and stayed `ok: true`. Now `ok` waits for an answer to the writer's
    probe (`get`), and one unanswered for `reply_timeout_s` is an error with the reason, the
    connection ended and tried again, `ok` false throughout."""
    mute = socket.create_server(("127.0.0.1", 0))  # connections complete; nothing is read
    port = mute.getsockname()[1]
    state = WeatherState().apply(load_preset("thunderstorm"))
    try:
        with (
            caplog.at_level(logging.WARNING, logger="wxsky.inputs.flightgear_link"),
            FlightGearWeather("127.0.0.1", port, min_interval_s=0.05, reply_timeout_s=0.5) as fg,
        ):
            for _ in range(50):  # the weather keeps changing: writes keep going out
                fg.offer(dataclasses.replace(state, visibility_m=5000.0 + _))
            _until(lambda: fg.stats.errors >= 2)  # judged mute, reconnected, judged again
            assert not fg.stats.ok
            assert "answered nothing" in fg.stats.last_error
            assert f"127.0.0.1:{port}" in fg.stats.last_error
            assert fg.stats.detail["connected"] == f"127.0.0.1:{port}"
        lines = [r.getMessage() for r in caplog.records if "answered nothing" in r.getMessage()]
        assert len(lines) == 1, lines  # once, not per reconnect
    finally:
        mute.close()


def test_a_flightgear_not_there_is_retried_and_never_holds_up_the_caller() -> None:
    with socket.socket() as probe:  # a port nothing listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    state = WeatherState().apply(load_preset("thunderstorm"))
    fg = FlightGearWeather("127.0.0.1", port, min_interval_s=0.05)
    try:
        # Offers only hand the writer thread the latest weather: none waits for the network
        # (whose failures below happen on the writer's thread, after the offers returned).
        for _ in range(100):
            fg.offer(state)
        _until(lambda: fg.stats.errors >= 2)  # tried, backed off, tried again
        assert not fg.stats.ok
        assert f"127.0.0.1:{port}" in fg.stats.last_error
        assert "\n" not in fg.stats.last_error
    finally:
        # Woken from its back-off, the writer ends (the wait only catches a hang).
        fg.close(wait_s=60.0)
    assert not fg._thread.is_alive()
    fg.close()


@pytest.mark.gl
def test_a_daemon_follows_flightgears_pose_and_writes_it_the_weather(
    tmp_path: Path, peer: _PropsPeer
) -> None:
    """`wxsky run --flightgear-pose ... --flightgear ...`: pose lines move the camera (the
    place, the view's direction and field of view), bad ones are counted in the status, and
    the applied weather reaches the props server."""
    from daemon_harness import running_daemon

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        pose_port = probe.getsockname()[1]
    args = (
        "--preset",
        "thunderstorm",
        "--flightgear-pose",
        f"udp:127.0.0.1:{pose_port}",
        "--flightgear",
        f"tcp:127.0.0.1:{peer.port}",
    )
    with running_daemon(tmp_path, args=args) as d:
        site = WeatherState().apply(load_preset("thunderstorm")).observer
        # 0.01 degrees north of the site, 1,500 ft, heading 090 with the view 90 left: north.
        line = (
            f"{site.lat_deg + 0.01:.7f},{site.lon_deg:.7f},1500.00,90.000,0.000,0.000,"
            f"90.000,-5.000,55.00,1400.0,{site.lat_deg + 0.01:.7f},{site.lon_deg:.7f},"
            "1500.00,1,2026-07-22T15:00:00\n"
        )
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:

            def status() -> dict[str, Any]:
                with d.client() as c:
                    return c.call("status")

            def moved() -> bool:
                out.sendto(line.encode(), ("127.0.0.1", pose_port))
                out.sendto(b"nan,1,2\n", ("127.0.0.1", pose_port))
                cam = status()["camera"]
                return abs(cam["position_m"][1] - 1112.0) < 20.0

            _until(moved)

            def pose_input() -> dict[str, Any]:
                inputs = {i["name"]: i for i in status()["inputs"]}
                return inputs["flightgear:pose"]

            # The bad line sent after the good one may still be on its way when the camera
            # has moved (a busy CI machine): wait for it to be counted, not for a time.
            _until(lambda: pose_input()["errors"] >= 1)
        s = status()
        cam = s["camera"]
        assert cam["heading_deg"] == pytest.approx(0.0, abs=1e-6)
        assert cam["pitch_deg"] == pytest.approx(-5.0)
        assert cam["fov_deg"] == pytest.approx(55.0)
        assert cam["position_m"][2] == pytest.approx(1500.0 * 0.3048, abs=0.01)
        inputs = {i["name"]: i for i in s["inputs"]}
        pose = inputs["flightgear:pose"]
        assert pose["kind"] == "flightgear" and pose["messages"] >= 1 and pose["errors"] >= 1
        assert "fields" in pose["last_error"]
        _until(lambda: bool(peer.lines) and len(peer.lines[0]) > 10)
        assert peer.lines[0][0] == "data"
        assert "set /environment/clouds/layer[2]/coverage broken" in peer.lines[0]
        _until(lambda: {i["name"]: i for i in status()["inputs"]}["flightgear:weather"]["ok"])


def test_a_far_pose_makes_a_new_site_on_flightgears_ground_and_its_clock_can_rule() -> None:
    """The part's handling of one pose, in process: Honolulu, far from the preset's Zurich,
    becomes the site at FlightGear's terrain height (not Zurich's 432 m: a descent over the
    sea would go below wxsky's ground), the camera where FlightGear's view is, and with
    clock = flightgear, FlightGear's UTC."""
    from wxsky.app.control import camera_from_params
    from wxsky.app.flightgear_part import FlightGearPart
    from wxsky.app.parts import PartContext
    from wxsky.engine.stages import SkyEngine
    from wxsky.protocols.flightgear import parse_pose
    from wxsky.scene.camera import Camera
    from wxsky.scene.layout import SceneSettings
    from wxsky.settings.config import FlightGearSection

    state = WeatherState().apply(load_preset("fair-cumulus"))
    with SkyEngine(state, Camera((0.0, 0.0, 500.0)), SceneSettings(), clock_rate=0.0) as e:

        def set_camera(params: dict[str, Any]) -> None:
            e.set_camera(camera_from_params(e, params, (960, 540)))

        part = FlightGearPart(FlightGearSection(clock="flightgear"))
        asyncio.run(part.start(PartContext(e, set_camera=set_camera)))  # no sockets to open
        pose = parse_pose(GOOD).pose
        assert pose is not None
        part._on_pose(pose)
        obs = e.target.observer
        assert (obs.lat_deg, obs.lon_deg) == (pose.lat_deg, pose.lon_deg)
        assert obs.alt_m == pytest.approx(12.0 * 0.3048)
        cam = e.camera
        assert cam.position_m[2] == pytest.approx(1504.0 * 0.3048)  # the pilot's eye
        assert (cam.heading_deg, cam.fov_deg) == (pytest.approx(0.0), 55.0)
        assert e.state.time_utc == pose.time_utc
        assert e.shared().aircraft_m is None  # the pilot's eye: no split
        assert part.inputs() == []  # no sockets asked for: no inputs to list
        # A chase view 100 m south of the aircraft and 100 ft below: the camera there, looking
        # at the aircraft, which is where the near layer is split.
        chase = GOOD.replace(
            "21.3245000,-157.9251000,1504.00,1,", "21.3235954,-157.9251000,1400.00,0,"
        )
        pose = parse_pose(chase).pose
        assert pose is not None
        part._on_pose(pose)
        cam = e.camera
        assert cam.position_m[1] == pytest.approx(-100.0, abs=0.1)
        assert cam.position_m[2] == pytest.approx(1400.0 * 0.3048)
        assert cam.heading_deg == pytest.approx(0.0, abs=0.01) and cam.roll_deg == 0.0
        aircraft = e.shared().aircraft_m
        assert aircraft is not None
        assert aircraft == pytest.approx((0.0, 0.0, 1500.0 * 0.3048), abs=0.01)


def test_a_preset_kept_at_the_site_comes_through_the_transition() -> None:
    """`apply_preset` with keep_site (the default while FlightGear places the camera): the
    preset's weather here, in this sky's cloud field, reached through the transition; without
    it, the preset's own site and seed, a different sky at once."""
    from wxsky.app.control import apply_preset
    from wxsky.engine.stages import SkyEngine
    from wxsky.scene.camera import Camera
    from wxsky.scene.layout import SceneSettings
    from wxsky.weather.transition import TransitionRates

    start = WeatherState().apply(load_preset("fair-cumulus"))
    here = dataclasses.replace(start.observer, lat_deg=21.3245, lon_deg=-157.9251, alt_m=4.0)
    with SkyEngine(
        dataclasses.replace(start, observer=here),
        Camera((0.0, 0.0, 500.0)),
        SceneSettings(),
        rates=TransitionRates(),  # the daemon's defaults
    ) as e:
        apply_preset(e, {"name": "overcast-stratus"}, (), keep_site=True)
        stratus = load_preset("overcast-stratus")
        assert e.target.observer == here and e.target.seed == start.seed
        # Nor its clock: overcast-stratus's 11:00Z would be 1 a.m. here.
        assert e.state.time_utc == start.time_utc
        assert [lay.type for lay in e.target.layers] == [lay.type for lay in stratus.layers or ()]
        assert not e.settled and e.state.layers == start.layers  # on its way, not there
        apply_preset(e, {"name": "overcast-stratus", "keep_site": False}, ())
        assert e.target.observer == stratus.observer and e.target.seed == stratus.seed
        assert e.settled and e.state.layers == e.target.layers  # a new sky: at once
        assert e.state.time_utc == stratus.time_utc
