"""Issue 14, memory: a snapshot or a segment too large for the memory there is is refused,
before it is allocated, with one line giving the estimate and what is available; and only
the process that made a segment removes it."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from wxsky.app.snapshot import snapshot_bytes
from wxsky.errors import RuntimeFailure
from wxsky.output import memory
from wxsky.output.memory import Headroom
from wxsky.output.shm import FrameReader, FrameWriter, LayerSpec
from wxsky.scene.layout import SceneSettings

GIB = 1 << 30


@pytest.fixture
def name(shm_name: str) -> str:
    return shm_name


def test_headroom_reads_memavailable_and_require_refuses_past_the_margin() -> None:
    kib = next(
        int(line.split()[1])
        for line in Path("/proc/meminfo").read_text().splitlines()
        if line.startswith("MemAvailable:")
    )
    found = {h.source: h.bytes for h in memory.memory_headroom()}
    assert abs(found["MemAvailable in /proc/meminfo"] - kib * 1024) < GIB  # read moments apart
    room = [Headroom(4 * GIB, "MemAvailable in /proc/meminfo"), Headroom(8 * GIB, "other")]
    memory.require(3 * GIB, "a thing", room)  # 4 GiB less 10 % spare holds it
    with pytest.raises(RuntimeFailure) as err:
        memory.require(int(3.7 * GIB), "a thing", room)
    assert str(err.value) == (
        "a thing needs about 3.7 GiB, but only 4.0 GiB is available (MemAvailable in "
        "/proc/meminfo) and 410 MiB is kept spare; make it smaller"
    )


def test_the_snapshot_estimate_covers_the_measured_peaks() -> None:
    # Peak resident memory of `wxsky snapshot --preset clear` measured on llvmpipe (KiB).
    settings = SceneSettings()
    for (w, h), peak_kib in (((960, 540), 279_908), ((1920, 1080), 689_460)):
        estimate = snapshot_bytes(w, h, settings)
        assert peak_kib * 1024 < estimate < 1.5 * peak_kib * 1024 + 100 * 2**20


# Runs the snapshot under a 2 GiB data limit from a small interpreter of its own and prints
# the snapshot's peak resident memory (KiB). Linux counts the memory of the process a child
# was forked from in the child's peak until its exec: started from a pytest worker that has
# run many tests, the child's figure was the worker's, not the snapshot's.
_MEASURE = """
import os, resource, subprocess, sys
resource.setrlimit(resource.RLIMIT_DATA, (2 * 2**30, resource.RLIM_INFINITY))
with open(sys.argv[1], "wb") as stderr:
    proc = subprocess.Popen(sys.argv[2:], stdout=subprocess.DEVNULL, stderr=stderr)
    _, status, usage = os.wait4(proc.pid, 0)
print(os.waitstatus_to_exitcode(status), usage.ru_maxrss)
"""


def test_a_huge_snapshot_is_refused_before_it_allocates(tmp_path: Path) -> None:
    out, log = tmp_path / "big.png", tmp_path / "stderr.txt"
    # 8192x8192 needs some 17 GiB; under a 2 GiB data limit, before the fix it was attempted
    # (and died of it after allocating what it could); now it is refused up front.
    command = [
        *(sys.executable, "-m", "wxsky", "snapshot", "--preset", "clear"),
        *("--size", "8192x8192", "--out", str(out)),
    ]
    measured = subprocess.run(
        [sys.executable, "-c", _MEASURE, str(log), *command],
        capture_output=True,
        text=True,
        check=True,
    )
    code, peak_kib = (int(v) for v in measured.stdout.split())
    err = log.read_text()
    assert code == 1, err
    assert err.count("\n") == 1, err
    assert err.startswith("wxsky: error: snapshot 8192x8192 needs about 17.7 GiB, but only ")
    assert "is available (RLIMIT_DATA 2.0 GiB, " in err
    assert not out.exists()
    assert peak_kib < 512 * 1024  # KiB: no layer of the picture was ever allocated


def test_a_segment_too_large_for_memory_is_refused_before_it_is_made(name: str) -> None:
    script = textwrap.dedent(
        """
        import resource, sys
        from pathlib import Path
        from wxsky.errors import RuntimeFailure
        from wxsky.output.shm import FrameWriter, LayerSpec
        status = Path("/proc/self/status").read_text()
        vm = next(int(l.split()[1]) for l in status.splitlines() if l.startswith("VmSize:"))
        # Room for 64 MiB more address space: a 2 x 64 MiB segment's mapping does not fit.
        resource.setrlimit(resource.RLIMIT_AS, (vm * 1024 + (64 << 20), resource.RLIM_INFINITY))
        try:
            FrameWriter.create(sys.argv[1], [LayerSpec("sky", 4096, 4096)])
        except RuntimeFailure as exc:
            print(exc)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script, name], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    line = done.stdout.strip()
    assert line.startswith(
        f"shared-memory segment {name!r} (1 layers up to 4096x4096, 2 slots) needs about "
        "128 MiB, but only "
    ), line
    assert "(RLIMIT_AS " in line
    assert not Path(f"/dev/shm/{name}").exists()


WRITER = textwrap.dedent(
    """
    import logging, sys
    from wxsky.output.shm import FrameWriter, LayerSpec
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    writer = FrameWriter.create(sys.argv[1], [LayerSpec("sky", 8, 8)])
    writer.publish(int(sys.argv[2]))
    print("ready", flush=True)
    sys.stdin.readline()
    writer.close()
    """
)


def _start_writer(name: str, frame: int) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER, name, str(frame)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line == "ready\n", proc.communicate(timeout=30)
    return proc


def _stop(proc: subprocess.Popen[str]) -> str:
    _, err = proc.communicate("close\n", timeout=30)
    assert proc.returncode == 0, err
    return err


def test_a_writer_never_removes_a_segment_another_process_made_under_its_name(
    name: str,
) -> None:
    first = _start_writer(name, 1)
    # The name is taken from under the first writer (by hand, as a cleanup script does with
    # /dev/shm/NAME), and a second writer makes a new segment under it.
    os.unlink(f"/dev/shm/{name}")
    second = _start_writer(name, 2)
    try:
        err = _stop(first)
        # Before the fix the first writer's close unlinked the name: the second's segment.
        with FrameReader.open(name) as reader:
            assert reader.read().frame_number == 2
        assert f"frame segment {name!r}: the name now belongs to another segment" in err
        assert f"(writer pid {second.pid}); left it" in err
    finally:
        if second.poll() is None:
            _stop(second)
    assert not Path(f"/dev/shm/{name}").exists()  # its own maker removed it


def test_a_second_writer_on_a_live_name_is_refused_and_removes_nothing(name: str) -> None:
    first = _start_writer(name, 1)
    try:
        done = subprocess.run(
            [sys.executable, "-c", WRITER, name, "5"],
            input="close\n",
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode != 0
        assert "is in use by another wxsky writer" in done.stderr
        with FrameReader.open(name) as reader:
            assert reader.read().frame_number == 1
    finally:
        _stop(first)
    assert not Path(f"/dev/shm/{name}").exists()


def test_a_small_segment_still_fits(name: str) -> None:
    with FrameWriter.create(name, [LayerSpec("sky", 64, 64)]) as writer:
        writer.publish(1)
    assert not Path(f"/dev/shm/{name}").exists()
