"""POSIX shared-memory frame hand-off: a double-buffered segment guarded by per-slot seqlocks.

The daemon (one `FrameWriter`) renders each frame into the *inactive* slot while hosts (any
number of `FrameReader`s, in any language) copy the *active* one. Every slot has its own sequence
counter, odd while the writer is filling it, so a reader detects a frame that changed under it and
retries; it never waits for the writer, which only ever touches the other slot.

Layout (all integers little-endian, every field naturally aligned; offsets in bytes)::

    Header, at segment offset 0
      off size type   field
        0    8 char[8] magic            b"WXSKYSHM"
        8    4 u32     version          1
       12    4 u32     header_size      offset of slot 0 (multiple of 4096)
       16    4 u32     slot_count       2
       20    4 u32     layer_count      L
       24    8 u64     slot_size        bytes per slot (multiple of 4096)
       32    4 u32     meta_capacity    bytes of the metadata region of each slot
       36    4 u32     writer_pid       process id of the writer (diagnostics only)
       40    4 u32     active_slot      slot holding the latest published frame (0 or 1)
       44    4 u32     state            0 initialising, 1 live, 2 closed by the writer
       48    8 u64     latest_frame     frame number of the latest published frame
       56    8 u64     publish_count    frames published so far (0: none yet)
       64 D*L          layer descriptors, D bytes each (D = 32 in version 1, 40 in 2):
                         +0  char[16] name        ASCII, NUL padded (no NUL when 16 long)
                         +16 u32      max_width   pixels
                         +20 u32      max_height  pixels
                         +24 u64      capacity    max_width * max_height * B bytes
                         +32 u32      format      version 2 only: 0 RGBA8 (B = 4),
                                                  1 RGBA16F (B = 8)
                         +36 u32      reserved    version 2 only: 0

    Slot i, at segment offset header_size + i * slot_size
      off size type   field
        0    8 u64     seq              odd while the writer fills the slot; 0: never written
        8    8 u64     frame_number     frame number of the frame in the slot
       16    4 u32     meta_length      used bytes of the metadata region
       20    4 u32     meta_offset      offset of the metadata region from the slot start
       24 16*L         layer table, 16 bytes each, in descriptor order:
                         +0  u32 width    used width of the layer in this frame (0: absent)
                         +4  u32 height   used height
                         +8  u64 offset   offset of the pixels from the *segment* start
      meta_offset      metadata region, meta_capacity bytes, the first meta_length used
      layer offsets    pixels: RGBA8 or RGBA16F (the layer's format), premultiplied alpha,
                       rows top to bottom, tightly packed (stride = width * B), each region
                       64-byte aligned

Versions. A segment whose layers are all RGBA8 is written as version 1, byte for byte the
layout of before HDR layers (so every reader of before still reads the default). A segment
with any RGBA16F layer (`[output] layer_format = "rgba16f"`) is version 2: its descriptors
carry the format, and a reader of version 1 refuses it for its version rather than reading
half floats as bytes. RGBA16F pixels are IEEE 754 binary16, little-endian, scene-linear
colour before exposure and tone map (docs/linear-output.md).

Writer, per frame: make the inactive slot's seq odd (before the first pixel is written), fill
pixels, layer table, frame number and metadata, make seq even, then store active_slot,
latest_frame and publish_count. Reader: load active_slot, load seq (retry if odd or 0), copy what
it needs, load seq and active_slot again; if either changed, retry. Re-checking active_slot is what
keeps frame numbers monotonic: without it a reader could return a frame that was complete but not
yet made active, and its next read would then go back one frame.

Memory ordering. Python cannot issue fences; each field is stored by a separate aligned 4- or
8-byte store (memoryview casts copy whole items, so a reader never sees half a counter), in
program order. On x86-64 (TSO) stores become visible in that order, which is all the seqlock needs.
On weakly ordered CPUs (AArch64) nothing in Python orders them, so the residual risk of a torn
frame there is accepted. A C/C++ reader must, on any CPU: load seq with acquire semantics
(`atomic_load_explicit(&seq, memory_order_acquire)`), copy, issue
`atomic_thread_fence(memory_order_acquire)`, then load seq (and active_slot) again; plain loads
let the compiler move the copy outside the two checks. A C writer stores seq odd, issues
`atomic_thread_fence(memory_order_release)`, writes the slot, then stores seq even and
active_slot with `memory_order_release`.

Stale segments. The writer holds an exclusive `flock` on the segment for its whole life (the kernel
drops it when the process dies, however it dies). `FrameWriter.create` on an existing name tries
that lock: if another process holds it the name is in use and creation fails; if not, the old
writer is gone and the segment is unlinked and recreated. Readers still mapping the old segment
see no new frames; `FrameReader.is_current()` tells them to reopen. The segment is created with
mode 0600: only processes of the daemon's user can attach. A writer only ever unlinks the file
it made (the name must still refer to its file's device and inode): if the name was removed
and made again by another writer, closing leaves that one alone. Before anything is made, the
segment's size is checked against the free space of /dev/shm and the memory available
(`output.memory`), and refused with both figures if it does not fit.

Truncation. Any process of the daemon's user may `ftruncate` /dev/shm/<name>; a store or load
through a mapping of a page past the new end ends that process with SIGBUS, which Python
cannot catch (its handler runs after the faulting instruction, which is retried for ever).
So neither the writer nor the Python reader uses a mapping of the segment: the writer fills a
private copy (anonymous memory, which no other process can shrink) and writes what each frame
changed into the file with `pwrite`; a reader copies what it needs with `pread`. Neither can
fault: a pwrite past the end extends the file, a pread past it reads short (a torn frame,
retried). Before each frame the writer checks the file's size, that every page is present
(a truncation that its own writes extended again leaves holes that read as zeros) and its
header; if anything differs it gives the file its size again and writes the private copy
whole (both slots, so kept layers hold again), counts it (`segment_status`, the daemon's
`status.segment`) and logs a line (at most one a minute). A truncation in the middle of a
frame shows as a torn or zeroed frame until the next one. The private copy doubles the
memory the segment takes (its pages are touched only where frames use them), and a pwrite
is slower than a store into a mapping: `wxsky bench` at 1280x720 publishes in 0.56 ms where
it took 0.34 (docs/performance.md). A host that maps the segment (the C host kit does)
still faults if it reads a page while the file is short, for up to one frame: the writer's
checks keep the segment whole, not another process's mapping. The seqlock is unchanged:
each field is written by its own pwrite, in the order above; a pwrite of an 8-byte counter
may land byte by byte, which a reader tolerates (`seq` only goes up, odd to even is a
carry a reader sees as a changed or odd value, and it re-reads `seq` after its copy).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import importlib
import logging
import mmap
import os
import re
import struct
import sys
import time
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from types import TracebackType

import numpy as np
import numpy.typing as npt

from wxsky.errors import RuntimeFailure, WxskyError
from wxsky.logs import RateLimitedLog
from wxsky.output import memory

if sys.byteorder != "little":  # pragma: no cover - every supported host is little-endian
    raise ImportError("wxsky.output.shm needs a little-endian CPU (the segment layout is LE)")

# The stdlib module behind multiprocessing.shared_memory, used directly because SharedMemory
# registers every attach with the resource tracker, which unlinks the segment when a *reader*
# process exits (Python < 3.13). It has no typeshed stub, hence the dynamic import.
_posixshmem = importlib.import_module("_posixshmem")

logger = logging.getLogger(__name__)

MAGIC = b"WXSKYSHM"
# The newest layout this module writes and reads; version 1 (RGBA8 layers only, no format
# field) is still written for such a segment and read.
VERSION = 2
VERSION_RGBA8 = 1
VERSIONS = (VERSION_RGBA8, VERSION)
SLOT_COUNT = 2
BYTES_PER_PIXEL = 4  # an RGBA8 layer's

# Layer formats: name -> (descriptor code, bytes per pixel). RGBA16F: 4 half floats.
RGBA8 = "rgba8"
RGBA16F = "rgba16f"
LAYER_FORMATS: dict[str, tuple[int, int]] = {RGBA8: (0, 4), RGBA16F: (1, 8)}
_FORMAT_NAMES = {code: name for name, (code, _) in LAYER_FORMATS.items()}

STATE_INITIALISING = 0
STATE_LIVE = 1
STATE_CLOSED = 2

# Header, offsets from the segment start.
HDR_MAGIC = 0  # char[8]
HDR_VERSION = 8  # u32
HDR_HEADER_SIZE = 12  # u32
HDR_SLOT_COUNT = 16  # u32
HDR_LAYER_COUNT = 20  # u32
HDR_SLOT_SIZE = 24  # u64
HDR_META_CAPACITY = 32  # u32
HDR_WRITER_PID = 36  # u32
HDR_ACTIVE_SLOT = 40  # u32
HDR_STATE = 44  # u32
HDR_LATEST_FRAME = 48  # u64
HDR_PUBLISH_COUNT = 56  # u64
HDR_LAYERS = 64  # first layer descriptor
HDR_FIXED_SIZE = 64

# Layer descriptor, offsets from its start.
LAYER_DESC_SIZE = 32  # version 1
LAYER_DESC_SIZE_V2 = 40  # version 2: the format and a reserved u32 follow
LD_NAME = 0  # char[16]
LAYER_NAME_SIZE = 16
LD_MAX_WIDTH = 16  # u32
LD_MAX_HEIGHT = 20  # u32
LD_CAPACITY = 24  # u64
LD_FORMAT = 32  # u32, version 2
LD_RESERVED = 36  # u32, version 2: 0

# Slot header, offsets from the slot start.
SLOT_SEQ = 0  # u64
SLOT_FRAME = 8  # u64
SLOT_META_LENGTH = 16  # u32
SLOT_META_OFFSET = 20  # u32
SLOT_LAYERS = 24  # first layer table entry

# Layer table entry, offsets from its start.
LAYER_ENTRY_SIZE = 16
LE_WIDTH = 0  # u32
LE_HEIGHT = 4  # u32
LE_OFFSET = 8  # u64, from the segment start

# One entry, packed: LE_WIDTH, LE_HEIGHT, LE_OFFSET.
_ENTRY_FORMAT = "IIQ"
assert struct.calcsize("<" + _ENTRY_FORMAT) == LAYER_ENTRY_SIZE and (LE_HEIGHT, LE_OFFSET) == (4, 8)

REGION_ALIGN = 64  # cache line: pixel and metadata regions
SLOT_ALIGN = 4096  # page: header and slot sizes, so every slot starts on a page boundary

MAX_LAYERS = 64
U32_MAX = 0xFFFF_FFFF
U64_MAX = 0xFFFF_FFFF_FFFF_FFFF

_NAME_RE = re.compile(r"[A-Za-z0-9._-]{1,200}")
_LAYER_NAME_RE = re.compile(r"[\x21-\x7e]{1,16}")


# What to do when a segment name is taken: how a daemon is given another.
OTHER_NAME_HINT = (
    "give this daemon another segment name with `wxsky run --shm-name NAME` or [output] shm_name"
)
# When a segment cannot be made at all: /dev/shm is missing, full or not writable.
_CREATE_HINT = "check that /dev/shm is mounted and writable by this user"


def _align(value: int, alignment: int) -> int:
    return (value + alignment - 1) // alignment * alignment


def _check_name(name: str) -> str:
    bare = name[1:] if name.startswith("/") else name
    if not _NAME_RE.fullmatch(bare):
        raise WxskyError(
            f"invalid shared-memory segment name {name!r}: use 1-200 characters from "
            "A-Z a-z 0-9 . _ -"
        )
    return bare


def _shm_open(name: str, flags: int, mode: int = 0o600) -> int:
    return int(_posixshmem.shm_open("/" + name, flags, mode))


def _shm_unlink(name: str) -> None:
    _posixshmem.shm_unlink("/" + name)


def _names_file(name: str, fd: int) -> bool:
    """Whether segment `name` is still the very file open as `fd` (same device and inode):
    the name may have been removed and made again by another writer since."""
    try:
        other = _shm_open(name, os.O_RDONLY)
    except OSError:
        return False
    try:
        mine, theirs = os.fstat(fd), os.fstat(other)
    finally:
        os.close(other)
    return (mine.st_dev, mine.st_ino) == (theirs.st_dev, theirs.st_ino)


def _other_writer(name: str) -> int | None:
    """For a name no longer this writer's: None if nothing has it, else the pid in its header
    (0 when unreadable)."""
    try:
        fd = _shm_open(name, os.O_RDONLY)
    except OSError:
        return None
    try:
        return _writer_pid(fd) or 0
    finally:
        os.close(fd)


def _unlink_own(name: str, fd: int) -> bool:
    """Unlink segment `name` only if it is the file open as `fd`, so that a writer never
    removes a segment another process made under the same name; True if it did."""
    if not _names_file(name, fd):
        return False
    with contextlib.suppress(FileNotFoundError):
        _shm_unlink(name)
    return True


@dataclass(frozen=True)
class LayerSpec:
    """A layer's fixed capacity and pixel format; a frame may use any width/height up to it."""

    name: str
    max_width: int
    max_height: int
    format: str = RGBA8  # a key of LAYER_FORMATS

    @property
    def bytes_per_pixel(self) -> int:
        return LAYER_FORMATS[self.format][1]

    @property
    def capacity(self) -> int:
        return self.max_width * self.max_height * self.bytes_per_pixel


# A layer's pixels as a reader copies them: (height, width, 4) uint8 for RGBA8, float16 for
# RGBA16F (the half floats as they are in the segment).
LayerPixels = npt.NDArray[np.uint8] | npt.NDArray[np.float16]


@dataclass(frozen=True, eq=False)
class Frame:
    """One published frame, copied out of the segment: arrays (height, width, 4), uint8 for
    RGBA8 layers and float16 for RGBA16F ones."""

    frame_number: int
    layers: dict[str, LayerPixels]
    meta: bytes


def segment_version(layers: Sequence[LayerSpec]) -> int:
    """The layout version a segment of these layers is written in: 1 while every layer is
    RGBA8 (the layout of before, which older readers read), 2 otherwise."""
    return VERSION_RGBA8 if all(spec.format == RGBA8 for spec in layers) else VERSION


def _desc_size(version: int) -> int:
    return LAYER_DESC_SIZE if version == VERSION_RGBA8 else LAYER_DESC_SIZE_V2


@dataclass(frozen=True)
class _Layout:
    layers: tuple[LayerSpec, ...]
    meta_capacity: int
    header_size: int
    slot_size: int
    meta_offset: int  # from the slot start
    pixel_offsets: tuple[int, ...]  # from the slot start
    version: int = VERSION_RGBA8

    @property
    def total_size(self) -> int:
        return self.header_size + SLOT_COUNT * self.slot_size

    @property
    def desc_size(self) -> int:
        return _desc_size(self.version)

    def slot_base(self, slot: int) -> int:
        return self.header_size + slot * self.slot_size

    @classmethod
    def compute(cls, layers: tuple[LayerSpec, ...], meta_capacity: int) -> _Layout:
        version = segment_version(layers)
        header_size = _align(HDR_LAYERS + _desc_size(version) * len(layers), SLOT_ALIGN)
        meta_offset = _align(SLOT_LAYERS + LAYER_ENTRY_SIZE * len(layers), REGION_ALIGN)
        end = meta_offset + meta_capacity
        offsets = []
        for spec in layers:
            start = _align(end, REGION_ALIGN)
            offsets.append(start)
            end = start + spec.capacity
        return cls(
            layers=layers,
            meta_capacity=meta_capacity,
            header_size=header_size,
            slot_size=_align(end, SLOT_ALIGN),
            meta_offset=meta_offset,
            pixel_offsets=tuple(offsets),
            version=version,
        )


def _check_specs(layers: Sequence[LayerSpec]) -> tuple[LayerSpec, ...]:
    specs = tuple(layers)
    if not 1 <= len(specs) <= MAX_LAYERS:
        raise ValueError(f"a frame segment needs 1 to {MAX_LAYERS} layers, got {len(specs)}")
    seen: set[str] = set()
    for spec in specs:
        if not _LAYER_NAME_RE.fullmatch(spec.name):
            raise ValueError(
                f"invalid layer name {spec.name!r}: 1-16 printable ASCII characters, no spaces"
            )
        if spec.name in seen:
            raise ValueError(f"duplicate layer name {spec.name!r}")
        seen.add(spec.name)
        if spec.format not in LAYER_FORMATS:
            raise ValueError(
                f"layer {spec.name!r}: format {spec.format!r} is not one of "
                f"{', '.join(LAYER_FORMATS)}"
            )
        if not (1 <= spec.max_width <= 65535 and 1 <= spec.max_height <= 65535):
            raise ValueError(
                f"layer {spec.name!r}: max size {spec.max_width}x{spec.max_height} is outside "
                "1..65535"
            )
    return specs


def _writer_pid(fd: int) -> int | None:
    """The pid recorded in an existing segment, for error messages; None if unreadable."""
    try:
        if os.fstat(fd).st_size < HDR_FIXED_SIZE:
            return None
        with mmap.mmap(fd, HDR_FIXED_SIZE, access=mmap.ACCESS_READ) as mm:
            magic = mm[HDR_MAGIC : HDR_MAGIC + len(MAGIC)]
            (pid,) = struct.unpack_from("<I", mm, HDR_WRITER_PID)
    except (OSError, ValueError):
        return None
    return int(pid) if magic == MAGIC else None


def _looks_like_ours(fd: int) -> bool:
    """True for a wxsky segment, or for one whose creator died before writing the magic."""
    size = os.fstat(fd).st_size
    if size < len(MAGIC):
        return True
    with mmap.mmap(fd, len(MAGIC), access=mmap.ACCESS_READ) as mm:
        magic = bytes(mm)
    return magic in (MAGIC, bytes(len(MAGIC)))


def _replace_stale(name: str) -> None:
    try:
        fd = _shm_open(name, os.O_RDWR)
    except FileNotFoundError:
        return  # removed between our create attempt and now
    except OSError as exc:
        raise RuntimeFailure(
            f"shared-memory segment {name!r} already exists and cannot be opened: "
            f"{exc.strerror}; {OTHER_NAME_HINT}"
        ) from exc
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN):
                raise RuntimeFailure(
                    f"cannot lock shared-memory segment {name!r}: {exc}; {OTHER_NAME_HINT}"
                ) from exc
            pid = _writer_pid(fd)
            owner = f" (pid {pid})" if pid else ""
            raise RuntimeFailure(
                f"shared-memory segment {name!r} is in use by another wxsky writer{owner}: "
                f"stop it, or {OTHER_NAME_HINT}"
            ) from None
        if not _looks_like_ours(fd):
            raise RuntimeFailure(
                f"shared-memory segment {name!r} exists and is not a wxsky frame segment; "
                f"refusing to replace it: remove /dev/shm/{name} by hand if it is stale, or "
                f"{OTHER_NAME_HINT}"
            )
        logger.warning(
            "replacing stale shared-memory segment %r (writer pid %s exited without closing it)",
            name,
            _writer_pid(fd),
        )
        # Only the stale file we locked: another writer may have replaced it meanwhile.
        _unlink_own(name, fd)
    finally:
        os.close(fd)  # also drops the lock we may hold on the old segment


def _create_segment(name: str, size: int) -> int:
    flags = os.O_CREAT | os.O_EXCL | os.O_RDWR
    try:
        fd = _shm_open(name, flags)
    except FileExistsError:
        _replace_stale(name)
        try:
            fd = _shm_open(name, flags)
        except FileExistsError:
            raise RuntimeFailure(
                f"shared-memory segment {name!r} was created by another writer while this one "
                f"was starting: stop it, or {OTHER_NAME_HINT}"
            ) from None
        except OSError as exc:
            raise RuntimeFailure(
                f"cannot create shared-memory segment {name!r}: {exc}; {_CREATE_HINT}"
            ) from exc
    except OSError as exc:
        raise RuntimeFailure(
            f"cannot create shared-memory segment {name!r}: {exc}; {_CREATE_HINT}"
        ) from exc
    try:
        # Taken before the segment has a magic, so a concurrent create sees it as in use.
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        if not _names_file(name, fd):
            # Another writer took the empty file for a dead one's before we locked it, and
            # replaced it: the name is theirs now.
            os.close(fd)
            raise RuntimeFailure(
                f"shared-memory segment {name!r} was replaced by another writer while this one "
                f"was starting: stop it, or {OTHER_NAME_HINT}"
            )
        os.ftruncate(fd, size)
        if hasattr(os, "posix_fallocate"):
            # Reserve the pages now: on a full tmpfs (Docker's /dev/shm is 64 MiB) a late page
            # fault would kill the daemon with SIGBUS instead of raising here.
            os.posix_fallocate(fd, 0, size)
    except OSError as exc:
        _unlink_own(name, fd)
        os.close(fd)
        raise RuntimeFailure(
            f"cannot allocate {size} bytes of shared memory for segment {name!r}: "
            f"{exc.strerror}; make /dev/shm larger (Docker: --shm-size) or the frames smaller "
            "([output] max_width and max_height)"
        ) from exc
    return fd


class FrameWriter:
    """The daemon's side of a segment. Build with `FrameWriter.create`; not thread-safe.

    The writer never loads or stores through a mapping of the segment: it fills a private
    copy (anonymous memory no other process can shrink) and writes what changed into the
    segment's file with `pwrite`, which extends a truncated file instead of faulting. See
    "Truncation" in the module docstring."""

    def __init__(self, name: str, fd: int, layout: _Layout) -> None:
        self._name = name
        self._fd = fd
        # The writer's copy of the whole segment: what the file must hold. Anonymous, so
        # another process cannot truncate it, and only the pages a frame uses are touched.
        self._mm = mmap.mmap(-1, layout.total_size)
        self._layout = layout
        self._view = memoryview(self._mm)
        self._u32 = self._view.cast("I")
        self._u64 = self._view.cast("Q")
        self._index = {spec.name: i for i, spec in enumerate(layout.layers)}
        self._bpp = tuple(spec.bytes_per_pixel for spec in layout.layers)
        self._target = 1  # slot being filled; slot 0 is "active" but empty until publish 1
        self._writing = False
        # Width and height of each layer published in the slot being filled, flat (0: absent),
        # and each slot's layer table as written by `publish`: one pack a frame, not two
        # writes per layer.
        n_layers = len(layout.layers)
        self._dims = [0] * (2 * n_layers)
        self._table = struct.Struct("<" + _ENTRY_FORMAT * n_layers)
        self._entries = [
            [v for offset in layout.pixel_offsets for v in (0, 0, layout.slot_base(slot) + offset)]
            for slot in range(SLOT_COUNT)
        ]
        # What each slot's layers hold, where the caller named it (`layer_buffer`'s content):
        # layer index -> (content, width, height), set when the slot is published and dropped
        # as soon as a buffer of that layer in that slot is handed out again. Only this writer
        # writes the segment (readers open it read-only), so a slot's pixels stay as published;
        # a segment changed under it is written again whole from the private copy.
        self._held: tuple[dict[int, tuple[Hashable, int, int]], ...] = tuple(
            {} for _ in range(SLOT_COUNT)
        )
        self._filling: dict[int, tuple[Hashable, int, int]] = {}  # named in the slot being filled
        self._handed_out: list[memoryview] = []
        # Byte ranges (offset, length) of the private copy written this frame, to go to the file.
        self._dirty: list[tuple[int, int]] = []
        self._last_frame = -1
        self._closed = False
        # Truncation and write failures: counted for status, logged at most once a minute.
        self.restores = 0
        self.write_errors = 0
        self.last_problem: str | None = None
        self._damaged = False  # a write to the file failed: write it whole at the next frame
        self._log = RateLimitedLog(logger)

    def segment_status(self) -> dict[str, object]:
        """For the daemon's status: how often the segment was found changed under the writer
        (truncated, extended, header overwritten) and written again, and failed writes."""
        return {
            "size_bytes": self._layout.total_size,
            "restores": self.restores,
            "write_errors": self.write_errors,
            "last_problem": self.last_problem,
        }

    @classmethod
    def create(
        cls, name: str, layers: Sequence[LayerSpec], meta_capacity: int = 4096
    ) -> FrameWriter:
        """Create segment `name` (as in shm_open, without the leading slash).

        Raises WxskyError if a live writer holds the name; a segment left by a dead writer is
        replaced (see the module docstring).
        """
        bare = _check_name(name)
        specs = _check_specs(layers)
        if not 0 <= meta_capacity <= U32_MAX:
            raise ValueError(f"meta_capacity {meta_capacity} is outside 0..{U32_MAX}")
        layout = _Layout.compute(specs, meta_capacity)
        # Before anything is made: /dev/shm and memory must hold it (the mapping is memory).
        memory.require(
            layout.total_size,
            f"shared-memory segment {bare!r} ({len(specs)} layers up to "
            f"{max(s.max_width for s in specs)}x{max(s.max_height for s in specs)}, "
            f"{SLOT_COUNT} slots)",
            [*memory.shm_headroom(), *memory.memory_headroom(private=False)],
        )
        fd = _create_segment(bare, layout.total_size)
        try:
            writer = cls(bare, fd, layout)
            writer._init_header()
        except OSError as exc:
            _unlink_own(bare, fd)
            os.close(fd)
            raise RuntimeFailure(
                f"cannot write shared-memory segment {bare!r}: {exc.strerror}; {_CREATE_HINT}"
            ) from exc
        return writer

    @property
    def name(self) -> str:
        return self._name

    @property
    def layers(self) -> tuple[LayerSpec, ...]:
        return self._layout.layers

    @property
    def segment_size(self) -> int:
        return self._layout.total_size

    @property
    def version(self) -> int:
        """The layout version the segment's header carries (1: RGBA8 layers only)."""
        return self._layout.version

    @property
    def target_slot(self) -> int:
        """The slot the next `publish` fills (0 or 1): where the zero-copy textures of the
        same frame go (docs/protocol.md §6)."""
        return self._target

    def _put32(self, offset: int, value: int) -> None:
        """Store a header field in the private copy and write it to the file."""
        self._u32[offset // 4] = value
        self._push(offset, 4)

    def _put64(self, offset: int, value: int) -> None:
        self._u64[offset // 8] = value
        self._push(offset, 8)

    def _push(self, offset: int, length: int) -> None:
        """Write bytes [offset, offset + length) of the private copy to the segment's file.
        pwrite cannot fault: on a file shrunk under the writer it extends it again (the rest
        reads as zeros until `_check_segment` writes it whole). A failure (no room left in
        /dev/shm after pages were freed and taken) is counted and logged, and the next frame
        writes the segment whole again; the daemon goes on."""
        end = offset + length
        try:
            while offset < end:
                offset += os.pwrite(self._fd, self._view[offset:end], offset)
        except OSError as exc:
            self._failed("write", f"writing it failed: {exc.strerror}")

    def _failed(self, kind: str, problem: str) -> None:
        """A write or resize of the segment failed: counted, logged (rate-limited per kind),
        and the whole segment written again at the next frame's check."""
        self.write_errors += 1
        self._damaged = True
        self.last_problem = problem
        self._log.log(
            logging.ERROR,
            kind,
            f"frame segment {self._name!r}: {problem} ({self.write_errors} failed writes so "
            "far); trying again next frame",
        )

    def _check_segment(self) -> None:
        """Before each frame: the segment's file must still be what this writer wrote: its
        size, every page present (a truncation that later writes extended again leaves holes,
        which read as zeros) and its header. If not (another process of this user truncated
        or overwrote it, or a write failed), write it whole from the private copy, count it
        and log it (at most once a minute)."""
        total, header_size = self._layout.total_size, self._layout.header_size
        problem: str | None = None
        try:
            info = os.fstat(self._fd)
            header = os.pread(self._fd, header_size, 0)
        except OSError as exc:  # pragma: no cover - fstat/pread of an open fd do not fail
            problem = f"it cannot be read: {exc.strerror}"
        else:
            if info.st_size != total:
                problem = f"it was resized to {info.st_size} bytes (of {total})"
            elif info.st_blocks * 512 < total:
                problem = "pages of it were dropped (truncated and extended again)"
            elif header != self._view[:header_size]:
                problem = "its header was overwritten"
        if problem is None and not self._damaged:
            return
        if problem is not None:
            self.restores += 1
            self.last_problem = problem
            self._log.warning(
                "changed",
                f"frame segment {self._name!r} was changed under the writer: {problem}; "
                f"wrote it again whole ({self.restores} times so far)",
            )
        self._damaged = False
        try:
            os.ftruncate(self._fd, total)  # also drops what an extension added past the end
            if hasattr(os, "posix_fallocate"):
                os.posix_fallocate(self._fd, 0, total)  # as at creation: no late ENOSPC
        except OSError as exc:
            self._failed("resize", f"it could not be given its size again: {exc.strerror}")
            return
        # Both slots as last published (and the one being filled as it was), so what a slot
        # is known to hold (`keep_layer`) holds in the file again too. Each published slot's
        # seq is odd while it is written again and moves on after: a reader that copied the
        # slot while the file was short or holed (zeros under an unchanged seq) sees the seq
        # change and retries, instead of taking a torn frame.
        seqs = [self._layout.slot_base(slot) + SLOT_SEQ for slot in range(SLOT_COUNT)]
        mended = [off for off in seqs if self._u64[off // 8] and not self._u64[off // 8] & 1]
        for off in mended:
            self._u64[off // 8] += 1
        self._push(0, total)
        for off in mended:
            self._put64(off, self._u64[off // 8] + 1)

    def _init_header(self) -> None:
        lay = self._layout
        self._put32(HDR_VERSION, lay.version)
        self._put32(HDR_HEADER_SIZE, lay.header_size)
        self._put32(HDR_SLOT_COUNT, SLOT_COUNT)
        self._put32(HDR_LAYER_COUNT, len(lay.layers))
        self._put64(HDR_SLOT_SIZE, lay.slot_size)
        self._put32(HDR_META_CAPACITY, lay.meta_capacity)
        self._put32(HDR_WRITER_PID, os.getpid() & U32_MAX)
        self._put32(HDR_ACTIVE_SLOT, 1 - self._target)
        for i, spec in enumerate(lay.layers):
            desc = HDR_LAYERS + i * lay.desc_size
            self._view[desc + LD_NAME : desc + LD_NAME + LAYER_NAME_SIZE] = spec.name.encode(
                "ascii"
            ).ljust(LAYER_NAME_SIZE, b"\0")
            self._push(desc + LD_NAME, LAYER_NAME_SIZE)
            self._put32(desc + LD_MAX_WIDTH, spec.max_width)
            self._put32(desc + LD_MAX_HEIGHT, spec.max_height)
            self._put64(desc + LD_CAPACITY, spec.capacity)
            if lay.version != VERSION_RGBA8:
                self._put32(desc + LD_FORMAT, LAYER_FORMATS[spec.format][0])
                self._put32(desc + LD_RESERVED, 0)
        for slot in range(SLOT_COUNT):
            base = lay.slot_base(slot)
            self._put32(base + SLOT_META_OFFSET, lay.meta_offset)
            for i, offset in enumerate(lay.pixel_offsets):
                self._put64(base + SLOT_LAYERS + i * LAYER_ENTRY_SIZE + LE_OFFSET, base + offset)
        self._put32(HDR_STATE, STATE_LIVE)
        # Last, so a reader that sees the magic sees a complete header.
        self._view[HDR_MAGIC : HDR_MAGIC + len(MAGIC)] = MAGIC
        self._push(HDR_MAGIC, len(MAGIC))

    def _check_open(self) -> None:
        if self._closed:
            raise WxskyError(f"frame writer for segment {self._name!r} is closed")

    def _begin(self) -> None:
        if not self._writing:
            self._check_segment()
            seq = self._layout.slot_base(self._target) + SLOT_SEQ
            self._put64(seq, self._u64[seq // 8] + 1)  # odd: readers of this slot retry
            self._writing = True

    def layer_buffer(
        self,
        layer: str,
        width: int,
        height: int,
        content: Hashable | None = None,
        rows: Sequence[tuple[int, int]] | None = None,
    ) -> memoryview:
        """The writable pixels of `layer` in the slot being filled: width*height*B contiguous
        bytes (the layer's format, B bytes a pixel: RGBA8 4, RGBA16F 8; premultiplied, rows
        top to bottom). Valid until the next `publish`; a layer
        not asked for before `publish` is published as absent (0x0). `content`: a name for
        what the caller writes there, by which a later frame filling this slot again may keep
        the pixels instead of writing them (`keep_layer`). `rows`: the (first, stop) row ranges
        the caller writes, the rest holding what the slot held (`held_layer`); None: all."""
        index = self._layer_index(layer, width, height)
        self._begin()
        self._dims[2 * index : 2 * index + 2] = (width, height)
        self._held[self._target].pop(index, None)
        if content is None:
            self._filling.pop(index, None)
        else:
            self._filling[index] = (content, width, height)
        start = self._layout.slot_base(self._target) + self._layout.pixel_offsets[index]
        row_bytes = width * self._bpp[index]
        if rows is None:
            self._dirty.append((start, height * row_bytes))
        else:
            for first, stop in rows:
                if not 0 <= first <= stop <= height:
                    raise ValueError(f"layer {layer!r}: rows {first}..{stop} outside 0..{height}")
                self._dirty.append((start + first * row_bytes, (stop - first) * row_bytes))
        view = self._view[start : start + height * row_bytes]
        self._handed_out.append(view)
        return view

    def keep_layer(self, layer: str, width: int, height: int, content: Hashable) -> bool:
        """Publish `layer` in the slot being filled with the pixels it already holds, if they
        are `content` at width x height: written under that name (`layer_buffer`) in an
        earlier frame published in this slot, and not handed out for writing since. False,
        and nothing done, otherwise: the caller writes the layer. Slots alternate, so a layer
        that stays the same (the ring's images between rebuilds) is written twice, once into
        each slot, and then kept."""
        index = self._layer_index(layer, width, height)
        if self._held[self._target].get(index) != (content, width, height):
            return False
        self._begin()
        self._dims[2 * index : 2 * index + 2] = (width, height)
        return True

    def held_layer(self, layer: str, width: int, height: int) -> Hashable | None:
        """The content (`layer_buffer`'s name for it) the slot being filled holds in `layer`
        at width x height, written in an earlier frame published in this slot and not handed
        out for writing since; None when unknown. A caller that writes only what changed
        since then (`publish_plan`, the sky's strips) starts from it."""
        index = self._layer_index(layer, width, height)
        held = self._held[self._target].get(index)
        if held is None or held[1:] != (width, height):
            return None
        return held[0]

    def _layer_index(self, layer: str, width: int, height: int) -> int:
        self._check_open()
        index = self._index.get(layer)
        if index is None:
            raise ValueError(f"unknown layer {layer!r}; segment layers: {sorted(self._index)}")
        spec = self._layout.layers[index]
        if not (0 <= width <= spec.max_width and 0 <= height <= spec.max_height):
            raise ValueError(
                f"layer {layer!r}: {width}x{height} exceeds its capacity "
                f"{spec.max_width}x{spec.max_height}"
            )
        return index

    def publish(self, frame_number: int, meta: bytes = b"") -> None:
        """Complete the frame being filled and make it the one readers get."""
        self._check_open()
        if not self._last_frame < frame_number <= U64_MAX:
            raise ValueError(
                f"frame number {frame_number} must be greater than the previous one "
                f"({self._last_frame}) and fit in 64 bits"
            )
        if len(meta) > self._layout.meta_capacity:
            raise ValueError(
                f"frame metadata is {len(meta)} bytes; the segment holds at most "
                f"{self._layout.meta_capacity}"
            )
        self._begin()
        base = self._layout.slot_base(self._target)
        entries = self._entries[self._target]
        entries[0::3] = self._dims[0::2]  # LE_WIDTH
        entries[1::3] = self._dims[1::2]  # LE_HEIGHT (LE_OFFSET: as _init_header wrote it)
        self._table.pack_into(self._view, base + SLOT_LAYERS, *entries)
        self._u64[(base + SLOT_FRAME) // 8] = frame_number
        meta_start = base + self._layout.meta_offset
        self._view[meta_start : meta_start + len(meta)] = meta
        self._u32[(base + SLOT_META_LENGTH) // 4] = len(meta)
        # Into the file, all before the seq turns even: the pixels written this frame, the
        # slot's frame number, metadata length and layer table, and the metadata.
        for offset, length in self._dirty:
            self._push(offset, length)
        self._dirty.clear()
        self._push(base + SLOT_FRAME, SLOT_LAYERS - SLOT_FRAME + self._table.size)
        self._push(meta_start, len(meta))
        self._put64(base + SLOT_SEQ, self._u64[(base + SLOT_SEQ) // 8] + 1)  # even: complete
        self._put32(HDR_ACTIVE_SLOT, self._target)
        self._put64(HDR_LATEST_FRAME, frame_number)
        self._put64(HDR_PUBLISH_COUNT, self._u64[HDR_PUBLISH_COUNT // 8] + 1)
        self._release_handed_out()
        self._held[self._target].update(self._filling)
        self._filling.clear()
        self._target ^= 1
        self._writing = False
        self._dims[:] = [0] * len(self._dims)
        self._last_frame = frame_number

    def _release_handed_out(self) -> None:
        # A released view raises on use, so a stale buffer cannot scribble on the active slot.
        for view in self._handed_out:
            # Still exported (e.g. a live np.frombuffer array): nothing to enforce then.
            with contextlib.suppress(BufferError):
                view.release()
        self._handed_out.clear()

    def close(self) -> None:
        """Mark the segment closed for attached readers and unlink it, if the name still
        refers to this writer's segment (another process may have made a new one under it).
        Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._put32(HDR_STATE, STATE_CLOSED)
            if not _unlink_own(self._name, self._fd):
                other = _other_writer(self._name)
                if other is not None:
                    logger.warning(
                        "frame segment %r: the name now belongs to another segment%s; left it",
                        self._name,
                        f" (writer pid {other})" if other else "",
                    )
        finally:
            self._release_handed_out()
            for view in (self._u32, self._u64, self._view):
                view.release()
            try:
                self._mm.close()
            except BufferError:
                logger.warning(
                    "frame segment %r: a layer buffer is still referenced; its mapping is "
                    "released when that reference goes away",
                    self._name,
                )
            os.close(self._fd)

    def __enter__(self) -> FrameWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _pread_exact(fd: int, length: int, offset: int) -> bytes | None:
    """`length` bytes of the file at `offset`, or None where the file is shorter (truncated)."""
    data = os.pread(fd, length, offset)
    return data if len(data) == length else None


def _parse_header(name: str, fd: int, size: int) -> _Layout:
    fixed = _pread_exact(fd, HDR_FIXED_SIZE, 0)
    if fixed is None:
        raise RuntimeFailure(f"shared-memory segment {name!r} was truncated while opening it")
    magic = fixed[HDR_MAGIC : HDR_MAGIC + len(MAGIC)]
    if magic != MAGIC:
        raise RuntimeFailure(
            f"shared-memory segment {name!r} is not a wxsky frame segment "
            f"(magic {magic!r}; a writer still starting up has none yet)"
        )
    version, header_size, slot_count, layer_count, slot_size, meta_capacity = struct.unpack_from(
        "<IIIIQI", fixed, HDR_VERSION
    )
    if version not in VERSIONS:
        raise RuntimeFailure(
            f"shared-memory segment {name!r} uses frame protocol version {version}; "
            f"this wxsky understands versions {' and '.join(map(str, VERSIONS))}: run a "
            "daemon and a host of the same wxsky version"
        )
    desc_size = _desc_size(version)

    def bad(why: str) -> WxskyError:
        return WxskyError(f"shared-memory segment {name!r} has a corrupt header: {why}")

    if slot_count != SLOT_COUNT:
        raise bad(f"slot_count {slot_count}, expected {SLOT_COUNT}")
    if not 1 <= layer_count <= MAX_LAYERS:
        raise bad(f"layer_count {layer_count}")
    if header_size < HDR_LAYERS + layer_count * desc_size or header_size % 8:
        raise bad(f"header_size {header_size}")
    if slot_size % 8 or header_size + SLOT_COUNT * slot_size > size:
        raise bad(f"slot_size {slot_size} does not fit the {size}-byte segment")
    # The descriptors and slot 0's header (for its meta_offset): within `size`, checked above.
    head = _pread_exact(fd, header_size + SLOT_LAYERS, 0)
    if head is None:
        raise RuntimeFailure(f"shared-memory segment {name!r} was truncated while opening it")
    specs = []
    for i in range(layer_count):
        desc = HDR_LAYERS + i * desc_size
        raw = head[desc + LD_NAME : desc + LD_NAME + LAYER_NAME_SIZE].rstrip(b"\0")
        max_width, max_height, capacity = struct.unpack_from("<IIQ", head, desc + LD_MAX_WIDTH)
        layer_name = raw.decode("ascii", "replace")
        layer_format = RGBA8
        if version != VERSION_RGBA8:
            (code,) = struct.unpack_from("<I", head, desc + LD_FORMAT)
            if code not in _FORMAT_NAMES:
                known = ", ".join(f"{c} {n.upper()}" for c, n in sorted(_FORMAT_NAMES.items()))
                raise bad(f"layer {layer_name!r} format {code} (this wxsky knows {known})")
            layer_format = _FORMAT_NAMES[code]
        spec = LayerSpec(layer_name, max_width, max_height, layer_format)
        if capacity != spec.capacity or capacity > slot_size:
            raise bad(f"layer {spec.name!r} capacity {capacity}")
        specs.append(spec)
    (meta_offset,) = struct.unpack_from("<I", head, header_size + SLOT_META_OFFSET)
    if meta_offset + meta_capacity > slot_size:
        raise bad(f"metadata region {meta_offset}+{meta_capacity} exceeds the slot")
    return _Layout(
        layers=tuple(specs),
        meta_capacity=meta_capacity,
        header_size=header_size,
        slot_size=slot_size,
        meta_offset=meta_offset,
        pixel_offsets=(),  # read per frame from the slot's layer table
        version=version,
    )


_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")


class FrameReader:
    """A host's side of a segment. Build with `FrameReader.open`; not thread-safe.

    It reads the segment with `pread`, never through a mapping: a segment truncated under it
    (by another process of the user) reads short, which is a torn frame to retry, where a
    mapped read would end the process with SIGBUS."""

    def __init__(self, name: str, fd: int, layout: _Layout, identity: tuple[int, int]) -> None:
        self._name = name
        self._fd = fd
        self._layout = layout
        self._identity = identity
        self._closed = False
        self._short = 0  # reads cut short by a truncated segment, since the last frame
        n = len(layout.layers)
        self._slot_head = struct.Struct("<QQII" + _ENTRY_FORMAT * n)
        assert self._slot_head.size == SLOT_LAYERS + LAYER_ENTRY_SIZE * n

    @classmethod
    def open(cls, name: str) -> FrameReader:
        """Attach read-only to segment `name`. The segment is never unlinked by a reader."""
        bare = _check_name(name)
        try:
            fd = _shm_open(bare, os.O_RDONLY)
        except FileNotFoundError:
            raise RuntimeFailure(
                f"no shared-memory frame segment named {bare!r}: start the daemon with `wxsky "
                "run`, or give the name its [output] shm_name sets (its status says it)"
            ) from None
        except OSError as exc:
            raise RuntimeFailure(f"cannot open shared-memory segment {bare!r}: {exc}") from exc
        try:
            info = os.fstat(fd)
            size = info.st_size
            if size < HDR_FIXED_SIZE or size % 8:
                raise RuntimeFailure(
                    f"shared-memory segment {bare!r} is not a wxsky frame segment ({size} bytes)"
                )
            layout = _parse_header(bare, fd, size)
        except BaseException:
            os.close(fd)
            raise
        return cls(bare, fd, layout, (info.st_dev, info.st_ino))

    @property
    def name(self) -> str:
        return self._name

    @property
    def layers(self) -> tuple[LayerSpec, ...]:
        return self._layout.layers

    @property
    def version(self) -> int:
        """The segment's layout version (1: RGBA8 layers only; 2: the descriptors carry each
        layer's format)."""
        return self._layout.version

    def _fixed(self) -> bytes | None:
        return _pread_exact(self._fd, HDR_FIXED_SIZE, 0)

    @property
    def frame_number(self) -> int:
        """Number of the latest published frame, or -1 if none has been published yet (or
        the segment is truncated just now).

        A cheap peek at the header. It is updated just after the slot flip, so it can lag the
        frame `read` returns by one: compare with `>` ("is there a newer frame than mine?").
        """
        self._check_open()
        fixed = self._fixed()
        if fixed is None or _U64.unpack_from(fixed, HDR_PUBLISH_COUNT)[0] == 0:
            return -1
        return int(_U64.unpack_from(fixed, HDR_LATEST_FRAME)[0])

    def is_current(self) -> bool:
        """False once the writer has closed this segment or the name now refers to another one
        (a restarted daemon): the cue for a host to close and reopen."""
        self._check_open()
        fixed = self._fixed()
        if fixed is not None and _U32.unpack_from(fixed, HDR_STATE)[0] == STATE_CLOSED:
            return False
        try:
            fd = _shm_open(self._name, os.O_RDONLY)
        except OSError:
            return False
        try:
            info = os.fstat(fd)
        finally:
            os.close(fd)
        return (info.st_dev, info.st_ino) == self._identity

    def _check_open(self) -> None:
        if self._closed:
            raise WxskyError(f"frame reader for segment {self._name!r} is closed")

    def read(self, timeout_s: float = 1.0) -> Frame:
        """Copy the latest complete frame, retrying while the writer races this reader.

        Raises WxskyError if no complete frame could be copied within `timeout_s` (also when
        none has been published yet, or the segment stays truncated) or when the writer has
        closed the segment.
        """
        self._check_open()
        deadline = time.monotonic() + timeout_s
        attempts = 0
        self._short = 0
        while True:
            frame = self._try_read()
            if frame is not None:
                return frame
            attempts += 1
            if time.monotonic() >= deadline:
                fixed = self._fixed()
                if self._short:
                    why = f"the segment was shorter than its header says ({self._short} reads)"
                elif fixed is None or _U64.unpack_from(fixed, HDR_PUBLISH_COUNT)[0] == 0:
                    why = "no frame has been published yet"
                else:
                    why = f"the writer overwrote it {attempts} times in a row"
                raise WxskyError(
                    f"no complete frame from segment {self._name!r} within {timeout_s} s: {why}"
                )
            if attempts > 2:  # the first retries are races with a flip: try again at once
                time.sleep(0.0005)

    def _try_read(self) -> Frame | None:
        fd, lay = self._fd, self._layout
        fixed = self._fixed()
        if fixed is None:
            self._short += 1
            return None
        if _U32.unpack_from(fixed, HDR_STATE)[0] == STATE_CLOSED:
            raise WxskyError(f"the writer has closed frame segment {self._name!r}")
        if _U64.unpack_from(fixed, HDR_PUBLISH_COUNT)[0] == 0:
            return None
        active = _U32.unpack_from(fixed, HDR_ACTIVE_SLOT)[0]
        if active >= SLOT_COUNT:
            raise WxskyError(f"segment {self._name!r}: active_slot {active} is out of range")
        base = lay.slot_base(active)
        head = _pread_exact(fd, self._slot_head.size, base)
        if head is None:
            self._short += 1
            return None
        seq, frame_number, meta_length, _meta_offset, *table = self._slot_head.unpack(head)
        if seq & 1 or seq == 0:
            return None
        problem = None
        if meta_length > lay.meta_capacity:
            problem = f"meta_length {meta_length}"
        regions = []
        for index, spec in enumerate(lay.layers):
            width, height, offset = table[3 * index : 3 * index + 3]
            length = width * height * spec.bytes_per_pixel
            if (
                width > spec.max_width
                or height > spec.max_height
                or offset < base
                or offset + length > base + lay.slot_size
            ):
                problem = f"layer {spec.name!r} entry {width}x{height}@{offset}"
                break
            regions.append((spec, width, height, offset, length))
        layers: dict[str, LayerPixels] = {}
        meta = b""
        if problem is None:
            got = _pread_exact(fd, meta_length, base + lay.meta_offset)
            if got is None:
                self._short += 1
                return None
            meta = got
            for spec, width, height, offset, length in regions:
                dtype = np.float16 if spec.format == RGBA16F else np.uint8
                pixels = np.empty((height, width, 4), dtype)
                if length and os.preadv(fd, [pixels.data], offset) != length:
                    self._short += 1
                    return None
                layers[spec.name] = pixels
        after = self._fixed()
        again = _pread_exact(fd, 8, base + SLOT_SEQ)
        if (
            after is None
            or again is None
            or _U64.unpack(again)[0] != seq
            or _U32.unpack_from(after, HDR_ACTIVE_SLOT)[0] != active
        ):
            return None  # torn: the writer got to this slot while we copied it
        if problem is not None:
            raise WxskyError(f"segment {self._name!r} slot {active} is corrupt: {problem}")
        return Frame(frame_number=int(frame_number), layers=layers, meta=meta)

    def close(self) -> None:
        """Detach. Idempotent; leaves the segment in place for the writer to unlink."""
        if self._closed:
            return
        self._closed = True
        os.close(self._fd)

    def __enter__(self) -> FrameReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
