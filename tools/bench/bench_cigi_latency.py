#!/usr/bin/env python3
"""How long a CIGI host's change takes to show in wxsky: a private daemon listens with
`--cigi udp:127.0.0.1:0`, this process is the host and times

    ownship      an Entity Control change (position and heading) -> the first `frame`
                 notification whose camera shows it;
    ownship SOF  the same change -> the first Start of Frame whose last host frame is the
                 change's or later (what the host itself sees over CIGI);
    weather      a Weather Control change (layer 1's base and coverage) -> the `target`
                 notification on the daemon's stream that shows it.

    .venv/bin/python tools/bench/bench_cigi_latency.py [--changes 120] [--tick-hz 30] [--json]

The host sends its frame (IG Control, the ownship, from the weather case on layer 1) at 60 Hz
throughout, as a host does; each change goes out at once as a message of its own, after a
random pause, so changes land at every phase of the daemon's tick and the host's frame
(tools/bench/bench_cockpit_latency.py measures the same way). Times run from the change, its
encoding and sendto included. The ownship goes first, once the rings built for start-up have
settled: the daemon moves its sky toward a host's weather at the [transition] rates, for
minutes, rebuilding the ring on the way, and those frames are the weather's cost. Prints
median, p99 and max per case, and the daemon's frame rate meanwhile (a camera change shows in
the frame after the one being drawn), against the issue's budget, one daemon tick plus 20 ms.
Frames are 640x360 by default (`--size`): a camera change waits for the frame being drawn and
then draws one, so on a CPU renderer the frame's own time decides whether it fits the budget.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`

from tools.bench.bench_cockpit_latency import Case, _drain, _measure, _p99
from tools.emulators.cigi_host import HostLink, Sof
from tools.emulators.cigi_script import AIRPORT_LAT, AIRPORT_LON
from tools.emulators.cockpit_daemon import private_daemon
from wxsky.host.client import ControlClient
from wxsky.inputs.cigi_link import parse_udp
from wxsky.protocols.cigi import Packet, make
from wxsky.weather.geo import geodetic_from_enu

CONFIG = """
[daemon]
tick_hz = {tick_hz}
[output]
max_width = {width}
max_height = {height}
[camera]
width = {width}
height = {height}
"""
HOST_RATE_HZ = 60.0
SHOW_TIMEOUT_S = 10.0
SYNC = "sync ownship -> frame"  # a change that never shows stops the run instead of hanging it


class HostLoop(threading.Thread):
    """The host's 60 Hz frames: the last state, again and again, and the IG's answers read
    in between. `change` sends a new state at once, never overtaken by an old one."""

    def __init__(self, link: HostLink, packets: list[Packet]) -> None:
        super().__init__(daemon=True)
        self.link = link
        self.packets = packets
        self.sent: list[tuple[int, float]] = []  # per change: host frame, sendto time
        self._lock = threading.Lock()
        self._halt = threading.Event()

    def change(self, packets: list[Packet]) -> None:
        with self._lock:
            self.packets = packets
            self.sent.append(self.link.send(packets))

    def run(self) -> None:
        next_tick = time.perf_counter()
        while not self._halt.is_set():
            with self._lock:
                self.link.send(self.packets)
            next_tick = max(next_tick + 1.0 / HOST_RATE_HZ, time.perf_counter())
            self.link.receive_until(next_tick)

    def stop(self) -> None:
        self._halt.set()
        self.join()


# Change i's state. Each differs from the one before; change -1 is the host's first state.
def _layer(i: int) -> tuple[float, float]:
    """Layer 1: base m, coverage %."""
    return 1000.0 + 20.0 * (i % 25), 50.0 + 20.0 * (i % 2)


def _place(i: int) -> tuple[float, float, float]:
    """The ownship: east m, north m, heading. Steps of metres, as a host's frames move it
    (a jump of a kilometre would have the ring rebuilt, a cost of its own); a turn does not
    move the ring."""
    return 5.0 * (i % 20), 0.0, float(37 * i % 360) + 0.5


def _packets(layer: tuple[float, float] | None, place: tuple[float, float, float]) -> list[Packet]:
    east, north, heading = place
    lat, lon = geodetic_from_enu(AIRPORT_LAT, AIRPORT_LON, east, north)
    ownship = make(
        "entity_control",
        entity_state=1,
        pitch_deg=5.0,
        yaw_deg=heading,
        lat_deg=lat,
        lon_deg=lon,
        alt_m=800.0,  # below the deck: the cloud base is 1000 m or higher
    )
    if layer is None:
        return [ownship]
    base, cover = layer
    return [
        ownship,
        make(
            "weather_control",
            layer_id=1,
            weather_enable=1,
            cloud_type=9,
            coverage_pct=cover,
            base_elevation_m=base,
            thickness_m=500.0,
        ),
    ]


def _deadline(shows: Case, loop: HostLoop) -> Case:
    def checked(i: int, params: dict[str, Any]) -> bool:
        if time.perf_counter() - loop.sent[-1][1] > SHOW_TIMEOUT_S:
            raise SystemExit(f"{shows.name}: change {i} not shown in {SHOW_TIMEOUT_S:g} s")
        return shows.shows(i, params)

    return Case(shows.name, shows.send, checked)


def _cases(loop: HostLoop) -> tuple[Case, Case]:
    # Each case changes one thing: the other stays where the last change left it.
    layer: tuple[float, float] | None = None  # no weather until the weather case
    place = _place(-1)

    def weather(i: int) -> None:
        nonlocal layer
        layer = _layer(i)
        loop.change(_packets(layer, place))

    def weather_shows(i: int, target: dict[str, Any]) -> bool:
        base, cover = _layer(i)
        return any(
            abs(lay["base_m"] - base) < 0.01 and abs(lay["cover_oktas"] - cover * 0.08) < 1e-4
            for lay in target["layers"]
        )

    def ownship(i: int) -> None:
        nonlocal place
        place = _place(i)
        loop.change(_packets(layer, place))

    def ownship_shows(i: int, frame: dict[str, Any]) -> bool:
        east, north, heading = _place(i)
        cam = frame["camera"]
        x, y, _ = cam["position_m"]
        turned = abs(float(cam["heading_deg"]) - heading) < 0.01
        return turned and abs(x - east) + abs(y - north) < 0.5

    return (
        _deadline(Case("ownship -> frame", ownship, ownship_shows), loop),
        _deadline(Case("weather -> target", weather, weather_shows), loop),
    )


def _synchronous(client: ControlClient, loop: HostLoop, changes: int) -> list[float]:
    """Ownship changes sent the moment a Start of Frame arrives, as a host in CIGI's
    synchronous mode answers each IG frame with its own; ms to the `frame` notification
    showing each. The host's data then lands just after the IG published a frame, and the
    next frame takes it."""
    out = []
    for i in range(changes):
        seen = len(loop.link.sofs)
        deadline = time.perf_counter() + SHOW_TIMEOUT_S
        while len(loop.link.sofs) == seen:
            if time.perf_counter() > deadline:
                raise SystemExit("ownship, synchronous host: no Start of Frame")
            time.sleep(0.0002)
        _drain(client)
        place = _place(1000 + i)
        start = time.perf_counter()
        loop.change(_packets(None, place))
        while True:
            note = client.next_notification(timeout_s=2.0)
            if note is None:
                raise SystemExit(f"ownship, synchronous host: change {i} never shown")
            cam = note.params["camera"] if note.method == "frame" else None
            if cam is not None and abs(float(cam["heading_deg"]) - place[2]) < 0.01:
                x, y, _ = cam["position_m"]
                if abs(x - place[0]) + abs(y - place[1]) < 0.5:
                    out.append((time.perf_counter() - start) * 1000.0)
                    break
    return out


def _sof_ms(loop: HostLoop, changes: Sequence[tuple[int, float]]) -> list[float]:
    """Per change, ms to the first Start of Frame that had applied its host frame."""
    out = []
    for frame, at in changes:
        sof = next((s for s in loop.link.sofs if s.at_s > at and s.last_host_frame >= frame), None)
        if sof is None:
            raise SystemExit(f"ownship -> SOF: no Start of Frame applied host frame {frame}")
        out.append((sof.at_s - at) * 1000.0)
    return out


def measure(
    changes: int, tick_hz: float, size: tuple[int, int] = (640, 360), preset: str | None = None
) -> dict[str, Any]:
    args = ["--cigi", "udp:127.0.0.1:0", *(("--preset", preset) if preset else ())]
    spans: dict[str, tuple[float, float]] = {}  # case -> perf_counter() span, for its fps
    with (
        private_daemon(CONFIG.format(tick_hz=tick_hz, width=size[0], height=size[1]), args) as (
            _,
            client,
        ),
        ControlClient.connect(client.address) as frames,
    ):
        status = client.call("status")
        listen = next(i["listen"] for i in status["inputs"] if i["kind"] == "cigi")
        loop = HostLoop(HostLink(parse_udp(f"udp:{listen}")), _packets(None, _place(-1)))
        loop.start()
        try:
            # A client per topic: a change that never shows times out on a quiet stream
            # instead of waiting among the frames.
            client.subscribe(["target"])
            frames.subscribe(["frame"])
            ownship, weather = _cases(loop)
            _ring_still(client)
            results: dict[str, list[float]] = {}
            for case, client_, topic in ((ownship, frames, "frame"), (weather, client, "target")):
                start = time.perf_counter()
                results[case.name] = _measure(client_, case, changes, topic)
                spans[case.name] = (start, time.perf_counter())
                if case is ownship:
                    start = time.perf_counter()
                    results[SYNC] = _synchronous(frames, loop, changes)
                    spans[SYNC] = (start, time.perf_counter())
        finally:
            loop.stop()
            loop.link.close()
        sof = _sof_ms(loop, loop.sent[:changes])
        results = {
            ownship.name: results[ownship.name],
            "ownship -> SOF": sof,
            SYNC: results[SYNC],
            weather.name: results[weather.name],
        }
        spans["ownship -> SOF"] = spans[ownship.name]
    budget_ms = 1000.0 / tick_hz + 20.0
    return {
        "cpu_cores": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
        "tick_hz": tick_hz,
        "tick_ms": 1000.0 / tick_hz,
        "budget_ms": budget_ms,
        "frame_size": f"{size[0]}x{size[1]}",
        "preset": preset or "the config's (fair-cumulus)",
        "host_rate_hz": HOST_RATE_HZ,
        "cases": {
            name: _stats(ms, budget_ms, _fps(loop.link.sofs, *spans[name]))
            for name, ms in results.items()
        },
    }


def _ring_still(client: ControlClient, still_s: float = 1.5, limit_s: float = 60.0) -> None:
    """Wait out the rings built for start-up and for the host's ownship (800 m up, where the
    first ring was centred on the default camera): their frames are no ownship change's."""
    deadline = time.monotonic() + limit_s
    last, since = None, time.monotonic()
    while time.monotonic() < deadline:
        scene = client.call("scene")
        now = (scene["ring_version"], scene["ring_busy"])
        if now != last:
            last, since = now, time.monotonic()
        elif not scene["ring_busy"] and time.monotonic() - since >= still_s:
            return
        time.sleep(0.1)
    raise SystemExit(f"the daemon's ring did not hold still within {limit_s:g} s")


def _fps(sofs: Sequence[Sof], start: float, end: float) -> float:
    """The daemon's frame rate between two times: it sends a Start of Frame per frame."""
    return sum(start <= s.at_s <= end for s in sofs) / (end - start)


def _stats(ms: list[float], budget_ms: float, fps: float) -> dict[str, Any]:
    return {
        "n": len(ms),
        "median_ms": statistics.median(ms),
        "p99_ms": _p99(ms),
        "max_ms": max(ms),
        "within_budget": sum(x <= budget_ms for x in ms),
        "p99_within_budget": _p99(ms) <= budget_ms,
        "fps": fps,
    }


def report(r: dict[str, Any]) -> str:
    lines = [
        f"cpu: {r['cpu_cores']} cores, load {r['load_average_1min']:.1f}; daemon tick "
        f"{r['tick_hz']:g} Hz ({r['tick_ms']:.1f} ms), {r['frame_size']}, {r['preset']}; host "
        f"{r['host_rate_hz']:g} Hz",
        f"budget: one tick + 20 ms = {r['budget_ms']:.1f} ms (p99)",
        f"{'case':<22} {'n':>4} {'median ms':>10} {'p99 ms':>8} {'max ms':>8} {'fps':>5}"
        "  within budget",
    ]
    for name, c in r["cases"].items():
        verdict = "p99 within" if c["p99_within_budget"] else "p99 OVER"
        lines.append(
            f"{name:<22} {c['n']:>4} {c['median_ms']:>10.2f} {c['p99_ms']:>8.2f} "
            f"{c['max_ms']:>8.2f} {c['fps']:>5.1f}  {c['within_budget']}/{c['n']}, {verdict}"
        )
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--changes", type=int, default=120, help="changes per case (>= 100)")
    p.add_argument("--tick-hz", type=float, default=30.0, help="the daemon's [daemon] tick_hz")
    p.add_argument("--size", default="640x360", help="frame size WxH (default 640x360)")
    p.add_argument("--preset", help="the daemon's start-up sky (default: the config's)")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    args = p.parse_args()
    width, _, height = args.size.partition("x")
    if not (width.isdigit() and height.isdigit()):
        p.error(f"--size {args.size!r}: expected WxH, e.g. 320x180")
    result = measure(args.changes, args.tick_hz, (int(width), int(height)), args.preset)
    print(json.dumps(result, indent=2) if args.json else report(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
