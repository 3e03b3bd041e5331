"""How long one big control request holds up the other clients of a real daemon.

    .venv/bin/python tools/bench/control_stall.py [--rounds 3]

Starts a private daemon (small frames), keeps a second client calling `status` in a loop, and
sends from a raw connection, one at a time: an `apply_metar` whose report fills the largest
message the daemon reads, a `subscribe` whose topic list fills it, and an `apply_metar` with
the longest report the daemon accepts. Prints, per case, how long the sender waited for its
answer and the longest `status` round trip the other client saw meanwhile, against the
median round trip with nothing else going on (all in ms, the worst of `--rounds`).
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from wxsky.app import control
from wxsky.errors import ProtocolError
from wxsky.host.client import ControlClient
from wxsky.output import wire
from wxsky.output.wire import MessageDecoder, Request

# The largest message the daemon reads: the request limit where there is one, else the
# protocol's message limit (before the control channel had a request limit).
READ_LIMIT: int = getattr(wire, "MAX_REQUEST_SIZE", wire.MAX_MESSAGE_SIZE)
METAR_HEAD = "LSZH 211250Z 24012KT 9999 "


def _metar_of(size: int) -> str:
    groups = "BKN080 " * (size // 7 + 1)
    return (METAR_HEAD + groups)[:size].rstrip() + " 18/09 Q1012"


def _fill(make: Any, limit: int) -> dict[str, Any]:
    """The params made by make(n) with the largest n whose request encodes within `limit`."""
    lo, hi = 1, limit
    while lo < hi:
        mid = (lo + hi + 1) // 2
        try:
            fits = len(_enc(make(mid))) <= limit
        except ProtocolError:  # over the protocol's own limit
            fits = False
        if fits:
            lo = mid
        else:
            hi = mid - 1
    params: dict[str, Any] = make(lo)
    return params


def _enc(params: dict[str, Any]) -> bytes:
    method = params["__method"]
    rest = {k: v for k, v in params.items() if k != "__method"}
    return wire.encode(Request(1, method, rest))


@contextlib.contextmanager
def _daemon() -> Iterator[str]:
    with tempfile.TemporaryDirectory() as tmp:
        sock = Path(tmp) / "wx.sock"
        cfg = Path(tmp) / "wxsky.toml"
        shm = f"wxsky-stall-{uuid.uuid4().hex[:8]}"
        cfg.write_text(
            f'[output]\nshm_name = "{shm}"\nmax_width = 320\nmax_height = 180\n'
            "[camera]\nwidth = 320\nheight = 180\n"
        )
        cmd = [sys.executable, "-m", "wxsky", "run", "--config", str(cfg)]
        proc = subprocess.Popen(
            [*cmd, "--control", f"unix:{sock}"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            deadline = time.monotonic() + 60
            while True:
                with contextlib.suppress(Exception), ControlClient.connect(f"unix:{sock}") as c:
                    if c.call("status")["frames_published"] > 0:
                        break
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise SystemExit("the daemon did not start")
                time.sleep(0.2)
            yield f"unix:{sock}"
        finally:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()


def _probe(address: str, stop: threading.Event, out: list[tuple[float, float]]) -> None:
    """Call `status` in a loop; record (start, round trip s) of each call."""
    with ControlClient.connect(address) as c:
        while not stop.is_set():
            t0 = time.monotonic()
            c.call("status", timeout_s=120)
            out.append((t0, time.monotonic() - t0))


def _send(path: str, data: bytes) -> float:
    """Send one request on a fresh connection; seconds until the answer (or the hang-up)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(120)
        s.connect(path)
        t0 = time.monotonic()
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):
            s.sendall(data)
        decoder = MessageDecoder()
        while True:
            try:
                chunk = s.recv(65536)
            except ConnectionResetError:
                chunk = b""
            if not chunk or decoder.feed(chunk):
                return time.monotonic() - t0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    cases = {
        f"apply_metar, report filling {READ_LIMIT} B": _fill(
            lambda n: {"__method": "apply_metar", "report": _metar_of(n)}, READ_LIMIT
        ),
        f"subscribe, topics filling {READ_LIMIT} B": _fill(
            lambda n: {"__method": "subscribe", "topics": [f"t{i:06d}" for i in range(n)]},
            READ_LIMIT,
        ),
    }
    longest = getattr(control, "METAR_MAX_CHARS", None)
    if longest is not None:
        cases[f"apply_metar, longest accepted report ({longest} chars)"] = {
            "__method": "apply_metar",
            "report": _metar_of(longest - 12),
        }
    with _daemon() as address:
        path = address.removeprefix("unix:")
        rtts: list[tuple[float, float]] = []
        stop = threading.Event()
        probe = threading.Thread(target=_probe, args=(address, stop, rtts), daemon=True)
        probe.start()
        time.sleep(2.0)
        idle = statistics.median(r for _, r in rtts)
        print(f"status round trip, nothing else going on: median {idle * 1e3:.1f} ms")
        for name, params in cases.items():
            data = _enc(params)
            worst_send, worst_stall = 0.0, 0.0
            for _ in range(args.rounds):
                start = time.monotonic()
                took = _send(path, data)
                time.sleep(0.3)  # let a status call that was held up finish
                during = [r for t, r in rtts if t + r >= start and t <= start + took]
                worst_send = max(worst_send, took)
                worst_stall = max([worst_stall, *during])
            print(
                f"{name} ({len(data)} B): answered in {worst_send * 1e3:.0f} ms; "
                f"longest status round trip meanwhile {worst_stall * 1e3:.0f} ms"
            )
        stop.set()
        probe.join(130)
    return 0


if __name__ == "__main__":
    sys.exit(main())
