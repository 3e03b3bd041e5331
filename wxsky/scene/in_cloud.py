"""Flying through a cloud (Wang, "In-Cloud Experience"): a sprite's facing locks when the camera
comes within half its radius, so the camera passes through a fixed quad instead of a sprite
that swings round to face it; the locked sprite then fades with the angle between its normal
and the direction to the eye (see the sprite shader). Also: is the camera in cloud, and how
far can it see there, for the host to fog its own scene; and the same fog on our own layers
(`in_cloud_fog`), so the sprites beyond the visibility and the ring and sky behind them vanish
into the cloud instead of showing clear through it.

Locks are the only per-frame memory of the scene stage. They are keyed by a sprite's identity
(its cloud, size and rotation, which generation fixes), not by its place in a batch, so a
sprite keeps its lock while others form, dissipate or are sorted around it.

A sprite's dense part is where it is drawn: within its reach of the sprite's centre, and
within the layer the sprite belongs to, its base to its top. The sprites of a deck are far
wider than the deck is thick, so a sphere round each would reach hundreds of metres above
and below it, and a point in the clear air over a stratus deck would be "in cloud". So the
eye is in a sprite only while it is inside a cloud layer holding the sprite's centre, and its
depth there falls to nothing at the layer's base and top as it does at the sprite's edge. Rain
and snow shafts hang below their clouds and are not cloud. Pure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import numpy.typing as npt

from wxsky.scene.clouds import SpriteBatch
from wxsky.scene.rain import is_shaft
from wxsky.scene.sky import KOSCHMIEDER
from wxsky.weather.state import CloudLayer

F32 = npt.NDArray[np.float32]
SpriteKey = tuple[int, int, int]  # (cloud_id, size in cm, rotation in 1e-4 rad)
Locks = Mapping[SpriteKey, tuple[float, float, float]]  # sprite -> locked unit normal (ENU)
Spans = tuple[tuple[float, float], ...]  # each cloud layer's (base, top), m MSL

LOCK_FRAC = 0.25  # lock within half the sprite's radius (a quarter of its edge)
UNLOCK_FRAC = 0.5  # release once the camera is out of the sprite's radius again
INSIDE_FRAC = 0.35  # the camera is in cloud within this share of a sprite's edge length
# In-cloud visibility runs from the edge of a sprite's dense part to its centre; 40 m is
# about what a pilot sees inside a cumulus (a liquid water content near 0.5 g/m3).
VISIBILITY_EDGE_M = 600.0
VISIBILITY_CORE_M = 40.0
# The fog thickens from nothing at the edge of a cloud's dense part to all-hiding this far
# in (as a share of the way to the centre), so entering a cloud never pops.
VEIL_FULL_DEPTH = 0.5
NO_LOCKS: Locks = MappingProxyType({})
NO_VEIL = (0.0, 0.0, 0.0, 0.0)
# A sprite's centre is its layer's base plus a height within the layer's thickness: the sum
# may miss the top by a rounding, so a layer holds the centres within this of it.
SPAN_SLACK_M = 0.01


@dataclass(frozen=True)
class InCloud:
    inside: bool
    visibility_m: float | None  # None outside cloud

    def to_dict(self) -> dict[str, object]:
        return {"in_cloud": self.inside, "in_cloud_visibility_m": self.visibility_m}


OUTSIDE = InCloud(False, None)


def sprite_keys(batch: SpriteBatch) -> npt.NDArray[np.int64]:
    """(N, 3) identity of each sprite, stable across frames and processes."""
    return np.stack(
        [
            batch.cloud_id.astype(np.int64),
            np.round(batch.size_m.astype(np.float64) * 100.0).astype(np.int64),
            np.round(batch.rotation_rad.astype(np.float64) * 1e4).astype(np.int64),
        ],
        axis=1,
    )


def lock_reach_frac(locks: Locks) -> float:
    """How near the eye, in sprite edges, a sprite may be locked or keep its lock: with no
    lock held only within LOCK_FRAC (where a lock is taken), else within UNLOCK_FRAC (where a
    held one is let go). Beyond it for every sprite, nothing locks (lock_facing)."""
    return UNLOCK_FRAC if locks else LOCK_FRAC


def lock_facing(
    batch: SpriteBatch, eye_m: tuple[float, float, float], locks: Locks
) -> tuple[F32 | None, Locks]:
    """(N, 3) normals for the batch (zero rows face the camera; None when no sprite is locked)
    and the locks to keep for the next frame."""
    n = len(batch)
    if n == 0:
        return None, NO_LOCKS
    offset = np.asarray(eye_m, np.float64) - batch.centre_m  # (N, 3) sprite -> eye
    dist = np.linalg.norm(offset, axis=1)
    size = batch.size_m.astype(np.float64)
    near = np.flatnonzero(dist < lock_reach_frac(locks) * size)
    if near.size == 0:
        return None, NO_LOCKS
    keys = sprite_keys(batch.take(near))
    normals = np.zeros((n, 3), np.float32)
    kept: dict[SpriteKey, tuple[float, float, float]] = {}
    for row, i in enumerate(near):
        key: SpriteKey = (int(keys[row, 0]), int(keys[row, 1]), int(keys[row, 2]))
        normal = locks.get(key)
        if normal is None and dist[i] < LOCK_FRAC * size[i] and dist[i] > 0.0:
            # Lock to the facing it has now: the camera sees no jump at the moment of locking.
            d = offset[i] / dist[i]
            normal = (float(d[0]), float(d[1]), float(d[2]))
        if normal is not None:
            kept[key] = normal
            normals[i] = normal
    if not kept:
        return None, NO_LOCKS
    return normals, MappingProxyType(kept)


def layer_spans(layers: Sequence[CloudLayer]) -> Spans:
    """The cloud layers' (base, top), what `in_cloud` and `sprite_depths` hold sprites to."""
    return tuple((layer.base_m, layer.top_m) for layer in layers)


def in_cloud(
    batch: SpriteBatch,
    eye_m: tuple[float, float, float],
    weather_visibility_m: float,
    dist_m: npt.NDArray[np.float64] | None = None,
    *,
    spans_m: Spans,
) -> InCloud:
    """Whether the eye is inside a cloud's dense part, and the visibility there (`dist_m`:
    the sprites' distances from the eye, if known; `spans_m`: the layers the sprites belong
    to, `layer_spans`)."""
    if len(batch) == 0:
        return OUTSIDE
    deepest = float(sprite_depths(batch, eye_m, spans_m, dist_m).max())
    if deepest <= 0.0:
        return OUTSIDE
    depth_frac = min(1.0, deepest)
    visibility_m = VISIBILITY_EDGE_M * (VISIBILITY_CORE_M / VISIBILITY_EDGE_M) ** depth_frac
    return InCloud(True, min(visibility_m, weather_visibility_m))


def in_cloud_fog(
    batch: SpriteBatch,
    rgba: F32,
    eye_m: tuple[float, float, float],
    cloud: InCloud,
    dist_m: npt.NDArray[np.float64] | None = None,
) -> tuple[F32, tuple[float, float, float, float]]:
    """The sprites' (N, 4) (with rims (N, 7)) straight-alpha colours fogged by the cloud the
    eye is in, and the premultiplied veil over everything behind them (ring and sky). The
    fog is the colour of the sprite the eye is deepest in, thickening with distance at the
    in-cloud visibility (Koschmieder), and with depth into the cloud (VEIL_FULL_DEPTH).
    `dist_m`: (N,) the sprites' distances from the eye, if known."""
    if not cloud.inside or cloud.visibility_m is None or len(batch) == 0:
        return rgba, NO_VEIL
    depth_frac = math.log(cloud.visibility_m / VISIBILITY_EDGE_M) / math.log(
        VISIBILITY_CORE_M / VISIBILITY_EDGE_M
    )
    t = min(1.0, max(0.0, depth_frac / VEIL_FULL_DEPTH))
    strength = t * t * (3.0 - 2.0 * t)
    if strength <= 0.0:
        return rgba, NO_VEIL
    dist = (
        np.linalg.norm(batch.centre_m - np.asarray(eye_m, np.float64), axis=1)
        if dist_m is None
        else dist_m
    )
    # The colour only: the sprite nearest the eye for its size, drawn or not in its layer.
    fog_rgb = rgba[int(np.argmax(_radial_depths(batch, eye_m, dist))), :3].astype(np.float64)
    f = strength * (1.0 - np.exp(-KOSCHMIEDER * dist / cloud.visibility_m))  # (N,)
    out = rgba.copy()
    # Channel by channel, (3, N): numpy's loops run along the sprites, not over rows of three.
    fogged = np.multiply(rgba[:, :3].T, 1.0 - f, order="C")
    fogged += fog_rgb[:, None] * f
    out[:, :3] = fogged.T
    if rgba.shape[1] > 4:  # the sprites' rims (SpriteDraw.rgba), in the same fog
        out[:, 4:7] = (rgba[:, 4:7].T * (1.0 - f) + fog_rgb[:, None] * f).T
    r, g, b = (float(c) * strength for c in fog_rgb)
    return out, (r, g, b, strength)


def sprite_depths(
    batch: SpriteBatch,
    eye_m: tuple[float, float, float],
    spans_m: Spans,
    dist_m: npt.NDArray[np.float64] | None = None,
) -> npt.NDArray[np.float64]:
    """(N,) how deep the eye is in each sprite's dense part: > 0 inside, 1 at its centre, 0
    where it is not in the sprite. The depth is the lesser of how far in from the sprite's
    edge (its reach round its centre) and how far in from the nearer of its layer's base and
    top, each as a share of the reach: it falls to 0 at either, never jumps. A sprite counts
    only while the eye is inside a layer of `spans_m` holding the sprite's centre (overlapping
    layers: the one the eye is deepest in); rain and snow shafts never count."""
    n = len(batch)
    out = np.zeros(n)
    alt = float(eye_m[2])
    # The eye's room in each layer it is in: how far it is from that layer's base or top.
    rooms = [(base, top, min(alt - base, top - alt)) for base, top in spans_m if base <= alt <= top]
    if not rooms or n == 0:
        return out
    reach = INSIDE_FRAC * batch.size_m.astype(np.float64)
    radial = _radial_depths(batch, eye_m, dist_m, opacity=False)
    near = np.flatnonzero(radial > 0.0)
    if near.size == 0:
        return out
    centre_z = batch.centre_m[near, 2]
    room = np.zeros(near.size)
    for base, top, eye_room in rooms:
        holds = (centre_z >= base - SPAN_SLACK_M) & (centre_z <= top + SPAN_SLACK_M)
        room = np.where(holds, np.maximum(room, eye_room), room)
    depth = np.minimum(radial[near], room / reach[near]) * batch.opacity[near].astype(np.float64)
    if depth.max() > 0.0:
        depth[is_shaft(batch)[near]] = 0.0
    out[near] = np.maximum(depth, 0.0)
    return out


def _radial_depths(
    batch: SpriteBatch,
    eye_m: tuple[float, float, float],
    dist_m: npt.NDArray[np.float64] | None = None,
    *,
    opacity: bool = True,
) -> npt.NDArray[np.float64]:
    """(N,) how far in from each sprite's edge the eye is, by distance alone (> 0 within its
    reach, 1 at its centre), times its opacity unless `opacity` is False."""
    dist = (
        np.linalg.norm(batch.centre_m - np.asarray(eye_m, np.float64), axis=1)
        if dist_m is None
        else dist_m
    )
    reach = INSIDE_FRAC * batch.size_m.astype(np.float64)
    out: npt.NDArray[np.float64] = 1.0 - dist / reach
    if opacity:
        out *= batch.opacity.astype(np.float64)
    return out
