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
