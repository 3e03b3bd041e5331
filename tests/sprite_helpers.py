"""One way for tests to make a sprite batch by hand: the fields a test cares about, the rest
at plain defaults (half-way up the cloud, lit from above, opaque, core)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from wxsky.scene.sprites import SpriteBatch
from wxsky.scene.texture_slots import TEX_FOG

ArrayLike = Sequence[float] | npt.NDArray[np.floating] | float


def sprite_batch(
    centres: Sequence[Sequence[float]] | npt.NDArray[np.floating],
    sizes: ArrayLike = 400.0,
    *,
    texture: int = TEX_FOG[0],
    rotation: ArrayLike = 0.0,
    cloud_id: Sequence[int] | npt.NDArray[np.integer] | int = 0,
) -> SpriteBatch:
    """N sprites at `centres` (N, 3); sizes, rotations and cloud ids one each or one for all."""
    centre = np.asarray(centres, np.float64).reshape(-1, 3)
    n = len(centre)
    return SpriteBatch(
        centre_m=centre,
        size_m=np.broadcast_to(np.asarray(sizes, np.float32), (n,)).copy(),
        rotation_rad=np.broadcast_to(np.asarray(rotation, np.float32), (n,)).copy(),
        texture=np.full(n, texture, np.int32),
        height_frac=np.full(n, 0.5, np.float32),
        light_dir=np.tile(np.float32([0, 0, 1]), (n, 1)),
        opacity=np.ones(n, np.float32),
        darkness=np.zeros(n, np.float32),
        cloud_id=np.broadcast_to(np.asarray(cloud_id, np.int64), (n,)).copy(),
        core_frac=np.zeros(n, np.float32),
    )
