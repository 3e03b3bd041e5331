#!/usr/bin/env python3
"""The web instructor station as a browser shows it (issue 46): PNG screenshots for
docs/gallery/ and the README.

    .venv/bin/python tools/gallery/web_station.py [--out-dir docs/gallery]

Starts a daemon with the station on loopback, a real METAR cycle replayed (Swiss stations,
26 July 2025 15:50Z, showers and thunderstorms; four stations blended) and a serial cockpit
link whose line is pulled, so every panel has something real in it. Debian's Chromium,
driven by Selenium, takes two shots: a desktop window (web-station.png) and a tablet held
upright (web-station-tablet.png).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run as a script from a checkout
    sys.path.insert(0, str(ROOT))

from tools.gallery.chromium import chromium  # noqa: E402
from wxsky.host.client import ControlClient  # noqa: E402
from wxsky.protocols.nmea import sentence  # noqa: E402

FEED = ROOT / "tests" / "data" / "metar" / "noaa_cycle_2025-07-26_okay_weather_HEAD1500.txt.gz"
REPLAY = "2025-07-26T16:05:00Z"
SHOTS = (("web-station.png", 1600, 1250), ("web-station-tablet.png", 834, 1194))


def wait(check: Any, what: str, timeout_s: float = 120.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(0.1)
    raise SystemExit(f"timed out waiting for {what}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--out-dir", type=Path, default=ROOT / "docs" / "gallery", help="where the PNGs go"
    )
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        sock, cfg, device = tmp / "wx.sock", tmp / "wxsky.toml", tmp / "ttyUSB-panel"
        master, slave = os.openpty()
        device.symlink_to(os.ttyname(slave))
        args.out_dir.mkdir(parents=True, exist_ok=True)
        cfg.write_text(
            f'[output]\nshm_name = "wxsky-web-gallery-{uuid.uuid4().hex[:8]}"\n'
            "[camera]\nheading_deg = 230.0\npitch_deg = 8.0\n"
            "[metar]\nblend_stations = 4\n"
            '[web]\nlisten = "127.0.0.1:0"\n'
        )
        env = dict(os.environ, XDG_CONFIG_HOME=str(tmp / "config"))
        cmd = [sys.executable, "-m", "wxsky", "run", "--config", str(cfg)]
        cmd += ["--control", f"unix:{sock}", "--serial", str(device)]
        cmd += ["--metar-feed", str(FEED), "--replay", REPLAY]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        try:
            wait(sock.exists, "the daemon's socket")
            with ControlClient.connect(f"unix:{sock}") as client:
                url = wait(lambda: client.call("status").get("web", {}).get("url"), "the url")
                os.write(master, sentence("WIMWV,230.0,T,6.0,M,A"))
                time.sleep(1.0)
                os.close(master)  # the cable pulled: the page shows the link down
                os.close(slave)
                wait(lambda: client.call("status")["frames_published"] > 100, "frames")
                # The sky whole: the first ring built and on show.
                wait(lambda: client.call("scene")["ring"] is not None, "the first ring", 600.0)
            for name, width, height in SHOTS:
                driver = chromium(tmp / f"chromium-{width}", width, height)
                try:
                    driver.get(url)
                    time.sleep(6.0)  # pictures, views, the station map
                    out = args.out_dir / name
                    if not driver.save_screenshot(str(out)):
                        print(f"web_station: error: could not write {out}", file=sys.stderr)
                        return 1
                    print(f"wrote {out}")
                finally:
                    driver.quit()
        finally:
            proc.terminate()
            proc.wait(30)
    return 0


if __name__ == "__main__":
    sys.exit(main())
