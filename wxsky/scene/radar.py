"""Weather radar (issue 43, item 5): a plan-position picture of reflectivity (dBZ) around the
aircraft, computed from the very clouds that are drawn.

Every cumulonimbus and nimbostratus cloud of the applied weather (the layers whose clouds shed
rain and snow shafts, `rain.SHAFT_TYPES`) is a precipitation cell where its block puts it
(`clouds.block_layout`: the same draws that place its sprites), moved by its layer's drift and
formed as far as the layer's cover forms it (`formation`'s rule, cloud by cloud). A cell's
core falls at the rate the weather reports (METAR intensity or CIGI precipitation, `rain`);
a cumulonimbus's core at CONVECTIVE_FACTOR times it, and at a moderate rate where nothing is
reported (a radar sees a storm's core before its rain reaches a station). Across a cell the
reflectivity falls off as a Gaussian over the shaft's radius (`rain.SHAFT_RADIUS_FRAC` of
the base's); up it holds to the freezing level and falls FALL_DB_PER_KM above it, to the
layer's top.

Published relations, all in SI but where the literature states mm/h and dB/km:
- rain: Z = 200 R^1.6 (Marshall & Palmer 1948), Z in mm^6 m^-3, R in mm/h;
- snow: Z = 2000 R^2 (Gunn & Marshall 1958, R the melted rate);
- attenuation at X band, where airborne weather radars work: k = 0.01217 R^1.2571 dB/km
  (ITU-R P.838-3, 10 GHz, horizontal polarisation), two-way along the beam;
- the beam's height: h = h0 + r sin(tilt) + r^2 / (2 k_e R_e), k_e = 4/3 (the standard
  refraction of the 4/3 Earth).

The picture is north-up, the aircraft at its middle, `size_px` square over twice the range,
each pixel the reflectivity at its middle (cells smaller than a pixel keep their integral:
`_splat`). Clear air reads NOISE_DBZ.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.cloud_model_files import default_models
from wxsky.scene.cloud_models import CloudModel, CloudModels
from wxsky.scene.clouds import BLOCK_SIZE_M, BlockLayout, block_layout, layer_keys
from wxsky.scene.formation import progress_of_ranks
from wxsky.scene.rain import SHAFT_RADIUS_FRAC, SHAFT_TYPES, rain_of
from wxsky.weather.state import CloudType, WeatherState

F64 = npt.NDArray[np.float64]

NM_M = 1852.0
RANGE_NM = (10.0, 320.0)
TILT_DEG = (-15.0, 15.0)
SIZE_PX = (64, 1024)
NOISE_DBZ = -30.0  # clear air, and the floor of the picture
# A picture's bytes: dBZ = byte x DBZ_STEP + DBZ_OFFSET (0: DBZ_OFFSET or less).
DBZ_OFFSET = -32.0
DBZ_STEP = 0.5
# The core's rain at each METAR intensity, mm/h: the middle of the US Federal Meteorological
# Handbook No. 1's bands for rain (light up to 2.5 mm/h, moderate 2.6-7.6, heavy above),
# keyed by `rain.INTENSITY`'s 0..1.
RATE_MM_H = ((0.35, 1.5), (0.65, 5.0), (1.0, 15.0))
CONVECTIVE_FACTOR = 3.0  # a cumulonimbus's core over the rain the station reports
UNREPORTED_INTENSITY = 0.65  # a cumulonimbus's core where no rain is reported: moderate
Z_RAIN = (200.0, 1.6)
Z_SNOW = (2000.0, 2.0)
ATTENUATION = (0.01217, 1.2571)  # dB/km = a R^b at 10 GHz
FALL_DB_PER_KM = 6.0  # above the freezing level, ice reflects less
LAPSE_K_PER_M = 0.0065
EARTH_RADIUS_M = 6_371_000.0
K_EFFECTIVE = 4.0 / 3.0
# A nimbostratus cloud's echo over its half width (its lattice's clouds overlap into a deck).
STRATIFORM_RADIUS_FRAC = 1.0
# Cells are looked for this far past the picture's edge (their Gaussians reach in).
MARGIN_M = 8_000.0


def rate_mm_h(intensity: float) -> float:
    """The core rate for `rain.Rain.intensity` (0..1), between the handbook's bands."""
    xs, ys = zip(*RATE_MM_H, strict=True)
    return float(np.interp(intensity, xs, ys))


def z_of_rate(rate: F64, snow: bool) -> F64:
    """Linear reflectivity (mm^6 m^-3) of a rate (mm/h)."""
    a, b = Z_SNOW if snow else Z_RAIN
    out: F64 = a * np.power(np.maximum(rate, 0.0), b)
    return out


def rate_of_z(z: F64) -> F64:
    """The rain rate (mm/h) a linear reflectivity stands for (Marshall & Palmer inverted)."""
    a, b = Z_RAIN
    out: F64 = np.power(np.maximum(z, 0.0) / a, 1.0 / b)
    return out


@dataclass(frozen=True)
class RadarCells:
    """Precipitation cells of one layer, in the ENU frame (drift applied)."""

    centre_m: F64  # (K, 2)
    radius_m: F64  # (K,) the Gaussian's e-folding radius
    z_core: F64  # (K,) linear reflectivity at the core (formation applied)
    ground_m: float
    freeze_m: float
    top_m: float


@dataclass(frozen=True)
class RadarPicture:
    """A plan-position picture: dBZ per pixel, rows from north to south, columns west to
    east, the aircraft at the middle."""

    dbz: F64  # (size_px, size_px)
    range_m: float
    tilt_deg: float
    centre_m: tuple[float, float, float]

    def to_bytes(self) -> bytes:
        """One byte a pixel, (dBZ - DBZ_OFFSET) / DBZ_STEP, clipped to 0..255."""
        scaled = np.round((self.dbz - DBZ_OFFSET) / DBZ_STEP)
        return bytes(np.clip(scaled, 0, 255).astype(np.uint8))


def layer_cells(
    state: WeatherState,
    index: int,
    drift_m: tuple[float, float],
    centre_m: tuple[float, float],
    reach_m: float,
    models: CloudModels | None = None,
) -> RadarCells | None:
    """The precipitation cells of layer `index` within `reach_m` of `centre_m` (ENU), or None
    when the layer sheds nothing the radar sees."""
    layer = state.layers[index]
    if layer.type not in SHAFT_TYPES:
        return None
    rain = rain_of(state)
    convective = layer.type is CloudType.CUMULONIMBUS
    if rain is None and not convective:
        return None
    intensity = rain.intensity if rain is not None else UNREPORTED_INTENSITY
    snow = rain.snow if rain is not None else False
    rate = rate_mm_h(intensity) * (CONVECTIVE_FACTOR if convective else 1.0)
    key = layer_keys(state.layers)[index]
    blend = (models or default_models()).blend_for_layer(layer.type, layer.thickness_m)
    # The layer's drifting frame: its clouds stand at their block's places plus the drift.
    cx, cy = centre_m[0] - drift_m[0], centre_m[1] - drift_m[1]
    lo_x = math.floor((cx - reach_m) / BLOCK_SIZE_M)
    hi_x = math.floor((cx + reach_m) / BLOCK_SIZE_M)
    lo_y = math.floor((cy - reach_m) / BLOCK_SIZE_M)
    hi_y = math.floor((cy + reach_m) / BLOCK_SIZE_M)
    centres, radii, cores = [], [], []
    for model, weight in blend:
        for bx in range(lo_x, hi_x + 1):
            for by in range(lo_y, hi_y + 1):
                lay = _layout(bx, by, key, model, layer.thickness_m, state.seed)
                formed = _formed(lay, model, layer.cover_oktas * weight)
                keep = formed > 0.0
                if not keep.any():
                    continue
                centres.append(lay.axis_m[keep])
                # A storm's core is its shaft; a nimbostratus's rain falls from all of it,
                # the clouds of its lattice overlapping into one even echo.
                share = SHAFT_RADIUS_FRAC[snow] if convective else STRATIFORM_RADIUS_FRAC
                radii.append(share * 0.5 * lay.width_m[keep])
                cores.append(z_of_rate(rate * formed[keep], snow))
    if not centres:
        return None
    ground_m = state.observer.alt_m
    temperature_c = 15.0 if state.temperature_c is None else state.temperature_c
    return RadarCells(
        centre_m=np.concatenate(centres) + np.array(drift_m),
        radius_m=np.concatenate(radii),
        z_core=np.concatenate(cores),
        ground_m=ground_m,
        freeze_m=ground_m + max(temperature_c, 0.0) / LAPSE_K_PER_M,
        top_m=layer.top_m,
    )


# About a kilobyte a block: 8192 of them cover a 200 km square of one-cloud blocks.
@functools.lru_cache(maxsize=8192)
def _layout(
    bx: int, by: int, key: int, model: CloudModel, thickness_m: float, seed: int
) -> BlockLayout:
    return block_layout(bx, by, key, model, thickness_m, seed)


def _formed(lay: BlockLayout, model: CloudModel, cover_oktas: float) -> F64:
    """How far each cloud of a block has formed at this cover (formation's rule)."""
    return progress_of_ranks(
        lay.rank, lay.rank_offset, len(lay.rank), model.formation_spread_oktas, cover_oktas
    )


def beam_height_m(range_m: F64, antenna_m: float, tilt_deg: float) -> F64:
    """The beam's middle at each ground range, MSL (the 4/3 Earth)."""
    out: F64 = (
        antenna_m
        + range_m * math.sin(math.radians(tilt_deg))
        + range_m * range_m / (2.0 * K_EFFECTIVE * EARTH_RADIUS_M)
    )
    return out


def vertical_share(cells: RadarCells, height_m: F64) -> F64:
    """A layer's reflectivity at these heights over its cores' (0..1): full from the ground to
    the freezing level, falling FALL_DB_PER_KM above it, none under the ground or over the
    layer's top."""
    above = np.maximum(height_m - cells.freeze_m, 0.0)
    share: F64 = np.power(10.0, -0.1 * FALL_DB_PER_KM * above / 1000.0)
    inside = (height_m >= cells.ground_m) & (height_m <= cells.top_m)
    out: F64 = np.where(inside, share, 0.0)
    return out


def ppi(
    layers: Sequence[RadarCells],
    centre_m: tuple[float, float, float],
    range_m: float,
    tilt_deg: float,
    size_px: int,
    attenuate: bool = True,
) -> RadarPicture:
    """The plan-position picture of these cells from an aircraft at `centre_m` (ENU, up MSL);
    `attenuate` False: the reflectivity itself, as no rain between dims it (tests, tools)."""
    pixel_m = 2.0 * range_m / size_px
    offsets = (np.arange(size_px) + 0.5) * pixel_m - range_m
    east = centre_m[0] + offsets[None, :]
    north = centre_m[1] - offsets[:, None]
    ground_range = np.hypot(east - centre_m[0], north - centre_m[1])
    height = beam_height_m(ground_range, centre_m[2], tilt_deg)
    z = np.zeros((size_px, size_px))
    for cells in layers:
        horizontal = _splat(cells, centre_m, range_m, size_px)
        z += horizontal * vertical_share(cells, height)
    if attenuate:
        z *= _two_way_loss(z, range_m, size_px)
    dbz = np.maximum(10.0 * np.log10(np.maximum(z, 1e-12)), NOISE_DBZ)
    return RadarPicture(dbz, range_m, tilt_deg, centre_m)


def _splat(
    cells: RadarCells, centre_m: tuple[float, float, float], range_m: float, size_px: int
) -> F64:
    """(size_px, size_px) the cells' linear reflectivity at each pixel's middle, each cell a
    Gaussian widened by half a pixel and lowered to keep its integral: a cell smaller than a
    pixel still counts there with its whole area, not only where a pixel's middle falls in."""
    pixel_m = 2.0 * range_m / size_px
    out = np.zeros((size_px, size_px))
    rel = cells.centre_m - np.array(centre_m[:2])
    near = np.all(np.abs(rel) < range_m + MARGIN_M, axis=1)
    if not near.any():
        return out
    rel, radius, core = rel[near], cells.radius_m[near], cells.z_core[near]
    wide = np.sqrt(radius * radius + (0.5 * pixel_m) ** 2)
    peak = core * (radius / wide) ** 2
    col = (rel[:, 0] + range_m) / pixel_m - 0.5
    row = (range_m - rel[:, 1]) / pixel_m - 0.5
    reach = max(1, math.ceil(3.0 * float(wide.max()) / pixel_m))
    steps = np.arange(-reach, reach + 1)
    dr, dc = np.meshgrid(steps, steps, indexing="ij")
    rows = np.round(row)[:, None] + dr.reshape(-1)[None, :]
    cols = np.round(col)[:, None] + dc.reshape(-1)[None, :]
    dist2 = ((rows - row[:, None]) ** 2 + (cols - col[:, None]) ** 2) * pixel_m * pixel_m
    value = peak[:, None] * np.exp(-dist2 / (wide * wide)[:, None])
    inside = (rows >= 0) & (rows < size_px) & (cols >= 0) & (cols < size_px)
    np.add.at(out, (rows[inside].astype(np.intp), cols[inside].astype(np.intp)), value[inside])
    return out


def _two_way_loss(z: F64, range_m: float, size_px: int) -> F64:
    """(size_px, size_px) the share of the echo left after the rain between the aircraft and
    each pixel, both ways: the picture's rain rate sampled along 4 x size_px radials."""
    half = size_px / 2.0
    n_az = 4 * size_px
    n_r = size_px
    az = (np.arange(n_az) + 0.5) * (2.0 * math.pi / n_az)
    r_px = (np.arange(n_r) + 0.5) * (half / n_r)
    rows = np.clip((half - np.cos(az)[:, None] * r_px[None, :]).astype(np.intp), 0, size_px - 1)
    cols = np.clip((half + np.sin(az)[:, None] * r_px[None, :]).astype(np.intp), 0, size_px - 1)
    a, b = ATTENUATION
    step_km = range_m / n_r / 1000.0
    db = np.cumsum(a * np.power(rate_of_z(z[rows, cols]), b) * step_km, axis=1)
    # Each pixel takes the loss of the radial bin nearest it, up to the bin before its own.
    dy = half - (np.arange(size_px) + 0.5)
    dx = (np.arange(size_px) + 0.5) - half
    pr = np.hypot(dx[None, :], dy[:, None])
    pa = np.mod(np.arctan2(dx[None, :], dy[:, None]), 2.0 * math.pi)
    ai = np.clip((pa / (2.0 * math.pi) * n_az).astype(np.intp), 0, n_az - 1)
    ri = np.clip((pr / half * n_r).astype(np.intp) - 1, -1, n_r - 1)
    loss_db = np.where(ri >= 0, db[ai, np.maximum(ri, 0)], 0.0)
    out: F64 = np.power(10.0, -0.1 * 2.0 * loss_db)
    return out


def radar_picture(
    state: WeatherState,
    drift: Sequence[tuple[float, float]],
    centre_m: tuple[float, float, float],
    range_nm: float,
    tilt_deg: float,
    size_px: int,
    models: CloudModels | None = None,
    attenuate: bool = True,
) -> RadarPicture:
    """The weather radar's picture of the applied weather `state`, its layers moved by
    `drift` (the engine's, one per layer), from an aircraft at `centre_m`."""
    if not RANGE_NM[0] <= range_nm <= RANGE_NM[1]:
        raise ValueError(f"range_nm must be in {RANGE_NM[0]:g}..{RANGE_NM[1]:g}, got {range_nm}")
    if not TILT_DEG[0] <= tilt_deg <= TILT_DEG[1]:
        raise ValueError(f"tilt_deg must be in {TILT_DEG[0]:g}..{TILT_DEG[1]:g}, got {tilt_deg}")
    if not SIZE_PX[0] <= size_px <= SIZE_PX[1]:
        raise ValueError(f"size_px must be in {SIZE_PX[0]}..{SIZE_PX[1]}, got {size_px}")
    range_m = range_nm * NM_M
    cells = [
        c
        for i in range(len(state.layers))
        if (
            c := layer_cells(
                state, i, drift[i], (centre_m[0], centre_m[1]), range_m + MARGIN_M, models
            )
        )
        is not None
    ]
    return ppi(cells, centre_m, range_m, tilt_deg, size_px, attenuate)
