"""`wxsky-host-demo` (plugins/host-c/apps): a host with its own terrain flies a camera path
against a running daemon and composites the clouds with its depth buffer. Its pictures are
checked here: the ridge in front of the far clouds hides them, the near layer's clouds stay in
front, and every frame is drawn for the camera the host sent."""

from __future__ import annotations

import re
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from daemon_harness import RunningDaemon, running_daemon
from host_kit import gl_program, gl_sanitizer_env, host_kit, host_kit_sanitized  # noqa: F401

from wxsky.host.compositor import stretch
from wxsky.png import read_png

pytestmark = pytest.mark.gl

DEMO = "wxsky-host-demo"
W, H = 320, 180
# Late afternoon: the sun in the west-south-west, the clouds lit from the side.
WHEN = "2026-07-08T16:30:00Z"


@pytest.fixture(scope="module")
def daemon(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningDaemon]:
    folder = tmp_path_factory.mktemp("demo")
    # The demo asks for its own size; 128-texel impostors, as the GL tests' (conftest.py
    # GL_RING_PX), not the default 512: a sixteenth of the ring's fill for every rebuild.
    small = f"[camera]\nwidth = {W}\nheight = {H}\n[scene]\nring_texture_px = 128\n"
    with running_daemon(folder, small, args=("--preset", "scattered-cumulus")) as d:
        yield d


def _run(tool: Path, d: RunningDaemon, *args: str, env: dict[str, str] | None = None) -> str:
    proc = subprocess.run(
        [str(tool), "--control", d.address, "--size", f"{W}x{H}", "--time", WHEN, *args],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    if proc.returncode == 2:
        pytest.skip(proc.stderr.strip())
    assert proc.returncode == 0, proc.stderr + d.log()[-2000:]
    return proc.stdout


def _f(image: np.ndarray) -> np.ndarray:
    return image.astype(np.float64) / 255.0


def test_the_ridge_hides_the_far_clouds_and_near_clouds_stay_in_front(
    daemon: RunningDaemon,
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    tool = gl_program(host_kit, DEMO)
    debug = tmp_path / "debug"
    debug.mkdir()
    strip = tmp_path / "strip.png"
    out = _run(
        tool,
        daemon,
        "--frames",
        "2",
        "--out",
        str(strip),
        "--debug-out",
        str(debug),
        "--debug-frame",
        "1",
    )
    assert f"wrote {strip} ({2 * W + 4}x{H}, 2 frames)" in out
    # Each frame was the daemon's frame for the camera the demo sent, along its path north.
    norths = [float(m) for m in re.findall(r"camera \(0, (-?\d+), \d+\) m", out)]
    assert norths == [-1300.0, 3000.0]
    pic = {
        n: read_png(debug / f"{n}.png")
        for n in ("terrain", "distance", "clouds", "near", "sky", "final")
    }
    assert read_png(strip).shape == (H, 2 * W + 4, 4)
    # The final frame is the strip's second picture.
    assert np.array_equal(read_png(strip)[:, W + 4 :], pic["final"])

    ground = pic["terrain"][..., 3] == 255
    distance_m = (pic["distance"][..., 0] + pic["distance"][..., 1] / 255.0) * 100.0
    # Terrain nearer than any ring quad can be (the ring radius, 8 km, less the 15 % the camera
    # may stray from the ring's centre, at the octagon's flat sides): the ridge, 4 km ahead.
    ridge = ground & (distance_m < 6000.0)
    assert ridge.sum() > 0.1 * W * H
    # Without the terrain, ring clouds stand where the ridge is: the clouds picture differs
    # from the bare sky there.
    # (0.06: far clouds fade into the haze, their detail too, docs/cloud-form.md.)
    behind = ridge & (np.abs(_f(pic["clouds"]) - _f(pic["sky"]))[..., :3].sum(axis=-1) > 0.06)
    assert behind.sum() > 500, behind.sum()
    # With it, the ridge hides them: there the picture is the terrain with only the near
    # layer over it (premultiplied over), to rounding.
    near = stretch(pic["near"], W, H)  # drawn at a fraction of the picture; GL stretches it
    expected = near[..., :3] + (1.0 - near[..., 3:]) * _f(pic["terrain"])[..., :3]
    # (To rounding: GL stretches the 8-bit near layer and rounds once more than this does.)
    diff = np.abs(expected - _f(pic["final"])[..., :3])[ridge]
    assert diff.max() <= 2.0 / 255.0, diff.max() * 255
    # The clouds in front (the near layer) stay in front of the terrain.
    in_front = ground & (near[..., 3] > 0.5)
    if in_front.any():
        assert np.abs(_f(pic["final"]) - _f(pic["terrain"]))[in_front][..., :3].max() > 0.05
    # Above the terrain the picture is the clouds picture (sky, ring and near, no terrain).
    sky = ~ground
    assert np.abs(_f(pic["final"]) - _f(pic["clouds"]))[sky][..., :3].max() <= 1.5 / 255.0


def test_the_demo_is_clean_under_the_sanitizers_and_says_what_is_wrong(
    daemon: RunningDaemon,
    host_kit_sanitized: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    tool = gl_program(host_kit_sanitized, DEMO)
    strip = tmp_path / "s.png"
    _run(tool, daemon, "--frames", "1", "--out", str(strip), env=gl_sanitizer_env())
    assert read_png(strip).shape == (H, W, 4)
    for args, code, says in [
        (["--frames", "0"], 64, "--frames 0"),
        (["--debug-frame", "3"], 64, "go together"),
        (["--size", "8x8"], 64, "--size 8x8"),
    ]:
        proc = subprocess.run(
            [str(tool), "--control", daemon.address, "--out", str(strip), *args],
            capture_output=True,
            text=True,
            timeout=60,
            env=gl_sanitizer_env(),
        )
        assert proc.returncode == code, proc.stderr
        assert proc.stderr.startswith(f"{DEMO}: error: ") and says in proc.stderr


def test_the_demo_flies_live_in_a_window(
    daemon: RunningDaemon,
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """--window on a real X server (Xvfb): the path flown live, each frame compositing the
    newest frame the daemon has for the cameras it keeps sending."""
    tool = gl_program(host_kit, DEMO)
    if shutil.which("xvfb-run") is None:
        pytest.skip("no xvfb-run for a display (Debian: xvfb xauth; tools/setup installs them)")
    shot = tmp_path / "window.png"
    proc = subprocess.run(
        [
            "xvfb-run",
            "-a",
            "-s",
            "-screen 0 1024x768x24",
            str(tool),
            "--control",
            daemon.address,
            "--window",
            "--duration-s",
            "3",
            "--path-s",
            "6",
            "--size",
            f"{W}x{H}",
            "--out",
            str(shot),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    if "has no GLFW" in proc.stderr:
        pytest.skip(proc.stderr.strip())
    assert proc.returncode == 0, proc.stderr
    m = re.search(r"flew (\d+) frames in [\d.]+ s, (\d+) of them with a new frame", proc.stdout)
    assert m is not None, proc.stdout
    assert int(m.group(1)) >= 10 and int(m.group(2)) >= 5
    image = read_png(shot)
    assert image.shape == (H, W, 4)
    # Sky at the top (bluer than red), terrain at the bottom (greener or browner than blue):
    # the picture is the right way up and has both.
    top, bottom = image[: H // 8, :, :3].astype(int), image[-H // 8 :, :, :3].astype(int)
    assert (top[..., 2] - top[..., 0]).mean() > 20
    assert (bottom[..., 1] - bottom[..., 2]).mean() > 5
