"""Issue 40, attack 7: another process of the daemon's user truncates the frame segment.

Before, the writer stored frames through a mapping of the segment, and a truncation from a
second process ended the daemon with SIGBUS within a frame, no log line, its socket left.
Now the writer and the Python reader never touch a mapping of the file (pwrite / pread), and
the writer finds the change at its next frame, writes the segment whole again, counts it and
logs it. Every truncation here is made by a second process, on the real /dev/shm file.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from daemon_harness import HANG_S, running_daemon

from wxsky.errors import WxskyError
from wxsky.output.shm import FrameReader, FrameWriter, LayerSpec

LAYERS = [LayerSpec("clouds", 64, 32), LayerSpec("ring", 32, 32)]


def truncate_from_another_process(name: str, size: int) -> None:
    """`os.truncate('/dev/shm/<name>', size)`, done by a second process as an attacker would."""
    subprocess.run(
        [
            sys.executable,
            "-c",
            "import os, sys; os.truncate(sys.argv[1], int(sys.argv[2]))",
            f"/dev/shm/{name}",
            str(size),
        ],
        check=True,
        timeout=60,
    )


def segment_size(name: str) -> int:
    return os.stat(f"/dev/shm/{name}").st_size


def publish(writer: FrameWriter, frame: int, clouds: np.ndarray, ring: np.ndarray) -> None:
    """A frame as the daemon makes one: clouds drawn every frame, the ring kept once a slot
    holds it (so a restored segment must hold the kept pixels again too)."""
    np.frombuffer(writer.layer_buffer("clouds", 64, 32), np.uint8)[:] = clouds.ravel()
    if not writer.keep_layer("ring", 32, 32, "ring-1"):
        np.frombuffer(writer.layer_buffer("ring", 32, 32, "ring-1"), np.uint8)[:] = ring.ravel()
    writer.publish(frame, f"frame {frame}".encode())


@pytest.mark.parametrize("cut", ["zero", "half"])
def test_a_truncated_segment_is_written_again_and_readers_survive(
    shm_name: str, cut: str, caplog: pytest.LogCaptureFixture
) -> None:
    rng = np.random.default_rng(7)
    ring = rng.integers(0, 256, (32, 32, 4), dtype=np.uint8)
    with FrameWriter.create(shm_name, LAYERS) as writer, FrameReader.open(shm_name) as reader:
        full = writer.segment_size
        for frame in (1, 2, 3):  # both slots hold the ring: the next frames keep it
            clouds = np.full((32, 64, 4), frame, np.uint8)
            publish(writer, frame, clouds, ring)
        assert reader.read().frame_number == 3

        truncate_from_another_process(shm_name, 0 if cut == "zero" else full // 2)
        assert segment_size(shm_name) < full
        # A reader of the shortened file does not fault: no frame, and it says why.
        if cut == "zero":
            with pytest.raises(WxskyError, match="shorter than its header says"):
                reader.read(timeout_s=0.05)

        with caplog.at_level(logging.WARNING, logger="wxsky.output.shm"):
            for frame in (4, 5):
                publish(writer, frame, np.full((32, 64, 4), frame, np.uint8), ring)
        assert segment_size(shm_name) == full
        got = reader.read()
        assert got.frame_number == 5 and got.meta == b"frame 5"
        assert (got.layers["clouds"] == 5).all()
        # Kept from before the truncation, not drawn again: written back whole.
        np.testing.assert_array_equal(got.layers["ring"], ring)
        status = writer.segment_status()
        assert status["restores"] == 1 and status["write_errors"] == 0
        assert "resized" in str(status["last_problem"])
        lines = [r.getMessage() for r in caplog.records]
        lines = [line for line in lines if "changed under the writer" in line]
        assert len(lines) == 1 and shm_name in lines[0], lines
        # The other slot too: the frame before holds its kept ring again.
        publish(writer, 6, np.full((32, 64, 4), 6, np.uint8), ring)
        np.testing.assert_array_equal(reader.read().layers["ring"], ring)


def test_a_truncation_during_a_frame_is_found_at_the_next(shm_name: str) -> None:
    """Truncated after the frame began: the frame's own writes extend the file again (the
    rest reads as zeros, pages dropped), and the next frame finds and mends that."""
    ring = np.full((32, 32, 4), 9, np.uint8)
    with FrameWriter.create(shm_name, LAYERS) as writer, FrameReader.open(shm_name) as reader:
        full = writer.segment_size
        for frame in (1, 2):
            publish(writer, frame, np.full((32, 64, 4), frame, np.uint8), ring)
        view = writer.layer_buffer("clouds", 64, 32)  # frame 3 begun: its check is done
        truncate_from_another_process(shm_name, 0)
        np.frombuffer(view, np.uint8)[:] = 3
        assert writer.keep_layer("ring", 32, 32, "ring-1")
        writer.publish(3)
        assert writer.segment_status()["restores"] == 0  # not yet seen
        publish(writer, 4, np.full((32, 64, 4), 4, np.uint8), ring)
        assert writer.segment_status()["restores"] == 1
        assert os.stat(f"/dev/shm/{shm_name}").st_size == full
        got = reader.read()
        assert got.frame_number == 4
        np.testing.assert_array_equal(got.layers["ring"], ring)


def test_a_mended_slot_moves_its_seq_on(shm_name: str) -> None:
    """A reader that copied a slot while the file was short or holed read zeros under an
    unchanged seq; the mend moves every published slot's seq on (odd while it is written
    again), so that reader's second look at the seq sends it back, not off with a torn frame."""
    import struct

    def seqs() -> list[int]:
        with open(f"/dev/shm/{shm_name}", "rb") as f:
            data = f.read()
        return [struct.unpack_from("<Q", data, writer._layout.slot_base(s))[0] for s in (0, 1)]

    with FrameWriter.create(shm_name, LAYERS) as writer:
        ring = np.full((32, 32, 4), 9, np.uint8)
        for frame in (1, 2):
            publish(writer, frame, np.full((32, 64, 4), frame, np.uint8), ring)
        before = seqs()
        assert all(s and not s & 1 for s in before)
        truncate_from_another_process(shm_name, writer.segment_size // 2)
        writer.layer_buffer("clouds", 64, 32)  # the next frame's check mends the segment
        after = seqs()
        # Both moved on by the mend; the slot now being filled is odd again, as every frame.
        assert all(a >= b + 2 for a, b in zip(after, before, strict=True))
        assert not after[1 - writer.target_slot] & 1


def test_a_daemon_survives_truncations_of_its_segment(tmp_path: Path) -> None:
    """The attack against a real daemon: truncated to 0 and to half by a second process,
    the daemon keeps running and publishing (a reader sees frame numbers advance), its
    segment is its size again, status counts what happened, the log has a line, and it
    still exits cleanly, removing its socket."""
    with running_daemon(tmp_path) as daemon:
        name = daemon.shm_name
        full = segment_size(name)
        for n, size in enumerate((0, full // 2), start=1):
            with FrameReader.open(name) as reader:
                before = reader.read(timeout_s=HANG_S).frame_number
                truncate_from_another_process(name, size)
                deadline = time.monotonic() + HANG_S
                while True:
                    assert daemon.proc.poll() is None, f"daemon died:\n{daemon.log()}"
                    with daemon.client() as c:
                        status = c.call("status")
                    if status["segment"]["restores"] >= n:
                        break
                    assert time.monotonic() < deadline, f"not restored:\n{daemon.log()}"
                    time.sleep(0.05)
                # The same reader, without reopening: later frames, from the same segment;
                # frames published after the status that counted the restore, so after the
                # restore (it is counted as it begins, and a frame waits for it to end).
                after = max(before + 1, status["frames_published"])
                while (frame := reader.read(timeout_s=HANG_S).frame_number) <= after:
                    assert time.monotonic() < deadline, "frames stopped"
                    time.sleep(0.05)
                assert frame > after
                assert reader.is_current()
            assert segment_size(name) == full == status["segment"]["size_bytes"]
            assert status["segment"]["restores"] == n
            assert status["segment"]["write_errors"] == 0
        assert daemon.proc.poll() is None
        # Cut during a frame, the frame's own writes extend it again before the next check:
        # the size the log gives is whatever the writer then found.
        assert "was changed under the writer: it was resized to" in daemon.log()
        code, _ = daemon.stop(signal.SIGTERM)
        assert code == 0, daemon.log()
        assert not daemon.socket_path.exists()


def test_a_fatal_signal_leaves_a_line_in_the_daemons_log(tmp_path: Path) -> None:
    """Whatever still ends the daemon by a fatal signal (here SIGBUS sent by hand) leaves a
    line and the stacks in its log; before, the truncation's SIGBUS left nothing."""
    with running_daemon(tmp_path) as daemon:
        daemon.proc.send_signal(signal.SIGBUS)
        code = daemon.proc.wait(timeout=HANG_S)
        assert code == -signal.SIGBUS
        assert "Fatal Python error: Bus error" in daemon.log()
