"""Generated blocks kept for the next ring build, bounded by their bytes.

A ring rebuild reads the same few hundred blocks per layer as the last one (the camera and the
drift move a little between builds), so generating them once is the cache's whole point. What
it must not do is grow with the hours: the wind drifts new blocks in and each new layer
thickness is a new key, so a cache bounded by a count of blocks filled for half an hour of the
soak (to some 200 MB at 4096 blocks of cumulus). The bound here is in bytes and follows the
scene: at least `floor_bytes`, and room for 1.5 times the blocks the last build used, so a
scene larger than the floor does not evict the blocks its next build needs.

Thread use: the ring is built on its worker thread while the render thread gathers the near
blocks; one lock guards the table, never held while a block is generated.
"""

from __future__ import annotations

import dataclasses
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Generic, TypeVar

__all__ = ["BlockCache", "CacheInfo"]

V = TypeVar("V")

DEFAULT_FLOOR_BYTES = 64 << 20
# Headroom over the last build's blocks: a layer forming or the ring moving adds blocks.
WORKING_SET_FACTOR = 1.5


@dataclass(frozen=True)
class CacheInfo:
    hits: int
    misses: int
    evictions: int
    entries: int
    bytes: int
    limit_bytes: int

    def to_dict(self) -> dict[str, int]:
        return dataclasses.asdict(self)


class BlockCache(Generic[V]):
    """Least recently used first out, once the bytes pass the limit."""

    def __init__(self, size_of: Callable[[V], int], floor_bytes: int = DEFAULT_FLOOR_BYTES) -> None:
        self._size_of = size_of
        self.floor_bytes = floor_bytes
        self._limit = floor_bytes
        self._entries: OrderedDict[Hashable, tuple[V, int]] = OrderedDict()
        self._bytes = 0
        self._used: dict[Hashable, int] = {}  # keys read since the build began, their bytes
        self._hits = self._misses = self._evictions = 0
        self._lock = threading.Lock()

    def get(self, key: Hashable, make: Callable[[], V]) -> V:
        with self._lock:
            found = self._entries.get(key)
            if found is not None:
                self._entries.move_to_end(key)
                self._hits += 1
                self._used[key] = found[1]
                return found[0]
        value = make()  # unlocked: two threads may make one block; both get equal values
        size = self._size_of(value)
        with self._lock:
            self._misses += 1
            old = self._entries.pop(key, None)
            if old is not None:
                self._bytes -= old[1]
            self._entries[key] = (value, size)
            self._bytes += size
            self._used[key] = size
            self._evict()
        return value

    def start_build(self) -> None:
        """A ring build begins: the limit becomes room for the blocks used since the last
        one began (never under the floor), and the count of those starts again."""
        with self._lock:
            used = sum(self._used.values())
            self._limit = max(self.floor_bytes, int(WORKING_SET_FACTOR * used))
            self._used.clear()
            self._evict()

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
            self._used.clear()
            self._bytes = 0
            self._hits = self._misses = self._evictions = 0
            self._limit = self.floor_bytes

    def info(self) -> CacheInfo:
        with self._lock:
            return CacheInfo(
                self._hits,
                self._misses,
                self._evictions,
                len(self._entries),
                self._bytes,
                self._limit,
            )

    def _evict(self) -> None:
        # The newest entry always stays: a block larger than the limit is still returned.
        while self._bytes > self._limit and len(self._entries) > 1:
            _, (_, size) = self._entries.popitem(last=False)
            self._bytes -= size
            self._evictions += 1
