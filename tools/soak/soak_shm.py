"""The shared-memory side of tools/soak/soak.py, run as its own processes, as hosts would be:

    soak_shm.py check SHM_NAME STATS.json   the checking reader: reads every frame it can and
                                            checks each one; writes its counts every second
    soak_shm.py farm SHM_NAME               readers to kill: for each line `kill N MAX_S` on
                                            stdin, forks N readers that attach and read frames
                                            in a loop and SIGKILLs each at a random moment
                                            within MAX_S; answers one JSON line per command

A frame counts as **torn** when its parts disagree: the frame record's frame number is not
the slot's; a layer's size is not what the record says (sky at the record's camera size, near
at half of it, ring_in_* present exactly while it fades, shadow exactly when it places one); or two
reads of the same frame number, one straight after the other, differ in any byte (the slot
of a published frame is not written again until the writer has flipped twice, so a clean copy
is always the same copy). Frame numbers going back count apart (`order_errors`).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from wxsky.errors import WxskyError
from wxsky.output.frame_meta import FrameMeta
from wxsky.output.shm import Frame, FrameReader
from wxsky.render.renderer import near_layer_size

MAX_PROBLEMS = 20  # torn frames and errors described in the stats; all are counted


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="role", required=True)
    check = sub.add_parser("check", help="the checking reader")
    check.add_argument("shm_name")
    check.add_argument("stats", type=Path)
    farm = sub.add_parser("farm", help="readers to kill mid-read")
    farm.add_argument("shm_name")
    farm.add_argument("--seed", type=int, default=1)
    args = p.parse_args()
    if args.role == "check":
        return CheckingReader(args.shm_name, args.stats).run()
    return _farm(args.shm_name, random.Random(args.seed))


# -- the checking reader ------------------------------------------------------------------


class CheckingReader:
    def __init__(self, shm_name: str, stats_path: Path) -> None:
        self.shm_name = shm_name
        self.stats_path = stats_path
        self.stop = False
        self.last = -1
        self.first: int | None = None
        self.reads = 0
        self.frames = 0  # distinct frames read and checked
        self.double_reads = 0  # frames read twice and compared
        self.torn = 0
        self.order_errors = 0
        self.skipped = 0  # frames published that this reader never saw
        self.read_errors = 0
        self.reopens = 0
        self.problems: list[str] = []
        self.per_second: list[tuple[float, int]] = []  # (unix time, distinct frames read)
        self._count_this_second = 0

    def run(self) -> int:
        signal.signal(signal.SIGTERM, self._on_signal)
        signal.signal(signal.SIGINT, self._on_signal)
        reader = self._open()
        next_write = time.monotonic() + 1.0
        try:
            while not self.stop and reader is not None:
                now = time.monotonic()
                if now >= next_write:
                    next_write = now + 1.0
                    self.per_second.append((time.time(), self._count_this_second))
                    self._count_this_second = 0
                    self._write_stats()
                if reader.frame_number <= self.last:
                    time.sleep(0.002)
                    continue
                reader = self._read_once(reader)
        finally:
            if reader is not None:
                reader.close()
            self._write_stats()
        return 0

    def _on_signal(self, signum: int, frame: object) -> None:
        self.stop = True

    def _open(self) -> FrameReader | None:
        deadline = time.monotonic() + 30.0
        while not self.stop and time.monotonic() < deadline:
            try:
                return FrameReader.open(self.shm_name)
            except WxskyError:
                time.sleep(0.1)
        self._problem(f"could not open segment {self.shm_name!r}")
        return None

    def _read_once(self, reader: FrameReader) -> FrameReader | None:
        try:
            frame = reader.read(timeout_s=1.0)
            self.reads += 1
            self._check(frame)
            again = reader.read(timeout_s=1.0)
            self.reads += 1
        except WxskyError as exc:
            self.read_errors += 1
            self._problem(f"read error: {exc}")
            if not reader.is_current():
                reader.close()
                self.reopens += 1
                return self._open()
            return reader
        if again.frame_number == frame.frame_number:
            self.double_reads += 1
            differs = _differences(frame, again)
            if differs:
                self._torn(frame.frame_number, f"second read differs in {', '.join(differs)}")
        else:
            self._check(again)
        return reader

    def _check(self, frame: Frame) -> None:
        n = frame.frame_number
        if n <= self.last:
            self.order_errors += 1
            self._problem(f"frame {n} read after frame {self.last}")
            return
        if self.first is None:
            self.first = n
        elif n > self.last + 1:
            self.skipped += n - self.last - 1
        self.last = n
        self.frames += 1
        self._count_this_second += 1
        why = _structure_problem(frame)
        if why:
            self._torn(n, why)

    def _torn(self, frame_number: int, why: str) -> None:
        self.torn += 1
        self._problem(f"torn frame {frame_number}: {why}")

    def _problem(self, text: str) -> None:
        if len(self.problems) < MAX_PROBLEMS:
            self.problems.append(text)

    def _write_stats(self) -> None:
        stats: dict[str, Any] = {
            "first_frame": self.first,
            "last_frame": self.last,
            "reads": self.reads,
            "frames": self.frames,
            "double_reads": self.double_reads,
            "torn": self.torn,
            "order_errors": self.order_errors,
            "skipped": self.skipped,
            "read_errors": self.read_errors,
            "reopens": self.reopens,
            "problems": self.problems,
            "per_second": self.per_second,
        }
        tmp = self.stats_path.with_suffix(".tmp")
        tmp.write_text(json.dumps(stats))
        tmp.replace(self.stats_path)


def _structure_problem(frame: Frame) -> str | None:
    """Why a frame's parts disagree with each other, or None."""
    try:
        meta = FrameMeta.unpack(frame.meta)
    except WxskyError as exc:
        return f"frame record: {exc}"
    if meta.frame_number != frame.frame_number:
        return f"record says frame {meta.frame_number}"
    cam = (meta.camera.height_px, meta.camera.width_px)
    near_w, near_h = near_layer_size(meta.camera)
    expected = {"sky": cam, "near": (near_h, near_w)}
    layers = frame.layers
    for name, size in expected.items():
        if layers[name].shape[:2] != size:
            return f"{name} is {layers[name].shape[:2]}, for the record's camera {size}"
    if layers["near_front"].size and layers["near_front"].shape[:2] != (near_h, near_w):
        return f"near_front is {layers['near_front'].shape[:2]}, near {(near_h, near_w)}"
    ring = layers["ring_0"].shape
    for name, pixels in layers.items():
        if name.startswith("ring_in_"):
            if bool(pixels.size) != meta.fading:
                return f"{name} {'present' if pixels.size else 'absent'}, fading {meta.fading}"
            if pixels.size and pixels.shape != ring:
                return f"{name} is {pixels.shape}, ring_0 {ring}"
        elif name.startswith("ring_") and (pixels.shape != ring or not pixels.size):
            return f"{name} is {pixels.shape}, ring_0 {ring}"
    if "shadow" in layers and bool(layers["shadow"].size) != (meta.shadow is not None):
        return f"shadow layer {layers['shadow'].shape}, record places {meta.shadow}"
    return None


def _differences(a: Frame, b: Frame) -> list[str]:
    out = [name for name in a.layers if not np.array_equal(a.layers[name], b.layers[name])]
    if a.meta != b.meta:
        out.append("the frame record")
    return out


# -- the reader farm ----------------------------------------------------------------------


def _farm(shm_name: str, rng: random.Random) -> int:
    """Single-threaded, so forking it is safe; each child is a fresh reader."""
    for line in sys.stdin:
        words = line.split()
        if len(words) != 3 or words[0] != "kill":
            print(json.dumps({"error": f"unknown command {line.strip()!r}"}), flush=True)
            continue
        count, max_s = int(words[1]), float(words[2])
        print(json.dumps(_kill_readers(shm_name, count, max_s, rng)), flush=True)
    return 0


def _kill_readers(shm_name: str, count: int, max_s: float, rng: random.Random) -> dict[str, Any]:
    children: list[tuple[float, int, int]] = []  # (kill at, pid, read end of its pipe)
    start = time.monotonic()
    for _ in range(count):
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the reader: never returns
            os.close(r)
            _reader_child(shm_name, w)
        os.close(w)
        children.append((start + rng.uniform(0.05, max_s), pid, r))
    reading = killed = 0
    for kill_at, pid, r in sorted(children):
        time.sleep(max(0.0, kill_at - time.monotonic()))
        os.set_blocking(r, False)
        try:
            reads = len(os.read(r, 1 << 16))  # one byte per completed read
        except BlockingIOError:
            reads = 0
        os.close(r)
        os.kill(pid, signal.SIGKILL)
        _, status = os.waitpid(pid, 0)
        reading += reads > 0
        killed += os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
    return {"spawned": count, "reading_when_killed": reading, "killed": killed}


def _reader_child(shm_name: str, pipe: int) -> None:
    code = 0
    try:
        reader = FrameReader.open(shm_name)
        os.set_blocking(pipe, False)
        while True:  # until the SIGKILL, most of the time inside read()
            reader.read(timeout_s=1.0)
            with contextlib.suppress(BlockingIOError):
                os.write(pipe, b".")
    except BaseException:
        code = 1
    os._exit(code)


if __name__ == "__main__":
    raise SystemExit(main())
