"""Cockpit hardware into a real daemon process: NMEA on a pty and CANaerospace over
udp_multicast change the target on the stream, bad input is counted without harm, and a
pulled serial device is read again when it comes back."""

from __future__ import annotations

import os
import random
import time
from collections.abc import Callable, Iterator
from datetime import date
from pathlib import Path
from typing import Any

import can
import pytest
from cockpit_helpers import Pty, wait_until
from daemon_harness import HANG_S, RunningDaemon, running_daemon

from wxsky.host.client import ControlClient
from wxsky.protocols.canaerospace import encode_date, encode_float, encode_time
from wxsky.protocols.nmea import sentence

# Every test runs a daemon, which draws every frame. python-can's udp_multicast binds port
# 43113 on every address, and Linux hands such a socket the datagrams of every group any
# socket on the machine joined: tests that use it run on one xdist worker, one at a time.
pytestmark = [pytest.mark.gl, pytest.mark.xdist_group("udp_multicast")]

GROUP = f"239.74.163.{random.Random(os.getpid()).randrange(10, 250)}"


@pytest.fixture
def pty() -> Iterator[Pty]:
    p = Pty()
    yield p
    p.close()


def multicast_bus() -> can.BusABC:
    try:
        bus = can.Bus(interface="udp_multicast", channel=GROUP)
        bus.send(can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False))
    except (can.CanError, OSError) as exc:
        pytest.skip(f"no udp multicast on this host: {exc}")
    return bus


def send(bus: can.BusABC, can_id: int, data: bytes) -> None:
    bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))


def wait_target(
    client: ControlClient, predicate: Callable[[dict[str, Any]], bool], timeout_s: float = HANG_S
) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        note = client.next_notification(timeout_s=max(0.01, deadline - time.monotonic()))
        if note is not None and note.method == "target" and predicate(note.params):
            return note.params
    raise AssertionError("the target never showed the change")


def layer_at(target: dict[str, Any], base_m: float) -> dict[str, Any] | None:
    for lay in target["layers"]:
        if abs(lay["base_m"] - base_m) < 1.0:
            return lay
    return None


def inputs_by_kind(daemon: RunningDaemon) -> dict[str, dict[str, Any]]:
    with daemon.client() as c:
        return {i["kind"]: i for i in c.call("status")["inputs"]}


def test_serial_and_can_change_the_target(tmp_path: Path, pty: Pty) -> None:
    bus = multicast_bus()
    args = ("--serial", f"{pty.path}@4800", "--can", f"udp_multicast:{GROUP}")
    try:
        with running_daemon(tmp_path, args=args) as daemon, daemon.client() as client:
            assert wait_until(lambda: inputs_by_kind(daemon)["can"]["ok"])
            client.subscribe(["target"])

            pty.write(sentence("WIMWV,090.0,T,10.0,M,A"))
            t = wait_target(client, lambda p: p["wind"][0]["dir_deg"] == 90.0)
            assert t["wind"][0]["speed_mps"] == 10.0 and t["sources"]["wind"] == "cockpit"

            pty.write(sentence("GPZDA,134322.00,12,06,1987,00,00"))
            t = wait_target(client, lambda p: p["time_utc"].startswith("1987-06-12T13:43"))
            assert t["sources"]["time_utc"] == "cockpit"

            pty.write(sentence("PWXCL,1,8,3000,1000,STRATUS"))
            t = wait_target(client, lambda p: layer_at(p, 914.4) is not None)
            assert layer_at(t, 914.4) == {
                "cover_oktas": 8.0,
                "base_m": pytest.approx(914.4),
                "top_m": pytest.approx(1219.2),
                "type": "stratus",
            }

            send(bus, 333, encode_float(333, 7.5))
            send(bus, 334, encode_float(334, -45.0))
            wait_target(
                client,
                lambda p: p["wind"][0]["speed_mps"] == 7.5 and p["wind"][0]["dir_deg"] == 315.0,
            )
            send(bus, 1500, encode_float(1500, 6.0, service_code=2))
            send(bus, 1501, encode_float(1501, 4000.0, service_code=2))
            send(bus, 1502, encode_float(1502, 800.0, service_code=2))
            # Three frames, three targets: wait for the one that has them all.
            t = wait_target(
                client,
                lambda p: any(
                    lay["base_m"] == 4000.0 and abs(lay["top_m"] - 4800.0) < 0.01
                    for lay in p["layers"]
                ),
            )
            assert layer_at(t, 4000.0)["cover_oktas"] == 6.0  # type: ignore[index]
            send(bus, 1206, encode_date(date(2031, 3, 4)))
            send(bus, 1200, encode_time(5, 6, 7))
            wait_target(client, lambda p: p["time_utc"] == "2031-03-04T05:06:07Z")

            inputs = inputs_by_kind(daemon)
            for kind in ("serial", "can"):
                entry = inputs[kind]
                assert {"name", "kind", "ok", "messages", "errors", "last_message_s"} <= set(entry)
                assert entry["ok"] and entry["errors"] == 0
                assert entry["last_message_s"] is not None and entry["last_message_s"] < 30.0
            assert inputs["serial"]["messages"] == 3
            assert inputs["can"]["messages"] >= 7
            # Reader threads stop within the daemon's shutdown budget, none abandoned.
            code, _ = daemon.stop()
            assert code == 0, daemon.log()
            assert "cockpit readers did not stop in time" not in daemon.log()
    finally:
        bus.shutdown()


def test_bad_input_is_dropped_and_frames_keep_coming(tmp_path: Path, pty: Pty) -> None:
    rng = random.Random(7)
    with running_daemon(tmp_path, args=("--serial", pty.path)) as daemon, daemon.client() as c:
        frames_before = c.call("status")["frames_published"]
        c.subscribe(["target"])
        good = 0
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:
            pty.write(bytes(rng.getrandbits(8) for _ in range(500)))
            pty.write(b"\r\n" + b"Z" * 3000 + b"\r\n")
            pty.write(sentence("WIMWV,090.0,T,999,M,A"))  # out of range
            pty.write(sentence("PWXCL,9,4,3000,1000"))  # no layer 9
            pty.write(sentence("GPZDA,250000.00,12,06,1987,00,00"))  # hour 25
            pty.write(b"$WIMWV,0")  # truncated...
            pty.write(b"\r\n")
            pty.write(sentence(f"WIMWV,{good % 360:03d}.0,T,{good % 50}.0,M,A"))  # ...a good one
            good += 1
            time.sleep(0.02)
        last = good - 1
        t = wait_target(c, lambda p: p["wind"][0]["dir_deg"] == float(last % 360))
        assert t["wind"][0]["speed_mps"] == float(last % 50)
        status = c.call("status")
        serial = next(i for i in status["inputs"] if i["kind"] == "serial")
        assert serial["messages"] == good
        assert serial["errors"] >= 5 * good
        assert serial["ok"]
        assert not status["target"]["time_utc"].startswith("1987")
        assert all(layer["base_m"] < 25_000.0 for layer in status["target"]["layers"])
        # The daemon kept publishing while the junk poured in. (At what rate is a benchmark's
        # business: on a busy machine any rate drops.)
        assert status["frames_published"] > frames_before
        assert daemon.proc.poll() is None


def test_pulled_serial_device_is_read_again(tmp_path: Path) -> None:
    first = Pty()
    device = tmp_path / "ttyUSB-panel"
    device.symlink_to(first.path)
    second: Pty | None = None
    try:
        with running_daemon(tmp_path, args=("--serial", str(device))) as daemon:
            with daemon.client() as c:
                c.subscribe(["target"])
                first.write(sentence("WIMWV,010.0,T,3.0,M,A"))
                wait_target(c, lambda p: p["wind"][0]["dir_deg"] == 10.0)
            first.close()
            assert wait_until(lambda: not inputs_by_kind(daemon)["serial"]["ok"])
            second = Pty()
            device.unlink()
            device.symlink_to(second.path)
            assert wait_until(lambda: inputs_by_kind(daemon)["serial"]["ok"], timeout_s=HANG_S)
            with daemon.client() as c:
                c.subscribe(["target"])
                second.write(sentence("WIMWV,020.0,T,4.0,M,A"))
                wait_target(c, lambda p: p["wind"][0]["dir_deg"] == 20.0)
            assert inputs_by_kind(daemon)["serial"]["reopens"] >= 1
            code, _ = daemon.stop()
            log = daemon.log()
            assert code == 0, log
            assert log.count("lost") + log.count("cannot open") >= 1
    finally:
        first.close()
        if second is not None:
            second.close()
