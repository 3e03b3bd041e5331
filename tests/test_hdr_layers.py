"""HDR layers in the segment (issue 41, item 4; docs/linear-output.md, docs/protocol.md §1.2):
RGBA16F scene-linear layers when the daemon is set to write them (`[output] layer_format`),
negotiated over the control channel (`output_format`), a segment version of their own that
readers of before refuse, the 8-bit default unchanged; read back by the Python reader and the
C host kit bit for bit, composited in linear and tone-mapped once by the kit's GL compositor.

Real parts throughout: POSIX shared memory written by `FrameWriter`, the GL renderer on EGL,
the C kit built as its other tests build it (and under ASan/UBSan), a running daemon, and the
readers of before this change, taken from git (commit OLD) and run as they were."""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import shutil
import struct
import subprocess
import sys
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
from daemon_harness import HANG_S, running_daemons
from host_kit import gl_program, host_kit, host_kit_sanitized, sanitizer_env  # noqa: F401

from wxsky.errors import RuntimeFailure, WxskyError
from wxsky.output import shm
from wxsky.output.frame_meta import FrameMeta
from wxsky.output.shm import RGBA8, RGBA16F, FrameReader, FrameWriter, LayerSpec
from wxsky.scene import exposure
from wxsky.scene.camera import Camera

ROOT = Path(__file__).resolve().parents[1]
# The last commit before HDR layers: its readers are the "old" ones, which must refuse.
OLD = "ac3b3fc"
F64 = npt.NDArray[np.float64]


# ---- helpers -------------------------------------------------------------------------------


@pytest.fixture
def names() -> Iterator[Callable[[], str]]:
    made: list[str] = []

    def make() -> str:
        made.append(f"wxsky-hdr-{os.getpid()}-{uuid.uuid4().hex[:10]}")
        return made[-1]

    yield make
    for name in made:
        with contextlib.suppress(FileNotFoundError):
            shm._shm_unlink(name)


def segment_bytes(name: str) -> bytes:
    return Path(f"/dev/shm/{name}").read_bytes()


def copy_segment(data: bytes, name: str) -> None:
    """A segment made by hand from bytes (no writer holds it): a bad or patched copy."""
    fd = shm._shm_open(name, os.O_CREAT | os.O_EXCL | os.O_RDWR)
    try:
        os.write(fd, data)
    finally:
        os.close(fd)


def patched(data: bytes, offset: int, value: int) -> bytes:
    out = bytearray(data)
    struct.pack_into("<I", out, offset, value)
    return bytes(out)


def halves(rng: np.random.Generator, shape: tuple[int, ...]) -> npt.NDArray[np.float16]:
    """Half floats across the whole range a scene-linear layer can hold, and the odd ones:
    subnormals, zeros of both signs, the largest finite, infinity."""
    out = (rng.random(shape) * 8.0).astype(np.float16)
    flat = out.reshape(-1)
    special = np.array([0.0, -0.0, 6e-8, 6.1e-5, 65504.0, np.inf, 1.0, 7.24], np.float16)
    flat[: len(special)] = special
    return out


def fnv1a64(data: bytes) -> str:
    h = 0xCBF29CE484222325
    for byte in data:
        h = ((h ^ byte) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return f"{h:016x}"


SPECS = [
    LayerSpec("sky", 24, 16, RGBA16F),
    LayerSpec("near", 24, 16, RGBA16F),
    LayerSpec("ring_0", 8, 8, RGBA16F),
    LayerSpec("shadow", 8, 8, RGBA8),
]


def record(frame_number: int) -> bytes:
    """A valid frame record for a frame of the small test segments (the C kit decodes it)."""
    eye = (0.0, 0.0, 100.0)
    quads = np.zeros((8, 4, 3))
    return FrameMeta(
        frame_number=frame_number,
        ring_version=1,
        time_utc_unix_s=0.0,
        camera=Camera(eye, width_px=24, height_px=16),
        sun_direction_enu=(0.0, 0.6, 0.8),
        ring_centre_m=eye,
        ring_radius_m=8000.0,
        ring_quads_m=quads,
    ).pack()


def publish_hdr(writer: FrameWriter, seed: int = 1) -> dict[str, Any]:
    """Frame `seed`: random half floats (and a byte shadow map), with a valid record;
    returns what was written."""
    rng = np.random.default_rng(seed)
    written: dict[str, Any] = {}
    for spec in writer.layers:
        w, h = spec.max_width, spec.max_height
        buffer = writer.layer_buffer(spec.name, w, h)
        if spec.format == RGBA16F:
            pixels: Any = halves(rng, (h, w, 4))
            np.frombuffer(buffer, np.float16)[:] = pixels.reshape(-1)
        else:
            pixels = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
            np.frombuffer(buffer, np.uint8)[:] = pixels.reshape(-1)
        written[spec.name] = pixels
    writer.publish(seed, record(seed))
    return written


# ---- the segment (Python reader and writer) ------------------------------------------------


def test_an_rgba8_segment_is_still_version_1_byte_for_byte(names: Callable[[], str]) -> None:
    """The default: every layer RGBA8, so the header is the layout of before HDR layers,
    field by field (32-byte descriptors, no format), and capacities of 4 bytes a pixel."""
    name = names()
    specs = [LayerSpec("sky", 24, 16), LayerSpec("ring_0", 8, 8)]
    with FrameWriter.create(name, specs) as writer:
        assert writer.version == 1
        data = segment_bytes(name)
    version, header_size, slot_count, layer_count = struct.unpack_from("<4I", data, 8)
    assert (version, header_size, slot_count, layer_count) == (1, 4096, 2, 2)
    for k, (spec, want_capacity) in enumerate(zip(specs, (24 * 16 * 4, 8 * 8 * 4), strict=True)):
        desc = 64 + 32 * k
        assert data[desc : desc + 16] == spec.name.encode().ljust(16, b"\0")
        assert struct.unpack_from("<IIQ", data, desc + 16) == (
            spec.max_width,
            spec.max_height,
            want_capacity,
        )
    # Nothing after the descriptors: the header is exactly the old one.
    assert data[64 + 32 * 2 : 4096] == bytes(4096 - 128)


def test_rgba16f_layers_round_trip_bit_for_bit(names: Callable[[], str]) -> None:
    name = names()
    with FrameWriter.create(name, SPECS) as writer, FrameReader.open(name) as reader:
        written = publish_hdr(writer, seed=7)
        frame = reader.read()
        data = segment_bytes(name)
        assert writer.version == reader.version == 2
        assert [s.format for s in reader.layers] == [RGBA16F, RGBA16F, RGBA16F, RGBA8]
    assert struct.unpack_from("<I", data, 8)[0] == 2
    for k, spec in enumerate(SPECS):
        desc = 64 + 40 * k
        bpp = 8 if spec.format == RGBA16F else 4
        width, height, capacity, code, reserved = struct.unpack_from("<IIQII", data, desc + 16)
        assert (width, height) == (spec.max_width, spec.max_height)
        assert capacity == width * height * bpp
        assert (code, reserved) == ((1 if spec.format == RGBA16F else 0), 0)
    for spec in SPECS:
        got, want = frame.layers[spec.name], written[spec.name]
        assert got.dtype == want.dtype and got.shape == want.shape
        # bits, not values: -0.0 and inf included
        assert got.tobytes() == want.tobytes(), spec.name


def test_a_newer_segment_version_is_refused_with_its_number(names: Callable[[], str]) -> None:
    name, bad = names(), names()
    with FrameWriter.create(name, SPECS) as writer:
        publish_hdr(writer)
        copy_segment(patched(segment_bytes(name), 8, 3), bad)
    with pytest.raises(RuntimeFailure) as info:
        FrameReader.open(bad)
    assert "version 3; this wxsky understands versions 1 and 2" in str(info.value)
    assert "\n" not in str(info.value)


def test_an_unknown_layer_format_is_refused_by_name(names: Callable[[], str]) -> None:
    name, bad = names(), names()
    with FrameWriter.create(name, SPECS) as writer:
        publish_hdr(writer)
        copy_segment(patched(segment_bytes(name), 64 + 40 * 1 + 32, 7), bad)
    with pytest.raises(WxskyError) as info:
        FrameReader.open(bad)
    assert "layer 'near' format 7" in str(info.value)
    assert "0 RGBA8, 1 RGBA16F" in str(info.value)


def test_a_layer_format_outside_the_choices_is_refused(names: Callable[[], str]) -> None:
    with pytest.raises(ValueError, match="format 'rgba32f' is not one of rgba8, rgba16f"):
        FrameWriter.create(names(), [LayerSpec("sky", 8, 8, "rgba32f")])


# ---- the readers of before -----------------------------------------------------------------


def old_module(path: str, module_name: str) -> ModuleType:
    """A module as it was at OLD, loaded from git under a name of its own."""
    if shutil.which("git") is None:
        pytest.skip("no git: the readers of before are taken from the repository's history")
    proc = subprocess.run(
        ["git", "-C", str(ROOT), "show", f"{OLD}:{path}"], capture_output=True, check=False
    )
    if proc.returncode != 0:
        pytest.skip(f"commit {OLD} is not in this checkout: {proc.stderr.decode().strip()}")
    spec = importlib.util.spec_from_loader(module_name, loader=None)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module  # dataclasses look their module up
    exec(compile(proc.stdout, f"{OLD}:{path}", "exec"), module.__dict__)
    return module


def test_the_python_reader_of_before_refuses_rgba16f_and_reads_the_default(
    names: Callable[[], str],
) -> None:
    old = old_module("wxsky/output/shm.py", "old_wxsky_shm")
    hdr, default = names(), names()
    with FrameWriter.create(hdr, SPECS) as writer:
        publish_hdr(writer)
        with pytest.raises(RuntimeFailure) as info:
            old.FrameReader.open(hdr)
    message = str(info.value)
    assert "uses frame protocol version 2; this wxsky understands version 1" in message
    assert "\n" not in message
    # The 8-bit default it still reads, pixels and all.
    with FrameWriter.create(default, [LayerSpec("sky", 8, 4)]) as writer:
        buffer = writer.layer_buffer("sky", 8, 4)
        buffer[:] = bytes(range(128))
        writer.publish(1, b"meta")
        with old.FrameReader.open(default) as reader:
            frame = reader.read()
    assert frame.layers["sky"].tobytes() == bytes(range(128)) and frame.meta == b"meta"


@pytest.fixture(scope="module")
def old_kit(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The C host kit as it was at OLD: its frames checker, built as the kit builds it."""
    if shutil.which("git") is None or shutil.which("make") is None:
        pytest.skip("no git or make: the C kit of before is built from the repository's history")
    if shutil.which(os.environ.get("CC", "cc")) is None:
        pytest.skip("no C compiler")
    where = tmp_path_factory.mktemp("old-kit")
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", OLD, "plugins/host-c"], capture_output=True
    )
    if archive.returncode != 0:
        pytest.skip(f"commit {OLD} is not in this checkout: {archive.stderr.decode().strip()}")
    subprocess.run(["tar", "-x", "-C", str(where)], input=archive.stdout, check=True)
    kit = where / "plugins" / "host-c"
    proc = subprocess.run(
        ["make", "-s", "-C", str(kit), "build/wxsky_frames_check"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return kit / "build" / "wxsky_frames_check"


def test_the_c_kit_of_before_refuses_rgba16f_and_reads_the_default(
    old_kit: Path, names: Callable[[], str]
) -> None:
    hdr, default = names(), names()
    with FrameWriter.create(hdr, SPECS) as writer:
        publish_hdr(writer)
        proc = subprocess.run([str(old_kit), "open", hdr], capture_output=True, text=True)
    assert proc.returncode == 1
    assert proc.stderr.strip() == (
        f"wxsky_frames_check: WXSKY_EVERSION: segment '{hdr}' has layout version 2 (offset 8); "
        "this kit reads version 1"
    )
    with FrameWriter.create(default, [LayerSpec("sky", 8, 4)]) as writer:
        writer.layer_buffer("sky", 8, 4)[:] = bytes(range(128))
        writer.publish(1, b"")
        proc = subprocess.run([str(old_kit), "open", default], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["version"] == 1


# ---- the C host kit ------------------------------------------------------------------------


@pytest.fixture(params=[False, True], ids=["plain", "sanitized"])
def build(request: pytest.FixtureRequest) -> tuple[Path, bool]:
    sanitized: bool = request.param
    folder = request.getfixturevalue("host_kit_sanitized" if sanitized else "host_kit")
    return folder, sanitized


def check(
    build: tuple[Path, bool], *args: str, stdin: str | None = None
) -> subprocess.CompletedProcess[str]:
    folder, sanitized = build
    proc = subprocess.run(
        [str(folder / "wxsky_frames_check"), *args],
        capture_output=True,
        text=True,
        input=stdin,
        timeout=120,
        env=sanitizer_env() if sanitized else None,
        check=False,
    )
    assert proc.returncode not in (98, 99), proc.stderr
    assert "Sanitizer" not in proc.stderr and "runtime error" not in proc.stderr, proc.stderr
    return proc


def test_the_kit_reads_rgba16f_layers_bit_for_bit(
    build: tuple[Path, bool], names: Callable[[], str]
) -> None:
    name = names()
    with FrameWriter.create(name, SPECS) as writer:
        written = publish_hdr(writer, seed=3)
        opened = check(build, "open", name)
        read = check(build, "read", name)
        view = check(build, "view", name)
    assert opened.returncode == 0, opened.stderr
    header = json.loads(opened.stdout)
    assert header["version"] == 2
    assert [(x["format"], x["bytes_per_pixel"], x["capacity"]) for x in header["layers"]] == [
        (1, 8, 24 * 16 * 8),
        (1, 8, 24 * 16 * 8),
        (1, 8, 8 * 8 * 8),
        (0, 4, 8 * 8 * 4),
    ]
    want = {k: fnv1a64(v.tobytes()) for k, v in written.items()}
    for proc in (read, view):
        assert proc.returncode == 0, proc.stderr
        frame = json.loads(proc.stdout.splitlines()[0])
        assert {x["name"]: x["fnv"] for x in frame["layers"]} == want


def test_the_kit_refuses_a_newer_version_and_an_unknown_format(
    build: tuple[Path, bool], names: Callable[[], str]
) -> None:
    name, newer, odd = names(), names(), names()
    with FrameWriter.create(name, SPECS) as writer:
        publish_hdr(writer)
        data = segment_bytes(name)
    copy_segment(patched(data, 8, 3), newer)
    copy_segment(patched(data, 64 + 40 * 2 + 32, 9), odd)
    got = check(build, "open", newer)
    assert got.returncode == 1
    assert got.stderr.strip() == (
        f"wxsky_frames_check: WXSKY_EVERSION: segment '{newer}' has layout version 3 (offset 8);"
        " this kit reads versions 1 to 2"
    )
    got = check(build, "open", odd)
    assert got.returncode == 1
    assert got.stderr.strip() == (
        f"wxsky_frames_check: WXSKY_EFORMAT: segment '{odd}': layer 2 'ring_0' has format 9 "
        f"(descriptor offset {64 + 40 * 2 + 32}); this kit reads 0 RGBA8 and 1 RGBA16F"
    )


def test_the_kits_tone_map_is_the_daemons(build: tuple[Path, bool]) -> None:
    """wxsky_display against wxsky/scene/exposure.py `display`: dark to far past the curve's
    white, saturated and grey, at three exposures."""
    rng = np.random.default_rng(5)
    rgb = np.concatenate(
        [
            rng.random((200, 3)) * 0.2,
            rng.random((200, 3)) * 10.0,
            np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [7.0, 0.1, 0.0], [1e-5, 2e-5, 3e-5]]),
            np.array([[exposure.TM_WHITE, 0.5, 0.25], [100.0, 50.0, 1.0]]),
        ]
    ).astype(np.float32)
    text = "".join(f"{r:.9g} {g:.9g} {b:.9g}\n" for r, g, b in rgb)
    for scale in (1.0, 0.25, 4.0):
        proc = check(build, "display", repr(scale), stdin=text)
        assert proc.returncode == 0, proc.stderr
        got = np.array([[float(v) for v in line.split()] for line in proc.stdout.splitlines()])
        want = exposure.display(rgb.astype(np.float64), scale)
        assert got.shape == want.shape
        # float32 in and out: far below an 8-bit level (1/255)
        assert np.max(np.abs(got - want)) < 1e-5, np.max(np.abs(got - want))


def test_the_kits_half_floats_are_exact(build: tuple[Path, bool]) -> None:
    every = np.arange(65536, dtype=np.uint16)
    proc = check(build, "half", stdin="".join(f"{v:x}\n" for v in every))
    assert proc.returncode == 0, proc.stderr
    got = np.array([float(v) for v in proc.stdout.split()])
    want = every.view(np.float16).astype(np.float64)
    assert len(got) == 65536
    assert np.array_equal(np.isnan(got), np.isnan(want))
    finite = ~np.isnan(want)
    assert np.array_equal(got[finite], want[finite])
    assert np.array_equal(np.signbit(got[finite]), np.signbit(want[finite]))


# ---- a rendered frame: Renderer.read_linear, the segment, the C compositor ------------------

W, H, RING_PX, SHADOW_PX = 96, 54, 32, 16
# The C compositor's linear composite against numpy's, relative to 1 + the value: GL's
# bilinear filter of the stretched near layer and float32 blending (llvmpipe: 3.5e-6 at most,
# on values up to 2.1; ten times that allowed for other drivers).
LINEAR_TOLERANCE = 1e-5


@pytest.fixture(scope="module")
def linear_frame(gl_renderer: Any) -> Iterator[tuple[Any, Any, dict[str, npt.NDArray[np.float16]]]]:
    """A linear renderer's frame of scattered cumulus (ring and all), on the session's GL
    context, the plan, and each picture layer as `Renderer.read_linear` gives it (as half
    floats: exactly what it holds)."""
    from wxsky.app.frame_publish import draw_ring
    from wxsky.engine.stages import SkyEngine
    from wxsky.render.renderer import Renderer
    from wxsky.scene.layout import SceneSettings
    from wxsky.scene.ring import RING_SIZE, ring_target_name
    from wxsky.settings.presets import load_preset
    from wxsky.weather.state import Source, WeatherPatch, WeatherState, parse_time_utc

    state = WeatherState().apply(load_preset("scattered-cumulus"))
    state = state.apply(
        WeatherPatch(source=Source.CONTROL, time_utc=parse_time_utc("2024-06-21T17:00:00Z"))
    )
    camera = Camera(
        (0.0, 0.0, 600.0), heading_deg=225.0, pitch_deg=4.0, fov_deg=70.0, width_px=W, height_px=H
    )
    settings = SceneSettings(ring_texture_px=RING_PX, shadow_map_px=SHADOW_PX)
    # An earlier test on this worker may have left a context of its own current on this
    # thread (a renderer it made and released): GL calls through the session's moderngl
    # context then went to that one, where the session's framebuffers do not exist, and the
    # ring draw failed with GL_INVALID_OPERATION in some full-run orders. The `renderer`
    # fixture does the same for each test.
    gl_renderer.ctx.__enter__()
    with (
        SkyEngine(state, camera, settings, clock_rate=0.0, ring_build="immediate") as engine,
        Renderer(RING_PX, ctx=gl_renderer.ctx, output="linear") as renderer,
    ):
        plan = engine.advance(0.0)
        draw_ring(renderer, plan)
        renderer.render_frame(plan.frame)
        targets = {"sky": "sky", "near": "near"}
        for i in range(RING_SIZE):
            targets[f"ring_{i}"] = ring_target_name(i, plan.rings.current_set)
        linear = {
            layer: renderer.read_linear(target).astype(np.float16)
            for layer, target in targets.items()
        }
        yield renderer, plan, linear


def test_published_rgba16f_layers_are_read_linears_half_floats(
    linear_frame: tuple[Any, Any, dict[str, npt.NDArray[np.float16]]],
    names: Callable[[], str],
    host_kit: Path,  # noqa: F811
) -> None:
    """What a host asking for RGBA16F reads (the Python reader and the C kit) is exactly
    `Renderer.read_linear` of the same frame, through the daemon's own publish path."""
    from wxsky.app.frame_publish import frame_layer_specs, publish_plan

    renderer, plan, linear = linear_frame
    name = names()
    specs = frame_layer_specs(W, H, RING_PX, SHADOW_PX, RGBA16F)
    with FrameWriter.create(name, specs) as writer, FrameReader.open(name) as reader:
        publish_plan(renderer, writer, plan, 1, RING_PX)
        frame = reader.read()
        kit = subprocess.run(
            [str(host_kit / "wxsky_frames_check"), "read", name],
            capture_output=True,
            text=True,
            check=False,
        )
    assert kit.returncode == 0, kit.stderr
    kit_fnv = {x["name"]: x["fnv"] for x in json.loads(kit.stdout.splitlines()[0])["layers"]}
    for layer, want in linear.items():
        got = frame.layers[layer]
        assert got.dtype == np.float16, layer
        assert got.tobytes() == want.tobytes(), layer
        assert kit_fnv[layer] == fnv1a64(want.tobytes()), layer
    # scene-linear colour, not display values: a lit sky is above 0 and a picture's data
    assert float(np.max(linear["sky"][..., :3])) > 0.0
    assert frame.layers["shadow"].dtype == np.uint8


def test_rgba16f_slot_textures_hold_the_published_half_floats(
    linear_frame: tuple[Any, Any, dict[str, npt.NDArray[np.float16]]],
    names: Callable[[], str],
) -> None:
    """The zero-copy path's GPU copies (protocol §6) for RGBA16F layers, on this GL: the
    slot textures are half-float textures holding exactly what the segment gets. Their export
    as dma-bufs ('AB4H') needs a driver that exports, which is then checked too; elsewhere
    that part skips with the probe's reason."""
    from wxsky.app.frame_publish import frame_layer_specs, publish_plan
    from wxsky.render.texture_export import (
        DRM_FORMAT_ABGR16161616F,
        DmaBufExporter,
        SlotExport,
        SlotTextures,
        fourcc_text,
        probe,
    )

    assert fourcc_text(DRM_FORMAT_ABGR16161616F) == "AB4H"
    renderer, plan, _ = linear_frame
    name = names()
    specs = frame_layer_specs(W, H, RING_PX, SHADOW_PX, RGBA16F)
    layers = [(s.name, s.max_width, s.max_height) for s in specs]
    formats = {s.name: s.format for s in specs}
    slots = SlotTextures(renderer.ctx, layers, formats=formats)
    try:
        with FrameWriter.create(name, specs) as writer, FrameReader.open(name) as reader:
            slot = writer.target_slot
            publish_plan(renderer, writer, plan, 1, RING_PX, SlotExport(slots, renderer, slot))
            frame = reader.read()
        for layer, pixels in frame.layers.items():
            h, w, _ = pixels.shape
            if h == 0:
                continue
            dtype = np.float16 if pixels.dtype == np.float16 else np.uint8
            got = np.frombuffer(slots.read(slot, layer, w, h), dtype).reshape(h, w, 4)
            assert got.tobytes() == pixels.tobytes(), layer
    finally:
        slots.close()
    here = probe(renderer.ctx)
    if not here.supported:
        pytest.skip(f"the dma-buf export of RGBA16F textures is not tested here: {here.reason}")
    exported = SlotTextures(renderer.ctx, layers[:1], 1, DmaBufExporter.create(), formats)
    try:
        textures, _fds = exported.descriptors()
        assert textures[0]["fourcc"] == DRM_FORMAT_ABGR16161616F
    finally:
        exported.close()


def test_the_c_compositor_composites_rgba16f_in_linear_and_tone_maps_once(
    linear_frame: tuple[Any, Any, dict[str, npt.NDArray[np.float16]]],
    names: Callable[[], str],
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """The GL compositor's composite of the RGBA16F layers (into a float buffer) is the Python
    reference host's composite_linear, and its picture is that through the daemon's display
    transform once (wxsky_gl_tone_map), at EV 0 and at EV +2."""
    from wxsky.app.frame_publish import frame_layer_specs, publish_plan
    from wxsky.host.reference import host_frame

    program = gl_program(host_kit, "wxsky_gl_composite")
    renderer, plan, _ = linear_frame
    name = names()
    specs = frame_layer_specs(W, H, RING_PX, SHADOW_PX, RGBA16F)
    with FrameWriter.create(name, specs) as writer, FrameReader.open(name) as reader:
        publish_plan(renderer, writer, plan, 1, RING_PX)
        ref = host_frame(reader.read())
        runs = {}
        for ev in (0.0, 2.0):
            out, lin = tmp_path / f"out{ev}.rgba", tmp_path / f"lin{ev}.f32"
            proc = subprocess.run(
                [str(program), name, str(out), "--linear-out", str(lin), "--exposure", str(ev)],
                capture_output=True,
                text=True,
                check=False,
            )
            if proc.returncode == 2:
                pytest.skip(f"no headless GL context: {proc.stdout.strip()}")
            assert proc.returncode == 0, proc.stdout + proc.stderr
            runs[ev] = (out, lin)
    assert ref.linear
    want_linear = ref.composite_linear()
    for ev, (out, lin) in runs.items():
        got_linear = np.fromfile(lin, np.float32).reshape(H, W, 4)[..., :3].astype(np.float64)
        # The composite: the same half floats blended by GL in float32 and by numpy in
        # float64, the near layer stretched by GL's bilinear filter and by numpy's.
        error = np.abs(got_linear - want_linear)
        print(
            f"EV {ev}: linear composite C vs Python: max {error.max():.3g}, mean "
            f"{error.mean():.3g} (values up to {want_linear.max():.3g})"
        )
        assert np.all(error <= LINEAR_TOLERANCE * (1.0 + np.abs(want_linear))), error.max()
        # The tone map, once, on the composite: the picture is exactly display() of the
        # linear composite it was made from (within GL's float rounding: one 8-bit level).
        got = np.fromfile(out, np.uint8).reshape(H, W, 4)
        from_linear = np.round(np.clip(exposure.display(got_linear, 2.0**ev), 0, 1) * 255.0)
        assert np.max(np.abs(got[..., :3] - from_linear)) <= 1.0
        assert np.all(got[..., 3] == 255)
        # and the reference host's picture of the same frame, made its way
        picture = np.abs(got.astype(int) - ref.composite(exposure=2.0**ev).astype(int))[..., :3]
        print(f"EV {ev}: picture C vs Python: max {picture.max()}, mean {picture.mean():.3g}")
        assert picture.mean() <= 0.05 and picture.max() <= 1  # llvmpipe: 0 and 0
    # EV +2 is brighter: the exposure reached the tone map
    assert np.fromfile(runs[2.0][0], np.uint8).mean() > np.fromfile(runs[0.0][0], np.uint8).mean()


@pytest.mark.gl
def test_the_c_compositor_refuses_linear_out_for_rgba8_layers(
    names: Callable[[], str],
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    program = gl_program(host_kit, "wxsky_gl_composite")
    from wxsky.app.frame_publish import frame_layer_specs

    name = names()
    specs = frame_layer_specs(24, 16, 8, 0)
    with FrameWriter.create(name, specs) as writer:
        writer.layer_buffer("sky", 24, 16)[:] = bytes([255]) * (24 * 16 * 4)
        writer.layer_buffer("near", 12, 8)
        for i in range(8):
            writer.layer_buffer(f"ring_{i}", 8, 8)
        writer.publish(1, record(1))
        proc = subprocess.run(
            [str(program), name, str(tmp_path / "o.rgba"), "--linear-out", str(tmp_path / "l")],
            capture_output=True,
            text=True,
            check=False,
        )
    if proc.returncode == 2:
        pytest.skip(f"no headless GL context: {proc.stdout.strip()}")
    assert proc.returncode == 1
    assert proc.stdout.strip() == "error linear: the segment's layers are RGBA8"


# ---- the daemon: setting, negotiation, publishing ------------------------------------------


@pytest.fixture(scope="module")
def daemons(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Any, Any]]:
    """Two daemons, clocks stopped: one set to rgba16f, one on the default."""
    from daemon_harness import DaemonSpec

    root = tmp_path_factory.mktemp("daemons")
    # Small pictures and impostors, not the default 960x540 and 512 texels: the hosts here
    # ask for their own sizes (160x90, 96x54), and the formats do not depend on either.
    small = "[camera]\nwidth = 160\nheight = 90\n[scene]\nring_texture_px = 64\n"
    specs = [
        DaemonSpec(root / "hdr", 'layer_format = "rgba16f"\n[clock]\nrate = 0.0\n' + small),
        DaemonSpec(root / "default", "[clock]\nrate = 0.0\n" + small),
    ]
    for spec in specs:
        spec.tmp_path.mkdir()
    with running_daemons(specs) as pair:
        yield pair


@pytest.mark.gl
@pytest.mark.xdist_group("hdr_daemons")
def test_a_daemon_negotiates_its_layer_format_and_keeps_publishing_after_bad_input(
    daemons: tuple[Any, Any],
) -> None:
    """A host asking for rgba16f gets it from the daemon set to it (and reads half floats
    from a version 2 segment) and is told rgba8 by the default one, with how to get it; a
    format outside the choices is one line naming it and them, and the daemon publishes on."""
    from wxsky.host.client import ControlClient, RemoteError
    from wxsky.host.reference import ReferenceHost

    hdr, default = daemons
    with ReferenceHost.connect(hdr.address, timeout_s=HANG_S) as host:
        answer = host.call("output_format", {"layer_format": "rgba16f"})
        assert answer == {
            "layer_format": "rgba16f",
            "granted": True,
            "reason": None,
            "segment_version": 2,
        }
        assert host.call("scene")["layer_format"] == "rgba16f"
        assert host.reader.version == 2
        before = host.reader.frame_number
        with pytest.raises(RemoteError) as info:
            host.call("output_format", {"layer_format": "rgba32f"})
        assert str(info.value) == (
            "output_format: layer_format: must be one of rgba8, rgba16f, got 'rgba32f'"
        )
        with pytest.raises(RemoteError) as info:
            host.call("output_format", {"layer_format": "x" * 30_000})
        assert str(info.value) == (
            "output_format: layer_format: must be one of rgba8, rgba16f, got a string of "
            "30000 characters"
        )
        with pytest.raises(RemoteError, match="output_format: depth: unknown key"):
            host.call("output_format", {"depth": 16})
        # Still publishing, half floats of scene-linear colour.
        frame = host.wait_frame(after=before, timeout_s=HANG_S)
        assert frame.linear and frame.layers.sky.dtype == np.float16
        assert frame.composite().dtype == np.uint8
        eight_bit = host.call("output_format", {"layer_format": "rgba8"})
        assert eight_bit["granted"] is False and eight_bit["layer_format"] == "rgba16f"
        assert 'layer_format = "rgba8"' in eight_bit["reason"]
    with ControlClient.connect(default.address, timeout_s=HANG_S) as client:
        asked = client.call("output_format", {"layer_format": "rgba16f"})
        assert asked["layer_format"] == "rgba8" and asked["granted"] is False
        assert asked["segment_version"] == 1
        assert 'start it with layer_format = "rgba16f"' in asked["reason"]
        assert client.call("output_format", {}) == {
            "layer_format": "rgba8",
            "granted": True,
            "reason": None,
            "segment_version": 1,
        }
    with FrameReader.open(default.shm_name) as reader:
        assert reader.version == 1
        assert reader.read(timeout_s=HANG_S).layers["sky"].dtype == np.uint8


@pytest.mark.gl
@pytest.mark.xdist_group("hdr_daemons")
def test_the_kits_snapshot_tool_writes_the_linear_picture_and_tone_maps_it_once(
    daemons: tuple[Any, Any],
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    """wxsky-host-snapshot against the rgba16f daemon writes the linear composite (a float
    framebuffer's, read back) as a PFM, and a PNG that is exactly that composite through the
    daemon's display transform at --exposure (1 EV: a scale of 2), drawn by
    wxsky_gl_tone_map; against the default daemon --linear-out is refused in one line. (The
    composite itself is held to the reference host's in the wxsky_gl_composite test above.)"""
    from wxsky.app.snapshot import read_pfm
    from wxsky.png import read_png

    program = gl_program(host_kit, "wxsky-host-snapshot")
    hdr, default = daemons
    size = ["--size", "160x90", "--pitch-deg", "5", "--timeout-s", str(HANG_S)]
    png, pfm = tmp_path / "hdr.png", tmp_path / "hdr.pfm"
    proc = subprocess.run(
        [
            *(str(program), "--control", hdr.address, *size, "--out", str(png)),
            *("--linear-out", str(pfm), "--exposure", "1"),
        ],
        capture_output=True,
        text=True,
        timeout=HANG_S * 2,
        check=False,
    )
    if proc.returncode == 2:
        pytest.skip(f"no headless GL context: {proc.stderr.strip()}")
    assert proc.returncode == 0, proc.stderr
    linear = read_pfm(pfm).astype(np.float64)
    picture = read_png(png)
    assert linear.shape == (90, 160, 3) and picture.shape[:2] == (90, 160)
    assert float(linear.max()) > 0.0
    want = np.round(np.clip(exposure.display(linear, 2.0), 0.0, 1.0) * 255.0)
    assert np.max(np.abs(picture[..., :3].astype(float) - want)) <= 1.0
    refused = subprocess.run(
        [
            *(str(program), "--control", default.address, *size),
            *("--out", str(tmp_path / "d.png"), "--linear-out", str(tmp_path / "d.pfm")),
        ],
        capture_output=True,
        text=True,
        timeout=HANG_S * 2,
        check=False,
    )
    assert refused.returncode == 1
    assert refused.stderr.strip() == (
        "wxsky-host-snapshot: error: --linear-out: the daemon publishes rgba8 layers (display "
        'values); start it with [output] layer_format = "rgba16f" for scene-linear ones'
    )


@pytest.mark.gl
@pytest.mark.xdist_group("hdr_daemons")
def test_the_reference_host_writes_the_linear_picture_and_tone_maps_it_once(
    daemons: tuple[Any, Any], tmp_path: Path
) -> None:
    """plugins/reference-host against the rgba16f daemon: --linear-out is the linear
    composite, the PNG that through the daemon's display at --exposure; against the default
    daemon --linear-out is refused (exit 2, one line) before anything is written."""
    from wxsky.app.snapshot import read_pfm
    from wxsky.png import read_png

    script = ROOT / "plugins" / "reference-host" / "reference_host.py"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    hdr, default = daemons
    png, pfm = tmp_path / "r.png", tmp_path / "r.pfm"
    args = ["--size", "96x54", "--exposure", "-1", "--out", str(png), "--linear-out", str(pfm)]
    proc = subprocess.run(
        [sys.executable, str(script), "--control", hdr.address, *args],
        capture_output=True,
        text=True,
        timeout=HANG_S * 2,
        env=env,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    linear = read_pfm(pfm).astype(np.float64)
    want = np.round(np.clip(exposure.display(linear, 0.5), 0.0, 1.0) * 255.0)
    # the PFM holds float32 of the float64 composite the PNG was made from
    assert np.max(np.abs(read_png(png)[..., :3].astype(float) - want)) <= 1.0
    refused = subprocess.run(
        [sys.executable, str(script), "--control", default.address, *args],
        capture_output=True,
        text=True,
        timeout=HANG_S * 2,
        env=env,
        check=False,
    )
    assert refused.returncode == 2
    assert refused.stderr.strip() == (
        "reference-host: error: composite_linear: this frame's layers are rgba8 display "
        'values; ask the daemon for rgba16f ([output] layer_format = "rgba16f")'
    )


def test_the_config_checks_the_layer_format(tmp_path: Path) -> None:
    from wxsky.errors import ConfigError
    from wxsky.settings.config import load_config

    path = tmp_path / "x.toml"
    path.write_text('[output]\nlayer_format = "rgba32f"\n')
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == (
        f"{path}:2: output.layer_format: must be one of rgba8, rgba16f, got 'rgba32f'"
    )
    path.write_text('[output]\nlayer_format = "RGBA16F"\n')
    assert load_config(path).output.layer_format == "rgba16f"
    assert load_config(None).output.layer_format == "rgba8"
