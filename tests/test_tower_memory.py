"""Issue 40: towers took the daemon's memory from about 216 MB to 540-700 MB. The caches
that hold it are bounded in bytes, whatever the towers' grid: checked here by filling them
with more towers than they keep (64^3 and 128^3), not by timing or RSS."""

from __future__ import annotations

import numpy as np

from wxsky.engine import tower_work
from wxsky.scene.tower_field import LitVolume
from wxsky.towers.volume import TowerSpec


def test_the_process_tower_caches_stay_within_their_byte_bounds() -> None:
    before = tower_work.cache_info()
    seed = 900_001  # towers of no other test: their own keys
    for grid in (64, 128, 64):
        for cell in range(80):
            spec = TowerSpec(seed, (grid, 0), cell, grid=grid)
            tower_work.tower_volume(spec)
            texels = np.zeros((2, grid, grid, grid, 4), np.uint8)
            tower_work.share_lit(LitVolume((spec, 0, "test"), texels))
            info = tower_work.cache_info()
            # Over the bound only by the floor: at most MIN_VOLUMES_KEPT automata, one lit step.
            assert (
                info["automata_bytes"] <= tower_work.VOLUMES_KEPT_BYTES
                or info["automata"] <= tower_work.MIN_VOLUMES_KEPT
            ), info
            assert info["lit_bytes"] <= tower_work.LIT_SHARED_BYTES or info["lit_steps"] == 1
        # The bytes counted are the bytes held.
        assert info["lit_bytes"] == sum(
            lit.texels.nbytes for lit in tower_work._shared_lit.values()
        )
        assert info["automata_bytes"] == sum(
            tower_work.automaton_bytes(s) for s in tower_work._volumes
        )
        # Full: the bound is what limits it (80 towers of 1.5 or 12 MiB do not fit 96 MiB).
        assert info["automata_bytes"] > tower_work.VOLUMES_KEPT_BYTES // 2
    assert before["automata_limit_bytes"] == 96 << 20 and before["lit_limit_bytes"] == 64 << 20
