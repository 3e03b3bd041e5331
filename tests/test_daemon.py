"""The daemon end to end: a real process, real socket, real shared memory, real GL."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from daemon_harness import HANG_S, running_daemon

from wxsky import __version__
from wxsky.app.snapshot import take_snapshot
from wxsky.errors import WxskyError
from wxsky.host.client import RemoteError
from wxsky.host.reference import ReferenceHost
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.settings.presets import load_preset
from wxsky.weather.state import Source, WeatherPatch, WeatherState, parse_time_utc


@pytest.mark.gl
def test_status_json_reports_the_running_daemon(tmp_path: Path) -> None:
    with running_daemon(tmp_path) as d:
        # A rate needs two frames; on a loaded machine the first status may come before.
        deadline = time.monotonic() + HANG_S
        while True:
            out = subprocess.run(
                [sys.executable, "-m", "wxsky", "status", "--control", d.address, "--json"],
                capture_output=True,
                text=True,
                timeout=30,
                check=True,
            )
            status = json.loads(out.stdout)
            if status["frames_published"] >= 3 or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        assert status["version"] == __version__
        assert status["frames_published"] > 0
        assert status["uptime_s"] > 0
        assert status["fps"] > 0
        w = status["weather"]
        assert w["time_utc"].endswith("Z")
        assert w["observer"] == {"lat_deg": 47.4647, "lon_deg": 8.5492, "alt_m": 432.0}
        assert [lay["type"] for lay in w["layers"]] == ["cumulus"]  # fair-cumulus default
        assert {"alt_m", "dir_deg", "speed_mps", "gust_mps"} <= set(w["wind"][0])
        for key in ("visibility_m", "temperature_c", "dewpoint_c", "qnh_hpa"):
            assert isinstance(w[key], float)
        names = {i["name"]: i for i in status["inputs"]}
        assert names["control"]["ok"] is True
        assert {"name", "kind", "ok", "messages", "errors"} <= set(names["control"])
        human = subprocess.run(
            [sys.executable, "-m", "wxsky", "status", "--control", d.address],
            capture_output=True,
            text=True,
            timeout=30,
            check=True,
        ).stdout
        assert "cloud cumulus 3/8" in human


@pytest.mark.gl
def test_sigterm_stops_cleanly_and_removes_socket_and_segment(tmp_path: Path) -> None:
    with running_daemon(tmp_path) as d:
        assert Path(f"/dev/shm/{d.shm_name}").exists()
        code, _ = d.stop(signal.SIGTERM)
        assert code == 0, d.log()
        assert not d.socket_path.exists()
        assert not Path(f"/dev/shm/{d.shm_name}").exists()
        assert "stopped after" in d.log()


@pytest.mark.gl
def test_second_sigint_forces_exit_and_still_cleans_up(tmp_path: Path) -> None:
    # A long shutdown timeout would hold the first SIGINT; the second must not wait for it.
    with running_daemon(tmp_path) as d:
        d.proc.send_signal(signal.SIGINT)
        d.proc.send_signal(signal.SIGINT)
        code = d.proc.wait(timeout=HANG_S)
        assert code in (0, 130), d.log()  # 0 if the first SIGINT finished shutting down
        assert not Path(f"/dev/shm/{d.shm_name}").exists()
        assert not d.socket_path.exists()


@pytest.mark.gl
def test_set_camera_by_position_flies_near_the_site_and_moves_the_site_when_far(
    tmp_path: Path,
) -> None:
    with running_daemon(tmp_path) as d, d.client() as c:
        site = c.call("status")["weather"]["observer"]
        lat, lon = site["lat_deg"], site["lon_deg"]
        # 0.1° north (11 km): the camera moves there in the local frame, same site.
        cam = c.call("set_camera", {"lat_deg": lat + 0.1, "lon_deg": lon, "alt_m": 900.0})
        np.testing.assert_allclose(cam["position_m"], [0.0, 11_054.0, 900.0], atol=0.5)
        assert c.call("status")["weather"]["observer"]["lat_deg"] == pytest.approx(lat)
        # 3° north (330 km): that place becomes the site and the camera stands over it.
        cam = c.call("set_camera", {"lat_deg": lat + 3.0, "lon_deg": lon, "alt_m": 900.0})
        np.testing.assert_allclose(cam["position_m"], [0.0, 0.0, 900.0], atol=1e-6)
        moved = c.call("status")["weather"]["observer"]
        assert (moved["lat_deg"], moved["lon_deg"]) == pytest.approx((lat + 3.0, lon))


@pytest.mark.gl
def test_bad_control_input_is_answered_and_the_daemon_keeps_publishing(tmp_path: Path) -> None:
    with running_daemon(tmp_path) as d, d.client() as c:
        before = c.call("status")
        with pytest.raises(RemoteError, match="unknown command 'fly'"):
            c.call("fly", {})
        with pytest.raises(RemoteError, match=r"no-such-sky"):
            c.call("apply_preset", {"name": "no-such-sky"})
        with pytest.raises(RemoteError, match="METAR"):
            c.call("apply_metar", {"report": "this is not a metar %%"})
        with pytest.raises(RemoteError, match="set_camera: fov_deg"):
            c.call("set_camera", {"fov_deg": 500})
        with pytest.raises(RemoteError, match="set_time"):
            c.call("set_time", {"time_utc": "yesterday"})
        # Positions beyond the flat local frame, and params a command does not take.
        with pytest.raises(RemoteError, match=r"set_camera: position_m.*-1000000"):
            c.call("set_camera", {"position_m": [1e308, 0.0, 500.0]})
        with pytest.raises(RemoteError, match=r"set_camera: position_m"):
            c.call("set_camera", {"position_m": [0.0, 0.0, 2e5]})
        # Found by the control fuzzer: a position and half a geodetic one was an internal error.
        for both in ({"lat_deg": 0.0}, {"lat_deg": 1.0, "lon_deg": 2.0}, {"alt_m": 900.0}):
            with pytest.raises(RemoteError, match=r"^set_camera: give position_m or lat_deg"):
                c.call("set_camera", {"position_m": [0.0, 0.0, 500.0], **both})
        with pytest.raises(RemoteError, match=r"^set_camera: lat_deg and lon_deg go together"):
            c.call("set_camera", {"lon_deg": 2.0})
        for command in ("status", "scene", "export_textures"):
            with pytest.raises(RemoteError, match=rf"{command}: verbose: unknown key"):
                c.call(command, {"verbose": True})
        assert c.call("scene")["camera"]["position_m"][0] != 1e308
        # Raw garbage on a second connection: answered, that connection closed, others fine.
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as raw:
            raw.connect(str(d.socket_path))
            raw.sendall(b"\xc1\xc1 not msgpack")
            raw.settimeout(5)
            reply = raw.recv(4096)
            assert reply, "no error answer to garbage"
            assert b"msgpack" in reply.lower() or b"control message" in reply.lower()
        # Frames go on: wait for the next one, however long a busy machine takes.
        deadline = time.monotonic() + HANG_S
        while (after := c.call("status"))["frames_published"] <= before["frames_published"]:
            assert time.monotonic() < deadline, "no frame published after the bad input"
            time.sleep(0.05)
        # The last good state is kept: only the clock has moved on.
        assert {**after["weather"], "time_utc": None} == {**before["weather"], "time_utc": None}
        assert after["frames_published"] > before["frames_published"]
        control = next(i for i in after["inputs"] if i["name"] == "control")
        assert control["errors"] >= 5
        assert "rejected" in d.log()


@pytest.mark.gl
def test_apply_metar_and_preset_set_the_target_in_precedence_order(tmp_path: Path) -> None:
    with running_daemon(tmp_path) as d, d.client() as c:
        c.call("apply_metar", {"report": "LSZH 211250Z 24012G25KT 9999 FEW030 BKN080 18/09 Q1012"})
        status = c.call("status")
        t = status["target"]
        assert [lay["cover_oktas"] for lay in t["layers"]] == [2, 6]
        assert t["qnh_hpa"] == pytest.approx(1012.0)
        assert t["wind"][0]["speed_mps"] == pytest.approx(12 * 1852 / 3600, rel=1e-3)
        assert t["sources"]["layers"] == "metar"
        # The applied weather has not jumped there: it moves at the configured rates.
        assert status["weather"]["layers"] != t["layers"] and not status["settled"]
        c.call("apply_preset", {"name": "overcast-stratus"})
        t = c.call("status")["target"]
        assert [(lay["type"], lay["cover_oktas"]) for lay in t["layers"]] == [("stratus", 8)]
        assert t["sources"]["layers"] == "control"
        assert "layers" in c.call("release", {})["released"]
        assert c.call("status")["target"]["sources"]["layers"] == "metar"


@pytest.mark.gl
def test_reference_host_composites_the_same_picture_as_snapshot(tmp_path: Path) -> None:
    when = "2026-06-21T15:30:00Z"
    # Impostors of 128 texels (conftest.py GL_RING_PX), not the default 512, in both pictures
    # alike (the daemon's config and the snapshot's settings): a sixteenth of each ring's fill.
    ring = "[scene]\nring_texture_px = 128\n"
    with (
        running_daemon(tmp_path, extra_config="[clock]\nrate = 0.0\n" + ring) as d,
        ReferenceHost.connect(d.address) as host,
    ):
        host.call("set_time", {"time_utc": when})
        host.call(
            "set_camera",
            {
                "heading_deg": 225.0,
                "pitch_deg": 18.0,
                "fov_deg": 70.0,
                "width": 320,
                "height": 180,
            },
        )
        start = host.reader.frame_number
        frame = host.wait_settled_frame(after=start + 2, timeout_s=HANG_S)
        assert frame.meta.camera.width_px == 320 and not frame.meta.fading
        hosted = frame.composite()
        assert host.weather is not None

    state = WeatherState().apply(load_preset("fair-cumulus"))
    preset_utc = state.time_utc
    state = state.apply(WeatherPatch(source=Source.CONTROL, time_utc=parse_time_utc(when)))
    # The daemon started on the preset at its own time: by `when` the wind has blown the
    # clouds on, there as here.
    drift_s = (state.time_utc - preset_utc).total_seconds()
    camera = Camera(
        position_m=(0.0, 0.0, 434.0),
        heading_deg=225.0,
        pitch_deg=18.0,
        fov_deg=70.0,
        width_px=320,
        height_px=180,
    )
    shot = take_snapshot(state, camera, SceneSettings(ring_texture_px=128), drift_s=drift_s)
    assert hosted.shape == shot.image.shape
    diff = np.abs(hosted.astype(int) - shot.image.astype(int))
    assert diff.max() <= 1, f"max diff {diff.max()}, {np.mean(diff > 1):.4f} of values off"


@pytest.mark.gl
def test_daemon_writes_a_preview_png(tmp_path: Path) -> None:
    from wxsky.png import read_png

    preview = tmp_path / "preview"
    with running_daemon(tmp_path, args=("--preview", str(preview))) as d:
        deadline = time.monotonic() + HANG_S
        target = preview / "preview.png"
        while not target.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert target.exists(), d.log()
        image = read_png(target)
        assert image.shape == (540, 960, 4)
        # A daytime sky with cumulus: blue above, brighter cloud pixels somewhere.
        top = image[:60].reshape(-1, 4).astype(int)
        assert (top[:, 2] > top[:, 0]).mean() > 0.5
        assert image[..., :3].std() > 5


# No GL: no daemon at all.
def test_client_reports_a_missing_daemon(tmp_path: Path) -> None:
    from wxsky.host.client import ControlClient

    with pytest.raises(WxskyError, match="cannot connect"):
        ControlClient.connect(f"unix:{tmp_path / 'nobody.sock'}")


@pytest.mark.gl
def test_frame_notifications_say_whether_the_camera_is_in_cloud(tmp_path: Path) -> None:
    with running_daemon(tmp_path) as d, d.client() as c:
        c.subscribe(["frame"])
        note = c.next_notification(timeout_s=HANG_S)
        while note is not None and note.method != "frame":
            note = c.next_notification(timeout_s=HANG_S)
        assert note is not None
        # On the ground under fair cumulus: out of cloud, so no in-cloud visibility.
        assert note.params["in_cloud"] is False
        assert note.params["in_cloud_visibility_m"] is None


def test_frame_notification_times_are_iso_8601_in_every_year() -> None:
    from datetime import UTC, datetime

    from wxsky.app.daemon import _frame_time
    from wxsky.weather.state import parse_time_utc

    # The clock's range (1900..2199) is all a frame can carry; year 857 only for the digits.
    assert _frame_time(datetime(857, 1, 2, 3, 4, 5, 6, tzinfo=UTC)).startswith("0857-01-02T")
    for t in (
        datetime(1900, 1, 2, 3, 4, 5, 6, tzinfo=UTC),
        datetime(2026, 6, 21, 12, tzinfo=UTC),
        datetime(2199, 12, 31, 23, 59, 59, 999_999, tzinfo=UTC),
    ):
        text = _frame_time(t)
        assert text.endswith("Z") and parse_time_utc(text) == t, text
