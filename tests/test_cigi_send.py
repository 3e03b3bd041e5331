"""wxsky as a CIGI weather source (issue 15, item 3): what `host_message` makes of a weather
state, the status `weather` map back into a state, and `wxsky cigi send` against a fake
daemon (its control server in a thread) and a real one, with a UDP socket of the test's own as
the image generator. What a real daemon's weather is sent as is read back by Wireshark's CIGI
dissector (tshark), which shares nothing with wxsky's encoder."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from cigi_tshark_helpers import REL_TOL, TSHARK, decode_pcap, needs_tshark, number
from daemon_harness import running_daemon
from server_thread import ServerThread
from tool_loader import load_tool

from wxsky.protocols.cigi import Packet, decode_datagram, encode_datagram, make
from wxsky.protocols.cigi_source import PCT_PER_OKTA, SourceFrame, host_message
from wxsky.settings.presets import load_preset
from wxsky.weather.state import (
    CloudLayer,
    CloudType,
    Observer,
    PrecipKind,
    PrecipLayer,
    Provenance,
    Source,
    WeatherState,
    WindLayer,
    weather_from_dict,
    weather_to_dict,
)

pcap = load_tool("emulators/pcap")

T0 = datetime(2026, 7, 22, 15, 0, 0, tzinfo=UTC)
WEATHER_IDS = list(range(1, 8))  # cloud layers 1-3, precipitation 4-7


def state_with(**changes: Any) -> WeatherState:
    return dataclasses.replace(WeatherState(time_utc=T0), **changes)


def weather_controls(message: list[Packet]) -> dict[int, Packet]:
    controls = [p for p in message if p.key == "weather_control"]
    by_id = {int(p["layer_id"]): p for p in controls}
    assert sorted(by_id) == WEATHER_IDS and len(controls) == len(WEATHER_IDS)
    return by_id


# -- host_message -------------------------------------------------------------------------------


def test_of_four_cloud_layers_the_three_with_most_cover_go_sorted_by_base() -> None:
    layers = (
        CloudLayer(2.0, 600.0, 900.0, CloudType.CUMULUS),  # the least cover: left out
        CloudLayer(5.0, 1200.0, 1700.0, CloudType.STRATOCUMULUS),
        CloudLayer(3.0, 3000.0, 3400.0, CloudType.ALTOCUMULUS),
        CloudLayer(4.5, 8000.0, 8600.0, CloudType.CIRRUS),
    )
    by_id = weather_controls(host_message(state_with(layers=layers), SourceFrame()))
    sent = [(by_id[i]["cloud_type"], by_id[i]["coverage_pct"]) for i in (1, 2, 3)]
    assert sent == [
        (int(CloudType.STRATOCUMULUS), 5.0 * PCT_PER_OKTA),
        (int(CloudType.ALTOCUMULUS), 3.0 * PCT_PER_OKTA),
        (int(CloudType.CIRRUS), 4.5 * PCT_PER_OKTA),
    ]
    for layer_id, lay in zip((1, 2, 3), layers[1:], strict=True):
        p = by_id[layer_id]
        assert p["weather_enable"] == 1 and p["scope"] == 0
        assert p["base_elevation_m"] == pytest.approx(lay.base_m)
        assert p["thickness_m"] == pytest.approx(lay.thickness_m)


def test_layer_ids_without_weather_are_switched_off() -> None:
    one = (CloudLayer(6.0, 1100.0, 1700.0, CloudType.STRATOCUMULUS),)
    by_id = weather_controls(host_message(state_with(layers=one), SourceFrame()))
    assert {i: int(p["weather_enable"]) for i, p in by_id.items()} == {
        1: 1,
        2: 0,
        3: 0,
        4: 0,
        5: 0,
        6: 0,
        7: 0,
    }
    clear = weather_controls(host_message(state_with(), SourceFrame()))
    assert all(p["weather_enable"] == 0 for p in clear.values())


def test_light_rain_in_the_metar_weather_is_an_enabled_rain_layer_of_severity_1() -> None:
    layers = (CloudLayer(7.0, 1400.0, 2500.0, CloudType.NIMBOSTRATUS),)
    state = state_with(layers=layers, present_weather=("-RA", "BR"), visibility_m=4000.0)
    by_id = weather_controls(host_message(state, SourceFrame()))
    rain = by_id[int(PrecipKind.RAIN)]
    assert (rain["weather_enable"], rain["severity"]) == (1, 1)
    # From the observer up to the lowest cloud base, everywhere, as far as the METAR says.
    assert rain["base_elevation_m"] == pytest.approx(state.observer.alt_m)
    assert rain["thickness_m"] == pytest.approx(1400.0 - state.observer.alt_m)
    assert (rain["coverage_pct"], rain["visibility_m"]) == (100.0, 4000.0)
    assert [by_id[int(k)]["weather_enable"] for k in PrecipKind if k is not PrecipKind.RAIN] == [
        0,
        0,
        0,
    ]


def test_the_state_is_also_sent_as_time_and_atmosphere() -> None:
    state = state_with(qnh_hpa=1002.5, visibility_m=7000.0, temperature_c=21.0)
    message = host_message(state, SourceFrame(number=41, last_ig_frame=977))
    assert [p.key for p in message[:3]] == [
        "ig_control",
        "celestial_sphere_control",
        "atmosphere_control",
    ]
    ig, sky, air = message[:3]
    assert (ig["host_frame_number"], ig["last_ig_frame_number"]) == (41, 977)
    assert (sky["date_mmddyyyy"], sky["hour"], sky["minute"]) == (7_22_2026, 15, 0)
    assert sky["date_time_valid"] == 1
    assert air["visibility_m"] == 7000.0
    assert air["temperature_c"] == pytest.approx(21.0)  # at the observer
    assert air["pressure_hpa"] == pytest.approx(1002.5)


# -- the status weather map back into a state ---------------------------------------------------


def full_state() -> WeatherState:
    return WeatherState(
        observer=Observer(51.47, -0.4543, 25.0),
        time_utc=datetime(2026, 1, 5, 6, 7, 8, tzinfo=UTC),
        layers=(
            CloudLayer(2.625, 450.0, 700.0, CloudType.STRATUS),  # mid-transition: fractional
            CloudLayer(8.0, 1200.0, 3100.0, CloudType.NIMBOSTRATUS),
        ),
        wind=(
            WindLayer(35.0, 210.0, 7.5, 13.0, True),
            WindLayer(1500.0, 230.5, 15.25),
        ),
        visibility_m=2500.0,
        temperature_c=None,
        dewpoint_c=-1.5,
        qnh_hpa=998.0,
        present_weather=("+SHRASN", "BR"),
        precipitation=(
            PrecipLayer(PrecipKind.SNOW, 25.0, 1200.0, 60.0, 4, 1500.0),
            PrecipLayer(PrecipKind.RAIN, 300.0, 1200.0, 100.0, 2, 3000.0),
        ),
        seed=987654321,
        sources=Provenance(
            layers=Source.METAR, wind=Source.COCKPIT, precipitation=Source.CIGI, seed=Source.PRESET
        ),
    )


@pytest.mark.parametrize(
    "state",
    [full_state(), WeatherState(), WeatherState().apply(load_preset("thunderstorm"))],
    ids=["full", "default", "preset"],
)
def test_the_weather_map_turns_back_into_the_same_state(state: WeatherState) -> None:
    data = weather_to_dict(state)
    assert weather_from_dict(data) == state
    # As it comes over the control channel: plain data, nothing shared with the original.
    assert weather_from_dict(json.loads(json.dumps(data))) == state
    without_sources = {k: v for k, v in data.items() if k != "sources"}
    assert weather_from_dict(without_sources) == dataclasses.replace(state, sources=Provenance())


@pytest.mark.parametrize(
    ("change", "error"),
    [
        (
            {"layers": [{"cover_oktas": 3, "base_m": 900.0, "top_m": 800.0, "type": "stratus"}]},
            ValueError,
        ),
        (
            {"layers": [{"cover_oktas": 3, "base_m": 900.0, "top_m": 1800.0, "type": "fog"}]},
            ValueError,
        ),
        ({"precipitation": [{"kind": "frogs"}]}, KeyError),
        ({"time_utc": "noon"}, ValueError),
        ({"wind": None}, TypeError),
    ],
)
def test_a_map_that_is_not_weather_is_refused(change: dict[str, Any], error: type) -> None:
    with pytest.raises(error):
        weather_from_dict({**weather_to_dict(WeatherState()), **change})


# -- the command line ---------------------------------------------------------------------------


def _sigint_as_at_a_terminal() -> None:
    # A shell that runs the tests in the background (`&` without job control) starts them
    # with SIGINT ignored, and Python then installs no KeyboardInterrupt: Ctrl-C tests would
    # hang. A command typed at a terminal has the default.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def wxsky_process(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "wxsky", "cigi", "send", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_sigint_as_at_a_terminal,
    )


def run_send(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "wxsky", "cigi", "send", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        ((), "the following arguments are required: --to"),
        (
            ("--to", "udp:ig.local:8001"),
            "--to 'udp:ig.local:8001': 'ig.local' is not an IP address",
        ),
        (("--to", "tcp:127.0.0.1:8001"), "expected udp:HOST:PORT"),
        (("--to", "udp:127.0.0.1:0"), "not 0"),
        (("--to", "udp:127.0.0.1:8001", "--rate-hz", "0"), "--rate-hz 0 is outside 0.1..240"),
        (("--to", "udp:127.0.0.1:8001", "--rate-hz", "nan"), "--rate-hz nan is not a finite"),
        (("--to", "udp:127.0.0.1:8001", "--count", "0"), "--count 0 is outside"),
        (("--to", "udp:127.0.0.1:8001", "--count", "3", "--seconds", "1"), "not allowed with"),
        (("--to", "udp:127.0.0.1:8001", "--byte-order", "middle"), "invalid choice: 'middle'"),
        (("--to", "udp:127.0.0.1:8001", "--bind", "udp:127.0.0.1"), "--bind 'udp:127.0.0.1'"),
    ],
)
def test_usage_errors_exit_2_with_one_line(args: tuple[str, ...], needle: str) -> None:
    proc = run_send(*args)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wxsky: error: ") and needle in lines[0]
    assert proc.stdout == ""


def test_no_daemon_is_a_runtime_failure(tmp_path: Path) -> None:
    proc = run_send("--to", "udp:127.0.0.1:8001", "--control", f"unix:{tmp_path}/none.sock")
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f"wxsky: error: cannot connect to the wxsky daemon at unix:{tmp_path}/none.sock: "
        "No such file or directory; start one with `wxsky run`, or name the address it listens "
        "on with --control ADDR (its [output] control)"
    ]
    assert proc.stdout == ""


@contextlib.contextmanager
def fake_ig() -> Iterator[socket.socket]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(10.0)
    try:
        yield sock
    finally:
        sock.close()


def port_of(sock: socket.socket) -> int:
    return int(sock.getsockname()[1])


@contextlib.contextmanager
def fake_daemon(tmp_path: Path, state: WeatherState) -> Iterator[ServerThread]:
    async def handle(method: str, params: dict[str, Any]) -> Any:
        if method == "status":
            return {"weather": weather_to_dict(state)}
        raise ValueError(f"{method}: not in this fake")

    server = ServerThread(f"unix:{tmp_path}/ctl.sock", handle)
    try:
        yield server
    finally:
        server.stop()


def answer(ig: socket.socket, to: Any, ig_frame: int) -> None:
    """What an IG answers a host's message with: Start of Frame and one weather answer."""
    sof = make("start_of_frame", ig_mode=1, ig_frame_number=ig_frame)
    response = make(
        "weather_conditions_response",
        request_id=7,
        humidity_pct=55,
        temperature_c=12.5,
        visibility_m=9000.0,
        wind_speed_mps=4.0,
        wind_dir_deg=250.0,
        pressure_hpa=1009.0,
    )
    ig.sendto(encode_datagram([sof, response]), to)


def json_lines(text: str) -> list[dict[str, Any]]:
    return [json.loads(line) for line in text.splitlines()]


def test_follows_the_daemons_weather_and_clock_and_hears_the_ig(tmp_path: Path) -> None:
    before = state_with(layers=(CloudLayer(3.0, 900.0, 1300.0, CloudType.CUMULUS),))
    after = state_with(
        layers=(CloudLayer(7.0, 600.0, 900.0, CloudType.STRATUS),),
        visibility_m=1800.0,
        present_weather=("+SN",),
    )
    count = 6
    with fake_daemon(tmp_path, before) as daemon, fake_ig() as ig:
        proc = wxsky_process(
            "--to",
            f"udp:127.0.0.1:{port_of(ig)}",
            "--control",
            f"unix:{tmp_path}/ctl.sock",
            "--rate-hz",
            "10",
            "--count",
            str(count),
            "--byte-order",
            "little",
            "--json",
        )
        messages = []
        try:
            for k in range(1, count + 1):
                data, source = ig.recvfrom(65_535)
                decoded = decode_datagram(data)
                assert decoded.byte_order == "little" and not decoded.counts
                messages.append(list(decoded.packets))
                answer(ig, source, 1000 + k)
                if k == 2:
                    daemon.broadcast("weather", weather_to_dict(after))
                    daemon.broadcast("frame", {"time_utc": "2026-07-22T16:42:10.250000Z"})
            out, err = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert proc.returncode == 0, err
    assert err == ""
    frames = [(m[0]["host_frame_number"], m[0]["last_ig_frame_number"]) for m in messages]
    # Each message tells the IG the last of its frames the host heard of: the answer to a
    # message before it (the one just before, unless that answer was still on its way when
    # the next message left: on a loaded machine 100 ms is not always enough), never going
    # back; and most of them the one just before.
    assert [f[0] for f in frames] == list(range(1, count + 1))
    assert frames[0] == (1, 0)
    heard = [f[1] for f in frames]
    assert heard == sorted(heard)
    assert all(h == 0 or 1000 < h <= 1000 + k - 1 for k, h in frames[1:]), frames
    assert sum(h == 1000 + k - 1 for k, h in frames[1:]) >= (count - 1) // 2, frames
    first, last = weather_controls(messages[0]), weather_controls(messages[-1])
    assert first[1]["cloud_type"] == int(CloudType.CUMULUS)
    assert first[int(PrecipKind.SNOW)]["weather_enable"] == 0
    assert last[1]["cloud_type"] == int(CloudType.STRATUS)
    assert (last[1]["coverage_pct"], last[1]["base_elevation_m"]) == (87.5, 600.0)
    assert (
        last[int(PrecipKind.SNOW)]["weather_enable"],
        last[int(PrecipKind.SNOW)]["severity"],
    ) == (1, 5)
    assert messages[-1][2]["visibility_m"] == 1800.0
    sky = messages[-1][1]
    assert (sky["date_mmddyyyy"], sky["hour"], sky["minute"]) == (7_22_2026, 16, 42)
    lines = json_lines(out)
    final = lines[-1]
    assert final["sent"] == count and final["send_errors"] == 0
    assert (final["start_of_frame"], final["responses"], final["last_ig_frame"]) == (
        count,
        count,
        1000 + count,
    )
    assert final["last_response"]["request_id"] == 7
    assert final["last_response"]["visibility_m"] == 9000.0
    assert (final["weather_updates"], final["other"]) == (1, 0)
    assert final["time_utc"] == "2026-07-22T16:42:10Z"


def test_ctrl_c_prints_the_totals_and_exits_130(tmp_path: Path) -> None:
    with fake_daemon(tmp_path, state_with()), fake_ig() as ig:
        proc = wxsky_process(
            "--to", f"udp:127.0.0.1:{port_of(ig)}", "--control", f"unix:{tmp_path}/ctl.sock"
        )
        try:
            for _ in range(3):
                ig.recvfrom(65_535)
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["wxsky: interrupted"]
    lines = out.strip().splitlines()
    assert lines[0].startswith("sending the weather of the daemon at unix:")
    assert "30 messages a second, big-endian" in lines[0]
    assert lines[-1].startswith("sent ") and ", Start of Frame 0, last IG frame -," in lines[-1]
    assert lines[-1].endswith("last response none")


def test_a_daemon_that_goes_away_is_a_runtime_failure(tmp_path: Path) -> None:
    with fake_daemon(tmp_path, state_with()) as daemon, fake_ig() as ig:
        proc = wxsky_process(
            "--to",
            f"udp:127.0.0.1:{port_of(ig)}",
            "--control",
            f"unix:{tmp_path}/ctl.sock",
            "--seconds",
            "20",
        )
        try:
            ig.recvfrom(65_535)
            daemon.stop()
            _, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert proc.returncode == 1, err
    (line,) = err.strip().splitlines()
    assert line.startswith("wxsky: error: ") and "daemon" in line


# -- a real daemon's weather, read by Wireshark ------------------------------------------------


def shown(key: str, name: str) -> str:
    """The tshark field showing a table field (the one map, tests/cigi_tshark_helpers.py)."""
    field = TSHARK[key][name]
    assert isinstance(field, str)
    return field


def values(row: dict[str, list[str]], key: str, name: str) -> list[float]:
    return [number(v) for v in row[shown(key, name)]]


def close(got: list[float], want: list[float]) -> bool:
    return len(got) == len(want) and all(
        math.isclose(g, w, rel_tol=REL_TOL["f32"], abs_tol=1e-6)
        for g, w in zip(got, want, strict=True)
    )


CLOCK_STOPPED = """
[clock]
rate = 0.0
[camera]
width = 320
height = 180
"""


@pytest.mark.gl
@needs_tshark
def test_tshark_reads_the_daemons_weather_in_what_cigi_send_sends(tmp_path: Path) -> None:
    count = 3
    with (
        running_daemon(tmp_path, CLOCK_STOPPED, ("--preset", "thunderstorm")) as d,
        fake_ig() as ig,
    ):
        with d.client() as c:
            weather: dict[str, Any] = c.call("status")["weather"]
        proc = run_send(
            "--to", f"udp:127.0.0.1:{port_of(ig)}", "--control", d.address, "--count", str(count)
        )
        assert proc.returncode == 0, proc.stderr
        received = [ig.recvfrom(65_535) for _ in range(count)]
        ig_address = ("127.0.0.1", port_of(ig))
        with d.client() as c:
            assert c.call("status")["weather"] == weather, "the daemon's weather moved"
    datagrams = [
        pcap.Datagram(i / 1000, (str(src[0]), int(src[1])), ig_address, data)
        for i, (data, src) in enumerate(received)
    ]
    path = tmp_path / "cigi-send.pcap"
    pcap.write_pcap(path, datagrams)
    rows = decode_pcap(path, tmp_path)
    assert len(rows) == count

    when = datetime.fromisoformat(weather["time_utc"].replace("Z", "+00:00"))
    layers = sorted(weather["layers"], key=lambda lay: -lay["cover_oktas"])[:3]
    layers.sort(key=lambda lay: lay["base_m"])
    assert len(weather["layers"]) == 3 and weather["present_weather"] == ["+TSRA"]
    assert weather["precipitation"] == []
    observer_alt = weather["observer"]["alt_m"]
    wc = "weather_control"
    for k, row in enumerate(rows, 1):
        where = f"message {k}"
        assert row["_ws.expert.message"] == [] and row["_ws.malformed"] == [], where
        ids = [int(v) for v in row["cigi.packet_id"]]
        assert ids == [1, 9, 10] + [12] * 7, where
        assert values(row, "ig_control", "host_frame_number") == [k], where
        # the clock
        sky = "celestial_sphere_control"
        assert values(row, sky, "date_mmddyyyy") == [
            when.month * 1_000_000 + when.day * 10_000 + when.year
        ], where
        assert values(row, sky, "hour") == [when.hour], where
        assert values(row, sky, "minute") == [when.minute], where
        assert values(row, sky, "date_time_valid") == [1], where
        # the atmosphere at the observer
        air = "atmosphere_control"
        assert close(values(row, air, "visibility_m"), [weather["visibility_m"]]), where
        assert close(values(row, air, "temperature_c"), [weather["temperature_c"]]), where
        assert close(values(row, air, "pressure_hpa"), [weather["qnh_hpa"]]), where
        # the cloud layers, then the precipitation the METAR weather reports (+TSRA: heavy
        # rain, from the ground up to the lowest cloud base)
        assert values(row, wc, "layer_id") == WEATHER_IDS, where
        assert values(row, wc, "weather_enable") == [1, 1, 1, 1, 0, 0, 0], where
        assert values(row, wc, "cloud_type")[:3] == [
            int(CloudType.from_name(lay["type"])) for lay in layers
        ], where
        assert close(
            values(row, wc, "coverage_pct")[:4],
            [lay["cover_oktas"] * 12.5 for lay in layers] + [100.0],
        ), where
        assert close(
            values(row, wc, "base_elevation_m")[:4],
            [lay["base_m"] for lay in layers] + [observer_alt],
        ), where
        assert close(
            values(row, wc, "thickness_m")[:4],
            [lay["top_m"] - lay["base_m"] for lay in layers] + [layers[0]["base_m"] - observer_alt],
        ), where
        assert values(row, wc, "severity")[3] == 5, where
