"""Feed a real daemon valid and bad cockpit input for a minute and check it kept every valid
value, rejected every invalid one and kept publishing frames at its normal rate.

    .venv/bin/python tools/soak/soak_cockpit.py [--seconds 60] [--period-s 0.1]

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
import os
import random
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import can

from wxsky.host.client import ControlClient
from wxsky.protocols.nmea import NmeaDecoder

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`
from tools.emulators.cockpit_daemon import cockpit_daemon
from tools.soak.cockpit_faults import (
    FOREIGN_CAN_ID,
    bad_can_frames,
    bad_nmea,
    can_frame,
    look,
    temperature_frame,
    valid_temperature_c,
    valid_wind,
    wind_sentence,
)


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
        wind = valid_wind(i)
        chunk = bad_nmea(rng) + wind_sentence(wind)
        sent_serial.append(wind)
        os.write(master, chunk)
        local.feed(chunk, time.monotonic())
        if bus is not None:
            for frame in bad_can_frames():
                bus.send(frame)
                can_bad += 1
            can_ignored += 1
            bus.send(can_frame(FOREIGN_CAN_ID, bytes(8)))
            # The CAN input sets the temperature, the serial one the wind: two inputs setting
            # one field would overwrite each other, and this checks that nothing is lost.
            temperature_c = valid_temperature_c(i)
            bus.send(temperature_frame(temperature_c))
            sent_can.append(temperature_c)
        deadline = time.monotonic() + period_s
        while (left := deadline - time.monotonic()) > 0:
            note = client.next_notification(timeout_s=left)
            if note is not None and note.method == "target":
                look(note.params, seen, invalid_seen)
        if time.monotonic() >= next_fps:
            next_fps += 1.0
            fps.append(client.call("status")["fps"])
    # Let the last values arrive.
    settle_end = time.monotonic() + 1.0
    while (left := settle_end - time.monotonic()) > 0:
        note = client.next_notification(timeout_s=left)
        if note is not None and note.method == "target":
            look(note.params, seen, invalid_seen)
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
