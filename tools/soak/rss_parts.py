"""What a process's resident memory is made of, by kind of mapping, from /proc/PID/smaps.

The soak samples it beside RSS so that a climb can be placed: glibc's main heap, its other
arenas (threads that malloc get their own, up to 8 per core, each a 64 MiB-aligned mapping),
anonymous executable memory (llvmpipe's compiled shaders), other anonymous mappings (large
numpy arrays and other mmapped chunks, GL buffers, stacks) and files (libraries, fonts).
"""

from __future__ import annotations

import re

# glibc's HEAP_MAX_SIZE on 64-bit: 2 * DEFAULT_MMAP_THRESHOLD_MAX (32 MiB). A thread arena's
# heap starts on a multiple of it, and no heap is larger.
ARENA_ALIGN = 64 * 1024 * 1024
PARTS = ("main_heap", "arenas", "jit", "anon", "files")
_RANGE = re.compile(r"^([0-9a-f]+)-([0-9a-f]+) (\S+) \S+ \S+ \S+\s*(.*)$")


def rss_parts(pid: int) -> dict[str, int]:
    """KiB resident in each of PARTS (summing to RSS, give or take the moment between reads)."""
    out = dict.fromkeys(PARTS, 0)
    kind = "anon"
    with open(f"/proc/{pid}/smaps", encoding="ascii", errors="replace") as f:
        for line in f:
            m = _RANGE.match(line)
            if m is not None:
                start, end = int(m[1], 16), int(m[2], 16)
                perms, path = m[3], m[4].strip()
                kind = _kind(start, end, perms, path)
            elif line.startswith("Rss:"):
                out[kind] += int(line.split()[1])
    return out


def _kind(start: int, end: int, perms: str, path: str) -> str:
    if path == "[heap]":
        return "main_heap"
    if path and not path.startswith("["):
        return "files"  # /dev/zero and memfd mappings included: named, not malloc's
    if path:
        return "anon"  # [stack], [vdso] and the like
    if "x" in perms:
        return "jit"
    if start % ARENA_ALIGN == 0 and end - start <= ARENA_ALIGN:
        return "arenas"
    return "anon"
