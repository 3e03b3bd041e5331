"""The per-frame near-sprite cap (farthest clouds out first, fading at the cut) and Wang's
10,000 ft rule (clouds far above or below the ring's centre are drawn directly, not in
impostors)."""

from __future__ import annotations

import numpy as np
from sprite_helpers import sprite_batch

from wxsky.scene.gather import NearRing, gather_near, zero_drift
from wxsky.scene.layout import SceneSettings, build_ring
from wxsky.scene.ring import in_impostors
from wxsky.scene.sky import sky_params
from wxsky.scene.sprite_budget import FADE_SHARE, cap_sprites
from wxsky.scene.sprites import SpriteBatch
from wxsky.weather.state import CloudLayer, CloudType, WeatherState


def _clouds(n_clouds: int, per_cloud: int) -> tuple[SpriteBatch, np.ndarray]:
    n = n_clouds * per_cloud
    cloud = np.repeat(np.arange(n_clouds), per_cloud)
    centre = np.column_stack([np.zeros(n), 1000.0 * (cloud + 1), np.zeros(n)])
    batch = sprite_batch(centre, 300.0, cloud_id=cloud.astype(np.int64) * 7919)
    return batch, np.ones((n, 4), np.float32)


def test_under_the_cap_nothing_changes() -> None:
    batch, rgba = _clouds(5, 10)
    out = cap_sprites(batch, rgba, (0.0, 0.0, 0.0), 50)
    assert out.dropped == 0 and out.sprites is batch and out.rgba is rgba


def test_over_the_cap_the_farthest_clouds_go_first_and_whole() -> None:
    batch, rgba = _clouds(20, 10)  # 200 sprites, clouds 1 km apart going away
    out = cap_sprites(batch, rgba, (0.0, 0.0, 0.0), 100)
    assert len(out.sprites) <= 100 and out.dropped == 200 - len(out.sprites)
    kept = np.unique(out.sprites.cloud_id) // 7919
    assert list(kept) == list(range(len(kept)))  # the nearest clouds, no gaps
    for c in kept:  # whole clouds
        assert np.count_nonzero(out.sprites.cloud_id == c * 7919) == 10
    alpha = np.array([out.rgba[out.sprites.cloud_id == c * 7919, 3][0] for c in kept])
    fading = round(FADE_SHARE * 100 / 10)
    assert np.all(alpha[: len(kept) - fading] == 1.0)
    assert np.all(np.diff(alpha) <= 0.0) and alpha[-1] < 1.0  # fading toward the cut
    assert np.array_equal(
        np.argsort(out.sprites.centre_m[:, 1], kind="stable"), np.arange(len(out.sprites))
    )


def test_ten_thousand_feet_rule() -> None:
    assert in_impostors(9000.0, 9800.0, 9000.0 - 3000.0)
    assert not in_impostors(9000.0, 9800.0, 9000.0 - 3100.0)
    assert not in_impostors(1000.0, 1500.0, 1500.0 + 3100.0)


def test_high_cirrus_is_drawn_directly_from_the_ground_not_in_impostors() -> None:
    state = WeatherState(
        layers=(
            CloudLayer(4.0, 1500.0, 2200.0, CloudType.CUMULUS),
            CloudLayer(5.0, 9000.0, 9800.0, CloudType.CIRRUS),
        ),
        wind=(),
    )
    drift = zero_drift(state)
    settings = SceneSettings(max_range_m=20_000.0)
    eye = (0.0, 0.0, 500.0)
    ring = build_ring(state, drift, eye, sky_params(state), settings)
    in_ring = np.concatenate([d.sprites.centre_m[:, 2] for d in ring.impostors if len(d)])
    assert in_ring.max() < 3000.0  # cumulus only
    near, _ = gather_near(state, drift, (NearRing(eye, drift, 1.0),), 8000.0, 20_000.0)
    flat = near.flat
    horizontal = np.hypot(near.centre_m[:, 0], near.centre_m[:, 1])
    assert flat.any() and horizontal[flat].max() > 12_000.0  # far cirrus, drawn directly
    assert horizontal[~flat].max() < 8000.0 + 6000.0  # cumulus near blocks only
