"""ControlServer + ControlClient over real unix and loopback tcp sockets.

The server runs on an event loop in a background thread, as in the daemon; the blocking client
runs in the test thread, as in a host.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import select
import socket
import stat
import time
from collections.abc import Awaitable, Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import pytest
from server_thread import ServerThread as LoopServer

from wxsky.errors import RuntimeFailure, WxskyError
from wxsky.host.client import ControlClient, DaemonHungUp, RemoteError
from wxsky.output.transport import (
    ControlServer,
    TcpAddress,
    UnixAddress,
    default_address,
    parse_address,
)
from wxsky.output.wire import MessageDecoder, Notification, Request, Response, encode

T = TypeVar("T")


async def handler(method: str, params: dict[str, Any]) -> Any:
    if method == "echo":
        return params
    if method == "fail":
        raise WxskyError("unknown weather preset 'foggy'")
    if method == "crash":
        raise RuntimeError("boom\nsecond line")
    if method == "bad_result":
        return {"s": {1, 2}}
    if method == "slow":
        await asyncio.sleep(params["s"])
        return "done"
    raise WxskyError(f"unknown method {method!r}")


class ServerThread(LoopServer):
    def __init__(
        self,
        address: str,
        handler: Callable[[str, dict[str, Any]], Awaitable[Any]] = handler,
        **kwargs: Any,
    ) -> None:
        super().__init__(address, handler, **kwargs)

    def wait_for_clients(self, count: int) -> None:
        deadline = time.monotonic() + 5
        while self.on_loop(lambda: self.server.client_count) != count:
            assert time.monotonic() < deadline, f"client_count never became {count}"
            time.sleep(0.01)


@pytest.fixture
def sock_path(tmp_path: Path) -> Path:
    return tmp_path / "wx.sock"


@pytest.fixture
def unix_server(sock_path: Path) -> Iterator[ServerThread]:
    server = ServerThread(f"unix:{sock_path}")
    yield server
    server.stop()


@pytest.fixture
def tcp_server() -> Iterator[ServerThread]:
    server = ServerThread("tcp:127.0.0.1:0")
    yield server
    server.stop()


def raw_exchange(address: UnixAddress, data: bytes) -> tuple[list[Any], bool]:
    """Send raw bytes; return the messages answered and whether the server hung up."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(5)
        sock.connect(str(address.path))
        sock.sendall(data)
        decoder = MessageDecoder()
        messages: list[Any] = []
        while True:
            try:
                chunk = sock.recv(65536)
            except TimeoutError:
                return messages, False
            if not chunk:
                return messages, True
            messages += decoder.feed(chunk)
            sock.settimeout(0.3)  # answered: now only wait to see whether it hangs up


def test_unix_round_trip(unix_server: ServerThread, sock_path: Path) -> None:
    assert unix_server.server.address == UnixAddress(sock_path)
    assert stat.S_IMODE(os.stat(sock_path).st_mode) == 0o600
    with ControlClient.connect(f"unix:{sock_path}") as client:
        params = {"a": 1, "b": [1.5, None, True], "c": b"\x00\x01", "d": {"e": "ü"}}
        assert client.call("echo", params) == params
        assert client.call("echo") == {}
        unix_server.wait_for_clients(1)
    unix_server.wait_for_clients(0)


def test_tcp_ephemeral_port_round_trip(tcp_server: ServerThread) -> None:
    address = tcp_server.server.address
    assert isinstance(address, TcpAddress)
    assert address.host == "127.0.0.1"
    assert address.port != 0
    with ControlClient.connect(str(address)) as client:
        assert client.call("echo", {"x": 1}) == {"x": 1}


def test_error_responses_keep_the_connection(
    unix_server: ServerThread, sock_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with ControlClient.connect(f"unix:{sock_path}") as client:
        with pytest.raises(RemoteError) as info:
            client.call("fail")
        assert str(info.value) == "unknown weather preset 'foggy'"
        with (
            caplog.at_level(logging.ERROR, logger="wxsky.output.transport"),
            pytest.raises(RemoteError) as info,
        ):
            client.call("crash")
        assert str(info.value) == "internal error: RuntimeError: boom second line"
        assert "Traceback" in caplog.text and "RuntimeError: boom" in caplog.text
        with pytest.raises(RemoteError, match=r"^internal error: cannot encode response"):
            client.call("bad_result")
        with pytest.raises(RemoteError, match="unknown method 'nope'"):
            client.call("nope")
        with pytest.raises(RemoteError, match=r'subscribe: params must be \{"topics"'):
            client.call("subscribe", {"topics": "frame"})
        assert client.call("echo", {"still": "open"}) == {"still": "open"}


def test_client_rejects_params_that_cannot_be_sent(unix_server: ServerThread) -> None:
    with ControlClient.connect(unix_server.server.address) as client:
        with pytest.raises(WxskyError, match="has type set"):
            client.call("echo", {"s": {1}})
        assert client.call("echo", {"ok": 1}) == {"ok": 1}


def test_wrong_shaped_request_is_answered_by_msgid(unix_server: ServerThread) -> None:
    address = unix_server.server.address
    assert isinstance(address, UnixAddress)
    # [0, 7, "echo", [1]]: a request with positional params, hand-encoded.
    messages, hung_up = raw_exchange(address, b"\x94\x00\x07\xa4echo\x91\x01")
    assert messages == [
        Response(
            7,
            "control message 1: expected [0, msgid, method, params], got list params "
            "(must be a map)",
            None,
        )
    ]
    assert not hung_up


@pytest.mark.parametrize(
    ("garbage", "expected"),
    [
        (b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", "expected an array [type, ...], got int"),
        (b"\xc1\xc1\xc1", "not valid msgpack"),
    ],
)
def test_garbage_is_answered_and_disconnected_while_others_carry_on(
    unix_server: ServerThread, garbage: bytes, expected: str
) -> None:
    address = unix_server.server.address
    assert isinstance(address, UnixAddress)
    with ControlClient.connect(address) as other:
        assert other.call("echo", {"n": 1}) == {"n": 1}
        messages, hung_up = raw_exchange(address, garbage)
        assert hung_up
        assert len(messages) == 1
        (response,) = messages
        assert isinstance(response, Response)
        assert response.msgid is None
        assert response.error is not None and expected in response.error
        assert other.call("echo", {"n": 2}) == {"n": 2}
        unix_server.wait_for_clients(1)


def test_subscribe_and_broadcast(unix_server: ServerThread) -> None:
    address = unix_server.server.address
    with ControlClient.connect(address) as frames, ControlClient.connect(address) as weather:
        assert frames.subscribe(["frame"]) == ["frame"]
        assert weather.subscribe(["weather", "scene"]) == ["scene", "weather"]
        assert unix_server.on_loop(lambda: unix_server.server.broadcast("frame", {"n": 1})) == 1
        assert unix_server.on_loop(lambda: unix_server.server.broadcast("weather", {"w": 2})) == 1
        assert unix_server.on_loop(lambda: unix_server.server.broadcast("nobody")) == 0

        assert frames.next_notification(2) == Notification("frame", {"n": 1})
        assert weather.next_notification(2) == Notification("weather", {"w": 2})
        assert frames.next_notification(0.05) is None
        assert weather.next_notification(0.05) is None

        # Notifications that arrive while a call waits for its answer are queued, not lost.
        def burst() -> None:
            for n in range(3):
                unix_server.server.broadcast("frame", {"n": n})

        unix_server.on_loop(burst)
        assert frames.call("slow", {"s": 0.05}) == "done"
        got = [frames.next_notification(2) for _ in range(3)]
        assert got == [Notification("frame", {"n": n}) for n in range(3)]

        assert frames.call("unsubscribe", {"topics": ["frame"]}) == {"topics": []}
        assert unix_server.on_loop(lambda: unix_server.server.broadcast("frame", {})) == 0


def test_slow_client_loses_its_oldest_notifications(sock_path: Path) -> None:
    server = ServerThread(f"unix:{sock_path}", max_queued=8)
    total = 2000
    pad = b"x" * 4096  # 8 MB in all: far beyond the socket and transport buffers
    try:
        with (
            ControlClient.connect(server.server.address) as slow,
            ControlClient.connect(server.server.address) as fast,
        ):
            slow.subscribe(["frame"])

            async def flood() -> None:
                for n in range(total):
                    server.server.broadcast("frame", {"n": n, "pad": pad})
                    await asyncio.sleep(0)  # let the sender tasks run between broadcasts

            server.run(flood())
            # The daemon is not blocked by the client that does not read.
            assert fast.call("echo", {"alive": True}) == {"alive": True}
            dropped = server.on_loop(lambda: server.server.dropped_notifications)
            assert dropped > 0

            received: list[int] = []
            while not received or received[-1] != total - 1:
                note = slow.next_notification(5)
                assert note is not None, "the newest notification never arrived"
                received.append(note.params["n"])
            assert received == sorted(received)
            assert len(received) + dropped == total
            assert received[0] == 0  # the oldest ones dropped are those still queued, not sent
            assert slow.next_notification(0.05) is None
    finally:
        server.stop()


def test_call_timeout_then_late_answer_is_discarded(unix_server: ServerThread) -> None:
    with ControlClient.connect(unix_server.server.address) as client:
        with pytest.raises(WxskyError, match="no answer to 'slow'"):
            client.call("slow", {"s": 0.3}, timeout_s=0.05)
        assert client.call("echo", {"after": 1}) == {"after": 1}


def test_server_close_disconnects_clients_and_removes_socket(sock_path: Path) -> None:
    server = ServerThread(f"unix:{sock_path}")
    try:
        client = ControlClient.connect(f"unix:{sock_path}")
        assert client.call("echo", {}) == {}
        server.run(server.server.close())
        server.run(server.server.close())  # idempotent
        assert not sock_path.exists()
        with pytest.raises(WxskyError, match=r"closed the connection|lost the wxsky daemon"):
            client.call("echo", {}, timeout_s=2)
        with pytest.raises(WxskyError, match="is closed"):
            client.call("echo")
        client.close()
        client.close()
        with pytest.raises(WxskyError, match="cannot connect to the wxsky daemon"):
            ControlClient.connect(f"unix:{sock_path}", timeout_s=1)
    finally:
        server.stop()


def test_only_the_socket_file_this_server_bound_is_removed(sock_path: Path) -> None:
    server = ServerThread(f"unix:{sock_path}")
    successor = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        # Another daemon took the path over (this one's file was removed under it).
        os.unlink(sock_path)
        successor.bind(str(sock_path))
        theirs = os.lstat(sock_path)
        assert server.server.remove_socket_file() is False  # as on a forced exit
        server.stop()
        now = os.lstat(sock_path)
        assert (now.st_dev, now.st_ino) == (theirs.st_dev, theirs.st_ino)
    finally:
        server.stop()
        successor.close()


def test_a_client_that_sends_nothing_and_subscribes_to_nothing_is_closed(sock_path: Path) -> None:
    server = ServerThread(f"unix:{sock_path}", idle_timeout_s=0.3)
    try:
        with ControlClient.connect(f"unix:{sock_path}") as listener:
            listener.subscribe(["frame"])
            messages, hung_up = raw_exchange(UnixAddress(sock_path), b"")
            assert hung_up
            assert messages == [
                Response(
                    None,
                    "control: nothing sent and nothing subscribed for 0.3 s (the daemon's "
                    "[output] client_idle_timeout_s): closing this connection",
                    None,
                )
            ]
            # The subscriber has sent nothing for longer than that, and is still served.
            assert server.broadcast("frame", {"n": 1}) == 1
            note = listener.next_notification(timeout_s=5)
            assert note is not None and note.params == {"n": 1}
            assert listener.call("echo", {"still": "here"}) == {"still": "here"}
    finally:
        server.stop()


def test_subscribe_params_are_checked_and_bounded(unix_server: ServerThread) -> None:
    with ControlClient.connect(unix_server.server.address) as client:
        with pytest.raises(RemoteError, match=r"^subscribe: x: unknown key"):
            client.call("subscribe", {"topics": ["frame"], "x": 1})
        with pytest.raises(RemoteError, match=r"^subscribe: topics: must have at most 32 items"):
            client.subscribe([f"t{i}" for i in range(33)])
        with pytest.raises(RemoteError, match=r"^subscribe: topics\[0\]: must be 1 to 64 char"):
            client.subscribe(["x" * 65])
        assert len(client.subscribe([f"t{i}" for i in range(32)])) == 32
        with pytest.raises(RemoteError, match="at most 32 topics, this would make 33"):
            client.subscribe(["one-more"])
        assert len(client.call("unsubscribe", {"topics": ["t0"]})["topics"]) == 31


def test_a_flood_of_failing_notifications_logs_a_line_and_one_traceback(
    unix_server: ServerThread, caplog: pytest.LogCaptureFixture
) -> None:
    flood = [encode(Notification("crash", {}))] * 1000 + [encode(Notification("fail", {}))] * 1000
    with caplog.at_level(logging.DEBUG):
        # The echo is answered after every notification before it was handled.
        messages, _ = raw_exchange(
            unix_server.server.address, b"".join([*flood, encode(Request(1, "echo", {}))])
        )
    assert messages == [Response(1, None, {})]
    lines = [r.getMessage() for r in caplog.records if "notification" in r.getMessage()]
    assert len(lines) == 2, lines  # one crash, one rejection: not 2000
    assert caplog.text.count("Traceback") == 1


def test_stale_socket_file_is_replaced(sock_path: Path) -> None:
    dead = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    dead.bind(str(sock_path))
    dead.close()  # the file stays, nobody listens: what a crashed daemon leaves
    assert stat.S_ISSOCK(os.lstat(sock_path).st_mode)
    server = ServerThread(f"unix:{sock_path}")
    try:
        with ControlClient.connect(f"unix:{sock_path}") as client:
            assert client.call("echo", {"fresh": 1}) == {"fresh": 1}
    finally:
        server.stop()
    assert not sock_path.exists()


def test_live_socket_is_refused(unix_server: ServerThread, sock_path: Path) -> None:
    with pytest.raises(WxskyError, match=f"another wxsky daemon is listening on unix:{sock_path}"):
        ServerThread(f"unix:{sock_path}")
    with ControlClient.connect(f"unix:{sock_path}") as client:
        assert client.call("echo", {"first": "unharmed"}) == {"first": "unharmed"}


def test_non_socket_file_is_not_replaced(sock_path: Path) -> None:
    sock_path.write_text("precious")
    with pytest.raises(WxskyError, match="exists and is not a socket"):
        ServerThread(f"unix:{sock_path}")
    assert sock_path.read_text() == "precious"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("unix:/run/wx.sock", UnixAddress(Path("/run/wx.sock"))),
        ("tcp:127.0.0.1:5555", TcpAddress("127.0.0.1", 5555)),
        ("tcp:127.1.2.3:0", TcpAddress("127.1.2.3", 0)),
        ("tcp:localhost:80", TcpAddress("localhost", 80)),
        ("tcp:[::1]:9000", TcpAddress("::1", 9000)),
        ("tcp:::1:9000", TcpAddress("::1", 9000)),
    ],
)
def test_parse_address(text: str, expected: UnixAddress | TcpAddress) -> None:
    assert parse_address(text) == expected
    assert parse_address(str(expected)) == expected


@pytest.mark.parametrize("host", ["0.0.0.0", "192.168.1.20", "example.com", "[::]", "10.0.0.1"])
def test_non_loopback_tcp_is_refused(host: str) -> None:
    with pytest.raises(WxskyError, match="is not a loopback address"):
        parse_address(f"tcp:{host}:5555")
    with pytest.raises(WxskyError, match="is not a loopback address"):
        ControlServer(f"tcp:{host}:0", handler)


@pytest.mark.parametrize(
    "text", ["wx.sock", "unix:", "tcp:127.0.0.1", "tcp:127.0.0.1:port", "tcp::80", "udp:x:1"]
)
def test_malformed_addresses(text: str) -> None:
    with pytest.raises(WxskyError, match="invalid address"):
        parse_address(text)


def test_out_of_range_addresses() -> None:
    with pytest.raises(WxskyError, match="tcp port 70000"):
        parse_address("tcp:127.0.0.1:70000")
    with pytest.raises(WxskyError, match="limited to 107 bytes"):
        parse_address("unix:/" + "x" * 200)


def test_default_address_uses_xdg_runtime_dir(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    address = default_address()
    assert address == UnixAddress(tmp_path / "wxsky" / "wxsky.sock")
    assert stat.S_IMODE(os.stat(tmp_path / "wxsky").st_mode) == 0o700


def test_default_address_falls_back_to_tmp(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("XDG_RUNTIME_DIR", raising=False)
    directory = Path(f"/tmp/wxsky-{os.getuid()}")
    existed = directory.exists()
    try:
        assert default_address() == UnixAddress(directory / "wxsky.sock")
        info = os.lstat(directory)
        assert stat.S_ISDIR(info.st_mode) and stat.S_IMODE(info.st_mode) == 0o700
    finally:
        if not existed:
            with contextlib.suppress(OSError):
                directory.rmdir()


# -- a full server makes room (issue 39) ----------------------------------------------------


def connect_unix(sock: socket.socket, path: Path, timeout_s: float = 120.0) -> None:
    """Connect as a blocking client would, but never hang: a unix socket whose listen
    backlog is full refuses a non-blocking connect (EAGAIN) until the server accepts."""
    deadline = time.monotonic() + timeout_s
    sock.setblocking(False)
    while True:
        try:
            sock.connect(str(path))
            break
        except BlockingIOError:
            assert time.monotonic() < deadline, f"{path}: the server never accepted"
            select.select([], [], [], 0.005)
    sock.settimeout(timeout_s)


def _connect_raw(address: UnixAddress) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    connect_unix(sock, address.path)
    return sock


def _hung_up_with(sock: socket.socket) -> list[Any]:
    """Every message the server sends on `sock` until it closes it (waiting as long as it
    takes: only a hang fails)."""
    decoder = MessageDecoder()
    messages: list[Any] = []
    while True:
        chunk = sock.recv(65536)
        if not chunk:
            return messages
        messages += decoder.feed(chunk)


def _answers(sock: socket.socket, msgid: int) -> Any:
    """Send an echo request on a raw connection; its answer (the connection is open)."""
    sock.sendall(encode(Request(msgid, "echo", {"n": msgid})))
    decoder = MessageDecoder()
    while True:
        chunk = sock.recv(65536)
        assert chunk, f"connection {msgid} was closed"
        for message in decoder.feed(chunk):
            assert isinstance(message, Response) and message.msgid == msgid, message
            return message.result


def _made_room(message: Any, max_clients: int) -> bool:
    return (
        isinstance(message, Response)
        and message.msgid is None
        and message.error is not None
        and message.error.startswith("control: closed to make room for a new client")
        and f"of the {max_clients} the daemon serves ([output] max_clients)" in message.error
    )


def test_a_full_server_closes_the_longest_idle_clients_to_answer_a_new_one(
    sock_path: Path,
) -> None:
    max_clients = 8
    server = ServerThread(f"unix:{sock_path}", max_clients=max_clients)
    address = UnixAddress(sock_path)
    idle: list[socket.socket] = []
    try:
        # max_clients + 100 connections that never send anything, opened one after another.
        idle = [_connect_raw(address) for _ in range(max_clients + 100)]
        # The first 100 were closed, each with one line saying why: the longest idle went.
        for n, sock in enumerate(idle[:100]):
            messages = _hung_up_with(sock)
            assert len(messages) == 1 and _made_room(messages[0], max_clients), (n, messages)
        # A new client is answered at once...
        with ControlClient.connect(address) as operator:
            assert operator.call("echo", {"status": "?"}) == {"status": "?"}
            # ... and the one that made room for it was the longest idle of those left.
            assert _made_room(_hung_up_with(idle[100])[0], max_clients)
            for n, sock in enumerate(idle[101:], 101):
                assert _answers(sock, n) == {"n": n}
            assert server.on_loop(lambda: server.server.evicted_clients) == 101
            assert operator.call("echo", {"still": "served"}) == {"still": "served"}
    finally:
        for sock in idle:
            sock.close()
        server.stop()


def test_listeners_are_closed_to_make_room_only_when_every_client_is_one(sock_path: Path) -> None:
    server = ServerThread(f"unix:{sock_path}", max_clients=3)
    address = UnixAddress(sock_path)
    raw: list[socket.socket] = []
    try:
        with ControlClient.connect(address) as listener:
            listener.subscribe(["frame"])  # the oldest connection, and a listener
            raw = [_connect_raw(address) for _ in range(2)]  # b, c: idle
            server.wait_for_clients(3)
            raw.append(_connect_raw(address))  # d: b goes, not the older listener
            assert _made_room(_hung_up_with(raw[0])[0], 3)
            raw.append(_connect_raw(address))  # e: c goes
            assert _made_room(_hung_up_with(raw[1])[0], 3)
            assert server.broadcast("frame", {"n": 1}) == 1
            note = listener.next_notification(timeout_s=10)
            assert note is not None and note.params == {"n": 1}
            # Every client a listener now: the longest idle of them goes for a new one.
            for n, sock in enumerate(raw[2:], 2):
                sock.sendall(encode(Request(n, SUBSCRIBE_METHOD, {"topics": ["frame"]})))
                assert _hung_up_with_answer(sock, n) == {"topics": ["frame"]}
            with ControlClient.connect(address) as newcomer:
                assert newcomer.call("echo", {}) == {}
                with pytest.raises(DaemonHungUp, match="closed to make room"):
                    listener.call("echo", {})
    finally:
        for sock in raw:
            sock.close()
        server.stop()


SUBSCRIBE_METHOD = "subscribe"


def _hung_up_with_answer(sock: socket.socket, msgid: int) -> Any:
    decoder = MessageDecoder()
    while True:
        chunk = sock.recv(65536)
        assert chunk, f"connection {msgid} was closed"
        for message in decoder.feed(chunk):
            if isinstance(message, Response) and message.msgid == msgid:
                return message.result


class Gate:
    """A handler whose "wait" requests are answered only when the test opens the gate: they
    stay in the middle of a request as long as the test wants, with no clock involved."""

    def __init__(self) -> None:
        self.waiting = 0
        self.gate: asyncio.Event | None = None

    async def __call__(self, method: str, params: dict[str, Any]) -> Any:
        if self.gate is None:
            self.gate = asyncio.Event()
        if method == "wait":
            self.waiting += 1
            await self.gate.wait()
            return "opened"
        return await handler(method, params)


def test_when_every_client_is_in_the_middle_of_a_request_a_new_one_is_refused(
    sock_path: Path,
) -> None:
    gate = Gate()
    server = ServerThread(f"unix:{sock_path}", gate, max_clients=2)
    address = UnixAddress(sock_path)
    busy: list[socket.socket] = []
    try:
        busy = [_connect_raw(address) for _ in range(2)]
        for n, sock in enumerate(busy):
            sock.sendall(encode(Request(n, "wait", {})))
        deadline = time.monotonic() + 30
        while server.on_loop(lambda: gate.waiting) < 2:
            assert time.monotonic() < deadline, "the requests never arrived"
            time.sleep(0.01)
        with pytest.raises(DaemonHungUp) as refused, ControlClient.connect(address) as late:
            late.call("echo", {})
        assert str(refused.value).startswith(
            "too many control clients: all 2 the daemon serves ([output] max_clients) are in "
            "the middle of a request"
        )
        assert isinstance(refused.value, RuntimeFailure)  # the CLI's exit 1

        def open_gate() -> None:
            assert gate.gate is not None
            gate.gate.set()

        server.on_loop(open_gate)
        for n, sock in enumerate(busy):
            assert _hung_up_with_answer(sock, n) == "opened"
    finally:
        for sock in busy:
            sock.close()
        server.stop()
