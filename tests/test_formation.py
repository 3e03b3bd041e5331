"""Formation and dissipation by cover (Wang: the core first, the edges last; dissipation the
reverse), and clouds that keep their identity while the wind carries them."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from wxsky.scene.cloud_model_files import default_models
from wxsky.scene.cloud_models import CloudModel
from wxsky.scene.clouds import BLOCK_CACHE, BLOCK_SIZE_M, BlockClouds, block_clouds
from wxsky.scene.formation import cloud_progress, layer_block, sprite_alpha, visible_sprites
from wxsky.scene.gather import advance_drift, gather_blocks, zero_drift
from wxsky.scene.layout import fade_by_range
from wxsky.scene.sky import sky_params
from wxsky.scene.sprites import SpriteBatch
from wxsky.weather.state import CloudLayer, CloudType, WeatherState, WindLayer

ALL_MODELS = [m for models in default_models().by_type.values() for m in models]
COVERS = np.round(np.arange(0.0, 8.0001, 0.05), 4)


def _thickness(model: CloudModel) -> float:
    return max(model.min_thickness_m, 1000.0) * 1.2


def _block(model: CloudModel, bx: int = 3, by: int = -1, seed: int = 21) -> BlockClouds:
    return block_clouds(bx, by, 0, model, _thickness(model), seed)


def _alphas(block: BlockClouds, cover: float) -> np.ndarray:
    """(N,) every sprite's share of its opacity at this cover, hidden ones included."""
    return sprite_alpha(cloud_progress(block, cover), block.sprites.core_frac)


@pytest.mark.parametrize("model", ALL_MODELS, ids=lambda m: m.name)
def test_visible_opacity_rises_monotonically_with_cover(model: CloudModel) -> None:
    block = _block(model)
    totals = [float(visible_sprites(block, c).opacity.sum()) for c in COVERS]
    counts = [len(visible_sprites(block, c)) for c in COVERS]
    assert totals[0] == 0.0 and counts[0] == 0
    assert totals[-1] == pytest.approx(float(block.sprites.opacity.sum()), rel=1e-5)
    assert all(b >= a - 1e-4 for a, b in itertools.pairwise(totals)), totals
    assert all(b >= a for a, b in itertools.pairwise(counts))
    # Each sprite on its own, too: formation never takes back what it showed.
    alphas = np.stack([_alphas(block, c) for c in COVERS])  # (covers, N)
    assert np.all(np.diff(alphas, axis=0) >= -1e-6)


@pytest.mark.parametrize("model", ALL_MODELS, ids=lambda m: m.name)
def test_core_forms_first_and_dissipates_last_in_every_cloud(model: CloudModel) -> None:
    block = _block(model)
    core = block.sprites.core_frac < 0.5
    clouds = [block.sprites.cloud_id == cid for cid in np.unique(block.sprites.cloud_id)]
    shown_partly = 0
    for cover in COVERS:
        alpha = _alphas(block, cover)
        for one in clouds:
            c, e = alpha[one & core], alpha[one & ~core]
            if len(c) and len(e):
                assert c.mean() >= e.mean() - 1e-6, (cover, c.mean(), e.mean())
            # Wang: outer sprites start only once the core has reached its opacity, and on
            # the way back they are gone before the core starts to fade.
            if len(e) and e.max() > 0.0:
                assert np.all(c >= 1.0 - 1e-6), cover
            shown_partly += int(0.0 < alpha[one].mean() < 1.0)
    assert shown_partly > 0


@pytest.mark.parametrize("model", ALL_MODELS[:4], ids=lambda m: m.name)
def test_dissipation_is_formation_played_backwards(model: CloudModel) -> None:
    block = _block(model, seed=8)
    rising = [_alphas(block, c) for c in COVERS]
    falling = [_alphas(block, c) for c in COVERS[::-1]]
    for a, b in zip(rising, falling[::-1], strict=True):
        np.testing.assert_array_equal(a, b)
    totals = [a.sum() for a in falling]
    assert all(b <= a + 1e-4 for a, b in itertools.pairwise(totals))


def test_hidden_sprites_are_dropped_and_full_cover_is_the_cached_batch() -> None:
    model = default_models().for_layer(CloudType.CUMULUS, 1200.0)
    block = _block(model)
    for cover in (0.5, 2.0, 3.3, 6.9):
        shown = visible_sprites(block, cover)
        assert np.all(shown.opacity > 0.0)
        assert len(shown) == int(np.count_nonzero(_alphas(block, cover)))
    assert len(visible_sprites(block, 0.0)) == 0
    assert visible_sprites(block, 8.0) is block.sprites


@pytest.mark.parametrize(
    ("kind", "thickness_m", "tolerance"),
    [
        (CloudType.CUMULUS, 800.0, 0.02),
        (CloudType.STRATUS, 500.0, 0.02),
        (CloudType.CUMULONIMBUS, 9000.0, 0.06),
    ],
)
def test_formed_share_of_the_clouds_follows_the_cover(
    kind: CloudType, thickness_m: float, tolerance: float
) -> None:
    """Over many blocks the clouds' mean formation is cover / 8, even for one storm per
    block: the block's own offset decides which blocks hold one."""
    model = default_models().for_layer(kind, thickness_m)
    blocks = [
        block_clouds(bx, by, 0, model, thickness_m, 4) for bx in range(20) for by in range(20)
    ]
    for cover in (2.0, 4.0, 6.0):
        share = []
        for block in blocks:
            first = np.unique(block.cloud_rank, return_index=True)[1]
            share.append(cloud_progress(block, cover)[first].sum() / block.n_clouds)
        assert np.mean(share) == pytest.approx(cover / 8.0, abs=tolerance)


def test_a_cover_change_forms_whole_clouds_a_few_at_a_time() -> None:
    model = default_models().for_layer(CloudType.CUMULUS, 800.0)
    block = _block(model)
    first = np.unique(block.cloud_rank, return_index=True)[1]
    limit = int(np.ceil(model.formation_spread_oktas / 8.0 * block.n_clouds)) + 1
    for cover in COVERS:
        progress = cloud_progress(block, cover)[first]
        assert np.count_nonzero((progress > 0.0) & (progress < 1.0)) <= limit
        # Clouds form in the block's order: an earlier one is never less formed.
        by_rank = progress[np.argsort(block.cloud_rank[first])]
        assert np.all(np.diff(by_rank) <= 1e-6)


def test_layers_at_any_cover_share_one_generation_through_gather_blocks() -> None:
    BLOCK_CACHE.clear()
    layer = CloudLayer(3.0, 1930.0, 2700.0, CloudType.CUMULUS)
    state = WeatherState(layers=(layer,), seed=7)
    gather_blocks(state, zero_drift(state), (0.0, 0.0, 500.0), 0.0, 12_000.0)
    generated = BLOCK_CACHE.info().misses
    for cover in (3.2, 3.4, 5.0, 7.5):
        moved = dataclasses.replace(layer, cover_oktas=cover)
        later = dataclasses.replace(state, layers=(moved,))
        gather_blocks(later, zero_drift(later), (0.0, 0.0, 500.0), 0.0, 12_000.0)
    assert BLOCK_CACHE.info().misses == generated


# -- wind drift --------------------------------------------------------------------------

DRIFT_STATE = WeatherState(
    layers=(CloudLayer(4.0, 1560.0, 3200.0, CloudType.CUMULUS),),
    wind=(WindLayer(442.0, 250.0, 6.0), WindLayer(3000.0, 270.0, 14.0)),
    seed=11,
)


def test_a_cloud_keeps_its_identity_and_shape_as_it_drifts() -> None:
    state = DRIFT_STATE
    centre = (0.0, 0.0, 500.0)
    before = gather_blocks(state, zero_drift(state), centre, 0.0, 20_000.0)
    drift = advance_drift(state, zero_drift(state), 900.0)  # 15 minutes
    ((dx, dy),) = drift
    assert np.hypot(dx, dy) > 5000.0
    after = gather_blocks(state, drift, centre, 0.0, 20_000.0)
    common = np.intersect1d(before.cloud_id, after.cloud_id)
    assert len(common) > 20
    for cid in common:
        a = before.take(before.cloud_id == cid)
        b = after.take(after.cloud_id == cid)
        np.testing.assert_allclose(b.centre_m - a.centre_m, np.tile([dx, dy, 0.0], (len(a), 1)))
        for name in ("size_m", "texture", "rotation_rad", "opacity", "core_frac", "flat"):
            np.testing.assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)


def test_blocks_entering_the_field_fade_in_instead_of_popping() -> None:
    state = DRIFT_STATE
    sky = sky_params(state)
    centre = (0.0, 0.0, 500.0)
    max_range_m = 40_000.0
    drift = zero_drift(state)
    previous: np.ndarray | None = None
    entered = 0
    for _ in range(60):  # 20 s steps (about 280 m) for 20 minutes: blocks cross the edge
        drift = advance_drift(state, drift, 20.0)
        # The whole field, near and far: a block crossing the ring radius only changes hands.
        field = gather_blocks(state, drift, centre, 0.0, max_range_m)
        rgba = np.ones((len(field), 4), np.float32)
        alpha = fade_by_range(rgba, field, centre, sky, max_range_m)[:, 3]
        # A sprite's identity: its cloud and its place in the layer's own (drifting) frame.
        ((dx, dy),) = drift
        keys = np.stack(
            [
                field.cloud_id,
                np.round((field.centre_m[:, 0] - dx) * 1000.0).astype(np.int64),
                np.round((field.centre_m[:, 1] - dy) * 1000.0).astype(np.int64),
            ],
            axis=1,
        )
        keys = np.ascontiguousarray(keys).view(np.dtype((np.void, 24))).ravel()
        if previous is not None:
            new = ~np.isin(keys, previous)
            entered += int(new.sum())
            # A cloud reaches a cloud radius past its block: that much inside the range, the
            # fade still leaves it nearly transparent.
            assert np.all(alpha[new] < 0.05), alpha[new].max()
        previous = keys
    assert entered > 100
    assert float(np.hypot(*drift[0])) > BLOCK_SIZE_M


def test_a_drifting_block_is_the_same_block_moved() -> None:
    layer = DRIFT_STATE.layers[0]
    here = layer_block(1, 2, 0, layer, 11)
    there = layer_block(1, 2, 0, layer, 11, offset_m=(1234.5, -987.25))
    np.testing.assert_array_equal(there.centre_m, here.centre_m + np.array([1234.5, -987.25, 0.0]))
    np.testing.assert_array_equal(there.cloud_id, here.cloud_id)


# -- cumulus subtypes ----------------------------------------------------------------------


def test_a_layer_deepening_through_a_subtype_boundary_cross_fades() -> None:
    """Humilis gives way to mediocris at 1000 m: across the band around it the humilis
    clouds dissipate while the mediocris ones form, with no jump in the sky's opacity."""
    models = default_models()
    humilis, mediocris = (models.for_layer(CloudType.CUMULUS, t) for t in (800.0, 1200.0))
    totals, mixes = [], []
    for thickness in np.arange(850.0, 1150.0, 2.0):
        layer = CloudLayer(4.0, 1500.0, 1500.0 + float(thickness), CloudType.CUMULUS)
        blend = models.blend_for_layer(layer.type, layer.thickness_m)
        assert sum(w for _, w in blend) == pytest.approx(1.0)
        sprites = SpriteBatch.concat([layer_block(bx, 0, 0, layer, 3) for bx in range(-2, 3)])
        totals.append(float(sprites.opacity.sum()))
        mixes.append({m.name: w for m, w in blend})
    assert mixes[0] == {humilis.name: 1.0} and mixes[-1] == {mediocris.name: 1.0}
    assert 0.4 < mixes[len(mixes) // 2][humilis.name] < 0.6
    steps = np.abs(np.diff(totals)) / np.mean(totals)
    assert steps.max() < 0.03, steps.max()
