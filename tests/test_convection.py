"""Convective cells from the weather (wxsky/scene/convection.py): which layers make towers,
how the weather sets their automata's odds and growth, where they stand, and the budget."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wxsky.scene.clouds import layer_keys
from wxsky.scene.convection import (
    BIRTH_SPAN,
    MATURE_S,
    instability,
    is_convective,
    nearest_towers,
    tower_specs,
)
from wxsky.scene.footprints import footprints
from wxsky.scene.formation import layer_block
from wxsky.settings.presets import load_preset
from wxsky.towers.volume import TowerVolume
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

TCU = WeatherState().apply(load_preset("towering-cumulus"))
LAYER = TCU.layers[0]


def _block(state: WeatherState, layer: CloudLayer, block: tuple[int, int] = (2, -1)):  # type: ignore[no-untyped-def]
    return layer_block(*block, layer_keys((layer,))[0], layer, state.seed)


def test_which_layers_are_convective() -> None:
    assert is_convective(LAYER)  # 4,000 m of cumulus: congestus
    assert is_convective(CloudLayer(2.0, 1500.0, 11_500.0, CloudType.CUMULONIMBUS))
    assert not is_convective(CloudLayer(4.0, 1500.0, 2500.0, CloudType.CUMULUS))  # mediocris
    assert not is_convective(CloudLayer(8.0, 800.0, 5000.0, CloudType.STRATUS))
    assert tower_specs(TCU, CloudLayer(4.0, 1500.0, 2500.0, CloudType.CUMULUS), (0, 0),
                       _block(TCU, LAYER), 50.0) == ()  # fmt: skip


def test_a_tower_for_every_cloud_of_the_block_at_its_base() -> None:
    clouds = _block(TCU, LAYER)
    specs = tower_specs(TCU, LAYER, (2, -1), clouds, 55.0)
    feet = footprints(clouds)
    assert len(specs) == len(feet.ids) > 0
    for cell, spec in enumerate(specs):
        assert spec.cell == cell and spec.block == (2, -1) and spec.weather_seed == TCU.seed
        assert spec.axis_m == pytest.approx(tuple(feet.axis_m[cell]))
        assert spec.base_m == LAYER.base_m and spec.height_m == LAYER.thickness_m
        assert spec.width_m == pytest.approx(2.0 * feet.radius_m[cell]) and spec.width_m > 500.0
        lo, hi = (b * MATURE_S[CloudType.CUMULUS] for b in BIRTH_SPAN)
        assert lo <= spec.born_s <= hi
    # The same block gives the same towers; another block other births.
    assert tower_specs(TCU, LAYER, (2, -1), clouds, 55.0) == specs
    other = tower_specs(TCU, LAYER, (3, -1), _block(TCU, LAYER, (3, -1)), 55.0)
    assert [s.born_s for s in other] != [s.born_s for s in specs]


def test_moist_deep_afternoon_air_grows_towers_readily() -> None:
    clouds = _block(TCU, LAYER)
    moist = tower_specs(TCU, LAYER, (2, -1), clouds, 55.0)[0]
    dry_state = dataclasses.replace(TCU, temperature_c=30.0, dewpoint_c=14.0)
    dry = tower_specs(dry_state, LAYER, (2, -1), clouds, 55.0)[0]
    morning = tower_specs(TCU, LAYER, (2, -1), clouds, 10.0)[0]
    shallow = dataclasses.replace(LAYER, top_m=LAYER.base_m + 2600.0)
    low = tower_specs(TCU, shallow, (2, -1), _block(TCU, shallow), 55.0)[0]
    assert moist.p_hum > dry.p_hum and moist.p_act == dry.p_act
    assert moist.p_act > morning.p_act and moist.p_hum == morning.p_hum
    assert moist.p_act > low.p_act
    unknown = dataclasses.replace(TCU, temperature_c=None, dewpoint_c=None)
    assert 0.0 < instability(unknown, LAYER, 55.0).moisture < 1.0
    cb = CloudLayer(8.0, 1500.0, 11_500.0, CloudType.CUMULONIMBUS)  # a storm in every block
    storm = tower_specs(TCU, cb, (2, -1), _block(TCU, cb), 55.0)[0]
    assert storm.mature_s < moist.mature_s  # a cumulonimbus builds faster
    # And the odds do grow a volume: more cloud at maturity than half way there.
    tower = TowerVolume(dataclasses.replace(moist, grid=64))
    assert (
        np.count_nonzero(tower.density_at(moist.mature_s) > 0.5)
        > np.count_nonzero(tower.density_at(0.5 * moist.mature_s) > 0.5)
        > 0
    )


def test_the_budget_keeps_the_nearest_towers() -> None:
    specs = tower_specs(TCU, LAYER, (2, -1), _block(TCU, LAYER), 55.0)
    far_eye = (specs[0].axis_m[0], specs[0].axis_m[1], LAYER.base_m)
    chosen, left = nearest_towers(specs, far_eye, 1)
    assert chosen == (specs[0],) and left == len(specs) - 1
    everything, none_left = nearest_towers(specs, far_eye, 100)
    assert set(everything) == set(specs) and none_left == 0
    assert nearest_towers(specs, far_eye, 0) == ((), len(specs))
