"""The C host kit's MessagePack code and control-channel client (plugins/host-c), driven
through its test program `wxsky_client_check` over real unix and loopback tcp sockets.

The daemon side is a real `ControlServer` with a small handler on an event loop in a
background thread, a raw socket server where a test needs bytes no ControlServer would send
(dribbled, garbage, a hang-up), and for one test a real `wxsky run` daemon. Socket tests run
against the plain build and the AddressSanitizer + UndefinedBehaviorSanitizer build; a
sanitizer finding exits 98/99 and fails the test.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import queue
import random
import signal
import socket
import struct
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import msgpack
import pytest
from daemon_harness import running_daemon
from host_kit import host_kit, host_kit_sanitized, sanitizer_env  # noqa: F401
from server_thread import ServerThread as LoopServer

from wxsky.errors import WxskyError
from wxsky.host.client import RemoteError

T = TypeVar("T")
CHECK = "wxsky_client_check"
SANITIZER_EXITS = (98, 99)


# -- the test program -------------------------------------------------------------------


class Kit:
    """One build of the kit: runs its `wxsky_client_check`."""

    def __init__(self, build: Path, sanitized: bool) -> None:
        self.program = build / CHECK
        self.sanitized = sanitized
        self.env = sanitizer_env() if sanitized else dict(os.environ)

    def run(self, *args: str, timeout: float = 120, env: dict[str, str] | None = None) -> Run:
        proc = subprocess.run(
            [str(self.program), *args],
            capture_output=True,
            text=True,
            timeout=timeout,
            env={**self.env, **(env or {})},
        )
        assert proc.returncode not in SANITIZER_EXITS, proc.stderr
        return Run(proc.returncode, proc.stdout, proc.stderr)

    def session(self, address: str, *steps: str, options: tuple[str, ...] = ()) -> Run:
        # A step's own timeout (5 s unless given) only catches a hang: a minute, so that a
        # busy machine is never taken for one.
        if "--timeout" not in options:
            options = ("--timeout", "60000", *options)
        return self.run("session", *options, address, *steps)

    def start(self, address: str, *steps: str) -> Live:
        return Live(self, ["session", "--timeout", "60000", address, *steps])


class Run:
    def __init__(self, returncode: int, stdout: str, stderr: str) -> None:
        self.returncode = returncode
        self.stdout = stdout
        self.stderr = stderr
        self.lines: list[dict[str, Any]] = [json.loads(line) for line in stdout.splitlines()]

    def ok(self) -> Run:
        assert self.returncode == 0, f"exit {self.returncode}: {self.stderr}\n{self.stdout}"
        return self

    def steps(self, name: str) -> list[dict[str, Any]]:
        return [line for line in self.lines if line.get("step") == name]

    def step(self, name: str) -> dict[str, Any]:
        found = self.steps(name)
        assert len(found) == 1, (name, self.lines)
        return found[0]

    def notifications(self) -> list[dict[str, Any]]:
        return [line for line in self.lines if line.get("kind") == "notification"]


class Live:
    """A session running in the background, read line by line as it goes."""

    def __init__(self, kit: Kit, args: list[str]) -> None:
        self.proc = subprocess.Popen(
            [str(kit.program), *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=kit.env,
        )
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.seen: list[dict[str, Any]] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line)
        self.lines.put(None)

    def next_line(self, timeout: float = 60) -> dict[str, Any]:
        line = self.lines.get(timeout=timeout)
        assert line is not None, f"the session ended early: {self.finish()[1]}"
        parsed: dict[str, Any] = json.loads(line)
        self.seen.append(parsed)
        return parsed

    def wait_for(self, test: Callable[[dict[str, Any]], bool], timeout: float = 60) -> None:
        deadline = time.monotonic() + timeout
        while not test(self.next_line(max(0.01, deadline - time.monotonic()))):
            pass

    def finish(self, timeout: float = 60) -> tuple[int, str]:
        try:
            self.proc.wait(timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(5)
        while True:
            try:
                line = self.lines.get_nowait()
            except queue.Empty:
                break
            if line is not None:
                self.seen.append(json.loads(line))
        assert self.proc.stderr is not None
        stderr = self.proc.stderr.read()
        self.proc.stderr.close()
        assert self.proc.stdout is not None
        self.proc.stdout.close()
        assert self.proc.returncode not in SANITIZER_EXITS, stderr
        return self.proc.returncode, stderr


@pytest.fixture(params=["plain", "sanitized"])
def kit(request: pytest.FixtureRequest) -> Kit:
    sanitized = request.param == "sanitized"
    build: Path = request.getfixturevalue("host_kit_sanitized" if sanitized else "host_kit")
    return Kit(build, sanitized)


@pytest.fixture
def plain_kit(host_kit: Path) -> Kit:  # noqa: F811
    return Kit(host_kit, sanitized=False)


@pytest.fixture
def sanitized_kit(host_kit_sanitized: Path) -> Kit:  # noqa: F811
    return Kit(host_kit_sanitized, sanitized=True)


def packed(value: Any) -> str:
    """msgpack of `value` as the hex a session step takes."""
    data: bytes = msgpack.packb(value, use_bin_type=True)
    return data.hex()


# -- servers ----------------------------------------------------------------------------


class ServerThread(LoopServer):
    """A ControlServer that records the requests it gets and answers like a small daemon."""

    def __init__(self, address: str) -> None:
        self.received: list[tuple[str, dict[str, Any]]] = []
        super().__init__(address, self.handle)

    async def handle(self, method: str, params: dict[str, Any]) -> Any:
        self.received.append((method, params))
        if method == "echo":
            return params
        if method == "fail":
            raise WxskyError("unknown weather preset 'foggy'")
        if method == "crash":
            raise RuntimeError("boom\nsecond line")
        if method == "slow":
            await asyncio.sleep(params["s"])
            return params.get("tag")
        if method == "burst":
            # Notifications go out before the response: the caller reads them while it waits.
            for seq in range(params["n"]):
                self.server.broadcast("tick", {"seq": seq})
            await asyncio.sleep(0.05)
            return "done"
        if method == "status":
            return {"version": "0.1.0-test", "shm_name": "wxsky-test", "frames_published": 3}
        if method == "set_camera":
            return {
                "position_m": params["position_m"],
                **{k: params[k] for k in ("heading_deg", "pitch_deg", "roll_deg", "fov_deg")},
                "width": params.get("width", 960),
                "height": params.get("height", 540),
            }
        if method in ("set_aircraft", "set_time", "apply_preset", "apply_metar", "release"):
            return {"method": method}
        if method == "radar":
            return _radar_answer(params)
        raise WxskyError(f"unknown method {method!r}")


@contextlib.contextmanager
def control_server(address: str) -> Iterator[ServerThread]:
    server = ServerThread(address)
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def sock_path(tmp_path: Path) -> Path:
    return tmp_path / "wx.sock"


@pytest.fixture
def server(sock_path: Path) -> Iterator[ServerThread]:
    with control_server(f"unix:{sock_path}") as s:
        yield s


class RawServer:
    """A unix socket server that runs `script(conn)` on each connection it accepts, for
    streams no ControlServer would send."""

    def __init__(self, path: Path, script: Callable[[socket.socket], None]) -> None:
        self.path = path
        self.script = script
        self.errors: list[BaseException] = []
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.bind(str(path))
        self.sock.listen(4)
        self.sock.settimeout(0.2)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    @property
    def address(self) -> str:
        return f"unix:{self.path}"

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            with conn:
                try:
                    self.script(conn)
                    _drain(conn)
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the client hung up first: what it should do after bad bytes
                except BaseException as exc:
                    self.errors.append(exc)

    def close(self) -> None:
        self._stop.set()
        self.sock.close()
        self.thread.join(5)
        assert not self.errors, self.errors


def _drain(conn: socket.socket) -> None:
    """Read what the client sent, so closing does not reset the connection."""
    conn.setblocking(False)
    with contextlib.suppress(BlockingIOError, OSError):
        while conn.recv(65536):
            pass


@contextlib.contextmanager
def raw_server(path: Path, script: Callable[[socket.socket], None]) -> Iterator[RawServer]:
    srv = RawServer(path, script)
    try:
        yield srv
    finally:
        srv.close()


def notification(method: str, params: Any) -> bytes:
    data: bytes = msgpack.packb([2, method, params], use_bin_type=True)
    return data


def response(msgid: Any, error: Any, result: Any) -> bytes:
    data: bytes = msgpack.packb([1, msgid, error, result], use_bin_type=True)
    return data


def read_request(conn: socket.socket) -> list[Any]:
    """One request from the client (blocking)."""
    unpacker = msgpack.Unpacker(raw=False)
    conn.settimeout(60)
    while True:
        chunk = conn.recv(65536)
        assert chunk, "the client hung up before sending a request"
        unpacker.feed(chunk)
        for obj in unpacker:
            assert isinstance(obj, list)
            return obj


# -- MessagePack ------------------------------------------------------------------------


def test_mp_selftest(kit: Kit) -> None:
    run = kit.run("mp-selftest").ok()
    assert run.lines == [{"selftest": "ok", "failures": 0}]


BOUNDARY_INTS = [
    0, 1, 127, 128, 255, 256, 65535, 65536, 2**32 - 1, 2**32, 2**63 - 1, 2**63, 2**64 - 1,
    -1, -31, -32, -33, -127, -128, -129, -32767, -32768, -32769, -(2**31), -(2**31) - 1,
    -(2**63),
]  # fmt: skip
FLOATS = [0.0, -0.0, 1.5, -2.25e-300, 1e300, 5e-324, math.inf, -math.inf, math.nan, 0.1]
STRINGS = ["", "a", "x" * 31, "x" * 32, "x" * 255, "x" * 256, "héllo €😀", '\x00\n"\\']
BINS = [b"", b"\x00\xff", b"b" * 255, b"b" * 256]


def sample_values() -> list[Any]:
    return [
        None, True, False, *BOUNDARY_INTS, *FLOATS, *STRINGS, *BINS,
        [], [None] * 15, [None] * 16, {}, {f"k{i}": i for i in range(15)},
        {f"k{i}": i for i in range(16)},
        {"position_m": [1.5, -2.0, 1500.25], "nested": {"a": [[], {}, [1, [2, [3]]]]}},
        [0, 1, "status", {}],
    ]  # fmt: skip


def tokens(value: Any) -> list[str]:
    """The mp-encode tokens that write `value` with the C writer."""
    if value is None:
        return ["n"]
    if value is True:
        return ["t"]
    if value is False:
        return ["f"]
    if isinstance(value, int):
        # Both writers for non-negative ints: write_int must give write_uint's bytes.
        if value < 0 or (value < 2**63 and value % 2):
            return [f"i:{value}"]
        return [f"u:{value}"]
    if isinstance(value, float):
        return ["d:" + struct.pack(">d", value).hex()]
    if isinstance(value, str):
        data = value.encode()
        if len(data) > 64 and len(set(data)) == 1:
            return [f"s:{len(data)}:{data[:1].hex()}"]
        return ["s:" + data.hex()]
    if isinstance(value, bytes):
        if len(value) > 64 and len(set(value)) == 1:
            return [f"b:{len(value)}:{value[:1].hex()}"]
        return ["b:" + value.hex()]
    if isinstance(value, list):
        return [f"a:{len(value)}", *(t for item in value for t in tokens(item))]
    if isinstance(value, dict):
        out = [f"m:{len(value)}"]
        for key, item in value.items():
            out += tokens(key) + tokens(item)
        return out
    raise TypeError(value)


def test_c_encoding_is_byte_identical_to_msgpack_python(kit: Kit) -> None:
    values = [*sample_values(), "x" * 65535, "x" * 65536, b"b" * 65535, b"b" * 65536]
    for value in values:
        run = kit.run("mp-encode", *tokens(value)).ok()
        expected = msgpack.packb(value, use_bin_type=True)
        assert bytes.fromhex(run.lines[0]["hex"]) == expected, repr(value)[:80]
    # Big containers in one object: array16/32 and map16/32 headers.
    for count in (65535, 65536):
        run = kit.run("mp-encode", f"a:{count}", *(["n"] * count)).ok()
        assert bytes.fromhex(run.lines[0]["hex"]) == msgpack.packb([None] * count)
    every = sample_values()
    run = kit.run("mp-encode", *tokens(every)).ok()
    decoded = msgpack.unpackb(bytes.fromhex(run.lines[0]["hex"]), raw=False)
    assert _comparable(decoded) == _comparable(every)


def _comparable(value: Any) -> Any:
    """NaN compares unequal to itself: replace it for whole-structure comparisons."""
    if isinstance(value, float) and math.isnan(value):
        return "NaN"
    if isinstance(value, list):
        return [_comparable(v) for v in value]
    if isinstance(value, dict):
        return {k: _comparable(v) for k, v in value.items()}
    return value


def as_json(value: Any) -> Any:
    """What mp-decode prints for a Python value."""
    if isinstance(value, bytes):
        return {"$bin": value.hex()}
    if isinstance(value, list):
        return [as_json(v) for v in value]
    if isinstance(value, dict):
        return {k: as_json(v) for k, v in value.items()}
    return value


def same(a: Any, b: Any) -> bool:
    """Equal, with the same types (1 is not 1.0) and NaN equal to NaN."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return (math.isnan(a) and math.isnan(b)) or (
            a == b and math.copysign(1, a) == math.copysign(1, b)
        )
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    return bool(a == b)


def test_python_encoding_decodes_in_c(kit: Kit) -> None:
    values = sample_values()
    encoded = [msgpack.packb(v, use_bin_type=True) for v in values]
    # float32 (the daemon sends float64, but a receiver reads both) and encodings larger than
    # needed, which another encoder may produce.
    extra: list[tuple[bytes, Any]] = [
        (msgpack.packb(1.5, use_single_float=True), 1.5),
        (msgpack.packb(-0.25, use_single_float=True), -0.25),
        (b"\xd0\x05", 5), (b"\xcd\x00\x01", 1), (b"\xd3" + (7).to_bytes(8, "big"), 7),
        (b"\xd9\x01a", "a"), (b"\xdc\x00\x01\xc0", [None]), (b"\xde\x00\x01\xa1k\x01", {"k": 1}),
        (b"\xc5\x00\x01z", b"z"),
    ]  # fmt: skip
    run = kit.run("mp-decode", *(e.hex() for e in encoded), *(e.hex() for e, _ in extra)).ok()
    expected = [*values, *(v for _, v in extra)]
    data = [*encoded, *(e for e, _ in extra)]
    assert len(run.lines) == len(expected)
    for line, value, raw in zip(run.lines, expected, data, strict=True):
        assert line["size"] == len(raw), value
        assert same(line["value"], as_json(value)), (line["value"], value)
    # Bytes after the object are not part of it.
    run = kit.run("mp-decode", (encoded[-1] + b"\xc1\xc1").hex()).ok()
    assert run.lines[0]["size"] == len(encoded[-1])


@pytest.mark.parametrize(
    ("name", "data"),
    [
        ("0xc1", b"\xc1"),
        ("ext type", msgpack.packb([2, "t", {"x": msgpack.ExtType(1, b"x")}])),
        ("timestamp", msgpack.packb([2, "t", {"x": msgpack.Timestamp(1, 0)}])),
        ("int map key", msgpack.packb([2, "t", {1: 2}])),
        ("bin map key", msgpack.packb({b"k": 1}, use_bin_type=True)),
        ("invalid utf-8", b"\x92\xa2\xff\xfe\xc0"),
        ("nesting 65", b"\x91" * 65 + b"\xc0"),
        ("9 MiB str", b"\xdb" + (9 << 20).to_bytes(4, "big")),
        ("9M-element array", b"\xdd" + (9 << 20).to_bytes(4, "big")),
    ],
)
def test_bytes_outside_the_protocol_are_refused(plain_kit: Kit, name: str, data: bytes) -> None:
    run = plain_kit.run("mp-decode", data.hex()).ok()
    assert run.lines[0]["size"] == -3, name  # WXSKY_EFORMAT


def fuzz_inputs(seed: int, count: int) -> list[bytes]:
    """Random bytes, valid messages, and valid messages mutated: flipped, cut, spliced."""
    rng = random.Random(seed)

    def value(depth: int) -> Any:
        kind = rng.randrange(10 if depth < 4 else 7)
        if kind == 0:
            return None
        if kind == 1:
            return rng.random() < 0.5
        if kind == 2:
            near = rng.choice(BOUNDARY_INTS) + rng.randrange(-2, 3) * (rng.random() < 0.3)
            return min(max(near, -(2**63)), 2**64 - 1)
        if kind == 3:
            return rng.choice([*FLOATS, rng.uniform(-1e6, 1e6)])
        if kind == 4:
            return "".join(rng.choice("ab€😀\x00") for _ in range(rng.randrange(40)))
        if kind == 5:
            return rng.randbytes(rng.randrange(40))
        if kind == 6:
            return rng.randrange(-100, 100)
        if kind == 7:
            return [value(depth + 1) for _ in range(rng.randrange(5))]
        return {f"k{i}": value(depth + 1) for i in range(rng.randrange(5))}

    def message() -> bytes:
        shape = rng.randrange(3)
        if shape == 0:
            obj: Any = [2, rng.choice(["frame", "scene", "weather"]), {"v": value(1)}]
        elif shape == 1:
            obj = [1, rng.randrange(2**32), None, value(1)]
        else:
            obj = [1, rng.choice([None, 7]), "error text", None]
        data: bytes = msgpack.packb(obj, use_bin_type=True)
        return data

    def radar() -> bytes:
        """A `radar` answer's body (wxsky_radar_decode's input), often a little wrong."""
        size = rng.choice([0, 1, 2, 3, 8, 2**32 + 1])
        body: dict[str, Any] = {
            "pending": rng.choice([False, False, True, 1, None]),
            "size_px": size,
            "range_nm": rng.choice([40.0, "x", None]),
            "dbz_offset": -32.0,
            "dbz_step": rng.choice([0.5, 0.0, -1.0]),
            "centre_m": rng.choice([[1.0, 2.0, 3.0], [1.0], "c"]),
            "pixels": rng.randbytes(max(0, min(size, 9) ** 2 + rng.choice([0, 0, -1, 1]))),
        }
        for key in rng.sample(sorted(body), rng.randrange(3)):
            del body[key]
        data: bytes = msgpack.packb(body, use_bin_type=True)
        return data

    headers = [bytes([b]) for b in (0xC1, 0xC7, 0xD4, 0xD6, 0xDB, 0xDD, 0xDF, 0xC6)]
    out: list[bytes] = []
    for _ in range(count):
        pick = rng.randrange(7)
        if pick == 6:
            out.append(radar())
        elif pick == 0:
            out.append(rng.randbytes(rng.randrange(64)))
        elif pick == 1:
            out.append(b"".join(message() for _ in range(rng.randrange(1, 4))))
        elif pick == 2:
            data = bytearray(message())
            for _ in range(rng.randrange(1, 4)):
                data[rng.randrange(len(data))] = rng.randrange(256)
            out.append(bytes(data))
        elif pick == 3:
            data = bytearray(message())
            out.append(bytes(data[: rng.randrange(len(data))]))
        elif pick == 4:
            data = bytearray(message())
            at = rng.randrange(len(data))
            out.append(bytes(data[:at] + rng.choice(headers) + rng.randbytes(4) + data[at:]))
        else:
            depth = rng.randrange(60, 70)
            out.append(b"\x93\x02\xa1t\x81\xa1k" + b"\x91" * depth + b"\xc0")
    return out


def test_fuzz_under_the_sanitizers(sanitized_kit: Kit, tmp_path: Path) -> None:
    inputs = fuzz_inputs(seed=20240621, count=3000)
    records = tmp_path / "fuzz.bin"
    records.write_bytes(b"".join(struct.pack("<I", len(d)) + d for d in inputs))
    run = sanitized_kit.run("mp-fuzz", str(records), str(tmp_path / "fuzz.sock"), timeout=120)
    run.ok()
    summary = run.lines[-1]
    assert summary["inputs"] == len(inputs)
    # The mix exercised every outcome: whole objects, partial ones, refusals; on the socket,
    # good messages, then the end of the stream or the refusal that closes it.
    assert summary["complete"] > 300 and summary["need_more"] > 100 and summary["refused"] > 300
    assert summary["messages"] > 300 and summary["eformat"] > 300 and summary["eclosed"] > 300


# -- the control channel ----------------------------------------------------------------


def test_status_and_set_camera_round_trip(kit: Kit, server: ServerThread, sock_path: Path) -> None:
    run = kit.session(
        f"unix:{sock_path}", "status", "camera:100,-200.5,1500,90,5,-2.5,60,640,360",
        "camera:1,2,3,10,0,0,45",
    ).ok()  # fmt: skip
    status = run.step("status")
    assert status["status"] == "WXSKY_OK" and status["msgid"] == 1 and status["error"] is None
    assert status["result"]["version"] == "0.1.0-test"
    assert status["result"]["shm_name"] == "wxsky-test"
    camera = run.steps("camera:100,-200.5,1500,90,5,-2.5,60,640,360")[0]
    assert camera["msgid"] == 2
    assert camera["result"] == {
        "position_m": [100.0, -200.5, 1500.0], "heading_deg": 90.0, "pitch_deg": 5.0,
        "roll_deg": -2.5, "fov_deg": 60.0, "width": 640, "height": 360,
    }  # fmt: skip
    # width/height 0: left out, the daemon keeps its own
    assert server.received[2] == (
        "set_camera",
        {"position_m": [1.0, 2.0, 3.0], "heading_deg": 10.0, "pitch_deg": 0.0,
         "roll_deg": 0.0, "fov_deg": 45.0},
    )  # fmt: skip


def test_typed_requests_send_the_documented_params(
    kit: Kit, server: ServerThread, sock_path: Path
) -> None:
    kit.session(
        f"unix:{sock_path}",
        "aircraft:10,20,1000", "aircraft:none", "time:2024-06-21T12:00:00Z",
        "time:2024-06-21T18:30:00Z,60", "rate:0", "preset:scattered-cumulus",
        "metar:EGLL 211250Z 24010KT 9999 SCT030 18/09 Q1015", "release", "release:cockpit",
        "status", "sub:frame,weather", "unsub:weather",
    ).ok()  # fmt: skip
    assert server.received == [
        ("set_aircraft", {"position_m": [10.0, 20.0, 1000.0]}),
        ("set_aircraft", {"position_m": None}),
        ("set_time", {"time_utc": "2024-06-21T12:00:00Z"}),
        ("set_time", {"time_utc": "2024-06-21T18:30:00Z", "rate": 60.0}),
        ("set_time", {"rate": 0.0}),
        ("apply_preset", {"name": "scattered-cumulus"}),
        ("apply_metar", {"report": "EGLL 211250Z 24010KT 9999 SCT030 18/09 Q1015"}),
        ("release", {"source": "control"}),
        ("release", {"source": "cockpit"}),
        ("status", {}),
    ]  # subscribe/unsubscribe are answered by the server itself


def _radar_answer(params: dict[str, Any]) -> dict[str, Any]:
    """The test server's `radar`: pending at tilt 9; at size 65 pixels one byte short (not
    the protocol); else a picture whose brightest byte is 200 (68 dBZ)."""
    size = int(params["size_px"])
    out = {k: params[k] for k in ("range_nm", "tilt_deg", "size_px")}
    if params["tilt_deg"] == 9.0:
        return out | {"pending": True}
    pixels = bytearray(size * size - (1 if size == 65 else 0))
    pixels[size + 3] = 200
    return out | {
        "pending": False,
        "centre_m": [1.0, 2.0, 1500.0],
        "time_utc": "2026-07-22T15:00:00+00:00",
        "age_s": 0.25,
        "took_s": 0.1,
        "dbz_offset": -32.0,
        "dbz_step": 0.5,
        "pixels": bytes(pixels),
    }


def test_the_radar_is_asked_for_and_decoded(
    kit: Kit, server: ServerThread, sock_path: Path
) -> None:
    """`wxsky_request_radar` sends the documented params; `wxsky_radar_decode` reads a
    picture and a pending answer, and refuses pixels that are not size_px squared."""
    out = kit.session(f"unix:{sock_path}", "radar:40,1.5,64", "radar:20,9,64").ok()
    assert server.received[:2] == [
        ("radar", {"range_nm": 40.0, "tilt_deg": 1.5, "size_px": 64}),
        ("radar", {"range_nm": 20.0, "tilt_deg": 9.0, "size_px": 64}),
    ]
    picture, pending = (line["radar"] for line in out.lines if "radar" in line)
    assert picture == {
        "pending": False,
        "size_px": 64,
        "range_nm": 40.0,
        "tilt_deg": 1.5,
        "max_dbz": 68.0,
        "bytes": 64 * 64,
    }
    assert pending["pending"] is True and pending["bytes"] == 0
    bad = kit.session(f"unix:{sock_path}", "radar:40,0,65")
    assert bad.returncode == 1 and "WXSKY_EFORMAT" in bad.stderr


def test_subscribe_delivers_in_order_and_call_queues_what_arrives_meanwhile(
    kit: Kit, server: ServerThread, sock_path: Path
) -> None:
    run = kit.session(
        f"unix:{sock_path}", "sub:tick,other", "call:burst:" + packed({"n": 5}), "poll:5",
        "sub:tick", "call:burst:" + packed({"n": 3}), "poll:3", "unsub:tick",
        "call:burst:" + packed({"n": 2}), "drain:150",
    ).ok()  # fmt: skip
    assert run.steps("sub:tick,other")[0]["result"] == {"topics": ["other", "tick"]}
    assert run.step("sub:tick")["result"] == {"topics": ["other", "tick"]}
    assert run.step("unsub:tick")["result"] == {"topics": ["other"]}
    # The response first (call returned it), then the queued notifications, oldest first.
    kinds = [(line["step"], line.get("kind")) for line in run.lines if "kind" in line]
    assert kinds[1] == ("call:burst:" + packed({"n": 5}), "response")
    assert [n["params"]["seq"] for n in run.notifications()] == [0, 1, 2, 3, 4, 0, 1, 2]
    assert all(n["method"] == "tick" and n["step"].startswith("poll:") for n in run.notifications())
    assert run.steps("drain:150") == []  # unsubscribed: nothing more


def test_a_full_queue_drops_the_oldest(kit: Kit, server: ServerThread, sock_path: Path) -> None:
    run = kit.session(
        f"unix:{sock_path}", "sub:tick", "call:burst:" + packed({"n": 10}), "poll:3",
        "dropped", "drain:100", options=("--queue", "3"),
    ).ok()  # fmt: skip
    assert [n["params"]["seq"] for n in run.notifications()] == [7, 8, 9]
    assert run.step("dropped")["dropped"] == 7


def test_remote_errors_come_back_verbatim(kit: Kit, server: ServerThread, sock_path: Path) -> None:
    bad_topics = packed({"topics": 5})
    run = kit.session(
        f"unix:{sock_path}", "call:fail", "call:nosuch", f"call:subscribe:{bad_topics}",
        "call:crash", "call:echo:" + packed({"still": "open"}),
    ).ok()  # fmt: skip
    expected = {
        "call:fail": "unknown weather preset 'foggy'",
        "call:nosuch": "unknown method 'nosuch'",
        f"call:subscribe:{bad_topics}": 'subscribe: params must be {"topics": [str, ...]}',
        "call:crash": "internal error: RuntimeError: boom second line",
    }
    for step, message in expected.items():
        line = run.step(step)
        assert line["status"] == "WXSKY_EREMOTE" and line["error"] == message, line
        assert line["result"] is None
    assert run.step("call:echo:" + packed({"still": "open"}))["result"] == {"still": "open"}


def test_params_that_are_not_one_map_are_refused_locally(
    kit: Kit, server: ServerThread, sock_path: Path
) -> None:
    for params in (packed([1]), packed({"a": 1}) + "c0", "c1"):
        run = kit.session(f"unix:{sock_path}", f"call:echo:{params}")
        assert run.returncode == 1 and "WXSKY_EINVAL" in run.stderr, run.stderr
    assert server.received == []


def test_pipelined_requests_are_matched_by_msgid(
    kit: Kit, server: ServerThread, sock_path: Path
) -> None:
    slow = "send:slow:" + packed({"s": 0.15, "tag": "first"})
    run = kit.session(
        f"unix:{sock_path}", slow, "send:echo:" + packed({"n": 2}),
        "call:echo:" + packed({"n": 3}), "poll:2",
        "send:echo:" + packed({"n": 4}), "send:echo:" + packed({"n": 5}), "wait:5", "wait:4",
    ).ok()  # fmt: skip
    assert [line["msgid"] for line in run.lines if "msgid" in line][:3] == [1, 2, 3]
    call = run.step("call:echo:" + packed({"n": 3}))
    assert call["msgid"] == 3 and call["result"] == {"n": 3}
    polled = run.steps("poll:2")
    assert [(p["msgid"], p["result"]) for p in polled] == [(1, "first"), (2, {"n": 2})]
    assert [line["msgid"] for line in run.lines if "msgid" in line][5:7] == [4, 5]
    assert run.step("wait:5")["result"] == {"n": 5}
    assert run.step("wait:4")["result"] == {"n": 4}  # queued while waiting for 5


def test_a_late_response_comes_through_poll(
    kit: Kit, server: ServerThread, sock_path: Path
) -> None:
    run = kit.session(
        f"unix:{sock_path}",
        "send:slow:" + packed({"s": 0.3, "tag": "late"}),
        "wait:1:50",
        "poll:1",
    ).ok()
    assert run.step("wait:1:50")["status"] == "WXSKY_ETIMEDOUT"
    late = run.step("poll:1")
    assert late["kind"] == "response" and late["msgid"] == 1 and late["result"] == "late"


def test_messages_split_across_reads_and_many_in_one_read(kit: Kit, tmp_path: Path) -> None:
    dribbled = notification("frame", {"frame_number": 1, "camera": {"fov_deg": 60.0}})
    burst = b"".join(notification("frame", {"frame_number": n}) for n in range(2, 52))
    big = notification("weather", {"blob": b"\xab" * (7 << 20), "n": 52})  # 7 MiB
    tail = notification("frame", {"frame_number": 53})

    def script(conn: socket.socket) -> None:
        for i in range(len(dribbled)):
            conn.sendall(dribbled[i : i + 1])
            time.sleep(0.002)
        conn.sendall(burst + tail[:3])  # and the start of the last one
        time.sleep(0.05)
        conn.sendall(tail[3:] + big[:5])
        for i in range(5, len(big), 1 << 18):
            conn.sendall(big[i : i + (1 << 18)])

    with raw_server(tmp_path / "raw.sock", script) as srv:
        run = kit.session(srv.address, "poll:53", "expect:WXSKY_ECLOSED").ok()
    numbers = [n["params"].get("frame_number", n["params"].get("n")) for n in run.notifications()]
    assert numbers == [*range(1, 52), 53, 52]
    assert run.notifications()[0]["params"]["camera"] == {"fov_deg": 60.0}
    blob = run.notifications()[-1]["params"]["blob"]["$bin"]
    assert len(blob) == 2 * (7 << 20) and set(blob) == {"a", "b"}
    assert "closed the connection" in run.step("expect:WXSKY_ECLOSED")["message"]


def test_a_message_larger_than_the_buffer_is_enospc(kit: Kit, tmp_path: Path) -> None:
    def script(conn: socket.socket) -> None:
        conn.sendall(notification("frame", {"n": 1}) + notification("frame", {"b": b"x" * 5000}))

    with raw_server(tmp_path / "raw.sock", script) as srv:
        steps = ("poll:1", "expect:WXSKY_ENOSPC")
        run = kit.session(srv.address, *steps, options=("--buffer", "4096")).ok()
    assert "larger than the receive buffer" in run.step("expect:WXSKY_ENOSPC")["message"]


def deep(levels: int) -> Any:
    value: Any = None
    for _ in range(levels):
        value = [value]
    return value


GARBAGE = {
    "not msgpack": b"\xc1\xc1 this is not msgpack",
    "ext type": notification("frame", {"x": msgpack.ExtType(5, b"abc")}),
    "timestamp": notification("frame", {"t": msgpack.Timestamp(1_700_000_000, 0)}),
    "int map keys": notification("frame", {1: "one", 2: "two"}),
    "9 MiB str declared": b"\x93\x02\xa5frame\x81\xa1b\xdb" + (9 << 20).to_bytes(4, "big"),
    "9 MiB sent": msgpack.packb([2, "frame", {"a": b"a" * (5 << 20), "b": b"b" * (4 << 20)}]),
    "nesting 100 deep": notification("frame", {"deep": deep(100)}),
    "not an array": msgpack.packb({"method": "frame"}),
    "unknown type": msgpack.packb([3, "frame", {}]),
    "short array": msgpack.packb([2, "frame"]),
    "method not a string": msgpack.packb([2, 7, {}]),
    "params not a map": msgpack.packb([2, "frame", [1, 2]]),
    "msgid not an int": response("seven", None, None),
    "msgid above 2^32-1": response(2**32, None, None),
    "error not a string": response(1, 5, None),
    "invalid utf-8": b"\x93\x02\xa5frame\x81\xa1s\xa2\xff\xfe",
    "bool as type": msgpack.packb([True, "frame", {}]),
}


@pytest.mark.parametrize("name", sorted(GARBAGE))
def test_garbage_from_the_server_is_eformat(kit: Kit, tmp_path: Path, name: str) -> None:
    good = notification("frame", {"frame_number": 1})

    def script(conn: socket.socket) -> None:
        conn.sendall(good + GARBAGE[name] + good)
        time.sleep(0.1)

    with raw_server(tmp_path / "raw.sock", script) as srv:
        run = kit.session(srv.address, "poll:1", "expect:WXSKY_EFORMAT").ok()
    assert run.notifications()[0]["params"] == {"frame_number": 1}
    message = run.step("expect:WXSKY_EFORMAT")["message"]
    assert "bad data from the wxsky daemon" in message and "message 2" in message, message
    assert "connection closed" in message


def test_garbage_while_waiting_for_a_response(kit: Kit, tmp_path: Path) -> None:
    def script(conn: socket.socket) -> None:
        request = read_request(conn)
        assert request[:3] == [0, 1, "status"]
        conn.sendall(notification("frame", {}) + b"\xd4\x01\x00")

    with raw_server(tmp_path / "raw.sock", script) as srv:
        run = kit.session(srv.address, "status")
    assert run.returncode == 1 and "status: WXSKY_EFORMAT" in run.stderr, run.stderr
    assert "extension types" in run.stderr


def test_server_hang_up_is_eclosed(kit: Kit, tmp_path: Path) -> None:
    frame = notification("frame", {"frame_number": 9})

    def clean(conn: socket.socket) -> None:
        conn.sendall(frame)

    def mid_message(conn: socket.socket) -> None:
        conn.sendall(frame + frame[:4])

    def silent(conn: socket.socket) -> None:
        read_request(conn)

    with raw_server(tmp_path / "a.sock", clean) as srv:
        run = kit.session(srv.address, "poll:1", "expect:WXSKY_ECLOSED", "expect:WXSKY_ECLOSED")
    run.ok()
    assert run.notifications()[0]["params"] == {"frame_number": 9}
    with raw_server(tmp_path / "b.sock", mid_message) as srv:
        run = kit.session(srv.address, "poll:1", "expect:WXSKY_ECLOSED").ok()
    assert "in the middle of a message" in run.step("expect:WXSKY_ECLOSED")["message"]
    with raw_server(tmp_path / "c.sock", silent) as srv:
        run = kit.session(srv.address, "status")
    assert run.returncode == 1 and "status: WXSKY_ECLOSED" in run.stderr, run.stderr


def test_nil_msgid_error_ends_the_wait_and_the_connection(kit: Kit, tmp_path: Path) -> None:
    said = "control message 1: not valid msgpack (unpack failed)"

    def script(conn: socket.socket) -> None:
        read_request(conn)
        conn.sendall(response(None, said, None))

    with raw_server(tmp_path / "raw.sock", script) as srv:
        run = kit.session(srv.address, "status", "expect:WXSKY_ECLOSED").ok()
    line = run.step("status")
    assert line["status"] == "WXSKY_EREMOTE" and line["msgid"] is None and line["error"] == said


def test_requests_from_the_daemon_are_skipped(kit: Kit, tmp_path: Path) -> None:
    def script(conn: socket.socket) -> None:
        conn.sendall(msgpack.packb([0, 1, "ping", {}]) + notification("frame", {"n": 1}))

    with raw_server(tmp_path / "raw.sock", script) as srv:
        run = kit.session(srv.address, "poll:1", "expect:WXSKY_ECLOSED").ok()
    assert [n["params"] for n in run.notifications()] == [{"n": 1}]


def test_reconnect_after_a_restart_renews_the_subscription(kit: Kit, sock_path: Path) -> None:
    address = f"unix:{sock_path}"
    first = ServerThread(address)
    live = None
    try:
        live = kit.start(
            address, "sub:tick,scene", "note:tick", "expect:WXSKY_ECLOSED", "reconnect:3000",
            "note:tick", "call:echo:" + packed({"after": "restart"}),
        )  # fmt: skip
        live.wait_for(lambda line: line["step"] == "sub:tick,scene")
        first.broadcast("tick", {"server": 1})
        live.wait_for(lambda line: line.get("kind") == "notification")
        first.stop()
        live.wait_for(lambda line: line["step"] == "expect:WXSKY_ECLOSED")
        with control_server(address) as second:
            deadline = time.monotonic() + 60
            # The renewed subscription shows as a client the broadcast reaches.
            while second.broadcast("tick", {"server": 2}) == 0:
                assert time.monotonic() < deadline, "the client never subscribed again"
                time.sleep(0.02)
            code, stderr = live.finish()
            assert code == 0, stderr
            assert second.received == [("echo", {"after": "restart"})]
    finally:
        if live is not None and live.proc.poll() is None:
            live.proc.kill()
        with contextlib.suppress(Exception):
            first.stop()
    notes = [line["params"] for line in live.seen if line.get("kind") == "notification"]
    assert notes[0] == {"server": 1} and notes[-1] == {"server": 2}
    # The renewed subscribe's response is the client's own: never shown to the host.
    responses = [line for line in live.seen if line.get("kind") == "response"]
    assert [r["step"] for r in responses] == [
        "sub:tick,scene",
        "call:echo:" + packed({"after": "restart"}),
    ]
    # msgids carry on over the reconnect (1: subscribe, 2: the renewed one, 3: echo)
    assert responses[-1]["msgid"] == 3


def test_tcp_loopback(kit: Kit) -> None:
    with control_server("tcp:127.0.0.1:0") as srv:
        port = srv.server.address.port  # type: ignore[union-attr]
        for address in (f"tcp:127.0.0.1:{port}", f"tcp:localhost:{port}"):
            run = kit.session(address, "call:echo:" + packed({"via": "tcp"})).ok()
            assert run.lines[-1]["result"] == {"via": "tcp"}


def test_tcp_ipv6_loopback(kit: Kit) -> None:
    try:
        server = ServerThread("tcp:[::1]:0")
    except Exception as exc:  # no IPv6 loopback on this machine
        pytest.skip(f"cannot listen on [::1]: {exc}")
    try:
        port = server.server.address.port  # type: ignore[union-attr]
        for address in (f"tcp:[::1]:{port}", f"tcp:::1:{port}"):
            run = kit.session(address, "call:echo:" + packed({"via": "v6"})).ok()
            assert run.lines[-1]["result"] == {"via": "v6"}
    finally:
        server.stop()


@pytest.mark.parametrize(
    "host", ["10.0.0.1", "0.0.0.0", "192.168.1.20", "example.com", "[::]", "[::ffff:127.0.0.1]"]
)
def test_non_loopback_tcp_is_refused_without_a_packet(kit: Kit, host: str) -> None:
    # --no-network: the session runs under a seccomp filter that kills it on socket(),
    # connect(), sendto() or sendmsg(), so a refusal here provably sent nothing.
    run = kit.session(f"tcp:{host}:1", options=("--no-network",))
    if run.returncode == 4:
        pytest.skip(run.stderr.strip())
    assert run.returncode == 1, (run.returncode, run.stderr)
    assert "connect: WXSKY_EINVAL" in run.stderr and "is not a loopback address" in run.stderr


def test_the_no_network_sandbox_is_real(plain_kit: Kit) -> None:
    """The filter of the test above does kill a process that makes a socket."""
    run = plain_kit.session("tcp:127.0.0.1:1", options=("--no-network",))
    if run.returncode == 4:
        pytest.skip(run.stderr.strip())
    assert run.returncode == -31  # SIGSYS


@pytest.mark.parametrize(
    ("address", "why"),
    [
        ("wx.sock", "expected unix:PATH or tcp:HOST:PORT"),
        ("unix:", "unix: needs a socket path"),
        ("tcp:127.0.0.1", "expected tcp:HOST:PORT"),
        ("tcp:127.0.0.1:port", "expected tcp:HOST:PORT"),
        ("tcp::80", "expected tcp:HOST:PORT"),
        ("udp:x:1", "expected unix:PATH or tcp:HOST:PORT"),
        ("tcp:127.0.0.1:70000", "outside 0..65535"),
        ("tcp:127.0.0.1:0", "not 0"),
        ("unix:/" + "x" * 200, "limited to 107 bytes"),
    ],
)
def test_malformed_addresses(plain_kit: Kit, address: str, why: str) -> None:
    run = plain_kit.session(address, options=("--no-network",))
    if run.returncode == 4:
        run = plain_kit.session(address)
    assert run.returncode == 1 and "WXSKY_EINVAL" in run.stderr and why in run.stderr, run.stderr


def test_no_daemon_is_enoent(kit: Kit, tmp_path: Path) -> None:
    run = kit.session(f"unix:{tmp_path / 'nobody.sock'}")
    assert run.returncode == 1 and "connect: WXSKY_ENOENT" in run.stderr, run.stderr
    with socket.socket() as sock:  # a port nothing listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    run = kit.session(f"tcp:127.0.0.1:{port}")
    assert run.returncode == 1 and "connect: WXSKY_ENOENT" in run.stderr, run.stderr


def test_default_address_and_home_expansion(plain_kit: Kit, tmp_path: Path) -> None:
    runtime = tmp_path / "run"
    runtime.mkdir()
    env = {"XDG_RUNTIME_DIR": str(runtime), "HOME": str(tmp_path)}
    run = plain_kit.run("session", "default", env=env)
    assert run.returncode == 1 and "connect: WXSKY_ENOENT" in run.stderr, run.stderr
    (runtime / "wxsky").mkdir(mode=0o700)
    with control_server(f"unix:{runtime / 'wxsky' / 'wxsky.sock'}"):
        run = plain_kit.run("session", "default", "call:echo:" + packed({"at": "default"}), env=env)
        assert run.ok().lines[-1]["result"] == {"at": "default"}
    with control_server(f"unix:{tmp_path / 'home.sock'}"):
        run = plain_kit.run("session", "unix:~/home.sock", "call:echo", env=env)
        assert run.ok().lines[-1]["result"] == {}
    # Without XDG_RUNTIME_DIR (or with a relative one): /tmp/wxsky-<uid>.
    env = {"XDG_RUNTIME_DIR": "relative/dir"}
    run = plain_kit.run("session", "default", "close", env=env)
    # (exit 0 only where a daemon happens to listen at this user's default address)
    assert run.returncode == 0 or f"/tmp/wxsky-{os.getuid()}" in run.stderr, run.stderr


@pytest.mark.gl
def test_against_a_real_daemon(plain_kit: Kit, sanitized_kit: Kit, tmp_path: Path) -> None:
    with running_daemon(tmp_path) as daemon:
        bad: list[tuple[str, dict[str, Any]]] = [
            ("nosuch", {}),
            ("set_camera", {"pitch_deg": 120.0}),
            ("apply_preset", {"name": "no-such-preset"}),
            ("set_time", {}),
        ]
        # What the daemon says, through the Python client: the C client must say the same.
        said = []
        with daemon.client() as client:
            for method, params in bad:
                with pytest.raises(RemoteError) as info:
                    client.call(method, params)
                said.append(str(info.value))
        for kit in (plain_kit, sanitized_kit):
            run = kit.session(
                daemon.address, "status", "sub:frame", "note:frame",
                "time:2024-06-21T12:00:00Z", "preset:scattered-cumulus",
                "camera:0,0,1500,45,10,0,70,320,180", "note:frame",
                *(f"call:{m}:{packed(p)}" for m, p in bad), "release", "aircraft:0,100,1400",
                "aircraft:none", "status",
            ).ok()  # fmt: skip
            status = run.steps("status")[0]["result"]
            assert status["shm_name"] == daemon.shm_name and isinstance(status["version"], str)
            frame = run.notifications()[0]
            assert frame["method"] == "frame" and frame["params"]["frame_number"] >= 1
            camera = run.step("camera:0,0,1500,45,10,0,70,320,180")["result"]
            assert camera["position_m"] == [0.0, 0.0, 1500.0] and camera["width"] == 320
            assert camera["heading_deg"] == 45.0 and camera["fov_deg"] == 70.0
            assert run.step("preset:scattered-cumulus")["result"] == "scattered-cumulus"
            for (method, params), message in zip(bad, said, strict=True):
                line = run.step(f"call:{method}:{packed(params)}")
                assert line["status"] == "WXSKY_EREMOTE" and line["error"] == message
            assert run.step("release")["result"]["source"] == "control"
            assert run.step("aircraft:none")["result"] == {"position_m": None}
            final = run.steps("status")[-1]["result"]
            assert final["camera"]["width"] == 320
            assert final["overrides"] == {}  # released


@pytest.mark.gl
def test_reconnect_after_a_real_daemon_restarts(plain_kit: Kit, tmp_path: Path) -> None:
    # The daemon is stopped and a new one started on the same socket path (a new segment
    # name too): the client sees the hang-up, reconnects, renews its subscription and talks
    # to the new daemon.
    with running_daemon(tmp_path) as first:
        live = Live(
            plain_kit,
            ["session", "--timeout", "60000", first.address, "sub:frame", "note:frame",
             "expect:WXSKY_ECLOSED", "reconnect:6000", "note:frame", "status"],
        )  # fmt: skip
        try:
            live.wait_for(lambda line: line.get("kind") == "notification", timeout=120)
            first.proc.send_signal(signal.SIGTERM)
            assert first.proc.wait(timeout=120) == 0, first.log()
            live.wait_for(lambda line: line.get("step") == "expect:WXSKY_ECLOSED", timeout=120)
        except BaseException:
            live.proc.kill()
            raise
    with running_daemon(tmp_path) as second:
        code, stderr = live.finish(timeout=180)
        assert code == 0, stderr
        status = [line for line in live.seen if line.get("step") == "status"][-1]["result"]
        assert status["shm_name"] == second.shm_name != first.shm_name
        frames = [line for line in live.seen if line.get("kind") == "notification"]
        assert len(frames) >= 2 and all(f["method"] == "frame" for f in frames)
