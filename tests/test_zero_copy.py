"""Zero-copy textures (docs/protocol.md §6): the probe, the slot textures' per-frame copies,
file descriptors over the control socket (SCM_RIGHTS, real memfds over a real unix socket,
to the Python side and to the C host kit), a real daemon's fallback answer with the C host
falling back to the segment and still compositing what the Python reference host does, and
the zero-copy import itself, which needs a GPU whose EGL exports dma-bufs: it skips with the
probe's reason elsewhere (llvmpipe)."""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
from daemon_harness import HANG_S, running_daemon
from host_kit import gl_program, host_kit, host_kit_sanitized, sanitizer_env  # noqa: F401
from server_thread import ServerThread

from wxsky.errors import RenderError
from wxsky.output.transport import WithFds

ROOT = Path(__file__).resolve().parents[1]
PROBE = ROOT / "tools" / "bench" / "probe_zero_copy.py"
ZERO_COPY = "wxsky_gl_zero_copy"
SANITIZER_EXITS = (98, 99)
ABGR8888 = 0x34324241  # 'AB24'


@pytest.fixture(scope="module")
def probed() -> dict[str, Any]:
    """What tools/bench/probe_zero_copy.py says of this machine (its own process, as a user runs
    it)."""
    proc = subprocess.run(
        [sys.executable, str(PROBE), "--json"], capture_output=True, text=True, timeout=60
    )
    if proc.returncode != 0 and "cannot create a headless EGL" in proc.stderr:
        pytest.skip(f"no EGL OpenGL context: {proc.stderr.strip().splitlines()[-1]}")
    assert proc.returncode == 0, proc.stderr
    found: dict[str, Any] = json.loads(proc.stdout)
    return found


# -- the probe --------------------------------------------------------------------------


@pytest.mark.gl
def test_the_probe_reports_what_this_machine_offers(probed: dict[str, Any]) -> None:
    # Facts the probe can only get right by looking.
    assert probed["udmabuf"] == os.path.exists("/dev/udmabuf")
    assert probed["render_nodes"] == sorted(
        f"/dev/dri/{n}"
        for n in (os.listdir("/dev/dri") if os.path.isdir("/dev/dri") else ())
        if n.startswith("renderD")
    )
    display = probed["display_extensions"]
    exports = "EGL_MESA_image_dma_buf_export" in display
    if not exports:
        assert probed["supported"] is False
        assert probed["reason"].startswith("no EGL_MESA_image_dma_buf_export on ")
        assert probed["gl_renderer"] in probed["reason"]
        assert probed["export"].startswith("not called: the display does not list")
    else:
        assert probed["supported"] == probed["export"].startswith("ok: fourcc ")
    if "llvmpipe" in probed["gl_renderer"]:
        # Mesa's CPU renderer here (Debian 12: Mesa 22.3.6): EGLImages from GL textures, but
        # no dma-buf export, and no DRM device behind its EGL display.
        assert "Mesa" in probed["gl_version"]
        assert not exports
        assert "EGL_KHR_gl_texture_2D_image" in display
        assert "EGL_MESA_device_software" in probed["device"]["extensions"]
        assert probed["device"]["drm_render_node"] is None


@pytest.mark.gl
def test_the_exporter_names_the_missing_extension(renderer: Any, probed: dict[str, Any]) -> None:
    from wxsky.render.texture_export import DmaBufExporter, probe

    here = probe(renderer.ctx)
    assert here.reason == probed["reason"]  # the daemon's context: the same as the tool's
    if here.supported:
        pytest.skip("this EGL display exports dma-bufs (the GPU test covers it)")
    with pytest.raises(RenderError, match="EGL_MESA_image_dma_buf_export"):
        DmaBufExporter.create()


@pytest.mark.gl
def test_slot_textures_hold_each_slots_layers_top_row_first(renderer: Any) -> None:
    """The per-frame GPU copies (what a host imports on a GPU), on llvmpipe's real GL: each
    layer lands in the corner of its slot's capacity-sized texture, rows as in the segment,
    and the other slot keeps what it had."""
    from wxsky.render.context import release_framebuffer
    from wxsky.render.texture_export import SlotTextures

    ctx = renderer.ctx
    rng = np.random.default_rng(7)
    frame = rng.integers(0, 256, size=(5, 9, 4), dtype=np.uint8)  # 9 x 5, not the capacity
    src = ctx.texture((9, 5), 4, frame.tobytes())
    fbo = ctx.framebuffer(color_attachments=[src])
    slots = SlotTextures(ctx, [("sky", 16, 8), ("ring_0", 4, 4)])
    try:
        slots.copy(1, "sky", fbo)
        renderer.finish()
        got = np.frombuffer(slots.read(1, "sky", 9, 5), np.uint8).reshape(5, 9, 4)
        assert np.array_equal(got, frame)
        whole = np.frombuffer(slots.read(1, "sky", 16, 8), np.uint8).reshape(8, 16, 4)
        assert not whole[5:].any() and not whole[:, 9:].any()  # only the corner was written
        assert not np.frombuffer(slots.read(0, "sky", 16, 8), np.uint8).any()
        with pytest.raises(RenderError, match="not exported"):
            slots.descriptors()
    finally:
        slots.close()
        release_framebuffer(fbo)
        src.release()


# -- descriptors over the socket ----------------------------------------------------------


def memfds(count: int) -> list[int]:
    """Real descriptors standing in for dma-bufs: memfds with known, distinct contents."""
    fds = []
    for i in range(count):
        fd = os.memfd_create(f"wxsky-zc-test-{i}")
        os.write(fd, bytes([0xA0 + i]) * 16 + b"tail")
        fds.append(fd)
    return fds


def exported_answer(fds: list[int]) -> dict[str, Any]:
    """An answer shaped as the daemon's (§6): two slots of `sky` and `ring_0`, the second
    slot's ring sharing the first fd's buffer at an offset (planes may share an fd)."""
    textures = []
    for slot in range(2):
        for layer, size in (("sky", (64, 32)), ("ring_0", (16, 16))):
            fd = len(textures) if len(textures) < len(fds) else 0
            textures.append(
                {
                    "layer": layer,
                    "slot": slot,
                    "width": size[0],
                    "height": size[1],
                    "fourcc": ABGR8888,
                    "modifier": 0x0300000000606014,  # a 64-bit value, as NVIDIA's block-linear
                    "planes": [{"fd": fd, "stride": size[0] * 4, "offset": 4096 * slot}],
                }
            )
    return {
        "supported": True,
        "slot_count": 2,
        "sync": "seqlock",
        "renderer": "test",
        "fd_count": len(fds),
        "textures": textures,
    }


TCP_ANSWER = {"supported": False, "reason": "tcp: no descriptors", "fallback": "shm"}


class FdServer(ServerThread):
    """A real ControlServer whose `export_textures` answers with real memfds; before it, a
    burst of notifications, so the descriptors have bytes of other messages in front."""

    def __init__(self, address: str, fds: list[int]) -> None:
        self.fds = fds
        super().__init__(address, self.handle)

    async def handle(self, method: str, params: dict[str, Any]) -> Any:
        if method == "export_textures":
            for seq in range(20):
                self.server.broadcast("tick", {"seq": seq, "pad": "x" * 200})
            return WithFds(exported_answer(self.fds), tuple(self.fds), without_fds=TCP_ANSWER)
        return {"method": method}


@contextlib.contextmanager
def fd_server(address: str, count: int = 3) -> Iterator[FdServer]:
    fds = memfds(count)
    server = FdServer(address, fds)
    try:
        yield server
    finally:
        server.stop()
        for fd in fds:
            os.close(fd)


def recv_answer(sock: socket.socket, msgid: int) -> tuple[Any, list[int]]:
    """Reads until the response to msgid; every descriptor that came meanwhile."""
    unpacker = msgpack.Unpacker(raw=False)
    got: list[int] = []
    while True:
        data, fds, _, _ = socket.recv_fds(sock, 65536, 253)
        assert data, "the server hung up"
        got.extend(fds)
        unpacker.feed(data)
        for msg in unpacker:
            if msg[0] == 1 and msg[1] == msgid:
                return msg, got


def test_descriptors_pass_over_the_unix_socket_with_the_answer(tmp_path: Path) -> None:
    with fd_server(f"unix:{tmp_path / 'zc.sock'}") as server:
        with socket.socket(socket.AF_UNIX) as sock:
            sock.connect(str(tmp_path / "zc.sock"))
            sock.sendall(msgpack.packb([0, 1, "subscribe", {"topics": ["tick"]}]))
            sock.sendall(msgpack.packb([0, 2, "export_textures", {}]))
            msg, fds = recv_answer(sock, 2)
        try:
            assert msg[2] is None and msg[3]["supported"] is True
            assert msg[3]["fd_count"] == len(fds) == 3
            for i, (ours, theirs) in enumerate(zip(server.fds, fds, strict=True)):
                assert theirs != ours  # a new descriptor in this process ...
                assert os.fstat(theirs).st_ino == os.fstat(ours).st_ino  # ... for the same file
                assert os.pread(theirs, 16, 0) == bytes([0xA0 + i]) * 16
        finally:
            for fd in fds:
                os.close(fd)
        for fd in server.fds:  # the sender keeps its own
            assert os.fstat(fd).st_size == 20


def test_a_tcp_connection_gets_the_answer_without_descriptors() -> None:
    with fd_server("tcp:127.0.0.1:0") as server:
        port = server.server.address.port  # type: ignore[union-attr]
        with socket.create_connection(("127.0.0.1", port)) as sock:
            sock.sendall(msgpack.packb([0, 7, "export_textures", {}]))
            unpacker = msgpack.Unpacker(raw=False)
            while True:
                data = sock.recv(65536)
                assert data
                unpacker.feed(data)
                msgs = [m for m in unpacker if m[0] == 1]
                if msgs:
                    break
    assert msgs[0][1] == 7 and msgs[0][3] == TCP_ANSWER


@pytest.mark.parametrize("sanitized", [False, True], ids=["plain", "sanitized"])
def test_the_c_client_receives_the_descriptors_with_the_answer(
    tmp_path: Path, request: pytest.FixtureRequest, sanitized: bool
) -> None:
    """wxsky_request_textures on the kit's client, behind 20 notifications the client queues
    while it waits: the answer parsed, each plane mapped to its descriptor, each descriptor
    the server's file (same inode, same bytes) and close-on-exec; then a raw call whose
    descriptors nobody claims, which the next poll closes, and the textures' own closed by
    wxsky_textures_close: the process ends with as many open as before."""
    build: Path = request.getfixturevalue("host_kit_sanitized" if sanitized else "host_kit")
    address = f"unix:{tmp_path / 'zc.sock'}"
    with fd_server(address) as server:
        proc = subprocess.run(
            [
                str(build / "wxsky_client_check"),
                "session",
                address,
                "fds",
                "sub:tick",
                "textures",
                "call:export_textures",
                "drain:300",
                "fds",
            ],
            capture_output=True,
            text=True,
            timeout=60,
            env=sanitizer_env() if sanitized else None,
        )
        inodes = [os.fstat(fd).st_ino for fd in server.fds]
    assert proc.returncode not in SANITIZER_EXITS, proc.stderr
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = [json.loads(line) for line in proc.stdout.splitlines()]
    tex = next(line for line in lines if line.get("step") == "textures")
    assert tex["status"] == "WXSKY_OK" and tex["supported"] is True, tex
    assert tex["fd_count"] == 3 and tex["slot_count"] == 2
    assert [fd["ino"] for fd in tex["fds"]] == inodes
    assert [fd["head"] for fd in tex["fds"]] == [bytes([0xA0 + i] * 16).hex() for i in range(3)]
    assert all(fd["cloexec"] for fd in tex["fds"])
    want = exported_answer([0, 1, 2])["textures"]
    assert tex["textures"] == want
    ticks = [line for line in lines if line.get("method") == "tick"]
    assert len(ticks) == 40  # the queued ones and the second call's, none lost
    before, after = (line["open"] for line in lines if line.get("step") == "fds")
    assert after == before


# -- a real daemon ------------------------------------------------------------------------


def daemon_composite(
    kit: Path, d: Any, tmp_path: Path, *extra: str
) -> tuple[str, str, np.ndarray, np.ndarray]:
    """The C host asks the daemon for textures, the daemon is stopped, both hosts read its
    latest frame: (textures line, ok line, C picture, Python reference picture)."""
    from wxsky.host.reference import ReferenceHost

    exe = gl_program(kit, ZERO_COPY)
    out = tmp_path / "zc.rgba"
    with ReferenceHost.connect(d.address) as host:
        host.call(
            "set_camera",
            {"heading_deg": 200.0, "pitch_deg": 6.0, "fov_deg": 75.0, "width": 320, "height": 180},
        )
        host.wait_settled_frame(after=host.reader.frame_number + 2, timeout_s=HANG_S)
        proc = subprocess.Popen(
            [str(exe), d.address, d.shm_name, str(out), "--wait-stdin", *extra],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert proc.stdout is not None and proc.stdin is not None
        textures = proc.stdout.readline().strip()
        d.pause()
        try:
            ref_frame = host.read_latest()
            stdout, stderr = proc.communicate("go\n", timeout=60)
        finally:
            d.resume()
    if proc.returncode == 2:
        pytest.skip(f"no headless EGL context: {stdout.strip()}")
    assert proc.returncode == 0, textures + "\n" + stdout + stderr
    ok = stdout.strip().splitlines()[-1]
    assert ok.split()[3] == str(ref_frame.meta.frame_number), ok
    got = np.fromfile(out, dtype=np.uint8).reshape(180, 320, 4)
    return textures, ok, got, ref_frame.composite()


@pytest.mark.gl
def test_a_daemon_without_exports_says_why_and_the_c_host_falls_back(
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
    probed: dict[str, Any],
) -> None:
    if probed["supported"]:
        pytest.skip("this GPU exports dma-bufs: the fallback is not what the daemon answers")
    with running_daemon(tmp_path, extra_config="[clock]\nrate = 0.0\n") as d:
        # The answer itself, on a raw socket: no descriptors, the probe's reason.
        with socket.socket(socket.AF_UNIX) as sock:
            sock.connect(str(d.socket_path))
            sock.sendall(msgpack.packb([0, 1, "export_textures", {}]))
            msg, fds = recv_answer(sock, 1)
            sock.sendall(msgpack.packb([0, 2, "export_textures", {"slots": 3}]))
            bad, _ = recv_answer(sock, 2)
        assert fds == []
        assert msg[2] is None
        assert msg[3] == {"supported": False, "reason": probed["reason"], "fallback": "shm"}
        assert "EGL_MESA_image_dma_buf_export" in msg[3]["reason"]
        assert bad[2] == "export_textures: slots: unknown key"
        with d.client() as c:
            assert c.call("status")["zero_copy"] == {
                "supported": False,
                "reason": probed["reason"],
                "exported": False,
            }
        # The C host: asks, is told no, reads the segment and composites as before.
        textures, ok, got, ref = daemon_composite(host_kit, d, tmp_path)
    assert textures.startswith("textures WXSKY_OK supported 0 count 0 fds 0 reason no ")
    assert "EGL_MESA_image_dma_buf_export" in textures
    assert " mode shm " in ok
    per_channel = np.mean(np.abs(got.astype(int) - ref.astype(int)), axis=(0, 1))
    assert np.all(per_channel <= 1.0), per_channel


@pytest.mark.gl
def test_zero_copy_textures_composite_as_the_segment_does(
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
    probed: dict[str, Any],
) -> None:
    """The GPU path: the daemon exports its slot textures, the C host imports them (no CPU
    copy) and composites the frame the Python reference host reads from the segment."""
    if not probed["supported"]:
        pytest.skip(f"no zero-copy textures on this machine: {probed['reason']}")
    with running_daemon(tmp_path, extra_config="[clock]\nrate = 0.0\n") as d:
        textures, ok, got, ref = daemon_composite(host_kit, d, tmp_path, "--require")
        with d.client() as c:
            assert c.call("status")["zero_copy"]["exported"] is True
            layers = c.call("scene")["layers"]
    # every layer of the segment, in both slots
    assert textures.startswith(f"textures WXSKY_OK supported 1 count {2 * len(layers)} ")
    assert " mode zero-copy " in ok
    per_channel = np.mean(np.abs(got.astype(int) - ref.astype(int)), axis=(0, 1))
    assert np.all(per_channel <= 1.0), per_channel


def test_with_fds_refuses_more_than_one_message_carries() -> None:
    with pytest.raises(ValueError, match=r"1\.\.253"):
        WithFds({}, tuple(range(254)), without_fds={})
    with pytest.raises(ValueError, match=r"1\.\.253"):
        WithFds({}, (), without_fds={})


@pytest.mark.gl
def test_a_published_frame_goes_to_the_slot_textures_as_to_the_segment(
    renderer: Any, tmp_path: Path
) -> None:
    """The daemon's half of the GPU path, on llvmpipe: `publish_plan` with the slot textures
    of the slot being filled (as the daemon does once a host took textures) puts into them,
    layer for layer, exactly the pixels it writes into the segment, in that slot."""
    import uuid

    from conftest import GL_RING_PX

    from wxsky.app.frame_publish import draw_ring, frame_layer_specs, publish_plan
    from wxsky.engine.stages import SkyEngine
    from wxsky.output import shm
    from wxsky.output.shm import FrameReader, FrameWriter
    from wxsky.render.texture_export import SlotExport, SlotTextures
    from wxsky.scene.camera import Camera
    from wxsky.scene.layout import SceneSettings
    from wxsky.weather.state import WeatherState

    camera = Camera(position_m=(0.0, 0.0, 900.0), pitch_deg=5.0, width_px=64, height_px=48)
    engine = SkyEngine(
        WeatherState(), camera, SceneSettings(ring_texture_px=GL_RING_PX), clock_rate=0.0
    )
    plan = engine.advance(0.0)
    draw_ring(renderer, plan)
    renderer.render_frame(plan.frame)
    specs = frame_layer_specs(80, 60, GL_RING_PX)
    name = f"wxsky-zc-{uuid.uuid4().hex[:10]}"
    writer = FrameWriter.create(name, specs)
    slots = SlotTextures(renderer.ctx, [(s.name, s.max_width, s.max_height) for s in specs])
    try:
        slot = writer.target_slot
        publish_plan(renderer, writer, plan, 1, GL_RING_PX, SlotExport(slots, renderer, slot))
        with FrameReader.open(name) as reader:
            frame = reader.read(timeout_s=1.0)
        assert writer.target_slot == 1 - slot
        present = {k: v for k, v in frame.layers.items() if v.shape[0] > 0}
        assert {"sky", "near", "ring_0", "ring_7"} <= set(present)
        assert present["sky"].any()
        for layer, pixels in present.items():
            h, w, _ = pixels.shape
            got = np.frombuffer(slots.read(slot, layer, w, h), np.uint8).reshape(h, w, 4)
            assert np.array_equal(got, pixels), layer
        # the other slot was not touched
        assert not np.frombuffer(slots.read(1 - slot, "sky", 64, 48), np.uint8).any()
    finally:
        slots.close()
        writer.close()
        with contextlib.suppress(FileNotFoundError):
            shm._shm_unlink(name)


@pytest.mark.gl
def test_a_host_whose_gl_cannot_import_falls_back_to_the_segment(
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
    probed: dict[str, Any],
) -> None:
    """A daemon that says "supported" (real descriptors: memfds) to a host whose EGL cannot
    take them: the C compositor's run-time check refuses the import, names what is missing,
    and the host composites from the segment what the Python reference host does."""
    import uuid

    from test_host_c_gl import publish, python_composite, synthetic

    from wxsky.output import shm

    exe = gl_program(host_kit, ZERO_COPY)
    specs, images, meta = synthetic(fading=False, front=False)
    name = f"wxsky-zc-{uuid.uuid4().hex[:10]}"
    writer = publish(name, specs, images, meta)
    address = f"unix:{tmp_path / 'zc.sock'}"
    out = tmp_path / "out.rgba"
    try:
        with fd_server(address):
            proc = subprocess.run(
                [str(exe), address, name, str(out)], capture_output=True, text=True, timeout=60
            )
        if proc.returncode == 2:
            pytest.skip(f"no headless EGL context: {proc.stdout.strip()}")
        assert proc.returncode == 0, proc.stdout + proc.stderr
        ref = python_composite(name)
    finally:
        writer.close()
        with contextlib.suppress(FileNotFoundError):
            shm._shm_unlink(name)
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("textures WXSKY_OK supported 1 count 4 fds 3 "), lines
    assert lines[1].startswith("import failed WXSKY_EFORMAT: "), lines
    if "EGL_EXT_image_dma_buf_import" not in probed["display_extensions"]:
        assert "no EGL_EXT_image_dma_buf_import on this EGL display" in lines[1]
    assert " mode shm " in lines[2]
    h, w = ref.shape[:2]
    got = np.fromfile(out, dtype=np.uint8).reshape(h, w, 4)
    assert np.abs(got.astype(int) - ref.astype(int)).max() <= 1
