"""Turbulence for a host's flight model (issue 45, docs/weather-aloft.md): how rough the air is at a
point, and the gust there, so the aircraft flies in the weather its pilot sees.

**Intensity.** The vertical gust's standard deviation `sigma_w` adds, in variance, what each
cause gives (figures after MIL-F-8785C and the ICAO turbulence categories: light under about
1.5 m/s, moderate 1.5..3, severe above):

- clear air: `CLEAR_AIR_MPS`;
- near the ground (under `LOW_ALTITUDE_M` above it): 0.1 x the wind speed there (MIL-F-8785C's
  low-altitude model, sigma_w = 0.1 W20), fading to nothing at `LOW_ALTITUDE_M`;
- wind shear: `SHEAR_SCALE_M` x the change of wind with height (s-1) around the point;
- in cloud: `IN_CLOUD_MPS` for the cloud's type (stratus smooth, cumulus bumpy, cumulonimbus
  severe);
- near a cumulonimbus layer: `NEAR_CB_MPS` x its cover in eighths, fading over `NEAR_CB_M`
  above and below the layer.

**Gusts.** Frozen turbulence (Taylor's hypothesis), as the Dryden model is meant: the gusts
are a function of the distance the aircraft has flown through the air mass (its path relative
to the air, so a faster aircraft meets shorter gusts, and one standing in a wind meets the
air going by). Each component is a sum of `MODES` cosines of that distance, wavenumbers
spread from 20 km to 10 m, with random phases from the sky's seed (the same sky, the same
gusts), their amplitudes following the Dryden spectra (MIL-F-8785C) with the scale lengths of
the height above ground (533 m above 600 m; smaller near the ground), scaled so each
component's variance is its sigma squared. Pure; numpy.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from wxsky.weather.state import CloudType, WeatherState

CLEAR_AIR_MPS = 0.3
LOW_ALTITUDE_M = 300.0
SHEAR_SCALE_M = 30.0
SHEAR_SPAN_M = 150.0  # the shear is the wind's change over this much above and below
NEAR_CB_MPS = 3.0
NEAR_CB_M = 2000.0
HIGH_L_M = 533.0  # 1750 ft: Dryden's scale length above 2000 ft
LOW_L_TOP_M = 600.0
MODES = 64
K_MIN = 2.0 * math.pi / 20_000.0  # rad/m: gusts from 20 km ...
K_MAX = 2.0 * math.pi / 10.0  # ... down to 10 m

IN_CLOUD_MPS: Mapping[CloudType, float] = MappingProxyType(
    {
        CloudType.NONE: 0.0,
        CloudType.ALTOCUMULUS: 1.2,
        CloudType.ALTOSTRATUS: 0.6,
        CloudType.CIRROCUMULUS: 0.8,
        CloudType.CIRROSTRATUS: 0.4,
        CloudType.CIRRUS: 0.4,
        CloudType.CUMULONIMBUS: 6.0,
        CloudType.CUMULUS: 2.5,
        CloudType.NIMBOSTRATUS: 1.2,
        CloudType.STRATOCUMULUS: 1.0,
        CloudType.STRATUS: 0.5,
    }
)


@dataclass(frozen=True)
class Roughness:
    sigma_w_mps: float  # the vertical gust's standard deviation
    causes: Mapping[str, float]  # each cause's sigma, for status and tests

    @property
    def category(self) -> str:
        s = self.sigma_w_mps
        return "none" if s < 0.5 else "light" if s < 1.5 else "moderate" if s < 3.0 else "severe"


def roughness(
    state: WeatherState, alt_m: float, ground_m: float, cloud_type: CloudType | None
) -> Roughness:
    """How rough the air is at a height (MSL) over ground at `ground_m`, in a cloud of
    `cloud_type` (None: clear air)."""
    causes: dict[str, float] = {"clear_air": CLEAR_AIR_MPS}
    agl = max(0.0, alt_m - ground_m)
    if agl < LOW_ALTITUDE_M:
        e, n = state.wind_at(ground_m + 6.0)
        causes["low_altitude"] = 0.1 * math.hypot(e, n) * (1.0 - agl / LOW_ALTITUDE_M)
    e1, n1 = state.wind_at(alt_m + SHEAR_SPAN_M)
    e0, n0 = state.wind_at(max(ground_m, alt_m - SHEAR_SPAN_M))
    dz = alt_m + SHEAR_SPAN_M - max(ground_m, alt_m - SHEAR_SPAN_M)
    if dz > 0:
        causes["shear"] = SHEAR_SCALE_M * math.hypot(e1 - e0, n1 - n0) / dz
    if cloud_type is not None:
        causes["in_cloud"] = IN_CLOUD_MPS[cloud_type]
    near = 0.0
    for lay in state.layers:
        if lay.type is not CloudType.CUMULONIMBUS or lay.cover_oktas <= 0:
            continue
        gap = max(0.0, lay.base_m - alt_m, alt_m - lay.top_m)
        near = max(near, NEAR_CB_MPS * lay.cover_oktas / 8.0 * max(0.0, 1.0 - gap / NEAR_CB_M))
    if near > 0:
        causes["near_cumulonimbus"] = near
    sigma = math.sqrt(sum(v * v for v in causes.values()))
    return Roughness(sigma, MappingProxyType(causes))


def scale_lengths_m(agl_m: float) -> tuple[float, float]:
    """(L_u, L_w) of the Dryden spectra at a height above ground (MIL-F-8785C's low-altitude
    forms below 600 m, in feet inside; 533 m above)."""
    if agl_m >= LOW_L_TOP_M:
        return HIGH_L_M, HIGH_L_M
    h_ft = max(agl_m, 3.0) / 0.3048
    lu_ft = h_ft / (0.177 + 0.000823 * h_ft) ** 1.2
    return lu_ft * 0.3048, h_ft * 0.3048


def sigma_ratio(agl_m: float) -> float:
    """sigma_u / sigma_w: 1 aloft; larger near the ground (MIL-F-8785C)."""
    if agl_m >= LOW_L_TOP_M:
        return 1.0
    h_ft = max(agl_m, 3.0) / 0.3048
    return float(1.0 / (0.177 + 0.000823 * h_ft) ** 0.4)


@functools.lru_cache(maxsize=8)
def _modes(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k (MODES,), phases (3, MODES), dk (MODES,)) of the seed's gusts."""
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x7475_7262])  # "turb"
    k = np.geomspace(K_MIN, K_MAX, MODES)
    edges = np.sqrt(k[:-1] * k[1:])
    dk = np.diff(np.concatenate(([K_MIN], edges, [K_MAX])))
    phases = rng.uniform(0.0, 2.0 * math.pi, size=(3, MODES))
    return k, phases, dk


def _amplitudes(k: np.ndarray, dk: np.ndarray, length_m: float, vertical: bool) -> np.ndarray:
    """Each mode's share of the variance (summing to 1) under a Dryden spectrum."""
    lk2 = (length_m * k) ** 2
    psd = (1.0 + 3.0 * lk2) / (1.0 + lk2) ** 2 if vertical else 1.0 / (1.0 + lk2)
    share = psd * dk
    return np.asarray(share / share.sum())


def gust_mps(
    seed: int, flown_m: float, sigma_w_mps: float, agl_m: float
) -> tuple[float, float, float]:
    """(along, across, up) gust, metres a second, after `flown_m` metres through the air:
    along and across the aircraft's path through the air, and up."""
    if sigma_w_mps <= 0.0:
        return 0.0, 0.0, 0.0
    k, phases, dk = _modes(seed)
    lu, lw = scale_lengths_m(agl_m)
    su = sigma_w_mps * sigma_ratio(agl_m)
    out = []
    components = ((su, lu, False), (su, lu, True), (sigma_w_mps, lw, True))
    for c, (sigma, length, transverse) in enumerate(components):
        share = _amplitudes(k, dk, length, transverse)
        # a cosine's variance is half its amplitude squared
        amp = sigma * np.sqrt(2.0 * share)
        out.append(float(np.sum(amp * np.cos(k * flown_m + phases[c]))))
    return out[0], out[1], out[2]


def icing(in_cloud: bool, temperature_c: float) -> bool:
    """Airframe icing: supercooled water, in cloud between -20 and 0 degC."""
    return in_cloud and -20.0 <= temperature_c <= 0.0
