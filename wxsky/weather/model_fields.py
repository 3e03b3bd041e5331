"""Numerical weather model fields (GRIB2 data, issue 45) as wxsky holds them: one 2-D field
per (name, level) and valid time on a regular latitude/longitude window, SI units.

The decoder (`wxsky.inputs.grib_decode`, the only eccodes user) turns a model's messages into
these; everything after it is pure. Names are wxsky's own, not one centre's: NCEP, ECMWF and
DWD spell the same quantity differently, and the decoder maps each to these.

Levels (`level_type`; `level` is the pressure in hPa on isobaric levels, else 0):

- `isobaric`: `u`, `v` (m/s), `t` (K), `gh` (geopotential height, m), `r` (%),
  `clwmr` (cloud water, kg/kg);
- `surface`: `orog` (m), `sp` (Pa), `cape` (J/kg), `t2m` (K), `u10`, `v10` (m/s),
  `prate` (kg m-2 s-1);
- `low_cloud`, `middle_cloud`, `high_cloud`, `convective_cloud`: `tcc` (cover, %);
- `low_cloud_top`, `low_cloud_bottom`, ... `convective_cloud_bottom`: `pres` (Pa);
- `tropopause`: `pres` (Pa), `gh` (m); `freezing`: `gh` (m, the 0 degC isotherm).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from datetime import datetime

import numpy as np

CLOUD_DECKS = ("low", "middle", "high", "convective")


@dataclass(frozen=True)
class Grid:
    """A window of a regular latitude/longitude grid: ascending axes in degrees. Longitudes may
    run past 360 or below 0 where a window crosses the grid's seam; `wraps` says the grid
    goes round the earth, so any longitude can be brought into the window's range."""

    lats_deg: np.ndarray  # (ny,) ascending
    lons_deg: np.ndarray  # (nx,) ascending
    wraps: bool

    @property
    def full_circle(self) -> bool:
        """The columns go all the way round: the last one's eastern neighbour is the first."""
        n = len(self.lons_deg)
        if not self.wraps or n < 2:
            return False
        step = float(self.lons_deg[1] - self.lons_deg[0])
        return abs(n * step - 360.0) < 0.5 * step

    def covers(self, lat_deg: float, lon_deg: float) -> bool:
        inside_lat = bool(self.lats_deg[0] <= lat_deg <= self.lats_deg[-1])
        if self.full_circle:
            return inside_lat
        lon = self.local_lon(lon_deg)
        return inside_lat and bool(self.lons_deg[0] <= lon <= self.lons_deg[-1])

    def local_lon(self, lon_deg: float) -> float:
        """`lon_deg` turned by whole turns to fall in the window where it can."""
        if not self.wraps:
            return lon_deg
        lo = float(self.lons_deg[0])
        return lo + (lon_deg - lo) % 360.0

    def weights(self, lat_deg: float, lon_deg: float) -> tuple[int, int, int, int, float, float]:
        """(i, i1, j, j1, fy, fx): the rows and columns around the point and its place
        between them, for bilinear interpolation. The point must be covered; on a grid that
        goes all the way round, the last column's neighbour is the first."""
        lon = self.local_lon(lon_deg)
        i, fy = _cell(self.lats_deg, lat_deg)
        n = len(self.lons_deg)
        if self.full_circle:
            step = float(self.lons_deg[1] - self.lons_deg[0])
            x = (lon - float(self.lons_deg[0])) / step
            j = int(np.floor(x))
            return i, min(i + 1, len(self.lats_deg) - 1), j % n, (j + 1) % n, fy, x - j
        j, fx = _cell(self.lons_deg, lon)
        return i, min(i + 1, len(self.lats_deg) - 1), j, min(j + 1, n - 1), fy, fx


def _cell(axis: np.ndarray, x: float) -> tuple[int, float]:
    n = len(axis)
    if n == 1:
        return 0, 0.0
    k = int(np.searchsorted(axis, x, side="right")) - 1
    k = min(max(k, 0), n - 2)
    span = float(axis[k + 1] - axis[k])
    f = (x - float(axis[k])) / span if span > 0 else 0.0
    return k, min(max(f, 0.0), 1.0)


@dataclass(frozen=True)
class ModelField:
    name: str
    level_type: str
    level: float
    valid_utc: datetime
    grid: Grid
    values: np.ndarray  # (ny, nx) float32, NaN where the model has no value

    @property
    def key(self) -> tuple[str, str, float]:
        return (self.name, self.level_type, self.level)

    def at(self, lat_deg: float, lon_deg: float, valid: tuple[float, float] | None = None) -> float:
        """Bilinear value at a point of the window; NaN where a corner is missing. With
        `valid` (lo, hi), corners outside it are left out and the others' weights scaled up:
        a cloud deck's height exists only where the deck does, and a grid cell at its edge
        must not average a real pressure with the "no cloud" code beside it."""
        i, i1, j, j1, fy, fx = self.grid.weights(lat_deg, lon_deg)
        v = self.values
        corners = (
            (float(v[i, j]), (1.0 - fy) * (1.0 - fx)),
            (float(v[i, j1]), (1.0 - fy) * fx),
            (float(v[i1, j]), fy * (1.0 - fx)),
            (float(v[i1, j1]), fy * fx),
        )
        if valid is None:
            return sum(x * w for x, w in corners)
        lo, hi = valid
        kept = [(x, w) for x, w in corners if lo <= x <= hi]
        total = sum(w for _, w in kept)
        if not kept or total <= 1e-9:
            kept = [(x, 1.0) for x, w in corners if lo <= x <= hi and w > 0.0]
            total = float(len(kept))
        return sum(x * w for x, w in kept) / total if kept else math.nan


@dataclass(frozen=True)
class ModelStep:
    """Every field of one valid time, by key."""

    valid_utc: datetime
    fields: dict[tuple[str, str, float], ModelField]
    sources: tuple[str, ...]  # the files or URLs it came from, for status

    def get(self, name: str, level_type: str, level: float = 0.0) -> ModelField | None:
        return self.fields.get((name, level_type, level))

    def isobaric_levels_hpa(self) -> tuple[float, ...]:
        """Pressure levels holding the whole set a profile needs (u, v, t; heights are
        reckoned where the model gives none), high pressure (low altitude) first."""
        need = ("u", "v", "t")
        levels = {k[2] for k in self.fields if k[1] == "isobaric"}
        full = [p for p in levels if all((n, "isobaric", p) in self.fields for n in need)]
        return tuple(sorted(full, reverse=True))

    def covers(self, lat_deg: float, lon_deg: float) -> bool:
        return all(f.grid.covers(lat_deg, lon_deg) for f in self.fields.values())

    def gaps(self) -> list[str]:
        """The pressure levels that lack part of what a profile needs (u, v, t), one line
        each: such a level is left out of the profile."""
        need = ("u", "v", "t")
        levels = sorted({k[2] for k in self.fields if k[1] == "isobaric"}, reverse=True)
        out = []
        for p in levels:
            have = [n for n in need if (n, "isobaric", p) in self.fields]
            if have and len(have) < len(need):
                missing = [n for n in need if n not in have]
                out.append(
                    f"{self.valid_utc.isoformat().replace('+00:00', 'Z')} {p:g} hPa: "
                    f"{', '.join(have)} but no {', '.join(missing)}; the level left out"
                )
        return out


def merge_steps(fields: list[ModelField], sources: tuple[str, ...]) -> dict[datetime, ModelStep]:
    """Fields grouped by valid time; a later field with the same key replaces an earlier."""
    by_time: dict[datetime, dict[tuple[str, str, float], ModelField]] = {}
    for f in fields:
        by_time.setdefault(f.valid_utc, {})[f.key] = f
    return {t: ModelStep(t, fs, sources) for t, fs in sorted(by_time.items())}


def bracket(times: list[datetime], at_utc: datetime) -> tuple[datetime, datetime, float]:
    """The two valid times around `at_utc` and the weight of the later (0..1); before the
    first or after the last time, that time alone (weight 0). `times` ascending, not empty."""
    if at_utc <= times[0]:
        return times[0], times[0], 0.0
    if at_utc >= times[-1]:
        return times[-1], times[-1], 0.0
    for a, b in itertools.pairwise(times):
        if a <= at_utc <= b:
            span = (b - a).total_seconds()
            w = (at_utc - a).total_seconds() / span if span > 0 else 0.0
            return a, b, w
    raise AssertionError("unreachable: times must be ascending")


def finite(x: float) -> float | None:
    return x if math.isfinite(x) else None
