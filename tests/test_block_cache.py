"""The block cache: bounded by bytes, sized to what the last ring build used, shared safely by
the ring worker and the render thread, and never a cause of different clouds."""

from __future__ import annotations

import threading

from wxsky.scene.block_cache import BlockCache
from wxsky.scene.cloud_model_files import default_models
from wxsky.scene.clouds import BLOCK_CACHE, block_clouds, generate_block_clouds
from wxsky.weather.state import CloudType


def _cache(floor: int = 100) -> BlockCache[bytes]:
    return BlockCache(len, floor_bytes=floor)


def test_a_value_is_made_once_and_read_back() -> None:
    cache, made = _cache(), []
    for _ in range(3):
        value = cache.get("a", lambda: made.append(1) or b"x" * 10)
    assert value == b"x" * 10 and made == [1]
    info = cache.info()
    assert (info.hits, info.misses, info.entries, info.bytes) == (2, 1, 1, 10)


def test_bytes_past_the_floor_evict_the_least_recently_used() -> None:
    cache = _cache(floor=100)
    for key in "abc":
        cache.get(key, lambda: b"x" * 30)
    assert cache.get("a", lambda: b"never made") == b"x" * 30  # a is now the most recent
    cache.get("d", lambda: b"x" * 40)  # 130 bytes: b goes, then 100 is within the limit
    info = cache.info()
    assert (info.entries, info.bytes, info.evictions) == (3, 100, 1)
    assert cache.get("a", lambda: b"remade") == b"x" * 30
    assert cache.get("b", lambda: b"remade") == b"remade"


def test_a_value_larger_than_the_limit_is_still_kept_alone() -> None:
    cache = _cache(floor=10)
    cache.get("a", lambda: b"x" * 5)
    assert cache.get("big", lambda: b"x" * 50) == b"x" * 50
    assert cache.info().entries == 1 and cache.get("big", lambda: b"") == b"x" * 50


def test_the_limit_follows_the_last_build_and_never_drops_under_the_floor() -> None:
    cache = _cache(floor=100)
    cache.start_build()
    for i in range(10):  # a build that reads 300 bytes of blocks
        cache.get(i, lambda: b"x" * 30)
    assert cache.info().limit_bytes == 100 and cache.info().entries == 3
    cache.start_build()
    assert cache.info().limit_bytes == 450  # 1.5 x what the build read
    for i in range(10):
        cache.get(i, lambda: b"x" * 30)
    assert cache.info().entries == 10  # the next build keeps every block it reads
    cache.start_build()
    cache.get(0, lambda: b"")
    cache.start_build()  # a small scene: the limit shrinks back to the floor and evicts
    info = cache.info()
    assert info.limit_bytes == 100 and info.bytes <= 100


def test_threads_sharing_the_cache_keep_its_byte_count_exact() -> None:
    cache = _cache(floor=2_000)

    def work(offset: int) -> None:
        for i in range(2_000):
            cache.get((i + offset) % 150, lambda: b"x" * 20)
            if i % 500 == 0:
                cache.start_build()

    threads = [threading.Thread(target=work, args=(k * 37,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    info = cache.info()
    assert info.bytes == 20 * info.entries <= info.limit_bytes


def test_cached_blocks_are_the_blocks_generated_and_counted_by_their_arrays() -> None:
    model = default_models().for_layer(CloudType.CUMULUS, 800.0)
    BLOCK_CACHE.clear()
    block = block_clouds(3, -2, 48, model, 800.0, 11)
    fresh = generate_block_clouds(3, -2, 48, model, 800.0, 11)
    assert block is block_clouds(3, -2, 48, model, 800.0, 11)
    assert (block.sprites.centre_m == fresh.sprites.centre_m).all()
    info = BLOCK_CACHE.info()
    # centre_m alone is 24 bytes a sprite; all the arrays together are more.
    assert info.bytes > 24 * len(block.sprites.size_m)
    assert (info.hits, info.misses, info.entries) == (1, 1, 1)
