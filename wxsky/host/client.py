"""Blocking MessagePack-RPC client for the daemon's control/state channel.

One request is in flight at a time; notifications that arrive while waiting for a response are
queued for `next_notification`, never lost. Not thread-safe: use one client per thread.
"""

from __future__ import annotations

import logging
import socket
import time
from collections import deque
from collections.abc import Iterable
from types import TracebackType
from typing import Any

from wxsky.errors import RuntimeFailure, WxskyError
from wxsky.output.transport import Address, UnixAddress, parse_address
from wxsky.output.wire import (
    MSGID_MAX,
    MessageDecoder,
    Notification,
    Request,
    Response,
    WireError,
    encode,
)

logger = logging.getLogger(__name__)

_READ_SIZE = 65536


class RemoteError(WxskyError):
    """The daemon answered a request with an error; the message is the daemon's, verbatim."""


class DaemonUnavailable(RuntimeFailure):
    """The daemon cannot be reached, stopped answering, hung up or sent what is not the
    protocol: nothing the request itself did wrong."""


class DaemonHungUp(DaemonUnavailable, RemoteError):
    """The daemon said why in one line and closed the connection (protocol §2.5: a response
    with no msgid): it is full, this connection was idle or made room for another, it is
    shutting down, or it could not read what was sent. The message is the daemon's, verbatim;
    a RemoteError too, as it was before it had a class of its own."""


# What to do when nothing answers at the address: a daemon is not running there.
NO_DAEMON_HINT = (
    "start one with `wxsky run`, or name the address it listens on with --control ADDR "
    "(its [output] control)"
)


class ControlClient:
    """Build with `ControlClient.connect`."""

    def __init__(self, sock: socket.socket, address: Address) -> None:
        self._sock = sock
        self._address = address
        self._decoder = MessageDecoder()
        self._notifications: deque[Notification] = deque()
        self._next_id = 0
        self._pending: int | None = None
        self._reply: Response | None = None
        self._closed = False

    @classmethod
    def connect(cls, address: Address | str, timeout_s: float = 2.0) -> ControlClient:
        addr = parse_address(address) if isinstance(address, str) else address
        try:
            if isinstance(addr, UnixAddress):
                sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                try:
                    sock.settimeout(timeout_s)
                    sock.connect(str(addr.path))
                except BaseException:
                    sock.close()
                    raise
            else:
                sock = socket.create_connection((addr.host, addr.port), timeout=timeout_s)
        except OSError as exc:
            why = exc.strerror or str(exc) or type(exc).__name__
            raise DaemonUnavailable(
                f"cannot connect to the wxsky daemon at {addr}: {why}; {_connect_hint(exc)}"
            ) from exc
        return cls(sock, addr)

    @property
    def address(self) -> Address:
        return self._address

    def call(
        self, method: str, params: dict[str, Any] | None = None, timeout_s: float = 5.0
    ) -> Any:
        """Send a request and wait for its result. Raises RemoteError with the daemon's message
        on an error response, DaemonUnavailable on a timeout or a lost connection."""
        self._check_open()
        msgid = self._next_id
        self._next_id = (self._next_id + 1) % (MSGID_MAX + 1)
        data = encode(Request(msgid, method, params if params is not None else {}))
        deadline = time.monotonic() + timeout_s
        self._send(data, timeout_s)
        self._pending, self._reply = msgid, None
        try:
            while self._reply is None:
                if not self._receive(deadline):
                    raise DaemonUnavailable(
                        f"no answer to {method!r} from the wxsky daemon at {self._address} "
                        f"within {timeout_s:g} s; it is running but busy or stuck: see its log, "
                        "and try again"
                    )
            reply = self._reply
        finally:
            self._pending = None
        if reply.error is not None:
            raise RemoteError(reply.error)
        return reply.result

    def subscribe(self, topics: Iterable[str], timeout_s: float = 5.0) -> list[str]:
        """Receive the notifications of `topics` from now on; returns all subscribed topics."""
        result = self.call("subscribe", {"topics": list(topics)}, timeout_s)
        if not isinstance(result, dict) or not isinstance(result.get("topics"), list):
            raise DaemonUnavailable(f"unexpected answer to subscribe: {result!r}")
        return [str(topic) for topic in result["topics"]]

    def next_notification(self, timeout_s: float | None = None) -> Notification | None:
        """The oldest unread notification, waiting up to `timeout_s` (None: forever) for one;
        None on timeout."""
        if self._notifications:
            return self._notifications.popleft()
        self._check_open()
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self._notifications:
            if not self._receive(deadline):
                return None
        return self._notifications.popleft()

    def _check_open(self) -> None:
        if self._closed:
            raise DaemonUnavailable(f"connection to the wxsky daemon at {self._address} is closed")

    def _send(self, data: bytes, timeout_s: float) -> None:
        try:
            self._sock.settimeout(timeout_s)
            self._sock.sendall(data)
        except OSError as exc:
            # The daemon may have said why it hung up before we wrote (protocol §2.5).
            said = self._hang_up_line()
            # A partial send leaves the stream out of step; the connection is unusable.
            self.close()
            if said is not None:
                raise DaemonHungUp(said) from exc
            why = exc.strerror or str(exc) or type(exc).__name__
            raise DaemonUnavailable(
                f"lost the wxsky daemon at {self._address}: {why}; it may have stopped: see its log"
            ) from exc

    def _hang_up_line(self) -> str | None:
        """The daemon's reason for closing the connection, if it is already here to read."""
        try:
            self._sock.settimeout(0.0)
            data = self._sock.recv(_READ_SIZE)
            messages = self._decoder.feed(data)
        except (OSError, WireError):
            return None
        for message in messages:
            if isinstance(message, Response) and message.msgid is None:
                return message.error or "protocol error"
        return None

    def _receive(self, deadline: float | None) -> bool:
        """Read once and sort what arrived; False if the deadline passed first."""
        if deadline is None:
            timeout = None
        else:
            timeout = deadline - time.monotonic()
            if timeout <= 0:
                return False
        try:
            self._sock.settimeout(timeout)
            data = self._sock.recv(_READ_SIZE)
        except TimeoutError:
            return False
        except OSError as exc:
            self.close()
            why = exc.strerror or str(exc) or type(exc).__name__
            raise DaemonUnavailable(
                f"lost the wxsky daemon at {self._address}: {why}; it may have stopped: see its log"
            ) from exc
        if not data:
            self.close()
            raise DaemonUnavailable(
                f"the wxsky daemon at {self._address} closed the connection; it may have "
                "stopped: see its log, or `wxsky status` to ask whether it still runs"
            )
        try:
            messages = self._decoder.feed(data)
        except WireError as exc:
            self.close()
            raise DaemonUnavailable(
                f"bad data from the wxsky daemon at {self._address}: {exc}"
            ) from exc
        for message in messages:
            if isinstance(message, Notification):
                self._notifications.append(message)
            elif isinstance(message, Response):
                if message.msgid is None:
                    # The daemon says why and hangs up (docs/protocol.md §2.5).
                    self.close()
                    raise DaemonHungUp(message.error or "protocol error")
                if message.msgid == self._pending:
                    self._reply = message
                else:
                    logger.debug("dropping late response %d", message.msgid)
            else:
                logger.debug("ignoring request %r from the daemon", message.method)
        return True

    def close(self) -> None:
        """Disconnect. Idempotent; queued notifications stay readable."""
        if self._closed:
            return
        self._closed = True
        self._sock.close()

    def __enter__(self) -> ControlClient:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _connect_hint(exc: OSError) -> str:
    """What to do when connecting failed, by why it failed."""
    if isinstance(exc, TimeoutError):
        return "a daemon is there but did not take the connection: see its log, and try again"
    if isinstance(exc, PermissionError):
        return (
            "the socket belongs to another user: run as that user, or start a daemon of your "
            "own with `wxsky run`"
        )
    return NO_DAEMON_HINT
