"""The control/state channel: socket addresses and the asyncio MessagePack-RPC server.

Addresses are `unix:PATH` or `tcp:HOST:PORT`. The channel has no authentication, so TCP is only
accepted on a loopback host; anything else must go through a unix socket (whose directory
permissions are the access control).

`ControlServer` answers requests through one handler coroutine and pushes notifications to the
clients that subscribed to them. It is built so a misbehaving client cannot hurt the daemon: a
client that stops reading loses its oldest queued notifications instead of growing memory or
blocking `broadcast`, and a client that sends bytes that are not MessagePack-RPC is answered and
disconnected without disturbing the others.

A handler may return `WithFds`: the response then carries open file descriptors (SCM_RIGHTS,
sent with the response's first byte) on a unix connection, and the handler's alternative
answer on a tcp one (docs/protocol.md §6: the zero-copy textures).
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import os
import socket
import stat
from array import array
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wxsky.errors import ProtocolError, RuntimeFailure, WxskyError
from wxsky.output.wire import (
    Message,
    MessageDecoder,
    Notification,
    Request,
    Response,
    WireError,
    encode,
)

logger = logging.getLogger(__name__)

Handler = Callable[[str, dict[str, Any]], Awaitable[Any]]
"""Answers one request: `await handler(method, params)` returns the result (plain data) or
raises WxskyError with a one-line message for the client."""

SUBSCRIBE = "subscribe"
UNSUBSCRIBE = "unsubscribe"
DEFAULT_MAX_QUEUED = 256
_READ_SIZE = 65536
_SUN_PATH_MAX = 107  # Linux sockaddr_un.sun_path is 108 bytes including the NUL
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
        raise RuntimeFailure(f"cannot create socket directory {directory}: {exc.strerror}") from exc
    info = os.lstat(directory)
    # In /tmp another user could have created the directory (or a symlink) first, to sit on
    # our socket; refuse rather than use it.
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid():
        raise RuntimeFailure(f"socket directory {directory} is not a directory owned by this user")
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
    return text or type(exc).__name__


class _Client:
    def __init__(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, peer: str
    ) -> None:
        self.reader = reader
        self.writer = writer
        self.peer = peer
        self.topics: set[str] = set()
        self.queue: deque[bytes] = deque()
        self.wakeup = asyncio.Event()
        self.dropped = 0
        sock = writer.get_extra_info("socket")
        # Only a unix socket can carry file descriptors (WithFds).
        self.unix = sock is not None and sock.family == socket.AF_UNIX


class ControlServer:
    """MessagePack-RPC server for one handler. Use from a single event loop."""

    def __init__(
        self, address: Address | str, handler: Handler, *, max_queued: int = DEFAULT_MAX_QUEUED
    ) -> None:
        self._address = parse_address(address) if isinstance(address, str) else address
        self._handler = handler
        self._max_queued = max(1, max_queued)
        self._server: asyncio.Server | None = None
        self._socket_id: tuple[int, int] | None = None
        self._clients: set[_Client] = set()
        self._tasks: set[asyncio.Task[None]] = set()
        self._dropped = 0
        self._closed = False

    @property
    def address(self) -> Address:
        """The address served; after `start`, a tcp port 0 is replaced by the bound port."""
        return self._address

    @property
    def client_count(self) -> int:
        return len(self._clients)

    @property
    def dropped_notifications(self) -> int:
        """Notifications discarded so far because a client was not reading them."""
        return self._dropped

    async def start(self) -> None:
        if self._server is not None or self._closed:
            raise WxskyError(f"control server on {self._address} was already started")
        address = self._address
        try:
            if isinstance(address, UnixAddress):
                await self._clear_stale_socket(address.path)
                self._server = await asyncio.start_unix_server(
                    self._serve_client, path=str(address.path), limit=_READ_SIZE
                )
                # The socket is unauthenticated: only this user may connect.
                os.chmod(address.path, 0o600)
                info = os.stat(address.path)
                self._socket_id = (info.st_dev, info.st_ino)
            else:
                self._server = await asyncio.start_server(
                    self._serve_client, address.host, address.port, limit=_READ_SIZE
                )
                if address.port == 0 and self._server.sockets:
                    port = int(self._server.sockets[0].getsockname()[1])
                    self._address = TcpAddress(address.host, port)
        except OSError as exc:
            raise RuntimeFailure(f"cannot listen on {address}: {exc.strerror or exc}") from exc
        logger.info("control server listening on %s", self._address)

    @staticmethod
    async def _clear_stale_socket(path: Path) -> None:
        try:
            info = os.lstat(path)
        except FileNotFoundError:
            return
        if not stat.S_ISSOCK(info.st_mode):
            raise RuntimeFailure(f"{path} exists and is not a socket; refusing to replace it")
        try:
            _, writer = await asyncio.wait_for(asyncio.open_unix_connection(str(path)), 1.0)
        except (ConnectionRefusedError, FileNotFoundError):
            logger.info("removing stale control socket %s (nothing is listening on it)", path)
            with contextlib.suppress(FileNotFoundError):
                os.unlink(path)
            return
        except (OSError, TimeoutError) as exc:
            raise RuntimeFailure(f"cannot tell whether {path} is in use: {_one_line(exc)}") from exc
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()
        raise RuntimeFailure(f"another wxsky daemon is listening on unix:{path}")

    async def close(self) -> None:
        """Stop listening, disconnect every client and remove the socket file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        if self._server is not None:
            self._server.close()
        tasks = list(self._tasks)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        if self._server is not None:
            await self._server.wait_closed()
        if isinstance(self._address, UnixAddress) and self._socket_id is not None:
            path = self._address.path
            with contextlib.suppress(FileNotFoundError):
                info = os.lstat(path)
                # Only our own socket: a successor daemon may already have replaced it.
                if (info.st_dev, info.st_ino) == self._socket_id:
                    os.unlink(path)
        logger.info("control server on %s closed", self._address)

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
                    logger.warning(
                        "control client %s is not reading; dropping its oldest notifications",
                        client.peer,
                    )
            client.queue.append(data)
            client.wakeup.set()
        return len(targets)

    async def _serve_client(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        task = asyncio.current_task()
        peer = _peer_name(writer)
        if self._closed or task is None:
            writer.close()
            return
        self._tasks.add(task)
        client = _Client(reader, writer, peer)
        self._clients.add(client)
        sender = asyncio.create_task(self._send_notifications(client))
        logger.debug("control client %s connected", peer)
        try:
            await self._read_requests(client)
        except ConnectionError as exc:
            logger.debug("control client %s: %s", peer, exc)
        except Exception:
            logger.exception("control client %s: unexpected error; disconnecting it", peer)
        finally:
            self._clients.discard(client)
            sender.cancel()
            await asyncio.gather(sender, return_exceptions=True)
            writer.close()
            with contextlib.suppress(OSError, asyncio.CancelledError):
                await writer.wait_closed()
            self._tasks.discard(task)
            if client.dropped:
                logger.info("control client %s: %d notifications dropped", peer, client.dropped)
            logger.debug("control client %s disconnected", peer)

    async def _read_requests(self, client: _Client) -> None:
        decoder = MessageDecoder()
        while True:
            data = await client.reader.read(_READ_SIZE)
            if not data:
                return
            while True:
                try:
                    messages, error = decoder.feed(data), None
                except WireError as exc:
                    messages, error = exc.decoded, exc
                for message in messages:
                    await self._dispatch(client, message)
                if error is None:
                    break
                if not (error.recoverable and error.msgid is not None):
                    # Not a request we can name: the peer is not speaking our protocol (or the
                    # stream is out of step), so answer once and hang up.
                    logger.warning("control client %s: %s; disconnecting it", client.peer, error)
                    client.writer.write(encode(Response(None, str(error), None)))
                    with contextlib.suppress(ConnectionError, TimeoutError):
                        await asyncio.wait_for(client.writer.drain(), 1.0)
                    return
                logger.info("control client %s: %s", client.peer, error)
                await self._send(client, encode(Response(error.msgid, str(error), None)))
                data = b""  # the rest of the buffered stream is still in step

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
            except Exception:
                logger.exception(
                    "control client %s: notification %r failed", client.peer, message.method
                )
        else:
            logger.info("control client %s sent an unexpected response; ignored", client.peer)

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
            logger.exception("control request %r failed", request.method)
            message = f"internal error: {type(exc).__name__}: {_one_line(exc)}"
            return encode(Response(request.msgid, message, None)), ()
        if isinstance(result, WithFds):
            fds, result = (result.fds, result.result) if client.unix else ((), result.without_fds)
        try:
            return encode(Response(request.msgid, None, result)), fds
        except ProtocolError as exc:
            logger.error("result of control request %r cannot be sent: %s", request.method, exc)
            return encode(Response(request.msgid, f"internal error: {_one_line(exc)}", None)), ()

    @staticmethod
    async def _send(client: _Client, data: bytes) -> None:
        # Awaiting drain here only holds up this client's own read loop, which is the
        # back-pressure we want: a client that does not read its responses stops being read.
        client.writer.write(data)
        await client.writer.drain()

    @staticmethod
    async def _send_with_fds(client: _Client, data: bytes, fds: tuple[int, ...]) -> None:
        """`data` with `fds` attached to its first byte. The asyncio transport cannot send
        ancillary data, so: wait until it has handed every earlier byte to the kernel (the
        stream stays in order; the notification sender runs on this loop too, and nothing
        awaits between the check and the send), sendmsg on a duplicate of the socket, and
        give the transport whatever the kernel did not take at once."""
        writer = client.writer
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
        try:
            while True:
                await client.wakeup.wait()
                client.wakeup.clear()
                while client.queue:
                    client.writer.write(client.queue.popleft())
                    await client.writer.drain()
        except ConnectionError:
            client.writer.close()  # the read loop sees EOF and cleans up


def _update_topics(client: _Client, method: str, params: dict[str, Any]) -> dict[str, Any]:
    topics = params.get("topics")
    if not isinstance(topics, list) or not all(isinstance(t, str) for t in topics):
        raise ProtocolError(f'{method}: params must be {{"topics": [str, ...]}}')
    if method == SUBSCRIBE:
        client.topics.update(topics)
    else:
        client.topics.difference_update(topics)
    return {"topics": sorted(client.topics)}


def _peer_name(writer: asyncio.StreamWriter) -> str:
    peer = writer.get_extra_info("peername")
    if isinstance(peer, tuple) and len(peer) >= 2:
        return f"{peer[0]}:{peer[1]}"
    sock = writer.get_extra_info("socket")
    return f"unix fd {sock.fileno()}" if sock is not None else "unix"
