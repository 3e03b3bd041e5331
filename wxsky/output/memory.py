"""Room for a large allocation, checked before it is made: a picture the size of a poster or
a shared-memory segment that does not fit is refused with one line giving what it needs and
what there is, rather than found out by the kernel's out-of-memory killer or a SIGBUS.

What there is, is the tightest of: MemAvailable in /proc/meminfo, the headroom under the
process's cgroup (v2) memory.max, and under its RLIMIT_DATA and RLIMIT_AS; for a segment
also the free space of /dev/shm (a tmpfs, whose pages are memory too). A margin is kept spare
(`MARGIN_FRAC` of it, at least `MARGIN_MIN_BYTES`): the rest of the system, and an estimate's
error, need some.
"""

from __future__ import annotations

import os
import resource
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from wxsky.errors import RuntimeFailure

MIB = 1 << 20
GIB = 1 << 30
MARGIN_FRAC = 0.1
MARGIN_MIN_BYTES = 256 * MIB
SHM_DIR = Path("/dev/shm")


@dataclass(frozen=True)
class Headroom:
    """Bytes that may still be taken from one limit, and which limit (for the message)."""

    bytes: int
    source: str


def fmt_bytes(n: float) -> str:
    """1.5 GiB, 312 MiB, 4 KiB: as a person reads a size."""
    if abs(n) >= GIB:
        return f"{n / GIB:.1f} GiB"
    if abs(n) >= MIB:
        return f"{n / MIB:.0f} MiB"
    return f"{n / 1024:.0f} KiB"


def _kib_field(path: Path, key: str) -> int | None:
    """A `Key:   123 kB` line of a /proc file, in bytes; None if absent or unreadable."""
    try:
        text = path.read_text()
    except OSError:
        return None
    for line in text.splitlines():
        name, _, value = line.partition(":")
        if name == key:
            parts = value.split()
            if parts and parts[0].isdigit():
                return int(parts[0]) * 1024
    return None


def _cgroup_headroom() -> Headroom | None:
    """memory.max - memory.current of this process's cgroup v2, when it has a limit."""
    try:
        lines = Path("/proc/self/cgroup").read_text().splitlines()
    except OSError:
        return None
    for line in lines:
        if line.startswith("0::"):
            folder = Path("/sys/fs/cgroup") / line[3:].lstrip("/")
            try:
                limit = (folder / "memory.max").read_text().strip()
                current = int((folder / "memory.current").read_text().strip())
            except (OSError, ValueError):
                return None
            if not limit.isdigit():
                return None  # "max": no limit
            return Headroom(max(0, int(limit) - current), f"cgroup {folder}/memory.max")
    return None


def _rlimit_headroom(which: int, name: str, used_key: str) -> Headroom | None:
    soft, _ = resource.getrlimit(which)
    if soft == resource.RLIM_INFINITY:
        return None
    used = _kib_field(Path("/proc/self/status"), used_key) or 0
    return Headroom(max(0, soft - used), f"{name} {fmt_bytes(soft)}, {fmt_bytes(used)} used")


def memory_headroom(private: bool = True) -> list[Headroom]:
    """Every memory limit this process knows of, with what is left under it. `private`
    False: for a shared mapping, which RLIMIT_DATA does not count."""
    out = []
    available = _kib_field(Path("/proc/meminfo"), "MemAvailable")
    if available is not None:
        out.append(Headroom(available, "MemAvailable in /proc/meminfo"))
    for found in (
        _cgroup_headroom(),
        _rlimit_headroom(resource.RLIMIT_DATA, "RLIMIT_DATA", "VmData") if private else None,
        _rlimit_headroom(resource.RLIMIT_AS, "RLIMIT_AS", "VmSize"),
    ):
        if found is not None:
            out.append(found)
    return out


def shm_headroom(folder: Path = SHM_DIR) -> list[Headroom]:
    """The free space of the shared-memory tmpfs (none where it has no such folder)."""
    try:
        st = os.statvfs(folder)
    except OSError:
        return []
    return [Headroom(st.f_bavail * st.f_frsize, f"free in {folder}")]


def require(need_bytes: int, what: str, headroom: Sequence[Headroom]) -> None:
    """Raise RuntimeFailure, one line, if `what` (needing about need_bytes) does not fit the
    tightest of `headroom` less the margin; nothing is allocated either way."""
    if not headroom:
        return
    tightest = min(headroom, key=lambda h: h.bytes)
    margin = max(MARGIN_MIN_BYTES, int(MARGIN_FRAC * tightest.bytes))
    if need_bytes > tightest.bytes - margin:
        raise RuntimeFailure(
            f"{what} needs about {fmt_bytes(need_bytes)}, but only "
            f"{fmt_bytes(tightest.bytes)} is available ({tightest.source}) and "
            f"{fmt_bytes(margin)} is kept spare; make it smaller"
        )
