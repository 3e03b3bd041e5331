"""The scene stage: weather state + camera -> the sprites and ring the renderer draws.

Blocks whose nearest point lies inside the ring radius (measured from the ring centre) are
"near" and drawn as sprites every frame from the host camera; the rest, out to the maximum
range, go into the impostor ring (which blocks: `gather`). Here they are sorted, shaded,
faded with range, oriented, and for the near layer fogged in cloud, thinned by the far band,
LOD and cap options, and split at the host's aircraft.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import math
from collections.abc import Callable, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from wxsky.scene.camera import Camera, spheres_in_view, view_bounds
from wxsky.scene.cloud_lod import collapse_far_clouds
from wxsky.scene.cloud_shadow import SHADOW_MAP_PX, CloudShadow, cloud_shadow
from wxsky.scene.clouds import BLOCK_CACHE, SpriteBatch
from wxsky.scene.fog import FogField, fog_field, fogged_at_eye
from wxsky.scene.gather import (
    CancelFlag,
    Drift,
    NearRing,
    check_cancel,
    gather_far,
    gather_near_blocks,
)
from wxsky.scene.in_cloud import (
    NO_LOCKS,
    NO_VEIL,
    OUTSIDE,
    InCloud,
    Locks,
    in_cloud,
    in_cloud_fog,
    layer_spans,
    lock_facing,
    lock_reach_frac,
)
from wxsky.scene.lightning import (
    FLASH_RGB,
    LONGEST_S,
    Flash,
    StormCell,
    flash_light,
    flashes_between,
    lit_flashes,
    storm_rate_per_min,
)
from wxsky.scene.near_sets import NearInputs, near_scattered_light
from wxsky.scene.precip_eye import AtEye, Shaft, precipitation_at
from wxsky.scene.precip_view import PrecipView, precip_view
from wxsky.scene.rain import is_shaft, rain_of
from wxsky.scene.ring import RingGeometry, bin_far_sprites, bin_indices
from wxsky.scene.shading import (
    DEFAULT_SHADING,
    ParticleLight,
    Scattered,
    display_colours_and_rim,
    prepare_lighting,
)
from wxsky.scene.shading_harris import LIGHT_REUSE_DEG, batch_balls, with_alpha
from wxsky.scene.sky import SkyParams
from wxsky.scene.sprite_budget import cap_sprites
from wxsky.scene.sprites import F64
from wxsky.scene.tower_field import (
    NO_TOWERS,
    Candidate,
    PlacedTowers,
    TowerClock,
    TowerShow,
    candidates,
    drop_mask,
    insert_points,
    place_towers,
)
from wxsky.weather.state import WeatherState

SKY_MODELS = ("physical", "roden-parberry")  # [scene] sky


@dataclass(frozen=True)
class SceneSettings:
    ring_radius_m: float = 8000.0
    max_range_m: float = 40000.0
    ring_texture_px: int = 512
    shading: str = DEFAULT_SHADING  # "wang" or "harris" (wxsky.scene.shading)
    # The sky: "physical" (wxsky.scene.atmosphere's tables) or "roden-parberry" (the gradient).
    sky: str = "physical"
    # Near clouds this far from the eye are drawn as one sprite (Wang's LOD for machines
    # short of fill rate; 0: never), cross-fading over the band beyond it (see cloud_lod).
    lod_start_m: float = 0.0
    lod_band_m: float = 1000.0
    # Near sprites this far from the eye are drawn at the ring impostors' resolution rather
    # than the near layer's (0: never); see Renderer._draw_near.
    far_band_m: float = 2000.0
    # Clouds in the ring this far from its centre go into the impostors as one sprite each
    # (0: never): halves an impostor's drawing time, but doubles the picture's difference
    # from drawing every sprite (docs/performance.md), so it is off unless asked for.
    impostor_lod_m: float = 0.0
    # At most this many near sprites a frame, farthest clouds left out first (0: no cap).
    max_near_sprites: int = 20_000
    # Texels per side of the cloud-shadow map made with each ring (cloud_shadow; 0: none).
    shadow_map_px: int = SHADOW_MAP_PX
    # At most this many convective cells of the near layer grow as volumes (tower_field).
    max_towers: int = 6
    # Lightning flashes a minute in each storm cell while a thunderstorm is reported
    # (`[lightning] flashes_per_min`); None: by the storm's strength (lightning.RATE_PER_MIN).
    flashes_per_min: float | None = None


@dataclass(frozen=True)
class SpriteDraw:
    """Sprites ready to draw from one eye: sorted back to front, shaded."""

    sprites: SpriteBatch
    # (N, 4) straight alpha; or (N, 7): then columns 4-6 are the display colour of each
    # sprite's thin outer texels, its rim (`shading.display_colours_and_rim`: the silver
    # lining of a cloud before a low sun). Stages that keep, drop or merge sprites carry
    # every column; a draw of four columns has rims of its sprites' own colour.
    rgba: npt.NDArray[np.float32]
    # (N, 3) unit normal of a quad with its own orientation (a flat cirrus sheet, a sprite
    # whose facing locked while the camera is inside it); a zero row, or None for all, faces
    # the camera.
    normals: npt.NDArray[np.float32] | None = None

    def __len__(self) -> int:
        return len(self.sprites)

    def slice(self, start: int, stop: int) -> SpriteDraw:
        """Sprites start..stop of the draw, in its order."""
        return self.take(np.arange(start, stop))

    def take(self, index: npt.NDArray[np.intp]) -> SpriteDraw:
        normals = None if self.normals is None else self.normals[index]
        return SpriteDraw(self.sprites.take(index), self.rgba[index], normals)


_ring_serials = itertools.count(1)


@dataclass(frozen=True)
class RingScene:
    geometry: RingGeometry
    impostors: tuple[SpriteDraw, ...]  # (8,)
    drift: Drift  # the drift the ring was built with
    # The clouds' shadow on the ground over the ring's area (2 ring radii square), made with
    # the ring's drift and sun; None for an empty ring or with `shadow_map_px` 0.
    shadow: CloudShadow | None = None
    # The sky's haze distance the impostors were hazed with (SkyParams.haze_m) and the top of
    # its hazy layer (MSL): the renderer fades the flat bases' shade into the air by them as
    # the shading faded the colours.
    haze_m: float = math.inf
    haze_top_m: float = math.inf
    # Unique to this ring in the process: what a publisher names its images by, so a slot
    # that already holds them keeps them (`FrameWriter.keep_layer`).
    serial: int = field(init=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "serial", next(_ring_serials))


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
    # With the host's aircraft set: the near sprites nearer than it (`near` keeps those
    # behind it), for a layer the host draws over its aircraft; None without one.
    near_front: SpriteDraw | None = None
    split_distance_m: float | None = None
    # The first this many of `near` (the farthest) are the far band, drawn at a lower
    # resolution, as the ring's impostors are; 0: none.
    near_far_count: int = 0
    near_dropped: int = 0  # near sprites left out by the per-frame cap
    # Convective cells drawn as volumes, each between the near sprites at its distance, and
    # how many more the budget left as sprite clouds.
    towers: tuple[TowerShow, ...] = ()
    towers_left_out: int = 0
    # Each convective cell's progress from sprite cloud to tower, to carry into the next
    # frame (`tower_field.place_towers`'s fades).
    tower_fades: tuple[tuple[int, float], ...] = ()
    # Lightning (`lightning.py`): the flashes lighting the clouds at this frame's moment with
    # their glow, and every flash that started since the frame before (for the stream).
    flashes: tuple[tuple[Flash, float], ...] = ()
    new_flashes: tuple[Flash, ...] = ()
    # What falls at the eye, how hard, how far one sees in it (`precip_eye.py`).
    at_eye: AtEye | None = None
    # The rain curtains under the near storms and the drops about the eye, as drawn
    # (`precip_view.py`); None: nothing falls in view.
    precip: PrecipView | None = None
    # The fog over the ground the renderer draws (`fog.py`); None: no fog, no fog pass.
    fog: FogField | None = None


class StageClock(Protocol):
    """Times named stages of a frame (`wxsky bench`); the scene only marks where they are."""

    def stage(self, name: str) -> AbstractContextManager[object]: ...


class _NoClock:
    def stage(self, name: str) -> AbstractContextManager[object]:
        return contextlib.nullcontext()


NO_CLOCK: StageClock = _NoClock()


def sort_back_to_front(batch: SpriteBatch, eye_m: tuple[float, float, float]) -> SpriteBatch:
    return batch.take(sort_order(batch, eye_m))


def sort_order(batch: SpriteBatch, eye_m: tuple[float, float, float]) -> npt.NDArray[np.intp]:
    """(N,) indices that put the sprites back to front from the eye."""
    return back_to_front(squares(eye_offsets(batch, eye_m)))


def eye_offsets(batch: SpriteBatch, eye_m: tuple[float, float, float]) -> F64:
    """(3, N): east, north and up of the sprites' centres less the eye, a row each. Row by
    row is a quarter of the time of the (N, 3) difference for a near set of thousands."""
    # order="C": the transpose's own layout would leave each row strided across the sprites.
    out: F64 = np.subtract(batch.centre_m.T, np.asarray(eye_m, np.float64)[:, None], order="C")
    return out


def squares(offsets: F64) -> F64:
    """(N,) squared lengths of `eye_offsets`: the sums np.sum makes over rows of three, in
    its order, so their square roots are np.linalg.norm's to the bit."""
    x, y, z = offsets
    out: F64 = x * x + y * y + z * z
    return out


def back_to_front(d2: F64) -> npt.NDArray[np.intp]:
    # Stable sort on distance so equal distances keep their generation order on every machine.
    out: npt.NDArray[np.intp] = np.argsort(-d2, kind="stable")
    return out


def fade_by_range(
    rgba: npt.NDArray[np.float32],
    batch: SpriteBatch,
    eye_m: tuple[float, float, float],
    sky: SkyParams,
    max_range_m: float,
    dist_m: F64 | None = None,
) -> npt.NDArray[np.float32]:
    """Aerial perspective: distant clouds take the haze's colour (`SkyParams.haze_rgb`; with
    the physical sky, the sky behind each, `SkyParams.haze_toward`) and
    fade out before the edge of the generated range, so the range limit never shows as a
    hard line. `dist_m`: (N,) the sprites' distances from the eye, if known."""
    rim = rgba[:, 4:7].T if rgba.shape[1] > 4 else None
    return hazed(rgba[:, :3].T, rgba[:, 3], batch, eye_m, sky, max_range_m, dist_m, rim)


def hazed(
    colours: F64 | npt.NDArray[np.float32],
    alpha: npt.NDArray[np.float32],
    batch: SpriteBatch,
    eye_m: tuple[float, float, float],
    sky: SkyParams,
    max_range_m: float,
    dist_m: F64 | None = None,
    rim: F64 | npt.NDArray[np.float32] | None = None,
) -> npt.NDArray[np.float32]:
    """`fade_by_range` of (3, N) colours (`shading.display_colours`) and (N,) alphas: (N, 4)
    straight-alpha RGBA, rounded to float32 once; with `rim` ((3, N) the sprites' rim
    colours, hazed alike), (N, 7) (see SpriteDraw.rgba)."""
    dist = np.linalg.norm(batch.centre_m - np.asarray(eye_m), axis=1) if dist_m is None else dist_m
    # Thinner above the hazy layer's top (`sky.haze_share`): a tower's upper part stands out.
    haze = sky.haze_of(dist, batch.centre_m[:, 2] - eye_m[2], eye_m[2])
    if sky.atmosphere is None:
        air = np.asarray(sky.haze_rgb, np.float64)[:, None] * haze
    else:
        # The physical sky: each cloud fades into the sky right behind it (a frame's sprites,
        # one table lookup each).
        air = sky.haze_toward((batch.centre_m - np.asarray(eye_m)).T, eye_m[2]) * haze
    rgb = colours * (1.0 - haze) + air
    out = with_alpha(rgb, alpha)
    if rim is not None:
        out = np.concatenate([out, (rim * (1.0 - haze) + air).T.astype(np.float32)], axis=1)
    if len(dist) and float(dist.max()) > 0.75 * max_range_m:  # the near layer never is
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
    share: npt.NDArray[np.float32] | None = None,
    order: npt.NDArray[np.intp] | None = None,
    scattered: Scattered | None = None,
    dist_m: F64 | None = None,
) -> SpriteDraw:
    """`light`: a precompute (`prepare_lighting`) of a batch holding these sprites; `share`:
    (N,) a factor on each sprite's alpha after shading (see `gather_near`); `order`: the
    back-to-front order if already known (`sort_order`), of all or some of the sprites (those
    it leaves out, out of view or drawn as towers, are neither shaded nor drawn);
    `scattered`: Harris's light on each sprite of the batch (`near_scattered_light`);
    `dist_m`: (N,) each sprite's distance from the eye, if known."""
    if order is None:
        order = sort_order(batch, eye_m)
    # Only the sprites drawn are shaded (a sixth of a near set at 60 degrees).
    drawn = batch.take(order)
    if scattered is not None:
        scattered = scattered.take(order)
    dist = None if dist_m is None else dist_m[order]
    # Wang has no precompute over whole clouds: the clouds' balls (the depth toward the eye)
    # from the whole batch, not from the drawn sprites, or a cloud half out of view would
    # change its shade as the view turns.
    balls = batch_balls(batch)[order] if shading == "wang" else None
    colours, rim = display_colours_and_rim(
        drawn, sky, eye_m, shading, light, scattered, dist, balls
    )
    rgba = hazed(colours, drawn.opacity, drawn, eye_m, sky, max_range_m, dist, rim)
    if share is not None and len(share) and share.min() < 1.0:
        rgba[:, 3] *= share[order]
    return SpriteDraw(drawn, rgba)


def oriented(
    draw: SpriteDraw,
    eye_m: tuple[float, float, float],
    locks: Locks = NO_LOCKS,
    dist_m: F64 | None = None,
) -> tuple[SpriteDraw, Locks]:
    """The draw with each sprite's normal: flat ones lie in their layer (normal up), sprites
    the eye is inside keep the facing they locked with, the rest face the camera. `dist_m`:
    (N,) the sprites' distances from the eye, if known."""
    sprites = draw.sprites
    flat = sprites.flat
    # lock_facing's own reach: a deck's sprites lie within where a held lock is kept, but not
    # where one is taken, under a camera just above or below it, frame after frame.
    reach = lock_reach_frac(locks)
    if dist_m is not None and not np.any((dist_m < reach * sprites.size_m) & ~flat):
        # The eye is near no standing sprite (most frames): nothing locks, as lock_facing
        # would find, without cutting the batch.
        lock_normals, kept = None, NO_LOCKS
    else:
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
    cancel: CancelFlag | None = None,
) -> RingScene:
    """The ring's impostors and shadow map. Raises BuildCancelled (`gather.check_cancel`)
    between blocks and between stages once `cancel` is set."""
    BLOCK_CACHE.start_build()  # the cache makes room for what the last build used
    far = gather_far(state, drift, centre_m, settings.ring_radius_m, settings.max_range_m, cancel)
    # Every impostor is seen from the ring's centre: light and shade the far clouds once,
    # whole, before the bins cut those that straddle two impostors.
    check_cancel(cancel)
    light = prepare_lighting(far, sky, settings.shading)
    check_cancel(cancel)
    shaded = shade_for_eye(far, centre_m, sky, settings.max_range_m, settings.shading, light)
    check_cancel(cancel)
    if settings.impostor_lod_m > 0.0:
        # A cloud this far is a few texels of an impostor: one sprite draws it as well.
        collapsed = collapse_far_clouds(
            shaded.sprites, shaded.rgba, centre_m, settings.impostor_lod_m, settings.lod_band_m
        )
        if collapsed.lod_clouds:
            order = sort_order(collapsed.sprites, centre_m)
            shaded = SpriteDraw(collapsed.sprites.take(order), collapsed.rgba[order])
    geometry, index = bin_indices(shaded.sprites, centre_m, settings.ring_radius_m)
    impostors = tuple(oriented(shaded.take(idx), centre_m)[0] for idx in index)
    shadow = None
    check_cancel(cancel)
    if settings.shadow_map_px > 0:
        # With the ring, on its worker thread: a map costs tens of milliseconds, too much
        # for a frame, and it must match the ring's clouds (the same drift and sun).
        shadow = cloud_shadow(
            state,
            drift,
            centre_m,
            sky.sun.direction_enu,
            2.0 * settings.ring_radius_m,
            settings.shadow_map_px,
            settings.max_range_m,
            cancel,
        )
    return RingScene(
        geometry=geometry,
        impostors=impostors,
        drift=drift,
        shadow=shadow,
        haze_m=sky.haze_m,
        haze_top_m=sky.haze_top_m,
    )


def empty_ring(centre_m: tuple[float, float, float], radius_m: float, drift: Drift) -> RingScene:
    """A ring with no clouds in it: what shows before the first ring is built, or in direct
    mode, where every cloud is a near sprite."""
    geometry, bins = bin_far_sprites(SpriteBatch.empty(), centre_m, radius_m)
    nothing = SpriteDraw(SpriteBatch.empty(), np.zeros((0, 4), np.float32))
    return RingScene(geometry=geometry, impostors=tuple(nothing for _ in bins), drift=drift)


def build_frame(
    state: WeatherState,
    drift: Drift,
    camera: Camera,
    rings: tuple[NearRing, ...],
    sky: SkyParams,
    settings: SceneSettings,
    locks: Locks = NO_LOCKS,
    near_radius_m: float | None = None,
    clock: StageClock | None = None,
    split_at_m: tuple[float, float, float] | None = None,
    lod: bool = True,
    towers: TowerClock | None = None,
    gathered: NearInputs | None = None,
    fill_towers: Callable[[tuple[TowerShow, ...]], tuple[TowerShow, ...]] | None = None,
    tower_fades: Mapping[int, float] | None = None,
    dt_s: float = 0.0,
    flash_times_s: tuple[float, float] | None = None,
    eye_velocity_mps: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> FrameScene:
    """The near sprites for the camera, complementing `rings` (see `gather_near`) within
    `near_radius_m` (default: the ring radius; the whole range draws every cloud directly);
    `locks` are the previous frame's in-cloud locks; `clock` times the sort for benchmarks;
    `split_at_m`: the host's aircraft, at whose distance the near layer is split; `lod`: far
    near clouds as one sprite each (off in direct mode, which draws every sprite).
    `gathered`: the near layer already gathered, lit and its cells found (the daemon's
    frames, which never make a set: `engine.near_work`); by default gathered here, and what
    is missing made at once. `fill_towers`: gives the towers their lit steps
    (`engine.tower_work.TowerWork.fill`); a tower it leaves without any stays the sprite
    cloud it grew from until one is made, rather than a hole in the sky. `tower_fades`: the
    previous frame's `FrameScene.tower_fades`, `dt_s` (wall-clock) before it: cells coming
    into the towers' budget or leaving it cross-fade between sprites and tower; None (a
    first frame, a picture): none is part-way. `flash_times_s`: (the frame before's,
    this frame's) simulated time, seconds since the epoch: the flashes lit now and those
    started since (`FrameScene.flashes`, `new_flashes`); None: `state`'s time, and the flashes
    of the second before it. `eye_velocity_mps`: the eye's velocity (ENU), for the streaks
    of the drops about it."""
    if gathered is None:
        gathered = gather_inputs(state, drift, rings, sky, settings, near_radius_m, towers)
    near, share, blocks, scattered = (
        gathered.near,
        gathered.share,
        gathered.blocks,
        gathered.scattered,
    )
    eye = camera.position_m
    placed = NO_TOWERS
    found = None
    storms = storm_rate_per_min(state, settings.flashes_per_min)
    rain = rain_of(state)
    if (
        towers is not None
        and blocks is not None
        and (settings.max_towers > 0 or storms > 0.0 or rain is not None)
    ):
        found = gathered.found
        if found is None:
            found = candidates(blocks, state, towers.epochs)
    # The storms (the near set's cumulonimbus cells, where they stand now): their lightning
    # and the rain shafts under them.
    cells = (
        storm_cells(found, drift, state.observer.alt_m)
        if found and (storms > 0.0 or rain is not None)
        else ()
    )
    shafts = (
        ()
        if rain is None
        else tuple(Shaft(c.axis_m, c.shaft_radius_m(rain.snow), c.base_m) for c in cells)
    )
    at_eye = precipitation_at(state, eye, shafts)
    fog = fog_field(state)
    if fog is not None:
        at_eye = fogged_at_eye(at_eye, fog, eye)
    if flash_times_s is None:
        now_s = state.time_utc.timestamp()
        flash_times_s = (now_s - 1.0, now_s)
    since_s, now_s = flash_times_s
    precip = precip_view(state, rain, cells, at_eye, eye, eye_velocity_mps, now_s)
    lit: list[tuple[Flash, float]] = []
    started: list[Flash] = []
    if cells and storms > 0.0:
        lit = lit_flashes(cells, state.seed, storms, now_s)
        # A frame more than a flash's length after the last (a clock set) reports only
        # the last second's.
        since_s = max(since_s, now_s - LONGEST_S)
        started = flashes_between(cells, state.seed, storms, since_s + 1e-9, now_s + 1e-9)
    if found is not None and towers is not None and settings.max_towers > 0:
        placed = place_towers(
            found,
            drift,
            share,
            eye,
            towers,
            sky,
            settings.max_towers,
            settings.max_range_m,
            tower_fades,
            dt_s,
        )
        if fill_towers is not None and placed.shows:
            placed = _filled(placed, fill_towers(placed.shows))
        share = fading_share(near, share, placed)
    with (clock or NO_CLOCK).stage("sort"):
        offsets = eye_offsets(near, eye)
        d2 = squares(offsets)
        # Left out of the order, not cut from the set (the set and its light stay the ones
        # kept from frame to frame): the towers' clouds, and sprites wholly outside the view,
        # which draw nothing (five sixths of the near layer at 60 degrees). A cloud collapses
        # to one sprite from all its sprites, in view or not: with the one-sprite LOD, the
        # view is cut after it.
        drawn = np.ones(len(near), np.bool_)
        if len(placed.drop_ids):
            drawn &= drop_mask(near.cloud_id, is_shaft(near), placed.drop_ids)
        if precip is not None and precip.curtains:  # (the veil has no sprites to replace)
            # The near storms' shafts are drawn as curtains (precip.glsl), not as sprites.
            drawn &= ~is_shaft(near)
        collapsing = lod and settings.lod_start_m > 0.0
        if not collapsing:
            drawn &= in_view(near, camera, offsets)
        # Sorted as the whole set would be: a stable sort of the kept sprites in set order.
        shown = np.flatnonzero(drawn)
        order = shown[back_to_front(d2[shown])]
    dist = np.sqrt(d2)
    shaded = shade_for_eye(
        near,
        eye,
        sky,
        settings.max_range_m,
        settings.shading,
        share=share,
        order=order,
        scattered=scattered,
        dist_m=dist,
    )
    if lit:
        shaded = lit_by_flashes(shaded, lit)
    drawn_dist: F64 | None = dist[order]  # of the sprites drawn, while they are these
    if collapsing:
        drawn_dist = None
        collapsed = collapse_far_clouds(
            shaded.sprites, shaded.rgba, eye, settings.lod_start_m, settings.lod_band_m
        )
        if collapsed.lod_clouds:
            with (clock or NO_CLOCK).stage("sort"):
                again = sort_order(collapsed.sprites, eye)
            shaded = SpriteDraw(collapsed.sprites.take(again), collapsed.rgba[again])
        # A cloud collapses from all its sprites, in view or not; the view is cut after.
        seen = np.flatnonzero(in_view(shaded.sprites, camera))
        if len(seen) < len(shaded):
            shaded = SpriteDraw(shaded.sprites.take(seen), shaded.rgba[seen])
    dropped = 0
    if lod and settings.max_near_sprites > 0:
        budget = cap_sprites(shaded.sprites, shaded.rgba, eye, settings.max_near_sprites)
        if budget.dropped:
            shaded, dropped = SpriteDraw(budget.sprites, budget.rgba), budget.dropped
            drawn_dist = None
    cloud = in_cloud(near, eye, state.visibility_m, dist, spans_m=layer_spans(state.layers))
    fogged, veil = in_cloud_fog(shaded.sprites, shaded.rgba, eye, cloud, drawn_dist)
    draw, kept = oriented(SpriteDraw(shaded.sprites, fogged), eye, locks, drawn_dist)
    front: SpriteDraw | None = None
    split_m: float | None = None
    if split_at_m is not None:
        split_m = math.dist(split_at_m, eye)
        draw, front = split_at_distance(draw, eye, split_m)
    far_count = 0
    shows = placed.shows
    far_band = lod and settings.far_band_m > 0.0 and len(draw) > 0
    if far_band or shows:
        # The drawn sprites' distances, kept while the draw is still those sprites.
        known = drawn_dist if front is None else None
        dist = (
            np.linalg.norm(draw.sprites.centre_m - np.asarray(eye), axis=1)
            if known is None
            else known
        )
    if far_band:
        far_count = int(np.count_nonzero(dist >= settings.far_band_m))
    if shows:
        at = insert_points(dist, [t.distance_m for t in shows])
        shows = tuple(
            dataclasses.replace(t, insert_at=i)
            for i, t in sorted(zip(at, shows, strict=True), key=lambda p: -p[1].distance_m)
        )
    return FrameScene(
        camera=camera,
        sky=sky,
        near=draw,
        in_cloud=cloud,
        locks=kept,
        veil_rgba=veil,
        near_front=front,
        split_distance_m=split_m,
        near_far_count=far_count,
        near_dropped=dropped,
        towers=tuple(
            dataclasses.replace(t, flash=float(flash_light(lit, np.array([t.centre_m]))[0]))
            for t in shows
        )
        if lit
        else shows,
        towers_left_out=placed.left_out,
        tower_fades=placed.fades,
        flashes=tuple(lit),
        new_flashes=tuple(started),
        at_eye=at_eye,
        precip=precip,
        fog=fog,
    )


def storm_cells(
    found: tuple[Candidate, ...], drift: Drift, ground_m: float
) -> tuple[StormCell, ...]:
    """The cumulonimbus cells among a near set's convective cells, where they stand now."""
    out = []
    for c in found:
        if not c.spec.anvil:
            continue
        dx, dy = drift[c.layer] if c.layer < len(drift) else (0.0, 0.0)
        out.append(
            StormCell(
                cloud_id=c.cloud_id,
                axis_m=(c.spec.axis_m[0] + dx, c.spec.axis_m[1] + dy),
                base_m=c.spec.base_m,
                top_m=c.spec.base_m + c.spec.height_m,
                formed=c.formed,
                ground_m=ground_m,
                width_m=c.spec.width_m,
            )
        )
    return tuple(out)


def lit_by_flashes(draw: SpriteDraw, lit: list[tuple[Flash, float]]) -> SpriteDraw:
    """The sprites' display colours (and rims) with the flashes' light added where it reaches
    them (`lightning.flash_light` at each sprite's centre), clipped to white."""
    light = flash_light(lit, draw.sprites.centre_m)
    if not np.any(light > 1e-4):
        return draw
    rgba = draw.rgba.copy()
    add = (light[:, None] * np.asarray(FLASH_RGB)[None, :]).astype(np.float32)
    rgba[:, 0:3] = np.minimum(rgba[:, 0:3] + add, 1.0)
    if rgba.shape[1] >= 7:
        rgba[:, 4:7] = np.minimum(rgba[:, 4:7] + add, 1.0)
    return dataclasses.replace(draw, rgba=rgba)


def _filled(placed: PlacedTowers, filled: tuple[TowerShow, ...]) -> PlacedTowers:
    """`placed` with the towers' lit steps; those with none yet keep their clouds' sprites."""
    waiting = [t.cloud_id for t in filled if not t.volumes]
    if not waiting:
        return dataclasses.replace(placed, shows=filled)
    ids = np.asarray(waiting, np.int64)
    keep = ~np.isin(placed.drop_ids, ids)
    fading = ~np.isin(placed.fade_ids, ids)
    shows = tuple(t for t in filled if t.volumes)
    # A tower waiting for its first lit step fades in from nothing once it has one.
    unset = set(waiting)
    return dataclasses.replace(
        placed,
        shows=shows,
        drop_ids=placed.drop_ids[keep],
        fade_ids=placed.fade_ids[fading],
        fade_keep=placed.fade_keep[fading],
        fades=tuple((cid, p) for cid, p in placed.fades if cid not in unset),
    )


def fading_share(
    near: SpriteBatch, share: npt.NDArray[np.float32], placed: PlacedTowers
) -> npt.NDArray[np.float32]:
    """The near layer's alpha share with the clouds part-way to or from being towers faded
    by what their towers take (`PlacedTowers.fade_keep`; rain shafts keep theirs)."""
    if not len(placed.fade_ids):
        return share
    out = np.array(share, np.float32, copy=True)
    if len(out) != len(near):
        out = np.ones(len(near), np.float32)
    shaft = is_shaft(near)
    for cloud_id, kept in zip(placed.fade_ids.tolist(), placed.fade_keep.tolist(), strict=True):
        out[(near.cloud_id == cloud_id) & ~shaft] *= kept
    return out


def gather_inputs(
    state: WeatherState,
    drift: Drift,
    rings: tuple[NearRing, ...],
    sky: SkyParams,
    settings: SceneSettings,
    near_radius_m: float | None = None,
    towers: TowerClock | None = None,
) -> NearInputs:
    """The near layer for `rings` gathered, and what a frame needs of its set made now where
    it is missing (the set, its light, its cells)."""
    radius_m = settings.ring_radius_m if near_radius_m is None else near_radius_m
    near, share, blocks = gather_near_blocks(state, drift, rings, radius_m, settings.max_range_m)
    scattered = None
    if blocks is not None and settings.shading == "harris":
        scattered = near_scattered_light(blocks, near, sky, LIGHT_REUSE_DEG)
    found = None
    if towers is not None and blocks is not None and settings.max_towers > 0:
        found = candidates(blocks, state, towers.epochs)
    return NearInputs(near, share, blocks, scattered, found)


# A sprite's quad reaches 0.71 of its edge from its centre (a corner of the octagon's square):
# the sphere it is culled by is a little larger. It holds every sprite the eye is in or locked
# to (in_cloud's INSIDE_FRAC, UNLOCK_FRAC), so culling never drops the in-cloud fog's colour
# nor a lock.
VIEW_REACH = 0.75


def in_view(
    batch: SpriteBatch, camera: Camera, offsets_m: F64 | None = None
) -> npt.NDArray[np.bool_]:
    """(N,) whether each sprite of the batch may show in the camera's picture (`offsets_m`:
    `eye_offsets` from the camera, if known)."""
    global _last_bounds
    # A near set's sprites keep their sizes frame after frame (each frame's batch shares the
    # set's array), and a camera its field of view: their reach is worked out once.
    tans = (camera.tan_half_fov_x, camera.tan_half_fov_y)
    last = _last_bounds  # one read: another thread may replace it
    if last is not None and last[0] is batch.size_m and last[1] == tans:
        bounds = last[2]
    else:
        bounds = view_bounds(camera, VIEW_REACH * batch.size_m.astype(np.float64))
        bounds.flags.writeable = False
        _last_bounds = (batch.size_m, tans, bounds)
    return spheres_in_view(camera, batch.centre_m, bounds[4], offsets_m, bounds)


_last_bounds: tuple[npt.NDArray[np.float32], tuple[float, float], F64] | None = None


def split_at_distance(
    draw: SpriteDraw, eye_m: tuple[float, float, float], distance_m: float
) -> tuple[SpriteDraw, SpriteDraw]:
    """(behind, in front): a back-to-front draw cut where its sprites come nearer the eye than
    distance_m (Harris's impostor splitting). A camera-facing sprite lies at one depth, so the
    cut never passes through one; drawn one over the other, the two are the whole draw."""
    dist = np.linalg.norm(draw.sprites.centre_m - np.asarray(eye_m), axis=1)  # decreasing
    k = int(np.count_nonzero(dist >= distance_m))

    def part(index: slice) -> SpriteDraw:
        normals = None if draw.normals is None else draw.normals[index]
        return SpriteDraw(draw.sprites.take(np.arange(len(draw))[index]), draw.rgba[index], normals)

    return part(slice(0, k)), part(slice(k, None))
