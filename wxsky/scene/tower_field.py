"""Which convective cells of the near layer are drawn as growing volumes this frame, how old
each is, and the volumes' light (issue 17, items 2 and 4; docs/towers.md).

A convective layer's cells (`convection.tower_specs`) are found once per near set, in the
layers' drifting frames. Each frame places them with the drift and keeps the `max_towers`
nearest the eye as towers; their clouds' sprites leave the near layer (their rain shafts
stay). A cell entering or leaving the budget as the eye flies on turns from one to the
other over TOWER_FADE_S (the tower fading in as its cloud's sprites fade out) instead of
switching in one frame: each frame carries the cells' progress to the next
(`PlacedTowers.fades`, as the in-cloud locks are carried). The rest stay sprite clouds, as
do cells the eye is in or at (the in-cloud rules of the sprites then apply) and every cell
beyond the near layer (the ring's impostors draw them).

A tower's age is the sim time since its layer's weather was set (`LayerEpoch`, kept by the
engine as it keeps the drift's anchor) less its birth: a picture at a later time shows the
towers grown by then, as it shows the clouds drifted. When the air starts clearing the
engine marks the moment (`cut_utc`) and the towers' supply stops there.
"""

from __future__ import annotations

import math
import threading
import weakref
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from datetime import datetime

import numpy as np
import numpy.typing as npt

from wxsky.scene.convection import is_convective, tower_specs
from wxsky.scene.footprints import footprints
from wxsky.scene.gather import Drift, NearBlocks
from wxsky.scene.rain import is_shaft
from wxsky.scene.shading_harris import Lights, close_directions, scene_lights
from wxsky.scene.sky import SkyParams
from wxsky.scene.tower_shading import tower_light
from wxsky.towers.volume import STEP_S, TowerSpec, TowerVolume
from wxsky.weather.state import WeatherState

U8 = npt.NDArray[np.uint8]
# The eye this close to a tower's box (as a share of the box's half size) sees its sprite
# cloud instead: the in-cloud rules (fog, facing locks, visibility) are the sprites'.
INSIDE_MARGIN = 1.1
# Channels of the two textures of a lit volume: up to MAX_LIGHTS lights (Harris's key light,
# zenith and skylights), then the density in channel DENSITY_CHANNEL.
TEXTURES = 2
MAX_LIGHTS = 6
DENSITY_CHANNEL = 6
# Density below this is not drawn as cloud (the smoothed field's faint fringe and the odd lone
# cell): the impostor is fitted to the rest.
OCCUPIED_FLOOR = 0.05
# A cell entering the budget turns from sprite cloud to tower over this long (and back when
# it leaves), wall-clock; the ring's impostors cross-fade over 1 s, and a tower's look
# changes more. By time, not by the distance to the budget's edge: that left the cell
# nearest the edge a ghost of both for as long as the eye kept its distance (drifting with
# the layer, for ever).
TOWER_FADE_S = 2.0


@dataclass(frozen=True)
class LayerEpoch:
    """When a layer's weather was set, the sun's elevation then (its towers' heating), the
    cover it was supplied at, and, once the air is clearing, when the supply stopped."""

    set_utc: datetime
    sun_elevation_deg: float
    cut_utc: datetime | None = None
    cover_oktas: float = 0.0


@dataclass(frozen=True)
class TowerClock:
    """What a frame's towers are timed by: per layer of the frame's weather its epoch (None:
    the layer makes no towers), and the frame's sim time."""

    epochs: tuple[LayerEpoch | None, ...]
    time_utc: datetime


@dataclass(frozen=True, eq=False)
class LitVolume:
    """One automaton step of a tower, lit for one sky: (2, nz, ny, nx, 4) bytes, the light
    from lights 0-3 in the first texture, lights 4-5 and the density in the second."""

    key: tuple[object, ...]  # (spec, step, lights): equal keys hold equal bytes
    texels: U8
    # The lights it was lit by (`scene_lights`): directions (L, 3) and colours (L, 3).
    light_dirs: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    light_rgb: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    # The part of the box holding cloud, as shares of the box from its low corner: (low,
    # high) per axis (x, y, z), a cell wider than the cloud; ((0.5,)*3,)*2 when empty.
    occupied: tuple[tuple[float, float, float], tuple[float, float, float]] = (
        (0.5, 0.5, 0.5),
        (0.5, 0.5, 0.5),
    )

    @property
    def step(self) -> int:
        step = self.key[1]
        assert isinstance(step, int)
        return step


@dataclass(frozen=True)
class TowerShow:
    """One tower in a frame."""

    spec: TowerSpec
    layer: int
    cloud_id: int
    centre_m: tuple[float, float, float]  # the box's middle, ENU
    age_s: float
    distance_m: float
    alpha: float  # the cloud's formation and the near layer's share
    haze: float  # 0..1 aerial perspective toward SkyParams.haze_rgb
    insert_at: int = 0  # drawn after this many of the near layer's sprites (back to front)
    # Filled in by the engine: the lit steps around the tower's age, and how far between.
    volumes: tuple[LitVolume, ...] = ()
    frac: float = 0.0
    flash: float = 0.0  # lightning's light on it this frame (`lightning.flash_light`)

    @property
    def step(self) -> int:
        return int(self.age_s // STEP_S)

    @property
    def ready(self) -> bool:
        return bool(self.volumes)


@dataclass(frozen=True)
class Candidate:
    spec: TowerSpec
    layer: int
    cloud_id: int
    row: int  # one of the cloud's sprites in the near set's batch
    formed: float


@dataclass(frozen=True)
class PlacedTowers:
    shows: tuple[TowerShow, ...]
    drop_ids: npt.NDArray[np.int64]  # clouds whose sprites the towers replace
    left_out: int  # cells past the budget, drawn as sprite clouds
    candidates: int = 0
    # Clouds part-way between sprites and tower, their sprites kept at this share of their
    # alpha (TOWER_FADE_S).
    fade_ids: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    fade_keep: npt.NDArray[np.float32] = field(default_factory=lambda: np.zeros(0, np.float32))
    # Every cell's progress from sprite cloud (0) to tower (1) where it is above 0, for the
    # next frame's `place_towers`.
    fades: tuple[tuple[int, float], ...] = ()


NO_TOWERS = PlacedTowers((), np.zeros(0, np.int64), 0)

_found: weakref.WeakKeyDictionary[NearBlocks, dict[object, tuple[Candidate, ...]]] = (
    weakref.WeakKeyDictionary()
)
_found_lock = threading.Lock()


def candidates(
    blocks: NearBlocks, state: WeatherState, epochs: tuple[LayerEpoch | None, ...]
) -> tuple[Candidate, ...]:
    """Every convective cell of the near set (kept with it: the same set gives the same cells
    until the weather or the epochs change)."""
    key = candidates_key(state, epochs)
    found = kept_candidates(blocks, state, epochs, key)
    if found is not None:
        return found
    out: list[Candidate] = []
    starts = np.concatenate([[0], np.cumsum(blocks.block_rows)])
    for b, (li, bx, by) in enumerate(blocks.block_keys):
        if li >= len(state.layers) or li >= len(epochs):
            continue
        layer, epoch = state.layers[li], epochs[li]
        if epoch is None or not is_convective(layer):
            continue
        rows = np.arange(starts[b], starts[b + 1])
        clouds = blocks.batch.take(rows)
        cloud_rows = rows[~is_shaft(clouds)]
        clouds = blocks.batch.take(cloud_rows)
        if not len(clouds):
            continue
        feet = footprints(clouds)
        first = np.full(len(feet.ids), -1)
        first[feet.inverse[::-1]] = cloud_rows[::-1]
        cut_s = (
            math.inf if epoch.cut_utc is None else (epoch.cut_utc - epoch.set_utc).total_seconds()
        )
        for spec in tower_specs(state, layer, (bx, by), clouds, epoch.sun_elevation_deg):
            supplied = cut_s - spec.born_s
            if supplied <= 0.0:
                continue  # the air cleared before it was born
            out.append(
                Candidate(
                    spec=replace(spec, supplied_s=supplied),
                    layer=li,
                    cloud_id=int(feet.ids[spec.cell]),
                    row=int(first[spec.cell]),
                    formed=float(feet.formed[spec.cell]),
                )
            )
    made = tuple(out)
    install_candidates(blocks, key, made)
    return made


def candidates_key(state: WeatherState, epochs: tuple[LayerEpoch | None, ...]) -> object:
    """What a set's convective cells depend on besides the set: the epochs and the air."""
    return (epochs, state.temperature_c, state.dewpoint_c, state.layers)


def kept_candidates(
    blocks: NearBlocks,
    state: WeatherState,
    epochs: tuple[LayerEpoch | None, ...],
    key: object | None = None,
) -> tuple[Candidate, ...] | None:
    """The set's convective cells if already found for this weather and these epochs."""
    if key is None:
        key = candidates_key(state, epochs)
    with _found_lock:
        return _found.get(blocks, {}).get(key)


def install_candidates(blocks: NearBlocks, key: object, found: tuple[Candidate, ...]) -> None:
    """Keep a set's cells (found here, or by a worker process for the set it handed back)."""
    with _found_lock:
        _found.setdefault(blocks, {})[key] = found


def place_towers(
    found: tuple[Candidate, ...],
    drift: Drift,
    share: npt.NDArray[np.float32],
    eye_m: tuple[float, float, float],
    clock: TowerClock,
    sky: SkyParams,
    budget: int,
    max_range_m: float,
    fades: Mapping[int, float] | None = None,
    dt_s: float = 0.0,
) -> PlacedTowers:
    """The `budget` cells nearest the eye, placed with the frame's drift: the born ones as
    towers, their clouds' sprites (born or not: a cell not born yet is clear air) to drop.
    Cells the eye is in or at stay sprite clouds and do not count. `fades`: the previous
    frame's `PlacedTowers.fades`, `dt_s` (wall-clock) before: cells that came into the budget
    or left it since move toward tower or sprites by dt_s / TOWER_FADE_S; None (a first
    frame, a picture): every cell is already what the budget makes it."""
    if budget <= 0 or not found:
        return PlacedTowers((), np.zeros(0, np.int64), len(found), len(found))
    eye = np.asarray(eye_m, np.float64)
    boxes = _boxes(found)
    # Each candidate moved by its layer's drift (none for a layer the drift does not hold).
    shift = np.zeros((max(len(drift), boxes.layer_count), 3))
    if drift:
        shift[: len(drift), :2] = drift
    rel = boxes.centres + shift[boxes.layers]
    centres = rel.copy()
    rel -= eye
    inside = np.all(np.abs(rel) < boxes.reach, axis=1)
    dists = np.sqrt(np.einsum("ij,ij->i", rel, rel))
    # Nearest first, ties in candidate order; only the chosen few become Python objects (the
    # candidates are a whole near set's worth of cells, every frame).
    scored = np.flatnonzero(~inside)
    ranked: list[int] = scored[np.lexsort((scored, dists[scored]))][:budget].tolist()
    step = max(dt_s, 0.0) / TOWER_FADE_S
    progress = {found[i].cloud_id: _toward(fades, found[i].cloud_id, 1.0, step) for i in ranked}
    kept = len(ranked)
    if fades:
        # Cells that left the budget (not for the eye entering them) fade back to sprites.
        leaving = [cid for cid in fades if cid not in progress]
        if leaving:
            where = {c.cloud_id: i for i, c in enumerate(found)}
            for cid in leaving:
                i = where.get(cid, -1)
                if i >= 0 and not inside[i]:
                    ranked.append(i)
                    progress[cid] = _toward(fades, cid, 0.0, step)
    chosen = [
        (
            float(dists[i]),
            found[i],
            (float(centres[i, 0]), float(centres[i, 1]), float(centres[i, 2])),
        )
        for i in ranked
    ]
    shows = []
    drop: list[int] = []
    fade_ids: list[int] = []
    fade_keep: list[float] = []
    for dist, c, centre in chosen:
        turned = _smooth(progress[c.cloud_id])
        if turned <= 0.0:
            continue  # faded back: all sprite cloud
        if turned < 1.0:
            fade_ids.append(c.cloud_id)
            fade_keep.append(1.0 - turned)
        else:
            drop.append(c.cloud_id)
        since_s = (clock.time_utc - _set_utc(clock, c.layer)).total_seconds()
        age = c.spec.age_s(since_s)
        if age < 0.0:
            continue  # not born yet: clear air (its cloud's sprites go as a tower's would)
        shows.append(
            TowerShow(
                spec=c.spec,
                layer=c.layer,
                cloud_id=c.cloud_id,
                centre_m=centre,
                age_s=age,
                distance_m=dist,
                alpha=float(
                    min(1.0, c.formed)
                    * (share[c.row] if c.row < len(share) else 1.0)
                    * _edge(dist, max_range_m)
                    * turned
                ),
                haze=float(sky.haze_of(dist, centre[2] - float(eye[2]), float(eye[2]))),
            )
        )
    return PlacedTowers(
        tuple(shows),
        np.asarray(drop, np.int64),
        len(scored) - kept,
        len(found),
        np.asarray(fade_ids, np.int64),
        np.asarray(fade_keep, np.float32),
        tuple((cid, p) for cid, p in progress.items() if p > 0.0),
    )


def _toward(fades: Mapping[int, float] | None, cloud_id: int, target: float, step: float) -> float:
    """A cell's progress toward tower (1) or sprites (0), `step` on from the last frame's."""
    if fades is None:
        return target
    was = fades.get(cloud_id, 0.0)
    return min(target, was + step) if target > was else max(target, was - step)


def _smooth(progress: float) -> float:
    """How much of a cell is tower (the rest its sprite cloud) at a linear `progress`."""
    t = min(max(progress, 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


@dataclass(frozen=True)
class _Boxes:
    centres: npt.NDArray[np.float64]  # (C, 3) in the layers' drifting frames
    reach: npt.NDArray[np.float64]  # (C, 3) half the box, times INSIDE_MARGIN
    layers: npt.NDArray[np.intp]  # (C,)
    layer_count: int  # the highest layer index, plus one


_boxes_memo: dict[int, tuple[tuple[Candidate, ...], _Boxes]] = {}


def _boxes(found: tuple[Candidate, ...]) -> _Boxes:
    """The candidates' boxes as arrays (kept for the last few candidate sets: a frame asks
    for the same set as the one before)."""
    memo = _boxes_memo.get(id(found))
    if memo is not None and memo[0] is found:
        return memo[1]
    layers = np.asarray([c.layer for c in found], np.intp)
    made = _Boxes(
        np.asarray([c.spec.box_centre_m for c in found], np.float64).reshape(-1, 3),
        0.5
        * np.asarray([c.spec.box_size_m for c in found], np.float64).reshape(-1, 3)
        * INSIDE_MARGIN,
        layers,
        int(layers.max()) + 1 if len(layers) else 0,
    )
    if len(_boxes_memo) > 8:
        _boxes_memo.clear()
    _boxes_memo[id(found)] = (found, made)
    return made


def _set_utc(clock: TowerClock, layer: int) -> datetime:
    epoch = clock.epochs[layer] if layer < len(clock.epochs) else None
    return clock.time_utc if epoch is None else epoch.set_utc


def _edge(dist_m: float, max_range_m: float) -> float:
    """The fade before the edge of the generated range, as `layout.fade_by_range` fades a
    sprite (it matters in direct mode, where towers reach that far)."""
    edge = min(max((max_range_m - dist_m) / (0.25 * max_range_m), 0.0), 1.0)
    return edge * edge * (3.0 - 2.0 * edge)


def drop_mask(
    cloud_id: npt.NDArray[np.int64], shaft: npt.NDArray[np.bool_], drop_ids: npt.NDArray[np.int64]
) -> npt.NDArray[np.bool_]:
    """(N,) True for the sprites to keep: not a tower's cloud, or its rain shaft."""
    out: npt.NDArray[np.bool_] = ~np.isin(cloud_id, drop_ids) | shaft
    return out


def insert_points(dist_sorted_m: npt.NDArray[np.float64], towers_m: list[float]) -> list[int]:
    """Where each tower goes in a back-to-front draw whose sprites lie at `dist_sorted_m`
    (descending): after every sprite farther than it."""
    neg = -np.asarray(dist_sorted_m)
    return [int(np.searchsorted(neg, -d, side="left")) for d in towers_m]


# A lit step serves while the sky's lights stay this close to those it was lit by: the sun
# takes some 8 minutes to move 2 degrees, and relighting every tower costs 30 ms each.
RELIGHT_DEG = 2.0
RELIGHT_RGB = 0.03


def still_lit(lit: LitVolume, lights: Lights) -> bool:
    """Whether `lit` is lit closely enough for a sky with these lights (`scene_lights`;
    RELIGHT_DEG, RELIGHT_RGB)."""
    rgb = np.asarray(lights.rgb)
    if lit.light_rgb.shape != rgb.shape:
        return False
    return close_directions(lit.light_dirs, lights.directions, RELIGHT_DEG) and bool(
        np.abs(lit.light_rgb - rgb).max() <= RELIGHT_RGB
    )


def lights_key(lights: Lights) -> tuple[object, ...]:
    """What a tower's light depends on in the sky's lights (`scene_lights`): their
    (quantised) directions and their colours to a hundredth."""
    return (
        lights.directions.round(4).tobytes(),
        np.round(np.asarray(lights.rgb), 2).tobytes(),
    )


def lit_volume(volume: TowerVolume, step_n: int, sky: SkyParams) -> LitVolume:
    """Step `step_n` of a tower's volume lit for `sky`, as the renderer's textures take it."""
    density = volume.density_of_step(step_n)
    light = tower_light(density, sky, volume.spec.extinction_per_cell)  # (nz, ny, nx, L)
    if light.shape[-1] > MAX_LIGHTS:
        raise ValueError(f"{light.shape[-1]} lights; a lit tower holds {MAX_LIGHTS}")
    nz, ny, nx = density.shape
    channels = np.zeros((nz, ny, nx, 4 * TEXTURES), np.float32)
    channels[..., : light.shape[-1]] = light
    channels[..., DENSITY_CHANNEL] = density
    texels = np.clip(channels * 255.0 + 0.5, 0.0, 255.0).astype(np.uint8)
    texels = np.ascontiguousarray(np.moveaxis(texels.reshape(nz, ny, nx, TEXTURES, 4), 3, 0))
    texels.flags.writeable = False
    lights = scene_lights(sky)
    return LitVolume(
        key=(volume.spec, step_n, lights_key(lights)),
        texels=texels,
        occupied=occupied_part(density),
        light_dirs=np.asarray(lights.directions, np.float64),
        light_rgb=np.asarray(lights.rgb, np.float64),
    )


def occupied_part(
    density: npt.NDArray[np.float32], floor: float = OCCUPIED_FLOOR
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(low, high) corners, x y z as shares of the box, of the cells whose density is above
    `floor`, one cell wider on every side (the textures are read between cells)."""
    nz, ny, nx = density.shape
    found = density > floor
    if not found.any():
        return ((0.5, 0.5, 0.5), (0.5, 0.5, 0.5))
    lo, hi = [], []
    for axis, n in ((2, nx), (1, ny), (0, nz)):
        other = tuple(a for a in range(3) if a != axis)
        cells = np.flatnonzero(found.any(axis=other))
        lo.append(max(0.0, (int(cells[0]) - 1) / n))
        hi.append(min(1.0, (int(cells[-1]) + 2) / n))
    return ((lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2]))
