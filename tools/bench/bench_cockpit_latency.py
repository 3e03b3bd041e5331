"""How long a cockpit knob takes to reach the daemon's stream: a real daemon reads NMEA 0183 on
a pty and CANaerospace on a udp_multicast bus; this process changes a value and times the
`target` notification that shows it.

    .venv/bin/python tools/bench/bench_cockpit_latency.py [--changes 60] [--tick-hz 30] [--png FILE]

Each case (MWV, ZDA, $PWXCL on serial; 333/334, 1200+1206, 1500-1502 on CAN) is changed
`--changes` times, with a random pause before each so the changes land at every phase of the
daemon's tick. Prints median, p99 and max per case against the issue's budget (one tick plus
20 ms). Without multicast on the host the CAN cases are skipped, and the output says so.
`--png` also draws every measurement against the budget (docs/cockpit-latency.png).
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import can

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`

from tools.emulators.cockpit_daemon import cockpit_daemon
from wxsky.host.client import ControlClient
from wxsky.protocols.canaerospace import encode_date, encode_float, encode_time
from wxsky.protocols.nmea import sentence
from wxsky.units import FT_TO_M


@dataclass
class Case:
    name: str
    send: Callable[[int], None]  # make change i
    shows: Callable[[int, dict[str, Any]], bool]  # does a target show change i?


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--changes", type=int, default=60, help="changes per case (>= 50)")
    p.add_argument("--tick-hz", type=float, default=30.0)
    p.add_argument("--group", default="239.74.163.77", help="udp_multicast group for CAN")
    p.add_argument("--png", type=Path, help="also draw the distributions into this PNG")
    args = p.parse_args()
    with cockpit_daemon(args.group, f"[daemon]\ntick_hz = {args.tick_hz}") as daemon:
        client, bus = daemon.client, daemon.bus
        client.subscribe(["target"])
        time.sleep(2.0)  # past start-up and the first ring build
        cases = _serial_cases(daemon.master) + (_can_cases(bus) if bus is not None else [])
        results = {case.name: _measure(client, case, args.changes) for case in cases}
        fps = client.call("status")["fps"]
    budget_ms = 1000.0 / args.tick_hz + 20.0
    print(f"cpu: {os.cpu_count()} cores; tick {args.tick_hz:g} Hz; daemon at {fps:.1f} fps")
    print(f"budget: one tick + 20 ms = {budget_ms:.1f} ms")
    print(f"{'case':<22} {'n':>4} {'median ms':>10} {'p99 ms':>8} {'max ms':>8}  within budget")
    everything: list[float] = []
    for name, lat_ms in results.items():
        everything += lat_ms
        within = sum(x <= budget_ms for x in lat_ms)
        print(
            f"{name:<22} {len(lat_ms):>4} {statistics.median(lat_ms):>10.2f} "
            f"{_p99(lat_ms):>8.2f} {max(lat_ms):>8.2f}  {within}/{len(lat_ms)}"
        )
    print(
        f"{'all':<22} {len(everything):>4} {statistics.median(everything):>10.2f} "
        f"{_p99(everything):>8.2f} {max(everything):>8.2f}"
    )
    if bus is None:
        print("CAN cases skipped: no udp multicast on this host")
    if args.png is not None:
        _chart(results, budget_ms, fps, args.png)
        print(f"chart: {args.png}")
    return 0


def _chart(results: dict[str, list[float]], budget_ms: float, fps: float, path: Path) -> None:
    """Every measurement as a dot per case on a log time axis, with median, p99 and the budget."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results)
    fig, ax = plt.subplots(figsize=(9, 0.55 * len(names) + 1.6), dpi=110)
    rng = random.Random(0)
    for row, name in enumerate(names):
        lat_ms = results[name]
        ys = [row + rng.uniform(-0.18, 0.18) for _ in lat_ms]
        ax.scatter(lat_ms, ys, s=9, alpha=0.55, color="tab:blue", linewidths=0)
        med, p99 = statistics.median(lat_ms), _p99(lat_ms)
        ax.plot([med, med], [row - 0.3, row + 0.3], color="black", lw=2)
        ax.plot([p99, p99], [row - 0.3, row + 0.3], color="tab:orange", lw=2)
        ax.text(
            budget_ms * 1.08, row, f"median {med:.2f} ms, p99 {p99:.1f} ms", va="center", fontsize=8
        )
    ax.axvline(budget_ms, color="tab:red", ls="--", lw=1.2)
    ax.text(budget_ms, len(names) - 0.4, f" budget {budget_ms:.1f} ms", color="tab:red", fontsize=8)
    ax.set_xscale("log")
    ax.set_xlim(0.1, budget_ms * 6)
    ax.set_yticks(range(len(names)), names)
    ax.set_ylim(-0.6, len(names) - 0.2)
    ax.invert_yaxis()
    ax.set_xlabel("knob change to `target` on the daemon's stream, ms (log)")
    n = len(next(iter(results.values())))
    ax.set_title(
        f"Cockpit input latency: {n} changes per case, daemon at {fps:.0f} fps, "
        f"{os.cpu_count()} CPU cores (black: median, orange: p99)",
        fontsize=9,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def _measure(client: ControlClient, case: Case, changes: int, topic: str = "target") -> list[float]:
    """Milliseconds from each change to the first `topic` notification that shows it."""
    rng = random.Random(case.name)
    out = []
    for i in range(changes):
        time.sleep(rng.uniform(0.0, 0.05))  # land at every phase of the tick
        _drain(client)
        start = time.perf_counter()
        case.send(i)
        while True:
            note = client.next_notification(timeout_s=2.0)
            if note is None:
                raise SystemExit(f"{case.name}: change {i} never reached the stream")
            if note.method == topic and case.shows(i, note.params):
                out.append((time.perf_counter() - start) * 1000.0)
                break
    return out


def _drain(client: ControlClient) -> None:
    while client.next_notification(timeout_s=0.0) is not None:
        pass


def _serial_cases(master: int) -> list[Case]:
    def mwv(i: int) -> None:
        os.write(master, sentence(f"WIMWV,{_dir(i):05.1f},T,{_speed(i):.1f},M,A"))

    def zda(i: int) -> None:
        t = _when(i)
        os.write(master, sentence(f"GPZDA,{t:%H%M%S}.00,{t:%d},{t:%m},{t:%Y},00,00"))

    def pwxcl(i: int) -> None:
        os.write(master, sentence(f"PWXCL,1,{1 + i % 8},{_base_ft(i)},1000,"))

    return [
        Case("serial MWV wind", mwv, _wind_shows),
        Case("serial ZDA time", zda, _time_shows),
        Case("serial PWXCL layer", pwxcl, _layer_shows),
    ]


def _can_cases(bus: can.BusABC) -> list[Case]:
    def send(can_id: int, data: bytes) -> None:
        bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    def wind(i: int) -> None:
        send(333, encode_float(333, _speed(i), message_code=i % 256))
        # The standard's form is -180..180: 270° goes on the wire as -90°.
        signed_deg = _dir(i) - 360.0 if _dir(i) > 180.0 else _dir(i)
        send(334, encode_float(334, signed_deg, message_code=i % 256))

    def time_date(i: int) -> None:
        t = _when(i)
        send(1206, encode_date(t.date()))
        send(1200, encode_time(t.hour, t.minute, t.second))

    def layer(i: int) -> None:
        send(1500, encode_float(1500, float(1 + i % 8), service_code=1))
        send(1501, encode_float(1501, _base_ft(i) * FT_TO_M, service_code=1))
        send(1502, encode_float(1502, 300.0, service_code=1))

    return [
        Case("CAN 333+334 wind", wind, _wind_shows),
        Case("CAN 1200+1206 time", time_date, _time_shows),
        Case("CAN 1500-1502 layer", layer, _layer_shows),
    ]


def _dir(i: int) -> float:
    return float((37 * i) % 360)


def _speed(i: int) -> float:
    return float(1 + i % 29)


def _when(i: int) -> datetime:
    # Different days and hours, never within a second of the last one.
    return datetime(2027, 1, 1, tzinfo=UTC) + timedelta(days=i % 300, hours=(5 * i) % 24)


def _base_ft(i: int) -> int:
    return 2000 + 100 * (i % 50)


def _wind_shows(i: int, target: dict[str, Any]) -> bool:
    w = target["wind"][0] if target["wind"] else None
    return (
        w is not None
        and abs(w["dir_deg"] - _dir(i)) < 0.01
        and abs(w["speed_mps"] - _speed(i)) < 0.01
    )


def _time_shows(i: int, target: dict[str, Any]) -> bool:
    return bool(target["time_utc"] == _when(i).strftime("%Y-%m-%dT%H:%M:%SZ"))


def _layer_shows(i: int, target: dict[str, Any]) -> bool:
    base_m = _base_ft(i) * FT_TO_M
    return any(
        abs(lay["base_m"] - base_m) < 0.5 and abs(lay["cover_oktas"] - (1 + i % 8)) < 1e-6
        for lay in target["layers"]
    )


def _p99(values: list[float]) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))]


if __name__ == "__main__":
    raise SystemExit(main())
