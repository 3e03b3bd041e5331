"""The C host kit's GL compositor (plugins/host-c: src/gl/compositor.c, wxsky_host_gl.h),
driven through its headless test program `wxsky_gl_composite` on real segments written by the
Python `FrameWriter`, against the Python reference host (wxsky/host/reference.py,
compositor.py) reading the same segment: solid synthetic layers whose pictures are known
exactly, and a rendered snapshot's layers, still and cross-fading."""

from __future__ import annotations

import contextlib
import math
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

from wxsky.host.compositor import stretch
from wxsky.host.reference import host_frame
from wxsky.output import shm
from wxsky.output.frame_meta import FrameMeta
from wxsky.output.shm import FrameReader, FrameWriter, LayerSpec
from wxsky.scene.camera import Camera

pytestmark = pytest.mark.gl

PROGRAM = "wxsky_gl_composite"  # OpenGL 3.3 core
PROGRAM_GLES = "wxsky_gles_composite"  # the same on OpenGL ES 3.0 (the GLES build)
U8 = npt.NDArray[np.uint8]
F64 = npt.NDArray[np.float64]


def program(folder: Path, exe: str = PROGRAM) -> Path:
    return gl_program(folder, exe)


@pytest.fixture
def name() -> Iterator[str]:
    made = f"wxsky-hgl-{os.getpid()}-{uuid.uuid4().hex[:10]}"
    yield made
    with contextlib.suppress(FileNotFoundError):
        shm._shm_unlink(made)


def layer_specs(width: int, height: int, ring_px: int) -> list[LayerSpec]:
    """The daemon's 19 layers (protocol §1.5)."""
    return [
        LayerSpec("sky", width, height),
        LayerSpec("near", width, height),
        LayerSpec("near_front", width, height),
        *(LayerSpec(f"ring_{i}", ring_px, ring_px) for i in range(8)),
        *(LayerSpec(f"ring_in_{i}", ring_px, ring_px) for i in range(8)),
    ]


def octagon(centre: tuple[float, float, float], radius: float, bottom: float, top: float) -> F64:
    """8 vertical quads around `centre`, quad i at heading i x 45 deg, corners top-left,
    top-right, bottom-right, bottom-left as seen from the centre (protocol §3)."""
    quads = np.zeros((8, 4, 3))
    half = radius * math.tan(math.radians(22.5))
    c = np.asarray(centre, dtype=np.float64)
    for i in range(8):
        h = math.radians(45.0 * i)
        out = np.array([math.sin(h), math.cos(h), 0.0])
        right = np.array([math.cos(h), -math.sin(h), 0.0])
        mid = c + radius * out
        left_pt, right_pt = mid - half * right, mid + half * right
        up, down = np.array([0.0, 0.0, top]), np.array([0.0, 0.0, bottom])
        quads[i] = [left_pt + up, right_pt + up, right_pt + down, left_pt + down]
    return quads


def publish(
    name: str, specs: list[LayerSpec], images: dict[str, U8], meta: FrameMeta
) -> FrameWriter:
    """A new segment `name` holding one frame; the caller closes the writer."""
    writer = FrameWriter.create(name, specs)
    for layer, pixels in images.items():
        h, w, _ = pixels.shape
        np.frombuffer(writer.layer_buffer(layer, w, h), dtype=np.uint8)[:] = pixels.ravel()
    writer.publish(meta.frame_number, meta.pack())
    return writer


def c_composite(
    folder: Path,
    name: str,
    shape: tuple[int, int],
    *args: str,
    env: dict[str, str] | None = None,
    exe_name: str = PROGRAM,
    frame_out: list[int] | None = None,
) -> U8:
    out = folder / f"{name}.rgba"
    exe = program(folder, exe_name)
    try:
        proc = subprocess.run(
            [str(exe), name, str(out), *args],
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
        )
        if proc.returncode == 2:
            pytest.skip(f"no headless EGL context: {proc.stdout.strip()}")
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert proc.stdout.startswith("ok "), proc.stdout
        if frame_out is not None:
            frame_out.append(int(proc.stdout.split()[3]))
        h, w = shape
        data = np.fromfile(out, dtype=np.uint8)
        assert data.size == h * w * 4
        return data.reshape(h, w, 4)
    finally:
        with contextlib.suppress(FileNotFoundError):
            out.unlink()


def python_composite(name: str) -> U8:
    with FrameReader.open(name) as reader:
        return host_frame(reader.read(timeout_s=1.0)).composite()


def assert_pixel(image: U8, row: int, col: int, want: F64) -> None:
    """Within one level of `want` (0..255) in every channel."""
    got = image[row, col].astype(int)
    assert np.all(np.abs(got - want) <= 1), f"pixel ({row}, {col}) is {got}, not {want}"


def mean_abs_diff(a: U8, b: U8) -> float:
    return float(np.mean(np.abs(a.astype(np.int16) - b.astype(np.int16))))


# ---- synthetic layers: the picture is known exactly ------------------------------------------

W, H, RING_PX = 64, 48, 32
SKY = (51, 102, 204, 255)
RING = (100, 60, 20, 128)
RING_IN = (10, 120, 60, 200)
NEAR = (40, 20, 0, 64)
FRONT = (0, 0, 90, 90)


def solid(h: int, w: int, rgba: tuple[int, int, int, int]) -> U8:
    return np.broadcast_to(np.array(rgba, dtype=np.uint8), (h, w, 4)).copy()


def f(rgba: tuple[int, int, int, int]) -> F64:
    """A colour of levels 0..255 as 0..1."""
    return np.array(rgba, dtype=np.float64) / 255.0


def over(src: F64, dst: F64) -> F64:
    result: F64 = src + (1.0 - src[3]) * dst
    return result


def synthetic(fading: bool, front: bool) -> tuple[list[LayerSpec], dict[str, U8], FrameMeta]:
    camera = Camera(
        (100.0, -50.0, 1000.0),
        heading_deg=30.0,
        pitch_deg=0.0,
        fov_deg=90.0,
        width_px=W,
        height_px=H,
    )
    near = np.zeros((H, W, 4), dtype=np.uint8)
    near[:, : W // 2] = NEAR  # the left half
    images = {"sky": solid(H, W, SKY), "near": near}
    for i in range(8):
        images[f"ring_{i}"] = solid(RING_PX, RING_PX, RING)
    # The ring covers altitudes 0..2000 m at 20 km: the camera at 1000 m sees it over the
    # middle rows only (a band of +- atan(1000/20000) about the horizon).
    quads = octagon(camera.position_m, 20_000.0, -1000.0, 3000.0)
    incoming = None
    if fading:
        for i in range(8):
            images[f"ring_in_{i}"] = solid(RING_PX, RING_PX, RING_IN)
        incoming = octagon(camera.position_m, 25_000.0, -500.0, 1500.0)
    if front:
        images["near_front"] = solid(H, W, FRONT)
    meta = FrameMeta(
        frame_number=5,
        ring_version=9,
        time_utc_unix_s=1_718_000_000.0,
        camera=camera,
        sun_direction_enu=(0.0, 0.6, 0.8),
        ring_centre_m=camera.position_m,
        ring_radius_m=20_000.0,
        ring_quads_m=quads,
        ring_fade=0.5 if fading else 0.0,
        incoming_centre_m=camera.position_m if fading else None,
        incoming_radius_m=25_000.0 if fading else 0.0,
        incoming_quads_m=incoming,
    )
    return layer_specs(W, H, RING_PX), images, meta


@pytest.mark.parametrize(
    ("fading", "front", "args"),
    [
        (False, False, ()),
        (False, False, ("--window",)),
        (True, False, ()),
        (True, True, ("--twice",)),
        (True, True, ("--view", "--twice")),
        (True, True, ("--pbo", "--twice")),
    ],
    ids=[
        "still",
        "window-orientation",
        "fading",
        "fading-near-front-twice",
        "zero-copy-view",
        "pbo-streaming",
    ],
)
def test_solid_layers_composite_to_the_exact_colours(
    host_kit: Path,  # noqa: F811
    name: str,
    fading: bool,
    front: bool,
    args: tuple[str, ...],
) -> None:
    specs, images, meta = synthetic(fading, front)
    writer = publish(name, specs, images, meta)
    try:
        got = c_composite(host_kit, name, (H, W), *args)
        ref = python_composite(name)
    finally:
        writer.close()

    ring = f(RING)
    # the row below the horizon meets both rings while fading: half of each
    ring_mid = 0.5 * ring + 0.5 * f(RING_IN) if fading else ring
    sky = f(SKY)

    def expected(ring_c: F64 | None, left: bool) -> F64:
        out = sky if ring_c is None else over(ring_c, sky)
        if left:
            out = over(f(NEAR), out)
        if front:
            out = over(f(FRONT), out)
        out = out.copy()
        out[3] = 1.0
        return np.round(out * 255.0)

    mid = H // 2  # just below the horizon: meets the ring(s)
    for row, ring_c in ((0, None), (mid, ring_mid), (H - 1, None)):
        for col, left in ((2, True), (W - 3, False)):
            want = expected(ring_c, left)
            assert_pixel(got, row, col, want)
            assert_pixel(ref, row, col, want)
    diff = np.abs(got.astype(int) - ref.astype(int))
    assert diff.max() <= 1, f"max {diff.max()} at {np.argwhere(diff > 1)[:5].tolist()}"


# ---- a rendered frame: the layers of a real snapshot ----------------------------------------

SNAP_W, SNAP_H = 320, 180


@pytest.fixture(scope="module")
def rendered() -> tuple[Camera, dict[str, U8], F64]:
    """The layers `wxsky snapshot --layers-out` writes, for a camera looking a little up at
    scattered cumulus in the late afternoon (the ring fills the middle of the picture)."""
    from wxsky.app.snapshot import take_snapshot
    from wxsky.scene.layout import SceneSettings
    from wxsky.settings.presets import load_preset
    from wxsky.weather.state import Source, WeatherPatch, WeatherState, parse_time_utc

    state = WeatherState().apply(load_preset("scattered-cumulus"))
    state = state.apply(
        WeatherPatch(source=Source.CONTROL, time_utc=parse_time_utc("2024-06-21T17:00:00Z"))
    )
    camera = Camera(
        (0.0, 0.0, 600.0),
        heading_deg=225.0,
        pitch_deg=4.0,
        roll_deg=3.0,
        fov_deg=70.0,
        width_px=SNAP_W,
        height_px=SNAP_H,
    )
    shot = take_snapshot(state, camera, SceneSettings())
    # The pictures only: these segments have the 19 layers without the shadow map.
    layers = {k: v for k, v in shot.layers.items() if k != "shadow"}
    return camera, layers, shot.ring_quads_m


def rendered_frame(
    rendered: tuple[Camera, dict[str, U8], F64], fading: bool
) -> tuple[list[LayerSpec], dict[str, U8], FrameMeta]:
    camera, layers, quads = rendered
    ring_px = layers["ring_0"].shape[0]
    images = {k: np.ascontiguousarray(v) for k, v in layers.items()}
    incoming = None
    if fading:
        # another ring: the images turned by three quads and mirrored, on quads 10 % larger
        # about a centre 300 m east
        for i in range(8):
            images[f"ring_in_{i}"] = np.ascontiguousarray(layers[f"ring_{(i + 3) % 8}"][:, ::-1])
        eye = np.asarray(camera.position_m)
        incoming = (quads - eye) * 1.1 + eye + np.array([300.0, 0.0, 0.0])
    meta = FrameMeta(
        frame_number=41,
        ring_version=17,
        time_utc_unix_s=1_718_989_200.0,
        camera=camera,
        sun_direction_enu=(0.0, 0.6, 0.8),
        ring_centre_m=camera.position_m,
        ring_radius_m=8000.0,
        ring_quads_m=quads,
        ring_fade=0.5 if fading else 0.0,
        incoming_centre_m=(300.0, 0.0, 600.0) if fading else None,
        incoming_radius_m=8800.0 if fading else 0.0,
        incoming_quads_m=incoming,
    )
    return layer_specs(SNAP_W, SNAP_H, ring_px), images, meta


@pytest.mark.parametrize("fading", [False, True], ids=["still", "fading"])
def test_a_rendered_frame_composites_as_the_python_reference_host_does(
    host_kit: Path,  # noqa: F811
    name: str,
    rendered: tuple[Camera, dict[str, U8], F64],
    fading: bool,
) -> None:
    specs, images, meta = rendered_frame(rendered, fading)
    writer = publish(name, specs, images, meta)
    try:
        got = c_composite(host_kit, name, (SNAP_H, SNAP_W))
        ref = python_composite(name)
    finally:
        writer.close()
    mean = mean_abs_diff(got, ref)
    per_channel = np.mean(np.abs(got.astype(int) - ref.astype(int)), axis=(0, 1))
    print(
        f"C vs Python ({'fading' if fading else 'still'}): mean {mean:.4f}/255 per "
        f"value, per channel (levels) {np.round(per_channel, 4).tolist()}, max "
        f"{int(np.abs(got.astype(int) - ref.astype(int)).max())}"
    )
    # the ring shows: the picture is not just sky and near (its far clouds, in the haze of
    # the physical sky's aerial perspective, differ from the sky by a few levels where they
    # are, so: in how many pixels, not by how much over the whole picture)
    sky_near = python_composite_without_ring(images)
    ring_px = np.abs(ref.astype(int) - sky_near.astype(int))[..., :3].max(axis=2) > 2
    print(f"ring shows in {ring_px.mean():.3f} of the picture")
    assert ring_px.mean() > 0.05
    assert np.all(per_channel <= 1.0), per_channel


def python_composite_without_ring(images: dict[str, U8]) -> U8:
    sky = images["sky"].astype(np.float64) / 255.0
    near = stretch(images["near"], sky.shape[1], sky.shape[0])  # drawn at a fraction
    out = near + (1.0 - near[..., 3:4]) * sky
    out[..., 3] = 1.0
    return np.round(out * 255.0).astype(np.uint8)


def test_the_sanitized_build_composites_the_same(
    host_kit: Path,  # noqa: F811
    host_kit_sanitized: Path,  # noqa: F811
    name: str,
) -> None:
    specs, images, meta = synthetic(fading=True, front=True)
    writer = publish(name, specs, images, meta)
    try:
        plain = c_composite(host_kit, name, (H, W))
        env = gl_sanitizer_env()
        sanitized = c_composite(host_kit_sanitized, name, (H, W), "--twice", env=env)
        view = c_composite(host_kit_sanitized, name, (H, W), "--view", "--window", env=env)
        pbo = c_composite(host_kit_sanitized, name, (H, W), "--pbo", "--terrain-m", "1e6", env=env)
    finally:
        writer.close()
    assert np.array_equal(plain, sanitized)
    assert np.array_equal(plain, view)
    assert np.array_equal(plain[:, W // 2 :], pbo[:, W // 2 :])  # the left half is "terrain"


@pytest.mark.parametrize("terrain_m", [5_000.0, 50_000.0], ids=["near-terrain", "far-terrain"])
def test_host_terrain_hides_the_sky_and_the_ring_clouds_behind_it(
    host_kit: Path,  # noqa: F811
    name: str,
    terrain_m: float,
) -> None:
    """The program stands in for a host that drew opaque terrain first: the left half green
    at the depth of a plane `terrain_m` ahead. The ring is at 20 km: terrain at 5 km hides it,
    terrain at 50 km is behind it, so the ring's clouds are blended over the terrain."""
    specs, images, meta = synthetic(fading=False, front=False)
    writer = publish(name, specs, images, meta)
    try:
        got = c_composite(host_kit, name, (H, W), "--terrain-m", str(terrain_m))
    finally:
        writer.close()
    terrain, near, ring, sky = f((0, 128, 0, 255)), f(NEAR), f(RING), f(SKY)
    mid = H // 2
    cases = {
        (0, 2): over(near, terrain),  # above the ring: terrain, not sky
        (mid, 2): over(near, terrain if terrain_m < 20_000.0 else over(ring, terrain)),
        (0, W - 3): sky,  # the right half has no terrain
        (mid, W - 3): over(ring, sky),
    }
    for (row, col), want in cases.items():
        want = np.round(want * 255.0)
        want[3] = 255.0
        assert_pixel(got, row, col, want)


def test_the_gles_build_composites_what_the_gl_build_does(
    host_kit: Path,  # noqa: F811
    name: str,
    rendered: tuple[Camera, dict[str, U8], F64],
) -> None:
    """The same source built for OpenGL ES 3.0 (-DWXSKY_GL_ES), on an ES 3.0 context."""
    specs, images, meta = rendered_frame(rendered, fading=True)
    writer = publish(name, specs, images, meta)
    try:
        gles = c_composite(host_kit, name, (SNAP_H, SNAP_W), exe_name=PROGRAM_GLES)
        gl = c_composite(host_kit, name, (SNAP_H, SNAP_W), "--pbo")
        ref = python_composite(name)
    finally:
        writer.close()
    assert np.abs(gles.astype(int) - gl.astype(int)).max() <= 1
    assert mean_abs_diff(gles, ref) <= 1.0


def test_a_running_daemons_frame_composites_as_the_python_reference_host_does(
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """The daemon's own segment: both hosts read its latest frame while the daemon is stopped
    (SIGSTOP), so they read the same one."""
    from wxsky.host.reference import ReferenceHost

    with (
        running_daemon(tmp_path, extra_config="[clock]\nrate = 0.0\n") as d,
        ReferenceHost.connect(d.address) as host,
    ):
        host.call("apply_preset", {"name": "scattered-cumulus"})
        host.call("set_time", {"time_utc": "2026-06-21T16:00:00Z"})
        host.call(
            "set_camera",
            {"heading_deg": 200.0, "pitch_deg": 6.0, "fov_deg": 75.0, "width": 320, "height": 180},
        )
        start = host.reader.frame_number
        host.wait_settled_frame(after=start + 2, timeout_s=HANG_S)
        d.pause()
        try:
            ref_frame = host.read_latest()
            frames: list[int] = []
            got = c_composite(host_kit, d.shm_name, (180, 320), frame_out=frames)
        finally:
            d.resume()
    assert frames == [ref_frame.meta.frame_number]
    ref = ref_frame.composite()
    per_channel = np.mean(np.abs(got.astype(int) - ref.astype(int)), axis=(0, 1))
    print(f"C vs Python (daemon frame): per channel (levels) {np.round(per_channel, 4).tolist()}")
    assert np.all(per_channel <= 1.0), per_channel


def test_layers_stretch_over_a_larger_viewport(
    host_kit: Path,  # noqa: F811
    name: str,
) -> None:
    """A framebuffer twice the layers' size: the full-screen layers are sampled bilinearly
    over it and the ring is met per pixel of it."""
    specs, images, meta = synthetic(fading=False, front=False)
    writer = publish(name, specs, images, meta)
    try:
        got = c_composite(host_kit, name, (2 * H, 2 * W), "--scale", "2")
    finally:
        writer.close()
    near, ring, sky = f(NEAR), f(RING), f(SKY)
    mid = H  # the row just below the horizon, at twice the size
    cases = {
        (0, 4): over(near, sky),
        (mid, 4): over(near, over(ring, sky)),
        (2 * H - 1, 2 * W - 6): sky,
        (mid, 2 * W - 6): over(ring, sky),
    }
    for (row, col), want in cases.items():
        want = np.round(want * 255.0)
        want[3] = 255.0
        assert_pixel(got, row, col, want)
