"""Which clouds the scene holds: every block of every layer whose nearest point lies in a
range of distances from a centre, placed where the wind has drifted its layer. The near layer
takes the blocks within the ring radius of the ring(s) it complements, each with its share of
the picture (`gather_near`); the ring takes the rest out to the maximum range (`gather_far`).

Each layer drifts with the wind at its altitude: its blocks live in a frame moved by the
integrated wind (`Drift`), so the clouds travel but never change shape.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections import OrderedDict
from collections.abc import Hashable, Iterator
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

from wxsky.scene.clouds import BLOCK_SIZE_M, SpriteBatch, layer_keys
from wxsky.scene.formation import layer_block
from wxsky.scene.rain import Rain, rain_of
from wxsky.scene.ring import in_impostors
from wxsky.weather.state import WeatherState

Drift = tuple[tuple[float, float], ...]  # per cloud layer: (east, north) offset in metres


def zero_drift(state: WeatherState) -> Drift:
    return tuple((0.0, 0.0) for _ in state.layers)


def carry_drift(old: WeatherState, new: WeatherState, drift: Drift) -> Drift:
    """The drift of `new`'s layers: a layer that was already there keeps its offset (found by
    its key), a new one starts at zero, so forming or dissipating a layer moves no other."""
    if len(drift) != len(old.layers):
        return zero_drift(new)
    by_key = dict(zip(layer_keys(old.layers), drift, strict=True))
    return tuple(by_key.get(key, (0.0, 0.0)) for key in layer_keys(new.layers))


def advance_drift(state: WeatherState, drift: Drift, dt_s: float) -> Drift:
    """Move every layer by the wind at its mid altitude for dt_s simulated seconds."""
    if len(drift) != len(state.layers):
        drift = zero_drift(state)
    winds = state.layer_winds_mps
    return tuple(
        (dx + ve * dt_s, dy + vn * dt_s) for (dx, dy), (ve, vn) in zip(drift, winds, strict=True)
    )


def gather_blocks(
    state: WeatherState,
    drift: Drift,
    centre_m: tuple[float, float, float],
    min_range_m: float,
    max_range_m: float,
    select_drift: Drift | None = None,
) -> SpriteBatch:
    """Sprites of every block whose nearest point to the centre lies in [min, max) metres,
    placed with `drift`. Blocks are chosen with `select_drift` when given: the near layer
    picks its blocks as they stood when the ring was built, so no block is drawn both as
    sprites and in the ring, nor in neither, until the ring is rebuilt."""
    ring = NearRing(centre_m, drift if select_drift is None else select_drift, 1.0)
    return _gather(state, drift, (ring,), min_range_m, max_range_m)[0]


class NearRing(NamedTuple):
    """A ring the near layer complements: blocks within its radius of `centre_m` (as they
    stood at `select_drift`) are near sprites, the rest are in the ring's impostors."""

    centre_m: tuple[float, float, float]
    select_drift: Drift
    weight: float  # the ring's share of the picture: 1, or its side of a cross-fade


def gather_near(
    state: WeatherState,
    drift: Drift,
    rings: tuple[NearRing, ...],
    radius_m: float,
    max_range_m: float | None = None,
) -> tuple[SpriteBatch, npt.NDArray[np.float32]]:
    near, share, _ = gather_near_blocks(state, drift, rings, radius_m, max_range_m)
    return near, share


def gather_near_blocks(
    state: WeatherState,
    drift: Drift,
    rings: tuple[NearRing, ...],
    radius_m: float,
    max_range_m: float | None = None,
) -> tuple[SpriteBatch, npt.NDArray[np.float32], NearBlocks | None]:
    """`gather_near`, and the set of blocks it placed (`near_blocks`; None where it gathered
    them anew): the same set, frame after frame, holds the same sprites."""
    if len(drift) != len(state.layers):
        drift = zero_drift(state)
    rings = selecting_now(rings, drift, radius_m)
    blocks = near_blocks(state, drift, rings, radius_m, max_range_m)
    placed = None if blocks is None else blocks.placed(drift, rings)
    if placed is None:
        return (*_gather_near(state, drift, rings, radius_m, max_range_m), None)
    return (*placed, blocks)


def selecting_now(
    rings: tuple[NearRing, ...], drift: Drift, radius_m: float
) -> tuple[NearRing, ...]:
    """The rings, each choosing its blocks with `drift` where the clouds have moved more than
    `radius_m` since it was built (a clock set: months of wind move them a hundred thousand
    kilometres). Blocks chosen as they stood would be placed that far from the eye, and until
    a ring for the new time arrived the near layer would show nothing; chosen as they stand,
    it shows the clouds around the eye, and the old ring's impostors stay beyond them."""
    out = []
    for ring in rings:
        if len(ring.select_drift) == len(drift) and any(
            math.hypot(a[0] - b[0], a[1] - b[1]) > radius_m
            for a, b in zip(ring.select_drift, drift, strict=True)
        ):
            ring = ring._replace(select_drift=drift)
        out.append(ring)
    return tuple(out)


def _gather_near(
    state: WeatherState,
    drift: Drift,
    rings: tuple[NearRing, ...],
    radius_m: float,
    max_range_m: float | None = None,
) -> tuple[SpriteBatch, npt.NDArray[np.float32]]:
    """The near sprites that complement the rings drawn, and (N,) the share of each to show:
    a block inside the radius of rings whose weights add up to w shows at w. While an old and
    a new ring cross-fade (weights 1 - f and f), every block then totals 1 between the near
    layer and the two rings, wherever the two centres are, so nothing doubles or vanishes
    mid-fade. The share is applied after shading, so a fade never changes the lighting.
    With `max_range_m`, layers too far above or below the rings to go into impostors
    (`ring.in_impostors`) are gathered out to it: they are drawn directly."""
    if max_range_m is None or not rings:
        return _gather(state, drift, rings, 0.0, radius_m)
    centre_z = rings[0].centre_m[2]
    ranges = [
        (0.0, radius_m if in_impostors(lay.base_m, lay.top_m, centre_z) else max_range_m)
        for lay in state.layers
    ]
    return _gather(state, drift, rings, 0.0, radius_m, ranges)


def blocks_within(qx_m: float, qy_m: float, lo_m: float, hi_m: float) -> Iterator[tuple[int, int]]:
    """(bx, by) of every block whose nearest point to (qx_m, qy_m) lies in [lo_m, hi_m),
    row by row."""
    bx0, bx1 = math.floor((qx_m - hi_m) / BLOCK_SIZE_M), math.floor((qx_m + hi_m) / BLOCK_SIZE_M)
    by0, by1 = math.floor((qy_m - hi_m) / BLOCK_SIZE_M), math.floor((qy_m + hi_m) / BLOCK_SIZE_M)
    for by in range(by0, by1 + 1):
        for bx in range(bx0, bx1 + 1):
            near_x = min(max(qx_m, bx * BLOCK_SIZE_M), (bx + 1) * BLOCK_SIZE_M)
            near_y = min(max(qy_m, by * BLOCK_SIZE_M), (by + 1) * BLOCK_SIZE_M)
            if lo_m <= math.hypot(near_x - qx_m, near_y - qy_m) < hi_m:
                yield bx, by


def count_blocks(lo_m: float, hi_m: float) -> int:
    """The most blocks of one layer whose nearest point lies in [lo_m, hi_m) of a centre,
    wherever in its block the centre stands (counted, vectorised, for centres on a grid of
    1/16 of a block over the eighth of a block that by symmetry stands for all of it)."""
    if hi_m <= lo_m:
        return 0
    n = math.ceil(hi_m / BLOCK_SIZE_M) + 1
    edges = np.arange(-n, n + 1, dtype=np.float64) * BLOCK_SIZE_M  # block corners
    most = 0
    steps = [i / 16.0 for i in range(9)]  # 0 .. 0.5
    for fx, fy in ((fx, fy) for fx in steps for fy in steps if fy <= fx):
        qx, qy = fx * BLOCK_SIZE_M, fy * BLOCK_SIZE_M
        dx = np.clip(qx, edges[:-1], edges[1:]) - qx
        dy = np.clip(qy, edges[:-1], edges[1:]) - qy
        d = np.hypot(dx[None, :], dy[:, None])
        most = max(most, int(np.count_nonzero((d >= lo_m) & (d < hi_m))))
    return most


# The most blocks of one layer the scene may hold (`[scene]` ring_radius_m and max_range_m
# are checked against them at load). A ring build gathers, shades and bins every sprite of
# its blocks (about 600 bytes and 20 us of one core per sprite, some 100 to 400 sprites a
# block and layer): 1024 blocks, three times the default's 337 (max_range_m about 69 km at a
# small radius), is a build of some 8 s and 300 MB for a three-layer storm; 256 near blocks,
# eleven times the default's 23 (ring_radius_m about 33 km), some 0.2 s a frame. Three layers'
# The block cache (`clouds.BLOCK_CACHE`) sizes itself to the blocks the last build used, so a
# rebuild reads its blocks rather than generating them again.
MAX_RING_BLOCKS = 1024
MAX_NEAR_BLOCKS = 256


def largest_range(lo_m: float, max_blocks: int, step_m: float = 1000.0) -> float:
    """The largest multiple of step_m, above lo_m, out to which [lo_m, range) holds at most
    max_blocks blocks (lo_m itself when no such range exists)."""
    good, bad = lo_m, lo_m + step_m
    while count_blocks(lo_m, bad) <= max_blocks:
        good, bad = bad, 2.0 * bad
    while bad - good > step_m:
        mid = 0.5 * (good + bad)
        if count_blocks(lo_m, mid) <= max_blocks:
            good = mid
        else:
            bad = mid
    return max(lo_m, math.floor(good / step_m) * step_m)


class SceneBlocks(NamedTuple):
    """How many blocks of one layer a scene with this ring radius and range holds at most."""

    near: int  # within the ring radius: gathered for every frame
    ring: int  # from the ring radius to the maximum range: gathered for every ring build


def scene_blocks(ring_radius_m: float, max_range_m: float) -> SceneBlocks:
    return SceneBlocks(count_blocks(0.0, ring_radius_m), count_blocks(ring_radius_m, max_range_m))


class BuildCancelled(Exception):
    """Scene work given up because its `cancel` Event was set (the daemon is stopping)."""


class CancelFlag(Protocol):
    """What scene work polls to give up: a threading.Event, or in the ring's worker process
    its socket (`engine.ring_worker`)."""

    def is_set(self) -> bool: ...


def check_cancel(cancel: CancelFlag | None) -> None:
    """Raise BuildCancelled once `cancel` is set: scene work that can take seconds calls this
    between blocks, so that a shutdown never waits for a ring to finish."""
    if cancel is not None and cancel.is_set():
        raise BuildCancelled("scene work cancelled")


def _gather(
    state: WeatherState,
    drift: Drift,
    rings: tuple[NearRing, ...],
    min_range_m: float,
    max_range_m: float,
    layer_ranges: list[tuple[float, float]] | None = None,
    cancel: CancelFlag | None = None,
) -> tuple[SpriteBatch, npt.NDArray[np.float32]]:
    """`layer_ranges`: per layer, (min, max) in place of (min_range_m, max_range_m); a layer
    with max <= min is skipped. `cancel`: see `check_cancel`."""
    if len(drift) != len(state.layers):
        drift = zero_drift(state)
    rings = tuple(
        r if len(r.select_drift) == len(drift) else r._replace(select_drift=drift) for r in rings
    )
    batches: list[SpriteBatch] = []
    shares: list[npt.NDArray[np.float32]] = []
    rain = rain_of(state)
    for li, (key, layer, (dx, dy)) in enumerate(
        zip(layer_keys(state.layers), state.layers, drift, strict=True)
    ):
        lo_m, hi_m = (min_range_m, max_range_m) if layer_ranges is None else layer_ranges[li]
        if layer.cover_oktas <= 0.0 or hi_m <= lo_m:
            continue
        weights: dict[tuple[int, int], float] = {}
        for ring in rings:
            sx, sy = ring.select_drift[li]
            for xy in blocks_within(ring.centre_m[0] - sx, ring.centre_m[1] - sy, lo_m, hi_m):
                weights[xy] = weights.get(xy, 0.0) + ring.weight
        for (bx, by), weight in sorted(weights.items(), key=lambda kv: (kv[0][1], kv[0][0])):
            if weight <= 0.0:
                continue
            check_cancel(cancel)
            # Cover only fades whole clouds in and out, so the cached generation of the
            # block is reused while the weather forms or dissipates it.
            block = layer_block(bx, by, key, layer, state.seed, (dx, dy), rain=rain)
            if not len(block):
                continue
            batches.append(block)
            shares.append(np.full(len(block), min(weight, 1.0), np.float32))
    share = np.concatenate(shares) if shares else np.zeros(0, np.float32)
    return SpriteBatch.concat(batches), share


def gather_far(
    state: WeatherState,
    drift: Drift,
    centre_m: tuple[float, float, float],
    radius_m: float,
    max_range_m: float,
    cancel: CancelFlag | None = None,
) -> SpriteBatch:
    """The ring's sprites: blocks from radius_m to max_range_m of the centre, of the layers
    close enough in altitude to go into impostors (`ring.in_impostors`). Raises
    BuildCancelled once `cancel` is set."""
    ring = NearRing(centre_m, drift, 1.0)
    ranges = [
        (radius_m, max_range_m) if in_impostors(lay.base_m, lay.top_m, centre_m[2]) else (0.0, 0.0)
        for lay in state.layers
    ]
    return _gather(state, drift, (ring,), radius_m, max_range_m, ranges, cancel)[0]


# The near layer's blocks are chosen by the rings' centres and drifts, not by the camera: the
# same few dozen blocks are gathered every frame until the ring is rebuilt, and their sprites
# differ from frame to frame only by the drift, which is added last. So each set of blocks is
# formed, joined and put at its layers' bases once (`near_blocks`), and a frame only adds its
# drift to a copy of the centres (`NearBlocks.placed`): gathering anew every frame was most
# of the scene stage. Keyed by content (the weather's layers and seed, and the blocks each
# ring picks), so a hit is exactly what gathering again would give.
_NEAR_SETS = 4  # the ring on show's, a cross-fade's (both rings'), the incoming ring's, one spare
_PICKS = 64  # blocks_within results: per layer and ring, a few rings' worth


@dataclass(frozen=True, eq=False)
class NearBlocks:
    """The sprites of the near layer's blocks before the frame's drift: formed at the
    weather's cover, z MSL, x and y in each layer's drifting frame; layers in order, each
    layer's blocks row by row (the order `gather_near` has always given)."""

    batch: SpriteBatch
    layer_rows: tuple[tuple[int, int, int], ...]  # (layer index, first row, end row)
    block_rows: npt.NDArray[np.intp]  # (B,) sprites of each block, in batch order
    members: npt.NDArray[np.bool_]  # (R, B) True where the block is within ring r's radius
    block_keys: tuple[tuple[int, int, int], ...] = ()  # (B,) (layer index, east, north)
    # The shares for the last few rings' weights: the same, frame after frame, but in a fade.
    _shares: dict[tuple[float, ...], npt.NDArray[np.float32]] = field(
        default_factory=dict, repr=False
    )

    def __post_init__(self) -> None:
        # The set's slab mask, kept with its batch once: every frame's moved batch
        # (SpriteBatch.with_centres) and its drawn rows (take) share it.
        _ = self.batch.slab

    def placed(
        self, drift: Drift, rings: tuple[NearRing, ...]
    ) -> tuple[SpriteBatch, npt.NDArray[np.float32]] | None:
        """The sprites moved by `drift` and (N,) each one's share for these rings' weights
        (see `gather_near`), or None where a weight leaves a block out (a ring weighing 0:
        never the case in a fade, so not worth a set of its own)."""
        weights = tuple(ring.weight for ring in rings)
        share = self._shares.get(weights)
        if share is None:
            weight = np.zeros(len(self.block_rows))
            for member, w in zip(self.members, weights, strict=True):
                # In ring order, as the blocks' weights have always been summed.
                weight = weight + np.where(member, w, 0.0)
            if not (weight > 0.0).all():
                return None
            share = np.repeat(np.minimum(weight, 1.0).astype(np.float32), self.block_rows)
            share.flags.writeable = False
            if len(self._shares) >= 4:  # a fade's weights change every frame
                self._shares.clear()
            self._shares[weights] = share
        centre = self.batch.centre_m.copy()
        moved = np.zeros((len(centre), 2), np.float32)
        for li, start, stop in self.layer_rows:
            dx, dy = drift[li]
            centre[start:stop, 0] += dx
            centre[start:stop, 1] += dy
            moved[start:stop] = (dx, dy)
        return self.batch.with_centres(centre, moved), share


class SetKey:
    """A near set's key: the weather's seed and layers, its rain, and the blocks each ring
    picks. Its hash is worked out once: hashing the layers (dataclasses) and every block's
    place anew, twice a frame, was a fiftieth of the scene stage. Rebuilt from its parts
    when pickled, since a string's hash differs from process to process."""

    __slots__ = ("_hash", "parts")

    def __init__(self, parts: tuple[object, ...]) -> None:
        self.parts = parts
        self._hash = hash(parts)

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other: object) -> bool:
        return isinstance(other, SetKey) and self._hash == other._hash and self.parts == other.parts

    def __reduce__(self) -> tuple[type[SetKey], tuple[tuple[object, ...]]]:
        return SetKey, (self.parts,)


_near_lock = threading.Lock()
_near_sets: OrderedDict[Hashable, NearBlocks] = OrderedDict()
# The key the last lookup made: a frame's parts are the last frame's (the same objects, from
# the weather and `_picks`), which compare equal at once, so its hash is kept too.
_last_key: SetKey | None = None
_picks: OrderedDict[tuple[float, float, float, float], tuple[tuple[int, int], ...]] = OrderedDict()


def near_blocks(
    state: WeatherState,
    drift: Drift,
    rings: tuple[NearRing, ...],
    radius_m: float,
    max_range_m: float | None = None,
) -> NearBlocks | None:
    """The blocks `gather_near` gathers for these rings, before the drift (None without
    rings). Safe from any thread: the ring's worker prepares the next ring's set with it."""
    keyed = near_blocks_keyed(state, drift, rings, radius_m, max_range_m)
    return None if keyed is None else keyed[1]


def near_blocks_keyed(
    state: WeatherState,
    drift: Drift,
    rings: tuple[NearRing, ...],
    radius_m: float,
    max_range_m: float | None = None,
) -> tuple[Hashable, NearBlocks] | None:
    """`near_blocks`, with the key it is kept under (`install_near_blocks`)."""
    wanted = near_set_key(state, drift, rings, radius_m, max_range_m)
    if wanted is None:
        return None
    found = kept_near_blocks(wanted.key)
    if found is not None:
        return wanted.key, found
    made = make_near_blocks(state, wanted)
    install_near_blocks(wanted.key, made)
    return wanted.key, made


class NearSetKey(NamedTuple):
    """Which near set a frame needs (`near_set_key`): its key and what making it reads."""

    key: SetKey
    picks: tuple[tuple[tuple[tuple[int, int], ...], ...], ...]  # per layer, per ring: blocks
    n_rings: int
    rain: Rain | None


def near_set_key(
    state: WeatherState,
    drift: Drift,
    rings: tuple[NearRing, ...],
    radius_m: float,
    max_range_m: float | None = None,
) -> NearSetKey | None:
    """The key of the near set these rings pick (None without rings), without making it:
    a frame that must not wait looks it up (`kept_near_blocks`) and, where it is missing,
    has it made elsewhere (`make_near_blocks`)."""
    global _last_key
    if not rings:
        return None
    if len(drift) != len(state.layers):
        drift = zero_drift(state)
    if max_range_m is None:
        ranges = [(0.0, radius_m)] * len(state.layers)
    else:
        centre_z = rings[0].centre_m[2]
        ranges = [
            (0.0, radius_m if in_impostors(lay.base_m, lay.top_m, centre_z) else max_range_m)
            for lay in state.layers
        ]
    picks: list[tuple[tuple[tuple[int, int], ...], ...]] = []
    for li, layer in enumerate(state.layers):
        lo_m, hi_m = ranges[li]
        if layer.cover_oktas <= 0.0 or hi_m <= lo_m:
            picks.append(())
            continue
        per_ring = []
        for ring in rings:
            select = ring.select_drift if len(ring.select_drift) == len(drift) else drift
            sx, sy = select[li]
            per_ring.append(
                _blocks_picked(ring.centre_m[0] - sx, ring.centre_m[1] - sy, lo_m, hi_m)
            )
        picks.append(tuple(per_ring))
    rain = rain_of(state)
    chosen = tuple(picks)
    parts = (state.seed, state.layers, rain, len(rings), chosen)
    last = _last_key  # one read: another thread may replace it
    key = last if last is not None and last.parts == parts else SetKey(parts)
    _last_key = key
    return NearSetKey(key, chosen, len(rings), rain)


def kept_near_blocks(key: Hashable) -> NearBlocks | None:
    """The near set kept under `key` (made here or installed), or None."""
    with _near_lock:
        found = _near_sets.get(key)
        if found is not None:
            _near_sets.move_to_end(key)
        return found


def make_near_blocks(state: WeatherState, wanted: NearSetKey) -> NearBlocks:
    """The near set `wanted` names, made now (tens to hundreds of milliseconds: every block
    not in the block cache is generated); not kept: see `install_near_blocks`."""
    return _make_near_blocks(state, list(wanted.picks), wanted.n_rings, wanted.rain)


def install_near_blocks(key: Hashable, blocks: NearBlocks) -> None:
    """Keep a near set made elsewhere (the ring's worker process) under its key, as if it
    had been made here: the frames then find it instead of gathering it."""
    with _near_lock:
        _near_sets[key] = blocks
        _near_sets.move_to_end(key)
        while len(_near_sets) > _NEAR_SETS:
            _near_sets.popitem(last=False)


def _blocks_picked(
    qx_m: float, qy_m: float, lo_m: float, hi_m: float
) -> tuple[tuple[int, int], ...]:
    key = (qx_m, qy_m, lo_m, hi_m)
    with _near_lock:
        found = _picks.get(key)
        if found is not None:
            _picks.move_to_end(key)
            return found
    made = tuple(blocks_within(qx_m, qy_m, lo_m, hi_m))
    with _near_lock:
        _picks[key] = made
        while len(_picks) > _PICKS:
            _picks.popitem(last=False)
    return made


def _make_near_blocks(
    state: WeatherState,
    picks: list[tuple[tuple[tuple[int, int], ...], ...]],
    n_rings: int,
    rain: Rain | None,
) -> NearBlocks:
    batches: list[SpriteBatch] = []
    rows: list[int] = []
    members: list[list[bool]] = []
    layer_rows: list[tuple[int, int, int]] = []
    keys: list[tuple[int, int, int]] = []
    start = 0
    for li, (key, layer, per_ring) in enumerate(
        zip(layer_keys(state.layers), state.layers, picks, strict=True)
    ):
        within: dict[tuple[int, int], list[bool]] = {}
        for r, blocks in enumerate(per_ring):
            for xy in blocks:
                within.setdefault(xy, [False] * n_rings)[r] = True
        first = start
        for (bx, by), member in sorted(within.items(), key=lambda kv: (kv[0][1], kv[0][0])):
            block = layer_block(bx, by, key, layer, state.seed, rain=rain)
            batches.append(block)
            rows.append(len(block))
            members.append(member)
            keys.append((li, bx, by))
            start += len(block)
        if start > first:
            layer_rows.append((li, first, start))
    batch = SpriteBatch.concat(batches)
    for f in dataclasses.fields(batch):
        getattr(batch, f.name).flags.writeable = False
    return NearBlocks(
        batch,
        tuple(layer_rows),
        np.asarray(rows, np.intp),
        np.asarray(members, np.bool_).reshape(len(members), n_rings).T,
        tuple(keys),
    )


def clear_near_blocks() -> None:
    """Forget every near set (tests that count block generations)."""
    with _near_lock:
        _near_sets.clear()
        _picks.clear()
