#!/usr/bin/env python3
"""wxsky's clouds in `osgviewer` (issue 44): OpenSceneGraph's own viewer, unchanged, loads the
example terrain and a `.wxsky` file (`osgviewer terrain.osg sky.wxsky`, the osgdb_wxsky plugin
in OSG_LIBRARY_PATH) in an Xvfb window; for a few cameras (osgviewer's camera path, `-p`), its
window (Xvfb's frame buffer) beside `wxsky-host-snapshot` of the camera the plugin sent. Needs
osgviewer (Debian's openscenegraph), Xvfb, and the kits (make -C plugins/osg plugins/host-c).

    .venv/bin/python tools/gallery/osgviewer_sky.py --out docs/gallery/osgviewer-sky.png

tests/test_osg_plugin.py uses `view_path`.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

from tools.gallery.flightgear_sky import (  # noqa: E402
    daemon,
    host_snapshot,
    stable_screen,
    write_sheet,
)
from wxsky.host.client import ControlClient  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

KIT = ROOT / "plugins" / "osg"
TERRAIN = KIT / "examples" / "terrain.osg"
SIZE = (640, 360)
# (heading, pitch, east, north, up): toward the ridge from the site, up over it from nearer,
# and along it from the west, looking north-east.
CAMERAS = (
    (0.0, 5.0, 0.0, 0.0, 300.0),
    (20.0, 12.0, 0.0, 2000.0, 350.0),
    (60.0, 4.0, -5000.0, 1000.0, 500.0),
)


def view_path(heading_deg: float, pitch_deg: float, position_m: tuple[float, float, float]) -> str:
    """An osgviewer camera path (osg::AnimationPath's text: time, position, quaternion) that
    holds one camera: the rotation takes OSG's camera axes (x right, y up, looking down -z)
    to the view's right, up and back in the scene's east-north-up."""
    h, p = np.radians(heading_deg), np.radians(pitch_deg)
    fwd = np.array([np.sin(h) * np.cos(p), np.cos(h) * np.cos(p), np.sin(p)])
    right = np.array([np.cos(h), -np.sin(h), 0.0])
    r = np.stack([right, np.cross(right, fwd), -fwd], axis=1)
    w = np.sqrt(max(0.0, 1.0 + np.trace(r))) / 2.0
    x = np.copysign(np.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2.0, r[2, 1] - r[1, 2])
    y = np.copysign(np.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2.0, r[0, 2] - r[2, 0])
    z = np.copysign(np.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2.0, r[1, 0] - r[0, 1])
    e, n, u = position_m
    return "".join(f"{t} {e} {n} {u} {x} {y} {z} {w}\n" for t in (0.0, 1e6))


@contextlib.contextmanager
def xvfb(size: tuple[int, int], fbdir: Path) -> Iterator[str]:
    """A virtual screen of `size` whose frame buffer Xvfb keeps in fbdir; its display."""
    display = f":{100 + os.getpid() % 800}"
    server = subprocess.Popen(
        [
            "Xvfb",
            display,
            "-screen",
            "0",
            f"{size[0]}x{size[1]}x24",
            "-fbdir",
            str(fbdir),
            "-nolisten",
            "tcp",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 30.0
        while not (fbdir / "Xvfb_screen0").exists():
            if server.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("Xvfb did not start")
            time.sleep(0.1)
        yield display
    finally:
        server.terminate()
        server.wait(30)


def shoot(client: ControlClient, control: str, work: Path, camera: tuple[float, ...]) -> np.ndarray:
    """osgviewer's window for one camera beside the host kit's picture of it."""
    heading, pitch, e, n, u = camera
    (work / "view.path").write_text(view_path(heading, pitch, (e, n, u)))
    fbdir = work / "fb"
    fbdir.mkdir(exist_ok=True)
    env = {**os.environ, "OSG_LIBRARY_PATH": str(KIT / "build")}
    with xvfb(SIZE, fbdir) as display:
        env["DISPLAY"] = display
        w, h = SIZE
        app = subprocess.Popen(
            [
                "osgviewer",
                "--window",
                "0",
                "0",
                str(w),
                str(h),
                "-p",
                str(work / "view.path"),
                str(TERRAIN),
                str(work / "sky.wxsky"),
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            deadline = time.monotonic() + 120.0
            while True:
                cam = client.call("status")["camera"]
                there = abs(cam["heading_deg"] - heading) < 0.01 and np.allclose(
                    cam["position_m"], (e, n, u), atol=0.1
                )
                if there and not client.call("scene")["ring_busy"]:
                    break
                if time.monotonic() > deadline or app.poll() is not None:
                    raise RuntimeError("osgviewer's camera did not reach the daemon")
                time.sleep(0.2)
            seen = stable_screen(fbdir / "Xvfb_screen0", deadline)[:h, :w]
        finally:
            app.terminate()
            app.wait(30)
    host = host_snapshot(control, work / "host.png")
    return np.concatenate([seen, host], axis=1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    out = ROOT / "docs" / "gallery" / "osgviewer-sky.png"
    parser.add_argument("--out", type=Path, default=out, help="the sheet (PNG)")
    parser.add_argument("--preset", default="scattered-cumulus", help="the daemon's weather")
    args = parser.parse_args()
    for tool in ("osgviewer", "Xvfb"):
        if shutil.which(tool) is None:
            print(f"osgviewer_sky: no {tool} (apt-get install openscenegraph xvfb)")
            return 1
    work = Path(tempfile.mkdtemp(prefix="wxsky-osgviewer-"))
    state = WeatherState().apply(load_preset(args.preset))
    # the preset's day, early afternoon at its site
    lon = state.observer.lon_deg
    when = state.time_utc.replace(hour=0, minute=0, second=0)
    when = when.fromtimestamp(when.timestamp() + (14.0 - lon / 15.0) * 3600.0, when.tzinfo)
    rows = []
    with daemon(work, args.preset) as control, ControlClient.connect(control) as client:
        (work / "sky.wxsky").write_text(f"# osgviewer_sky\ncontrol = {control}\nframe = enu\n")
        client.call("set_time", {"time_utc": when.strftime("%Y-%m-%dT%H:%M:%SZ"), "rate": 0.0})
        for camera in CAMERAS:
            rows.append(shoot(client, control, work, camera))
            print(f"camera {camera}: done")
    write_sheet(rows, args.out)
    print(f"wrote {args.out} ({len(rows)} cameras: osgviewer left, wxsky-host-snapshot right)")
    shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
