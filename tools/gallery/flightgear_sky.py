#!/usr/bin/env python3
"""wxsky's clouds in FlightGear's own view (issue 44): FlightGear 2020.3 started headless by
`plugins/flightgear/fgfs-with-wxsky --sky` (the osgdb_wxsky plugin in its scene through the
add-on, FlightGear's clouds off) beside a `wxsky run` it drives the camera of, frozen over
Honolulu; for each view, FlightGear's picture (exactly what it drew: Xvfb's frame buffer)
beside `wxsky-host-snapshot` of the camera the plugin sent. Needs FlightGear, the plugin
(make -C plugins/osg) and the host kit (make -C plugins/host-c).

    .venv/bin/python tools/gallery/flightgear_sky.py --out docs/gallery/flightgear-sky.png

tests/test_flightgear_sky.py uses the same pieces (`flightgear_with_sky`, `settle`).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

from wxsky.host.client import ControlClient  # noqa: E402
from wxsky.png import read_png, write_png  # noqa: E402

LAUNCHER = ROOT / "plugins" / "flightgear" / "fgfs-with-wxsky"
PLUGIN = ROOT / "plugins" / "osg" / "build" / "osgdb_wxsky.so"
HOST_SNAPSHOT = ROOT / "plugins" / "host-c" / "build" / "wxsky-host-snapshot"
SIZE = (640, 360)
START_S = 240.0  # FlightGear's start-up and scenery on a busy 2-core machine: 10-80 s
# (view number, heading offset, pitch offset): the cockpit looking ahead and up, and the
# helicopter view behind the aircraft and beside it, with the aircraft and Oahu's mountains in
# front of the clouds. Offsets turn the view left and up.
VIEWS = {
    "cockpit": (0, 0.0, 12.0),
    "chase": (1, 0.0, 0.0),
    "chase-side": (1, 100.0, 4.0),
}


def fgfs() -> Path | None:
    found = shutil.which("fgfs") or "/usr/games/fgfs"
    return Path(found) if Path(found).exists() else None


def missing() -> str | None:
    """Why this cannot run here, or None."""
    if fgfs() is None:
        return "FlightGear is not installed (apt-get install flightgear)"
    for tool in ("xvfb-run", "dbus-run-session"):
        if shutil.which(tool) is None:
            return f"no {tool} (apt-get install xvfb dbus)"
    if not PLUGIN.exists():
        return f"no {PLUGIN.relative_to(ROOT)} (make -C plugins/osg)"
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Props:
    """FlightGear's telnet props server in data mode."""

    def __init__(self, port: int, timeout_s: float) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout_s)
        self.file = self.sock.makefile("rwb")
        self._send("data")

    def _send(self, line: str) -> None:
        self.file.write((line + "\r\n").encode())
        self.file.flush()

    def get(self, path: str) -> str:
        self._send(f"get {path}")
        return self.file.readline().decode(errors="replace").strip()

    def set(self, path: str, value: object) -> None:
        self._send(f"set {path} {value}")

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.file.close()
            self.sock.close()


def read_xwd(path: Path) -> np.ndarray:
    """Xvfb's -fbdir screen (XWD, 32-bit little-endian pixels) as (H, W, 3) RGB."""
    data = path.read_bytes()
    head = np.frombuffer(data[:100], dtype=">u4")
    header, width, height, per_line, colours = (int(head[i]) for i in (0, 4, 5, 12, 19))
    start = header + colours * 12
    rows = np.frombuffer(data, np.uint8, count=per_line * height, offset=start)
    px = rows.reshape(height, per_line)[:, : width * 4].reshape(height, width, 4)
    return np.ascontiguousarray(px[..., [2, 1, 0]])


def stable_screen(path: Path, deadline: float, still_s: float = 1.0) -> np.ndarray:
    """The screen an Xvfb keeps in `path` once it has not changed for `still_s` (a frozen view
    whose layers have settled: on a busy machine a viewer draws a frame every second or so,
    and one taken earlier may still hold the layers before)."""
    last = read_xwd(path)
    since = time.monotonic()
    while time.monotonic() - since < still_s:
        if time.monotonic() > deadline:
            raise TimeoutError(f"the screen in {path} never stood still for {still_s} s")
        time.sleep(0.2)
        now = read_xwd(path)
        if not np.array_equal(now, last):
            last, since = now, time.monotonic()
    return last


@dataclass
class FlightGear:
    proc: subprocess.Popen[bytes]
    props: Props
    fbdir: Path
    log: Path

    def screen(self, size: tuple[int, int] = SIZE, timeout_s: float = 120.0) -> np.ndarray:
        """What FlightGear draws (its window fills the screen's top-left corner), once its
        picture has stood still for 2 s: the simulation is frozen, so it changes only while
        the layers it draws change."""
        deadline = time.monotonic() + timeout_s
        screen = stable_screen(self.fbdir / "Xvfb_screen0", deadline, still_s=2.0)
        return screen[: size[1], : size[0]]

    def view(self, number: int, heading_offset_deg: float, pitch_offset_deg: float) -> None:
        self.props.set("/sim/current-view/view-number", number)
        self.props.set("/sim/current-view/heading-offset-deg", heading_offset_deg)
        self.props.set("/sim/current-view/pitch-offset-deg", pitch_offset_deg)


@contextlib.contextmanager
def flightgear_with_sky(
    work: Path, control: str, size: tuple[int, int] = SIZE
) -> Iterator[FlightGear]:
    """fgfs with wxsky's sky from the daemon at `control`, headless, its clouds off, the
    simulation frozen (the aircraft where it starts, trimmed level at 1,500 ft over PHNL),
    noon, no menu bar; yields once the scenery is loaded."""
    work.mkdir(parents=True, exist_ok=True)
    fbdir = work / "fb"
    fbdir.mkdir(exist_ok=True)
    port = free_port()
    log = work / "fgfs.log"
    cmd = [
        str(LAUNCHER),
        "--sky",
        "--headless",
        "--size",
        f"{size[0]}x{size[1]}",
        "--control",
        control,
        "--fbdir",
        str(fbdir),
        "--telnet",
        str(port),
        "--",
        "--timeofday=noon",
        "--prop:/sim/menubar/visibility=false",
    ]
    with open(log, "wb") as out:
        proc = subprocess.Popen(
            cmd, stdout=out, stderr=subprocess.STDOUT, cwd=work, start_new_session=True
        )
    props: Props | None = None
    try:
        deadline = time.monotonic() + START_S
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"fgfs exited ({proc.returncode}): see {log}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"FlightGear's scenery not loaded in {START_S:.0f} s: {log}")
            try:
                props = props or Props(port, 30.0)
                if props.get("/sim/sceneryloaded") in ("true", "1"):
                    # (a freeze on the command line is lifted when the flight starts)
                    props.set("/sim/freeze/master", "true")
                    props.set("/sim/freeze/clock", "true")
                    break
            except OSError:
                if props is not None:
                    props.close()
                props = None
            time.sleep(1.0)
        yield FlightGear(proc, props, fbdir, log)
    finally:
        if props is not None:
            props.close()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def settle(client: ControlClient, timeout_s: float = 120.0) -> dict[str, object]:
    """Waits until the camera FlightGear's node sends has stood still for 2 s and the ring
    built for it has settled; the daemon's camera then."""
    deadline = time.monotonic() + timeout_s
    last, since = None, time.monotonic()
    while time.monotonic() < deadline:
        camera = client.call("status")["camera"]
        busy = client.call("scene")["ring_busy"]
        if camera != last:
            last, since = camera, time.monotonic()
        elif not busy and time.monotonic() - since >= 2.0:
            return camera  # type: ignore[no-any-return]
        time.sleep(0.25)
    raise TimeoutError(f"the camera did not settle in {timeout_s:.0f} s (last: {last})")


def host_snapshot(control: str, out: Path) -> np.ndarray:
    """The C host kit's picture of the daemon's camera as it stands (no camera arguments)."""
    proc = subprocess.run(
        [str(HOST_SNAPSHOT), "--control", control, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=180,
    )
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr.strip())
    return read_png(out)[..., :3]


@contextlib.contextmanager
def daemon(work: Path, preset: str) -> Iterator[str]:
    """`wxsky run` with the near layer's depth, on a unix socket in `work`; its address."""
    sock = work / "wx.sock"
    preset_args = ("--preset", preset)
    (work / "wxsky.toml").write_text(
        f'[output]\ncontrol = "unix:{sock}"\nshm_name = "wxsky-fg-{os.getpid()}"\n'
        "max_width = 960\nmax_height = 540\nnear_depth = true\n"
        # 10 frames a second: FlightGear on llvmpipe needs the cores more than the sky does
        "[daemon]\ntick_hz = 10.0\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "wxsky", "run", "--config", str(work / "wxsky.toml"), *preset_args],
        stdout=subprocess.DEVNULL,
        stderr=open(work / "daemon.log", "wb"),  # noqa: SIM115 (the child keeps it)
    )
    try:
        deadline = time.monotonic() + 60.0
        while not sock.exists():
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the daemon did not start: {work / 'daemon.log'}")
            time.sleep(0.2)
        yield f"unix:{sock}"
    finally:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def write_sheet(rows: list[np.ndarray], out: Path) -> None:
    """Rows of RGB pictures, one under the other, as an opaque PNG."""
    sheet = np.concatenate(rows, axis=0)
    rgba = np.concatenate([sheet, np.full((*sheet.shape[:2], 1), 255, np.uint8)], axis=2)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_png(out, np.ascontiguousarray(rgba))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    out = ROOT / "docs" / "gallery" / "flightgear-sky.png"
    parser.add_argument("--out", type=Path, default=out, help="the sheet (PNG)")
    parser.add_argument("--preset", default="scattered-cumulus", help="the daemon's weather")
    args = parser.parse_args()
    why = missing()
    if why is not None:
        print(f"flightgear_sky: {why}")
        return 1
    work = Path(tempfile.mkdtemp(prefix="wxsky-fg-sky-"))
    rows = []
    with (
        daemon(work, args.preset) as control,
        ControlClient.connect(control) as client,
        flightgear_with_sky(work / "fg", control) as fg,
    ):
        # FlightGear's clock is the sky's: its sun where wxsky's is, held still
        gmt = fg.props.get("/sim/time/gmt")
        client.call("set_time", {"time_utc": gmt + "Z", "rate": 0.0})
        for name, (number, heading, pitch) in VIEWS.items():
            fg.view(number, heading, pitch)
            camera = settle(client)
            seen = fg.screen()
            host = host_snapshot(control, work / f"host-{name}.png")
            print(f"{name}: camera {camera}")
            rows.append(np.concatenate([seen, host], axis=1))
    write_sheet(rows, args.out)
    print(f"wrote {args.out} ({len(rows)} views: FlightGear left, wxsky-host-snapshot right)")
    shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
