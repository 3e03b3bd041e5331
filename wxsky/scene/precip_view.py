"""Precipitation as it is drawn (issue 43, items 1 and 2): the rain and snow curtains under
the storms near the eye, and the drops and flakes around the eye.

**Curtains.** Under each cumulonimbus of the near set that sheds rain or snow hangs a curtain:
a column whose extinction falls off across it as the radar's cells and the rate at the eye do
(a Gaussian of the shaft's e-folding radius, `precip_eye.Shaft`), so the eye sees through it
what the rain at that rate leaves: rain's extinction is Marshall & Palmer's 0.365 R^0.63 per
km (`precip_eye.RAIN_SIGMA_PER_KM`) at the core's rate, snow's the handbook's visibility at its
intensity (`precip_eye.SNOW_VISIBILITY_M`). A storm's core (+RA, 45 mm/h) takes 4 per km out of
the light: a curtain a kilometre across hides what stands behind it, a light shower's
(4.5 mm/h) shows the hills through it. The renderer streaks the extinction with falling
bands (`render/shaders/precip.glsl`): thicker and thinner sheets of rain, lighter where
they thin.

**Virga.** Drops falling out of a base into dry air evaporate before they reach the ground.
The fall they survive grows with the rain's rate (bigger drops) and shrinks with the dryness
of the air under the base; as a rule of thumb (drops of a millimetre evaporate within a few
hundred metres in air of 30-40 % humidity, Beard & Pruppacher's ventilated evaporation, and
heavy rain's larger drops fall farther):

    reach_m = VIRGA_REACH_M * rate_mm_h ** 0.25 / (1 - RH)

with RH the surface air's relative humidity (Magnus, from its temperature and dew point). A
curtain whose base stands higher above the ground than that stops short of it, a ragged end
in the air. The thunderstorm preset's moist air (19/17 degC, RH 88 %) lets every drop land.

**At the eye.** Drops (or flakes) in a box about the eye, each a streak the length its
motion relative to the eye sweeps while the eye holds it (`STREAK_S`): the drop's fall
and the wind it drifts in, less the aircraft's own velocity. Flakes fall slowly, tumble and
catch the light as points: their streak is `SNOW_STREAK_SHARE` of a drop's at the same
relative speed. How many: the rate at the eye (`precip_eye.AtEye`) with a square root, so
+RA is denser than RA but not ten times.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.lightning import StormCell
from wxsky.scene.precip_eye import (
    KOSCHMIEDER,
    RAIN_SIGMA_PER_KM,
    SNOW_VISIBILITY_M,
    AtEye,
)
from wxsky.scene.radar import CONVECTIVE_FACTOR, rate_mm_h
from wxsky.scene.rain import Rain
from wxsky.weather.state import CloudType, WeatherState

MAX_CURTAINS = 8  # the nearest curtains drawn; the shader's array size
CURTAIN_RANGE_M = 40_000.0  # farther storms are the ring's (their shafts are sprites there)
VIRGA_REACH_M = 120.0  # the reach formula's scale (module docstring)
# Drops at the eye.
DROP_FALL_MPS = {False: 7.0, True: 1.0}  # rain's terminal speed (2 mm drops), snow's
STREAK_S = 1.0 / 30.0  # what a streak sweeps: the eye's persistence, two display frames
SNOW_STREAK_SHARE = 0.3
DROP_BOX_M = 24.0  # the box of drops about the eye, each side
# Drops in that box at 1 mm/h, and how many drops rise with the rate (a square root). The box
# holds the drops a pilot picks out, not every drop: at +RA (15 mm/h at the eye), standing
# in it, some 3 % of the picture is streak, in flight far more.
DROPS_AT_1_MM_H = 2500.0
MAX_DROPS = 20_000
MAX_SPEED_MPS = 400.0  # faster eye speeds (a jump of the camera) are clamped


@dataclass(frozen=True)
class Curtain:
    """One storm's rain curtain: its axis (ENU, drift applied), e-folding radius, base (its
    top) and lowest reach MSL, extinction per metre on its axis, and whether it is snow."""

    axis_m: tuple[float, float]
    radius_m: float
    top_m: float
    bottom_m: float
    extinction_per_m: float
    snow: bool
    base_radius_m: float = 0.0  # the cloud's base: its underside is drawn dark this wide


@dataclass(frozen=True)
class EyeDrops:
    """What falls about the eye as it is drawn: how many drops in the box, their velocity
    relative to the eye (ENU m/s), a streak's exposure, whether they are flakes."""

    count: int
    relative_mps: tuple[float, float, float]
    streak_s: float
    snow: bool


@dataclass(frozen=True)
class PrecipView:
    """The frame's curtains (nearest first) and drops (None: nothing falls at the eye), and
    the clock the streaks fall by (seconds, wrapped so float32 keeps its detail)."""

    curtains: tuple[Curtain, ...]
    drops: EyeDrops | None
    time_s: float
    # The lowest cloud base MSL (at most the storms'): seen from under it, the curtains are
    # drawn over the clouds up to there, and those clouds cover them above it.
    clip_top_m: float = math.inf
    # Rain from a raining nimbostratus, everywhere under its base: its extinction per metre
    # (0: none) and the base MSL; the ground MSL it falls to.
    veil_per_m: float = 0.0
    veil_top_m: float = 0.0
    ground_m: float = 0.0

    @property
    def drawn(self) -> bool:
        """Whether the curtains' pass has anything to draw (curtains or the veil)."""
        return bool(self.curtains) or self.veil_per_m > 0.0


def relative_humidity(temperature_c: float | None, dewpoint_c: float | None) -> float:
    """The surface air's relative humidity 0..1 (Magnus); 1 when either is unknown."""
    if temperature_c is None or dewpoint_c is None:
        return 1.0

    def es(t: float) -> float:
        return math.exp(17.62 * t / (243.12 + t))

    return min(1.0, es(dewpoint_c) / es(temperature_c))


def reach_m(rate: float, humidity: float) -> float:
    """How far rain at `rate` mm/h falls below its base before it evaporates, in air of
    relative humidity `humidity` (0..1): the module docstring's rule."""
    dry = max(1.0 - humidity, 1e-3)
    return float(VIRGA_REACH_M * max(rate, 0.0) ** 0.25 / dry)


def extinction_per_m(rain: Rain, core_rate: float) -> float:
    """The extinction on a curtain's axis: Marshall-Palmer rain at the core's rate, or the
    handbook's snow at the storm's intensity."""
    if rain.snow:
        xs, ys = zip(*SNOW_VISIBILITY_M, strict=True)
        return KOSCHMIEDER / float(np.interp(min(1.0, rain.intensity), xs, ys))
    a, b = RAIN_SIGMA_PER_KM
    return float(a * core_rate**b / 1000.0)


def curtains(
    state: WeatherState, rain: Rain | None, cells: Sequence[StormCell], eye_m: Sequence[float]
) -> tuple[Curtain, ...]:
    """The curtains under the storm cells within CURTAIN_RANGE_M of the eye, nearest first,
    at most MAX_CURTAINS; none when nothing falls."""
    if rain is None or not cells:
        return ()
    core = rate_mm_h(rain.intensity) * CONVECTIVE_FACTOR
    sigma = extinction_per_m(rain, core)
    humidity = relative_humidity(state.temperature_c, state.dewpoint_c)
    falls_m = reach_m(core, humidity)
    out = []
    for cell in cells:
        d = math.hypot(cell.axis_m[0] - eye_m[0], cell.axis_m[1] - eye_m[1])
        if d > CURTAIN_RANGE_M or cell.formed <= 0.0 or cell.base_m <= cell.ground_m + 1.0:
            continue
        radius = cell.shaft_radius_m(rain.snow)
        out.append(
            (
                d,
                Curtain(
                    axis_m=cell.axis_m,
                    radius_m=max(radius, 100.0),
                    top_m=cell.base_m,
                    bottom_m=max(cell.ground_m, cell.base_m - falls_m),
                    extinction_per_m=sigma * min(1.0, cell.formed),
                    snow=rain.snow,
                    base_radius_m=0.5 * cell.width_m,
                ),
            )
        )
    out.sort(key=lambda p: p[0])
    return tuple(c for _, c in out[:MAX_CURTAINS])


def eye_drops(
    at_eye: AtEye | None,
    eye_velocity_mps: Sequence[float],
    wind_mps: Sequence[float],
) -> EyeDrops | None:
    """The drops drawn about the eye for what falls there; None when nothing does."""
    if at_eye is None or at_eye.kind is None or at_eye.rate_mm_h <= 0.0:
        return None
    snow = at_eye.kind == "snow"
    count = min(MAX_DROPS, round(DROPS_AT_1_MM_H * math.sqrt(at_eye.rate_mm_h)))
    v = [float(x) for x in eye_velocity_mps]
    speed = math.sqrt(sum(x * x for x in v))
    if not math.isfinite(speed):
        v, speed = [0.0, 0.0, 0.0], 0.0
    if speed > MAX_SPEED_MPS:
        v = [x * MAX_SPEED_MPS / speed for x in v]
    fall = DROP_FALL_MPS[snow]
    relative = (
        float(wind_mps[0]) - v[0],
        float(wind_mps[1]) - v[1],
        -fall - v[2],
    )
    streak_s = STREAK_S * (SNOW_STREAK_SHARE if snow else 1.0)
    return EyeDrops(count=count, relative_mps=relative, streak_s=streak_s, snow=snow)


def streak_length_m(drops: EyeDrops) -> float:
    """How long one drop's streak is, metres (its relative speed over the exposure)."""
    return math.sqrt(sum(x * x for x in drops.relative_mps)) * drops.streak_s


def precip_view(
    state: WeatherState,
    rain: Rain | None,
    cells: Sequence[StormCell],
    at_eye: AtEye | None,
    eye_m: Sequence[float],
    eye_velocity_mps: Sequence[float],
    time_s: float,
) -> PrecipView | None:
    """What the frame draws of the precipitation, or None when there is nothing to draw."""
    shown = curtains(state, rain, cells, eye_m)
    drops = eye_drops(at_eye, eye_velocity_mps, state.wind_at(float(eye_m[2])))
    veil_per_m, veil_top_m = veil(state, rain)
    if not shown and drops is None and veil_per_m <= 0.0:
        return None
    bases = [lay.base_m for lay in state.layers]
    clip = min(bases) if bases else math.inf
    return PrecipView(
        curtains=shown,
        drops=drops,
        time_s=time_s % 3600.0,
        clip_top_m=clip,
        veil_per_m=veil_per_m,
        veil_top_m=veil_top_m,
        ground_m=state.observer.alt_m,
    )


def veil(state: WeatherState, rain: Rain | None) -> tuple[float, float]:
    """The rain under a raining nimbostratus as the eye sees it, everywhere under the layer's
    base: (extinction per metre, base MSL), at the rate `precip_eye` gives the eye there (the
    reported rate, as much of it as the layer covers); (0, 0) when none rains."""
    if rain is None:
        return 0.0, 0.0
    best = (0.0, 0.0)
    for layer in state.layers:
        if layer.type is CloudType.NIMBOSTRATUS:
            share = min(1.0, layer.cover_oktas / 8.0)
            sigma = extinction_per_m(rain, rate_mm_h(rain.intensity) * share)
            if rain.snow:  # snow's goes by its intensity: as much of it as the layer covers
                sigma *= share
            if sigma > best[0]:
                best = (sigma, layer.base_m)
    return best


def curtain_opacity(
    view: PrecipView, eye_m: Sequence[float], rays: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """(N,) how much of what lies behind the curtains they hide along each of N unit rays
    (N, 3 ENU) from the eye: precip.glsl's columns at their mean density (its sheets
    average 1), without the haze; for tests and tools, where the shaft is in a picture."""
    ch = np.maximum(np.hypot(rays[:, 0], rays[:, 1]), 1e-4)
    u = rays[:, :2] / ch[:, None]
    slope = rays[:, 2] / ch
    tau = np.zeros(len(rays))
    for c in view.curtains:
        a = np.array([c.axis_m[0] - eye_m[0], c.axis_m[1] - eye_m[1]])
        s0 = u @ a
        off = a[None, :] - s0[:, None] * u
        p2 = np.sum(off * off, axis=1) / (c.radius_m * c.radius_m)
        clip = view.clip_top_m if eye_m[2] < view.clip_top_m else math.inf
        top = min(c.top_m, clip) - eye_m[2]
        bottom = c.bottom_m - eye_m[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            s_top = np.where(np.abs(slope) > 1e-6, top / slope, np.inf)
            s_bottom = np.where(np.abs(slope) > 1e-6, bottom / slope, -np.inf)
        level = np.abs(slope) <= 1e-6
        lo = np.where(level, 0.0, np.maximum(0.0, np.minimum(s_top, s_bottom)))
        hi = np.where(
            level, np.where((top >= 0) & (bottom <= 0), 1e7, 0.0), np.maximum(s_top, s_bottom)
        )
        lo = np.maximum(lo, s0 - 3.0 * c.radius_m)
        hi = np.minimum(hi, s0 + 3.0 * c.radius_m)
        inside = (hi > lo) & (p2 <= 9.0)
        r = c.radius_m
        path = 0.886227 * r * np.exp(-p2) * (_erf((hi - s0) / r) - _erf((lo - s0) / r)) / ch
        tau += np.where(inside, c.extinction_per_m * path, 0.0)
    out: npt.NDArray[np.float64] = 1.0 - np.exp(-tau)
    return out


def _erf(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """erf as precip.glsl takes it (a tanh form, within 4e-4)."""
    out: npt.NDArray[np.float64] = np.tanh(1.1283792 * x + 0.1009109 * x**3)
    return out
