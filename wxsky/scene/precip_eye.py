"""Precipitation at the eye (issue 43, item 2, first part): what falls where the camera is,
how hard, and how far one sees in it, for the host's windshield, sound and fog.

The eye is in the precipitation when it is under a raining cloud and below its base: in a
cumulonimbus's shaft (its core's rate, falling off across the shaft as the radar's cells do,
`radar.py`: the same clouds, the same Gaussian) or under a raining nimbostratus layer. The
rate is the weather's (METAR intensity, CIGI precipitation: `rain.rain_of`), a storm's core
CONVECTIVE_FACTOR times it.

How far one sees in it (the meteorological optical range, Koschmieder's 3.912 over the
extinction), the precipitation's extinction added to the air's (the weather's visibility):
- rain: the Marshall & Palmer (1948) drop sizes, N(D) = 8000 exp(-4.1 R^-0.21 D) m^-3 mm^-1,
  each drop taking twice its cross-section out of the light (large-drop extinction), give
  sigma = pi N0 / Lambda^3 = 0.365 R^0.63 per km: 2.5 mm/h alone leaves 6.0 km, 10 mm/h
  2.5 km, 50 mm/h 0.9 km;
- snow: the US Federal Meteorological Handbook No. 1 defines snow's intensity by the
  visibility it leaves: light more than 1/2 statute mile, moderate 1/4 to 1/2, heavy 1/4 or
  less; the middles of those bands, 1200, 600 and 300 m, at its light, moderate and heavy
  rates, in between as the intensity goes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from wxsky.scene.radar import CONVECTIVE_FACTOR, rate_mm_h
from wxsky.scene.rain import rain_of
from wxsky.weather.state import CloudType, WeatherState

KOSCHMIEDER = 3.912
# Rain's extinction per km at 1 mm/h and its exponent (derived above).
RAIN_SIGMA_PER_KM = (0.365, 0.63)
# Snow: visibility at each intensity (rain.INTENSITY's 0..1), metres.
SNOW_VISIBILITY_M = ((0.35, 1200.0), (0.65, 600.0), (1.0, 300.0))
INSIDE_MM_H = 0.1  # less than this at the eye is no precipitation there


@dataclass(frozen=True)
class Shaft:
    """A raining cumulonimbus's shaft: its base's middle (ENU, drift applied), the shaft's
    e-folding radius and the cloud's base MSL."""

    axis_m: tuple[float, float]
    radius_m: float
    base_m: float


@dataclass(frozen=True)
class AtEye:
    """What falls at the eye: `kind` "rain", "snow" or None; rate in mm/h (melted for
    snow); METAR-like intensity "-", "" or "+" (None when nothing falls); how far one sees."""

    kind: str | None
    rate_mm_h: float
    intensity: str | None
    visibility_m: float

    def to_dict(self) -> dict[str, object]:
        return {
            "precipitation": self.kind,
            "rate_mm_h": self.rate_mm_h,
            "intensity": self.intensity,
            "visibility_m": self.visibility_m,
        }


def rain_visibility_m(rate: float, air_m: float) -> float:
    """How far one sees in rain at `rate` mm/h in air of visibility `air_m`."""
    a, b = RAIN_SIGMA_PER_KM
    sigma_per_m = KOSCHMIEDER / max(air_m, 1.0) + a * math.pow(max(rate, 0.0), b) / 1000.0
    return KOSCHMIEDER / sigma_per_m


def snow_visibility_m(intensity: float, air_m: float) -> float:
    """How far one sees in snow of this intensity (0..1) in air of visibility `air_m`."""
    xs, ys = zip(*SNOW_VISIBILITY_M, strict=True)
    alone = float(np.interp(intensity, xs, ys))
    return 1.0 / (1.0 / alone + 1.0 / max(air_m, 1.0))


def precipitation_at(
    state: WeatherState, eye_m: tuple[float, float, float], shafts: Sequence[Shaft]
) -> AtEye:
    """What falls at the eye under the weather `state` and these cumulonimbus shafts."""
    air_m = state.visibility_m
    rain = rain_of(state)
    if rain is None:
        return AtEye(None, 0.0, None, air_m)
    core = rate_mm_h(rain.intensity)
    rate = 0.0
    for shaft in shafts:
        if eye_m[2] < shaft.base_m:
            d = math.hypot(eye_m[0] - shaft.axis_m[0], eye_m[1] - shaft.axis_m[1])
            across = math.exp(-((d / max(shaft.radius_m, 1.0)) ** 2))
            rate = max(rate, core * CONVECTIVE_FACTOR * across)
    for layer in state.layers:
        if layer.type is CloudType.NIMBOSTRATUS and eye_m[2] < layer.base_m:
            rate = max(rate, core * min(1.0, layer.cover_oktas / 8.0))
    if rate < INSIDE_MM_H:
        return AtEye(None, 0.0, None, air_m)
    if rain.snow:
        share = min(1.0, rain.intensity * rate / max(core, 1e-6))
        seen = snow_visibility_m(share, air_m)
        # The handbook names snow by what it leaves to see, of the snow alone.
        alone = 1.0 / max(1.0 / seen - 1.0 / max(air_m, 1.0), 1e-9)
        label = "+" if alone <= 400.0 else "" if alone <= 800.0 else "-"
        return AtEye("snow", rate, label, seen)
    # Rain by its rate: light up to 2.5 mm/h, moderate to 7.6, heavy above (the handbook).
    label = "-" if rate <= 2.5 else "" if rate <= 7.6 else "+"
    return AtEye("rain", rate, label, rain_visibility_m(rate, air_m))
