"""The scene stage: weather state + camera -> the sprites and ring the renderer draws.

Blocks whose nearest point lies inside the ring radius (measured from the ring centre) are
"near" and drawn as sprites every frame from the host camera; the rest, out to the maximum
range, go into the impostor ring. Each layer drifts with the wind at its altitude: its blocks
live in a frame moved by the integrated wind, so the clouds travel but never change shape.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from wxsky.scene.camera import Camera
from wxsky.scene.clouds import BLOCK_SIZE_M, SpriteBatch, layer_keys
from wxsky.scene.formation import layer_block
from wxsky.scene.in_cloud import (
    NO_LOCKS,
    NO_VEIL,
    OUTSIDE,
    InCloud,
    Locks,
    in_cloud,
    in_cloud_fog,
    lock_facing,
)
from wxsky.scene.ring import RingGeometry, bin_far_sprites
from wxsky.scene.shading import DEFAULT_SHADING, ParticleLight, prepare_lighting, sprite_colours
from wxsky.scene.sky import SkyParams
from wxsky.weather.state import WeatherState

Drift = tuple[tuple[float, float], ...]  # per cloud layer: (east, north) offset in metres


@dataclass(frozen=True)
class SceneSettings:
    ring_radius_m: float = 8000.0
    max_range_m: float = 40000.0
    ring_texture_px: int = 256
    shading: str = DEFAULT_SHADING  # "wang" or "harris" (wxsky.scene.shading)


@dataclass(frozen=True)
class SpriteDraw:
    """Sprites ready to draw from one eye: sorted back to front, shaded."""

    sprites: SpriteBatch
    rgba: npt.NDArray[np.float32]  # (N, 4) straight alpha
    # (N, 3) unit normal of a quad with its own orientation (a flat cirrus sheet, a sprite
    # whose facing locked while the camera is inside it); a zero row, or None for all, faces
    # the camera.
    normals: npt.NDArray[np.float32] | None = None

    def __len__(self) -> int:
        return len(self.sprites)


@dataclass(frozen=True)
class RingScene:
    geometry: RingGeometry
    impostors: tuple[SpriteDraw, ...]  # (8,)
    drift: Drift  # the drift the ring was built with


@dataclass(frozen=True)
class FrameScene:
    camera: Camera
    sky: SkyParams
    near: SpriteDraw
    in_cloud: InCloud = OUTSIDE
    # in-cloud facing locks to carry into the next frame
    locks: Locks = field(default_factory=lambda: NO_LOCKS)
    # premultiplied RGBA of the in-cloud fog over everything behind the near sprites
    veil_rgba: tuple[float, float, float, float] = NO_VEIL


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
    out = []
    for (dx, dy), layer in zip(drift, state.layers, strict=True):
        ve, vn = state.wind_at(0.5 * (layer.base_m + layer.top_m))
        out.append((dx + ve * dt_s, dy + vn * dt_s))
    return tuple(out)


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
    if len(drift) != len(state.layers):
        drift = zero_drift(state)
    if select_drift is None or len(select_drift) != len(drift):
        select_drift = drift
    batches: list[SpriteBatch] = []
    for key, layer, (dx, dy), (sx, sy) in zip(
        layer_keys(state.layers), state.layers, drift, select_drift, strict=True
    ):
        if layer.cover_oktas <= 0.0:
            continue
        qx, qy = centre_m[0] - sx, centre_m[1] - sy
        bx0 = math.floor((qx - max_range_m) / BLOCK_SIZE_M)
        bx1 = math.floor((qx + max_range_m) / BLOCK_SIZE_M)
        by0 = math.floor((qy - max_range_m) / BLOCK_SIZE_M)
        by1 = math.floor((qy + max_range_m) / BLOCK_SIZE_M)
        for by in range(by0, by1 + 1):
            for bx in range(bx0, bx1 + 1):
                near_x = min(max(qx, bx * BLOCK_SIZE_M), (bx + 1) * BLOCK_SIZE_M)
                near_y = min(max(qy, by * BLOCK_SIZE_M), (by + 1) * BLOCK_SIZE_M)
                d = math.hypot(near_x - qx, near_y - qy)
                if min_range_m <= d < max_range_m:
                    # Cover only fades whole clouds in and out, so the cached generation
                    # of the block is reused while the weather forms or dissipates it.
                    block = layer_block(bx, by, key, layer, state.seed, (dx, dy))
                    if len(block):
                        batches.append(block)
    return SpriteBatch.concat(batches)


def sort_back_to_front(batch: SpriteBatch, eye_m: tuple[float, float, float]) -> SpriteBatch:
    d2 = np.sum((batch.centre_m - np.asarray(eye_m)) ** 2, axis=1)
    # Stable sort on distance so equal distances keep their generation order on every machine.
    return batch.take(np.argsort(-d2, kind="stable"))


def fade_by_range(
    rgba: npt.NDArray[np.float32],
    batch: SpriteBatch,
    eye_m: tuple[float, float, float],
    sky: SkyParams,
    max_range_m: float,
) -> npt.NDArray[np.float32]:
    """Aerial perspective: distant clouds take the horizon colour and fade out before the
    edge of the generated range, so the range limit never shows as a hard line."""
    dist = np.linalg.norm(batch.centre_m - np.asarray(eye_m), axis=1)
    haze = (1.0 - np.exp(-dist / sky.haze_m)).astype(np.float32)
    out = rgba.copy()
    out[:, :3] = rgba[:, :3] * (1.0 - haze[:, None]) + np.asarray(sky.horizon_rgb) * haze[:, None]
    edge = np.clip((max_range_m - dist) / (0.25 * max_range_m), 0.0, 1.0)
    out[:, 3] *= (edge * edge * (3.0 - 2.0 * edge)).astype(np.float32)
    return out


def shade_for_eye(
    batch: SpriteBatch,
    eye_m: tuple[float, float, float],
    sky: SkyParams,
    max_range_m: float,
    shading: str = DEFAULT_SHADING,
    light: ParticleLight | None = None,
) -> SpriteDraw:
    """`light`: a precompute (`prepare_lighting`) of a batch holding these sprites."""
    ordered = sort_back_to_front(batch, eye_m)
    rgba = sprite_colours(ordered, sky, eye_m, shading, light)
    return SpriteDraw(ordered, fade_by_range(rgba, ordered, eye_m, sky, max_range_m))


def oriented(
    draw: SpriteDraw, eye_m: tuple[float, float, float], locks: Locks = NO_LOCKS
) -> tuple[SpriteDraw, Locks]:
    """The draw with each sprite's normal: flat ones lie in their layer (normal up), sprites
    the eye is inside keep the facing they locked with, the rest face the camera."""
    sprites = draw.sprites
    flat = sprites.flat
    standing = sprites.take(~flat) if flat.any() else sprites
    lock_normals, kept = lock_facing(standing, eye_m, locks)
    if not flat.any() and lock_normals is None:
        return draw, kept
    normals = np.zeros((len(sprites), 3), np.float32)
    normals[flat] = (0.0, 0.0, 1.0)
    if lock_normals is not None:
        normals[~flat] = lock_normals
    return SpriteDraw(sprites, draw.rgba, normals), kept


def build_ring(
    state: WeatherState,
    drift: Drift,
    centre_m: tuple[float, float, float],
    sky: SkyParams,
    settings: SceneSettings,
) -> RingScene:
    far = gather_blocks(state, drift, centre_m, settings.ring_radius_m, settings.max_range_m)
    geometry, bins = bin_far_sprites(far, centre_m, settings.ring_radius_m)
    # Light the far clouds whole, before the bins cut those that straddle two impostors.
    light = prepare_lighting(far, sky, settings.shading)
    impostors = tuple(
        oriented(
            shade_for_eye(b, centre_m, sky, settings.max_range_m, settings.shading, light),
            centre_m,
        )[0]
        for b in bins
    )
    return RingScene(geometry=geometry, impostors=impostors, drift=drift)


def build_frame(
    state: WeatherState,
    drift: Drift,
    camera: Camera,
    ring_centre_m: tuple[float, float, float],
    sky: SkyParams,
    settings: SceneSettings,
    ring_drift: Drift | None = None,
    locks: Locks = NO_LOCKS,
) -> FrameScene:
    """The near sprites for the camera; `locks` are the previous frame's in-cloud locks."""
    near = gather_blocks(
        state, drift, ring_centre_m, 0.0, settings.ring_radius_m, select_drift=ring_drift
    )
    eye = camera.position_m
    shaded = shade_for_eye(near, eye, sky, settings.max_range_m, settings.shading)
    cloud = in_cloud(near, eye, state.visibility_m)
    fogged, veil = in_cloud_fog(shaded.sprites, shaded.rgba, eye, cloud)
    draw, kept = oriented(SpriteDraw(shaded.sprites, fogged), eye, locks)
    return FrameScene(
        camera=camera,
        sky=sky,
        near=draw,
        in_cloud=cloud,
        locks=kept,
        veil_rgba=veil,
    )
