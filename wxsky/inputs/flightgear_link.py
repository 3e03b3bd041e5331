"""The sockets to FlightGear (issue 18; the one module that owns them): its pose stream in (the
generic protocol over UDP, `plugins/flightgear/Protocol/wxsky.xml`) and wxsky's weather out to
its telnet/props server.

Both run on threads of their own and never hold up the daemon's tick: FlightGear's props
server stalls for seconds when its frames are slow, and FlightGear may restart at any time.
The writer keeps only the latest weather offered, writes the properties that changed (all of
them after a connect, as a restarted FlightGear has forgotten them), at most every
`min_interval_s`, and reconnects with back-off while FlightGear is away (`ok` false then).
"""

from __future__ import annotations

import logging
import select
import socket
import threading
import time
from collections.abc import Callable, Sequence

from wxsky.errors import RuntimeFailure
from wxsky.inputs.networks import Network, address_allowed
from wxsky.inputs.stats import InputStats
from wxsky.logs import RateLimitedLog
from wxsky.protocols.flightgear import TAKE_OVER, FgPose, parse_pose, weather_properties
from wxsky.weather.state import WeatherState

log = logging.getLogger(__name__)

MAX_DATAGRAM = 2048
BACKOFF_S = (0.5, 10.0)  # first and longest wait between connection attempts
CONNECT_TIMEOUT_S = 2.0
SEND_TIMEOUT_S = 5.0  # a props server stalled this long is treated as gone
# A props server that accepts and then reads nothing takes every write into the socket buffers
# for hours: liveness is an answer. Every PROBE_INTERVAL_S the writer asks for a property
# (FlightGear answers a `get` within a frame, in data mode with just the value), and one
# unanswered for REPLY_TIMEOUT_S (FlightGear's slowest frames take seconds) ends the connection.
PROBE = b"get /sim/time/elapsed-sec\r\n"
PROBE_INTERVAL_S = 5.0
REPLY_TIMEOUT_S = 15.0


class _Unanswered(OSError):
    """A props server that answered no probe in time: the connection is ended."""


class FlightGearPose:
    """Receives FlightGear's pose lines on a UDP socket and hands each good pose to
    `on_pose` (on this object's thread); bad lines are counted, with the last reason.
    Datagrams from outside `allow_from` (empty: anywhere) are dropped unread and counted in
    the status as `not_allowed`: a pose moves the camera and may set the clock."""

    def __init__(
        self,
        host: str,
        port: int,
        on_pose: Callable[[FgPose], None],
        name: str = "flightgear",
        stats: InputStats | None = None,
        allow_from: Sequence[Network] = (),
    ) -> None:
        self.stats = stats or InputStats(f"{name}:pose", "flightgear")
        self.name = name
        self._allow_from = tuple(allow_from)
        self.stats.detail["not_allowed"] = 0
        self._warn = RateLimitedLog(log)
        self._on_pose = on_pose
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise RuntimeFailure(
                f"{name}: cannot listen for the pose stream on udp:{host}:{port}: "
                f"{exc.strerror or exc}; give another address with --flightgear-pose "
                "udp:HOST:PORT or [flightgear] pose"
            ) from None
        self._sock.settimeout(0.2)
        self.address = self._sock.getsockname()
        self.last_pose: FgPose | None = None
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._run, name="wxsky-fg-pose", daemon=True)
        self._thread.start()

    def close(self, wait_s: float = 1.0) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        self._thread.join(wait_s)
        self._sock.close()

    def __enter__(self) -> FlightGearPose:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        while not self._closed.is_set():
            try:
                data, source = self._sock.recvfrom(MAX_DATAGRAM)
            except TimeoutError:
                continue
            except OSError:
                if self._closed.is_set():
                    return
                raise
            if not address_allowed(source[0], self._allow_from):
                self.stats.detail["not_allowed"] += 1
                message = f"pose datagram from {source[0]}:{source[1]}, not in allow_from"
                self.stats.error(message)
                self._warn.warning("not_allowed", f"{self.name}: {message}")
                continue
            # A datagram holds one line, or a few if FlightGear's frames bunched up.
            for line in data.splitlines():
                if not line.strip():
                    continue
                got = parse_pose(line)
                if got.pose is None:
                    self.stats.error(got.error)
                    continue
                self.stats.message()
                self.last_pose = got.pose
                self.stats.detail["last_pose"] = {
                    "lat_deg": got.pose.lat_deg,
                    "lon_deg": got.pose.lon_deg,
                    "alt_m": round(got.pose.alt_m, 2),
                    "view_heading_deg": round(got.pose.view_heading_deg, 3),
                    "internal": got.pose.internal,
                    "time_utc": got.pose.time_utc.isoformat(),
                }
                try:
                    self._on_pose(got.pose)
                except Exception:  # a bug downstream must not end the stream
                    log.exception("flightgear pose handler failed")


class FlightGearWeather:
    """Writes wxsky's applied weather into FlightGear through its props server."""

    def __init__(
        self,
        host: str,
        port: int,
        min_interval_s: float = 2.0,
        name: str = "flightgear",
        stats: InputStats | None = None,
        reply_timeout_s: float = REPLY_TIMEOUT_S,
    ) -> None:
        self.host, self.port = host, port
        self.min_interval_s = min_interval_s
        self.reply_timeout_s = reply_timeout_s
        self._probe_sent: float | None = None  # monotonic time of the unanswered probe
        self._last_probe = 0.0
        self.stats = stats or InputStats(f"{name}:weather", "flightgear", ok=False)
        self._latest: WeatherState | None = None
        self._aloft_c: tuple[tuple[float, float], ...] = ()
        self._offered = 0  # bumped by every offer
        self._sent: dict[str, str] = {}
        self._wake = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="wxsky-fg-weather", daemon=True)
        self._thread.start()

    def offer(self, state: WeatherState, aloft_c: tuple[tuple[float, float], ...] = ()) -> None:
        """The weather to write next (never blocks; only the latest offered is written), with
        model data's temperatures by height where it is read."""
        with self._wake:
            self._latest = state
            self._aloft_c = aloft_c
            self._offered += 1
            self._wake.notify()

    def close(self, wait_s: float = 1.0) -> None:
        with self._wake:
            if self._closed:
                return
            self._closed = True
            self._wake.notify_all()
        self._thread.join(wait_s)
        if self._thread.is_alive():
            log.warning("flightgear: the props server did not let go within %.1f s", wait_s)

    def __enter__(self) -> FlightGearWeather:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        wait_s = BACKOFF_S[0]
        while not self._is_closed():
            try:
                conn = socket.create_connection((self.host, self.port), CONNECT_TIMEOUT_S)
            except OSError as exc:
                self._gone(
                    f"cannot reach FlightGear's props server at {self.host}:{self.port}: "
                    f"{exc.strerror or exc}"
                )
                if self._sleep(wait_s):
                    return
                wait_s = min(BACKOFF_S[1], wait_s * 2.0)
                continue
            wait_s = BACKOFF_S[0]
            try:
                with conn:
                    conn.settimeout(SEND_TIMEOUT_S)
                    self._serve(conn)
            except _Unanswered as exc:
                self._gone(str(exc))
                if self._sleep(wait_s):
                    return
            except OSError as exc:
                self._gone(f"FlightGear's props server went away: {exc.strerror or exc}")
                if self._sleep(wait_s):
                    return

    def _serve(self, conn: socket.socket) -> None:
        """One connection: take FlightGear's weather over, then write what changes."""
        self._sent = {}  # a new connection: FlightGear may have restarted
        # `ok` turns true at the first answer to the probe sent here, not at the connect: a
        # server that accepts and reads nothing never answers.
        conn.sendall(b"data\r\n" + b"".join(_set(p, v) for p, v in TAKE_OVER) + PROBE)
        self._probe_sent = self._last_probe = time.monotonic()
        self.stats.detail["connected"] = f"{self.host}:{self.port}"
        written = -1  # the latest weather offered is written whole on a new connection
        while True:
            with self._wake:
                while (self._latest is None or self._offered == written) and not self._closed:
                    self._wake.wait(0.5)
                    self._check_alive(conn)  # a FlightGear that quit while nothing changed
                if self._closed:
                    return
                state, written, aloft_c = self._latest, self._offered, self._aloft_c
            assert state is not None
            self._check_alive(conn)
            props = weather_properties(state, aloft_c)
            changed = [(p, v) for p, v in props if self._sent.get(p) != v]
            if changed:
                conn.sendall(b"".join(_set(p, v) for p, v in changed))
                self._sent.update(changed)
                self.stats.message(len(changed))
                self.stats.detail["last_write"] = {
                    "properties": len(changed),
                    "time_utc": state.time_utc.isoformat(),
                }
            if self._sleep(self.min_interval_s):
                return

    def _check_alive(self, conn: socket.socket) -> None:
        """Raise (an OSError, ending the connection) if the props server closed it or left a
        probe unanswered for `reply_timeout_s`; send the next probe when one is due. Any
        answer is life: `ok` turns true."""
        now = time.monotonic()
        if _check_open(conn):
            self._probe_sent = None
            if not self.stats.ok:
                self.stats.ok = True
                log.info("flightgear: the props server at %s:%d answers", self.host, self.port)
        elif self._probe_sent is not None and now - self._probe_sent >= self.reply_timeout_s:
            raise _Unanswered(
                f"FlightGear's props server at {self.host}:{self.port} answered nothing for "
                f"{self.reply_timeout_s:g} s (it reads nothing, or is stalled); reconnecting"
            )
        if self._probe_sent is None and now - self._last_probe >= min(
            PROBE_INTERVAL_S, self.reply_timeout_s
        ):
            conn.sendall(PROBE)
            self._probe_sent = self._last_probe = now

    def _gone(self, why: str) -> None:
        if self.stats.ok or self.stats.last_error != why:
            log.warning("flightgear: %s", why)
        self.stats.ok = False
        self.stats.error(why)

    def _is_closed(self) -> bool:
        with self._wake:
            return self._closed

    def _sleep(self, seconds: float) -> bool:
        """Wait `seconds` or until closed; True when closed."""
        deadline = time.monotonic() + seconds
        with self._wake:
            while not self._closed:
                left = deadline - time.monotonic()
                if left <= 0.0:
                    return False
                self._wake.wait(left)
            return True


def _check_open(conn: socket.socket) -> bool:
    """Raise ConnectionResetError if the props server has closed the connection; True when
    it said something (the answer to a probe: what it says is not kept), else False."""
    readable, _, _ = select.select([conn], [], [], 0.0)
    if not readable:
        return False
    if not conn.recv(65536):
        raise ConnectionResetError("FlightGear closed the connection")
    return True


def _set(path: str, value: str) -> bytes:
    return f"set {path} {value}\r\n".encode("ascii")
