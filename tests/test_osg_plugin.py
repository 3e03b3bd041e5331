"""The OpenSceneGraph kit (plugins/osg): wxsky's sky in an OSG scene through the osgDB plugin.

`wxsky-osg-snapshot` renders the example terrain with the plugin offscreen, as any OSG
application that loads a `.wxsky` file would; `wxsky-host-snapshot` composites the same
daemon's frame for the same camera with the C host kit alone. Where no terrain covers the sky
the two pictures must agree (mean within 2/255), where terrain covers it the plugin must leave
the terrain as the scene drew it (within 1/255), and the camera the node sends must be OSG's
(within 0.01 degrees and 0.1 m, read back from the daemon's status)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from daemon_harness import RunningDaemon, running_daemon
from host_kit import gl_program, gl_sanitizer_env, host_kit  # noqa: F401
from osg_kit import KIT, TOOL, osg_kit, osg_kit_sanitized  # noqa: F401

from tools.gallery.flightgear_sky import stable_screen
from tools.gallery.osgviewer_sky import view_path
from tools.generate.osg_terrain import write_osg
from wxsky.png import read_png, write_png
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

pytestmark = pytest.mark.gl

PRESETS = ("scattered-cumulus", "overcast-stratus")
SIZE = "320x180"
TERRAIN = KIT / "examples" / "terrain.osg"
# As test_host_c_snapshot: whole impostors, no cross-fade, 10 frames/s; and (in [output],
# where the harness puts the first lines) the near layer's depth. The impostors are of 128
# texels (conftest.py GL_RING_PX), not 256: both pictures here are of the one daemon frame,
# so their agreement does not depend on the ring's resolution, and each rebuild (a new time,
# a moved camera) fills a quarter as much.
PACING = "near_depth = true\n[scene]\nring_slice_ms = 0\nring_fade_s = 0\nring_texture_px = 128\n"
TICK = "tick_hz = 10.0"
# The tools' own wait for a settled frame (their default 60 s was reached on a loaded 2-core
# CI machine with nothing wrong but the load), and ours for them: only a hang reaches either.
WAIT_S = 300
HANG_S = WAIT_S + 60.0

# (north, east offset of the camera from the site in degrees, alt_m, heading, pitch, roll):
# north over the ridge (the terrain covers the lower part), up to the south (sky only), and
# from 2 km north-east, rolled, along the ridge.
CAMERAS = {
    "ridge": ((0.0, 0.0), 300.0, 0.0, 6.0, 0.0),
    "up": ((0.0, 0.0), 300.0, 180.0, 25.0, 0.0),
    "moved": ((0.02, 0.03), 350.0, 300.0, 3.0, 10.0),
}


@pytest.fixture(scope="module", params=PRESETS)
def daemon(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[tuple[str, RunningDaemon]]:
    preset = request.param
    with running_daemon(
        tmp_path_factory.mktemp(preset),
        extra_config=PACING,
        args=("--preset", preset),
        daemon_config=TICK,
    ) as d:
        yield preset, d


def _noon(preset: str) -> tuple[datetime, float, float]:
    """The preset's day at 12:00 local solar time, and its site."""
    state = WeatherState().apply(load_preset(preset))
    obs = state.observer
    midnight = state.time_utc.replace(hour=0, minute=0, second=0, microsecond=0)
    noon = midnight + timedelta(hours=12.0 - obs.lon_deg / 15.0)
    return noon, obs.lat_deg, obs.lon_deg


def _run(args: list[str], env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """One of the kits' snapshot tools, waiting as long as only a hang would."""
    args = [*args, "--timeout-s", str(WAIT_S)]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=HANG_S, env=env)
    if proc.returncode == 2:
        pytest.skip(proc.stderr.strip())
    return proc


def _json_line(stdout: str, prefix: str) -> dict[str, float]:
    for line in stdout.splitlines():
        if line.startswith(prefix):
            return json.loads(line[len(prefix) :])  # type: ignore[no-any-return]
    raise AssertionError(f"no {prefix!r} line in {stdout!r}")


def _camera_args(preset: str, view: str) -> list[str]:
    noon, lat, lon = _noon(preset)
    (dn, de), alt, heading, pitch, roll = CAMERAS[view]
    return [
        "--time",
        noon.strftime("%Y-%m-%dT%H:%M:%SZ"),
        "--lat",
        f"{lat + dn:.6f}",
        "--lon",
        f"{lon + de:.6f}",
        "--alt-m",
        f"{alt:g}",
        "--heading-deg",
        f"{heading:g}",
        "--pitch-deg",
        f"{pitch:g}",
        "--roll-deg",
        f"{roll:g}",
        "--fov-deg",
        "70",
        "--size",
        SIZE,
    ]


def _diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(a[..., :3].astype(int) - b[..., :3].astype(int))


def _same_camera(got: dict[str, float], want: dict[str, float]) -> None:
    for k in ("heading_deg", "pitch_deg", "roll_deg", "fov_deg"):
        turn = (got[k] - want[k] + 180.0) % 360.0 - 180.0
        assert abs(turn) <= 0.01, (k, got, want)
    gap = np.linalg.norm(np.subtract(got["position_m"], want["position_m"]))
    assert gap <= 0.1, (got, want)
    assert (got["width"], got["height"]) == (want["width"], want["height"])


@pytest.mark.parametrize("view", sorted(CAMERAS))
def test_the_plugins_picture_is_the_host_kits_and_leaves_the_terrain(
    daemon: tuple[str, RunningDaemon],
    view: str,
    osg_kit: Path,  # noqa: F811
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    preset, d = daemon
    args = _camera_args(preset, view)
    osg_png, bare_png, host_png = (tmp_path / f"{n}.png" for n in ("osg", "bare", "host"))
    proc = _run(
        [
            str(osg_kit / TOOL),
            "--control",
            d.address,
            *args,
            "--scene",
            str(TERRAIN),
            "--out",
            str(osg_png),
            "--bare-out",
            str(bare_png),
        ]
    )
    assert proc.returncode == 0, proc.stderr + d.log()[-2000:]
    asked, sent = _json_line(proc.stdout, "asked: "), _json_line(proc.stdout, "camera: ")
    # The camera the node took from OSG and sent is the one the daemon now has.
    with d.client() as c:
        status_camera = c.call("status")["camera"]
    _same_camera(status_camera, asked)
    _same_camera(sent, asked)
    assert sent["near_distance_m"] >= 0.0  # the stream said where `near` goes

    # The host kit's picture of the daemon's camera as the node left it, at the same moment.
    when = args[args.index("--time") + 1]
    tool = gl_program(host_kit, "wxsky-host-snapshot")
    host = _run([str(tool), "--control", d.address, "--time", when, "--out", str(host_png)])
    assert host.returncode == 0, host.stderr

    osg, bare, ref = read_png(osg_png), read_png(bare_png), read_png(host_png)
    assert osg.shape == bare.shape == ref.shape == (180, 320, 4)
    terrain = bare[..., 3] > 0
    sky = ~terrain
    if view == "up":
        assert not terrain.any()
    else:
        assert 0.05 < terrain.mean() < 0.8, f"{view}: terrain covers {terrain.mean():.0%}"
    sky_mean = float(_diff(osg, ref)[sky].mean())
    assert sky_mean <= 2.0, f"{preset} {view}: the sky differs by {sky_mean:.2f}/255"
    if terrain.any():
        # The near layer's depth is a quarter of the picture each way: along a ridge's skyline
        # a few pixels of cloud may still cross the crest (0.13 % of the terrain here).
        changed = _diff(osg, bare)[terrain].max(axis=-1)
        kept = float((changed <= 1).mean())
        assert float(changed.mean()) <= 1.0, f"{preset} {view}: terrain changed {changed.mean()}"
        assert kept >= 0.995, f"{preset} {view}: {1 - kept:.2%} of the terrain changed"
        # and the plugin drew: the host's own picture there is its sky's ground, not terrain
        assert float(_diff(ref, bare)[terrain].mean()) > 4.0


# One preset is enough here (the suite's time): what is tested is the camera's conversion.
@pytest.mark.parametrize("daemon", ["overcast-stratus"], indirect=True)
def test_a_whole_earth_scene_sends_and_draws_the_same_camera(
    daemon: tuple[str, RunningDaemon],
    osg_kit: Path,  # noqa: F811
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """FlightGear's frame: earth-centred WGS84 metres. The node turns OSG's camera into
    latitude, longitude, height and angles in the local frame, and draws in the daemon's."""
    preset, d = daemon
    args = _camera_args(preset, "moved")
    osg_png, host_png = tmp_path / "osg.png", tmp_path / "host.png"
    proc = _run(
        [
            str(osg_kit / TOOL),
            "--control",
            d.address,
            *args,
            "--frame",
            "geocentric",
            "--out",
            str(osg_png),
        ]
    )
    assert proc.returncode == 0, proc.stderr + d.log()[-2000:]
    asked = _json_line(proc.stdout, "asked: ")
    with d.client() as c:
        _same_camera(c.call("status")["camera"], asked)
    when = args[args.index("--time") + 1]
    tool = gl_program(host_kit, "wxsky-host-snapshot")
    host = _run([str(tool), "--control", d.address, "--time", when, "--out", str(host_png)])
    assert host.returncode == 0, host.stderr
    mean = float(_diff(read_png(osg_png), read_png(host_png)).mean())
    assert mean <= 2.0, f"{preset}: geocentric picture differs by {mean:.2f}/255"


BAD_FILES = {
    "unknown-key.wxsky": (
        "frame = enu\ncolour = blue\n",
        "unknown-key.wxsky:2: unknown key 'colour'",
    ),
    "bad-address.wxsky": ("control = http://127.0.0.1/\n", "bad-address.wxsky:1: control"),
    "bad-frame.wxsky": ("frame = ecef\n", "bad-frame.wxsky:1: frame 'ecef' is not"),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_a_bad_wxsky_file_is_one_line_and_the_application_goes_on(
    name: str,
    osg_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    text, message = BAD_FILES[name]
    path = tmp_path / name
    path.write_text(text)
    out = tmp_path / "scene.png"
    # the .wxsky file as a scene OSG loads: the application renders on without a sky
    proc = _run(
        [
            str(osg_kit / TOOL),
            "--no-sky",
            "--scene",
            str(path),
            "--size",
            "64x36",
            "--out",
            str(out),
        ]
    )
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if "wxsky:" in ln]
    assert len(lines) == 1, proc.stderr
    assert message in lines[0] and str(tmp_path) in lines[0], lines[0]
    assert "nothing drawn" in lines[0]
    assert (read_png(out)[..., 3] == 0).all()  # the sky node drew nothing


def _watch(
    kit: Path, sky: Path, seconds: float, env: dict[str, str] | None = None
) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [
            str(kit / TOOL),
            "--sky",
            str(sky),
            "--watch-s",
            str(seconds),
            "--size",
            "160x90",
            "--alt-m",
            "300",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _status_until(
    proc: subprocess.Popen[str], ok: object, what: str, seen: list[dict[str, object]]
) -> dict[str, object]:
    """Reads the tool's status lines until `ok(status)`; fails on a hang or an early exit."""
    deadline = time.monotonic() + HANG_S
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            raise AssertionError(f"the host stopped before {what}: {proc.stderr.read()}")  # type: ignore[union-attr]
        if not line.startswith("{"):  # OSG's notices (a connection made) go to stdout too
            continue
        s = json.loads(line)
        seen.append(s)
        if ok(s):  # type: ignore[operator]
            return s  # type: ignore[no-any-return]
    raise AssertionError(f"no {what} within {HANG_S} s")


def test_an_absent_daemon_costs_the_host_nothing_and_is_said_once(
    osg_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    sky = tmp_path / "sky.wxsky"
    sky.write_text(f"control = unix:{tmp_path / 'nobody.sock'}\n")
    proc = _watch(osg_kit, sky, 3.0)
    out, err = proc.communicate(timeout=HANG_S)
    assert proc.returncode == 0, err
    statuses = [json.loads(ln) for ln in out.splitlines() if ln.startswith("{")]
    assert len(statuses) >= 4 and statuses[-1]["host_frames"] > statuses[0]["host_frames"]
    assert not any(s["connected"] for s in statuses)
    assert "WXSKY_ENOENT" in statuses[-1]["error"]
    said = [ln for ln in err.splitlines() if "nobody.sock" in ln]
    assert len(said) == 1, err  # once, not at every retry


def test_the_node_rides_out_a_stalled_and_a_restarted_daemon(
    osg_kit_sanitized: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """A daemon that stalls costs the host only stale clouds; one that restarts (another
    segment, its frames numbered from 0) is found again, and its frames drawn. The host is
    the sanitizers' build: the link thread's hang-up and reconnection under AddressSanitizer
    and UBSan too."""
    seen: list[dict[str, object]] = []
    sky = tmp_path / "sky.wxsky"
    (tmp_path / "a").mkdir()
    env = gl_sanitizer_env()
    with running_daemon(tmp_path / "a", args=("--preset", "scattered-cumulus")) as a:
        sky.write_text(f"control = {a.address}\n")
        proc = _watch(osg_kit_sanitized, sky, 3600.0, env=env)
        try:
            first = _status_until(proc, lambda s: s["frames_uploaded"] > 5, "frames", seen)
            a.pause()
            stalled = _status_until(
                proc,
                lambda s: s["host_frames"] > first["host_frames"] + 30,  # type: ignore[operator]
                "host frames while the daemon is stopped",
                seen,
            )
            later = _status_until(
                proc,
                lambda s: s["host_frames"] > stalled["host_frames"] + 30,  # type: ignore[operator]
                "more host frames",
                seen,
            )
            # the host drew on, from the last layers, uploading nothing new
            assert later["frames_uploaded"] == stalled["frames_uploaded"]
            assert later["frames_drawn"] > stalled["frames_drawn"]  # type: ignore[operator]
            a.resume()
            a.stop()
            _status_until(proc, lambda s: not s["connected"], "the hang-up", seen)
            (tmp_path / "a" / "wx.sock").unlink(missing_ok=True)
            with running_daemon(tmp_path / "a", args=("--preset", "overcast-stratus")) as b:
                assert b.address == a.address
                back = _status_until(
                    proc,
                    lambda s: (
                        s["connected"]
                        and s["error"] == ""
                        and s["frames_uploaded"] > later["frames_uploaded"] + 5
                    ),  # type: ignore[operator]
                    "frames from the restarted daemon",
                    seen,
                )
                # frames uploaded after the first daemon died are the second one's: numbered
                # by its own count (which, on a busy machine, may pass the first's)
                with b.client() as c:
                    published = c.call("status")["frames_published"]
                assert back["last_frame_number"] <= published  # type: ignore[operator]
        finally:
            proc.send_signal(signal.SIGKILL)
            _, err = proc.communicate()
    assert "ERROR: AddressSanitizer" not in err and "runtime error" not in err, err


def test_the_plugin_is_clean_under_the_sanitizers(
    osg_kit_sanitized: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """The node and the reader plugin under AddressSanitizer and UBSan: a picture with a
    daemon, a bad file."""
    env = gl_sanitizer_env()
    bad = tmp_path / "bad.wxsky"
    bad.write_text("nonsense\n")
    proc = _run(
        [
            str(osg_kit_sanitized / TOOL),
            "--no-sky",
            "--scene",
            str(bad),
            "--size",
            "64x36",
            "--out",
            str(tmp_path / "bad.png"),
        ],
        env=env,
    )
    assert proc.returncode == 0, proc.stderr
    assert "ERROR: AddressSanitizer" not in proc.stderr, proc.stderr
    (tmp_path / "d").mkdir()
    with running_daemon(tmp_path / "d", args=("--preset", "scattered-cumulus")) as d:
        out = tmp_path / "sky.png"
        proc = _run(
            [
                str(osg_kit_sanitized / TOOL),
                "--control",
                d.address,
                "--alt-m",
                "300",
                "--size",
                "160x90",
                "--scene",
                str(TERRAIN),
                "--out",
                str(out),
            ],
            env=env,
        )
        assert proc.returncode == 0, proc.stderr
        errors = proc.stderr
        # a host's loop that ends by itself, and cleanly (LeakSanitizer looks at the exit);
        # one that sees its daemon stall, go and come back runs under the sanitizers in
        # test_the_node_rides_out_a_stalled_and_a_restarted_daemon
        sky = tmp_path / "sky.wxsky"
        sky.write_text(f"control = {d.address}\n")
        watch = _watch(osg_kit_sanitized, sky, 2.0, env=env)
        try:
            _, err = watch.communicate(timeout=HANG_S)
        finally:
            if watch.poll() is None:
                watch.kill()
                watch.communicate()
    assert watch.returncode == 0, err
    for text in (errors, err):
        assert "ERROR: AddressSanitizer" not in text and "runtime error" not in text, text


def test_the_example_terrain_is_the_generators(tmp_path: Path) -> None:
    """plugins/osg/examples/terrain.osg is what tools/generate/osg_terrain.py writes."""
    out = tmp_path / "terrain.osg"
    write_osg(out)
    assert out.read_text() == TERRAIN.read_text()


def _inside(mask: np.ndarray, px: int) -> np.ndarray:
    """The pixels of `mask` at least `px` pixels from its edge (either way of a skyline
    rasterised by two programs, a pixel's doubt)."""
    out = mask.copy()
    for dy in range(-px, px + 1):
        for dx in range(-px, px + 1):
            out &= np.roll(np.roll(mask, dy, axis=0), dx, axis=1)
    return out


def _osgviewer_screen(
    viewer: str, env: dict[str, str], args: list[str], fb: Path, ready: Any, deadline: float
) -> np.ndarray:
    """One osgviewer run in the Xvfb whose screen is kept in `fb`: its screen once `ready()`
    and it has stood still."""
    app = subprocess.Popen(
        [viewer, *args], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    try:
        while not ready():
            assert time.monotonic() < deadline, "osgviewer never got ready"
            assert app.poll() is None, app.communicate()[1]
            time.sleep(0.2)
        return stable_screen(fb / "Xvfb_screen0", deadline, still_s=2.0)
    finally:
        app.terminate()
        app.wait(30)


# One preset is enough here (the suite's time): the overcast, whose base over the ridge is the
# harder case for the terrain.
@pytest.mark.parametrize("daemon", ["overcast-stratus"], indirect=True)
def test_osgviewer_shows_the_clouds_over_the_terrain(
    daemon: tuple[str, RunningDaemon],
    osg_kit: Path,  # noqa: F811
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """`osgviewer terrain.osg sky.wxsky` in a window (Xvfb, its screen kept in a file): the
    clouds where the host kit has them for the camera osgviewer sent; the terrain as
    `osgviewer terrain.osg` alone draws it."""
    viewer, xvfb = shutil.which("osgviewer"), shutil.which("Xvfb")
    if viewer is None or xvfb is None:
        pytest.skip("no osgviewer or Xvfb (apt-get install openscenegraph xvfb)")
    preset, d = daemon
    noon, _, _ = _noon(preset)
    when = noon.strftime("%Y-%m-%dT%H:%M:%SZ")
    with d.client() as c:
        c.call("set_time", {"time_utc": when, "rate": 0.0})
    w, h = 320, 180
    heading, pitch, eye = 0.0, 6.0, (0.0, 0.0, 300.0)
    (tmp_path / "view.path").write_text(view_path(heading, pitch, eye))
    (tmp_path / "sky.wxsky").write_text(f"control = {d.address}\nframe = enu\n")
    fb = tmp_path / "fb"
    fb.mkdir()
    display = f":{100 + os.getpid() % 800}"
    server = subprocess.Popen(
        [xvfb, display, "-screen", "0", f"{w}x{h}x24", "-fbdir", str(fb), "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    env = {**os.environ, "DISPLAY": display, "OSG_LIBRARY_PATH": str(osg_kit)}
    args = ["--window", "0", "0", str(w), str(h), "-p", str(tmp_path / "view.path")]
    deadline = time.monotonic() + HANG_S
    cam: dict[str, Any] = {}

    def settled() -> bool:  # osgviewer's camera reached the daemon, and its ring settled
        with d.client() as c:
            cam.update(c.call("status")["camera"])
            return (
                abs(cam["heading_deg"] - heading) < 0.01
                and abs(cam["pitch_deg"] - pitch) < 0.01
                and bool(np.allclose(cam["position_m"], eye, atol=0.1))
                and (cam["width"], cam["height"]) == (w, h)
                and not c.call("scene")["ring_busy"]
            )

    try:
        while not (fb / "Xvfb_screen0").exists():
            assert time.monotonic() < deadline and server.poll() is None, "Xvfb did not start"
            time.sleep(0.1)
        alone = _osgviewer_screen(viewer, env, [*args, str(TERRAIN)], fb, lambda: True, deadline)[
            :h, :w
        ]
        seen = _osgviewer_screen(
            viewer, env, [*args, str(TERRAIN), str(tmp_path / "sky.wxsky")], fb, settled, deadline
        )[:h, :w]
    finally:
        server.terminate()
        server.wait(30)
    opaque = np.full((h, w, 1), 255, np.uint8)
    write_png(tmp_path / "osgviewer.png", np.concatenate([seen, opaque], axis=-1))
    write_png(tmp_path / "terrain-alone.png", np.concatenate([alone, opaque], axis=-1))
    tool = gl_program(host_kit, "wxsky-host-snapshot")
    host = _run(
        [str(tool), "--control", d.address, "--time", when, "--out", str(tmp_path / "h.png")]
    )
    assert host.returncode == 0, host.stderr
    # where the terrain is: the scene alone, drawn by wxsky-osg-snapshot for that camera
    fov = f"{cam['fov_deg']:.9f}"
    bare = _run(
        [
            str(osg_kit / TOOL),
            "--no-sky",
            "--scene",
            str(TERRAIN),
            "--size",
            f"{w}x{h}",
            "--alt-m",
            "300",
            "--heading-deg",
            "0",
            "--pitch-deg",
            "6",
            "--fov-deg",
            fov,
            "--out",
            str(tmp_path / "bare.png"),
        ]
    )
    assert bare.returncode == 0, bare.stderr
    ref, scene = read_png(tmp_path / "h.png"), read_png(tmp_path / "bare.png")
    terrain = scene[..., 3] > 0
    assert 0.05 < terrain.mean() < 0.8
    sky = _inside(~terrain, 2)
    sky_mean = float(_diff(seen, ref)[sky].mean())
    assert sky_mean <= 2.0, f"{preset}: osgviewer's sky differs by {sky_mean:.2f}/255"
    # (under the overcast, whose base is 100 m over the ridge's crest, the cloud that hangs in
    # front of the crest is drawn over it in blocks of the depth layer's texels: 1.1 % here)
    changed = _diff(seen, alone)[_inside(terrain, 2)].max(axis=-1)
    kept = float((changed <= 1).mean())
    assert kept >= 0.98, f"{preset}: {1 - kept:.2%} of the terrain changed"


def test_the_scenes_terrain_is_shaded_through_the_nodes_shadow_map(
    daemon: tuple[str, RunningDaemon],
    osg_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """SkyNode::shadowStateSet gives a host's terrain shader the cloud-shadow map: the
    example terrain drawn with `--shadows` (colour x (0.35 + 0.65 T)) against the same camera
    without: broken sun and shade under scattered cumulus, shade nearly everywhere under an
    overcast, and never brighter than the terrain's own colour."""
    preset, d = daemon
    noon, lat, lon = _noon(preset)
    args = ["--control", d.address, "--time", noon.strftime("%Y-%m-%dT%H:%M:%SZ")]
    args += ["--lat", f"{lat:.6f}", "--lon", f"{lon:.6f}", "--alt-m", "900"]
    args += ["--heading-deg", "0", "--pitch-deg", "-30", "--fov-deg", "70", "--size", SIZE]
    args += ["--scene", str(TERRAIN)]
    lit, plain = tmp_path / "lit.png", tmp_path / "plain.png"
    for extra, out in ((["--shadows"], lit), ([], plain)):
        sky = str(tmp_path / "sky.png")
        proc = _run([str(osg_kit / TOOL), *args, *extra, "--bare-out", str(out), "--out", sky])
        assert proc.returncode == 0, proc.stderr + d.log()[-2000:]
    a, b = read_png(lit), read_png(plain)
    terrain = (a[..., 3] > 0) & (b[..., 3] > 0)
    assert terrain.mean() > 0.5
    ratio = (a[..., :3].astype(float) + 0.5) / (b[..., :3].astype(float) + 0.5)
    share = ratio[terrain].mean(axis=-1)
    assert float(share.max()) <= 1.05  # T <= 1: the map never brightens
    shaded = float((share < 0.9).mean())
    if preset == "scattered-cumulus":
        assert 0.02 < shaded < 0.9, f"{shaded:.0%} of the terrain in cloud shadow"
    else:
        assert shaded > 0.5, f"{shaded:.0%} of the terrain under the overcast's shadow"
