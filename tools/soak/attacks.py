"""The seven attacks of issue 40 as scripted cases against running daemons, loopback only.

    .venv/bin/python tools/fuzz/fuzz.py --attacks [NAME ...]      # each once, one line each
    .venv/bin/python tools/soak/soak.py --attacks --minutes 60   # in the soak's fault cycles

Each attack is a function `attack(target) -> AttackResult`: it does its harm to the daemons of
a `Target` (a sky master with a CIGI port, a FlightGear pose port and a Zenoh bus, and where the
attack needs one a display channel joined to it), then watches what it did. A case holds when
the daemon it aimed at is alive (its pid, not its word), still publishing frames (the segment's
latest frame number, read with pread: a mapping of a segment someone truncates would fault this
process too), and `status` answers; some add a check of their own (a channel still follows
the master's real states, the master's status stays small, the frame rate holds). The harness
never raises for a daemon that died: the result says so, with its exit status and log tail.

1. `year9999_control`, `year9999_cigi`, `year9999_flightgear`: the clock at 9999-12-31T23:59
   from control `set_time`, a CIGI Celestial Sphere Control with the ephemeris on (the clock
   runs into year 10000 a minute later, so this case watches for 65 s), a FlightGear pose
   while the clock follows FlightGear;
2. `zenoh_tick`: a copy of the master's clock tick with master_mono_s = 1e12, to the channel;
3. `zenoh_state`: the master's state with its id, sequence 2**63-1 and an 8/8 cumulonimbus;
   then the master's weather changes and the channel must show the master's sky (sky_id);
4. `health_flood`: 100,000 `health/<name>` messages to the master: its status must answer
   and list at most MAX_PEERS_SEEN peers; then the channel SIGKILLed must leave them;
5. `conditions_requests`: one 64 KB CIGI datagram of 2,046 Environmental Conditions Requests
   (no frame gap over 3 frames), then a 60 Hz host asking 20 a frame (frame rate >= 0.9x,
   status's fps within 30 % of the segment's);
6. `regions_flood`: 20,000 CIGI environmental regions with a layer each, then a normal host
   (frame rate >= 0.8x, status's fps true);
7. `shm_truncate`: `os.truncate('/dev/shm/<name>', 0)` from this process.

The Zenoh cases publish from a session of their own with no credentials (a stranger), which
listens on a loopback port as well as connecting to the master: Zenoh's peers gossip their
locators, so a channel (listening on nothing) connects to the stranger and takes what it
publishes, as it would on a real network.

Everything is bounded in count and time; the Zenoh cases need eclipse-zenoh and skip without.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import re
import shutil
import signal
import socket
import statistics
import struct
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wxsky.errors import WxskyError
from wxsky.host.client import ControlClient
from wxsky.output.shm import HDR_LATEST_FRAME, MAGIC
from wxsky.output.wire import pack_data, unpack_data
from wxsky.protocols.cigi import Packet, encode_datagram, make

SITE = "default"
START_TIMEOUT_S = 120.0  # a daemon's first frame on a busy 2-core machine; only catches hangs
JOIN_TIMEOUT_S = 60.0
STATUS_TIMEOUT_S = 5.0
AFTER_S = 3.0  # frames must advance over this long after an attack
OBSERVER = (47.4647, 8.5492)  # the default site (Zurich): regions and requests near the camera
SMALL = (160, 90)
FG_POSE_LINE = re.compile(r"FlightGear pose stream on udp:([0-9.]+):(\d+)")
UDP_MAX = 65_507
MAX_PEERS_SEEN = 1000  # the health flood's check: a master listing more kept the strangers


# --- the daemons an attack aims at -----------------------------------------------------------


def latest_frame(shm_name: str) -> int | None:
    """A segment's latest frame number, by pread: never a mapping, which faults (SIGBUS) the
    process reading it once another process truncates the segment."""
    try:
        fd = os.open(f"/dev/shm/{shm_name}", os.O_RDONLY)
    except OSError:
        return None
    try:
        head = os.pread(fd, HDR_LATEST_FRAME + 8, 0)
    except OSError:
        return None
    finally:
        os.close(fd)
    if len(head) < HDR_LATEST_FRAME + 8 or head[: len(MAGIC)] != MAGIC:
        return None
    return int.from_bytes(head[HDR_LATEST_FRAME:], "little")


@dataclass
class Daemon:
    """A running `wxsky run` (started here or by the soak): its process and where it is."""

    name: str
    proc: subprocess.Popen[bytes]
    sock: Path
    shm_name: str
    log_path: Path
    # Ports once read: an attack can leave status unable to answer (the health flood), and
    # the cases after it still know where to send.
    ports: dict[str, int] = field(default_factory=dict)

    @property
    def address(self) -> str:
        return f"unix:{self.sock}"

    def alive(self) -> bool:
        return self.proc.poll() is None

    def exit_text(self) -> str:
        code = self.proc.poll()
        if code is None:
            return "running"
        if code < 0:
            with contextlib.suppress(ValueError):
                return f"killed by {signal.Signals(-code).name}"
        return f"exit status {code}"

    def status(self, timeout_s: float = STATUS_TIMEOUT_S) -> dict[str, Any] | None:
        """Its status, or None when it does not answer within `timeout_s`."""
        try:
            with ControlClient.connect(self.address, timeout_s=timeout_s) as client:
                result: dict[str, Any] = client.call("status", timeout_s=timeout_s)
                return result
        except (WxskyError, OSError, ValueError):
            return None

    def call(self, method: str, params: dict[str, Any], timeout_s: float = STATUS_TIMEOUT_S) -> Any:
        with ControlClient.connect(self.address, timeout_s=timeout_s) as client:
            return client.call(method, params, timeout_s=timeout_s)

    def frame(self) -> int | None:
        return latest_frame(self.shm_name)

    def log_tail(self, lines: int = 3) -> str:
        with contextlib.suppress(OSError):
            text = self.log_path.read_text(errors="replace").splitlines()
            return " | ".join(line[9:200] for line in text[-lines:])
        return ""

    def log_text(self) -> str:
        with contextlib.suppress(OSError):
            return self.log_path.read_text(errors="replace")
        return ""

    def rss_kib(self) -> int | None:
        with contextlib.suppress(OSError, ValueError), open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
        return None

    def cigi_port(self) -> int | None:
        if "cigi" not in self.ports:
            s = self.status()
            for i in (s or {}).get("inputs", []):
                if i.get("kind") == "cigi" and i.get("listen"):
                    self.ports["cigi"] = int(str(i["listen"]).rsplit(":", 1)[1])
        return self.ports.get("cigi")

    def pose_port(self) -> int | None:
        """The FlightGear pose port (status does not say it; the daemon's log does)."""
        if "pose" not in self.ports:
            m = FG_POSE_LINE.search(self.log_text())
            if m:
                self.ports["pose"] = int(m.group(2))
        return self.ports.get("pose")

    def stop(self) -> None:
        if self.alive():
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=15.0)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=15.0)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(f"/dev/shm/{self.shm_name}")
        with contextlib.suppress(FileNotFoundError):
            self.sock.unlink()


def master_config(shm_name: str, size: tuple[int, int] = SMALL) -> str:
    """A master's config: a CIGI IG port and a FlightGear pose port (its clock following
    FlightGear's), both on an ephemeral loopback port."""
    w, h = size
    return f"""
[daemon]
status_interval_s = 1.0
[camera]
width = {w}
height = {h}
[scene]
ring_texture_px = 64
[output]
shm_name = "{shm_name}"
max_width = {w}
max_height = {h}
[cigi]
listen = ["udp:127.0.0.1:0"]
[flightgear]
pose = "udp:127.0.0.1:0"
clock = "flightgear"
"""


def channel_config(shm_name: str, size: tuple[int, int] = SMALL) -> str:
    w, h = size
    return f"""
[daemon]
status_interval_s = 1.0
[camera]
width = {w}
height = {h}
[scene]
ring_texture_px = 64
[output]
shm_name = "{shm_name}"
max_width = {w}
max_height = {h}
"""


def start_daemon(folder: Path, name: str, config: str, args: tuple[str, ...] = ()) -> Daemon:
    """`wxsky run` in `folder` with `config`; returns at once (see `wait_started`)."""
    folder.mkdir(parents=True, exist_ok=True)
    shm = re.search(r'shm_name = "([^"]+)"', config)
    assert shm is not None
    cfg = folder / "wxsky.toml"
    cfg.write_text(config)
    sock = folder / "wx.sock"
    log_path = folder / "daemon.log"
    cmd = [sys.executable, "-m", "wxsky", "run", "--config", str(cfg)]
    cmd += ["--control", f"unix:{sock}", *args]
    with open(log_path, "wb") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    return Daemon(name, proc, sock, shm.group(1), log_path)


def wait_started(d: Daemon, timeout_s: float = START_TIMEOUT_S) -> None:
    """Until `d` has published a frame; AttackError when it exits or hangs first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not d.alive():
            raise AttackError(f"{d.name} exited at start ({d.exit_text()}): {d.log_tail()}")
        s = d.status(timeout_s=1.0) if d.sock.exists() else None
        if s is not None and s.get("frames_published", 0) > 0:
            return
        time.sleep(0.2)
    raise AttackError(f"{d.name} did not start within {timeout_s:.0f} s: {d.log_tail()}")


class AttackError(Exception):
    """The harness could not set up a case (a daemon did not start): not the attack's result."""


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@dataclass
class Target:
    """What an attack aims at: the master, and a channel joined to it where one runs.
    `respawn_channel` starts the channel again (after an attack killed it), where the owner
    can; `endpoint` is the master's Zenoh locator, empty when it shares nothing.
    `weather_is_ours`: an attack may change the master's weather to see a channel follow
    (False in the soak, whose presets change it every cycle and whose checks would count an
    attack's preset as theirs)."""

    master: Daemon
    channel: Daemon | None = None
    endpoint: str = ""
    site: str = SITE
    respawn_channel: Callable[[], Daemon] | None = None
    weather_is_ours: bool = True


class Dome:
    """A master (CIGI, FlightGear pose, Zenoh bus on a free loopback port when `share`) and
    optionally one display channel, in `folder`: the target of one case."""

    def __init__(self, folder: Path, *, share: bool, channel: bool) -> None:
        self.folder = folder
        self.share = share or channel
        self.endpoint = f"tcp/127.0.0.1:{free_tcp_port()}" if self.share else ""
        self.with_channel = channel
        self.target: Target | None = None
        self._daemons: list[Daemon] = []

    def __enter__(self) -> Target:
        tag = uuid.uuid4().hex[:8]
        args = ("--share", f"zenoh:{self.endpoint}") if self.share else ()
        master = start_daemon(
            self.folder / "master", "master", master_config(f"wxsky-attack-{tag}"), args
        )
        self._daemons.append(master)
        self.target = Target(master, endpoint=self.endpoint)
        if self.with_channel:
            self.target.channel = self._channel()
            self.target.respawn_channel = self._channel
        try:
            wait_started(master)
            master.cigi_port()  # read while status answers: the ports are kept
            master.pose_port()
            if self.target.channel is not None:
                wait_channel(self.target.channel)
        except BaseException:
            self.__exit__()
            raise
        return self.target

    def _channel(self) -> Daemon:
        tag = uuid.uuid4().hex[:8]
        args = ("--join", f"zenoh:{self.endpoint}", "--channel", "left")
        d = start_daemon(
            self.folder / f"channel-{tag}", "channel", channel_config(f"wxsky-attack-{tag}"), args
        )
        self._daemons.append(d)
        return d

    def __exit__(self, *exc: object) -> None:
        for d in reversed(self._daemons):
            d.stop()


def wait_channel(d: Daemon, timeout_s: float = START_TIMEOUT_S) -> None:
    """Until the channel publishes frames and sees the master alive."""
    wait_started(d, timeout_s)
    deadline = time.monotonic() + JOIN_TIMEOUT_S
    while time.monotonic() < deadline:
        s = d.status(timeout_s=1.0)
        if s is not None and s.get("channel", {}).get("master_alive"):
            return
        if not d.alive():
            break
        time.sleep(0.2)
    raise AttackError(f"the channel did not join: {d.log_tail()}")


# --- what an attack saw -----------------------------------------------------------------------


@dataclass
class AttackResult:
    name: str
    aimed_at: str  # "master" or "channel"
    alive: bool = False  # the aimed-at daemon's pid still running after the attack
    frames_before: int | None = None
    frames_after: int | None = None  # the segment's, AFTER_S after the attack
    advancing: bool = False  # frames_after > the frame when the attack ended
    status_ok: bool = False  # status answered after the attack
    checks: dict[str, bool] = field(default_factory=dict)  # the case's own, each must hold
    counters: dict[str, Any] = field(default_factory=dict)  # read from status, and sent
    what: str = ""  # one line: what happened
    seconds: float = 0.0
    skipped: str = ""  # why the case did not run (no zenoh); not a pass

    @property
    def survived(self) -> bool:
        return (
            not self.skipped
            and self.alive
            and self.advancing
            and self.status_ok
            and all(self.checks.values())
        )

    def line(self) -> str:
        if self.skipped:
            return f"{self.name:22s} skipped: {self.skipped}"
        checks = ", ".join(f"{k} {'ok' if v else 'FAILED'}" for k, v in self.checks.items())
        counters = json.dumps(self.counters, separators=(",", ":"), default=str)
        return (
            f"{self.name:22s} survived {'yes' if self.survived else 'no '}  "
            f"{self.aimed_at} alive {'yes' if self.alive else 'no'}, frames "
            f"{self.frames_before} -> {self.frames_after}, status "
            f"{'ok' if self.status_ok else 'silent'}"
            + (f"; {checks}" if checks else "")
            + f"; {self.what}; counters {counters}"
        )

    def as_dict(self) -> dict[str, Any]:
        return {k: v for k, v in vars(self).items()} | {"survived": self.survived}


class FrameWatch:
    """The segment's frame number sampled every 20 ms on a thread: largest gap and rate."""

    def __init__(self, d: Daemon) -> None:
        self.d = d
        self.samples: list[tuple[float, int]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="frame-watch", daemon=True)

    def __enter__(self) -> FrameWatch:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def _run(self) -> None:
        while not self._stop.wait(0.02):
            n = self.d.frame()
            if n is not None:
                self.samples.append((time.monotonic(), n))

    def largest_gap_s(self) -> float | None:
        """The longest the frame number stood still: between two samples that moved it, and
        from the first sample and to the last one (a stall through the whole watch counts
        as its length, a lower bound). None before two samples."""
        s = self.samples
        if len(s) < 2:
            return None
        moved = [b[0] for a, b in itertools.pairwise(s) if a[1] != b[1]]
        marks = [s[0][0], *moved, s[-1][0]]
        return max(b - a for a, b in itertools.pairwise(marks))

    def fps(self, start: float, end: float) -> float | None:
        window = [(t, n) for t, n in self.samples if start <= t <= end]
        if len(window) < 2 or window[-1][0] <= window[0][0]:
            return None
        return (window[-1][1] - window[0][1]) / (window[-1][0] - window[0][0])


def _fps_for(d: Daemon, seconds: float) -> float | None:
    return _undisturbed(d, seconds)[0]


def _undisturbed(d: Daemon, seconds: float) -> tuple[float | None, float | None]:
    """The frame rate and the largest frame gap over `seconds` before an attack: what the
    machine does without it (llvmpipe beside other work has gaps of its own)."""
    with FrameWatch(d) as w:
        time.sleep(seconds)
    return w.fps(0.0, float("inf")), w.largest_gap_s()


def observe(
    result: AttackResult, d: Daemon, ended_frame: int | None, after_s: float = AFTER_S
) -> dict[str, Any] | None:
    """Fill in alive, frames after, advancing and status_ok; returns the status read."""
    deadline = time.monotonic() + after_s
    while time.monotonic() < deadline and d.alive():
        time.sleep(0.1)
    result.alive = d.alive()
    result.frames_after = d.frame() if result.alive else None
    base = ended_frame if ended_frame is not None else result.frames_before
    result.advancing = (
        result.alive
        and result.frames_after is not None
        and (base is None or result.frames_after > base)
    )
    status = d.status() if result.alive else None
    result.status_ok = status is not None
    if not result.alive:
        result.what = f"{d.name} {d.exit_text()}; log: {_last_error(d)}"
    return status


def _last_error(d: Daemon) -> str:
    lines = [ln for ln in d.log_text().splitlines() if " ERROR " in ln or "rror:" in ln]
    return re.sub(r"^\d\d:\d\d:\d\d ", "", lines[-1])[:200] if lines else "(no error line)"


def _input(status: dict[str, Any] | None, kind: str) -> dict[str, Any]:
    for i in (status or {}).get("inputs", []):
        if i.get("kind") == kind:
            return dict(i)
    return {}


# --- 1. year 9999 -------------------------------------------------------------------------------

END_OF_9999 = "9999-12-31T23:59:58Z"


def year9999_control(t: Target) -> AttackResult:
    """control set_time to 9999-12-31T23:59:58Z (the sun's smoothing looks 2 s ahead)."""
    d = t.master
    r = AttackResult("year9999_control", "master", frames_before=d.frame())
    try:
        d.call("set_time", {"time_utc": END_OF_9999})
        r.counters["set_time"] = "accepted"
    except (WxskyError, OSError) as exc:
        r.counters["set_time"] = f"refused: {str(exc)[:120]}"
    status = observe(r, d, d.frame())
    if status is not None:
        r.counters["time_utc"] = status.get("weather", {}).get("time_utc")
        r.what = f"clock at {r.counters['time_utc']}"
    return r


def year9999_cigi(t: Target, watch_s: float = 65.0) -> AttackResult:
    """CIGI Celestial Sphere Control at 9999-12-31 23:59, ephemeris on.

    The daemon's clock runs into year 10000 within the minute, so the case watches `watch_s`."""
    d = t.master
    r = AttackResult("year9999_cigi", "master", frames_before=d.frame())
    port = d.cigi_port()
    if port is None:
        r.skipped = "the daemon has no CIGI port"
        return r
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(encode_datagram([_ig_control(1)]) + celestial_9999(), ("127.0.0.1", port))
    r.counters["datagrams"] = 1
    status = observe(r, d, d.frame(), after_s=watch_s)
    if status is not None:
        r.counters["time_utc"] = status.get("weather", {}).get("time_utc")
        cigi = _input(status, "cigi")
        r.counters["cigi_dropped"] = cigi.get("dropped")
        r.what = f"clock at {r.counters['time_utc']} after {watch_s:.0f} s"
    return r


def celestial_9999() -> bytes:
    """A Celestial Sphere Control (opcode 9, 16 bytes, big-endian) at 23:59 on 12/31/9999,
    ephemeris, sun and moon on, date valid: packed here, not by wxsky's encoder, which (as it
    should) may refuse a date outside the clock's years; a hostile host has no such scruple."""
    flags = 0b1_0111  # bit 0 ephemeris, 1 sun, 2 moon, 4 date/time valid
    return struct.pack(">BBBBB3xIf", 9, 16, 23, 59, flags, 12_31_9999, 0.0)


def year9999_flightgear(t: Target) -> AttackResult:
    """A FlightGear pose with gmt 9999-12-31T23:59:58 while the clock follows FlightGear."""
    d = t.master
    r = AttackResult("year9999_flightgear", "master", frames_before=d.frame())
    port = d.pose_port()
    if port is None:
        r.skipped = "the daemon has no FlightGear pose port"
        return r
    lat, lon = OBSERVER
    line = f"{lat},{lon},3000,90,0,0,0,0,60,1400,{lat},{lon},3000,1,9999-12-31T23:59:58\n"
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for _ in range(5):  # a few frames of it, as FlightGear streams
            s.sendto(line.encode(), ("127.0.0.1", port))
            time.sleep(0.05)
    r.counters["poses"] = 5
    status = observe(r, d, d.frame())
    if status is not None:
        r.counters["time_utc"] = status.get("weather", {}).get("time_utc")
        fg = _input(status, "flightgear")
        r.counters["pose_errors"] = fg.get("errors")
        r.what = f"clock at {r.counters['time_utc']}"
    return r


# --- 2.-4. the Zenoh bus -------------------------------------------------------------------------


def _zenoh() -> Any:
    try:
        import zenoh
    except ImportError:
        return None
    return zenoh


@contextlib.contextmanager
def stranger(endpoint: str, peers: int = 1, wait_s: float = 10.0) -> Iterator[Any]:
    """A Zenoh session of our own connected to the master's endpoint: a peer with no
    credentials, as anyone on the network could open. It listens on a loopback port too:
    Zenoh's peers gossip their locators, so the channels (which listen on nothing) connect
    to it directly, and what it publishes reaches them without the master forwarding it.
    Waits up to `wait_s` until `peers` sessions are connected to it."""
    zenoh = _zenoh()
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps("peer"))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{free_tcp_port()}"]))
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    session = zenoh.open(cfg)
    try:
        deadline = time.monotonic() + wait_s
        while len(list(session.info.peers_zid())) < peers and time.monotonic() < deadline:
            time.sleep(0.1)
        yield session
    finally:
        session.close()


def _capture(session: Any, key: str, timeout_s: float = 10.0) -> dict[str, Any] | None:
    """The next message published on `key`, unpacked; None when none comes."""
    got: list[bytes] = []
    ready = threading.Event()

    def deliver(sample: Any) -> None:
        if not got:
            got.append(sample.payload.to_bytes())
            ready.set()

    sub = session.declare_subscriber(key, deliver)
    try:
        ready.wait(timeout_s)
    finally:
        sub.undeclare()
    if not got:
        return None
    value = unpack_data(got[0])
    return value if isinstance(value, dict) else None


def _zenoh_case(name: str, aimed_at: str, t: Target) -> AttackResult | None:
    """A result marked skipped when this case cannot run here, else None."""
    r = AttackResult(name, aimed_at)
    if _zenoh() is None:
        r.skipped = "eclipse-zenoh is not installed"
    elif not t.endpoint:
        r.skipped = "the master shares nothing (no --share)"
    elif aimed_at == "channel" and t.channel is None:
        r.skipped = "no channel joined"
    return r if r.skipped else None


def zenoh_tick(t: Target) -> AttackResult:
    """A copy of the master's Zenoh clock tick with master_mono_s = 1e12.

    Published by a stranger's session (no credentials) to the master's endpoint."""
    skipped = _zenoh_case("zenoh_tick", "channel", t)
    if skipped is not None:
        return skipped
    assert t.channel is not None
    d = t.channel
    r = AttackResult("zenoh_tick", "channel", frames_before=d.frame())
    key = f"wxsky/{t.site}/clock"
    with stranger(t.endpoint, peers=2) as session:
        r.counters["peers_connected"] = len(list(session.info.peers_zid()))
        tick = _capture(session, key)
        if tick is None:
            r.what = "no real tick seen to copy"
            r.checks["tick_seen"] = False
            return r
        tick["master_mono_s"] = 1e12
        for _ in range(5):
            session.put(key, pack_data(tick))
            time.sleep(0.02)
    r.counters["forged_ticks"] = 5
    status = observe(r, d, d.frame())
    if status is not None:
        ch = status.get("channel", {})
        r.counters["dropped"] = ch.get("dropped")
        r.counters["lag_ms"] = ch.get("lag_ms")
        r.what = f"master_alive {ch.get('master_alive')}"
    return r


def zenoh_state(t: Target, follow_s: float = 20.0) -> AttackResult:
    """A forged Zenoh state: the master's id, sequence 2**63-1, an 8/8 cumulonimbus.

    Then the master's weather changes, and the channel must show the master's sky (the same
    sky_id) within `follow_s`."""
    skipped = _zenoh_case("zenoh_state", "channel", t)
    if skipped is not None:
        return skipped
    assert t.channel is not None
    d = t.channel
    r = AttackResult("zenoh_state", "channel", frames_before=d.frame())
    key = f"wxsky/{t.site}/state"
    with stranger(t.endpoint, peers=2) as session:
        r.counters["peers_connected"] = len(list(session.info.peers_zid()))
        state = _capture(session, key)  # the master repeats its state every second
        if state is None:
            r.what = "no real state seen to copy"
            r.checks["state_seen"] = False
            return r
        cb = {"cover_oktas": 8, "base_m": 600.0, "top_m": 11000.0, "type": "cumulonimbus"}
        state["sequence"] = 2**63 - 1
        for part in ("applied", "target"):
            if isinstance(state.get(part), dict):
                state[part]["layers"] = [dict(cb)]
        state["anchor_drift"] = [[0.0, 0.0]]
        if "tower_epochs" in state:
            state["tower_epochs"] = [None]
        session.put(key, pack_data(state))
    r.counters["forged_states"] = 1
    time.sleep(1.0)
    shown = d.status()
    r.counters["layers_after_forgery"] = _layers(shown)
    # The real master changes its weather (or its owner does): its next state must reach
    # the channel.
    if t.weather_is_ours:
        with contextlib.suppress(WxskyError, OSError):
            t.master.call("apply_preset", {"name": "overcast-stratus"})
    followed = False
    deadline = time.monotonic() + follow_s
    master_sky = channel_sky = None
    while time.monotonic() < deadline and d.alive() and t.master.alive():
        ms, cs = t.master.status(), d.status()
        master_sky = (ms or {}).get("sky_id")
        channel_sky = (cs or {}).get("sky_id")
        if master_sky is not None and master_sky == channel_sky:
            followed = True
            break
        time.sleep(0.5)
    r.checks["follows_master"] = followed
    status = observe(r, d, d.frame())
    if status is not None:
        ch = status.get("channel", {})
        r.counters["dropped"] = ch.get("dropped")
        r.counters["master_alive"] = ch.get("master_alive")
        r.counters["layers"] = _layers(status)
        if followed:
            r.what = f"channel follows the master's sky {master_sky}"
        elif master_sky is None:
            r.what = f"the master's status did not answer in {follow_s:.0f} s"
        else:
            r.what = (
                f"channel sky {channel_sky} vs master {master_sky} after {follow_s:.0f} s: "
                "frozen on the forged state"
            )
    if t.weather_is_ours:
        with contextlib.suppress(WxskyError, OSError):
            t.master.call("release", {})
    return r


def _layers(status: dict[str, Any] | None) -> str:
    layers = (status or {}).get("weather", {}).get("layers", [])
    return " ".join(f"{x.get('type')}:{x.get('cover_oktas')}/8" for x in layers) or "none"


def health_flood(t: Target, count: int = 100_000, forget_s: float = 15.0) -> AttackResult:
    """100,000 Zenoh health/<name> messages to the master; a channel SIGKILLed.

    `count` messages, each a new name; then status must answer and list at most
    MAX_PEERS_SEEN peers, and the joined channel, killed with SIGKILL, must leave the master's
    peers within `forget_s`."""
    skipped = _zenoh_case("health_flood", "master", t)
    if skipped is not None:
        return skipped
    d = t.master
    r = AttackResult("health_flood", "master", frames_before=d.frame())
    rss_before = d.rss_kib()
    with stranger(t.endpoint) as session:
        real = _capture(session, f"wxsky/{t.site}/health/*", timeout_s=5.0)
        message = real or {
            "v": 1,
            "kind": "health",
            "site": t.site,
            "role": "channel",
            "fps": 30.0,
            "lag_ms": 1.0,
            "frames": 1,
        }
        message["role"] = "channel"
        start = time.monotonic()
        for i in range(count):
            name = f"x{i:06d}"
            message["name"] = name
            session.put(f"wxsky/{t.site}/health/{name}", pack_data(message))
        r.counters["sent"] = count
        r.counters["send_s"] = round(time.monotonic() - start, 2)
    time.sleep(2.0)  # the master's Zenoh threads deliver what is queued
    status = d.status(timeout_s=10.0)
    r.checks["status_answers"] = status is not None
    if status is not None:
        peers = status.get("channel", {}).get("peers", {})
        r.counters["peers"] = len(peers)
        r.counters["status_bytes"] = len(pack_data(status))
        # Bounded: no dome has this many channels, whatever bound the daemon sets.
        r.checks["peers_bounded"] = len(peers) <= MAX_PEERS_SEEN
    rss_after = d.rss_kib()
    if rss_before and rss_after:
        r.counters["rss_growth_mib"] = round((rss_after - rss_before) / 1024, 1)
    if t.channel is not None and t.channel.alive():
        with contextlib.suppress(ProcessLookupError):
            os.killpg(t.channel.proc.pid, signal.SIGKILL)
        t.channel.proc.wait(timeout=10.0)
        forgotten = False
        deadline = time.monotonic() + forget_s
        while time.monotonic() < deadline and d.alive():
            s = d.status()
            if s is not None and "left" not in s.get("channel", {}).get("peers", {}):
                forgotten = True
                break
            time.sleep(0.5)
        r.checks["killed_channel_forgotten"] = forgotten
        if t.respawn_channel is not None:  # for the cases after this one
            with contextlib.suppress(AttackError):
                t.channel = t.respawn_channel()
                wait_channel(t.channel)
    status = observe(r, d, d.frame())
    if not r.what:
        r.what = (
            f"{r.counters.get('peers')} peers listed, status {r.counters.get('status_bytes')} B"
        )
    return r


# --- 5.-6. CIGI work per datagram ---------------------------------------------------------------


def _ig_control(frame: int) -> Packet:
    return make("ig_control", ig_mode=1, host_frame_number=frame & 0xFFFF_FFFF)


def _in_cloud_alt_m(d: Daemon) -> float:
    """Mid-height of the daemon's lowest cloud layer (2,000 m without one): a request there
    costs the most, the clouds' sprites looked up around the point."""
    layers = ((d.status() or {}).get("weather") or {}).get("layers") or []
    if not layers:
        return 2000.0
    return 0.5 * (float(layers[0]["base_m"]) + float(layers[0]["top_m"]))


def _request(i: int, alt_m: float, spread: int = 45) -> Packet:
    """Request `i`: a point in a `spread` x `spread` grid of 4 km cloud blocks around the
    site, each request another block (AI aircraft all around the ownship)."""
    lat, lon = OBSERVER
    k = i % (spread * spread)
    return make(
        "environmental_conditions_request",
        request_weather=1,
        request_aerosol=1,
        request_id=i % 256,
        lat_deg=lat + (k // spread - spread // 2) * 0.036,  # ~4 km
        lon_deg=lon + (k % spread - spread // 2) * 0.053,
        alt_m=alt_m,
    )


def conditions_requests(t: Target, host_s: float = 5.0) -> AttackResult:
    """A 64 KB CIGI datagram of 2,046 Conditions Requests; a 60 Hz host asking 20 a frame.

    The host runs `host_s`. Checks: no frame gap over 3 frame times for the datagram, and the
    frame rate under the host at least 0.9x of before."""
    d = t.master
    r = AttackResult("conditions_requests", "master", frames_before=d.frame())
    port = d.cigi_port()
    if port is None:
        r.skipped = "the daemon has no CIGI port"
        return r
    alt_m = _in_cloud_alt_m(d)
    r.counters["request_alt_m"] = alt_m
    fps_before, gap_before = _undisturbed(d, 4.0)
    big = encode_datagram([_ig_control(1), *(_request(i, alt_m) for i in range(2046))])
    assert len(big) <= UDP_MAX
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.setblocking(False)
        with FrameWatch(d) as watch:
            s.sendto(big, ("127.0.0.1", port))
            time.sleep(8.0)  # the issue saw 3.3 s stalls; a longer one shows its length
            _drain(s)
        gap = watch.largest_gap_s()
        frame_s = 1.0 / fps_before if fps_before else None
        r.counters["fps_before"] = _round(fps_before)
        r.counters["largest_gap_s"] = _round(gap)
        r.counters["largest_gap_before_s"] = _round(gap_before)
        if frame_s is not None and gap is not None:
            # Over 3 frames, and over the gaps the machine had without the datagram (a
            # shared 2-core machine has some): the datagram's doing. 20 ms: sampling.
            allowed = max(3 * frame_s, gap_before or 0.0) + 0.02
            r.checks["datagram_gap_le_3_frames"] = gap <= allowed
        # A 60 Hz host, 20 requests a frame.
        frame = 2
        with FrameWatch(d) as watch:
            start = time.monotonic()
            next_t = start
            while time.monotonic() - start < host_s and d.alive():
                # 20 AI aircraft, the same each frame (their blocks are made once).
                packets = [_ig_control(frame), *(_request(i * 97, alt_m) for i in range(20))]
                with contextlib.suppress(BlockingIOError):
                    s.sendto(encode_datagram(packets), ("127.0.0.1", port))
                _drain(s)
                frame += 1
                next_t += 1 / 60
                time.sleep(max(0.0, next_t - time.monotonic()))
        fps_host = watch.fps(start + 1.0, float("inf"))
        _status_fps_check(r, d, watch)
        r.counters["fps_under_host"] = _round(fps_host)
        if fps_before and fps_host is not None:
            r.checks["fps_ratio_ge_0.9"] = fps_host >= 0.9 * fps_before
    status = observe(r, d, d.frame())
    if status is not None:
        cigi = _input(status, "cigi")
        r.counters["status_fps"] = _round(status.get("fps"))
        r.counters["responses_sent"] = cigi.get("responses_sent")
        r.counters["dropped"] = cigi.get("dropped")
        r.what = f"fps {r.counters['fps_before']} -> {r.counters['fps_under_host']}"
    return r


def regions_flood(t: Target, regions: int = 20_000, host_s: float = 5.0) -> AttackResult:
    """20,000 CIGI environmental regions with a layer each; then a normal 60 Hz host.

    `regions` distinct ids; the host (IG Control and its ownship) runs `host_s`. Check: the
    frame rate under the host at least 0.8x of before the flood."""
    d = t.master
    r = AttackResult("regions_flood", "master", frames_before=d.frame())
    port = d.cigi_port()
    if port is None:
        r.skipped = "the daemon has no CIGI port"
        return r
    fps_before = _fps_for(d, 2.0)
    lat, lon = OBSERVER
    per_datagram = (UDP_MAX - 24) // (48 + 56)
    sent = 0
    frame = 1
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.setblocking(False)
        while sent < regions and d.alive():
            packets: list[Packet] = [_ig_control(frame)]
            for rid in range(sent, min(regions, sent + per_datagram)):
                packets.append(
                    make(
                        "environmental_region_control",
                        region_id=rid + 1,
                        region_state=1,
                        lat_deg=lat + (rid % 200) * 0.01,
                        lon_deg=lon + (rid // 200) * 0.01,
                        size_x_m=2000.0,
                        size_y_m=2000.0,
                    )
                )
                packets.append(
                    make(
                        "weather_control",
                        entity_or_region_id=rid + 1,
                        layer_id=1,
                        weather_enable=1,
                        cloud_type=7,
                        scope=1,
                        coverage_pct=50.0,
                        base_elevation_m=1500.0,
                        thickness_m=800.0,
                    )
                )
            try:
                s.sendto(encode_datagram(packets), ("127.0.0.1", port))
            except BlockingIOError:
                time.sleep(0.05)
                continue
            sent = min(regions, sent + per_datagram)
            frame += 1
            time.sleep(0.02)  # the socket's buffer is not the thing under test
            _drain(s)
        r.counters["regions_sent"] = sent
        with FrameWatch(d) as watch:
            start = time.monotonic()
            next_t = start
            while time.monotonic() - start < host_s and d.alive():
                packets = [_ig_control(frame), _ownship(frame)]
                with contextlib.suppress(BlockingIOError):
                    s.sendto(encode_datagram(packets), ("127.0.0.1", port))
                _drain(s)
                frame += 1
                next_t += 1 / 60
                time.sleep(max(0.0, next_t - time.monotonic()))
        fps_host = watch.fps(start + 1.0, float("inf"))
        _status_fps_check(r, d, watch)
    r.counters["fps_before"] = _round(fps_before)
    r.counters["fps_under_host"] = _round(fps_host)
    if fps_before and fps_host is not None:
        r.checks["fps_ratio_ge_0.8"] = fps_host >= 0.8 * fps_before
    status = observe(r, d, d.frame())
    if status is not None:
        cigi = _input(status, "cigi")
        r.counters["regions_kept"] = cigi.get("regions")
        r.counters["layers_kept"] = cigi.get("layers")
        r.counters["dropped"] = cigi.get("dropped")
        r.counters["cigi_ok"] = cigi.get("ok")
        r.what = (
            f"{cigi.get('regions')} regions kept, fps {r.counters['fps_before']} -> "
            f"{r.counters['fps_under_host']}"
        )
    return r


def _status_fps_check(r: AttackResult, d: Daemon, watch: FrameWatch) -> None:
    """Right after a host's run: status's fps against the segment's over the run's last 2 s
    (within 30 %, or 3 fps at low rates). A status that does not answer is not truthful."""
    end = watch.samples[-1][0] if watch.samples else time.monotonic()
    measured = watch.fps(end - 2.0, end)
    status = d.status(timeout_s=3.0) if d.alive() else None
    said = None if status is None else status.get("fps")
    r.counters["status_fps_during"] = _round(said)
    r.counters["segment_fps_during"] = _round(measured)
    if measured is not None and d.alive():
        r.checks["status_fps_truthful"] = said is not None and abs(float(said) - measured) <= max(
            3.0, 0.3 * measured
        )


def _ownship(frame: int) -> Packet:
    """The ownship flying east at 100 m/s, one 60 Hz frame at a time."""
    lat, lon = OBSERVER
    return make(
        "entity_control",
        entity_id=0,
        entity_state=1,
        lat_deg=lat,
        lon_deg=lon + frame * (100.0 / 60.0) / 75_000.0,
        alt_m=1000.0,
        yaw_deg=90.0,
    )


def _drain(s: socket.socket) -> None:
    """Read and drop what the IG answered (Start of Frame, responses)."""
    for _ in range(10_000):
        try:
            s.recv(UDP_MAX)
        except (BlockingIOError, OSError):
            return


def _round(x: float | None) -> float | None:
    return None if x is None else round(x, 3)


# --- 7. the segment ------------------------------------------------------------------------------


def shm_truncate(t: Target) -> AttackResult:
    """`os.truncate('/dev/shm/<name>', 0)` from this process (the same user)."""
    d = t.master
    r = AttackResult("shm_truncate", "master", frames_before=d.frame())
    lines_before = len(d.log_text().splitlines())
    try:
        os.truncate(f"/dev/shm/{d.shm_name}", 0)
        r.counters["truncated"] = True
    except OSError as exc:
        r.counters["truncated"] = f"no: {exc}"
    status = observe(r, d, None, after_s=AFTER_S)
    new_lines = d.log_text().splitlines()[lines_before:]
    r.counters["log_lines_after"] = len(new_lines)
    if not r.alive:
        r.checks["logged_its_end"] = any(" ERROR " in ln or "CRITICAL" in ln for ln in new_lines)
        r.counters["socket_left"] = d.sock.exists()
    elif status is not None:
        r.what = f"frames {r.frames_before} -> {r.frames_after}"
    return r


# --- the cases ---------------------------------------------------------------------------------

Attack = Callable[[Target], AttackResult]
# name -> (attack, needs a channel, needs the bus)
ATTACKS: dict[str, tuple[Attack, bool, bool]] = {
    "year9999_control": (year9999_control, False, False),
    "year9999_cigi": (year9999_cigi, False, False),
    "year9999_flightgear": (year9999_flightgear, False, False),
    "zenoh_tick": (zenoh_tick, True, True),
    "zenoh_state": (zenoh_state, True, True),
    "health_flood": (health_flood, True, True),
    "conditions_requests": (conditions_requests, False, False),
    "regions_flood": (regions_flood, False, False),
    "shm_truncate": (shm_truncate, False, False),
}


def run_attack(name: str, t: Target) -> AttackResult:
    """One attack against running daemons; whatever goes wrong in the harness is the
    result's `what`, never an exception (a daemon that died mid-attack breaks sockets)."""
    fn, needs_channel, _ = ATTACKS[name]
    aimed = t.channel if needs_channel and t.channel is not None else t.master
    if not aimed.alive():  # an attack before killed it and it could not be started again
        r = AttackResult(name, aimed.name)
        r.what = f"{aimed.name} dead before the attack ({aimed.exit_text()})"
        r.checks["alive_before"] = False
        return r
    start = time.monotonic()
    try:
        r = fn(t)
    except Exception as exc:  # the harness's own failure, reported with the daemon's state
        r = AttackResult(name, aimed.name)
        r.what = f"harness: {type(exc).__name__}: {str(exc)[:160]}"
        observe(r, aimed, None, after_s=0.5)
        r.checks["harness_ran"] = False
    r.seconds = round(time.monotonic() - start, 1)
    return r


def run_case(name: str, folder: Path) -> AttackResult:
    """One attack against fresh daemons of its own in `folder`, stopped after."""
    _, needs_channel, needs_bus = ATTACKS[name]
    if needs_bus and _zenoh() is None:
        return AttackResult(name, "channel", skipped="eclipse-zenoh is not installed")
    try:
        with Dome(folder / name, share=needs_bus, channel=needs_channel) as target:
            return run_attack(name, target)
    except AttackError as exc:
        r = AttackResult(name, "master")
        r.what = f"could not set up: {exc}"
        r.checks["set_up"] = False
        return r


def run_all(
    names: list[str], folder: Path, echo: Callable[[str], None], keep: Path | None = None
) -> list[AttackResult]:
    """Each named attack once, each against fresh daemons in `folder`; a line per attack to
    `echo`. The daemons' logs of a failed case are copied to `keep`/<name>/ (its folder's
    own go with it): a crash seen once is worth its traceback."""
    results = []
    for name in names:
        r = run_case(name, folder)
        echo(r.line())
        if keep is not None and not r.survived and not r.skipped:
            kept = keep_logs(folder / name, keep / name)
            if kept:
                echo(f"{'':22s} logs: {', '.join(str(k) for k in kept)}")
        results.append(r)
    return results


def keep_logs(case: Path, dest: Path) -> list[Path]:
    """Every daemon.log under `case`, as `dest`/<daemon folder>.log."""
    kept = []
    for log_path in sorted(case.glob("*/daemon.log")):
        dest.mkdir(parents=True, exist_ok=True)
        target = dest / f"{log_path.parent.name}.log"
        with contextlib.suppress(OSError):
            shutil.copyfile(log_path, target)
            kept.append(target)
    return kept


def summary(results: list[AttackResult]) -> dict[str, Any]:
    ran = [r for r in results if not r.skipped]
    return {
        "ran": len(ran),
        "survived": sum(r.survived for r in ran),
        "failed": sorted({r.name for r in ran if not r.survived}),
        "median_s": statistics.median([r.seconds for r in ran]) if ran else None,
    }
