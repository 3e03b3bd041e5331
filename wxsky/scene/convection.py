"""Which clouds are convective towers, and the odds their automata run with (issue 17, item 2;
docs/towers.md).

A cumulus layer deep enough to be cumulus congestus (the cloud models' own subtype boundary)
and a cumulonimbus layer make convective cells: every cloud of such a layer in a block is one,
at its base's axis, as wide as its base and as tall as the layer. How readily the automaton
grows comes from the weather:

- moisture, from the temperature-dewpoint spread (a spread of 0 is saturated air; 15 °C and
  more is dry; unknown counts as half way): Dobashi's vapour supply p_hum;
- depth, the layer's thickness against a tower reaching 10 km: the trigger supply p_act (a
  deep unstable layer lets parcels rise);
- heating, the sun's elevation (convection is an afternoon thing): p_act again, halved at
  night, full with the sun 50 degrees up.

A cumulonimbus matures in 20 minutes, cumulus congestus in 30 (the issue's "growing toward Cb
within about 30 minutes"). Each cell is born at a seeded moment between 60 % of its maturing
time before the weather was set and 20 % after it, so a field of towers holds every stage.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wxsky.scene.footprints import footprints
from wxsky.scene.sprites import SpriteBatch
from wxsky.towers.automaton import cell_rng
from wxsky.towers.volume import TowerSpec
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

CONGESTUS_MIN_M = 2500.0  # cumulus this deep is congestus (scene/clouds/cumulus-congestus.toml)
MATURE_S = {CloudType.CUMULONIMBUS: 1200.0, CloudType.CUMULUS: 1800.0}
DRY_SPREAD_C = 15.0  # a temperature-dewpoint spread this wide supplies the least vapour
FULL_TOWER_M = 10_000.0
P_HUM = (0.04, 0.16)  # vapour supply, dry .. saturated
P_ACT = (0.004, 0.02)  # trigger supply, shallow .. full-depth
BIRTH_SPAN = (-0.6, 0.2)  # birth, as a share of the maturing time around the weather's moment
_BIRTH_STREAM = 2  # the cell's stream for its birth (0: the automaton, 1: its shape)


@dataclass(frozen=True)
class Instability:
    """What drives a layer's convection, each 0..1."""

    moisture: float
    depth: float
    heating: float


def is_convective(layer: CloudLayer) -> bool:
    return layer.type == CloudType.CUMULONIMBUS or (
        layer.type == CloudType.CUMULUS and layer.thickness_m >= CONGESTUS_MIN_M
    )


def instability(state: WeatherState, layer: CloudLayer, sun_elevation_deg: float) -> Instability:
    if state.temperature_c is None or state.dewpoint_c is None:
        spread = 0.5 * DRY_SPREAD_C  # unknown: middling
    else:
        spread = max(0.0, state.temperature_c - state.dewpoint_c)
    return Instability(
        moisture=min(1.0, max(0.0, 1.0 - spread / DRY_SPREAD_C)),
        depth=min(1.0, max(0.0, layer.thickness_m / FULL_TOWER_M)),
        heating=min(1.0, max(0.0, sun_elevation_deg / 50.0)),
    )


def tower_specs(
    state: WeatherState,
    layer: CloudLayer,
    block: tuple[int, int],
    clouds: SpriteBatch,
    sun_elevation_deg: float,
) -> tuple[TowerSpec, ...]:
    """A tower for every cloud of `clouds` (one block of `layer` as drawn, z MSL, x and y in
    the layer's drifting frame), or none when the layer is not convective."""
    if not is_convective(layer) or not len(clouds):
        return ()
    weather = instability(state, layer, sun_elevation_deg)
    p_hum = P_HUM[0] + (P_HUM[1] - P_HUM[0]) * weather.moisture
    p_act = (P_ACT[0] + (P_ACT[1] - P_ACT[0]) * weather.depth) * (0.5 + 0.5 * weather.heating)
    mature_s = MATURE_S[layer.type]
    feet = footprints(clouds)
    out = []
    for cell in range(len(feet.ids)):
        birth = cell_rng(state.seed, block, cell, _BIRTH_STREAM).uniform(*BIRTH_SPAN)
        out.append(
            TowerSpec(
                weather_seed=state.seed,
                block=block,
                cell=cell,
                axis_m=(float(feet.axis_m[cell, 0]), float(feet.axis_m[cell, 1])),
                base_m=layer.base_m,
                width_m=2.0 * float(feet.radius_m[cell]),
                height_m=layer.thickness_m,
                born_s=float(birth) * mature_s,
                mature_s=mature_s,
                p_hum=p_hum,
                p_act=p_act,
                anvil=layer.type == CloudType.CUMULONIMBUS,
            )
        )
    return tuple(out)


def nearest_towers(
    specs: tuple[TowerSpec, ...], eye_m: tuple[float, float, float], budget: int
) -> tuple[tuple[TowerSpec, ...], int]:
    """The `budget` towers nearest the eye (their base's middle), nearest first, and how many
    were left out: those stay sprite clouds. Ties keep the specs' order."""
    if budget <= 0:
        return (), len(specs)
    dist = [math.dist((s.axis_m[0], s.axis_m[1], s.base_m), eye_m) for s in specs]
    order = np.argsort(np.asarray(dist), kind="stable")[:budget]
    return tuple(specs[i] for i in order), max(0, len(specs) - budget)
