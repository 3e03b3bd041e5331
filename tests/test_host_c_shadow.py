"""The cloud-shadow map end to end: the daemon publishes it with its placement in the record
(docs/protocol.md §1.5, §3, §3.3), the Python reference host samples it and lights a ground
with it (wxsky/host/compositor.py), and the C kit's GL compositor gives the same through
WXSKY_GL_SHADOW_GLSL and wxsky_gl_shadow_bind (plugins/host-c, test program
wxsky_gl_shadow): on a synthetic segment whose map is known, and on a live daemon's frame."""

from __future__ import annotations

import contextlib
import os
import subprocess
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from daemon_harness import HANG_S, running_daemon
from host_kit import gl_program, gl_sanitizer_env, host_kit, host_kit_sanitized  # noqa: F401

from wxsky.app.frame_publish import frame_layer_specs
from wxsky.host.compositor import Ground, ShadowMap
from wxsky.host.reference import ReferenceHost, host_frame
from wxsky.output import shm
from wxsky.output.frame_meta import FrameMeta, ShadowPlacement
from wxsky.output.shm import FrameReader, FrameWriter
from wxsky.scene.camera import Camera
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

pytestmark = pytest.mark.gl

U8 = npt.NDArray[np.uint8]
F64 = npt.NDArray[np.float64]
# GL's bilinear weights are fixed point (8 bits on llvmpipe and most GPUs), and may be
# truncated rather than rounded: between two texels 255 levels apart that is up to one level
# along each axis of the 2 x 2 footprint, so two levels of 255 bound the difference (a CI run
# measured 1.03 at a shadow's edge). A texel or half-texel misplacement shows as tens.
LEVEL = 2.0 / 255.0


@pytest.fixture
def name() -> Iterator[str]:
    made = f"wxsky-hsh-{os.getpid()}-{uuid.uuid4().hex[:10]}"
    yield made
    with contextlib.suppress(FileNotFoundError):
        shm._shm_unlink(made)


def c_points(
    folder: Path, segment: str, points: F64, exe: str = "wxsky_gl_shadow", **env: str
) -> tuple[npt.NDArray[np.float32], str]:
    program = gl_program(folder, exe)
    src, out = folder / f"{segment}.f64", folder / f"{segment}.f32"
    np.ascontiguousarray(points, np.float64).tofile(src)
    try:
        proc = subprocess.run(
            [str(program), segment, str(out), "--points", str(src)],
            capture_output=True,
            text=True,
            timeout=120,
            env={**os.environ, **env} if env else None,
        )
        if proc.returncode == 2:
            pytest.skip(f"no headless GL context or float framebuffer: {proc.stdout.strip()}")
        assert proc.returncode == 0, proc.stdout + proc.stderr
        return np.fromfile(out, np.float32), proc.stdout
    finally:
        for path in (src, out):
            with contextlib.suppress(FileNotFoundError):
                path.unlink()


def c_ground(folder: Path, segment: str, shape: tuple[int, int], ground: Ground) -> U8:
    program = gl_program(folder, "wxsky_gl_shadow")
    out = folder / f"{segment}.rgba"
    looks = ["--ambient", repr(ground.ambient), "--rgb", ",".join(map(repr, ground.rgb))]
    try:
        proc = subprocess.run(
            [str(program), segment, str(out), "--ground", repr(ground.up_m), *looks],
            capture_output=True,
            text=True,
            timeout=120,
        )
        if proc.returncode == 2:
            pytest.skip(f"no headless GL context: {proc.stdout.strip()}")
        assert proc.returncode == 0, proc.stdout + proc.stderr
        h, w = shape
        return np.fromfile(out, np.uint8).reshape(h, w, 4)
    finally:
        with contextlib.suppress(FileNotFoundError):
            out.unlink()


def random_points(
    rng: np.random.Generator, centre: tuple[float, float, float], reach_m: float, n: int
) -> F64:
    """Terrain points around a map's centre, some beyond its edges, from 300 m below its
    plane to 900 m above."""
    return np.column_stack(
        [
            centre[0] + rng.uniform(-reach_m, reach_m, n),
            centre[1] + rng.uniform(-reach_m, reach_m, n),
            centre[2] + rng.uniform(-300.0, 900.0, n),
        ]
    )


# ---- a segment whose map is known ------------------------------------------------------------

PX = 64
PLACEMENT = ShadowPlacement(
    version=77,
    centre_m=(1250.0, -730.0, 432.0),
    size_m=6400.0,
    # 35 deg up in the south-west: a point 500 m above the plane reads the map 714 m to its
    # north-east (where the sun ray through it meets the plane)
    sun_direction_enu=(-0.5792, -0.5792, 0.5736),
)


def synthetic(name: str, placement: ShadowPlacement | None, version: int = 3) -> FrameWriter:
    """A segment with the daemon's layers and one frame: a map of smooth blobs and sharp steps
    (known pixels), the placement in the record."""
    rng = np.random.default_rng(4)
    yy, xx = np.mgrid[0:PX, 0:PX].astype(np.float64)
    t = np.ones((PX, PX))
    for cx, cy, r in rng.uniform((0, 0, 3), (PX, PX, 12), size=(12, 3)):
        t *= 1.0 - 0.8 * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (r * r))
    t[20:28, 40:60] = 0.0  # a hard-edged block: the bilinear edge is tested too
    image = np.empty((PX, PX, 4), np.uint8)
    image[..., :3] = np.round(t * 255.0)[..., None].astype(np.uint8)
    image[..., 3] = 255
    camera = Camera((0.0, 0.0, 900.0), 45.0, -10.0, 0.0, 60.0, 32, 24)
    meta = FrameMeta(
        frame_number=3,
        ring_version=1,
        time_utc_unix_s=1_780_000_000.0,
        camera=camera,
        sun_direction_enu=(0.0, 0.6, 0.8),
        ring_centre_m=camera.position_m,
        ring_radius_m=3200.0,
        ring_quads_m=np.zeros((8, 4, 3)),
        shadow=placement,
    )
    writer = FrameWriter.create(name, frame_layer_specs(32, 24, 16, PX))
    for layer, (w, h) in (("sky", (32, 24)), ("near", (32, 24)), ("shadow", (PX, PX))):
        pixels = image if layer == "shadow" else np.zeros((h, w, 4), np.uint8)
        np.frombuffer(writer.layer_buffer(layer, w, h), np.uint8)[:] = pixels.ravel()
    for i in range(8):
        writer.layer_buffer(f"ring_{i}", 16, 16)
    data = meta.pack()
    if version == 2:  # the daemon of before the shadow map
        data = (2).to_bytes(4, "little") + data[4:1736]
    writer.publish(meta.frame_number, data)
    return writer


def reference_t(name: str, points: F64) -> F64:
    with FrameReader.open(name) as reader:
        frame = host_frame(reader.read(timeout_s=1.0))
    return frame.shadow_at(points)


@pytest.mark.parametrize("exe", ["wxsky_gl_shadow", "wxsky_gles_shadow"], ids=["gl", "gles"])
def test_the_c_shader_samples_the_map_as_the_reference_host_does(
    host_kit: Path,  # noqa: F811
    name: str,
    exe: str,
) -> None:
    writer = synthetic(name, PLACEMENT)
    try:
        points = random_points(np.random.default_rng(8), PLACEMENT.centre_m, 4000.0, 2000)
        got, out = c_points(host_kit, name, points, exe)
        want = reference_t(name, points)
    finally:
        writer.close()
    assert "shadow_version 77 present 1" in out, out
    inside = want < 1.0
    assert inside.mean() > 0.3 and (want < 0.1).sum() > 20  # the map, not its surroundings
    assert np.abs(got - want).max() <= LEVEL, np.abs(got - want).max()


def test_the_reference_sampling_follows_the_protocol_by_hand() -> None:
    """Protocol §3.3 step by step, for one point above the plane: moved along the map's sun
    to the plane, then the texel centres' bilinear mix."""
    image = np.zeros((4, 4, 4), np.uint8)
    image[1, 2, 0], image[1, 1, 0], image[2, 2, 0], image[2, 1, 0] = 200, 100, 40, 0
    sun = (0.6, 0.0, 0.8)  # 36.9 deg up in the east
    shadow = ShadowMap(image, (0.0, 0.0, 100.0), 400.0, sun)
    # The sun ray from the map's centre, halfway between texels (1, 1), (1, 2), (2, 1) and
    # (2, 2), passes 400 m over the plane 300 m east of it.
    t = shadow.transmittance(np.array([[300.0, 0.0, 500.0], [300.0, 0.0, np.nan]]))
    assert t[0] == pytest.approx((200 + 100 + 40 + 0) / 4 / 255.0)
    assert np.isnan(t[1])
    # Outside the map, or the sun below the horizon: 1.
    assert shadow.transmittance(np.array([[1000.0, 0.0, 100.0]])) == pytest.approx([1.0])
    night = ShadowMap(image, (0.0, 0.0, 100.0), 400.0, (0.6, 0.0, -0.8))
    assert night.transmittance(np.zeros((2, 3, 3))).tolist() == [[1.0] * 3] * 2


@pytest.mark.parametrize("version", [2, 3], ids=["record-v2", "no-map"])
def test_without_a_map_the_shader_gives_full_sun(
    host_kit: Path,  # noqa: F811
    name: str,
    version: int,
) -> None:
    writer = synthetic(name, None if version == 3 else PLACEMENT, version=version)
    try:
        points = random_points(np.random.default_rng(1), PLACEMENT.centre_m, 3000.0, 50)
        got, out = c_points(host_kit, name, points)
        want = reference_t(name, points)
    finally:
        writer.close()
    assert "present 0" in out, out
    assert np.all(got == 1.0) and np.all(want == 1.0)


def test_the_sanitized_build_samples_the_same(
    host_kit: Path,  # noqa: F811
    host_kit_sanitized: Path,  # noqa: F811
    name: str,
) -> None:
    writer = synthetic(name, PLACEMENT)
    try:
        points = random_points(np.random.default_rng(3), PLACEMENT.centre_m, 4000.0, 300)
        plain, _ = c_points(host_kit, name, points)
        sanitized, _ = c_points(host_kit_sanitized, name, points, **gl_sanitizer_env())
    finally:
        writer.close()
    assert np.array_equal(plain, sanitized)


# ---- a running daemon ------------------------------------------------------------------------

W, H = 320, 180


def test_a_daemons_shadow_map_reaches_both_hosts_and_moves_with_the_clouds(
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """scattered-cumulus at noon, the camera over the field looking down: the record places
    the map over the ring, its centre moves with the layer's wind from frame to frame, the C
    shader samples it as the reference host does, and the C host's ground, lit through it,
    composites as the reference compositor's."""
    preset = WeatherState().apply(load_preset("scattered-cumulus"))
    layer = preset.layers[0]
    wind = np.array(preset.wind_at(0.5 * (layer.base_m + layer.top_m)))
    with (
        # 128-texel impostors (conftest.py GL_RING_PX), not the default 512: the ring is not
        # what is looked at here, the shadow map (its own size) and the ground are.
        running_daemon(
            tmp_path,
            extra_config=f"[clock]\nrate = 1.0\n[camera]\nwidth = {W}\nheight = {H}\n"
            "[scene]\nring_texture_px = 128\n",
        ) as d,
        ReferenceHost.connect(d.address) as host,
    ):
        host.call("apply_preset", {"name": "scattered-cumulus"})
        host.call("set_time", {"time_utc": "2026-07-08T12:00:00Z"})
        host.call(
            "set_camera",
            {
                "position_m": [300.0, -200.0, 1200.0],
                "heading_deg": 200.0,
                "pitch_deg": -18.0,
                "fov_deg": 75.0,
                "width": W,
                "height": H,
            },
        )
        first = host.wait_settled_frame(after=host.reader.frame_number + 2, timeout_s=HANG_S)
        later = first
        while later.meta.time_utc_unix_s - first.meta.time_utc_unix_s < 1.5:
            later = host.wait_frame(later.meta.frame_number, timeout_s=60)
        d.pause()
        try:
            frame = host.read_latest()
            points = random_points(np.random.default_rng(6), (300.0, -200.0, 432.0), 9000.0, 800)
            got, out = c_points(host_kit, d.shm_name, points)
            ground = Ground(432.0, frame.meta.sun_direction_enu)
            c_picture = c_ground(host_kit, d.shm_name, (H, W), ground)
        finally:
            d.resume()
    meta, shadow = frame.meta, frame.meta.shadow
    assert shadow is not None and frame.layers.shadow is not None
    assert f"shadow_version {shadow.version} present 1" in out, out
    # Over the ring's area, on the observer's ground, for the frame's (noon) sun.
    assert shadow.size_m == 2.0 * meta.ring_radius_m and shadow.centre_m[2] == 432.0
    assert np.dot(shadow.sun_direction_enu, meta.sun_direction_enu) > 0.9999
    # Between two frames of one map the centre moved as the clouds did.
    # (The next rebuild is due only once the clouds drifted 240 m: 24 s at this wind.)
    first_shadow = first.meta.shadow
    assert first_shadow is not None and first_shadow.version == shadow.version
    dt_s = meta.time_utc_unix_s - first.meta.time_utc_unix_s
    moved = np.subtract(shadow.centre_m[:2], first_shadow.centre_m[:2])
    assert dt_s > 1.0 and np.allclose(moved, wind * dt_s, atol=1e-6), (moved, wind, dt_s)
    # The map has shade and sun (4 oktas of cumulus at noon).
    t = frame.layers.shadow.image[..., 0] / 255.0
    assert 0.2 < (t < 0.5).mean() < 0.8 and (t > 0.9).mean() > 0.2
    want = frame.shadow_at(points)
    assert np.abs(got - want).max() <= LEVEL, np.abs(got - want).max()
    ref_picture = frame.composite(ground)
    diff = np.abs(c_picture.astype(int) - ref_picture.astype(int))
    per_channel = diff.mean(axis=(0, 1))
    print(f"ground C vs Python: per channel {np.round(per_channel, 4).tolist()}, max {diff.max()}")
    # (0.02 levels measured on llvmpipe: GL's fixed-point bilinear weights on the map's edges)
    assert np.all(per_channel <= 0.25) and diff.max() <= 2, (per_channel, diff.max())
    # The ground shows the shadows: sunlit and shaded ground pixels both.
    lit = ground.rgb[1] * (ground.ambient + (1 - ground.ambient) * meta.sun_direction_enu[2])
    g = ref_picture[..., 1] / 255.0
    looks_down = np.arange(H) > H // 2
    assert (np.abs(g[looks_down] - lit) < 0.01).mean() > 0.1
    assert (np.abs(g[looks_down] - ground.rgb[1] * ground.ambient) < 0.01).mean() > 0.05
