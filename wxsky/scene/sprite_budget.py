"""A cap on the near sprites drawn per frame, so the frame budget holds in dense cover: past
it, whole clouds are left out farthest first, and the last ones kept fade out as they near the
cut, so a cloud leaving the budget fades rather than pops. Pure numpy."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wxsky.scene.sprites import F32, SpriteBatch

FADE_SHARE = 0.15  # the last share of the budget fades from full to nothing


@dataclass(frozen=True)
class Budgeted:
    sprites: SpriteBatch
    rgba: F32  # (N, 4) straight alpha
    dropped: int  # sprites left out


def cap_sprites(
    sprites: SpriteBatch, rgba: F32, eye_m: tuple[float, float, float], cap: int
) -> Budgeted:
    """At most `cap` sprites (0: no cap), whole clouds, nearest first (a cloud's distance is
    its nearest sprite's); the clouds filling the last FADE_SHARE of the budget fade with
    their place in it. The sprites keep their order."""
    n = len(sprites)
    if cap <= 0 or n <= cap:
        return Budgeted(sprites, rgba, 0)
    dist = np.linalg.norm(sprites.centre_m - np.asarray(eye_m, np.float64), axis=1)
    ids, inverse = np.unique(sprites.cloud_id, return_inverse=True)
    nearest = np.full(len(ids), np.inf)
    np.minimum.at(nearest, inverse, dist)
    by_distance = np.argsort(nearest, kind="stable")
    filled = np.cumsum(np.bincount(inverse, minlength=len(ids))[by_distance])  # (C,)
    share = np.empty(len(ids))
    # 1 up to the fade, falling to 0 where the budget runs out; clouds past it get 0.
    fade_from = (1.0 - FADE_SHARE) * cap
    share[by_distance] = np.clip((cap - filled) / max(cap - fade_from, 1.0), 0.0, 1.0)
    share[by_distance[filled <= fade_from]] = 1.0
    per_sprite = share[inverse]
    keep = per_sprite > 0.0
    out = rgba[keep].copy()
    out[:, 3] *= per_sprite[keep].astype(np.float32)
    return Budgeted(sprites.take(keep), out, int(n - keep.sum()))
