"""Control-channel clients that misbehave, for tools/soak/soak.py: each action is bounded in count
and time, and counts what the daemon did in return.

* `connect-drop`: connect, send a random piece of a request (or nothing), hang up;
* `slow-reader`: subscribe to every topic with a tiny receive buffer and read nothing for a
  few seconds (at most `MAX_SLOW` at a time);
* `flood`: `FLOOD_REQUESTS` requests pipelined as fast as the socket takes them (status, scene,
  unknown methods, bad params), then every answer read; answers missing after
  `FLOOD_TIMEOUT_S` count as `flood_unanswered`;
* `bad-bytes`: one message that is not the protocol per connection (not msgpack, positional
  params, a huge announced string, 2,000-deep nesting, an int map key, an extension type, a
  40 kB request); each must be answered with an error, the unreadable ones followed by a
  hang-up (the announced string may also be waited for: protocol §2.2 lets a receiver wait);
* `bad-commands`: well-formed requests the daemon must refuse (a camera at 1e308 m or NaN
  degrees, a 10 kB or path-like preset name, a report that is not a METAR, a negative clock
  rate, ...): each one it accepts is an invalid input that reached the daemon (`accepted_bad`);
* `burst`: `burst` connections at once, held for a second; those the daemon refuses (over
  its connection limit) are counted as `burst refused`.

Responses are read with msgpack itself, not wxsky's decoder, so a defect there shows up as
the daemon's.
"""

from __future__ import annotations

import contextlib
import logging
import math
import random
import select
import socket
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import msgpack

from wxsky.errors import WxskyError
from wxsky.host.client import ControlClient, DaemonUnavailable, RemoteError
from wxsky.output.wire import Request, Response, encode

log = logging.getLogger("soak.control")

ACTIONS = ("connect-drop", "flood", "slow-reader", "bad-bytes", "bad-commands", "burst")
MAX_SLOW = 4
SLOW_HOLD_S = (2.0, 8.0)
FLOOD_REQUESTS = 500
FLOOD_TIMEOUT_S = 10.0
ANSWER_TIMEOUT_S = 3.0

BAD_BYTES: tuple[tuple[str, bytes, bool | None], ...] = (
    # (what, bytes, the daemon hangs up after answering; None: it may also wait for more)
    ("not msgpack", b"\xc1\xc1\xc1\xc1", True),
    ("positional params", b"\x94\x00\x07\xa6status\x91\x01", False),
    # Protocol §2.2: a receiver *may* refuse a header announcing more than 8 MiB at once.
    ("a 100 MB string announced", b"\x94\x00\x08\xa6status\xdb\x06\x00\x00\x00", None),
    ("2,000-deep nesting", b"\x91" * 2000 + b"\xc0", True),
    ("an int map key", b"\x94\x00\x09\xa6status\x81\x01\x02", True),
    # msgpack frames an extension type, so the stream stays in step: answered, left open (§2.5).
    ("an extension type", b"\x94\x00\x0a\xa6status\xd4\x01\x00", False),
    ("a request that is not an array", b"\xa6status", True),
    # Over the 32 KiB a request may have (§2.2 of the working tree; 8 MiB before).
    ("a 40 kB request", encode(Request(11, "apply_metar", {"report": "X" * 40_000})), None),
)

BAD_COMMANDS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("set_camera", {"position_m": [1e308, 0.0, 1000.0]}),
    ("set_camera", {"heading_deg": math.nan}),
    ("set_camera", {"width": 1_000_000}),
    ("set_camera", {"pitch_deg": 1e9}),
    ("set_aircraft", {"position_m": [math.inf, 0.0, 0.0]}),
    ("set_time", {"time_utc": "yesterday"}),
    ("set_time", {"rate": -1.0}),
    ("apply_metar", {"report": ""}),
    ("apply_metar", {"report": "NOT A METAR AT ALL"}),
    ("apply_metar", {"report": "X" * 5000}),  # over the 4096 characters a report may have
    ("apply_preset", {"name": "../../../../etc/passwd"}),
    ("apply_preset", {"name": "p" * 10_000}),
    ("apply_preset", {"name": "no-such-preset"}),
    ("release", {"source": "metar"}),
    ("status", {"verbose": True}),
    ("no_such_method", {}),
)

FLOOD_MIX: tuple[tuple[str, dict[str, Any]], ...] = (
    ("status", {}),
    ("scene", {}),
    ("no_such_method", {"x": 1}),
    ("set_camera", {"heading_deg": "north"}),
    ("subscribe", {"topics": 7}),
)


class ControlFaults:
    def __init__(self, sock_path: Path, rng: random.Random, burst: int) -> None:
        self.sock_path = sock_path
        self.address = f"unix:{sock_path}"
        self.rng = rng
        self.burst = burst
        self.counts: Counter[str] = Counter()
        self.accepted_bad: list[str] = []  # bad commands the daemon took
        self.problems: list[str] = []
        self._slow: list[threading.Thread] = []
        self._lock = threading.Lock()

    def run(self, stop: threading.Event, period_s: float) -> None:
        """One action every period_s, in turn, until stop."""
        i = 0
        while not stop.wait(period_s):
            action = ACTIONS[i % len(ACTIONS)]
            i += 1
            try:
                getattr(self, "_" + action.replace("-", "_"))(stop)
                self.counts[action] += 1
            except (OSError, WxskyError) as exc:
                self._problem(f"{action}: {type(exc).__name__}: {exc}")
        for thread in self._slow:
            thread.join(timeout=SLOW_HOLD_S[1] + 2.0)

    def summary(self) -> dict[str, Any]:
        return {
            "actions": dict(self.counts),
            "accepted_bad": self.accepted_bad,
            "problems": self.problems[:20],
            "problem_count": len(self.problems),
        }

    # -- the actions --------------------------------------------------------------------

    def _connect(self, rcvbuf: int | None = None) -> socket.socket:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        if rcvbuf:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        sock.settimeout(ANSWER_TIMEOUT_S)
        try:
            sock.connect(str(self.sock_path))
        except BaseException:
            sock.close()
            raise
        return sock

    def _connect_drop(self, stop: threading.Event) -> None:
        with self._connect() as sock:
            data = encode(Request(1, "status", {}))
            cut = self.rng.randrange(0, len(data))
            if cut:
                sock.sendall(data[:cut])

    def _slow_reader(self, stop: threading.Event) -> None:
        self._slow = [t for t in self._slow if t.is_alive()]
        if len(self._slow) >= MAX_SLOW:
            self.counts["slow-reader skipped"] += 1
            return
        hold_s = self.rng.uniform(*SLOW_HOLD_S)
        sock = self._connect(rcvbuf=1024)

        def hold() -> None:
            with sock:
                topics = ["frame", "weather", "target", "scene"]
                sock.sendall(encode(Request(1, "subscribe", {"topics": topics})))
                stop.wait(hold_s)  # and read nothing

        thread = threading.Thread(target=hold, name="soak-slow-reader", daemon=True)
        thread.start()
        self._slow.append(thread)

    def _flood(self, stop: threading.Event) -> None:
        requests = b"".join(
            encode(Request(i, *FLOOD_MIX[i % len(FLOOD_MIX)])) for i in range(FLOOD_REQUESTS)
        )
        answered = 0
        decoder = _Decoder()
        with self._connect() as sock:
            sock.setblocking(False)
            sent = 0
            deadline = time.monotonic() + FLOOD_TIMEOUT_S
            while answered < FLOOD_REQUESTS and time.monotonic() < deadline:
                want_write = [sock] if sent < len(requests) else []
                readable, writable, _ = select.select([sock], want_write, [], 0.2)
                if writable:
                    with contextlib.suppress(BlockingIOError):
                        sent += sock.send(requests[sent : sent + 65536])
                if readable:
                    data = sock.recv(1 << 16)
                    if not data:
                        break
                    try:
                        answered += len(decoder.feed(data))
                    except ValueError as exc:
                        self._problem(f"flood: bad data from the daemon: {exc}")
                        break
        self.counts["flood requests"] += FLOOD_REQUESTS
        self.counts["flood answered"] += answered
        if answered < FLOOD_REQUESTS:
            self.counts["flood unanswered"] += FLOOD_REQUESTS - answered

    def _bad_bytes(self, stop: threading.Event) -> None:
        for what, data, hangs_up in BAD_BYTES:
            with self._connect() as sock:
                sock.sendall(data)
                answer, closed = _read_answer(sock)
            self.counts["bad-bytes sent"] += 1
            if answer is None and hangs_up is None and not closed:
                self.counts["bad-bytes waited for"] += 1
            elif answer is None or answer.error is None:
                self._problem(f"bad-bytes {what}: no error answer ({answer})")
            elif hangs_up and not closed:
                self._problem(f"bad-bytes {what}: answered but not disconnected")
            else:
                self.counts["bad-bytes answered"] += 1

    def _bad_commands(self, stop: threading.Event) -> None:
        try:
            client = ControlClient.connect(self.address)
        except DaemonUnavailable as exc:
            self._problem(f"bad-commands: {exc}")
            return
        with client:
            for method, params in BAD_COMMANDS:
                self.counts["bad-commands sent"] += 1
                try:
                    client.call(method, params, timeout_s=ANSWER_TIMEOUT_S)
                except RemoteError:
                    self.counts["bad-commands refused"] += 1
                    continue
                except DaemonUnavailable as exc:
                    self._problem(f"bad-commands {method}: {exc}")
                    return
                with self._lock:
                    self.accepted_bad.append(f"{method} {_short(params)}")

    def _burst(self, stop: threading.Event) -> None:
        socks: list[socket.socket] = []
        try:
            for _ in range(self.burst):
                try:
                    socks.append(self._connect())
                except OSError as exc:
                    self._problem(f"burst: connection {len(socks) + 1}: {exc}")
                    break
            self.counts["burst connections"] += len(socks)
            stop.wait(1.0)
            # Over the daemon's connection limit (§2.4.1) it answers and closes at once.
            self.counts["burst refused"] += sum(_closed_by_daemon(sock) for sock in socks)
        finally:
            for sock in socks:
                sock.close()

    def _problem(self, text: str) -> None:
        with self._lock:
            self.problems.append(text)
        log.debug("control fault: %s", text)


def _closed_by_daemon(sock: socket.socket) -> bool:
    """True when the daemon answered (it sends a fresh connection nothing unasked, but the
    refusal) or hung up."""
    sock.setblocking(False)
    try:
        sock.recv(1 << 16)
    except BlockingIOError:
        return False
    except OSError:
        pass
    return True


def _read_answer(sock: socket.socket) -> tuple[Response | None, bool]:
    """The first response on `sock` and whether the daemon then hung up (within the timeout)."""
    decoder = _Decoder()
    answer: Response | None = None
    deadline = time.monotonic() + ANSWER_TIMEOUT_S
    while time.monotonic() < deadline:
        sock.settimeout(max(0.01, deadline - time.monotonic()))
        try:
            data = sock.recv(1 << 16)
        except TimeoutError:
            break
        except OSError:
            return answer, True
        if not data:
            return answer, True
        try:
            messages = decoder.feed(data)
        except ValueError:
            return answer, True
        for message in messages:
            answer = answer or message
        if answer is not None and answer.msgid is not None:
            return answer, False  # a recoverable error: the connection stays open
    return answer, False


class _Decoder:
    """The daemon's responses, read with msgpack itself rather than wxsky's own decoder, so a
    defect of that decoder shows as the daemon's and does not hide in the soak's clients."""

    def __init__(self) -> None:
        self._unpacker = msgpack.Unpacker(raw=False, strict_map_key=False)

    def feed(self, data: bytes) -> list[Response]:
        self._unpacker.feed(data)
        out = []
        for obj in self._unpacker:
            if not (isinstance(obj, list) and len(obj) == 4 and obj[0] == 1):
                raise ValueError(f"not a response: {obj!r:.80}")
            out.append(Response(obj[1], obj[2], obj[3]))
        return out


def _short(params: dict[str, Any]) -> str:
    text = repr(params)
    return text if len(text) <= 80 else text[:77] + "..."
