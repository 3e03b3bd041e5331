"""The daemon's memory figures and the heap trim: real allocations, read back from /proc and
glibc."""

from __future__ import annotations

import pytest

from wxsky.app import memory


def test_memory_status_reads_this_process() -> None:
    m = memory.memory_status(trims=3, trimmed_kib=7)
    assert m["rss_kib"] > 1024  # a Python process with numpy is megabytes
    assert m["peak_rss_kib"] >= m["rss_kib"] * 0.9
    assert m["python_blocks"] > 0
    assert (m["trims"], m["trimmed_kib"]) == (3, 7)


@pytest.mark.skipif(memory._libc() is None, reason="not glibc >= 2.33: no mallinfo2/malloc_trim")
def test_a_trim_gives_freed_heap_back() -> None:
    # Many small blocks from the heap (under glibc's mmap threshold), the even ones freed
    # last so the heap's top stays in use: only malloc_trim's page release gets them back.
    blocks = [bytearray(64 * 1024) for _ in range(2000)]
    for b in blocks:
        b[::4096] = b"\x01" * len(b[::4096])  # touched: resident
    held = memory.memory_status()["heap"]["in_use_kib"]
    del blocks[:-1]
    before = memory.memory_status()
    assert before["heap"]["free_kib"] > 64 * 1024  # freed, but kept inside the heap
    assert before["heap"]["in_use_kib"] < held
    given = memory.trim()
    assert given is not None and given > 32 * 1024
    assert memory.rss_kib() < before["rss_kib"] - 32 * 1024


# Eight threads that malloc and free at once, outside the GIL (ctypes lets it go for the
# call): glibc gives contending threads arenas of their own. Prints the arena heaps in use
# (64 MiB-aligned anonymous mappings, tools/soak/rss_parts.py) and limit_arenas' answer.
_CONTEND = """
import ctypes, json, re, sys, threading
from wxsky.app import memory
cap = memory.limit_arenas() if sys.argv[1] == "cap" else None
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
start = threading.Barrier(8)
def churn():
    start.wait()
    for _ in range(20000):
        libc.free(libc.malloc(4096))
threads = [threading.Thread(target=churn) for _ in range(8)]
for t in threads: t.start()
for t in threads: t.join()
heaps = 0
for line in open("/proc/self/maps"):
    m = re.match(r"([0-9a-f]+)-([0-9a-f]+) rw-p 00000000 00:00 0 *$", line)
    if m and int(m[1], 16) % (64 << 20) == 0 and int(m[2], 16) - int(m[1], 16) <= 64 << 20:
        heaps += 1
print(json.dumps({"cap": cap, "heaps": heaps}))
"""


@pytest.mark.skipif(memory._libc() is None, reason="not glibc >= 2.33: no mallopt to cap with")
def test_arenas_are_capped_unless_the_user_set_their_own() -> None:
    import json
    import os
    import subprocess
    import sys

    def run(mode: str, **env: str) -> dict[str, int | None]:
        base = {k: v for k, v in os.environ.items() if k not in ("MALLOC_ARENA_MAX",)}
        out = subprocess.run(
            [sys.executable, "-c", _CONTEND, mode],
            env={**base, **env},
            capture_output=True,
            text=True,
            check=True,
            timeout=120,
        ).stdout
        result: dict[str, int | None] = json.loads(out)
        return result

    free = run("free")
    capped = run("cap")
    assert capped["cap"] == memory.ARENAS
    # The main arena is the brk heap, not one of these: a cap of 2 leaves one arena heap.
    assert capped["heaps"] <= memory.ARENAS - 1 < free["heaps"], (capped, free)
    assert run("cap", MALLOC_ARENA_MAX="4")["cap"] is None  # the user's own wins
