"""The near layer's per-set work: what a frame needs of a set of near blocks besides its
sprites, made once per set and kept with it.

A set of near blocks (`gather.NearBlocks`) stays the same from one ring rebuild, weather step
or site to the next; what depends on the set alone is worked out once and kept: Harris's
light on its particles (here) and its convective cells (`tower_field.candidates`). A frame
either makes what is missing at once (a snapshot, `wxsky bench`, the tests) or, in the daemon,
only looks it up and has it made off the frame path
(`engine.near_work.NearWork`), showing the last set it had meanwhile.
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Hashable
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt

from wxsky.scene.clouds import SpriteBatch
from wxsky.scene.gather import (
    Drift,
    NearBlocks,
    NearRing,
    install_near_blocks,
    near_blocks_keyed,
)
from wxsky.scene.shading import Scattered
from wxsky.scene.shading_harris import close_directions, scattered_light, scene_lights
from wxsky.scene.sky import SkyParams
from wxsky.scene.tower_field import (
    Candidate,
    LayerEpoch,
    candidates,
    candidates_key,
    install_candidates,
)
from wxsky.weather.state import WeatherState

if TYPE_CHECKING:
    from wxsky.scene.layout import RingScene, SceneSettings


@dataclass(frozen=True)
class NearInputs:
    """A frame's near layer as gathered: the set's sprites placed for the frame's drift, each
    one's share of the picture (`gather_near`), the set they come from (None where gathered
    anew), Harris's light on them (None: not Harris, or only slabs) and the set's convective
    cells (None: not looked for)."""

    near: SpriteBatch
    share: npt.NDArray[np.float32]
    blocks: NearBlocks | None
    scattered: Scattered | None
    found: tuple[Candidate, ...] | None


# Harris's light on the near layer's particles, per set of near blocks: it depends on the
# sprites and the light directions only (rounded so that the sun moves them every half
# minute or so), and the near layer's sprites are one set from one ring rebuild to the next.
# Working it out every frame (identifying every sprite, hashing the batch, looking the light
# up, scattering it) was a third of the scene stage.
# With each light, the same rows under the directions of the last lights (an array a sky
# step's frames share) it was found close enough to, and how close was asked: the frames of
# that step take it at once, and their shading sees by identity that it is for their lights.
# A light just made is under its own directions, found for them exactly (0 degrees).
_near_light: weakref.WeakKeyDictionary[NearBlocks, tuple[Scattered, Scattered, float]] = (
    weakref.WeakKeyDictionary()
)
_near_light_lock = threading.Lock()


def kept_light(blocks: NearBlocks, sky: SkyParams, within_deg: float = 0.0) -> Scattered | None:
    """The light kept for `blocks` if it was made for lights within `within_deg` of this
    sky's, under this sky's directions; None where there is none that close (nothing made)."""
    lights = scene_lights(sky)
    with _near_light_lock:
        found = _near_light.get(blocks)
    if found is None:
        return None
    light, shown, checked_deg = found
    if shown.directions is lights.directions and checked_deg <= within_deg:
        return shown
    # Against the directions the light was made for, so that reuse never drifts.
    if not close_directions(light.directions, lights.directions, within_deg):
        return None
    if light.directions is lights.directions:
        shown = light
    else:
        shown = Scattered(lights.directions, light.rows)
    with _near_light_lock:
        _near_light[blocks] = (light, shown, within_deg)
    return shown


def stale_light(blocks: NearBlocks, sky: SkyParams) -> Scattered | None:
    """The light kept for `blocks`, however far the sun has moved since it was made, under
    this sky's directions (a light more or fewer than the sky's: its rows cut or padded with
    darkness): what a frame shows while the light for this sky is made elsewhere."""
    with _near_light_lock:
        found = _near_light.get(blocks)
    if found is None:
        return None
    light = found[0]
    directions = scene_lights(sky).directions
    rows = light.rows
    want = directions.shape[0]
    if rows.shape[1] > want:
        rows = rows[:, :want]
    elif rows.shape[1] < want:
        rows = np.concatenate(
            [rows, np.zeros((rows.shape[0], want - rows.shape[1]), rows.dtype)], axis=1
        )
    return Scattered(directions, rows)


def near_scattered_light(
    blocks: NearBlocks, near: SpriteBatch, sky: SkyParams, within_deg: float = 0.0
) -> Scattered | None:
    """Harris's light (`shading_harris.scattered_light`) on each sprite of `near`, the sprites
    of `blocks` placed for a frame, a row per sprite (zeros for slab sprites); None when every
    sprite is a slab's. The drift moves a cloud's sprites alike, so it changes none of it.
    `within_deg`: light kept for lights that far from this sky's will do (a frame's case:
    LIGHT_REUSE_DEG); 0, what the ring's worker asks, makes it for exactly these lights."""
    found = kept_light(blocks, sky, within_deg)
    if found is not None:  # then the set has particles: no light is kept for slabs alone
        return found
    lights = scene_lights(sky)
    slab = near.slab
    if len(near) and slab.all():
        return None
    if slab.any():
        part = scattered_light(near.take(~slab), lights)
        rows = np.zeros((len(near), part.rows.shape[1]), np.float32)
        rows[~slab] = part.rows
        made = Scattered(lights.directions, rows)
    else:
        made = scattered_light(near, lights)
    with _near_light_lock:
        _near_light[blocks] = (made, made, 0.0)
    return made


def needs_light(blocks: NearBlocks) -> bool:
    """Whether the set has particles to light (slab sprites take no Harris light)."""
    return bool(len(blocks.batch)) and not bool(blocks.batch.slab.all())


class PreparedNear(NamedTuple):
    """A near set made with a ring or for a frame, Harris's light on it (None: not Harris,
    or every sprite a slab's) and its convective cells (None: not asked for), under the key
    the frames look it up by (`gather.near_blocks_keyed`)."""

    key: Hashable
    blocks: NearBlocks
    light: Scattered | None
    found: tuple[tuple[object, tuple[Candidate, ...]], ...] = ()  # (candidates key, cells)


def prepare_near(
    state: WeatherState,
    ring: RingScene,
    shown: NearRing | None,
    sky: SkyParams,
    settings: SceneSettings,
    epochs: tuple[LayerEpoch | None, ...] | None = None,
) -> tuple[PreparedNear, ...]:
    """Make, with a new ring (on its worker), the near sets the frames will ask for once it
    is complete, Harris's light on them and (with `epochs`) their convective cells: the
    cross-fade's (with `shown`, the ring then on show, at any weight) and the new ring's own.
    Made in a frame, each cost that frame tens of milliseconds. Returns them, for a worker
    in another process to hand back (`install_near`)."""
    new = NearRing(ring.geometry.centre_m, ring.drift, 1.0)
    sets: list[tuple[NearRing, ...]] = [(new,)]
    if shown is not None:
        cur = shown._replace(weight=0.5)
        sets.append((cur, new._replace(weight=0.5)))
    made = (near_set(state, ring.drift, rings, sky, settings, epochs) for rings in sets)
    return tuple(p for p in made if p is not None)


def warm_near(
    state: WeatherState,
    drift: Drift,
    ring: NearRing,
    sky: SkyParams,
    settings: SceneSettings,
    epochs: tuple[LayerEpoch | None, ...] | None = None,
) -> None:
    """Make the near set a frame gathers for `ring`, with its light and (with `epochs`) its
    cells, ahead of that frame."""
    near_set(state, drift, (ring,), sky, settings, epochs)


def near_set(
    state: WeatherState,
    drift: Drift,
    rings: tuple[NearRing, ...],
    sky: SkyParams,
    settings: SceneSettings,
    epochs: tuple[LayerEpoch | None, ...] | None = None,
) -> PreparedNear | None:
    """The near set for `rings` (made, or found in the cache), its light made for exactly
    this sky and, with `epochs`, its convective cells."""
    keyed = near_blocks_keyed(state, drift, rings, settings.ring_radius_m, settings.max_range_m)
    if keyed is None:
        return None
    key, blocks = keyed
    light = None
    if settings.shading == "harris":
        placed = blocks.placed(drift, rings)
        if placed is not None:
            light = near_scattered_light(blocks, placed[0], sky)
    found: tuple[tuple[object, tuple[Candidate, ...]], ...] = ()
    if epochs is not None and settings.max_towers > 0:
        cells = candidates(blocks, state, epochs)
        found = ((candidates_key(state, epochs), cells),)
    return PreparedNear(key, blocks, light, found)


def install_near(prepared: tuple[PreparedNear, ...]) -> None:
    """Keep near sets, their light and cells made by `prepare_near` or `near_set` in another
    process, so the frames find them as if made here."""
    for item in prepared:
        install_near_blocks(item.key, item.blocks)
        if item.light is not None:
            with _near_light_lock:
                _near_light[item.blocks] = (item.light, item.light, 0.0)
        for key, cells in item.found:
            install_candidates(item.blocks, key, cells)
