"""What the daemon's memory is, for `status`, and giving freed heap back to the system.

A long-running daemon with a few dozen threads (render, workers, Zenoh, readers) allocates
from several glibc malloc arenas. Bursts (a 100,000-message flood, a 20,000-region CIGI
datagram, a thunderstorm's towers) free what they took, but glibc keeps freed pages inside
its heaps until something asks it to give them back, so RSS steps up with each burst and
never comes down: issue 40's hour-long soak saw +18 % that way while the Python objects
alive stayed level. `status` tells the two apart (`python_blocks` and the heap's
`in_use_kib` against `rss_kib`), and `trim` (glibc's `malloc_trim(0)`, which also returns
free pages in the middle of a heap) runs once a minute on a worker thread, never on the
frame path. Elsewhere than glibc both are absent and say so.

Trimming was not enough. A 16-minute attack soak with RSS read by kind of mapping
(`tools/soak/rss_parts.py`) placed the rest of the climb: once the block cache was full the
main heap stayed level (86-88 MiB) and the other arenas went 90 -> 159 MiB, the heap's free
bytes 68 -> 119 MiB: freed memory spread over more and more per-thread arenas (glibc makes
up to 8 per core as threads contend: Zenoh's, llvmpipe's, the workers'), each holding
pages that a few live chunks pin. `limit_arenas` caps them at ARENAS before the daemon's
threads start, so freed memory is used again wherever it was freed; a user's own
MALLOC_ARENA_MAX (or glibc tunable) wins.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import resource
import sys
from functools import cache
from typing import Any

log = logging.getLogger(__name__)

TRIM_EVERY_S = 60.0
# The daemon's threads that allocate much at once hold the GIL while they do (numpy), so
# more arenas buy little: two keep a thread outside Python (Zenoh, llvmpipe) off its lock.
ARENAS = 2
_M_ARENA_MAX = -8  # mallopt's parameter number (malloc.h)
_PAGE_KIB = os.sysconf("SC_PAGE_SIZE") // 1024 if hasattr(os, "sysconf") else 4


class _Mallinfo2(ctypes.Structure):
    # glibc >= 2.33; every field a size_t.
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena",  # bytes from sbrk (the main arena)
            "ordblks",
            "smblks",
            "hblks",
            "hblkhd",  # bytes in mmapped chunks
            "usmblks",
            "fsmblks",
            "uordblks",  # bytes in use
            "fordblks",  # bytes free inside the heaps
            "keepcost",
        )
    ]


@cache
def _libc() -> Any | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.malloc_trim.argtypes = [ctypes.c_size_t]
        libc.malloc_trim.restype = ctypes.c_int
        libc.mallinfo2.restype = _Mallinfo2
        libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
        libc.mallopt.restype = ctypes.c_int
    except (OSError, AttributeError):  # not glibc, or one older than 2.33
        return None
    return libc


def limit_arenas(arenas: int = ARENAS) -> int | None:
    """Cap glibc's malloc arenas at `arenas` for this process; call it before the threads
    start (arenas made before stay). Returns the cap now in force, None where it is not
    glibc or the user set their own (MALLOC_ARENA_MAX, GLIBC_TUNABLES' arena_max)."""
    if "MALLOC_ARENA_MAX" in os.environ or "arena_max" in os.environ.get("GLIBC_TUNABLES", ""):
        return None
    libc = _libc()
    if libc is None or libc.mallopt(_M_ARENA_MAX, arenas) != 1:
        return None
    return arenas


def rss_kib() -> int | None:
    """Resident set size now (not the peak), from /proc."""
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * _PAGE_KIB
    except (OSError, ValueError, IndexError):
        return None


def memory_status(trims: int = 0, trimmed_kib: int = 0) -> dict[str, Any]:
    """`status`'s `memory`: RSS now and at most, Python's live blocks, glibc's heap (bytes
    in use, free inside it, in mmapped chunks) where it is glibc, and the caller's count of
    trims and what they gave back."""
    out: dict[str, Any] = {
        "rss_kib": rss_kib(),
        "peak_rss_kib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
        "python_blocks": sys.getallocatedblocks(),
        "heap": None,
        "trims": trims,
        "trimmed_kib": trimmed_kib,
    }
    libc = _libc()
    if libc is not None:
        info = libc.mallinfo2()
        out["heap"] = {
            "in_use_kib": info.uordblks // 1024,
            "free_kib": info.fordblks // 1024,
            "mmapped_kib": info.hblkhd // 1024,
        }
    return out


def trim() -> int | None:
    """Give the heaps' free pages back to the system (glibc); returns the RSS given back in
    KiB, None where there is no `malloc_trim`. Takes milliseconds, holding each arena's lock
    in turn: call it off the frame path."""
    libc = _libc()
    if libc is None:
        return None
    before = rss_kib()
    libc.malloc_trim(0)
    after = rss_kib()
    given = max(0, before - after) if before is not None and after is not None else 0
    if given >= 16 * 1024:
        log.debug("memory: gave %d MiB of freed heap back", given // 1024)
    return given


class TraceReport:
    """Where Python memory grew, for a daemon started with `PYTHONTRACEMALLOC=1` (or
    `-X tracemalloc`): each `report()` lists the source lines whose allocations grew most
    since the first. Taking a snapshot walks every traced block (a fraction of a second on
    the loop): a diagnostic for hunting a leak, never on in normal running."""

    def __init__(self) -> None:
        self._first: Any | None = None

    def report(self, limit: int = 20) -> str:
        import tracemalloc

        if not tracemalloc.is_tracing():
            return "tracemalloc is off: start the daemon with PYTHONTRACEMALLOC=1"
        snapshot = tracemalloc.take_snapshot().filter_traces(
            (tracemalloc.Filter(False, tracemalloc.__file__),)
        )
        if self._first is None:
            self._first = snapshot
            traced, _ = tracemalloc.get_traced_memory()
            return f"tracemalloc: first snapshot, {traced // 1024} KiB traced"
        stats = snapshot.compare_to(self._first, "lineno")[:limit]
        lines = [
            f"{s.size_diff // 1024:+d} KiB {s.count_diff:+d} blocks {s.traceback}" for s in stats
        ]
        return "tracemalloc growth since the first snapshot:\n  " + "\n  ".join(lines)
