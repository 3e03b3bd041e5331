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
