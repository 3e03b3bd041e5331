"""Feed a real daemon valid and bad cockpit input for a minute and check it kept every valid
value, rejected every invalid one and kept publishing frames at its normal rate.

    .venv/bin/python tools/soak_cockpit.py [--seconds 60] [--period-s 0.1]

Every period it writes to a pty (NMEA) and, where the host has multicast, to a udp_multicast
CAN bus: one valid value never sent before (the wind on serial, the temperature on CAN; two
inputs setting one field would overwrite each other), plus the issue's bad input (random
bytes, a bad checksum, truncation, a 10 kB line without a newline, wind 999 m/s, hour 25,
9 oktas, layer 7; on CAN also NaN, a wrong DLC and an unknown id). It compares:

* valid values: each one must show in a `target` notification;
* invalid values: none may ever show (no 999 m/s wind, no 1987 clock, no 9-okta layer);
* counts: the daemon's messages/errors/ignored for the serial input must equal those of a
  local `NmeaDecoder` fed the very same bytes; CAN counts must equal the frames sent per kind;
* frame rate: the median of `status` fps during the soak against a baseline taken just before.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import can

from wxsky.host.client import ControlClient
from wxsky.protocols.canaerospace import encode_float, encode_raw, encode_time
from wxsky.protocols.nmea import NmeaDecoder, sentence

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cockpit_daemon import cockpit_daemon


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--period-s", type=float, default=0.1)
    p.add_argument("--group", default="239.74.163.78")
    args = p.parse_args()
    rng = random.Random(1)
    with cockpit_daemon(args.group) as daemon:
        client, bus = daemon.client, daemon.bus
        baseline = _fps_samples(client, 6.0)
        client.subscribe(["target"])
        report = _soak(client, daemon.master, bus, rng, args.seconds, args.period_s)
        status = client.call("status")
        alive = daemon.alive()
    return _print(report, status, baseline, alive, bus is not None)


def _fps_samples(client: ControlClient, seconds: float) -> list[float]:
    out = []
    end = time.monotonic() + seconds
    time.sleep(2.0)  # a full fps window first
    while time.monotonic() < end:
        out.append(client.call("status")["fps"])
        time.sleep(1.0)
    return out


def _soak(
    client: ControlClient,
    master: int,
    bus: can.BusABC | None,
    rng: random.Random,
    seconds: float,
    period_s: float,
) -> dict[str, Any]:
    local = NmeaDecoder()
    sent_serial: list[tuple[float, float]] = []
    sent_can: list[float] = []
    can_bad = 0
    can_ignored = 0
    seen: set[Any] = set()
    invalid_seen: list[str] = []
    fps: list[float] = []
    next_fps = time.monotonic() + 2.0
    end = time.monotonic() + seconds
    i = 0
    while time.monotonic() < end:
        i += 1
        # Serial: the bad input, then one valid wind never sent before.
        chunk = _bad_nmea(rng)
        wind = (float(i % 360), round(0.1 * (i % 1400) + 0.05, 2))
        chunk += sentence(f"WIMWV,{wind[0]:05.1f},T,{wind[1]:.2f},M,A")
        sent_serial.append(wind)
        os.write(master, chunk)
        local.feed(chunk, time.monotonic())
        if bus is not None:
            can_bad += _send_bad_can(bus)
            can_ignored += 1
            bus.send(_msg(0x123, bytes(8)))  # someone else's id
            # The CAN input sets the temperature, the serial one the wind: two inputs setting
            # one field would overwrite each other, and this checks that nothing is lost.
            temperature_c = round(-40.0 + 0.01 * (i % 9000), 2)
            bus.send(_msg(335, encode_float(335, temperature_c + 273.15)))
            sent_can.append(temperature_c)
        deadline = time.monotonic() + period_s
        while (left := deadline - time.monotonic()) > 0:
            note = client.next_notification(timeout_s=left)
            if note is not None and note.method == "target":
                _look(note.params, seen, invalid_seen)
        if time.monotonic() >= next_fps:
            next_fps += 1.0
            fps.append(client.call("status")["fps"])
    # Let the last values arrive.
    settle_end = time.monotonic() + 1.0
    while (left := settle_end - time.monotonic()) > 0:
        note = client.next_notification(timeout_s=left)
        if note is not None and note.method == "target":
            _look(note.params, seen, invalid_seen)
    counts = local.stats
    return {
        "serial_sent": sent_serial,
        "can_sent": sent_can,
        "seen": seen,
        "invalid_seen": invalid_seen,
        "expected_serial": (counts.updates + counts.consumed, counts.errors, counts.ignored),
        "can_bad": can_bad,
        "can_ignored": can_ignored,
        "fps": fps,
    }


def _bad_nmea(rng: random.Random) -> bytes:
    junk = bytes(rng.getrandbits(8) for _ in range(200))
    return (
        junk
        + b"\r\n"
        + b"$WIMWV,270.0,T,12.5,M,A*00\r\n"  # bad checksum
        + b"$WIMWV,27"  # truncated ...
        + b"\r\n"
        + b"Q" * 10_000  # a 10 kB line without a newline ...
        + b"\r\n"
        + sentence("WIMWV,090.0,T,999,M,A")  # wind 999 m/s
        + sentence("GPZDA,250000.00,12,06,1987,00,00")  # hour 25
        + sentence("PWXCL,1,9,3000,1000")  # 9 oktas
        + sentence("PWXCL,7,4,3000,1000")  # layer 7
    )


def _send_bad_can(bus: can.BusABC) -> int:
    frames = [
        _msg(333, encode_float(333, 999.0)),
        _msg(333, encode_raw(333, 2, bytes.fromhex("7fc00000"))),  # NaN
        _msg(334, b"\x01\x02\x03"),  # wrong DLC
        _msg(1500, encode_float(1500, 9.0, service_code=1)),  # 9 oktas
        _msg(1500, encode_float(1500, 4.0, service_code=7)),  # layer 7
        _msg(1200, encode_time(25, 0, 0)),  # hour 25
    ]
    for frame in frames:
        bus.send(frame)
    return len(frames)


def _msg(can_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


def _look(target: dict[str, Any], seen: set[Any], invalid: list[str]) -> None:
    if target["temperature_c"] is not None:
        seen.add(round(target["temperature_c"], 2))
    if target["wind"]:
        w = target["wind"][0]
        seen.add((round(w["dir_deg"], 3), round(w["speed_mps"], 2)))
        if w["speed_mps"] > 150.0 or not math.isfinite(w["speed_mps"]):
            invalid.append(f"wind {w['speed_mps']}")
    if target["time_utc"].startswith("1987"):
        invalid.append(f"time {target['time_utc']}")
    for lay in target["layers"]:
        if lay["cover_oktas"] > 8.0:
            invalid.append(f"layer {lay}")


def _print(
    report: dict[str, Any], status: dict[str, Any], baseline: list[float], alive: bool, can_on: bool
) -> int:
    inputs = {i["kind"]: i for i in status["inputs"]}
    seen = report["seen"]
    ok = alive and not report["invalid_seen"]
    serial_kept = sum(1 for v in report["serial_sent"] if v in seen)
    print(f"cpu: {os.cpu_count()} cores; soak {len(report['serial_sent'])} periods")
    print(f"serial: valid winds kept {serial_kept}/{len(report['serial_sent'])}")
    ser = inputs["serial"]
    exp = report["expected_serial"]
    got = (ser["messages"], ser["errors"], ser["ignored"])
    print(f"serial: daemon (messages, errors, ignored) {got}, same bytes decoded here {exp}")
    ok &= serial_kept == len(report["serial_sent"]) and got == exp
    if can_on:
        can_kept = sum(1 for v in report["can_sent"] if v in seen)
        c = inputs["can"]
        print(f"CAN: valid temperatures kept {can_kept}/{len(report['can_sent'])}")
        print(
            f"CAN: daemon errors {c['errors']} (bad frames sent {report['can_bad']}), "
            f"ignored {c['ignored']} (foreign ids sent {report['can_ignored']})"
        )
        ok &= can_kept == len(report["can_sent"])
        ok &= c["errors"] == report["can_bad"] and c["ignored"] == report["can_ignored"]
    else:
        print("CAN: skipped (no udp multicast on this host)")
    print(f"invalid values that reached the target: {report['invalid_seen'] or 'none'}")
    during = report["fps"]
    print(
        f"fps: baseline median {statistics.median(baseline):.1f} ({len(baseline)} samples), "
        f"during soak median {statistics.median(during):.1f} ({len(during)} samples), "
        f"ratio {statistics.median(during) / statistics.median(baseline):.2f}"
    )
    print(f"daemon still running: {alive}; verdict: {'PASS' if ok else 'FAIL'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
