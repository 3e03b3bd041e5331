"""The control/state channel: socket addresses and the asyncio MessagePack-RPC server.

Addresses are `unix:PATH` or `tcp:HOST:PORT`. The channel has no authentication, so TCP is only
accepted on a loopback host; anything else must go through a unix socket (whose directory
permissions are the access control).

`ControlServer` answers requests through one handler coroutine and pushes notifications to the
clients that subscribed to them. It is built so a misbehaving client cannot hurt the daemon: a
client that stops reading loses its oldest queued notifications instead of growing memory or
blocking `broadcast`, and a client that sends bytes that are not MessagePack-RPC is answered and
disconnected without disturbing the others. No client can lock the others out: when
`max_clients` are connected, a new one is served and the longest-idle client is closed to make
room (with a one-line reason), as sshd's MaxStartups and nginx's keepalive reuse do, so an
operator's `wxsky status` is answered whoever holds the connections; a client in the middle of
a request is never the one closed, and a listener (subscribed to a topic) only when every
client is one. Only when every client is in the middle of a request is the new one answered
"too many control clients" and closed. A client that neither sends nor subscribes for
`idle_timeout_s` is closed, no message over `wire.MAX_REQUEST_SIZE` is read, and every log line
a client can cause is rate-limited and clipped (`wxsky.logs`). The server accepts connections
itself, so running out of file descriptors is one log line when it starts and one when it ends.

Only the socket file this server bound is ever removed (its device and inode are kept): a
second daemon that failed to start, or a stale-socket check racing a new daemon, never removes
the socket of a daemon that is running.

A handler may return `WithFds`: the response then carries open file descriptors (SCM_RIGHTS,
sent with the response's first byte) on a unix connection, and the handler's alternative
answer on a tcp one (docs/protocol.md §6: the zero-copy textures).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import ipaddress
import logging
import os
import socket
import stat
import traceback
from array import array
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wxsky.errors import ProtocolError, RuntimeFailure, WxskyError
from wxsky.logs import RateLimitedLog, clip
from wxsky.output.wire import (
    MAX_REQUEST_SIZE,
    Message,
    MessageDecoder,
    Notification,
    Request,
    Response,
    WireError,
    encode,
)
from wxsky.schema import REQUIRED, Field, Invalid, Items, Table, Text

logger = logging.getLogger(__name__)

Handler = Callable[[str, dict[str, Any]], Awaitable[Any]]
"""Answers one request: `await handler(method, params)` returns the result (plain data) or
raises WxskyError with a one-line message for the client."""

SUBSCRIBE = "subscribe"
UNSUBSCRIBE = "unsubscribe"
DEFAULT_MAX_QUEUED = 256
# Connections served at once. Each holds a file descriptor and up to about 300 KB (a read
# buffer, a decoder and 256 queued notifications); 64 hosts is far more than a simulator runs,
# and far fewer descriptors than the daemon's 1024 (its feeds and links need some too).
DEFAULT_MAX_CLIENTS = 64
# A client that sends nothing and subscribes to nothing for this long is closed: a host either
# calls commands or listens to a topic; a connection doing neither only holds a slot.
DEFAULT_IDLE_TIMEOUT_S = 300.0  # a cockpit tool calling every few minutes keeps its link
ERROR_MAX_CHARS = 1000  # an error string sent to a client: one line, at most this long
MAX_TOPICS = 32  # topics a connection may subscribe to (the daemon sends 4)
# subscribe/unsubscribe params: topic names are free strings, but bounded.
TOPICS = Table(
    {
        "topics": Field(
            Items(
                Text(pattern=r"(?s).{1,64}", pattern_desc="1 to 64 characters"),
                max_len=MAX_TOPICS,
                what="a list of topic names",
            ),
            REQUIRED,
        )
    }
)
_READ_SIZE = 65536
_BACKLOG = 128
_ACCEPT_RETRY_S = 0.5  # after accept fails (out of descriptors): try again this often
_SUN_PATH_MAX = 107  # Linux sockaddr_un.sun_path is 108 bytes including the NUL
# What to do when the address is taken: how a daemon is given another.
OTHER_ADDRESS_HINT = "give this daemon another with --control ADDR or [output] control"
SCM_MAX_FD = 253  # Linux: the most descriptors one sendmsg may carry


@dataclass(frozen=True)
class WithFds:
    """A handler's result to send together with open file descriptors.

    On a unix connection the response goes out in one sendmsg whose ancillary data carries
    `fds` (SCM_RIGHTS) with the response's first byte; the receiver gets its own copies and
    the fds stay the handler's (the server closes none). On a connection that cannot carry
    descriptors (tcp) the server sends `without_fds` as the result instead."""

    result: Any
    fds: tuple[int, ...]
    without_fds: Any

    def __post_init__(self) -> None:
        if not 0 < len(self.fds) <= SCM_MAX_FD:
            raise ValueError(
                f"{len(self.fds)} file descriptors: one message carries 1..{SCM_MAX_FD}"
            )


@dataclass(frozen=True)
class UnixAddress:
    path: Path

    def __str__(self) -> str:
        return f"unix:{self.path}"


@dataclass(frozen=True)
class TcpAddress:
    host: str
    port: int

    def __post_init__(self) -> None:
        # Checked here rather than only in parse_address so no code path can open the
        # unauthenticated channel to the network.
        if not _is_loopback(self.host):
            raise WxskyError(
                f"tcp host {self.host!r} is not a loopback address: the control channel has no "
                "authentication, so tcp is only allowed on 127.0.0.0/8, localhost or ::1 "
                "(use unix:PATH otherwise)"
            )
        if not 0 <= self.port <= 65535:
            raise WxskyError(f"tcp port {self.port} is outside 0..65535")

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"tcp:{host}:{self.port}"


Address = UnixAddress | TcpAddress


def _is_loopback(host: str) -> bool:
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def parse_address(text: str) -> Address:
    """Parse `unix:PATH` or `tcp:HOST:PORT` (HOST loopback only; IPv6 as `[::1]` or `::1`)."""
    scheme, sep, rest = text.partition(":")
    if scheme == "unix" and sep:
        if not rest:
            raise WxskyError(f"invalid address {text!r}: unix: needs a socket path")
        path = Path(rest).expanduser()
        if len(os.fsencode(path)) > _SUN_PATH_MAX:
            raise WxskyError(
                f"invalid address {text!r}: unix socket paths are limited to {_SUN_PATH_MAX} bytes"
            )
        return UnixAddress(path)
    if scheme == "tcp" and sep:
        host, sep, port_text = rest.rpartition(":")
        if not sep or not host or not port_text.isdigit():
            raise WxskyError(f"invalid address {text!r}: expected tcp:HOST:PORT")
        if host.startswith("[") and host.endswith("]"):
            host = host[1:-1]
        return TcpAddress(host, int(port_text))
    raise WxskyError(f"invalid address {text!r}: expected unix:PATH or tcp:HOST:PORT")


def _private_dir(directory: Path) -> Path:
    try:
        directory.mkdir(mode=0o700)
    except FileExistsError:
        pass
    except OSError as exc:
        raise RuntimeFailure(
            f"cannot create socket directory {directory}: {exc.strerror}; name a socket "
            "elsewhere with --control unix:PATH (or set XDG_RUNTIME_DIR)"
        ) from exc
    info = os.lstat(directory)
    # In /tmp another user could have created the directory (or a symlink) first, to sit on
    # our socket; refuse rather than use it.
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid():
        raise RuntimeFailure(
            f"socket directory {directory} is not a directory owned by this user; name a "
            "socket elsewhere with --control unix:PATH (or set XDG_RUNTIME_DIR)"
        )
    if stat.S_IMODE(info.st_mode) != 0o700:
        os.chmod(directory, 0o700)
    return directory


def default_address() -> UnixAddress:
    """`$XDG_RUNTIME_DIR/wxsky/wxsky.sock`, else `/tmp/wxsky-<uid>/wxsky.sock`; the directory
    is created with mode 0700."""
    runtime = os.environ.get("XDG_RUNTIME_DIR", "")
    if runtime and os.path.isabs(runtime) and os.path.isdir(runtime):
        directory = Path(runtime) / "wxsky"
    else:
        directory = Path("/tmp") / f"wxsky-{os.getuid()}"
    return UnixAddress(_private_dir(directory) / "wxsky.sock")


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return clip(text, ERROR_MAX_CHARS) if text else type(exc).__name__


class _Client:
    """One connection, from the moment it is accepted: its streams are made by its task."""

    def __init__(self, conn: socket.socket, now_s: float) -> None:
        self.conn = conn
        self.peer = _peer_name(conn)
        self.reader: asyncio.StreamReader | None = None
        self.writer: asyncio.StreamWriter | None = None
        self.task: asyncio.Task[None] | None = None
        self.topics: set[str] = set()
        self.queue: deque[bytes] = deque()
        self.wakeup = asyncio.Event()
        self.dropped = 0
        # Only a unix socket can carry file descriptors (WithFds).
        self.unix = conn.family == socket.AF_UNIX
        self.last_active_s = now_s  # when it last sent something or was last answered
        self.busy = 0  # its requests being answered now: it is not idle meanwhile
        self.started = False  # its task has begun making its streams
        self.evicted = False

    @property
    def streams(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        assert self.reader is not None and self.writer is not None, "not started"
        return self.reader, self.writer


class ControlServer:
    """MessagePack-RPC server for one handler. Use from a single event loop.

    `max_clients` connections are served at once (one more closes the longest-idle: see the
    module docstring); `idle_timeout_s` closes a client that sends nothing and subscribes to
    nothing for that long (0: never); per-client log lines are rate-limited to one of a kind
    per `log_interval_s`."""

    def __init__(
        self,
        address: Address | str,
        handler: Handler,
        *,
        max_queued: int = DEFAULT_MAX_QUEUED,
        max_clients: int = DEFAULT_MAX_CLIENTS,
        idle_timeout_s: float = DEFAULT_IDLE_TIMEOUT_S,
        log_interval_s: float = 60.0,
    ) -> None:
        self._address = parse_address(address) if isinstance(address, str) else address
        self._handler = handler
        self._max_queued = max(1, max_queued)
        self._max_clients = max(1, max_clients)
        self._idle_timeout_s = max(0.0, idle_timeout_s)
        self._log = RateLimitedLog(logger, log_interval_s)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._listeners: list[socket.socket] = []
        self._retry: asyncio.TimerHandle | None = None
        self._accept_failing = 0  # failed accepts since accepting last worked
        self._socket_id: tuple[int, int] | None = None
        # Connections being served and not being closed, by when they were accepted.
        self._clients: dict[_Client, None] = {}
        self._tasks: set[asyncio.Task[None]] = set()
        self._dropped = 0
        self._evicted = 0
        self._closed = False

    @property
    def address(self) -> Address:
        """The address served; after `start`, a tcp port 0 is replaced by the bound port."""
        return self._address

    @property
    def client_count(self) -> int:
        """Connections held, closing ones included (a client that hung up or was closed to
        make room holds its descriptor until its connection is closed here)."""
        return len(self._tasks)

    @property
    def evicted_clients(self) -> int:
        """Clients closed so far to make room for new ones."""
        return self._evicted

    @property
    def dropped_notifications(self) -> int:
        """Notifications discarded so far because a client was not reading them."""
        return self._dropped

    async def start(self) -> None:
        if self._listeners or self._closed:
            raise WxskyError(f"control server on {self._address} was already started")
        self._loop = asyncio.get_running_loop()
        address = self._address
        try:
            if isinstance(address, UnixAddress):
                await self._clear_stale_socket(address.path)
                listener = self._bind_unix(address.path)
            else:
                listener = _bind_tcp(address)
                if address.port == 0:
                    self._address = TcpAddress(address.host, int(listener.getsockname()[1]))
        except OSError as exc:
            why = exc.strerror or str(exc)
            if exc.errno == errno.EADDRINUSE:
                why += " (another program listens there)"
            raise RuntimeFailure(
                f"cannot listen on {address}: {why}; {OTHER_ADDRESS_HINT}"
            ) from exc
        listener.setblocking(False)
        self._listeners.append(listener)
        self._loop.add_reader(listener.fileno(), self._accept, listener)
        logger.info("control server listening on %s", self._address)

    def _bind_unix(self, path: Path) -> socket.socket:
        """A listening socket bound at `path`, which must not exist (asyncio's own unix server
        would remove whatever socket file is there first: perhaps a daemon's that has just
        started). Keeps the file's identity, so only this file is ever removed."""
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            try:
                sock.bind(str(path))
            except OSError as exc:
                if exc.errno == errno.EADDRINUSE:
                    raise RuntimeFailure(
                        f"another wxsky daemon is starting on unix:{path} (the socket file "
                        f"appeared while this one was checking it): stop it, or "
                        f"{OTHER_ADDRESS_HINT}"
                    ) from exc
                raise
            info = os.stat(path)
            self._socket_id = (info.st_dev, info.st_ino)
            # The socket is unauthenticated: only this user may connect.
            os.chmod(path, 0o600)
            sock.listen(_BACKLOG)
        except BaseException:
            sock.close()
            self.remove_socket_file()
            raise
        return sock

    @staticmethod
    async def _clear_stale_socket(path: Path) -> None:
        try:
            info = os.lstat(path)
        except FileNotFoundError:
            return
        if not stat.S_ISSOCK(info.st_mode):
            raise RuntimeFailure(
                f"{path} exists and is not a socket; refusing to replace it: remove it, or "
                f"{OTHER_ADDRESS_HINT}"
            )
        try:
            _, writer = await asyncio.wait_for(asyncio.open_unix_connection(str(path)), 1.0)
        except (ConnectionRefusedError, FileNotFoundError):
            with contextlib.suppress(FileNotFoundError):
                now = os.lstat(path)
                # Only the file found dead: a daemon starting meanwhile may have replaced it.
                if (now.st_dev, now.st_ino) == (info.st_dev, info.st_ino):
                    logger.info(
                        "removing stale control socket %s (nothing is listening on it)", path
                    )
                    os.unlink(path)
            return
        except (OSError, TimeoutError) as exc:
            raise RuntimeFailure(
                f"cannot tell whether {path} is in use: {_one_line(exc)}; if no daemon uses "
                f"it, remove it, or {OTHER_ADDRESS_HINT}"
            ) from exc
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()
        raise RuntimeFailure(
            f"another wxsky daemon is listening on unix:{path}: stop it (`wxsky status "
            f"--control unix:{path}` shows it), or {OTHER_ADDRESS_HINT}"
        )

    def remove_socket_file(self) -> bool:
        """Remove the socket file this server bound, if its path still names that file (a
        successor daemon may have replaced it); True if removed. Safe to call at any time,
        also from a forced exit; it never touches a file this server did not create."""
        if not isinstance(self._address, UnixAddress) or self._socket_id is None:
            return False
        path = self._address.path
        try:
            info = os.lstat(path)
            if (info.st_dev, info.st_ino) != self._socket_id:
                return False
            os.unlink(path)
        except OSError:
            return False
        self._socket_id = None
        return True

    async def close(self) -> None:
        """Stop listening, disconnect every client and remove the socket file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._stop_listening()
        # Now, not after the clients: a caller that stops waiting for them (the daemon's
        # shutdown budget) must not leave the file behind.
        self.remove_socket_file()
        for client in self._clients:
            if not client.started:  # its task is cancelled before it could close the socket
                client.conn.close()
        tasks = list(self._tasks)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        logger.info("control server on %s closed", self._address)

    def _stop_listening(self) -> None:
        if self._retry is not None:
            self._retry.cancel()
            self._retry = None
        for listener in self._listeners:
            if self._loop is not None and not self._loop.is_closed():
                self._loop.remove_reader(listener.fileno())
            listener.close()
        self._listeners = []

    # -- accepting --------------------------------------------------------------------

    def _accept(self, listener: socket.socket) -> None:
        """The listening socket is readable: take what is waiting (a bounded batch)."""
        for _ in range(_BACKLOG):
            try:
                conn, _ = listener.accept()
            except (BlockingIOError, InterruptedError):
                if self._accept_failing:
                    # Every client that waited is in: accepting works again (not before, so a
                    # daemon at its descriptor limit, taking one client now and then, does not
                    # log every one).
                    logger.warning(
                        "control: accepting again on %s (after %d failed attempts)",
                        self._address,
                        self._accept_failing,
                    )
                    self._accept_failing = 0
                return
            except ConnectionAbortedError:
                continue
            except OSError as exc:  # EMFILE, ENFILE, ENOBUFS, ENOMEM: out of something
                self._accept_failed(listener, exc)
                return
            self._admit(conn)

    def _accept_failed(self, listener: socket.socket, exc: OSError) -> None:
        # One line when accepting starts to fail, one when it works again: not one per try.
        if not self._accept_failing:
            logger.warning(
                "control: accept failing on %s: %s; new clients wait, retrying every %g s",
                self._address,
                exc.strerror or _one_line(exc),
                _ACCEPT_RETRY_S,
            )
        self._accept_failing += 1
        loop = self._loop
        assert loop is not None
        loop.remove_reader(listener.fileno())

        def resume() -> None:
            self._retry = None
            if not self._closed:
                loop.add_reader(listener.fileno(), self._accept, listener)

        self._retry = loop.call_later(_ACCEPT_RETRY_S, resume)

    def _admit(self, conn: socket.socket) -> None:
        conn.setblocking(False)
        if self._closed:
            self._refuse(conn, "the wxsky daemon is shutting down")
            return
        if len(self._clients) >= self._max_clients and not self._make_room():
            self._refuse(
                conn,
                f"too many control clients: all {self._max_clients} the daemon serves "
                "([output] max_clients) are in the middle of a request; closing this "
                "connection: try again shortly, or raise [output] max_clients",
            )
            return
        assert self._loop is not None
        client = _Client(conn, self._loop.time())
        self._clients[client] = None
        task = self._loop.create_task(self._serve(client))
        client.task = task
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _make_room(self) -> bool:
        """Close the longest-idle client for a new one; False if every client is busy. A
        listener is idle between its own requests too, but it is closed only when every
        other client is one: a host following the frames loses more than a forgotten
        connection does."""
        idle = [c for c in self._clients if not c.busy]
        if not idle:
            return False
        victim = min(idle, key=lambda c: (bool(c.topics), c.last_active_s))
        assert self._loop is not None
        idle_s = self._loop.time() - victim.last_active_s
        message = (
            f"control: closed to make room for a new client: this connection was the longest "
            f"idle ({idle_s:.0f} s) of the {self._max_clients} the daemon serves ([output] "
            "max_clients); connect again to go on"
        )
        self._log.warning(
            "evicted",
            f"control: {self._max_clients} clients connected ([output] max_clients): closing "
            f"the longest idle, {victim.peer} (idle {idle_s:.0f} s), to make room for a new one",
        )
        self._evict(victim, message)
        return True

    def _evict(self, client: _Client, message: str) -> None:
        """Say why in one line and close `client` now: its descriptor is free at once, not
        when its task gets round to it."""
        self._evicted += 1
        client.evicted = True
        self._clients.pop(client, None)
        data = encode(Response(None, message, None))
        if client.writer is None:  # its streams are not made yet: only the bare socket
            with contextlib.suppress(OSError):
                client.conn.send(data)
                client.conn.shutdown(socket.SHUT_WR)
            if client.task is not None:
                client.task.cancel()  # a task that has begun closes the socket itself
            if not client.started:
                client.conn.close()
            return
        transport = client.writer.transport
        # An idle client's socket has room: the line goes to the kernel now, before the
        # abort (which drops only what is still buffered here: a listener not reading).
        with contextlib.suppress(OSError, RuntimeError):
            transport.write(data)
        transport.abort()

    def _refuse(self, conn: socket.socket, message: str) -> None:
        """One line saying why, then the connection is closed."""
        with contextlib.suppress(OSError):
            # A fresh socket's buffer takes a line of a few hundred bytes.
            conn.send(encode(Response(None, message, None)))
            conn.shutdown(socket.SHUT_WR)
        conn.close()
        self._log.warning("too-many", f"control: {message}")

    async def _serve(self, client: _Client) -> None:
        client.started = True
        loop = asyncio.get_running_loop()
        conn = client.conn
        try:
            reader = asyncio.StreamReader(limit=_READ_SIZE, loop=loop)
            protocol = asyncio.StreamReaderProtocol(reader, loop=loop)
            transport, _ = await loop.connect_accepted_socket(lambda: protocol, conn)
        except (OSError, asyncio.CancelledError):
            self._clients.pop(client, None)
            conn.close()
            return
        client.reader = reader
        client.writer = asyncio.StreamWriter(transport, protocol, reader, loop)
        if client.evicted:  # closed to make room while its streams were being made
            transport.abort()
            return
        await self._serve_client(client)

    def broadcast(self, method: str, params: dict[str, Any] | None = None) -> int:
        """Queue a notification for every client subscribed to topic `method`; never blocks.

        Returns the number of clients it was queued for. A client whose queue is full loses its
        oldest queued notification. Call from the server's event loop.
        """
        targets = [client for client in self._clients if method in client.topics]
        if not targets:
            return 0
        data = encode(Notification(method, params if params is not None else {}))
        for client in targets:
            if len(client.queue) >= self._max_queued:
                client.queue.popleft()
                client.dropped += 1
                self._dropped += 1
                if client.dropped == 1:
                    self._log.warning(
                        "not-reading",
                        f"control client {client.peer} is not reading; dropping its oldest "
                        "notifications",
                    )
            client.queue.append(data)
            client.wakeup.set()
        return len(targets)

    # -- one client -------------------------------------------------------------------

    async def _serve_client(self, client: _Client) -> None:
        _, writer = client.streams
        peer = client.peer
        sender = asyncio.create_task(self._send_notifications(client))
        logger.debug("control client %s connected", peer)
        try:
            await self._read_requests(client)
        except asyncio.CancelledError:
            pass  # the server is closing: this client's end, not an error
        except ConnectionError as exc:
            logger.debug("control client %s: %s", peer, exc)
        except Exception as exc:
            self._log_bug(
                "client", f"control client {peer}: unexpected error; disconnecting it", exc
            )
        finally:
            self._clients.pop(client, None)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await asyncio.gather(sender, return_exceptions=True)
            writer.close()
            with contextlib.suppress(OSError, asyncio.CancelledError, TimeoutError):
                await asyncio.wait_for(writer.wait_closed(), 1.0)
            if client.dropped:
                self._log.log(
                    logging.INFO,
                    "dropped",
                    f"control client {peer}: {client.dropped} notifications dropped",
                )
            logger.debug("control client %s disconnected", peer)

    async def _read_requests(self, client: _Client) -> None:
        reader, _ = client.streams
        loop = asyncio.get_running_loop()
        decoder = MessageDecoder(MAX_REQUEST_SIZE)
        while True:
            # A client that subscribed may only listen; one that did not must send something.
            idle_s = self._idle_timeout_s if self._idle_timeout_s and not client.topics else None
            try:
                data = await asyncio.wait_for(reader.read(_READ_SIZE), idle_s)
            except TimeoutError:
                await self._hang_up(
                    client,
                    "idle",
                    f"control: nothing sent and nothing subscribed for {idle_s:g} s (the "
                    "daemon's [output] client_idle_timeout_s): closing this connection",
                )
                return
            if not data:
                return
            client.last_active_s = loop.time()
            while True:
                try:
                    messages, error = decoder.feed(data), None
                except WireError as exc:
                    messages, error = exc.decoded, exc
                # Busy until answered: a client waiting for its answer is never the one
                # closed to make room.
                client.busy += 1
                try:
                    for message in messages:
                        await self._dispatch(client, message)
                finally:
                    client.busy -= 1
                    client.last_active_s = loop.time()
                if error is None:
                    break
                if not (error.recoverable and error.msgid is not None):
                    # Not a request we can name: the peer is not speaking our protocol (or the
                    # stream is out of step, or the message is too large), so answer once and
                    # hang up.
                    await self._hang_up(client, "garbage", _one_line(error))
                    return
                self._log.log(logging.INFO, "wrong-shape", f"control client {client.peer}: {error}")
                await self._send(client, encode(Response(error.msgid, _one_line(error), None)))
                data = b""  # the rest of the buffered stream is still in step

    async def _hang_up(self, client: _Client, kind: str, message: str) -> None:
        """Say why in one line (a response with no msgid), then the caller closes."""
        self._log.warning(kind, f"control client {client.peer}: {message}; disconnecting it")
        _, writer = client.streams
        writer.write(encode(Response(None, message, None)))
        with contextlib.suppress(ConnectionError, TimeoutError):
            await asyncio.wait_for(writer.drain(), 1.0)

    async def _dispatch(self, client: _Client, message: Message) -> None:
        if isinstance(message, Request):
            data, fds = await self._answer(client, message)
            if fds:
                await self._send_with_fds(client, data, fds)
            else:
                await self._send(client, data)
        elif isinstance(message, Notification):
            try:
                await self._handler(message.method, message.params)
            except WxskyError as exc:
                # As for a request, the handler logs what it rejects; nobody is answered.
                self._log.log(
                    logging.DEBUG,
                    "notification-rejected",
                    f"control client {client.peer}: notification {clip(message.method, 64)!r} "
                    f"rejected: {exc}",
                )
            except Exception as exc:
                self._log_bug(
                    "notification",
                    f"control client {client.peer}: notification {clip(message.method, 64)!r} "
                    f"failed: {type(exc).__name__}: {exc}",
                    exc,
                )
        else:
            self._log.log(
                logging.INFO,
                "response",
                f"control client {client.peer} sent an unexpected response; ignored",
            )

    async def _answer(self, client: _Client, request: Request) -> tuple[bytes, tuple[int, ...]]:
        """The encoded response, and the file descriptors to send with it (none mostly)."""
        fds: tuple[int, ...] = ()
        try:
            if request.method in (SUBSCRIBE, UNSUBSCRIBE):
                result: Any = _update_topics(client, request.method, request.params)
            else:
                result = await self._handler(request.method, request.params)
        except WxskyError as exc:
            return encode(Response(request.msgid, _one_line(exc), None)), ()
        except Exception as exc:
            message = f"internal error: {type(exc).__name__}: {_one_line(exc)}"
            self._log_bug(
                "request", f"control request {clip(request.method, 64)!r} failed: {message}", exc
            )
            return encode(Response(request.msgid, clip(message, ERROR_MAX_CHARS), None)), ()
        if isinstance(result, WithFds):
            fds, result = (result.fds, result.result) if client.unix else ((), result.without_fds)
        try:
            return encode(Response(request.msgid, None, result)), fds
        except ProtocolError as exc:
            self._log.log(
                logging.ERROR,
                "unsendable",
                f"result of control request {clip(request.method, 64)!r} cannot be sent: {exc}",
            )
            return encode(Response(request.msgid, f"internal error: {_one_line(exc)}", None)), ()

    def _log_bug(self, kind: str, message: str, exc: BaseException) -> None:
        """A bug a client's message ran into: one line of a kind per interval, then its
        traceback (with the exception's text clipped as the line's is)."""
        if self._log.log(logging.ERROR, f"bug:{kind}", message):
            stack = "".join(traceback.format_tb(exc.__traceback__))
            last = f"{type(exc).__name__}: {clip(exc)}"
            logger.error("Traceback (most recent call last):\n%s%s", stack, last)

    @staticmethod
    async def _send(client: _Client, data: bytes) -> None:
        # Awaiting drain here only holds up this client's own read loop, which is the
        # back-pressure we want: a client that does not read its responses stops being read.
        _, writer = client.streams
        writer.write(data)
        await writer.drain()

    @staticmethod
    async def _send_with_fds(client: _Client, data: bytes, fds: tuple[int, ...]) -> None:
        """`data` with `fds` attached to its first byte. The asyncio transport cannot send
        ancillary data, so: wait until it has handed every earlier byte to the kernel (the
        stream stays in order; the notification sender runs on this loop too, and nothing
        awaits between the check and the send), sendmsg on a duplicate of the socket, and
        give the transport whatever the kernel did not take at once."""
        _, writer = client.streams
        transport = writer.transport
        pause = 0.001
        while True:
            if transport.is_closing():
                raise ConnectionError(f"control client {client.peer} went away")
            if transport.get_write_buffer_size() == 0:
                sock = socket.fromfd(
                    writer.get_extra_info("socket").fileno(), socket.AF_UNIX, socket.SOCK_STREAM
                )
                try:
                    sock.setblocking(False)
                    sent = sock.sendmsg(
                        [data], [(socket.SOL_SOCKET, socket.SCM_RIGHTS, array("i", fds))]
                    )
                    break
                except (BlockingIOError, InterruptedError):
                    pass  # the socket is full: the host is not reading yet
                finally:
                    sock.close()  # the duplicate only; the connection stays open
            # As drain() would: this client's reads wait, nobody else's.
            await asyncio.sleep(pause)
            pause = min(pause * 2, 0.05)
        if sent < len(data):
            writer.write(data[sent:])
        await writer.drain()

    @staticmethod
    async def _send_notifications(client: _Client) -> None:
        _, writer = client.streams
        try:
            while True:
                await client.wakeup.wait()
                client.wakeup.clear()
                while client.queue:
                    writer.write(client.queue.popleft())
                    await writer.drain()
        except ConnectionError:
            writer.close()  # the read loop sees EOF and cleans up


def _update_topics(client: _Client, method: str, params: dict[str, Any]) -> dict[str, Any]:
    topics = params.get("topics")
    if not isinstance(topics, list) or not all(isinstance(t, str) for t in topics):
        raise ProtocolError(f'{method}: params must be {{"topics": [str, ...]}}')
    try:
        checked = TOPICS.values(params)
    except Invalid as exc:
        raise ProtocolError(f"{method}: {exc}") from None
    if method == SUBSCRIBE:
        topics = client.topics | set(checked["topics"])
        if len(topics) > MAX_TOPICS:
            raise ProtocolError(
                f"{method}: a connection may subscribe to at most {MAX_TOPICS} topics, "
                f"this would make {len(topics)}"
            )
        client.topics = topics
    else:
        client.topics.difference_update(checked["topics"])
    return {"topics": sorted(client.topics)}


def _bind_tcp(address: TcpAddress) -> socket.socket:
    """A listening socket on the loopback address (`localhost` is 127.0.0.1: a host tries
    that first, and nothing asks a resolver)."""
    host = "127.0.0.1" if address.host.lower() == "localhost" else address.host
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    return socket.create_server((host, address.port), family=family, backlog=_BACKLOG)


def _peer_name(conn: socket.socket) -> str:
    try:
        peer = conn.getpeername()
    except OSError:
        peer = None
    if isinstance(peer, tuple) and len(peer) >= 2:
        return f"{peer[0]}:{peer[1]}"
    return f"unix fd {conn.fileno()}"
