"""Cloud shadows on the ground: a top-down map of how much direct sunlight the cloud field lets
through, for a host to darken its terrain under the clouds (docs/protocol.md §1.5 `shadow`,
§3, "Cloud shadows").

The map lies on a horizontal plane at `centre_m[2]` (the observer's ground altitude), centred
on the ring's centre, `size_m` on a side, `px` x `px` texels, row 0 the north edge and column
0 the west edge. Texel (row i, column j) is the point

    east  = centre_e - size_m / 2 + (j + 0.5) size_m / px
    north = centre_n + size_m / 2 - (i + 0.5) size_m / px

and holds T = exp(-tau), tau the clouds' optical depth along the line through that point in
the sun's direction s. A host finds the shadow at a terrain point P by moving P along s to the
plane, Q = P + s (plane_up - P_up) / s_up, and sampling the map at Q. The value is exact at the
texel centres (not a texel average).

The sun: with the sun below the horizon there is no direct sunlight to shade and the map is
all 1. A sun lower than MIN_SUN_ELEVATION_DEG is taken at that elevation (same azimuth, and
the record says so): the footprints of a grazing sun stretch across the whole cloud field,
which multiplies the work, for light a host's n.s term has all but taken away already.

Density model: the cloud shading's (Harris, `scattering` and `shading_harris`). Sprite k is a
sphere of radius r_k = SHADOW_REACH size_k casting the optical depth

    tau_k(d) = s_k (1 - d^2 / r_k^2)  for d < r_k,     s_k = -ln pass_on(tau_of(k)),

on a line passing d from its centre: the kernel with which it shades the particles below it,
so the ground under a cloud gets the light the cloud's base gets. tau_k is the chord integral
of the density rho(x) = 2 s_k / (pi r_k) sqrt(1 - |x|^2 / r_k^2), the field the tests march a
ray through. Depths of overlapping sprites add; a sprite counts whole (the clouds lie above
the plane).

The sum over sprites is splatted exactly. Seen along a sun ray, a sphere's footprint on the
plane is an ellipse stretched 1 / sin(elevation) along the sun's azimuth; on each texel row it
crosses, tau_k is a quadratic in the column over one interval of columns. Its three
coefficients go into difference arrays at the interval's ends and a cumulative sum along each
row adds every sprite up, so the cost goes with the rows the footprints cross, not with their
area. Rows run along whichever map axis is nearer the sun's azimuth, which keeps footprints
short across them.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from datetime import datetime

import numpy as np
import numpy.typing as npt

from wxsky.scene.cloud_model_files import default_models
from wxsky.scene.cloud_models import CloudModel
from wxsky.scene.clouds import BLOCK_SIZE_M, SpriteBatch, layer_keys
from wxsky.scene.formation import layer_block
from wxsky.scene.gather import CancelFlag, check_cancel
from wxsky.scene.scattering import pass_on
from wxsky.scene.shading_harris import SHADOW_REACH, tau_of
from wxsky.weather.state import CloudLayer, WeatherState

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]
ArrayF = npt.NDArray[np.floating]

SHADOW_MAP_PX = 512
MIN_SUN_ELEVATION_DEG = 3.0
# Row-and-sprite pairs splatted at once: bounds the working memory (about 100 bytes a pair)
# when a low sun stretches every footprint across hundreds of rows.
_CHUNK_PAIRS = 1 << 20
_serials = itertools.count(1)


@dataclass(frozen=True)
class CloudShadow:
    """One shadow map and where it lies: built with a ring, on its worker thread."""

    transmittance: F32  # (px, px), row 0 the north edge, column 0 the west edge
    centre_m: tuple[float, float, float]  # map centre (east, north) at time_utc; up: the plane
    size_m: float  # edge length of the square map
    sun_direction_enu: tuple[float, float, float]  # the sun the map was made for (unit)
    time_utc: datetime  # when the clouds stood where the map has them
    # The drift velocity (east, north) of the layer that casts most of the shadow: between
    # rebuilds the map moves with it (`centre_at`), so shadows keep under their clouds.
    velocity_mps: tuple[float, float] = (0.0, 0.0)
    # Different for every map made in this process, increasing: the record's shadow_version.
    serial: int = field(init=False)
    rgba: U8 = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "serial", next(_serials))
        # The segment layer's pixels (protocol §1.5): R = G = B = round(255 T), A = 255.
        # Made here, on the ring worker, so a frame only copies them.
        t8 = np.round(np.clip(self.transmittance, 0.0, 1.0) * 255.0).astype(np.uint8)
        rgba = np.empty((*t8.shape, 4), np.uint8)
        rgba[..., :3] = t8[..., None]
        rgba[..., 3] = 255
        rgba.flags.writeable = False
        object.__setattr__(self, "rgba", rgba)

    @property
    def px(self) -> int:
        return int(self.transmittance.shape[0])

    def centre_at(self, time_utc: datetime) -> tuple[float, float, float]:
        """The map's centre at another time: moved on with the clouds (drift is the wind's
        velocity times the time, so this holds across a set clock too)."""
        dt_s = (time_utc - self.time_utc).total_seconds()
        ve, vn = self.velocity_mps
        e, n, up = self.centre_m
        return (e + ve * dt_s, n + vn * dt_s, up)


def sprite_spheres(batch: SpriteBatch) -> tuple[F64, F64]:
    """(N,) radius_m and (N,) optical depth through the centre of each sprite's sphere, as the
    cloud shading has them (module doc)."""
    radius: F64 = SHADOW_REACH * np.asarray(batch.size_m, np.float64)
    depth: F64 = -np.log(np.maximum(pass_on(tau_of(batch)), 1e-30))
    return radius, depth


def map_sun(sun_direction_enu: tuple[float, float, float]) -> tuple[float, float, float]:
    """The sun a map is made for: the sun itself, raised to MIN_SUN_ELEVATION_DEG when it
    stands lower but above the horizon (module doc); unit length."""
    s = unit_sun(sun_direction_enu)
    low = math.sin(math.radians(MIN_SUN_ELEVATION_DEG))
    if 0.0 < s[2] < low:
        horizontal = math.hypot(s[0], s[1])
        scale = math.cos(math.radians(MIN_SUN_ELEVATION_DEG)) / horizontal
        s = np.array([s[0] * scale, s[1] * scale, low])
    return (float(s[0]), float(s[1]), float(s[2]))


def unit_sun(sun_direction_enu: ArrayF | tuple[float, float, float]) -> F64:
    """The sun direction as a unit vector; ValueError for a non-finite or zero one."""
    s = np.asarray(sun_direction_enu, np.float64).reshape(3)
    norm = float(np.linalg.norm(s))
    if not np.all(np.isfinite(s)) or not norm > 0.0:
        raise ValueError(f"sun direction must be finite and non-zero, got {s.tolist()}")
    out: F64 = s / norm
    return out


def optical_depth_along(
    points_m: ArrayF, centre_m: ArrayF, radius_m: ArrayF, depth: ArrayF, sun_direction_enu: ArrayF
) -> F64:
    """(...) optical depth of the spheres along the line through each point (..., 3) in the
    sun's direction: the closed form, summed sphere by sphere (a reference for the map and for
    single points; costs points x spheres)."""
    s = unit_sun(sun_direction_enu)
    p = np.asarray(points_m, np.float64)
    c = np.asarray(centre_m, np.float64).reshape(-1, 3)
    r = np.asarray(radius_m, np.float64).reshape(-1)
    k = np.asarray(depth, np.float64).reshape(-1)
    w = c - p[..., None, :]  # (..., N, 3)
    along = w @ s
    d2 = np.einsum("...i,...i->...", w, w) - along * along
    share = np.maximum(0.0, 1.0 - d2 / np.maximum(r * r, 1e-300))
    out: F64 = np.sum(k * share, axis=-1)
    return out


def transmittance_map(
    centre_m: ArrayF,
    radius_m: ArrayF,
    depth: ArrayF,
    sun_direction_enu: ArrayF | tuple[float, float, float],
    map_centre_m: tuple[float, float, float],
    size_m: float,
    px: int,
) -> F32:
    """(px, px) T = exp(-tau) at the texel centres of the map (module doc) for spheres with
    centres (N, 3), radii (N,) and optical depths through their centres (N,)."""
    if px < 1 or not (math.isfinite(size_m) and size_m > 0.0):
        raise ValueError(f"shadow map must have px >= 1 and size_m > 0, got {px}, {size_m}")
    if not all(math.isfinite(v) for v in map_centre_m):
        raise ValueError(f"shadow map centre must be finite, got {map_centre_m}")
    s = unit_sun(sun_direction_enu)
    if s[2] <= 0.0:  # no direct sunlight to shade
        return np.ones((px, px), np.float32)
    c = np.asarray(centre_m, np.float64).reshape(-1, 3)
    r = np.asarray(radius_m, np.float64).reshape(-1)
    k = np.asarray(depth, np.float64).reshape(-1)
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(r)) and np.all(np.isfinite(k))):
        raise ValueError("sphere centres, radii and depths must be finite")
    texel_m = size_m / px
    east0, north0, plane_m = map_centre_m
    h = (c[:, 2] - plane_m) / s[2]
    # Each sphere's shadow centre in texel coordinates: column a (east, texel j at a = j) and
    # row b (south, texel i at b = i); the sun's horizontal parts along +a and +b.
    a = (c[:, 0] - s[0] * h - (east0 - 0.5 * size_m)) / texel_m - 0.5
    b = ((north0 + 0.5 * size_m) - (c[:, 1] - s[1] * h)) / texel_m - 0.5
    sa, sb = float(s[0]), float(-s[1])
    rho = r / texel_m
    if abs(sa) >= abs(sb):
        tau = _splat(a, b, sa, sb, float(s[2]), rho, k, px)
    else:  # rows along the north-south axis: the same sum on the transposed map
        tau = _splat(b, a, sb, sa, float(s[2]), rho, k, px).T
    out: F32 = np.exp(-np.maximum(tau, 0.0)).astype(np.float32)
    return out


def _splat(a: F64, b: F64, sa: float, sb: float, sz: float, rho: F64, s: F64, n: int) -> F64:
    """(n, n) optical depth, [line i, position j], of footprints centred at (a, b) in texels
    (a along the lines, b across them), radius rho texels, depth s at the centre, for a sun
    whose horizontal components along a and b are sa and sb and vertical one sz.

    The squared distance (in texels) of sphere k's centre from the sun ray through texel
    (i, j) is, with da = j - a, db = i - b and A = 1 - sa^2,
        Q = A da^2 - 2 sa sb da db + (1 - sb^2) db^2 = A (j - m)^2 + (sz db)^2 / A,
        m = a + sa sb db / A,
    so on line i the sphere adds s (1 - Q / rho^2), a quadratic in j, where Q < rho^2: over
    |j - m| < sqrt(A rho^2 - (sz db)^2) / A, and on the lines |db| < rho sqrt(A) / sz."""
    coef = np.zeros((3, n * (n + 1)))
    big_a = 1.0 - sa * sa  # >= sz^2 > 0
    half_b = rho * math.sqrt(big_a) / sz  # the ellipse's extent across the lines
    half_a = rho * math.sqrt(1.0 - sb * sb) / sz
    hit = (
        (s > 0.0)
        & (rho > 0.0)
        & (a + half_a >= 0.0)
        & (a - half_a <= n - 1)
        & (b + half_b >= 0.0)
        & (b - half_b <= n - 1)
    )
    a, b, rho, s, half_b = a[hit], b[hit], rho[hit], s[hit], half_b[hit]
    first = np.maximum(np.ceil(b - half_b), 0.0).astype(np.int64)
    last = np.minimum(np.floor(b + half_b), n - 1.0).astype(np.int64)
    rows = np.maximum(last - first + 1, 0)
    ends = np.cumsum(rows)
    lo = 0
    while lo < len(rows):
        # Whole sprites, a chunk of (sprite, line) pairs at a time.
        done = int(ends[lo - 1]) if lo else 0
        hi = max(int(np.searchsorted(ends, done + _CHUNK_PAIRS, side="right")), lo + 1)
        sl = slice(lo, hi)
        _splat_lines(coef, n, a[sl], b[sl], rho[sl], s[sl], first[sl], rows[sl], big_a, sa * sb, sz)
        lo = hi
    fields = np.cumsum(coef.reshape(3, n, n + 1)[:, :, :n], axis=2)
    j = np.arange(n, dtype=np.float64)
    out: F64 = fields[0] + fields[1] * j + fields[2] * (j * j)
    return out


def _splat_lines(
    coef: F64,
    n: int,
    a: F64,
    b: F64,
    rho: F64,
    s: F64,
    first: npt.NDArray[np.int64],
    rows: npt.NDArray[np.int64],
    big_a: float,
    sab: float,
    sz: float,
) -> None:
    """Add these sprites' difference-array entries, rows[k] lines from line first[k] each,
    to coef (3, n (n + 1)): +c at the interval's first texel, -c after its last."""
    total = int(rows.sum())
    if total == 0:
        return
    # Per sprite, then per (sprite, line) pair.
    g = s / (rho * rho)
    c2 = -g * big_a
    i = np.arange(total) + np.repeat(first - (np.cumsum(rows) - rows), rows)
    db = i - np.repeat(b, rows)
    m = np.repeat(a, rows) + (sab / big_a) * db
    across = (sz * db) ** 2
    half = np.sqrt(np.maximum(np.repeat(big_a * rho * rho, rows) - across, 0.0)) / big_a
    j0 = np.maximum(np.ceil(m - half), 0.0).astype(np.int64)
    j1 = np.minimum(np.floor(m + half), n - 1.0).astype(np.int64)
    ok = (half > 0.0) & (j0 <= j1)
    c2k = np.repeat(c2, rows)
    # s (1 - Q / rho^2) = c0 + c1 j + c2 j^2
    c0 = np.repeat(s, rows) - np.repeat(g, rows) * across / big_a + c2k * m * m
    c1 = -2.0 * c2k * m
    row0 = i * (n + 1)
    where = np.concatenate([(row0 + j0)[ok], (row0 + j1 + 1)[ok]])
    for slot, c in enumerate((c0, c1, c2k)):
        c = c[ok]
        coef[slot] += np.bincount(where, weights=np.concatenate([c, -c]), minlength=coef.shape[1])


# -- the clouds that cast the map's shadows ------------------------------------------------


def shadow_casters(
    state: WeatherState,
    drift: tuple[tuple[float, float], ...],
    map_centre_m: tuple[float, float, float],
    size_m: float,
    sun_direction_enu: tuple[float, float, float],
    max_range_m: float,
    cancel: CancelFlag | None = None,
) -> list[tuple[int, SpriteBatch]]:
    """(layer index, sprites) of every block, among those the scene draws (nearest point
    within max_range_m of the map's centre), whose clouds may shade the map: the blocks
    under it and, with a low sun, those farther away whose shadows are cast into it."""
    s = unit_sun(sun_direction_enu)
    if s[2] <= 0.0:
        return []
    if len(drift) != len(state.layers):
        drift = tuple((0.0, 0.0) for _ in state.layers)
    east0, north0, plane_m = map_centre_m
    half = 0.5 * size_m
    # A sphere's footprint spans r times these east and north of its shadow centre.
    reach_e = math.sqrt(max(0.0, 1.0 - s[1] * s[1])) / s[2]
    reach_n = math.sqrt(max(0.0, 1.0 - s[0] * s[0])) / s[2]
    out: list[tuple[int, SpriteBatch]] = []
    for li, (key, layer, (dx, dy)) in enumerate(
        zip(layer_keys(state.layers), state.layers, drift, strict=True)
    ):
        if layer.cover_oktas <= 0.0:
            continue
        overhang_m, radius_m = layer_reach(layer)
        # A sprite at height h shades the map if its centre lies over the map moved towards
        # the sun by (h - plane) / tan(elevation), give or take its footprint.
        shift = [(h - plane_m) / s[2] for h in (layer.base_m, layer.top_m)]
        shift_e, shift_n = [s[0] * v for v in shift], [s[1] * v for v in shift]
        pad_e = overhang_m + radius_m * reach_e
        pad_n = overhang_m + radius_m * reach_n
        # In the layer's drifting frame, where its blocks are fixed.
        qx, qy = east0 - dx, north0 - dy
        e0, e1 = qx - half + min(shift_e) - pad_e, qx + half + max(shift_e) + pad_e
        n0, n1 = qy - half + min(shift_n) - pad_n, qy + half + max(shift_n) + pad_n
        parts = []
        for by in range(math.floor(n0 / BLOCK_SIZE_M), math.floor(n1 / BLOCK_SIZE_M) + 1):
            for bx in range(math.floor(e0 / BLOCK_SIZE_M), math.floor(e1 / BLOCK_SIZE_M) + 1):
                near_x = min(max(qx, bx * BLOCK_SIZE_M), (bx + 1) * BLOCK_SIZE_M)
                near_y = min(max(qy, by * BLOCK_SIZE_M), (by + 1) * BLOCK_SIZE_M)
                if math.hypot(near_x - qx, near_y - qy) >= max_range_m:
                    continue
                check_cancel(cancel)
                block = layer_block(bx, by, key, layer, state.seed, (dx, dy))
                if len(block):
                    parts.append(block)
        if parts:
            out.append((li, SpriteBatch.concat(parts)))
    return out


def layer_reach(layer: CloudLayer) -> tuple[float, float]:
    """(overhang_m, radius_m): how far a sprite's centre may lie outside its block, and the
    largest shadow sphere radius, for the layer's cloud models (bounds that pick the blocks
    to read; the test holds them to the generated clouds)."""
    overhang, radius = 0.0, 0.0
    for model, _ in default_models().blend_for_layer(layer.type, layer.thickness_m):
        o, r = _model_reach(model)
        overhang, radius = max(overhang, o), max(radius, r)
    return overhang, radius


def _model_reach(model: CloudModel) -> tuple[float, float]:
    cell_m = BLOCK_SIZE_M / max(1, round(BLOCK_SIZE_M / model.cell_m))
    width_m = cell_m * model.width_frac[1]
    # Sprite centres lie within a box's half extents of its centre (a lattice's jitter moves
    # them at most a lattice step more); the box centres lie at cloud-width offsets.
    box_m = max(
        max(abs(box.centre[0]), abs(box.centre[1]))
        + (0.5 + box.grid_jitter) * max(box.width[1], box.depth[1])
        for box in model.boxes
    )
    axis_out_m = max(0.0, (model.jitter_frac - 0.5) * cell_m)
    size_m = width_m * max(box.sprite_size[1] for box in model.boxes)
    return axis_out_m + box_m * width_m, SHADOW_REACH * size_m


def cloud_shadow(
    state: WeatherState,
    drift: tuple[tuple[float, float], ...],
    centre_m: tuple[float, float, float],
    sun_direction_enu: tuple[float, float, float],
    size_m: float,
    px: int,
    max_range_m: float,
    cancel: CancelFlag | None = None,
) -> CloudShadow:
    """The shadow map of the clouds `state` and `drift` place, centred over centre_m (its up
    is ignored: the map lies on the observer's ground altitude), for this sun. Raises
    BuildCancelled between blocks once `cancel` is set (`gather.check_cancel`)."""
    sun = map_sun(sun_direction_enu)
    plane = (float(centre_m[0]), float(centre_m[1]), float(state.observer.alt_m))
    casters = shadow_casters(state, drift, plane, size_m, sun, max_range_m, cancel)
    check_cancel(cancel)
    velocity = (0.0, 0.0)
    if casters:
        sprites = SpriteBatch.concat([batch for _, batch in casters])
        radius, depth = sprite_spheres(sprites)
        t = transmittance_map(sprites.centre_m, radius, depth, sun, plane, size_m, px)
        # The layer casting most shadow (depth times footprint area, r^2) sets the drift.
        bounds = np.cumsum([len(batch) for _, batch in casters])[:-1]
        weight = [float(np.sum(w)) for w in np.split(depth * radius * radius, bounds)]
        layer = state.layers[casters[int(np.argmax(weight))][0]]
        velocity = state.wind_at(0.5 * (layer.base_m + layer.top_m))
    else:
        t = np.ones((px, px), np.float32)
    return CloudShadow(
        transmittance=t,
        centre_m=plane,
        size_m=float(size_m),
        sun_direction_enu=sun,
        time_utc=state.time_utc,
        velocity_mps=(float(velocity[0]), float(velocity[1])),
    )
