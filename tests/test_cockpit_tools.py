"""The cockpit emulator and the capture replayer (tools/emulators/cockpit_emulator.py,
tools/emulators/replay_capture.py): scenarios sweep what they claim, what they send decodes
with wxsky's own decoders to the values meant, and both tools work end to end on a real pty and
on a python-can virtual bus, at the recorded pace or faster."""

from __future__ import annotations

import math
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from datetime import UTC, date, datetime
from pathlib import Path
from typing import Any

import can
import pytest
import serial
from tool_loader import load_tool

from wxsky.protocols.canaerospace import CanasDecoder
from wxsky.protocols.nmea import NmeaDecoder, NmeaStats
from wxsky.protocols.result import Decoded
from wxsky.weather.cockpit import (
    LAYER_BASE,
    LAYER_COVER,
    LAYER_THICKNESS,
    TEMPERATURE,
    VISIBILITY,
    WIND_DIR,
    WIND_SPEED,
    CockpitUpdate,
    checked,
    layer_key,
)

ROOT = Path(__file__).resolve().parents[1]
EMULATORS = ROOT / "tools" / "emulators"
DATA = ROOT / "tests" / "data" / "cockpit"
NMEA_FIXTURE = DATA / "instructor-panel.nmea"
CAN_LOG = DATA / "canaerospace.log"
CAN_ASC = DATA / "canaerospace.asc"


scenarios = load_tool("emulators/cockpit_scenarios")
emulator = load_tool("emulators/cockpit_emulator")
replay = load_tool("emulators/replay_capture")


def _merged(decoded: list[Decoded]) -> CockpitUpdate:
    out = CockpitUpdate()
    for d in decoded:
        assert d.update is not None, d
        out = out.merged(d.update)
    return out


def _angle_apart_deg(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def _sample_times(length_s: float, n: int = 25) -> list[float]:
    return [length_s * i / (n - 1) for i in range(n)]


# -- scenarios --------------------------------------------------------------------------


def test_sweep_goes_where_it_says() -> None:
    start, middle, end = (scenarios.scenario_at(t, "sweep") for t in (0.0, 30.0, 60.0))
    assert scenarios.SCENARIOS["sweep"].length_s == 60.0
    assert (start.wind_dir_deg, start.wind_speed_mps, start.layers[0].oktas) == (0.0, 0.0, 0.0)
    assert (middle.wind_dir_deg, middle.wind_speed_mps, middle.layers[0].oktas) == (
        180.0,
        12.5,
        8.0,
    )
    assert (end.wind_dir_deg, end.wind_speed_mps, end.layers[0].oktas) == (360.0, 25.0, 0.0)
    assert start.time_utc == datetime(2026, 6, 21, 4, 0, tzinfo=UTC)  # about sunrise
    assert middle.time_utc == datetime(2026, 6, 21, 12, 0, tzinfo=UTC)
    assert end.time_utc == datetime(2026, 6, 21, 20, 0, tzinfo=UTC)  # about sunset
    # Clamped outside its length, so a late tick sends the end state, not garbage.
    assert scenarios.scenario_at(99.0, "sweep") == end


@pytest.mark.parametrize("name", ["sweep", "front"])
def test_every_knob_stays_in_the_range_wxsky_accepts(name: str) -> None:
    scenario = scenarios.SCENARIOS[name]
    times = [scenario.at(t).time_utc for t in _sample_times(scenario.length_s)]
    assert times == sorted(times), "the sky clock never runs backwards within a scenario"
    for t_s in _sample_times(scenario.length_s, 121):
        knobs = scenario.at(t_s)
        checked(WIND_DIR, knobs.wind_dir_deg)
        checked(WIND_SPEED, knobs.wind_speed_mps)
        for layer in knobs.layers:
            checked(layer_key(layer.layer, LAYER_COVER), layer.oktas)
            checked(layer_key(layer.layer, LAYER_BASE), layer.base_m)
            checked(layer_key(layer.layer, LAYER_THICKNESS), layer.thickness_m)
        if knobs.temperature_c is not None:
            checked(TEMPERATURE, knobs.temperature_c)
        if knobs.visibility_m is not None:
            checked(VISIBILITY, knobs.visibility_m)
        assert knobs.time_utc.tzinfo is not None


def test_front_passes() -> None:
    scenario = scenarios.SCENARIOS["front"]
    before, after = scenario.at(0.0), scenario.at(scenario.length_s)
    samples = [scenario.at(t) for t in _sample_times(scenario.length_s, 121)]
    low = [next(lay for lay in k.layers if lay.layer == 1) for k in samples]
    assert (before.wind_dir_deg, after.wind_dir_deg) == (200.0, 300.0)  # veers
    assert max(k.wind_speed_mps for k in samples) > after.wind_speed_mps > before.wind_speed_mps
    assert max(lay.oktas for lay in low) == 8.0  # closes at the front ...
    assert min(lay.base_m for lay in low) == 500.0  # ... with its base down low
    assert low[0].oktas == 0.0 and 0.0 < low[-1].oktas < 8.0  # then breaks up
    assert after.temperature_c is not None and before.temperature_c is not None
    assert after.temperature_c < before.temperature_c
    assert min(k.visibility_m or math.inf for k in samples) < 10_000.0


# -- encoders ---------------------------------------------------------------------------


def _assert_matches(update: CockpitUpdate, knobs: Any, *, tol: dict[str, float]) -> None:
    values = update.values
    assert _angle_apart_deg(float(values[WIND_DIR]), knobs.wind_dir_deg) <= tol["deg"]
    assert float(values[WIND_SPEED]) == pytest.approx(knobs.wind_speed_mps, abs=tol["mps"])
    for layer in knobs.layers:
        n = layer.layer
        assert float(values[layer_key(n, LAYER_COVER)]) == pytest.approx(layer.oktas, abs=0.05)
        assert float(values[layer_key(n, LAYER_BASE)]) == pytest.approx(layer.base_m, abs=tol["m"])
        assert float(values[layer_key(n, LAYER_THICKNESS)]) == pytest.approx(
            layer.thickness_m, abs=tol["m"]
        )
    if knobs.temperature_c is None:
        assert TEMPERATURE not in values
    else:
        assert float(values[TEMPERATURE]) == pytest.approx(knobs.temperature_c, abs=0.05)


@pytest.mark.parametrize("wind_sentence", ["mwd", "mwv"])
@pytest.mark.parametrize("name", ["sweep", "front"])
def test_nmea_lines_decode_to_the_knobs(name: str, wind_sentence: str) -> None:
    scenario = scenarios.SCENARIOS[name]
    for t_s in _sample_times(scenario.length_s):
        knobs = scenario.at(t_s)
        decoder = NmeaDecoder(reference_year=2026)
        lines = scenarios.nmea_lines(knobs, wind_sentence=wind_sentence)
        assert all(line.endswith(b"\r\n") and len(line) <= 82 for line in lines)
        decoded = decoder.feed(b"".join(lines), now_s=0.0)
        assert (decoder.stats.errors, decoder.stats.ignored) == (0, 0), decoded
        update = _merged(decoded)
        # NMEA carries 0.1 deg, 0.1 m/s and whole feet (0.1524 m either way).
        _assert_matches(update, knobs, tol={"deg": 0.051, "mps": 0.051, "m": 0.16})
        assert VISIBILITY not in update.values  # NMEA 0183 has no field for it
        assert update.time_utc is not None
        assert abs((update.time_utc - knobs.time_utc).total_seconds()) < 0.01
        without_time = scenarios.nmea_lines(knobs, with_time=False, wind_sentence=wind_sentence)
        assert len(without_time) == len(lines) - 1


@pytest.mark.parametrize("name", ["sweep", "front"])
def test_can_frames_decode_to_the_knobs(name: str) -> None:
    scenario = scenarios.SCENARIOS[name]
    decoder = CanasDecoder(frozenset({7}))
    for t_s in _sample_times(scenario.length_s):
        knobs = scenario.at(t_s)
        frames = scenarios.can_frames(knobs, node_id=7)
        decoded = [decoder.decode(can_id, data) for can_id, data in frames]
        assert not [d for d in decoded if d.error or d.ignored]
        update = _merged(decoded)
        # FLOAT is single precision: about 7 digits.
        _assert_matches(update, knobs, tol={"deg": 1e-4, "mps": 1e-5, "m": 1e-3})
        if knobs.visibility_m is not None:
            assert float(update.values[VISIBILITY]) == pytest.approx(knobs.visibility_m, rel=1e-6)
        when = knobs.time_utc
        assert update.time_of_day_s == when.hour * 3600 + when.minute * 60 + when.second
        assert update.date_utc == when.date()
        ids = [can_id for can_id, _ in scenarios.can_frames(knobs, with_time=False)]
        assert 1200 not in ids and 1206 not in ids


def test_message_codes_count_per_id() -> None:
    codes = scenarios.MessageCodes()
    knobs = scenarios.scenario_at(10.0, "front")
    for round_ in range(3):
        stamped = codes.stamp(scenarios.can_frames(knobs))
        by_id: dict[int, list[int]] = {}
        for can_id, data in stamped:
            by_id.setdefault(can_id, []).append(data[3])
        assert by_id[333] == [round_]
        assert by_id[1500] == [3 * round_, 3 * round_ + 1, 3 * round_ + 2]  # 3 layers, one id


# -- the emulator end to end ------------------------------------------------------------


def _read_pty(path: str, proc: subprocess.Popen[str], timeout_s: float = 60.0) -> NmeaDecoder:
    """Decode what arrives on `path` until the sender closes the pty or exits."""
    decoder = NmeaDecoder(reference_year=2026)
    deadline = time.monotonic() + timeout_s
    with serial.Serial(path, timeout=0.05) as port:
        while time.monotonic() < deadline:
            try:
                data = port.read(4096)
            except serial.SerialException:
                break  # the sender closed the master: the pty is gone
            if data:
                decoder.feed(data, time.monotonic())
            elif proc.poll() is not None:
                break
    return decoder


@pytest.fixture
def run_tool() -> Iterator[Any]:
    procs: list[subprocess.Popen[str]] = []

    def start(tool: str, *args: str) -> tuple[subprocess.Popen[str], str]:
        proc = subprocess.Popen(
            [sys.executable, str(EMULATORS / tool), *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        procs.append(proc)
        assert proc.stdout is not None
        first = proc.stdout.readline().strip()
        assert first.startswith("/dev/"), (first, proc.stderr.read() if proc.stderr else "")
        return proc, first

    yield start
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=60)


def test_emulator_on_a_pty_is_read_by_pyserial(run_tool: Any) -> None:
    proc, path = run_tool("cockpit_emulator.py", "--pty", "--duration-s", "2", "--rate-hz", "10")
    decoder = _read_pty(path, proc)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert decoder.stats.updates > 0
    assert (decoder.stats.errors, decoder.stats.ignored) == (0, 0), decoder.stats
    assert "sent " in out.splitlines()[-1]


def test_emulator_stops_cleanly_on_sigterm(run_tool: Any) -> None:
    proc, path = run_tool("cockpit_emulator.py", "--pty", "--loop", "--rate-hz", "20")
    assert proc.stdout is not None
    with serial.Serial(path, timeout=2.0):
        # Its first second's log line: it is sending, not waiting for a reader.
        while not (line := proc.stdout.readline()).startswith("t="):
            assert line, "the emulator ended before sending"
        proc.terminate()
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    summary = out.splitlines()[-1]
    assert summary.startswith("sent ") and not summary.startswith("sent 0 "), summary


@pytest.fixture
def channel() -> str:
    return f"wxsky-tools-{uuid.uuid4().hex[:8]}"


def _received(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (msg := bus.recv(timeout=0.05)) is not None:
        out.append(msg)
    return out


def test_emulator_on_a_virtual_can_bus(channel: str, capsys: pytest.CaptureFixture[str]) -> None:
    with can.Bus(interface="virtual", channel=channel) as receiver:
        args = f"--can virtual:{channel} --scenario front --speed 120 --rate-hz 20 --node-id 9"
        assert emulator.main(args.split()) == 0
        frames = _received(receiver)
    decoder = CanasDecoder(frozenset({9}))
    decoded = [decoder.decode(m.arbitration_id, m.data) for m in frames]
    assert not [d for d in decoded if d.error or d.ignored]
    final = _merged(decoded)
    # The last tick sends the scenario's end state, whatever the rate.
    end = scenarios.scenario_at(scenarios.FRONT_LENGTH_S, "front")
    _assert_matches(final, end, tol={"deg": 1e-4, "mps": 1e-5, "m": 1e-3})
    assert f"sent {len(frames)} frames" in capsys.readouterr().out


# -- replay -----------------------------------------------------------------------------


def test_timestamps_and_untimestamped_lines() -> None:
    raw = (
        b"2026-11-21T10:00:00.000Z $A*41\r\n"
        b"2026-11-21T10:00:00.500+00:00 $B*42\n"
        b"\n"
        b"$C*43\r\n"  # no timestamp: 1/rate after the line before
        b"1795255201.5 $D*44\r\n"  # epoch seconds, 1.5 s after the first line
        b"12:00:01.123 $E*45\r\n"  # not a timestamp wxsky knows: sent as recorded
        b"2026-11-21T09:00:00Z $F*46\r\n"  # the clock stepped back: sent at once
        b"2026-11-21T12:00:00Z $G*47\r\n"  # three hours later: cut to the gap limit
    )
    lines = replay.parse_nmea_capture(raw)
    assert [line.data for line in lines] == [
        b"$A*41\r\n",
        b"$B*42\r\n",
        b"$C*43\r\n",
        b"$D*44\r\n",
        b"12:00:01.123 $E*45\r\n",
        b"$F*46\r\n",
        b"$G*47\r\n",
    ]
    first_s = datetime(2026, 11, 21, 10, tzinfo=UTC).timestamp()
    assert lines[0].recorded_s == first_s and lines[3].recorded_s == first_s + 1.5
    assert lines[2].recorded_s is None and lines[4].recorded_s is None
    schedule = [
        at_s for at_s, _ in replay.nmea_schedule(lines, speed=2.0, rate_hz=4.0, max_gap_s=60.0)
    ]
    assert schedule == pytest.approx([0.0, 0.25, 0.375, 0.875, 1.0, 1.0, 61.0])


def test_replay_nmea_fixture_into_a_pty(run_tool: Any) -> None:
    proc, path = run_tool("replay_capture.py", str(NMEA_FIXTURE), "--pty", "--speed", "50")
    decoder = _read_pty(path, proc)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    # What tests/data/cockpit/README.md says the capture holds.
    assert decoder.stats == NmeaStats(
        lines=48, updates=37, consumed=2, ignored=7, errors=2, bad_checksum=1, unknown=2
    )
    assert out.splitlines()[-1].startswith("replayed 48 lines")


def test_replay_nmea_keeps_the_recorded_pace(tmp_path: Path) -> None:
    capture = tmp_path / "two.nmea"
    capture.write_text(
        "1795255200.000 $WIMWV,270.0,T,12.5,M,A*15\n1795255200.500 $WIMWV,271.0,T,12.5,M,A*14\n"
    )

    def replay_s(*args: str) -> float:
        start = time.monotonic()
        assert replay.main([str(capture), "--serial", "loop://", *args], log=lambda _: None) == 0
        return time.monotonic() - start

    # Each line waits for its time in the schedule (0.5 s apart, a tenth of that at speed 10:
    # test_timestamps_and_untimestamped_lines): never sooner, so these bounds hold however
    # busy the machine. How close to the schedule it keeps is a benchmark's business.
    assert replay_s("--speed", "1") >= 0.5
    assert replay_s("--speed", "10") >= 0.05


@pytest.mark.parametrize("capture", [CAN_LOG, CAN_ASC], ids=lambda p: p.suffix)
def test_replay_can_log_fast_into_a_virtual_bus(
    capture: Path, channel: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with can.Bus(interface="virtual", channel=channel) as receiver:
        assert replay.main([str(capture), "--can", f"virtual:{channel}", "--fast"]) == 0
        frames = _received(receiver)
    recorded = list(can.LogReader(capture))
    assert [(m.arbitration_id, bytes(m.data)) for m in frames] == [
        (m.arbitration_id, bytes(m.data)) for m in recorded
    ]
    decoder = CanasDecoder()
    decoded = [decoder.decode(m.arbitration_id, m.data) for m in frames]
    # What tests/data/cockpit/README.md says the capture holds.
    assert sum(d.update is not None for d in decoded) == 39
    assert [d.ignored for d in decoded if d.ignored] == ["CAN id 0x12c not used by wxsky"]
    assert [d.error for d in decoded if d.error] == [
        "CAN 333 wind speed: DLC 6, expected 8 for FLOAT"
    ]
    final = _merged([d for d in decoded if d.update is not None])
    assert final.date_utc == date(2026, 11, 21)
    assert final.time_of_day_s == 10 * 3600 + 2
    assert f"replayed 41 frames ({sum(len(m.data) for m in frames)} B)" in capsys.readouterr().out


def test_replay_can_speed_scales_the_recorded_pace(channel: str) -> None:
    def replay_s(speed: str) -> float:
        with (
            can.Bus(interface="virtual", channel=channel) as receiver,
            can.Bus(interface="virtual", channel=channel) as sender,
        ):
            stats = replay.replay_can(replay.read_can_log(CAN_LOG), sender, speed=float(speed))
            assert len(_received(receiver)) == stats.sent == 41
        return float(stats.seconds)

    # 2.5 s recorded: sent over 0.5 s and 0.125 s, never sooner (python-can's MessageSync
    # skips a wait under 0.1 ms), however busy the machine.
    recorded = [m.timestamp for m in replay.read_can_log(CAN_LOG)]
    span_s = recorded[-1] - recorded[0]
    assert span_s == pytest.approx(2.5, abs=0.05)
    for speed in (5.0, 20.0):  # the schedule MessageSync keeps
        scaled = [m.timestamp for m in replay._scaled(replay.read_can_log(CAN_LOG), speed)]
        assert scaled[-1] - scaled[0] == pytest.approx(span_s / speed)
    assert replay_s("5") >= span_s / 5 - 1e-3
    assert replay_s("20") >= span_s / 20 - 1e-3


def test_error_frames_are_counted_not_sent(channel: str) -> None:
    messages = [
        can.Message(timestamp=0.0, arbitration_id=333, data=bytes(8), is_extended_id=False),
        can.Message(timestamp=0.0, is_error_frame=True),
    ]
    with (
        can.Bus(interface="virtual", channel=channel) as receiver,
        can.Bus(interface="virtual", channel=channel) as sender,
    ):
        stats = replay.replay_can(messages, sender, fast=True)
        assert len(_received(receiver)) == 1
    assert (stats.sent, stats.skipped) == (1, 1)
