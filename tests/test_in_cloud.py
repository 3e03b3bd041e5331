"""In-cloud: facing locks keyed by sprite identity, and in-cloud visibility."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sprite_helpers import sprite_batch

from wxsky.scene.camera import Camera
from wxsky.scene.clouds import SpriteBatch
from wxsky.scene.gather import NearRing, zero_drift
from wxsky.scene.in_cloud import (
    LOCK_FRAC,
    NO_LOCKS,
    NO_VEIL,
    VISIBILITY_CORE_M,
    Locks,
    in_cloud,
    in_cloud_fog,
    lock_facing,
)
from wxsky.scene.layout import FrameScene, SceneSettings, SpriteDraw, build_frame, oriented
from wxsky.scene.sky import sky_params
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

# Sprites of no particular layer: every height is inside one.
EVERYWHERE = ((-math.inf, math.inf),)


def batch(centres: list[tuple[float, float, float]], size_m: float = 400.0) -> SpriteBatch:
    n = len(centres)
    rotation = np.linspace(0.1, 1.0, n)
    return sprite_batch(centres, size_m, texture=0, rotation=rotation, cloud_id=np.arange(n) + 7)


def test_far_from_every_sprite_nothing_locks() -> None:
    normals, locks = lock_facing(batch([(0, 1000, 0), (0, 2000, 0)]), (0.0, 0.0, 0.0), NO_LOCKS)
    assert normals is None and not locks


def test_a_sprite_locks_within_half_its_radius_to_its_current_facing() -> None:
    b = batch([(0, 1000, 0), (0, 50, 0)])  # the second is 50 m away: inside 0.25 * 400
    normals, locks = lock_facing(b, (0.0, 0.0, 0.0), NO_LOCKS)
    assert normals is not None
    assert np.allclose(normals[0], 0.0)
    assert np.allclose(normals[1], (0.0, -1.0, 0.0))  # from the sprite toward the eye
    assert len(locks) == 1


def test_a_lock_holds_while_the_camera_flies_through_and_ignores_reordering() -> None:
    b = batch([(0, 1000, 0), (0, 50, 0)])
    _, locks = lock_facing(b, (0.0, 0.0, 0.0), NO_LOCKS)
    # The camera has passed the centre; the batch is sorted the other way round.
    moved = b.take(np.array([1, 0]))
    normals, locks2 = lock_facing(moved, (0.0, 120.0, 0.0), locks)
    assert normals is not None
    assert np.allclose(normals[0], (0.0, -1.0, 0.0))  # still the facing it locked with
    assert locks2 == locks
    # Out of the sprite's radius the lock is released.
    normals, locks3 = lock_facing(moved, (0.0, 300.0, 0.0), locks2)
    assert normals is None and not locks3


def test_entering_the_unlock_zone_from_outside_does_not_lock_yet() -> None:
    b = batch([(0, 150, 0)])  # 150 m: inside the radius (200) but not half of it (100)
    normals, locks = lock_facing(b, (0.0, 0.0, 0.0), NO_LOCKS)
    assert normals is None and not locks
    assert LOCK_FRAC * 400.0 < 150.0


def test_the_frames_lock_shortcut_agrees_with_lock_facing_between_the_two_radii() -> None:
    # 150 m from a 400 m sprite: beyond where a lock is taken (100 m), within where a held
    # one is kept (200 m). `oriented` skips lock_facing when nothing can lock: it must still
    # keep a lock held, and take none anew.
    b = batch([(0, 1000, 0), (0, 150, 0)])
    draw = SpriteDraw(b, np.ones((2, 4), np.float32))
    eye = (0.0, 0.0, 0.0)
    dist = np.linalg.norm(b.centre_m, axis=1)
    fresh, none_held = oriented(draw, eye, NO_LOCKS, dist)
    assert fresh.normals is None and not none_held
    assert lock_facing(b, eye, NO_LOCKS) == (None, NO_LOCKS)
    _, held = lock_facing(b, (0.0, 120.0, 0.0), NO_LOCKS)  # 30 m from it: locks
    assert len(held) == 1
    kept, still = oriented(draw, eye, held, dist)
    assert still == held
    assert kept.normals is not None
    assert np.allclose(kept.normals[1], (0.0, -1.0, 0.0)) and np.allclose(kept.normals[0], 0.0)


def test_in_cloud_visibility_falls_toward_the_core() -> None:
    b = batch([(0, 0, 0)])
    assert not in_cloud(b, (0.0, 500.0, 0.0), 10_000.0, spans_m=EVERYWHERE).inside
    edge = in_cloud(b, (0.0, 120.0, 0.0), 10_000.0, spans_m=EVERYWHERE)
    core = in_cloud(b, (0.0, 0.0, 0.0), 10_000.0, spans_m=EVERYWHERE)
    assert edge.inside and core.inside
    assert core.visibility_m == pytest.approx(VISIBILITY_CORE_M)
    assert edge.visibility_m is not None and edge.visibility_m > core.visibility_m
    fog = in_cloud(b, (0.0, 0.0, 0.0), 25.0, spans_m=EVERYWHERE)
    assert fog.visibility_m == 25.0  # fog is worse still
    assert core.to_dict() == {"in_cloud": True, "in_cloud_visibility_m": VISIBILITY_CORE_M}


def test_empty_batch_is_outside() -> None:
    empty = SpriteBatch.empty()
    assert not in_cloud(empty, (0.0, 0.0, 0.0), 1000.0, spans_m=EVERYWHERE).inside
    assert lock_facing(empty, (0.0, 0.0, 0.0), NO_LOCKS) == (None, NO_LOCKS)


# -- through the layout stage ---------------------------------------------------------


def _frame(eye: tuple[float, float, float], locks: Locks = NO_LOCKS) -> FrameScene:
    state = WeatherState(layers=(CloudLayer(8.0, 1000.0, 1600.0, CloudType.STRATUS),), wind=())
    camera = Camera(position_m=eye)
    # The ring centre stays put, as it does between ring rebuilds.
    return build_frame(
        state,
        zero_drift(state),
        camera,
        (NearRing((0.0, 0.0, 1300.0), zero_drift(state), 1.0),),
        sky_params(state),
        SceneSettings(),
        locks=locks,
    )


def test_a_camera_inside_a_deck_is_in_cloud_and_locks_sprites() -> None:
    # Fly to 20 m from one sprite's centre, well inside half its radius.
    first = _frame((0.0, 0.0, 1300.0))
    assert first.in_cloud.inside
    target = first.near.sprites.centre_m[len(first.near) // 2]
    eye = (float(target[0]), float(target[1]) + 20.0, float(target[2]))
    inside = _frame(eye)
    assert inside.in_cloud.inside
    assert inside.in_cloud.visibility_m is not None and inside.in_cloud.visibility_m < 600.0
    assert inside.locks
    assert inside.near.normals is not None
    locked = np.linalg.norm(inside.near.normals, axis=1) > 0.5
    assert 0 < int(locked.sum()) < len(inside.near)
    # The next frame, a little farther on, keeps the same sprites locked.
    later = _frame((eye[0], eye[1] + 30.0, eye[2]), inside.locks)
    assert set(inside.locks) <= set(later.locks)
    below = _frame((0.0, 0.0, 200.0))
    assert not below.in_cloud.inside and not below.locks


def test_flat_cirrus_lies_in_its_layer() -> None:
    state = WeatherState(layers=(CloudLayer(6.0, 9000.0, 9800.0, CloudType.CIRRUS),), wind=())
    eye = (0.0, 0.0, 500.0)
    rings = (NearRing(eye, zero_drift(state), 1.0),)
    frame = build_frame(
        state, zero_drift(state), Camera(position_m=eye), rings, sky_params(state), SceneSettings()
    )
    assert len(frame.near) > 0 and frame.near.sprites.flat.all()
    assert frame.near.normals is not None
    assert np.allclose(frame.near.normals, (0.0, 0.0, 1.0))


# -- the fog on our own layers ------------------------------------------------------------


def _fog_case(eye_y: float) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    # The eye on the axis of a 400 m sprite at y = 0, a second sprite 1.5 km on.
    b = batch([(0, 0, 0), (0, 1500, 0)])
    rgba = np.array([[0.3, 0.4, 0.5, 1.0], [0.9, 0.9, 0.9, 1.0]], np.float32)
    eye = (0.0, eye_y, 0.0)
    return in_cloud_fog(b, rgba, eye, in_cloud(b, eye, 9999.0, spans_m=EVERYWHERE))


def test_outside_a_cloud_nothing_is_fogged() -> None:
    b = batch([(0, 1000, 0)])
    rgba = np.full((1, 4), 0.5, np.float32)
    eye = (0.0, 0.0, 0.0)
    out, veil = in_cloud_fog(b, rgba, eye, in_cloud(b, eye, 9999.0, spans_m=EVERYWHERE))
    assert veil == NO_VEIL and out is rgba


def test_the_fog_thickens_smoothly_from_the_edge_to_the_core() -> None:
    # Inside reach 0.35 * 400 = 140 m; from the edge inward the veil rises without a jump.
    alphas = [_fog_case(float(y))[1][3] for y in np.arange(139.0, -1.0, -1.0)]
    assert alphas[0] < 0.01
    assert alphas == sorted(alphas) and alphas[-1] == 1.0
    assert max(np.diff(alphas)) < 0.05  # a metre further in never changes it by much


def test_the_fog_is_the_colour_of_the_cloud_the_eye_is_in() -> None:
    out, veil = _fog_case(0.0)
    np.testing.assert_allclose(veil, (0.3, 0.4, 0.5, 1.0), atol=1e-6)
    # The far sprite, 1.5 km off at 40 m visibility, is all fog; the alpha is untouched.
    np.testing.assert_allclose(out[1, :3], (0.3, 0.4, 0.5), atol=1e-4)
    assert out[1, 3] == 1.0
    # Halfway in, a sprite is fogged by its distance: the far one more than the near one.
    out, veil = _fog_case(80.0)
    assert 0.0 < veil[3] < 1.0
    near_shift = np.abs(out[0, :3] - [0.3, 0.4, 0.5]).max()
    far_shift = np.abs(out[1, :3] - [0.9, 0.9, 0.9]).max()
    assert near_shift < 1e-6 and far_shift > 0.3  # the eye's own sprite is the fog colour
