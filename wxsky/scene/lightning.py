"""Lightning (issue 43, item 4): flashes in the cumulonimbus cells near the eye, deterministic
from the sky's seed and the simulated time, so every display channel showing the same sky at
the same moment shows the same flash.

Each storm cell (a cumulonimbus of the near layer: `tower_field.Candidate`, where its tower
stands, drift applied) flashes as a Poisson process at RATE_PER_MIN for the storm's strength
(METAR `-TS`, `TS`, `+TS`), in SLOT_S slots of simulated time each drawn from its own stream
(seed, cell, slot): the same flashes whichever frames ask, in whatever order. A flash is
intra-cloud (IC_SHARE of them: a glow inside the cloud, 5-8 km up) or cloud-to-ground (a
channel from the cloud's base to the ground, 1-4 return strokes 40-80 ms apart); its light at
a moment is `glow`. Typical rates (Williams 2001; ordinary storms 1-5 flashes a minute,
severe ones tens) give the three strengths' rates.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.rain import SHAFT_RADIUS_FRAC, weather_group
from wxsky.weather.state import WeatherState

F64 = npt.NDArray[np.float64]

SLOT_S = 10.0  # simulated seconds a stream of flashes covers
# Flashes a minute in each storm cell: a thunderstorm reported light, moderate, heavy.
RATE_PER_MIN = {"-": 1.0, "": 3.0, "+": 8.0}
# The most flashes a minute a cell a config may ask for (`[lightning] flashes_per_min`): a
# severe storm's tens (Williams 2001), with room; past it a cell is a strobe, not a storm.
MAX_RATE_PER_MIN = 60.0
IC_SHARE = 0.7  # most flashes stay in the cloud (Williams 2001: 3-4 IC to 1 CG)
LONGEST_S = 1.0  # no flash lights the sky longer (its glow is 0 past its last stroke)
RETURN_STROKES = (1, 4)
STROKE_GAP_S = (0.04, 0.08)
STROKE_S = 0.03  # a return stroke's light; a continuing current glows dimmer after the last
IC_GLOW_S = (0.15, 0.45)
# How far a flash lights its cloud (e-folding, metres) and its light's colour (display units,
# added to what the cloud shows there at full intensity).
REACH_M = 4000.0
FLASH_RGB = (0.85, 0.9, 1.0)
MAX_LIT = 4  # flashes lit in one frame at most (the brightest)


@dataclass(frozen=True)
class Flash:
    """One flash: `id` the same in every process for the same sky; times in simulated
    seconds since the Unix epoch; `position_m` where it lights the cloud (ENU, up MSL): for a
    cloud-to-ground flash the channel runs from there straight down to `ground_m`."""

    id: int
    start_s: float
    kind: str  # "intra_cloud" or "cloud_to_ground"
    position_m: tuple[float, float, float]
    ground_m: float
    intensity: float  # 0..1
    strokes: tuple[tuple[float, float, float], ...]  # (offset s, duration s, brightness 0..1)

    def glow(self, time_s: float) -> float:
        """Its light at `time_s` (0..1 of `intensity`): each stroke's, while it lasts."""
        t = time_s - self.start_s
        lit = 0.0
        for offset, duration, brightness in self.strokes:
            if offset <= t < offset + duration:
                lit = max(lit, brightness)
        return lit * self.intensity

    def to_dict(self) -> dict[str, object]:
        """As the stream's `lightning` notification carries it (docs/protocol.md)."""
        return {
            "id": self.id,
            "start_s": self.start_s,
            "kind": self.kind,
            "position_m": list(self.position_m),
            "ground_m": self.ground_m,
            "intensity": self.intensity,
            "strokes": [list(s) for s in self.strokes],
        }


@dataclass(frozen=True)
class StormCell:
    """A cumulonimbus that flashes: its cloud's id, its base's middle (ENU, drift applied),
    its base and top MSL, how far it has formed (0..1)."""

    cloud_id: int
    axis_m: tuple[float, float]
    base_m: float
    top_m: float
    formed: float
    ground_m: float = 0.0
    width_m: float = 0.0  # its base's width (the rain shaft under it: `precip_eye.Shaft`)

    def shaft_radius_m(self, snow: bool) -> float:
        """The e-folding radius of the rain (or snow) shaft under its base: the one the rate
        at the eye, the radar and the drawn curtain share."""
        return SHAFT_RADIUS_FRAC[snow] * 0.5 * self.width_m


def storm_rate_per_min(state: WeatherState, override_per_min: float | None = None) -> float:
    """Flashes a minute per storm cell from the strongest thunderstorm the weather reports
    (0: none). `VCTS` (in the vicinity) counts as a light one. `override_per_min` (the
    config's `[lightning] flashes_per_min`; None: by the storm's strength) is every storm
    cell's rate while the weather reports a thunderstorm: it sets how often, never whether."""
    best = 0.0
    for group in state.present_weather:
        prefix, codes = weather_group(group)
        if "TS" not in codes:
            continue
        rate = RATE_PER_MIN["-" if "VC" in codes else prefix]
        best = max(best, rate)
    if best > 0.0 and override_per_min is not None:
        return override_per_min
    return best


def flashes_between(
    cells: Iterable[StormCell], seed: int, rate_per_min: float, t0_s: float, t1_s: float
) -> list[Flash]:
    """Every flash of these cells starting at or after `t0_s` and before `t1_s`, by start."""
    if rate_per_min <= 0.0 or t1_s <= t0_s:
        return []
    out: list[Flash] = []
    first, last = math.floor(t0_s / SLOT_S), math.floor(t1_s / SLOT_S)
    for cell in cells:
        # Formation in twentieths: a cover moving by a hair keeps the slot's flashes.
        formed = round(cell.formed * 20.0) / 20.0
        if formed <= 0.0:
            continue
        for slot in range(first, last + 1):
            for flash in _slot_flashes(
                seed, cell.cloud_id, slot, rate_per_min, formed, cell.base_m, cell.top_m
            ):
                if t0_s <= flash.start_s < t1_s:
                    # Drawn about the cell's axis: the flash rides with the cloud's drift.
                    dx, dy, z = flash.position_m
                    out.append(
                        dataclasses.replace(
                            flash,
                            position_m=(cell.axis_m[0] + dx, cell.axis_m[1] + dy, z),
                            ground_m=cell.ground_m,
                        )
                    )
    out.sort(key=lambda f: (f.start_s, f.id))
    return out


def lit_flashes(
    cells: Iterable[StormCell], seed: int, rate_per_min: float, time_s: float
) -> list[tuple[Flash, float]]:
    """The flashes lighting the sky at `time_s`, with their glow: the MAX_LIT brightest."""
    cells = tuple(cells)
    lit = [
        (f, g)
        for f in flashes_between(cells, seed, rate_per_min, time_s - LONGEST_S, time_s + 1e-9)
        if (g := f.glow(time_s)) > 0.0
    ]
    lit.sort(key=lambda fg: -fg[1])
    return lit[:MAX_LIT]


@functools.lru_cache(maxsize=4096)
def _slot_flashes(
    seed: int,
    cloud_id: int,
    slot: int,
    rate_per_min: float,
    formed: float,
    base_m: float,
    top_m: float,
) -> tuple[Flash, ...]:
    """A cell's flashes in one slot, their positions about its axis (x, y from it, z MSL)."""
    words = [seed & 0xFFFFFFFF, seed >> 32, cloud_id & 0xFFFFFFFF, (cloud_id >> 32) & 0x7FFFFFFF]
    rng = np.random.default_rng(np.random.SeedSequence([*words, slot + 2**40]))
    count = int(rng.poisson(rate_per_min / 60.0 * SLOT_S * formed))
    out = []
    depth = max(top_m - base_m, 1.0)
    radius = 0.25 * depth  # within a quarter of the storm's height of its axis
    for k in range(count):
        start = (slot + float(rng.uniform())) * SLOT_S
        ic = bool(rng.uniform() < IC_SHARE)
        angle, reach = rng.uniform(0.0, 2.0 * math.pi), radius * math.sqrt(rng.uniform())
        x, y = reach * math.cos(angle), reach * math.sin(angle)
        intensity = float(rng.uniform(0.5, 1.0))
        strokes: list[tuple[float, float, float]]
        if ic:
            z = base_m + depth * float(rng.uniform(0.35, 0.6))
            glow_s = float(rng.uniform(*IC_GLOW_S))
            # Two or three pulses, the middle one brightest.
            pulses = int(rng.integers(2, 4))
            strokes = [
                (glow_s * i / pulses, glow_s / pulses, 0.6 + 0.4 * (i == pulses // 2))
                for i in range(pulses)
            ]
        else:
            z = base_m + depth * float(rng.uniform(0.1, 0.3))
            n = int(rng.integers(RETURN_STROKES[0], RETURN_STROKES[1] + 1))
            strokes, t = [], 0.0
            for i in range(n):
                strokes.append((t, STROKE_S, 1.0 if i == 0 else float(rng.uniform(0.5, 0.9))))
                t += STROKE_S + float(rng.uniform(*STROKE_GAP_S))
            strokes.append((t, 0.1, 0.3))  # the continuing current's dim glow
        flash_id = (cloud_id * 1_000_003 + slot * 101 + k) & 0x7FFF_FFFF_FFFF_FFFF
        out.append(
            Flash(
                id=int(flash_id),
                start_s=start,
                kind="intra_cloud" if ic else "cloud_to_ground",
                position_m=(x, y, z),
                ground_m=0.0,
                intensity=intensity,
                strokes=tuple(strokes),
            )
        )
    return tuple(out)


def flash_light(lit: Iterable[tuple[Flash, float]], points_m: npt.NDArray[np.float64]) -> F64:
    """(N,) how much each point (N, 3 ENU) is lit by these flashes (0..~1: add FLASH_RGB
    times it to a cloud's colour there)."""
    out: F64 = np.zeros(len(points_m))
    for flash, glow in lit:
        d2 = np.sum((points_m - np.asarray(flash.position_m)) ** 2, axis=1)
        out += glow * np.exp(-d2 / (REACH_M * REACH_M))
    return out
