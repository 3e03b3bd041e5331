"""Emulate cockpit hardware: play a scripted weather scenario as NMEA 0183 on a serial line or
as CANaerospace frames on a CAN bus, so wxsky's cockpit links can be tried without a panel.

    # NMEA on a pseudo-terminal: prints the device path, then waits for a reader
    .venv/bin/python tools/emulators/cockpit_emulator.py --pty
    wxsky run --serial /dev/pts/7             # the path it printed

    # NMEA on a real port or any pyserial URL (wxsky reads at 4800 baud unless told otherwise)
    .venv/bin/python tools/emulators/cockpit_emulator.py --serial /dev/ttyUSB0@4800 --rate-hz 2
    .venv/bin/python tools/emulators/cockpit_emulator.py --serial socket://localhost:4001

    # CANaerospace through python-can; udp_multicast reaches other processes on this host
    .venv/bin/python tools/emulators/cockpit_emulator.py --can udp_multicast:239.74.163.2 --loop
    wxsky run --can udp_multicast:239.74.163.2
    .venv/bin/python tools/emulators/cockpit_emulator.py --can socketcan:vcan0 --scenario front \\
        --speed 4

Scenarios are pure functions of scenario time (`scenario_at`), so tests check them directly:

    sweep   60 s: layer 1 cover 0 -> 8 -> 0 oktas, wind from 0 -> 360 deg at 0 -> 25 m/s, and
            the sky clock from 04:00 to 20:00 UTC on 21 June (sunrise to sunset in Europe).
    front  120 s: a cold front passes: cirrus, then altostratus, then a low layer that closes
            and lowers to 500 m; the wind freshens to a squall at the front and veers from 200
            to 300 deg; it turns cold, visibility drops in the rain, then the sky clears.

Values are sent every 1/--rate-hz s, time and date once a second (as a GPS or an air-data
computer sends them). --speed scales scenario time; --duration-s is in scenario seconds.
Ctrl-C (or SIGTERM) stops cleanly.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import FrameType

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`

from tools.emulators.cockpit_outputs import (
    CanOut,
    NmeaOut,
    Output,
    PtyPort,
    SerialPort,
    add_output_arguments,
    open_can_bus,
)
from tools.emulators.cockpit_scenarios import SCENARIOS, Knobs, Scenario, nmea_lines

SERIAL_BITS_PER_BYTE = 10  # 8N1: start + 8 data + stop
TIME_PERIOD_S = 1.0  # time and date go out once a second, as a GPS or air-data computer sends them


# -- running ----------------------------------------------------------------------------


@dataclass
class RunStats:
    ticks: int = 0
    items: int = 0  # lines or frames
    bytes: int = 0
    skipped_ticks: int = 0  # the output could not keep up


def _describe(t_s: float, knobs: Knobs) -> str:
    layers = " ".join(f"L{lay.layer} {lay.oktas:.1f}/8 {lay.base_m:.0f} m" for lay in knobs.layers)
    extra = ""
    if knobs.temperature_c is not None:
        extra += f"  {knobs.temperature_c:.1f} °C"
    if knobs.visibility_m is not None:
        extra += f"  vis {knobs.visibility_m / 1000.0:.1f} km"
    return (
        f"t={t_s:6.1f} s  wind {knobs.wind_dir_deg % 360.0:05.1f}°/{knobs.wind_speed_mps:4.1f} "
        f"m/s  {layers}{extra}  {knobs.time_utc:%H:%M:%S}Z"
    )


def run(
    out: Output,
    scenario: Scenario,
    *,
    rate_hz: float,
    duration_s: float | None,
    speed: float,
    loop: bool,
    log: Callable[[str], None] = print,
    stats: RunStats | None = None,
) -> RunStats:
    """Send the scenario until `duration_s` of scenario time (None: for ever) has passed.
    `stats`, when given, is kept up to date, so a caller interrupted by Ctrl-C still has it."""
    stats = stats if stats is not None else RunStats()
    period_s = 1.0 / rate_hz
    start = time.monotonic()
    last_time_sent = -math.inf
    last_log = -math.inf
    logged = RunStats()
    tick = 0
    while True:
        wall_s = tick * period_s
        t_s = wall_s * speed
        last = duration_s is not None and t_s >= duration_s - 1e-9
        if last and duration_s is not None:
            t_s = duration_s  # the scenario's end state goes out, whatever the tick rate
        scenario_t_s = t_s % scenario.length_s if loop else min(t_s, scenario.length_s)
        knobs = scenario.at(scenario_t_s)
        with_time = wall_s - last_time_sent >= TIME_PERIOD_S - 1e-9
        if with_time:
            last_time_sent = wall_s
        items, sent_bytes = out.send(knobs, with_time)
        stats.ticks += 1
        stats.items += items
        stats.bytes += sent_bytes
        if wall_s - last_log >= 1.0 - 1e-9:
            last_log = wall_s
            reader = "" if out.has_reader() else "  (no reader: dropped)"
            log(
                f"{_describe(scenario_t_s, knobs)}  sent {stats.items - logged.items} "
                f"in {stats.bytes - logged.bytes} B{reader}"
            )
            logged = RunStats(items=stats.items, bytes=stats.bytes)
        if last:
            break
        tick += 1
        behind = int((time.monotonic() - start) / period_s) - tick
        if behind > 0:  # a slow line: send the scenario's present, not a backlog
            stats.skipped_ticks += behind
            tick += behind
        delay = start + tick * period_s - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    return stats


def _warn_if_too_fast(port: SerialPort, rate_hz: float, wind_sentence: str, knobs: Knobs) -> None:
    values_b = len(b"".join(nmea_lines(knobs, with_time=False, wind_sentence=wind_sentence)))
    time_b = len(b"".join(nmea_lines(knobs, wind_sentence=wind_sentence))) - values_b
    per_s = rate_hz * values_b + time_b / TIME_PERIOD_S
    capacity = port.baud / SERIAL_BITS_PER_BYTE
    if per_s > capacity:
        print(
            f"warning: about {per_s:.0f} B/s at --rate-hz {rate_hz:g}, but {port.baud} baud "
            f"carries {capacity:.0f} B/s; lower --rate-hz or raise the baud rate",
            file=sys.stderr,
        )


def stop_on_sigterm(_signum: int, _frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def positive_number(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text} is not a positive number")
    return value


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_output_arguments(p)
    p.add_argument("--scenario", choices=sorted(SCENARIOS), default="sweep")
    p.add_argument(
        "--rate-hz", type=positive_number, default=5.0, help="value updates per second (default 5)"
    )
    p.add_argument(
        "--duration-s",
        type=positive_number,
        help="scenario seconds to run (default: the scenario's length; with --loop, for ever)",
    )
    p.add_argument(
        "--speed", type=positive_number, default=1.0, help="scenario seconds per second (default 1)"
    )
    p.add_argument("--loop", action="store_true", help="start the scenario over at its end")
    p.add_argument(
        "--wind-sentence", choices=("mwd", "mwv"), default="mwd", help="NMEA wind sentence"
    )
    p.add_argument("--node-id", type=int, default=1, help="CANaerospace node id (0-255)")
    args = p.parse_args(argv)
    if not 0 <= args.node_id <= 255:
        p.error(f"--node-id {args.node_id} is not 0..255")
    scenario = SCENARIOS[args.scenario]
    duration_s = args.duration_s
    if duration_s is None and not args.loop:
        duration_s = scenario.length_s

    signal.signal(signal.SIGTERM, stop_on_sigterm)
    out: Output
    pty: PtyPort | None = None
    try:
        if args.can:
            out = CanOut(open_can_bus(args.can), args.node_id, f"CAN {args.can}")
        elif args.serial:
            port = SerialPort(args.serial)
            _warn_if_too_fast(port, args.rate_hz, args.wind_sentence, scenario.at(0.0))
            out = NmeaOut(port, args.wind_sentence)
        else:
            pty = PtyPort()
            out = NmeaOut(pty, args.wind_sentence)
    except Exception as exc:  # python-can and pyserial raise their own families
        print(f"cannot open the output: {exc}", file=sys.stderr)
        return 1
    stats = RunStats()
    started = time.monotonic()
    try:
        if pty is not None:
            print(pty.path, flush=True)
            print(f"waiting for a reader, e.g. wxsky run --serial {pty.path}", file=sys.stderr)
            pty.wait_for_reader()
            started = time.monotonic()
        print(f"{scenario.name} ({scenario.summary}) on {out.name}", flush=True)
        run(
            out,
            scenario,
            rate_hz=args.rate_hz,
            duration_s=duration_s,
            speed=args.speed,
            loop=args.loop,
            log=lambda line: print(line, flush=True),
            stats=stats,
        )
        if pty is not None:
            pty.drain()
    except KeyboardInterrupt:
        pass
    finally:
        out.close()
    unit = "frames" if args.can else "lines"
    print(
        f"sent {stats.items} {unit} ({stats.bytes} B) in {time.monotonic() - started:.1f} s"
        + (f", {stats.skipped_ticks} ticks skipped" if stats.skipped_ticks else ""),
        flush=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
