"""Shared-memory frame hand-off, on real POSIX shared memory and real processes."""

from __future__ import annotations

import logging
import mmap
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from wxsky.errors import WxskyError
from wxsky.output import shm
from wxsky.output.shm import Frame, FrameReader, FrameWriter, LayerSpec

LAYERS = [LayerSpec("clouds", 64, 32), LayerSpec("haze", 16, 16), LayerSpec("rain", 8, 4)]


@pytest.fixture
def name(shm_name: str) -> str:
    return shm_name


def exists(segment: str) -> bool:
    try:
        fd = shm._shm_open(segment, os.O_RDONLY)
    except FileNotFoundError:
        return False
    os.close(fd)
    return True


def run_python(code: str, *args: str, timeout: float = 10) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def fill(writer: FrameWriter, layer: str, pixels: np.ndarray) -> None:
    height, width, _ = pixels.shape
    view = writer.layer_buffer(layer, width, height)
    assert len(view) == width * height * 4
    np.frombuffer(view, dtype=np.uint8)[:] = pixels.ravel()


def test_round_trip_of_layers_with_different_used_sizes(name: str) -> None:
    rng = np.random.default_rng(1)
    clouds = rng.integers(0, 256, (20, 40, 4), dtype=np.uint8)
    haze = rng.integers(0, 256, (16, 16, 4), dtype=np.uint8)
    with (
        FrameWriter.create(name, LAYERS, meta_capacity=128) as writer,
        FrameReader.open(name) as reader,
    ):
        assert reader.layers == tuple(LAYERS)
        fill(writer, "clouds", clouds)
        fill(writer, "haze", haze)
        writer.publish(7, b"first")
        frame = reader.read()
        assert isinstance(frame, Frame)
        assert frame.frame_number == 7
        assert frame.meta == b"first"
        assert set(frame.layers) == {"clouds", "haze", "rain"}
        np.testing.assert_array_equal(frame.layers["clouds"], clouds)
        np.testing.assert_array_equal(frame.layers["haze"], haze)
        assert frame.layers["rain"].shape == (0, 0, 4)  # not written this frame: absent

        full = rng.integers(0, 256, (32, 64, 4), dtype=np.uint8)
        rain = rng.integers(0, 256, (4, 8, 4), dtype=np.uint8)
        fill(writer, "clouds", full)
        fill(writer, "rain", rain)
        writer.publish(8, b"")
        second = reader.read()
        assert second.frame_number == 8
        assert second.meta == b""
        np.testing.assert_array_equal(second.layers["clouds"], full)
        np.testing.assert_array_equal(second.layers["rain"], rain)
        assert second.layers["haze"].shape == (0, 0, 4)
        # Copies: the first frame is untouched by later publishes, and arrays are writable.
        np.testing.assert_array_equal(frame.layers["clouds"], clouds)
        second.layers["clouds"][0, 0, 0] ^= 1
        # The first frame's slot again: a layer it held then and not written now is absent.
        fill(writer, "rain", rain)
        writer.publish(9, b"")
        third = reader.read()
        assert third.layers["clouds"].shape == (0, 0, 4)
        assert third.layers["haze"].shape == (0, 0, 4)
        np.testing.assert_array_equal(third.layers["rain"], rain)


def test_frame_numbers_and_publish_checks(name: str) -> None:
    with (
        FrameWriter.create(name, LAYERS, meta_capacity=16) as writer,
        FrameReader.open(name) as reader,
    ):
        assert reader.frame_number == -1
        with pytest.raises(WxskyError, match="no frame has been published yet"):
            reader.read(timeout_s=0.02)
        writer.publish(0)
        assert reader.frame_number == 0
        writer.publish(5, b"m")
        assert reader.frame_number == 5
        assert reader.read().frame_number == 5
        with pytest.raises(ValueError, match="greater than the previous one"):
            writer.publish(5)
        with pytest.raises(ValueError, match="at most 16"):
            writer.publish(6, b"x" * 17)
        with pytest.raises(ValueError, match="unknown layer 'snow'"):
            writer.layer_buffer("snow", 1, 1)
        with pytest.raises(ValueError, match="exceeds its capacity 16x16"):
            writer.layer_buffer("haze", 17, 1)
        assert reader.frame_number == 5


def test_layer_buffer_is_released_by_publish(name: str) -> None:
    with FrameWriter.create(name, LAYERS) as writer:
        view = writer.layer_buffer("haze", 2, 2)
        view[:] = bytes(16)
        writer.publish(1)
        with pytest.raises(ValueError):
            view[0] = 1  # would otherwise scribble on the frame readers are copying


def test_concurrent_writer_never_yields_torn_frames(name: str) -> None:
    writer_code = """
        import signal, sys
        from wxsky.output.shm import FrameWriter, LayerSpec

        stop = False
        def on_term(*_):
            global stop
            stop = True
        signal.signal(signal.SIGTERM, on_term)
        layers = [LayerSpec("a", 256, 256), LayerSpec("b", 48, 32)]
        fills = [memoryview(bytes([v]) * (256 * 256 * 4)) for v in range(251)]
        clear = memoryview(bytes([238]) * (256 * 256 * 4))
        with FrameWriter.create(sys.argv[1], layers, meta_capacity=64) as writer:
            print("ready", flush=True)
            n = 0
            while not stop:
                n += 1
                pattern = fills[n % 251]
                wa, ha, wb, hb = 160 + n % 97, 128 + n % 129, 1 + n % 48, 1 + n % 32
                a = writer.layer_buffer("a", wa, ha)
                b = writer.layer_buffer("b", wb, hb)
                # Clear, then draw, like a renderer: a torn copy would show the clear value.
                a[:] = clear[: wa * ha * 4]
                b[:] = clear[: wb * hb * 4]
                a[:] = pattern[: wa * ha * 4]
                b[:] = pattern[: wb * hb * 4]
                writer.publish(n, n.to_bytes(8, "little") * (1 + n % 8))
    """
    proc = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(writer_code), name],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline() == "ready\n", proc.stderr and proc.stderr.read()
        seen: list[int] = []
        deadline = time.monotonic() + 60
        with FrameReader.open(name) as reader:
            while len(seen) < 500:
                # Wait for a newer frame so every read races a writer that is actually running.
                while seen and reader.frame_number <= seen[-1]:
                    assert time.monotonic() < deadline, "the writer stalled"
                    os.sched_yield()  # on a single core the writer needs this CPU
                frame = reader.read(timeout_s=60.0)
                n = frame.frame_number
                value = n % 251
                a, b = frame.layers["a"], frame.layers["b"]
                assert a.shape == (128 + n % 129, 160 + n % 97, 4)
                assert b.shape == (1 + n % 32, 1 + n % 48, 4)
                assert (a == value).all(), f"torn layer a in frame {n}"
                assert (b == value).all(), f"torn layer b in frame {n}"
                assert frame.meta == n.to_bytes(8, "little") * (1 + n % 8)
                assert not seen or n > seen[-1], "frame numbers went backwards"
                seen.append(n)
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert not exists(name)  # the writer's close() unlinked it


def test_open_missing_segment(name: str) -> None:
    with pytest.raises(WxskyError, match=f"no shared-memory frame segment named '{name}'"):
        FrameReader.open(name)


def test_invalid_segment_names() -> None:
    with pytest.raises(WxskyError, match="invalid shared-memory segment name"):
        FrameReader.open("a/b")
    with pytest.raises(WxskyError, match="invalid shared-memory segment name"):
        FrameWriter.create("", LAYERS)


def make_raw_segment(name: str, content: bytes) -> None:
    fd = shm._shm_open(name, os.O_CREAT | os.O_EXCL | os.O_RDWR)
    try:
        os.ftruncate(fd, 4096)
        with mmap.mmap(fd, 4096) as mm:
            mm[: len(content)] = content
    finally:
        os.close(fd)


def test_wrong_magic_is_refused_by_reader_and_writer(name: str) -> None:
    make_raw_segment(name, b"NOTWXSKY" + bytes(56))
    with pytest.raises(WxskyError, match="is not a wxsky frame segment"):
        FrameReader.open(name)
    with pytest.raises(WxskyError, match="not a wxsky frame segment; refusing to replace it"):
        FrameWriter.create(name, LAYERS)
    assert exists(name)


def test_wrong_version_is_refused(name: str) -> None:
    with FrameWriter.create(name, LAYERS):
        fd = shm._shm_open(name, os.O_RDWR)
        with mmap.mmap(fd, 4096) as mm:
            struct.pack_into("<I", mm, shm.HDR_VERSION, 3)
        os.close(fd)
        with pytest.raises(WxskyError, match="version 3; this wxsky understands versions 1 and 2"):
            FrameReader.open(name)


def test_close_is_idempotent_and_unlinks(name: str) -> None:
    writer = FrameWriter.create(name, LAYERS)
    reader = FrameReader.open(name)
    writer.publish(1)
    assert exists(name)
    assert reader.is_current()
    writer.close()
    writer.close()
    assert not exists(name)
    assert not reader.is_current()
    with pytest.raises(WxskyError, match="writer has closed frame segment"):
        reader.read()
    reader.close()
    reader.close()
    with pytest.raises(WxskyError, match="is closed"):
        reader.read()
    with pytest.raises(WxskyError, match="is closed"):
        writer.publish(2)
    with pytest.raises(WxskyError, match="no shared-memory frame segment"):
        FrameReader.open(name)


def test_second_writer_is_refused_while_the_first_lives(name: str) -> None:
    with FrameWriter.create(name, LAYERS) as first:
        with pytest.raises(
            WxskyError, match=rf"in use by another wxsky writer \(pid {os.getpid()}\)"
        ):
            FrameWriter.create(name, LAYERS)
        first.publish(1)  # untouched by the refused attempt
        with FrameReader.open(name) as reader:
            assert reader.read().frame_number == 1


def test_stale_segment_of_a_dead_writer_is_replaced(
    name: str, caplog: pytest.LogCaptureFixture
) -> None:
    crashed = run_python(
        """
        import os, sys
        from wxsky.output.shm import FrameWriter, LayerSpec
        writer = FrameWriter.create(sys.argv[1], [LayerSpec("x", 4, 4)])
        writer.publish(99)
        os._exit(0)  # dies without close(): the segment stays behind
        """,
        name,
    )
    assert crashed.returncode == 0, crashed.stderr
    assert exists(name)
    old_reader = FrameReader.open(name)
    assert old_reader.is_current()
    with caplog.at_level(logging.WARNING, logger="wxsky.output.shm"):
        writer = FrameWriter.create(name, LAYERS)
    with writer, FrameReader.open(name) as reader, old_reader:
        assert "replacing stale shared-memory segment" in caplog.text
        assert reader.layers == tuple(LAYERS)
        assert reader.frame_number == -1
        assert reader.is_current()
        # A host still attached to the dead writer's segment learns that it must reopen.
        assert old_reader.read().frame_number == 99
        assert not old_reader.is_current()


def test_reader_process_exit_leaves_the_segment(name: str) -> None:
    with FrameWriter.create(name, LAYERS) as writer:
        writer.layer_buffer("haze", 1, 1)[:] = b"\x01\x02\x03\x04"
        writer.publish(3, b"meta")
        for closes in (True, False):
            result = run_python(
                """
                import sys
                from wxsky.output.shm import FrameReader
                reader = FrameReader.open(sys.argv[1])
                frame = reader.read()
                assert frame.frame_number == 3 and frame.meta == b"meta", frame
                assert frame.layers["haze"].tobytes() == b"\\x01\\x02\\x03\\x04"
                if sys.argv[2] == "close":
                    reader.close()
                """,
                name,
                "close" if closes else "exit",
            )
            assert result.returncode == 0, result.stderr
            assert result.stderr == ""  # no resource_tracker "leaked" warning either
            assert exists(name)
        with FrameReader.open(name) as reader:
            assert reader.read().frame_number == 3


@pytest.mark.gl
def test_moderngl_reads_straight_into_a_layer_buffer(name: str) -> None:
    from wxsky.render.context import create_context

    ctx = create_context()
    try:
        fbo = ctx.simple_framebuffer((8, 4))
        fbo.use()
        ctx.clear(1.0, 0.5, 0.0, 1.0)
        with FrameWriter.create(name, LAYERS) as writer, FrameReader.open(name) as reader:
            fbo.read_into(writer.layer_buffer("clouds", 8, 4), components=4)
            writer.publish(1)
            pixels = reader.read().layers["clouds"]
        assert pixels.shape == (4, 8, 4)
        assert (pixels == np.array([255, 128, 0, 255], dtype=np.uint8)).all()
    finally:
        ctx.release()
