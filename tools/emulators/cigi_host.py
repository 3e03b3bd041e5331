#!/usr/bin/env python3
"""A CIGI 3.3 host emulator: plays a scripted flight (tools/emulators/cigi_script.py) at a host's
frame rate against an image generator, wxsky's or any other, and scores what comes back.

    .venv/bin/python tools/emulators/cigi_host.py --to udp:127.0.0.1:8000 [--rate-hz 60] \\
        [--seconds S] [--byte-order big|little] [--pcap FILE] [--json]

Every message leads with IG Control (operate, the host frame counter, the last IG frame heard)
and moves the ownship (Entity Control 0); the first also sets the view (View Definition,
60° wide). The clock, atmosphere, cloud deck and storm go out when the script changes them
and again each second (CIGI is stateful; the repeat covers a lost datagram), and an
Environmental Conditions Request (weather and aerosol) at the ownship each second.
`--seconds` plays the whole script in that time, its phases and path scaled to fit (default:
its own length, 140 s); the requests and repeats stay once a second.

It records each Start of Frame (IG frame, last host frame applied) and response and reports
messages sent, Starts of Frame received and IG frames without one, how far the SOF's last host
frame trails the host's frame counter (median, p99, max), requests answered, and any datagram
refused or packet dropped on the way back. `--pcap` writes everything sent and received, for
Wireshark (IPv4 only). Exits 1 when no Start of Frame came back, 2 for a bad option.
"""

from __future__ import annotations

import argparse
import ipaddress
import itertools
import json
import statistics
import sys
import threading
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wxsky.errors import ConfigError
from wxsky.inputs.cigi_link import Address, CigiHostSocket, parse_udp
from wxsky.protocols.cigi import (
    ByteOrder,
    CigiDatagram,
    Packet,
    encode_datagram,
    make,
    timestamp_10us,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`

from tools.emulators import cigi_script
from tools.emulators.pcap import Datagram, write_pcap

REPEAT_S = 1.0  # the stateful packets again, and a conditions request, this often
# After the last message, listen until a Start of Frame says the IG applied it (the answers
# to every request come with it or before), or this long.
DRAIN_S = 3.0


@dataclass(frozen=True)
class Sof:
    at_s: float  # time.perf_counter() on receipt
    ig_frame: int
    last_host_frame: int  # the last host frame the IG's frame applied; 0 for none yet
    host_frame: int  # the host's counter on receipt


@dataclass
class HostLink:
    """A CIGI host's end of the link: numbers and sends messages, reads what the IG sends
    back, keeps the score. `send` may be called from several threads, `receive_until` from
    one at a time."""

    to: Address
    byte_order: ByteOrder = "big"
    keep_datagrams: bool = False  # for --pcap
    host_frame: int = 0  # the last host frame sent; 0 before the first
    messages_sent: int = 0
    bytes_sent: int = 0
    sofs: list[Sof] = field(default_factory=list)
    responses: Counter[str] = field(default_factory=Counter)
    answered: set[int] = field(default_factory=set)  # request ids with a weather response
    problems: Counter[str] = field(default_factory=Counter)
    datagrams: list[Datagram] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.sock = CigiHostSocket(self.to)
        self._lock = threading.Lock()

    def close(self) -> None:
        self.sock.close()

    def send(self, packets: Sequence[Packet]) -> tuple[int, float]:
        """One message, IG Control for the next host frame leading `packets`. Returns the
        host frame and time.perf_counter() just before the sendto."""
        with self._lock:
            self.host_frame += 1
            lead = make(
                "ig_control",
                ig_mode=1,
                timestamp_valid=1,
                host_frame_number=self.host_frame & 0xFFFF_FFFF,
                timestamp_10us=timestamp_10us(time.monotonic()),
                last_ig_frame_number=self.sofs[-1].ig_frame if self.sofs else 0,
            )
            data = encode_datagram([lead, *packets], self.byte_order)
            at = time.perf_counter()
            self.sock.send_bytes(data)
            self.messages_sent += 1
            self.bytes_sent += len(data)
            self._keep(self.sock.address, self.to, data)
            return self.host_frame, at

    def receive_until(self, deadline: float) -> None:
        """Score every datagram arriving before time.perf_counter() reaches `deadline` (those
        already waiting when it has passed)."""
        while (got := self.sock.receive(max(0.0, deadline - time.perf_counter()))) is not None:
            self._score(*got)

    def _score(self, decoded: CigiDatagram, data: bytes) -> None:
        now = time.perf_counter()
        self._keep(self.to, self.sock.address, data)
        self.problems.update(decoded.counts)
        if decoded.refused or decoded.direction != "ig_to_host":
            if not decoded.refused:
                self.problems["host_to_ig_message"] += 1
            return
        if decoded.byte_order != self.byte_order:
            self.problems["other_byte_order"] += 1
        rest = list(decoded.packets)
        if not rest or rest[0].key != "start_of_frame":
            self.problems["start_of_frame_dropped"] += 1  # its answers still count
        else:
            sof, *rest = decoded.packets
            ig_frame, applied = int(sof["ig_frame_number"]), int(sof["last_host_frame_number"])
            # An IG splits a long list of answers over datagrams that each lead with the
            # frame's Start of Frame: one frame, one SOF.
            if not self.sofs or self.sofs[-1].ig_frame != ig_frame:
                self.sofs.append(Sof(now, ig_frame, applied, self.host_frame))
        for p in rest:
            self.responses[p.key] += 1
            if p.key == "weather_conditions_response":
                self.answered.add(int(p["request_id"]))

    def _keep(self, src: Address, dst: Address, data: bytes) -> None:
        if self.keep_datagrams:
            self.datagrams.append(Datagram(time.time(), src, dst, data))


def play(link: HostLink, rate_hz: float, seconds: float) -> dict[str, Any]:
    """The script in `seconds` at `rate_hz`, then the IG's last answers; the summary."""
    period, scale = 1.0 / rate_hz, seconds / cigi_script.LENGTH_S
    start = next_tick = time.perf_counter()
    world_sent: list[Packet] = []
    world_at = request_at = -1e9
    clock_sent: tuple[int, int] | None = None
    requests = late = 0
    phases: list[dict[str, Any]] = []
    starts = list(itertools.accumulate((p.length_s for p in cigi_script.SCRIPT), initial=0.0))
    last = len(cigi_script.SCRIPT) - 1
    played = 0  # the script's phases played so far, by index
    while True:
        now = time.perf_counter()
        t = min(now - start, seconds)  # the last message is the script's last moment
        script_s = t / scale
        # A stall longer than a phase (a short script on a busy machine: 10 s of it in 3 s is
        # 0.21 s) must not skip it: every phase is a change the IG is meant to see.
        index = min(last, max(i for i, at in enumerate(starts) if at <= script_s))
        if index > played + 1:
            index = played + 1
            script_s = starts[index]
        played = index
        m = cigi_script.moment(script_s)
        if not phases or phases[-1]["name"] != m.phase.name:
            phases.append({"name": m.phase.name, "at_s": round(t, 3)})
        packets = [cigi_script.ownship(m)]
        if link.host_frame == 0:
            packets.append(cigi_script.view_definition())
        world = cigi_script.world(m.phase, set_clock=False)
        set_clock = m.phase.clock_utc != clock_sent
        if set_clock or world != world_sent or now - world_at >= REPEAT_S:
            packets += cigi_script.world(m.phase, set_clock=True) if set_clock else world
            world_sent, world_at, clock_sent = world, now, m.phase.clock_utc
        if now - request_at >= REPEAT_S:
            # Ids are a byte: past 256 requests an answer counts for each request of its id.
            packets.append(cigi_script.conditions_request(m, requests))
            requests, request_at = requests + 1, now
        link.send(packets)
        if t >= seconds and played == last:
            break
        next_tick += period
        if next_tick < time.perf_counter():  # late: carry on from now, no burst to catch up
            late += 1
            next_tick = time.perf_counter()
        link.receive_until(next_tick)
    elapsed = time.perf_counter() - start
    deadline = time.perf_counter() + DRAIN_S
    while time.perf_counter() < deadline and not (
        link.sofs and link.sofs[-1].last_host_frame >= link.host_frame
    ):
        link.receive_until(min(deadline, time.perf_counter() + 0.05))
    answered = sum(1 for i in range(requests) if i % 256 in link.answered)
    return summary(link, rate_hz, elapsed, late, requests, answered, phases)


def spread(values: Sequence[float]) -> dict[str, float] | None:
    """Median, p99 and max, or None for no values."""
    if not values:
        return None
    p99 = statistics.quantiles(values, n=100, method="inclusive")[98] if values[1:] else values[0]
    return {"median": statistics.median(values), "p99": p99, "max": max(values)}


def summary(
    link: HostLink,
    rate_hz: float,
    elapsed_s: float,
    late: int,
    requests: int,
    answered: int,
    phases: list[dict[str, Any]],
) -> dict[str, Any]:
    frames = [s.ig_frame for s in link.sofs]
    # 0: the IG had no host frame yet; above the counter: a frame another host (or this
    # emulator's last run) sent, still in the IG's frame when this run's first message came.
    lags = [
        s.host_frame - s.last_host_frame for s in link.sofs if 0 < s.last_host_frame <= s.host_frame
    ]
    return {
        "to": f"{link.to[0]}:{link.to[1]}",
        "byte_order": link.byte_order,
        "rate_hz": rate_hz,
        "seconds": round(elapsed_s, 3),
        "messages_sent": link.messages_sent,
        "bytes_sent": link.bytes_sent,
        "late_ticks": late,
        "phases": phases,
        "start_of_frame": {
            "received": len(link.sofs),
            "ig_frames": [frames[0], frames[-1]] if frames else None,
            # IG frames between two received SOFs that sent none (or whose SOF was lost).
            "ig_frames_without_sof": sum(max(0, b - a - 1) for a, b in itertools.pairwise(frames)),
            "lag_host_frames": spread(lags),
            "last_host_frame_applied": max((s.last_host_frame for s in link.sofs), default=0),
        },
        "requests": {"sent": requests, "answered": answered},
        "responses": dict(link.responses),
        "problems": dict(link.problems),
    }


def report(s: dict[str, Any]) -> str:
    sof, lag = s["start_of_frame"], s["start_of_frame"]["lag_host_frames"]
    lag_text = (
        "none" if lag is None else "median {median:g}, p99 {p99:g}, max {max:g}".format(**lag)
    )
    responses = ", ".join(f"{k} {v}" for k, v in sorted(s["responses"].items())) or "none"
    problems = ", ".join(f"{k} {v}" for k, v in sorted(s["problems"].items())) or "none"
    return "\n".join(
        [
            f"CIGI host -> {s['to']}, {s['byte_order']}-endian, {s['rate_hz']:g} Hz, "
            f"{s['seconds']:.1f} s: {s['messages_sent']} messages ({s['bytes_sent']} bytes), "
            f"{s['late_ticks']} late ticks",
            "phases: " + ", ".join(f"{p['name']} at {p['at_s']:.1f} s" for p in s["phases"]),
            f"Start of Frame: {sof['received']} received (IG frames {sof['ig_frames']}), "
            f"{sof['ig_frames_without_sof']} IG frames without one",
            f"host frames applied behind the host's counter at each SOF: {lag_text}",
            f"requests: {s['requests']['sent']} sent, {s['requests']['answered']} answered; "
            f"responses: {responses}",
            f"refused or dropped on the way back: {problems}",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--to", required=True, metavar="udp:HOST:PORT", help="the IG's address")
    p.add_argument("--rate-hz", type=float, default=60.0, help="host frames a second")
    p.add_argument(
        "--seconds",
        type=float,
        default=cigi_script.LENGTH_S,
        help="play the script in this long (default: %(default)g s, its own length)",
    )
    p.add_argument("--byte-order", choices=("big", "little"), default="big")
    p.add_argument("--pcap", type=Path, help="write every datagram sent and received here")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    args = p.parse_args(argv)
    try:
        to = parse_udp(args.to, "--to")
    except ConfigError as exc:
        p.error(str(exc))
    if not (0 < args.rate_hz <= 1000 and args.seconds > 0):
        p.error("--rate-hz must be in (0, 1000] and --seconds above 0")
    if args.pcap is not None and ipaddress.ip_address(to[0]).version != 4:
        p.error("--pcap writes IPv4 only")
    link = HostLink(to, args.byte_order, keep_datagrams=args.pcap is not None)
    try:
        result = play(link, args.rate_hz, args.seconds)
    finally:
        link.close()
    if args.pcap is not None:
        result["pcap"] = {
            "path": str(args.pcap),
            "datagrams": write_pcap(args.pcap, link.datagrams),
        }
    print(json.dumps(result, indent=2) if args.json else report(result))
    return 0 if result["start_of_frame"]["received"] else 1


if __name__ == "__main__":
    sys.exit(main())
