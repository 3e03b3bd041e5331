#!/usr/bin/env python3
"""FlightGear and wxsky coupled, side by side (issue 18): starts fgfs (headless, through
plugins/flightgear/fgfs-with-wxsky) and `wxsky run` following its aircraft and writing it the
weather, changes the weather mid-flight, and every `--every-s` seconds saves FlightGear's own
screenshot (its `--httpd` server's /screenshot) beside wxsky's composite for FlightGear's
camera at that moment (the daemon's preview). Needs FlightGear installed.

    .venv/bin/python tools/gallery/flightgear_demo.py --out docs/gallery/flightgear.png \\
        [--preset fair-cumulus --then overcast-stratus --seconds 60 --every-s 10]
"""

from __future__ import annotations

import argparse
import io
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

from wxsky.host.client import ControlClient
from wxsky.png import read_png, write_png

ROOT = Path(__file__).resolve().parents[2]
LAUNCHER = ROOT / "plugins" / "flightgear" / "fgfs-with-wxsky"
TILE = (480, 270)


def free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def fit(rgb: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Nearest-neighbour resample to (width, height): enough for a side-by-side sheet."""
    h, w = rgb.shape[:2]
    ys = (np.arange(size[1]) * h // size[1]).clip(0, h - 1)
    xs = (np.arange(size[0]) * w // size[0]).clip(0, w - 1)
    return rgb[ys][:, xs]


def screenshot(httpd: int) -> np.ndarray | None:
    """FlightGear's own picture, (H, W, 3), or None when it does not answer."""
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{httpd}/screenshot", timeout=30) as r:
            data = r.read()
    except OSError:
        return None
    from PIL import Image  # matplotlib's dependency: a dev tool's, not wxsky's

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "gallery" / "flightgear.png")
    parser.add_argument("--preset", default="fair-cumulus")
    parser.add_argument("--then", default="overcast-stratus", help="applied half way")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--every-s", type=float, default=10.0)
    args = parser.parse_args()
    if shutil.which("fgfs") is None and not Path("/usr/games/fgfs").exists():
        print("flightgear_demo: fgfs is not installed (apt-get install flightgear xvfb dbus)")
        return 1
    telnet, httpd = free_port(socket.SOCK_STREAM), free_port(socket.SOCK_STREAM)
    pose = free_port(socket.SOCK_DGRAM)
    work = Path(tempfile.mkdtemp(prefix="wxsky-fg-demo-"))
    (work / "wxsky.toml").write_text(
        "[preview]\ninterval_s = 1.0\n[output]\nmax_width = 960\nmax_height = 540\n"
        '[flightgear]\nclock = "flightgear"\n'  # FlightGear's time of day, wxsky's sun
        # The change comes through wxsky's transition; eight times the default cover rate
        # lets the sheet's half minute show all of it.
        "[transition]\ncover_oktas_per_min = 16.0\n"
    )
    sock = work / "wx.sock"
    daemon = subprocess.Popen(
        [sys.executable, "-m", "wxsky", "run", "--config", str(work / "wxsky.toml"),
         "--control", f"unix:{sock}", "--preset", args.preset, "--preview", str(work),
         "--flightgear", f"tcp:127.0.0.1:{telnet}",
         "--flightgear-pose", f"udp:127.0.0.1:{pose}"],
        stdout=(work / "wxsky.log").open("w"), stderr=subprocess.STDOUT, start_new_session=True,
    )  # fmt: skip
    fgfs = subprocess.Popen(
        [str(LAUNCHER), "--headless", "--telnet", str(telnet), "--pose-port", str(pose),
         "--", f"--httpd={httpd}", "--timeofday=noon"],
        stdout=(work / "fgfs.log").open("w"), stderr=subprocess.STDOUT, start_new_session=True,
    )  # fmt: skip
    rows = []
    try:
        deadline = time.monotonic() + 240.0
        while time.monotonic() < deadline:
            time.sleep(1.0)
            if not sock.exists():
                continue
            with ControlClient.connect(f"unix:{sock}") as c:
                inputs = {i["name"]: i for i in c.call("status")["inputs"]}
            if inputs.get("flightgear:pose", {}).get("messages", 0) > 0:
                break
        else:
            print(f"flightgear_demo: no pose from fgfs; logs in {work}")
            return 1
        print("coupled: fgfs sends its pose, wxsky follows")
        start = time.monotonic()
        changed = False
        while time.monotonic() - start < args.seconds:
            t = time.monotonic() - start
            if not changed and t >= args.seconds / 2.0:
                with ControlClient.connect(f"unix:{sock}") as c:
                    c.call("apply_preset", {"name": args.then})
                changed = True
                print(f"{t:.0f} s: applied {args.then}")
            time.sleep(2.0)  # the preview catches up with the camera
            fg = screenshot(httpd)
            ours = read_png(work / "preview.png")[..., :3]
            left = fit(fg, TILE) if fg is not None else np.zeros((TILE[1], TILE[0], 3), np.uint8)
            gap = np.full((TILE[1], 4, 3), 255, np.uint8)
            rows.append(np.concatenate([left, gap, fit(ours, TILE)], axis=1))
            print(f"{t:.0f} s: {'FlightGear' if fg is not None else 'no FlightGear picture'}"
                  " and wxsky saved")  # fmt: skip
            time.sleep(max(0.0, args.every_s - 2.0))
    finally:
        for proc in (fgfs, daemon):
            try:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(30)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                os.killpg(proc.pid, signal.SIGKILL)
    if not rows:
        return 1
    sheet = np.concatenate([np.pad(r, ((0, 4), (0, 0), (0, 0)), constant_values=255) for r in rows])
    rgba = np.concatenate([sheet, np.full((*sheet.shape[:2], 1), 255, np.uint8)], axis=2)
    write_png(args.out, rgba)
    print(f"wrote {args.out} ({rgba.shape[1]}x{rgba.shape[0]}): FlightGear left, wxsky right")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
