"""The command line's rough edges a new user hits (issue 39): negative values, output paths
that are refused before any work, progress on a terminal and silence on a pipe, runtime errors
that say what to do next, no "inf" in a message, the exit status of an interrupted command and
of a stopped daemon, and a full control socket that still answers `wxsky status`."""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import resource
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import DaemonSpec, running_daemon, running_daemons, write_config
from server_thread import ServerThread

from wxsky.app.bench import run_bench
from wxsky.app.camera_path import straight_and_level
from wxsky.cli import build_parser, main
from wxsky.cli.common import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    NumberArg,
    Progress,
    logging_to_stderr,
)
from wxsky.cli.daemon_cmd import _shared_config
from wxsky.errors import RuntimeFailure
from wxsky.inputs.cigi_link import CigiIg, IgSettings
from wxsky.inputs.flightgear_link import FlightGearPose
from wxsky.output.shm import FrameWriter, LayerSpec
from wxsky.output.transport import ControlServer
from wxsky.output.wire import Request, encode
from wxsky.png import read_png
from wxsky.scene.layout import SceneSettings
from wxsky.settings.config import load_config
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

REPO = Path(__file__).resolve().parents[1]
FEED = REPO / "tests" / "data" / "metar" / "noaa_cycle_2025-07-26_okay_weather_HEAD1500.txt.gz"
WXSKY = (sys.executable, "-m", "wxsky")
HANG_S = 120.0  # only a hang takes this long: every wait below is for an event


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


def in_process(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


# -- negative values ----------------------------------------------------------------------------

# What each command needs besides the option tried, to parse.
REQUIRED: dict[tuple[str, ...], tuple[str, ...]] = {
    ("snapshot",): ("--preset", "clear", "--out", "x.png"),
    ("sun",): ("--lat", "0", "--lon", "0"),
    ("metar", "fetch"): ("feed.txt",),
    ("metar", "decode"): ("REPORT",),
    ("cigi", "send"): ("--to", "udp:127.0.0.1:8001"),
    ("preset", "save"): ("name", "--from-metar", "LSZH 211250Z 24012KT 9999 FEW030 18/09 Q1012"),
    ("grib", "show"): ("gfs.grib2",),
}
# Options that come in pairs.
PARTNER = {"--lat": ("--lon", "0"), "--lon": ("--lat", "0")}


def _commands(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _commands(sub, (*path, name))


def _signed_options() -> list[tuple[tuple[str, ...], str, float, str]]:
    """Every (command, option, a negative value it takes, a way to type it) of the command
    line: an integer one way, a number three."""
    found = []
    for path, parser in _commands(build_parser()):
        for action in parser._actions:
            if not isinstance(action.type, NumberArg):
                continue
            kind = action.type.kind
            if kind.lo is not None and kind.lo >= 0:
                continue
            value = -1.0 if kind.lo is None else max(float(kind.lo), -1.0)
            if kind.hi is not None and value > kind.hi:
                continue
            for spelling in ("plain",) if kind.integer else ("plain", "exponent", "dot"):
                found.append((path, action.option_strings[0], value, spelling))
    return found


SIGNED = _signed_options()


def test_the_signed_options_are_found() -> None:
    named = {(p, o) for p, o, _, _ in SIGNED}
    for expected in [
        (("snapshot",), "--lat"),
        (("snapshot",), "--lon"),
        (("snapshot",), "--alt-m"),
        (("snapshot",), "--heading-deg"),
        (("snapshot",), "--pitch-deg"),
        (("sun",), "--lat"),
        (("sun",), "--lon"),
        (("metar", "fetch"), "--lat"),
        (("metar", "fetch"), "--lon"),
    ]:
        assert expected in named


@pytest.mark.parametrize(
    ("path", "option", "value", "spelling"),
    SIGNED,
    ids=[f"{' '.join(p)} {o} {s}" for p, o, _, s in SIGNED],
)
def test_every_signed_option_takes_a_negative_value_as_typed(
    path: tuple[str, ...], option: str, value: float, spelling: str
) -> None:
    parser = build_parser()
    (action,) = (
        a
        for p, sub in _commands(parser)
        if p == path
        for a in sub._actions
        if option in a.option_strings
    )
    assert isinstance(action.type, NumberArg)
    integer = action.type.kind.integer
    if spelling == "plain":
        text = str(int(value)) if integer else repr(value)  # -1 and -1.0 worked before
    elif spelling == "exponent":
        text = f"{value * 10:g}e-1"  # -10e-1: as a script may print it
    else:  # -1. or -.5: as typed in a hurry
        text = f"-{abs(value):g}." if value.is_integer() else f"{value:g}".replace("-0.", "-.")
    extra = PARTNER.get(option, ()) if path in (("snapshot",), ("metar", "fetch")) else ()
    args = parser.parse_args([*path, *REQUIRED.get(path, ()), *extra, option, text])
    assert getattr(args, option.lstrip("-").replace("-", "_")) == pytest.approx(float(text))


def test_a_left_channel_is_typed_as_anyone_types_it(tmp_path: Path) -> None:
    args = build_parser().parse_args(["run", "--view-offset", "-60,0,0", "--fov-deg", "60"])
    assert args.view_offset == (-60.0, 0.0, 0.0)
    config = _shared_config(load_config(None), args)
    assert config.channel.view_offset_deg == (-60.0, 0.0, 0.0)
    # Through the real entry point: the value passes, the run stops at what comes next (an
    # unknown preset, a usage error of its own) and not at "expected one argument".
    proc = subprocess.run(
        [*WXSKY, "run", "--view-offset", "-60,-2.5,0", "--preset", "no-such-sky"],
        capture_output=True,
        text=True,
        timeout=HANG_S,
    )
    assert proc.returncode == EXIT_USAGE, proc.stderr
    assert "no-such-sky" in one_line(proc.stderr)


def test_negative_coordinates_through_the_entry_point() -> None:
    proc = subprocess.run(
        [*WXSKY, "sun", "--lat", "-33.9", "--lon", "-70.7", "--alt-m", "-5.", "--json"],
        capture_output=True,
        text=True,
        timeout=HANG_S,
    )
    assert proc.returncode == 0, proc.stderr
    assert '"lat_deg": -33.9' in proc.stdout and '"lon_deg": -70.7' in proc.stdout


def test_metar_fetch_for_an_observer_in_the_south_west(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = in_process(
        capsys, "metar", "fetch", str(FEED), "--lat", "-33.9", "--lon", "-7e1"
    )
    assert code == 0, err
    assert "observer -33.9000 -70.0000:" in out


@pytest.mark.gl
def test_a_snapshot_looking_down_from_the_southern_hemisphere(tmp_path: Path) -> None:
    out = tmp_path / "down.png"
    proc = subprocess.run(
        [*WXSKY, "snapshot", "--preset", "clear", "--size", "48x32", "--lat", "-33.9",
         "--lon", "-70.7", "--pitch-deg", "-5", "--heading-deg", "-9e1", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert read_png(out).shape == (32, 48, 4)


# -- output paths -------------------------------------------------------------------------------


# Each command is also given an unknown preset: the path must be refused first, before any
# work (and a command that took the path would stop there, not render or run a daemon).
NO_SKY = ("--preset", "no-such-sky")


@pytest.mark.parametrize(
    ("command", "name", "needle"),
    [
        (("snapshot", *NO_SKY), "--out", "does not exist (create it first)"),
        (("snapshot", *NO_SKY, "--out", "x.png"), "--layers-out", "does not exist"),
        (("bench", *NO_SKY), "--trace", "does not exist (create it first)"),
        (("run", *NO_SKY), "--trace", "does not exist (create it first)"),
        (("run", *NO_SKY), "--preview", "does not exist"),
    ],
)
def test_a_missing_directory_is_refused_not_made(
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    command: tuple[str, ...],
    name: str,
    needle: str,
) -> None:
    target = tmp_path / "missing" / "dir" / "x.png"
    code, out, err = in_process(capsys, *command, name, str(target))
    assert code == EXIT_USAGE, err
    line = one_line(err)
    assert line.startswith(f"wxsky: error: {name} {target}: directory ") and needle in line
    assert out == ""
    assert not (tmp_path / "missing").exists()


@pytest.mark.parametrize("name", ["x.jpg", "x.jpeg", "x", "x.png.txt", "x.tiff"])
def test_out_must_be_a_png(capsys: pytest.CaptureFixture[str], tmp_path: Path, name: str) -> None:
    out = tmp_path / name
    code, _, err = in_process(capsys, "snapshot", *NO_SKY, "--out", str(out))
    assert code == EXIT_USAGE
    assert one_line(err) == (
        f"wxsky: error: --out {out}: PNG is written: give a name ending in .png"
    )
    assert not out.exists()


def test_out_refuses_a_directory_and_layers_out_a_file(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    folder = tmp_path / "shots.png"
    folder.mkdir()
    code, _, err = in_process(capsys, "snapshot", *NO_SKY, "--out", str(folder))
    assert code == EXIT_USAGE
    assert one_line(err).endswith(": is a directory: give a file name")
    afile = tmp_path / "layers"
    afile.write_text("")
    args = ("snapshot", *NO_SKY, "--out", str(tmp_path / "x.png"))
    code, _, err = in_process(capsys, *args, "--layers-out", str(afile))
    assert code == EXIT_USAGE
    assert one_line(err) == f"wxsky: error: --layers-out {afile}: is not a directory"


def test_good_output_paths_pass(tmp_path: Path) -> None:
    parser = build_parser()
    args = parser.parse_args(
        ["snapshot", "--preset", "clear", "--out", str(tmp_path / "X.PNG"),
         "--layers-out", str(tmp_path / "new-layers")]
    )  # fmt: skip
    assert args.out == tmp_path / "X.PNG"
    assert args.layers_out == tmp_path / "new-layers"  # one level made when written
    args = parser.parse_args(["bench", "--trace", str(tmp_path / "ring.jsonl")])
    assert args.trace == tmp_path / "ring.jsonl"
    args = parser.parse_args(["run", "--preview", str(tmp_path)])
    assert args.preview == tmp_path


@pytest.mark.gl
def test_a_snapshot_writes_its_layers_into_a_new_directory(tmp_path: Path) -> None:
    layers = tmp_path / "layers"
    proc = subprocess.run(
        [*WXSKY, "snapshot", "--preset", "clear", "--size", "32x16", "--out",
         str(tmp_path / "x.png"), "--layers-out", str(layers)],
        capture_output=True,
        text=True,
        timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert read_png(layers / "sky.png").shape == (16, 32, 4)
    assert proc.stderr == ""  # stderr is a pipe: no progress line


# -- progress on a terminal, silence on a pipe --------------------------------------------------


class HeldFeed:
    """A one-request HTTP server on loopback that answers only when the test says so: the
    command waits on it for as long as the test needs, with no clock involved."""

    def __init__(self, body: bytes) -> None:
        self.body = body
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.url = f"http://127.0.0.1:{self.listener.getsockname()[1]}/metar.txt"
        self.requested = threading.Event()
        self._answer = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        with contextlib.suppress(OSError):
            conn, _ = self.listener.accept()
            with conn:
                request = b""
                while b"\r\n\r\n" not in request:
                    chunk = conn.recv(4096)
                    if not chunk:
                        return
                    request += chunk
                self.requested.set()
                if not self._answer.wait(HANG_S):
                    return
                head = f"HTTP/1.1 200 OK\r\nContent-Length: {len(self.body)}\r\n"
                conn.sendall(head.encode() + b"Connection: close\r\n\r\n" + self.body)

    def answer(self) -> None:
        self._answer.set()

    def close(self) -> None:
        self._answer.set()
        self.listener.close()
        self._thread.join(10)


@contextlib.contextmanager
def held_feed() -> Iterator[HeldFeed]:
    feed = HeldFeed(FEED.read_bytes())
    try:
        yield feed
    finally:
        feed.close()


class Terminal:
    """A real pty: the child's stderr is its slave end, this reads the master end."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        self._data = b""
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    def start_reading(self) -> None:
        os.close(self.slave)  # the child holds it now: EIO at the master once it is gone
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while True:
            try:
                chunk = os.read(self.master, 4096)
            except OSError:
                return
            if not chunk:
                return
            with self._lock:
                self._data += chunk

    @property
    def text(self) -> str:
        with self._lock:
            return self._data.decode(errors="replace")

    def wait_for(self, needle: str, proc: subprocess.Popen[Any]) -> None:
        deadline = time.monotonic() + HANG_S
        while needle not in self.text:
            assert proc.poll() is None or needle in self.text, (
                f"{needle!r} never shown; exited {proc.returncode}:\n{self.text!r}"
            )
            assert time.monotonic() < deadline, f"{needle!r} never shown:\n{self.text!r}"
            time.sleep(0.01)

    def close(self) -> str:
        if self._thread is not None:
            self._thread.join(10)
        with contextlib.suppress(OSError):
            os.close(self.master)
        return self.text


ERASE = "\r\x1b[K"


def test_metar_fetch_shows_progress_on_a_terminal() -> None:
    term = Terminal()
    with held_feed() as feed:
        proc = subprocess.Popen(
            [*WXSKY, "metar", "fetch", feed.url],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=term.slave,
        )
        term.start_reading()
        try:
            # While the feed is held back the command says what it waits for.
            term.wait_for(f"wxsky: metar fetch: reading {feed.url} (", proc)
            feed.answer()
            out, _ = proc.communicate(timeout=HANG_S)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    shown = term.close()
    assert proc.returncode == 0, shown
    assert out.decode().startswith(f"{feed.url}: tgftp, ")
    # The line was erased before the result: nothing of it stays on the terminal.
    assert shown.startswith(ERASE) and shown.endswith(ERASE), repr(shown)
    assert "\n" not in shown  # one line, rewritten in place


def test_metar_fetch_is_silent_on_a_pipe() -> None:
    with held_feed() as feed:
        proc = subprocess.Popen(
            [*WXSKY, "metar", "fetch", feed.url],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        try:
            # Asked for the feed: on a terminal its progress line would be up by now.
            assert feed.requested.wait(HANG_S)
            feed.answer()
            out, err = proc.communicate(timeout=HANG_S)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert proc.returncode == 0, err
    assert err == b""
    assert out.decode().startswith(f"{feed.url}: tgftp, ")


def _pty_stream() -> tuple[int, Any]:
    master, slave = os.openpty()
    return master, open(slave, "w", encoding="utf-8", closefd=True)


def _drain(master: int) -> str:
    data = b""
    while select.select([master], [], [], 0)[0]:
        chunk = os.read(master, 65536)
        if not chunk:
            break
        data += chunk
    return data.decode()


def test_progress_keeps_its_line_up_to_date_and_out_of_the_way_of_log_records(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    master, stream = _pty_stream()
    try:
        monkeypatch.setattr(sys, "stderr", stream)
        with logging_to_stderr("INFO"):
            progress = Progress("bench")
            assert progress.enabled
            progress("starting")
            assert _drain(master) == f"{ERASE}wxsky: bench: starting (0 s)"
            progress("frame 7 of 9")  # shown by the next tick
            shown = ""
            deadline = time.monotonic() + HANG_S
            while "frame 7 of 9" not in shown:
                assert time.monotonic() < deadline
                shown += _drain(master)
                time.sleep(0.01)
            logging.getLogger("wxsky.test").warning("a record of its own")
            progress.done()
            progress("after done: never shown")
            shown = _drain(master)
        record = next(part for part in shown.split(ERASE) if "a record of its own" in part)
        # The record starts a clean line: the progress line was erased first.
        assert re.match(r"\d\d:\d\d:\d\d WARNING wxsky.test: a record of its own\r?\n$", record)
        # Nothing of the progress line is left on the terminal, and nothing came after done.
        assert "wxsky: bench:" not in shown.rsplit(ERASE, 1)[-1] and "never shown" not in shown
    finally:
        stream.close()
        os.close(master)


def test_progress_on_a_pipe_or_file_writes_nothing(tmp_path: Path) -> None:
    read, write = os.pipe()
    with open(write, "w") as pipe, open(tmp_path / "log", "w") as file:
        for stream in (pipe, file):
            progress = Progress("snapshot", stream)
            assert not progress.enabled
            progress("building the clouds")
            progress.done()
    with open(read, "rb") as pipe_end:
        assert pipe_end.read() == b""
    assert (tmp_path / "log").read_text() == ""


@pytest.mark.gl
def test_snapshot_shows_its_steps_on_a_terminal(tmp_path: Path) -> None:
    term = Terminal()
    out = tmp_path / "x.png"
    proc = subprocess.Popen(
        [*WXSKY, "snapshot", "--preset", "clear", "--size", "32x16", "--out", str(out)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=term.slave,
    )
    term.start_reading()
    try:
        stdout, _ = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    shown = term.close()
    assert proc.returncode == 0, shown
    assert stdout.decode().startswith(f"wrote {out} (32x16)")
    assert shown.startswith(f"{ERASE}wxsky: snapshot: reading the weather (0 s)"), repr(shown)
    assert shown.endswith(ERASE) and "\n" not in shown


@pytest.mark.gl
def test_bench_shows_its_frames_on_a_terminal() -> None:
    term = Terminal()
    proc = subprocess.Popen(
        [*WXSKY, "bench", "--mode", "direct", "--frames", "2", "--size", "48x32",
         "--preset", "clear"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=term.slave,
    )  # fmt: skip
    term.start_reading()
    try:
        stdout, _ = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    shown = term.close()
    assert proc.returncode == 0, shown
    assert stdout.decode().startswith("wxsky bench: clear, direct mode, 48x32, 2 frames")
    assert shown.startswith(f"{ERASE}wxsky: bench: starting the renderer and the scene (0 s)")
    assert shown.endswith(ERASE) and "\n" not in shown, repr(shown)


@pytest.mark.gl
def test_run_bench_says_each_frame() -> None:
    """What the bench's line shows, frame by frame (a terminal shows the latest each tick)."""
    said: list[str] = []
    state = WeatherState().apply(load_preset("clear"))
    run_bench(
        state,
        SceneSettings(),
        straight_and_level(),
        2,
        "direct",
        (48, 32),
        progress=said.append,
    )
    assert said == ["starting the renderer and the scene", "frame 1 of 2", "frame 2 of 2"]


# -- runtime errors say what to do next ---------------------------------------------------------


def test_no_daemon_says_start_one_or_name_its_address(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    address = f"unix:{tmp_path / 'nobody.sock'}"
    for command in (("status",), ("preset", "apply", "clear"), ("preset", "release")):
        code, _, err = in_process(capsys, *command, "--control", address)
        assert code == EXIT_FAILURE
        line = one_line(err)
        assert line.startswith(f"wxsky: error: cannot connect to the wxsky daemon at {address}")
        assert "start one with `wxsky run`" in line and "--control ADDR" in line, line


def test_a_socket_in_use_names_the_flag_and_key_that_pick_another(tmp_path: Path) -> None:
    async def answer(method: str, params: dict[str, Any]) -> Any:
        return {}

    path = tmp_path / "wx.sock"
    first = ServerThread(f"unix:{path}", answer)
    try:
        with pytest.raises(RuntimeFailure) as refused:
            first.run(ControlServer(f"unix:{path}", answer).start())
        text = str(refused.value)
        assert text.startswith(f"another wxsky daemon is listening on unix:{path}: stop it")
        assert "--control ADDR or [output] control" in text
    finally:
        first.stop()


def test_a_segment_in_use_names_the_flag_and_key_that_pick_another() -> None:
    name = f"wxsky-test-{uuid.uuid4().hex[:10]}"
    with (
        FrameWriter.create(name, [LayerSpec("sky", 16, 16)]),
        pytest.raises(RuntimeFailure) as refused,
    ):
        FrameWriter.create(name, [LayerSpec("sky", 16, 16)])
    text = str(refused.value)
    assert f"shared-memory segment {name!r} is in use by another wxsky writer" in text
    assert "`wxsky run --shm-name NAME` or [output] shm_name" in text


def test_a_udp_port_in_use_names_the_flag_and_key_that_pick_another() -> None:
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    port = taken.getsockname()[1]
    try:
        with pytest.raises(RuntimeFailure) as refused:  # an OSError (an internal error) before
            FlightGearPose("127.0.0.1", port, lambda pose: None)
        assert "--flightgear-pose udp:HOST:PORT or [flightgear] pose" in str(refused.value)

        async def listen() -> None:
            await CigiIg(IgSettings(listen=("127.0.0.1", port)), handler=None).start()  # type: ignore[arg-type]

        import asyncio

        with pytest.raises(RuntimeFailure) as refused:
            asyncio.run(listen())
        assert "--cigi udp:HOST:PORT or [cigi] listen" in str(refused.value)
    finally:
        taken.close()


def test_a_daemon_that_speaks_another_version_is_named_as_the_likely_cause(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    async def old_daemon(method: str, params: dict[str, Any]) -> Any:
        return {"version": "0.0"}  # a status without the weather this wxsky reads

    path = tmp_path / "wx.sock"
    server = ServerThread(f"unix:{path}", old_daemon)
    try:
        args = ("cigi", "send", "--to", "udp:127.0.0.1:9", "--count", "1")
        code, _, err = in_process(capsys, *args, "--control", f"unix:{path}")
    finally:
        server.stop()
    assert code == EXIT_FAILURE
    assert one_line(err) == (
        f"wxsky: error: the daemon at unix:{path} sent no weather; is it another wxsky "
        "version? run the daemon's own `wxsky cigi send`"
    )


def test_shm_name_is_checked_as_the_config_checks_it(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = in_process(capsys, "run", "--shm-name", "a/b")
    assert code == EXIT_USAGE
    assert one_line(err).startswith("wxsky: error: --shm-name: must be 1-64 letters")
    args = build_parser().parse_args(["run", "--shm-name", "wxsky-left"])
    assert _shared_config(load_config(None), args).output.shm_name == "wxsky-left"


@pytest.mark.gl
def test_a_second_daemon_is_told_how_to_run_beside_the_first(tmp_path: Path) -> None:
    (tmp_path / "first").mkdir()
    with running_daemon(tmp_path / "first") as first:
        # The same segment name, another socket: the segment is in use.
        config = write_config(tmp_path / "second.toml", first.shm_name)
        proc = subprocess.run(
            [*WXSKY, "run", "--config", str(config), "--control", f"unix:{tmp_path / 'b.sock'}"],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert proc.returncode == EXIT_FAILURE, proc.stderr
        last = proc.stderr.strip().splitlines()[-1]
        assert last.startswith(f"wxsky: error: shared-memory segment {first.shm_name!r} is in use")
        assert "--shm-name NAME" in last
        # Another segment name, the same socket: the socket is in use.
        proc = subprocess.run(
            [*WXSKY, "run", "--config", str(config), "--shm-name",
             f"wxsky-test-{uuid.uuid4().hex[:10]}", "--control", first.address],
            capture_output=True,
            text=True,
            timeout=600,
        )  # fmt: skip
        assert proc.returncode == EXIT_FAILURE, proc.stderr
        last = proc.stderr.strip().splitlines()[-1]
        assert last.startswith(
            f"wxsky: error: another wxsky daemon is listening on {first.address}"
        )
        assert "--control ADDR or [output] control" in last
        with first.client() as c:
            assert c.call("status")["frames_published"] > 0


def test_no_inf_in_a_station_message(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = in_process(capsys, "metar", "fetch", str(FEED), "--station", "KTGI")
    assert code == 0, err
    assert "no fresh report from station KTGI (older than 90 min)" in out
    assert not re.search(r"\b(inf|nan)\b", out + err, re.IGNORECASE), out
    code, out, err = in_process(capsys, "metar", "fetch", str(FEED), "--station", "KTGI", "--json")
    assert code == 0, err
    assert "Infinity" not in out and "NaN" not in out


# -- the exit status of an interrupted command and of a stopped daemon --------------------------


def _signal_state(status_path: str) -> dict[str, bool]:
    """Whether SIGINT is ignored, blocked or caught in a process or thread (Linux /proc)."""
    try:
        lines = Path(status_path).read_text().splitlines()
    except OSError:
        return {}
    bit = 1 << (signal.SIGINT - 1)
    fields = dict(line.split(":", 1) for line in lines if ":" in line)
    return {
        name: bool(int(fields[key].strip(), 16) & bit)
        for name, key in (("ignored", "SigIgn"), ("blocked", "SigBlk"), ("caught", "SigCgt"))
        if key in fields
    }


# A terminal starts a foreground command with SIGINT at its default. In a full run this test's
# worker process ignores SIGINT (set by something in the session, not found yet: no test
# changes it, see _signal_state), and an ignored signal stays ignored across exec, so the
# command is started through a step that puts SIGINT back to its default, as a shell does.
AS_A_TERMINAL_STARTS_IT = (
    "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
    "os.execv(sys.argv[1], sys.argv[1:])"
)


def test_a_one_shot_command_interrupted_by_ctrl_c_exits_130() -> None:
    with held_feed() as feed:
        proc = subprocess.Popen(
            [sys.executable, "-c", AS_A_TERMINAL_STARTS_IT, *WXSKY, "metar", "fetch", feed.url],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            assert feed.requested.wait(HANG_S)  # it waits for the feed, which never comes
            # How the child takes SIGINT, for the message if it does not exit 130: a mask or
            # an ignore inherited from this process would keep Ctrl-C from reaching it.
            child = _signal_state(f"/proc/{proc.pid}/status")
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=HANG_S)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    here = _signal_state(f"/proc/self/task/{threading.get_native_id()}/status")
    # What it said instead, if not, and how SIGINT stood in it and in this test's thread.
    assert proc.returncode == EXIT_INTERRUPTED == 130, (err, "child", child, "test", here)
    assert err.strip().splitlines() == ["wxsky: interrupted"]


@pytest.mark.gl
def test_a_daemon_stopped_by_ctrl_c_or_sigterm_exits_0(tmp_path: Path) -> None:
    specs = []
    for name in ("int", "term"):
        (tmp_path / name).mkdir()
        specs.append(DaemonSpec(tmp_path / name))
    with running_daemons(specs) as (by_int, by_term):
        for daemon, sig in ((by_int, signal.SIGINT), (by_term, signal.SIGTERM)):
            code, _ = daemon.stop(sig, timeout_s=HANG_S)
            assert code == 0, daemon.log()
            assert "Traceback" not in daemon.log()
            assert not daemon.socket_path.exists()


def test_the_readme_says_what_the_code_does() -> None:
    readme = " ".join((REPO / "README.md").read_text(encoding="utf-8").split())
    exit_status = readme[readme.index("**Exit status.**") :][:3000]
    assert "A command interrupted by Ctrl-C exits 130" in exit_status
    assert "`wxsky run` is a service" in exit_status
    assert "Ctrl-C or SIGTERM: it shuts down cleanly and exits 0" in exit_status
    assert "Ctrl-C exits 130." not in exit_status  # what it used to say, of every command


# -- a full control socket still answers `wxsky status` -----------------------------------------


class Gate:
    """A handler whose "wait" requests are answered only when the test opens the gate."""

    def __init__(self) -> None:
        self.waiting = 0
        self.gate: Any = None

    async def __call__(self, method: str, params: dict[str, Any]) -> Any:
        import asyncio

        if self.gate is None:
            self.gate = asyncio.Event()
        if method == "wait":
            self.waiting += 1
            await self.gate.wait()
        return "opened"


def test_too_many_clients_is_a_runtime_failure(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    gate = Gate()
    path = tmp_path / "wx.sock"
    server = ServerThread(f"unix:{path}", gate, max_clients=1)
    busy = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        busy.connect(str(path))
        busy.sendall(encode(Request(1, "wait", {})))
        deadline = time.monotonic() + HANG_S
        while server.on_loop(lambda: gate.waiting) < 1:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        code, out, err = in_process(capsys, "status", "--control", f"unix:{path}")
        assert code == EXIT_FAILURE  # the daemon's state, not the command's mistake
        # (The server, in this process, logs to the same stderr: its line is not the CLI's.)
        (line,) = [line for line in err.splitlines() if line.startswith("wxsky:")]
        assert line.startswith("wxsky: error: too many control clients: all 1 ")
        assert "try again shortly, or raise [output] max_clients" in err
        assert out == ""
    finally:
        server.on_loop(lambda: gate.gate.set())
        busy.close()
        server.stop()


@contextlib.contextmanager
def _descriptors(count: int) -> Iterator[None]:
    """Room for `count` more open files in this process (the soft limit raised within the
    hard one, and put back after)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = len(os.listdir("/proc/self/fd")) + count + 64
    if need > soft:
        if hard != resource.RLIM_INFINITY and need > hard:
            pytest.skip(f"{need} file descriptors needed, the hard limit is {hard}")
        resource.setrlimit(resource.RLIMIT_NOFILE, (need, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


@pytest.mark.gl
def test_status_is_answered_with_1100_idle_connections_open(tmp_path: Path) -> None:
    """The issue's case: the daemon's default 64 clients, 1,100 idle connections."""
    with running_daemon(tmp_path) as d, _descriptors(1100):
        idle: list[socket.socket] = []
        try:
            for _ in range(1100):
                sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                idle.append(sock)
                connect_unix(sock, d.socket_path)
            proc = subprocess.run(
                [*WXSKY, "status", "--control", d.address],
                capture_output=True,
                text=True,
                timeout=HANG_S,
            )
            assert proc.returncode == 0, proc.stderr
            assert proc.stdout.startswith("wxsky "), proc.stdout
            # The daemon holds its 64 and no more (plus those closing, and its own files).
            assert len(os.listdir(f"/proc/{d.proc.pid}/fd")) < 64 + 200
        finally:
            for sock in idle:
                sock.close()
        log = d.log()
        assert "Traceback" not in log
        assert 1 <= log.count("to make room for a new one") <= 3, log[-3000:]
