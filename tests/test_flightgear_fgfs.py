"""wxsky and a real FlightGear, both ways (issue 18): fgfs started headless by the launcher
streams its aircraft and view to wxsky's pose receiver, and wxsky's weather written to its
props server stays there (FlightGear's own weather is off) and reaches the flight model's
wind. Skips where fgfs is not installed (CI need not install 3 GB)."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

from wxsky.inputs.flightgear_link import FlightGearPose, FlightGearWeather
from wxsky.protocols.flightgear import FgPose
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

ROOT = Path(__file__).resolve().parents[1]
LAUNCHER = ROOT / "plugins" / "flightgear" / "fgfs-with-wxsky"
FGFS = shutil.which("fgfs") or ("/usr/games/fgfs" if Path("/usr/games/fgfs").exists() else None)

pytestmark = pytest.mark.skipif(
    FGFS is None or shutil.which("xvfb-run") is None or shutil.which("dbus-run-session") is None,
    reason="FlightGear is not installed (apt-get install flightgear xvfb dbus)",
)


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _get(port: int, paths: list[str]) -> dict[str, str]:
    """Read properties through FlightGear's props server."""
    with socket.create_connection(("127.0.0.1", port), 5) as s:
        s.settimeout(20)
        s.sendall(b"data\r\n")
        out = {}
        for path in paths:
            s.sendall(f"get {path}\r\n".encode())
            buf = b""
            while not buf.endswith(b"\n"):
                chunk = s.recv(4096)
                if not chunk:
                    break
                buf += chunk
            out[path] = buf.decode().strip()
        return out


def test_flightgear_drives_the_camera_and_wxsky_drives_its_weather(tmp_path: Path) -> None:
    telnet, pose_port = _free_port(socket.SOCK_STREAM), _free_port(socket.SOCK_DGRAM)
    poses: list[FgPose] = []
    log = (tmp_path / "fgfs.log").open("w")
    with FlightGearPose("127.0.0.1", pose_port, poses.append) as pose:
        proc = subprocess.Popen(
            [
                str(LAUNCHER),
                "--headless",
                "--telnet",
                str(telnet),
                "--pose-port",
                str(pose_port),
                "--heading-deg",
                "80",
            ],
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            env={**os.environ, "FGFS": str(FGFS)},
        )
        try:
            deadline = time.monotonic() + 240.0
            while not poses and time.monotonic() < deadline and proc.poll() is None:
                time.sleep(0.5)
            assert poses, f"no pose from fgfs (exit {proc.poll()}; see {tmp_path}/fgfs.log)"
            first = poses[0]
            # Over Honolulu, as launched; its clock is today's UTC.
            assert abs(first.lat_deg - 21.3245) < 0.05 and abs(first.lon_deg + 157.9251) < 0.05
            assert abs(((first.heading_deg - 80.0) + 180.0) % 360.0 - 180.0) < 5.0
            assert 1.0 <= first.fov_deg <= 170.0
            assert abs(first.time_utc.year - time.gmtime().tm_year) <= 1
            # wxsky's weather in.
            state = WeatherState().apply(load_preset("thunderstorm"))
            with FlightGearWeather("127.0.0.1", telnet, min_interval_s=0.5) as fg:
                fg.offer(state)
                deadline = time.monotonic() + 60.0
                while fg.stats.messages == 0 and time.monotonic() < deadline:
                    time.sleep(0.5)
                assert fg.stats.ok and fg.stats.messages > 20, fg.stats.to_dict()
                # FlightGear's basic weather would revert cloud layers within ~12 s: wait
                # past that, then read back.
                time.sleep(15.0)
                got = _get(
                    telnet,
                    [
                        "/environment/clouds/layer[0]/coverage",
                        "/environment/clouds/layer[2]/coverage",
                        "/environment/visibility-m",
                        "/environment/config/enabled",
                        "/fdm/jsbsim/atmosphere/wind-north-fps",
                    ],
                )
            assert got["/environment/clouds/layer[0]/coverage"] == "scattered"
            assert got["/environment/clouds/layer[2]/coverage"] == "broken"
            assert float(got["/environment/visibility-m"]) == pytest.approx(3000.0)
            assert got["/environment/config/enabled"] in ("false", "0")
            # 17.5 kt from 280 blows toward 100: a northward component of -5.1 ft/s, which
            # the c172p's JSBSim model feels.
            assert float(got["/fdm/jsbsim/atmosphere/wind-north-fps"]) == pytest.approx(
                -5.1, abs=1.0
            )
            assert pose.stats.errors == 0 or pose.stats.messages > 10 * pose.stats.errors
        finally:
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(10)
            log.close()
