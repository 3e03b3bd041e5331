"""The weather at a point of the scene, as a host's flight model asks for it (CIGI's
Environmental Conditions Request): the air there from the applied weather, and whether the
point is inside one of the clouds the sky draws, from the very sprites of that cloud, placed
where the wind has drifted them, by the rule the frames use for the camera
(`in_cloud.sprite_depths`: within a sprite's reach and within its layer's base and top). So
the wind, the visibility and the cloud water a host's aircraft feels are the ones its pilot
sees, and a point above or below every layer is never in cloud; the visibility there takes the
fog the frames draw (`fog.py`). Pure.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from wxsky.scene.clouds import SpriteBatch, layer_keys
from wxsky.scene.fog import fog_field
from wxsky.scene.formation import layer_block
from wxsky.scene.gather import Drift, blocks_within
from wxsky.scene.in_cloud import OUTSIDE, in_cloud, layer_spans, sprite_depths
from wxsky.scene.sky import KOSCHMIEDER
from wxsky.weather.atmosphere import PointWeather, air_at
from wxsky.weather.state import CloudLayer, CloudType, WeatherState, dir_from_deg

# Liquid (or ice) water in the dense part of each kind of cloud, g/m³: typical figures of
# the cloud-physics literature (cumulus 0.3-1, cumulonimbus up to 2-3, stratiform 0.1-0.5,
# cirrus 0.01-0.1). The point's share of it follows its depth into the nearest sprite.
CLOUD_WATER_GPM3: Mapping[CloudType, float] = MappingProxyType(
    {
        CloudType.NONE: 0.0,
        CloudType.ALTOCUMULUS: 0.2,
        CloudType.ALTOSTRATUS: 0.2,
        CloudType.CIRROCUMULUS: 0.05,
        CloudType.CIRROSTRATUS: 0.02,
        CloudType.CIRRUS: 0.03,
        CloudType.CUMULONIMBUS: 1.5,
        CloudType.CUMULUS: 0.5,
        CloudType.NIMBOSTRATUS: 0.4,
        CloudType.STRATOCUMULUS: 0.3,
        CloudType.STRATUS: 0.25,
    }
)
# A sprite reaches at most this far from the block it belongs to (the largest cloud models'
# sprites are under 1.5 km across), so the blocks within it of the point hold every sprite
# the point can be in.
SPRITE_REACH_M = 1500.0
# Blocks kept at their height across frames for the answers (8-22 KiB each: 3 MiB at most): a
# host's aircraft read the same blocks frame after frame.
PLACED_BLOCKS_KEPT = 128
# Clear air is not saturated: the lapse rates alone would bring the dew point to the
# temperature a few kilometres up. Out of cloud and out of fog the humidity stays below this.
CLEAR_AIR_MAX_HUMIDITY_PCT = 95.0
FOG_VISIBILITY_M = 1000.0


Blocks = tuple[tuple[int, int], ...]


@dataclass
class BlockMemo:
    """What a batch of points has looked up (one state, one drift): each drifted block's
    sprites, and the sprites of each set of blocks a point reaches, by layer index."""

    blocks: dict[tuple[int, int, int], SpriteBatch] = field(default_factory=dict)
    reached: dict[tuple[int, Blocks], SpriteBatch] = field(default_factory=dict)


def conditions_many(
    state: WeatherState,
    drift: Drift,
    points_m: Sequence[tuple[float, float, float]],
    memo: BlockMemo | None = None,
) -> list[PointWeather]:
    """`conditions_at` for each point, the drifted blocks looked up once for the batch: a
    host's aircraft share their blocks, and the lookup is most of an answer's cost. `memo`:
    one to go on with, of the same state and drift."""
    memo = BlockMemo() if memo is None else memo
    return [conditions_at(state, drift, point, memo) for point in points_m]


def conditions_at(
    state: WeatherState,
    drift: Drift,
    point_m: tuple[float, float, float],
    memo: BlockMemo | None = None,
) -> PointWeather:
    """The weather at `point_m` (east, north, alt MSL in the scene frame) with the clouds
    of `state` drifted by `drift`. `memo`: drifted blocks already looked up for this state
    and drift (`conditions_many`), added to."""
    east, north, alt = point_m
    temperature, humidity, pressure = air_at(state, alt)
    keys = layer_keys(state.layers)
    spans = layer_spans(state.layers)
    water: list[float] = []
    deepest: tuple[float, SpriteBatch] | None = None
    for i, (layer, key) in enumerate(zip(state.layers, keys, strict=True)):
        dx, dy = drift[i] if i < len(drift) else (0.0, 0.0)
        # A layer's sprites have their centres within it: they count only while the point is
        # in a layer holding them, so in one overlapping this one (itself, mostly).
        if not any(
            base <= alt <= top and base <= layer.top_m and top >= layer.base_m
            for base, top in spans
        ):
            water.append(0.0)
            continue
        reached = tuple(blocks_within(east - dx, north - dy, 0.0, SPRITE_REACH_M))
        batch = memo.reached.get((i, reached)) if memo is not None else None
        if batch is None:
            batch = SpriteBatch.concat(
                [_block(memo, i, bx, by, key, layer, state.seed, (dx, dy)) for bx, by in reached]
            )
            if memo is not None:
                memo.reached[(i, reached)] = batch
        depth = float(sprite_depths(batch, point_m, spans).max()) if len(batch) else 0.0
        water.append(CLOUD_WATER_GPM3[layer.type] * min(1.0, max(0.0, depth)))
        if deepest is None or depth > deepest[0]:
            deepest = (depth, batch)
    # In cloud by the deepest sprite of any layer: the layer holding it decides.
    inside = (
        in_cloud(deepest[1], point_m, state.visibility_m, spans_m=spans)
        if deepest is not None
        else OUTSIDE
    )
    ve, vn = state.wind_at(alt)
    speed = float(np.hypot(ve, vn))
    direction = dir_from_deg(ve, vn) if speed > 0.0 else 0.0
    seen = inside.visibility_m if inside.visibility_m is not None else state.visibility_m
    # The fog the frames draw (scene/fog.py), added to what the air and cloud leave there.
    fog = fog_field(state)
    fog_ext = 0.0 if fog is None else float(fog.extinction_per_m(east, north, alt - fog.ground_m))
    if fog_ext > 0.0:
        seen = KOSCHMIEDER / (KOSCHMIEDER / max(seen, 1.0) + fog_ext)
    return PointWeather(
        temperature_c=temperature,
        humidity_pct=100.0
        if inside.inside or state.visibility_m < FOG_VISIBILITY_M or seen < FOG_VISIBILITY_M
        else min(humidity, CLEAR_AIR_MAX_HUMIDITY_PCT),
        visibility_m=seen,
        wind_speed_mps=speed,
        wind_dir_deg=direction,
        pressure_hpa=pressure,
        in_cloud=inside.inside,
        cloud_water_gpm3=tuple(water),
    )


def _block(
    memo: BlockMemo | None,
    i: int,
    bx: int,
    by: int,
    key: int,
    layer: CloudLayer,
    seed: int,
    drift_m: tuple[float, float],
) -> SpriteBatch:
    found = memo.blocks.get((i, bx, by)) if memo is not None else None
    if found is None:
        found = _drifted(_placed_block(bx, by, key, layer, seed), drift_m)
        if memo is not None:
            memo.blocks[(i, bx, by)] = found
    return found


@functools.lru_cache(maxsize=PLACED_BLOCKS_KEPT)
def _placed_block(bx: int, by: int, key: int, layer: CloudLayer, seed: int) -> SpriteBatch:
    """A block of a layer at its height, not drifted: the same from frame to frame while
    the layer stands (the drift moves every frame with the wind)."""
    return layer_block(bx, by, key, layer, seed)


def _drifted(batch: SpriteBatch, drift_m: tuple[float, float]) -> SpriteBatch:
    """`layer_block`'s drift added after its height: the same sums, adding 0.0 being exact
    (x + dx, y + dy, z + base either way)."""
    if not len(batch) or drift_m == (0.0, 0.0):
        return batch
    drift = np.empty((len(batch), 2), np.float32)
    drift[:] = drift_m
    return batch.with_centres(batch.centre_m + np.array((drift_m[0], drift_m[1], 0.0)), drift)
