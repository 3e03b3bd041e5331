"""CIGI over UDP: the only module with CIGI sockets.

`CigiIg` is wxsky as an image generator: it listens on a UDP address for a CIGI host,
folds each datagram into the host's state (`protocols.cigi_session`), hands the daemon the
weather, camera and clock that makes, and answers with a Start of Frame for every frame wxsky
publishes, carrying the answers to the host's Environmental Conditions Requests. Replies go to
the source address of the host's datagrams (each starts with IG Control) unless a host
address is configured. Datagrams from addresses outside `allow_from` are dropped and counted.

The work a datagram makes is bounded before it is done (issue 40): a conditions request is
only queued when it arrives (at most `max_queued` waiting; more are dropped and counted one
by one), and the daemon answers at most `[cigi] requests_per_frame` of them after each frame
(`answer_queued`), the rest after the next; it stops early once the frame's share of time
for answers is spent (an answer far from the sky on show makes its cloud blocks, ~2.5 ms
each on a CPU). The host's regions are capped (`max_regions`).

`CigiHostSocket` is the other end: wxsky (or the host emulator, or a test) as a CIGI host
sending to an IG and reading its answers; `wxsky cigi send` and the daemon's `[cigi] send_to`
use it.

Bad input never raises out of here: each dropped packet is counted by reason in the input's
status (`protocols.cigi.REASONS`, plus `not_allowed` and the weather checks' `out_of_range`),
logged rate-limited, and the daemon goes on with the last good state.
"""

from __future__ import annotations

import asyncio
import collections
import ipaddress
import logging
import math
import socket
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any, Protocol, cast

from wxsky.errors import ConfigError, RuntimeFailure
from wxsky.inputs.networks import address_allowed
from wxsky.inputs.networks import parse_networks as parse_networks  # cigi_part imports it here
from wxsky.inputs.stats import InputStats
from wxsky.logs import RateLimitedLog
from wxsky.protocols.cigi import (
    ByteOrder,
    CigiDatagram,
    Packet,
    decode_datagram,
    encode_datagram,
    make,
    timestamp_10us,
)
from wxsky.protocols.cigi_eye import Eye, eye
from wxsky.protocols.cigi_session import MAX_REGIONS, Absorbed, HostState, absorb
from wxsky.protocols.cigi_weather import weather_patch
from wxsky.weather.state import WeatherPatch

log = logging.getLogger("wxsky.inputs.cigi")

MAX_DATAGRAM = 65_535
# A response datagram larger than this is split (Start of Frame leading each): well under
# the 1472-byte UDP payload of an Ethernet frame, so no host sees a fragmented reply.
MAX_REPLY_BYTES = 1400
MAX_PENDING_RESPONSES = 256  # answers waiting for the next frame; more are dropped, counted
# Conditions requests answered after each frame by default (`[cigi] requests_per_frame`): a
# 60 Hz host asking for 20 aircraft a frame sends 40 a frame of the daemon's 30.
REQUESTS_PER_FRAME = 64
# Requests waiting to be answered, in frames' worth: more are dropped (counted per request)
# rather than answered ever later.
QUEUED_FRAMES = 4
Address = tuple[str, int]


def parse_udp(text: str, what: str = "--cigi") -> Address:
    """`udp:HOST:PORT` (HOST an IP address or `localhost`; `[::1]` for IPv6)."""
    scheme, sep, rest = text.partition(":")
    host, sep2, port = rest.rpartition(":")
    if scheme != "udp" or not sep or not sep2 or not host or not port.isdigit():
        raise ConfigError(f"{what} {text!r}: expected udp:HOST:PORT, e.g. udp:127.0.0.1:8001")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    number = int(port)
    if not 0 <= number <= 65_535:
        raise ConfigError(f"{what} {text!r}: port {number} is outside 0..65535")
    if host == "localhost":
        host = "127.0.0.1"
    try:
        ipaddress.ip_address(host)
    except ValueError:
        raise ConfigError(f"{what} {text!r}: {host!r} is not an IP address") from None
    return host, number


class CigiHandler(Protocol):
    """What the IG side asks of the daemon; each runs on the event loop."""

    def cigi_weather(self, patch: WeatherPatch) -> None: ...
    # A datagram came; False when the weather the host gave no longer stands (the daemon
    # handed it back after `[cigi] hold_s` of silence), so that the IG gives it again.
    def cigi_heard(self) -> bool: ...
    def cigi_camera(self, eye: Eye) -> str | None: ...  # why it was refused, or None
    def cigi_clock(self, time_utc: datetime | None, running: bool | None) -> None: ...
    def cigi_answers(self, requests: Sequence[Packet]) -> list[Packet]: ...


@dataclass(frozen=True)
class IgSettings:
    listen: Address
    host_address: Address | None = None
    allow_from: tuple[ipaddress.IPv4Network | ipaddress.IPv6Network, ...] = ()
    view_id: int = 0
    requests_per_frame: int = REQUESTS_PER_FRAME
    max_regions: int = MAX_REGIONS

    @property
    def max_queued(self) -> int:
        """Conditions requests that may wait to be answered; more are dropped."""
        return max(MAX_PENDING_RESPONSES, QUEUED_FRAMES * self.requests_per_frame)


class CigiIg(asyncio.DatagramProtocol):
    """wxsky as a CIGI 3.3 image generator on one UDP address."""

    def __init__(self, settings: IgSettings, handler: CigiHandler) -> None:
        self.settings = settings
        self.name = f"cigi:udp:{settings.listen[0]}:{settings.listen[1]}"
        self.stats = InputStats(self.name, "cigi")
        self.state = HostState()
        self.reply_to: Address | None = settings.host_address
        self.byte_order: ByteOrder | None = None
        self._handler = handler
        self._transport: asyncio.DatagramTransport | None = None
        self._warn = RateLimitedLog(log)
        self._dropped: Counter[str] = Counter()
        self._ignored: Counter[str] = Counter()
        self._pending: list[Packet] = []
        self._requests: collections.deque[Packet] = collections.deque()
        self._requests_answered = 0
        self._regions_evicted = 0
        self._datagrams = 0
        self._sof_sent = 0
        self._responses_sent = 0
        self._send_errors = 0
        self._patch: WeatherPatch | None = None
        self.refresh_detail()

    # -- life ------------------------------------------------------------------------

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        host, port = self.settings.listen
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        try:
            await loop.create_datagram_endpoint(
                lambda: self, local_addr=(host, port), family=family
            )
        except OSError as exc:
            raise RuntimeFailure(
                f"{self.name}: cannot listen: {exc.strerror or exc}; give another address "
                "with --cigi udp:HOST:PORT or [cigi] listen"
            ) from None
        log.info("CIGI IG listening on udp %s:%d", host, self.port)

    @property
    def port(self) -> int:
        """The bound port (the configured one, or the one the system chose for port 0)."""
        if self._transport is None:
            return self.settings.listen[1]
        return int(self._transport.get_extra_info("sockname")[1])

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()
            self._transport = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # The selector loop's datagram transport does not subclass DatagramTransport.
        self._transport = cast(asyncio.DatagramTransport, transport)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable from a host that went away: the next reply tries again.
        self._send_errors += 1
        self._warn.warning("send", f"{self.name}: {exc}")

    # -- receiving -------------------------------------------------------------------

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self._datagrams += 1
        source: Address = (str(addr[0]), int(addr[1]))
        if not self._allowed(source[0]):
            self._drop("not_allowed", f"datagram from {source[0]}:{source[1]}, not in allow_from")
            return
        decoded = decode_datagram(data)
        for problem in decoded.problems:
            self._warn.warning(problem.reason, f"{self.name}: {problem.message}")
        for reason, count in decoded.counts.items():
            self._dropped[reason] += count
        if decoded.counts:
            first = decoded.problems[0].message if decoded.problems else "bad packet"
            self.stats.error(first, sum(decoded.counts.values()))
        if decoded.refused or decoded.direction != "host_to_ig":
            if not decoded.refused:
                self._drop("wrong_direction", f"IG→host message from {source[0]}:{source[1]}")
            return
        try:
            self._take(decoded, source)
        except Exception as exc:  # a wxsky defect: the host's datagram must not end the daemon
            log.debug("CIGI datagram from %s", source, exc_info=True)
            self._drop("internal_error", f"datagram from {source[0]}:{source[1]}: {exc!r}")

    def _allowed(self, host: str) -> bool:
        return address_allowed(host, self.settings.allow_from)

    def _drop(self, reason: str, message: str) -> None:
        self._dropped[reason] += 1
        self.stats.error(message)
        self._warn.warning(reason, f"{self.name}: {message}")

    def _take(self, decoded: CigiDatagram, source: Address) -> None:
        self.byte_order = decoded.byte_order
        if self.settings.host_address is None:
            self.reply_to = source
        done: Absorbed = absorb(
            self.state, decoded, self.settings.view_id, self.settings.max_regions
        )
        self.state = done.state
        if done.evicted:
            self._regions_evicted += done.evicted
            self._warn.warning(
                "regions_evicted",
                f"{self.name}: {done.evicted} regions evicted, least recently touched first: "
                f"more than max_regions = {self.settings.max_regions}",
            )
        self.stats.message()
        for reason, message in done.dropped:
            self._drop(reason, message)
        self._ignored.update(done.ignored)
        h = self._handler
        held = h.cigi_heard()
        if done.clock_utc is not None or done.clock_running is not None:
            h.cigi_clock(done.clock_utc, done.clock_running)
        view = eye(self.state)
        if done.camera_changed and view is not None:
            refused = h.cigi_camera(view)
            if refused is not None:
                self._drop("camera_refused", f"ownship not placed: {refused}")
        if not held:
            # The host fell silent and its weather was handed back; talking again, the
            # weather it set (CIGI's state stays set until the host changes it) is its
            # weather again, though this datagram changed none of it.
            self._patch = None
        if done.weather_changed or not held:
            self._weather(view)
        if done.requests:
            # Only queued here: answering costs a cloud lookup each, and a datagram holds
            # up to 2,046 requests (`answer_queued` does the work, a bounded amount a frame).
            room = self.settings.max_queued - len(self._requests)
            self._requests.extend(done.requests[: max(0, room)])
            if len(done.requests) > room:
                self._drop_many(
                    "requests_full",
                    len(done.requests) - room,
                    f"conditions requests dropped: {self.settings.max_queued} already wait",
                )

    def _drop_many(self, reason: str, count: int, message: str) -> None:
        self._dropped[reason] += count
        self.stats.error(f"{count} {message}", count)
        self._warn.warning(reason, f"{self.name}: {count} {message}")

    @property
    def queued_requests(self) -> int:
        return len(self._requests)

    def answer_queued(self, budget: int, deadline_s: float = math.inf) -> int:
        """Answer up to `budget` of the queued conditions requests, oldest first, starting
        none after `deadline_s` (`time.perf_counter()`) but always the first; the answers go
        with the next Start of Frame. Returns how many were answered. One at a time, so the
        deadline is overrun by one answer at most (a point far from the sky on show makes
        its blocks: milliseconds)."""
        done = 0
        while done < budget and self._requests:
            if done and time.perf_counter() >= deadline_s:
                break
            request = self._requests.popleft()
            done += 1
            try:
                answers = self._handler.cigi_answers([request])
            except Exception as exc:  # a wxsky defect: a host's request must not end the daemon
                log.debug("CIGI conditions request %r", request, exc_info=True)
                self._drop("internal_error", f"conditions request: {exc!r}")
                continue
            self._requests_answered += 1
            room = max(0, MAX_PENDING_RESPONSES - len(self._pending))
            if len(answers) > room:
                self._drop_many("responses_full", len(answers) - room, "answers left out")
            self._pending += answers[:room]
        return done

    def _weather(self, view: Eye | None) -> None:
        """The host's weather at the rendered view's eye, to the daemon when it differs from
        what was sent last. Before the host placed its ownship only a host without regions
        has weather that holds anywhere."""
        if view is None and self.state.regions:
            return
        lat, lon, alt = (view.lat_deg, view.lon_deg, view.alt_m) if view else (0.0, 0.0, 0.0)
        patch = weather_patch(self.state, lat, lon, alt)
        if patch != self._patch:
            self._patch = patch
            self._handler.cigi_weather(patch)

    # -- answering -------------------------------------------------------------------

    def start_of_frame(self, ig_frame: int, host_frame: int | None) -> None:
        """Send the host a Start of Frame for a published frame (with the answers waiting);
        `host_frame` is the last host frame the published frame applied."""
        if self._transport is None or self.reply_to is None or self.byte_order is None:
            return
        state = self.state
        sof = make(
            "start_of_frame",
            database_number=max(0, state.database_number),
            ig_status=0,
            ig_mode=state.ig_mode,
            timestamp_valid=1,
            ig_frame_number=ig_frame & 0xFFFF_FFFF,
            timestamp_10us=timestamp_10us(time.monotonic()),
            last_host_frame_number=(host_frame or 0) & 0xFFFF_FFFF,
        )
        pending, self._pending = self._pending, []
        for chunk in _chunks(sof, pending):
            try:
                self._transport.sendto(encode_datagram(chunk, self.byte_order), self.reply_to)
            except OSError as exc:
                self._send_errors += 1
                self._warn.warning("send", f"{self.name}: reply to {self.reply_to}: {exc}")
                return
        self._sof_sent += 1
        self._responses_sent += len(pending)

    @property
    def last_host_frame(self) -> int | None:
        return self.state.host_frame

    def refresh_detail(self) -> None:
        """Bring `stats.detail` up to date (status asks for it; nothing per datagram)."""
        s = self.state
        self.stats.detail = {
            "host_address": None
            if self.reply_to is None
            else f"{self.reply_to[0]}:{self.reply_to[1]}",
            "listen": f"{self.settings.listen[0]}:{self.port}",
            "byte_order": self.byte_order,
            "last_host_frame": s.host_frame,
            "ig_mode": s.ig_mode,
            "datagrams": self._datagrams,
            "dropped": dict(self._dropped),
            "ignored": dict(self._ignored),
            "regions": len(s.regions),
            "layers": len(s.layers),
            "regions_evicted": self._regions_evicted,
            "requests_queued": len(self._requests),
            "requests_answered": self._requests_answered,
            "start_of_frame_sent": self._sof_sent,
            "responses_sent": self._responses_sent,
            "send_errors": self._send_errors,
        }

    def detail(self) -> dict[str, Any]:
        self.refresh_detail()
        return self.stats.to_dict()


def _chunks(first: Packet, rest: list[Packet]) -> list[list[Packet]]:
    """Messages of at most MAX_REPLY_BYTES, each led by `first`."""
    out = [[first]]
    size = first.spec.size
    for p in rest:
        if size + p.spec.size > MAX_REPLY_BYTES:
            out.append([first])
            size = first.spec.size
        out[-1].append(p)
        size += p.spec.size
    return out


def _default_bind(to: Address, family: int) -> Address:
    """Loopback for an IG on loopback (nothing else can then reach the socket); any address
    otherwise, so the datagrams leave with a source the IG's network routes back."""
    if ipaddress.ip_address(to[0]).is_loopback:
        return ("::1" if family == socket.AF_INET6 else "127.0.0.1", 0)
    return ("::" if family == socket.AF_INET6 else "0.0.0.0", 0)


class CigiHostSocket:
    """A CIGI host's UDP socket: sends messages to an IG and reads its answers (blocking,
    with a timeout). A context manager; `close` is idempotent."""

    def __init__(self, to: Address, bind: Address | None = None) -> None:
        family = socket.AF_INET6 if ":" in to[0] else socket.AF_INET
        self.to = to
        self._sock: socket.socket | None = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._sock.bind(bind or _default_bind(to, family))
        except OSError as exc:
            self._sock.close()
            self._sock = None
            raise ConfigError(f"cannot bind a CIGI host socket to {bind}: {exc.strerror}") from None

    @property
    def address(self) -> Address:
        assert self._sock is not None
        host, port = self._sock.getsockname()[:2]
        return str(host), int(port)

    def send(self, packets: Sequence[Packet], byte_order: ByteOrder = "big") -> int:
        """Send one message; returns its size. An IG that is not there is no error."""
        return self.send_bytes(encode_datagram(packets, byte_order))

    def send_bytes(self, data: bytes) -> int:
        assert self._sock is not None, "socket closed"
        try:
            return self._sock.sendto(data, self.to)
        except ConnectionRefusedError:  # ICMP from an earlier datagram: the IG is not up yet
            return 0

    def receive(self, timeout_s: float) -> tuple[CigiDatagram, bytes] | None:
        """The next datagram from anyone, decoded, or None after timeout_s."""
        assert self._sock is not None, "socket closed"
        self._sock.settimeout(max(0.0, timeout_s))
        try:
            data, _ = self._sock.recvfrom(MAX_DATAGRAM)
        except (TimeoutError, BlockingIOError, ConnectionRefusedError):
            return None
        return decode_datagram(data), data

    def fileno(self) -> int:
        assert self._sock is not None
        return self._sock.fileno()

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> CigiHostSocket:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
