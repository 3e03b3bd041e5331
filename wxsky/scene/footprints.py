"""Each cloud's footprint in a batch of sprites: where its base is, how wide, how tall. Shared by
the rain shafts (`rain.py`) and the convective towers (`convection.py`), which both hang off a
cloud's base."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.sprites import SpriteBatch

BASE_BAND_M = 400.0  # a cloud's base: its sprites this close above its lowest one

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Footprints:
    """Per cloud of a batch, in the batch's frame (C clouds, in cloud-id order)."""

    ids: npt.NDArray[np.int64]  # (C,)
    inverse: npt.NDArray[np.intp]  # (N,) each sprite's cloud
    axis_m: F64  # (C, 2) the middle of the base's sprites
    radius_m: F64  # (C,) how far the base's sprites reach from the axis, their extent included
    bottom_m: F64  # (C,) the lowest sprite centre
    top_m: F64  # (C,) the highest sprite top
    formed: F64  # (C,) mean opacity of the base's sprites (formation, type transparency)
    base: npt.NDArray[np.bool_]  # (N,) whether each sprite is in its cloud's base


def footprints(clouds: SpriteBatch) -> Footprints:
    """The footprint of every cloud in `clouds` (at least one sprite)."""
    ids, inverse = np.unique(clouds.cloud_id, return_inverse=True)
    n = len(ids)
    z = clouds.centre_m[:, 2]
    bottom = np.full(n, np.inf)
    np.minimum.at(bottom, inverse, z)
    top = np.full(n, -np.inf)
    np.maximum.at(top, inverse, z + 0.5 * clouds.size_m)
    base = z <= bottom[inverse] + BASE_BAND_M
    count = np.bincount(inverse, base.astype(np.float64), minlength=n)
    axis = np.stack(
        [np.bincount(inverse, base * clouds.centre_m[:, k], n) / count for k in (0, 1)], axis=1
    )
    reach = np.hypot(*(clouds.centre_m[:, :2] - axis[inverse]).T) + 0.5 * clouds.size_m
    radius = np.zeros(n)
    np.maximum.at(radius, inverse, np.where(base, reach, 0.0))
    formed = np.bincount(inverse, base * clouds.opacity, n) / count
    return Footprints(ids, inverse, axis, radius, bottom, top, formed, base)
