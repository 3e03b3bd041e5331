#!/usr/bin/env python3
"""Latency and clock skew of one sky shared by a master and display channels (docs/channels.md).
Starts a private master (`--share zenoh:tcp/127.0.0.1:PORT`) and two channels (`--join`,
-60/+60 degrees), all on this machine, and measures:

    ping         a query over the bus to the master's clock queryable and its answer: the
                 round trip (the bus alone, both ways);
    tick age     a frame's start on the master -> its clock tick's arrival at a probe on the
                 bus (the tick goes out after the frame is published): exact here, one
                 monotonic clock for every process on a machine;
    state        `apply_preset` on the master's control socket -> the new state's arrival at
                 the probe (the master sends it after the frame that applies it);
    target       `apply_preset` on the master -> the channel's `status` showing the new
                 target (what a host asking the channel sees; polled every 5 ms);
    skew         a channel's sim time minus the master's at one instant, from their
                 `status` sim_clock (each a reading of the sim time at a monotonic instant);
    offset err   a channel's estimate of the offset between its monotonic clock and the
                 master's (0 on one machine: the estimate's error).

    .venv/bin/python tools/bench/bench_channels.py [--changes 40] [--json FILE]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import socket
import statistics
import sys
import threading
import time
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from tools.emulators.cockpit_daemon import private_daemon  # noqa: E402
from wxsky.host.client import ControlClient  # noqa: E402
from wxsky.output.wire import unpack_data  # noqa: E402
from wxsky.share.messages import decode_state, decode_tick  # noqa: E402
from wxsky.share.zenoh_bus import ShareBus  # noqa: E402
from wxsky.weather.state import parse_time_utc  # noqa: E402

CONFIG = """
[camera]
width = 320
height = 180
pitch_deg = 0.0
"""
PRESETS = ("overcast-stratus", "fair-cumulus")


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _summary(values_ms: list[float]) -> dict[str, float]:
    ordered = sorted(values_ms)
    p99 = ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))]
    return {
        "n": len(ordered),
        "median_ms": statistics.median(ordered),
        "p99_ms": p99,
        "max_ms": ordered[-1],
    }


class Probe:
    """A channel-role session on the bus that notes when each tick and state arrives."""

    def __init__(self, endpoint: str) -> None:
        self.bus = ShareBus(endpoint, role="channel", site="default", name="probe")
        self.tick_ms: list[float] = []
        self.states: list[tuple[float, int]] = []  # (arrival, sequence)
        self._lock = threading.Lock()
        self.bus.on_tick(self._tick)
        self.bus.on_state(self._state)

    def _tick(self, payload: bytes) -> None:
        now = time.monotonic()
        tick = decode_tick(unpack_data(payload), "default")
        with self._lock:
            self.tick_ms.append(1000.0 * (now - tick.master_mono_s))

    def _state(self, payload: bytes) -> None:
        now = time.monotonic()
        state = decode_state(unpack_data(payload), "default")
        with self._lock:
            self.states.append((now, state.sequence))

    def state_after(self, t0: float, sequence: int, timeout_s: float = 5.0) -> float | None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self._lock:
                for arrived, seq in self.states:
                    if arrived >= t0 and seq > sequence:
                        return arrived
            time.sleep(0.001)
        return None

    def latest_sequence(self) -> int:
        with self._lock:
            return max((seq for _, seq in self.states), default=0)


@contextlib.contextmanager
def dome(endpoint: str) -> Iterator[tuple[ControlClient, ControlClient, ControlClient]]:
    share = f"zenoh:{endpoint}"
    with (
        private_daemon(CONFIG, ["--share", share, "--preset", "fair-cumulus"]) as (_, master),
        private_daemon(CONFIG, ["--join", share, "--channel", "left", "--view-offset=-60,0,0"]) as (
            _,
            left,
        ),
        private_daemon(CONFIG, ["--join", share, "--channel", "right", "--view-offset=60,0,0"]) as (
            _,
            right,
        ),
    ):
        yield master, left, right


def skew_ms(a: dict[str, Any], b: dict[str, Any]) -> float:
    ta = parse_time_utc(a["sim_clock"]["time_utc"])
    tb = parse_time_utc(b["sim_clock"]["time_utc"])
    at_b = ta + timedelta(
        seconds=a["clock_rate"] * (b["sim_clock"]["mono_s"] - a["sim_clock"]["mono_s"])
    )
    return 1000.0 * (tb - at_b).total_seconds()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--changes", type=int, default=40)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    endpoint = f"tcp/127.0.0.1:{_port()}"
    with dome(endpoint) as (master, left, right):
        channels = {"left": left, "right": right}
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            m = master.call("status")
            if all(c.call("status")["sky_id"] == m["sky_id"] for c in channels.values()):
                break
            time.sleep(0.1)
        else:
            raise SystemExit("the channels did not join the master within 30 s")
        probe = Probe(endpoint)
        time.sleep(1.0)
        state_ms: list[float] = []
        target_ms: dict[str, list[float]] = {name: [] for name in channels}
        for k in range(args.changes):
            preset = PRESETS[k % 2]
            before = probe.latest_sequence()
            t0 = time.monotonic()
            master.call("apply_preset", {"name": preset})
            arrived = probe.state_after(t0, before)
            if arrived is not None:
                state_ms.append(1000.0 * (arrived - t0))
            want = master.call("status")["target"]["layers"]
            for name, c in channels.items():
                while c.call("status")["target"]["layers"] != want:
                    if time.monotonic() - t0 > 5.0:
                        raise SystemExit(f"{name} did not take the target within 5 s")
                    time.sleep(0.005)
                target_ms[name].append(1000.0 * (time.monotonic() - t0))
            time.sleep(0.2)
        skews: dict[str, list[float]] = {name: [] for name in channels}
        offsets: dict[str, list[float]] = {name: [] for name in channels}
        for _ in range(100):
            for name, c in channels.items():
                a = master.call("status")
                b = c.call("status")
                skews[name].append(skew_ms(a, b))
                offsets[name].append(b["channel"]["clock_offset_ms"])
            time.sleep(0.02)
        rtt_ms = []
        for _ in range(200):
            answer = probe.bus.ping()
            if answer is not None:
                rtt_ms.append(1000.0 * (answer[2] - answer[0]))
        probe.bus.close()
        fps = {n: c.call("status")["fps"] for n, c in {"master": master, **channels}.items()}
    result = {
        "ping": _summary(rtt_ms),
        "tick age": _summary(probe.tick_ms),
        "state": _summary(state_ms),
        **{f"target {n}": _summary(v) for n, v in target_ms.items()},
        **{f"skew {n}": _summary([abs(s) for s in v]) for n, v in skews.items()},
        **{f"offset err {n}": _summary([abs(o) for o in v]) for n, v in offsets.items()},
    }
    print(f"{'case':<20}{'n':>6}{'median ms':>12}{'p99 ms':>10}{'max ms':>10}")
    for case, s in result.items():
        print(
            f"{case:<20}{s['n']:>6}{s['median_ms']:>12.3f}{s['p99_ms']:>10.3f}{s['max_ms']:>10.3f}"
        )
    print("fps:", ", ".join(f"{n} {v:.1f}" for n, v in fps.items()))
    if args.json is not None:
        args.json.write_text(json.dumps({"cases": result, "fps": fps}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
