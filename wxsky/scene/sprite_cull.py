"""Wang's cull: walk the sprite list in order and drop any sprite whose centre lies closer than
the cull distance to a sprite kept before it, which removes overdraw and the doubles that
overlapping boxes make. Vectorised: a voxel grid finds the close pairs, then the walk's result
(the first-come maximal set) is reached by rounds that each settle every sprite whose earlier
neighbours are all settled.
"""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]

# Half of the 27 neighbour voxels: a pair in voxels v and v + o is found from v alone.
_OFFSETS = np.array(
    [o for o in itertools.product((-1, 0, 1), repeat=3) if o >= (0, 0, 0)], np.int64
)  # (14, 3)


def close_pairs(centre_m: F64, reach_m: F64, group: I64) -> tuple[I64, I64]:
    """Index pairs (i, j), i < j, of one group whose centres lie closer than
    max(reach_i, reach_j). centre_m (N, 3), reach_m (N,), group (N,) non-negative."""
    n = centre_m.shape[0]
    cell = float(reach_m.max()) if n else 0.0
    if n < 2 or cell <= 0.0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    voxel = np.floor(centre_m / cell).astype(np.int64)
    voxel -= voxel.min(axis=0) - 1  # one empty voxel of margin below, so offsets never wrap
    dims = voxel.max(axis=0) + 2
    key = ((group * dims[0] + voxel[:, 0]) * dims[1] + voxel[:, 1]) * dims[2] + voxel[:, 2]
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    strides = np.array([dims[1] * dims[2], dims[2], 1], np.int64)
    firsts, seconds = [], []
    for offset in _OFFSETS @ strides:
        query = key + offset
        lo = np.searchsorted(sorted_key, query, side="left")
        counts = np.searchsorted(sorted_key, query, side="right") - lo
        total = int(counts.sum())
        if total == 0:
            continue
        i = np.repeat(np.arange(n, dtype=np.int64), counts)
        starts = np.repeat(lo - (np.cumsum(counts) - counts), counts)
        j = order[starts + np.arange(total, dtype=np.int64)]
        if offset == 0:  # the same voxel finds each pair both ways round
            i, j = i[i < j], j[i < j]
        firsts.append(np.minimum(i, j))
        seconds.append(np.maximum(i, j))
    if not firsts:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    a, b = np.concatenate(firsts), np.concatenate(seconds)
    d2 = np.sum((centre_m[a] - centre_m[b]) ** 2, axis=1)
    reach = np.maximum(reach_m[a], reach_m[b])
    close = d2 < reach * reach
    return a[close], b[close]


def cull_mask(centre_m: F64, reach_m: F64, group: I64) -> B:
    """(N,) True for the sprites Wang's in-order walk keeps."""
    n = centre_m.shape[0]
    earlier, later = close_pairs(centre_m, reach_m, group)
    undecided, kept, dropped = 0, 1, 2
    state = np.zeros(n, np.int8)
    while True:
        open_ = state[later] == undecided
        earlier, later = earlier[open_], later[open_]
        pending = state == undecided
        if not pending.any():
            break
        # A sprite goes if an earlier neighbour stays; it stays once every earlier neighbour
        # has gone. The first pending sprite always settles, so the loop ends.
        beaten = np.zeros(n, np.bool_)
        beaten[later[state[earlier] == kept]] = True
        waiting = np.zeros(n, np.bool_)
        waiting[later[state[earlier] == undecided]] = True
        state[pending & beaten] = dropped
        state[pending & ~beaten & ~waiting] = kept
    keep: B = state == kept
    return keep


# Above this many sprite pairs per call the dense form's (n, k, k) tables cost more than the
# voxel grid's searches: `cull_mask_clouds` falls back to `cull_mask`.
DENSE_PAIRS_MAX = 2_000_000


def cull_mask_clouds(centre_m: F64, reach_m: F64) -> B:
    """`cull_mask` for n clouds of k sprites each, walked cloud by cloud: centre_m (n, k, 3),
    reach_m (n, k); returns (n, k). A block's clouds are small (tens of sprites), so every
    pair of a cloud is compared at once rather than found through a voxel grid: the same
    sprites kept, for a fraction of the calls."""
    n, k = reach_m.shape
    if n * k * k > DENSE_PAIRS_MAX:
        group = np.repeat(np.arange(n, dtype=np.int64), k)
        flat: B = cull_mask(centre_m.reshape(-1, 3), reach_m.reshape(-1), group)
        return flat.reshape(n, k)
    # Summed as cull_mask sums them, axis by axis, so the same pairs count as close.
    d2 = sum((centre_m[:, :, None, a] - centre_m[:, None, :, a]) ** 2 for a in range(3))
    reach = np.maximum(reach_m[:, :, None], reach_m[:, None, :])
    # close[c, i, j]: sprite i comes before j in cloud c and is within reach of it (as
    # float32, so that "has a neighbour that..." is one batched matrix product).
    close = ((d2 < reach * reach) & np.triu(np.ones((k, k), np.bool_), 1)[None]).astype(np.float32)
    kept = np.zeros((n, 1, k), np.float32)
    open_ = np.ones((n, 1, k), np.float32)
    while open_.any():
        # As cull_mask: a sprite goes if an earlier neighbour stays, stays once every
        # earlier neighbour has gone; the first open sprite of a cloud always settles.
        beaten = np.matmul(kept, close) > 0.0
        waiting = np.matmul(open_, close) > 0.0
        settles_kept = (open_ > 0.0) & ~beaten & ~waiting
        kept[settles_kept] = 1.0
        open_[beaten | ~waiting] = 0.0
    out: B = kept[:, 0, :] > 0.0
    return out
