"""The model's column at a place and time (issue 45, docs/weather-aloft.md): winds, temperatures and
humidity by height, the surface, the freezing level and the tropopause.

Interpolation, as the issue asks: bilinear in latitude and longitude between the four grid
points around the place; linear in time between the two forecast steps around the time (no
jump at a step: the weather one second after a step is the step's, moved one second toward the
next); and in height, linear in log-pressure between pressure levels. The levels are kept with
their heights (geopotential height, which within a few metres is height above mean sea level
this low in the atmosphere), so `wind_at` and `height_of_pressure` interpolate in log-pressure
for a height between two levels.

Levels below the ground (a pressure above the surface pressure: the model extrapolates them)
and above `TOP_M` are left out; the model's 10 m wind, where it gives one, is the lowest level.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from datetime import datetime

from wxsky.weather.model_fields import CLOUD_DECKS, ModelStep, bracket, finite
from wxsky.weather.state import WindLayer, dir_from_deg

TOP_M = 30_000.0  # the weather state's highest wind level (ALT_M)
BOTTOM_M = -500.0
KELVIN = 273.15
# A deck pressure the model means (NCEP writes 9.999e20 where a deck has no cloud)
DECK_PA = (1000.0, 110_000.0)


@dataclass(frozen=True)
class ProfileLevel:
    pressure_hpa: float
    height_m: float  # MSL
    u_mps: float  # towards the east
    v_mps: float  # towards the north
    t_k: float
    rh_pct: float | None
    cloud_water_kgkg: float | None = None

    @property
    def speed_mps(self) -> float:
        return math.hypot(self.u_mps, self.v_mps)

    @property
    def dir_deg(self) -> float:
        """Where the wind blows from, degrees true (meteorological)."""
        return dir_from_deg(self.u_mps, self.v_mps)

    def as_json(self) -> dict[str, float | None]:
        return {
            "pressure_hpa": round(self.pressure_hpa, 2),
            "height_m": round(self.height_m, 1),
            "u_mps": round(self.u_mps, 2),
            "v_mps": round(self.v_mps, 2),
            "speed_mps": round(self.speed_mps, 2),
            "dir_deg": round(self.dir_deg, 1),
            "t_k": round(self.t_k, 2),
            "t_c": round(self.t_k - KELVIN, 2),
            "rh_pct": None if self.rh_pct is None else round(self.rh_pct, 1),
        }


@dataclass(frozen=True)
class Deck:
    """One of the model's cloud decks (low, middle, high, convective) at the place."""

    name: str
    cover_pct: float
    base_hpa: float | None
    top_hpa: float | None


@dataclass(frozen=True)
class ModelProfile:
    lat_deg: float
    lon_deg: float
    valid_utc: datetime  # the time the column is for
    steps: tuple[datetime, ...]  # the forecast steps it was interpolated between
    levels: tuple[ProfileLevel, ...]  # from the ground up
    surface_m: float | None
    surface_hpa: float | None
    t2m_k: float | None
    cape_jkg: float | None
    precip_mmph: float | None
    freezing_m: float | None
    tropopause_m: float | None
    tropopause_hpa: float | None
    decks: tuple[Deck, ...]

    def height_of_pressure(self, hpa: float) -> float | None:
        """The height of a pressure, linear in log-pressure between levels; None outside."""
        lv = [lev for lev in self.levels if lev.pressure_hpa > 0]
        for a, b in itertools.pairwise(lv):
            if b.pressure_hpa <= hpa <= a.pressure_hpa:
                f = _log_f(a.pressure_hpa, b.pressure_hpa, hpa)
                return a.height_m + f * (b.height_m - a.height_m)
        return None

    def at_height(self, height_m: float) -> ProfileLevel | None:
        """The column at a height: the two levels around it, in log-pressure (the pressure
        at the height found as the hypsometric equation would between them); the lowest or
        highest level outside."""
        lv = self.levels
        if not lv:
            return None
        if height_m <= lv[0].height_m:
            return lv[0]
        for a, b in itertools.pairwise(lv):
            if a.height_m <= height_m <= b.height_m:
                span = b.height_m - a.height_m
                f = (height_m - a.height_m) / span if span > 0 else 0.0
                # linear in height between two levels is linear in log-pressure for a layer
                # of constant mean temperature; the pressure goes geometrically
                p = math.exp(
                    math.log(a.pressure_hpa) + f * math.log(b.pressure_hpa / a.pressure_hpa)
                )
                return ProfileLevel(
                    p,
                    height_m,
                    a.u_mps + f * (b.u_mps - a.u_mps),
                    a.v_mps + f * (b.v_mps - a.v_mps),
                    a.t_k + f * (b.t_k - a.t_k),
                    _lerp_opt(a.rh_pct, b.rh_pct, f),
                )
        return lv[-1]

    def winds(self) -> tuple[WindLayer, ...]:
        """The profile as the weather state's wind levels (MSL)."""
        out: list[WindLayer] = []
        for lev in self.levels:
            if not BOTTOM_M <= lev.height_m <= TOP_M:
                continue
            speed = min(lev.speed_mps, 150.0)
            out.append(WindLayer(lev.height_m, lev.dir_deg, speed))
        return tuple(out)

    def as_json(self) -> dict[str, object]:
        return {
            "lat_deg": self.lat_deg,
            "lon_deg": self.lon_deg,
            "valid_utc": self.valid_utc.isoformat().replace("+00:00", "Z"),
            "steps_utc": [t.isoformat().replace("+00:00", "Z") for t in self.steps],
            "surface_m": _r(self.surface_m, 1),
            "surface_hpa": _r(self.surface_hpa, 2),
            "t2m_c": _r(None if self.t2m_k is None else self.t2m_k - KELVIN, 2),
            "cape_jkg": _r(self.cape_jkg, 1),
            "precip_mmph": _r(self.precip_mmph, 3),
            "freezing_level_m": _r(self.freezing_m, 1),
            "tropopause_m": _r(self.tropopause_m, 1),
            "tropopause_hpa": _r(self.tropopause_hpa, 2),
            "decks": [
                {
                    "deck": d.name,
                    "cover_pct": round(d.cover_pct, 1),
                    "base_hpa": _r(d.base_hpa, 1),
                    "top_hpa": _r(d.top_hpa, 1),
                    "base_m": _r(
                        None if d.base_hpa is None else self.height_of_pressure(d.base_hpa), 1
                    ),
                    "top_m": _r(
                        None if d.top_hpa is None else self.height_of_pressure(d.top_hpa), 1
                    ),
                }
                for d in self.decks
            ],
            "levels": [lev.as_json() for lev in self.levels],
        }


LAPSE_K_PER_M = 0.0065  # the standard atmosphere's, below a column's lowest level


def temperature_at_height(levels: tuple[tuple[float, float], ...], alt_m: float) -> float | None:
    """The model's temperature (degC) at a height from its ((height_m, degC), ...) from the
    ground up: linear between levels; below the lowest (the model's smoothed ground may stand
    above a valley airfield) the standard lapse rate carries it down; above the highest,
    the highest's. None without levels."""
    if not levels:
        return None
    if alt_m <= levels[0][0]:
        return levels[0][1] + LAPSE_K_PER_M * (levels[0][0] - alt_m)
    for (h0, t0), (h1, t1) in itertools.pairwise(levels):
        if h0 <= alt_m <= h1:
            return t0 + (t1 - t0) * (alt_m - h0) / (h1 - h0) if h1 > h0 else t0
    return levels[-1][1]


def _r(x: float | None, nd: int) -> float | None:
    return None if x is None else round(x, nd)


def _log_f(p_a: float, p_b: float, p: float) -> float:
    den = math.log(p_b / p_a)
    return math.log(p / p_a) / den if den != 0 else 0.0


def _lerp_opt(a: float | None, b: float | None, f: float) -> float | None:
    if a is None or b is None:
        return a if b is None else b
    return a + f * (b - a)


def profile_at(
    steps: dict[datetime, ModelStep], lat_deg: float, lon_deg: float, at_utc: datetime
) -> ModelProfile | None:
    """The column at a place and time from the forecast steps; None when no step has the
    levels a profile needs there."""
    usable = {
        t: s for t, s in steps.items() if s.isobaric_levels_hpa() and s.covers(lat_deg, lon_deg)
    }
    if not usable:
        return None
    times = sorted(usable)
    a, b, w = bracket(times, at_utc)
    pa = _column(usable[a], lat_deg, lon_deg)
    if b == a or w <= 0.0:
        return _profile(pa, lat_deg, lon_deg, at_utc, (a,))
    pb = _column(usable[b], lat_deg, lon_deg)
    return _profile(_mix(pa, pb, w), lat_deg, lon_deg, at_utc, (a, b))


# A column is a flat dict of numbers (None where the model has none): what is mixed in time.
Column = dict[str, float | None]


def _column(step: ModelStep, lat: float, lon: float) -> Column:
    col: Column = {}

    def at(
        name: str, level_type: str, level: float = 0.0, valid: tuple[float, float] | None = None
    ) -> float | None:
        f = step.get(name, level_type, level)
        return None if f is None else finite(f.at(lat, lon, valid))

    for p in step.isobaric_levels_hpa():
        for name in ("u", "v", "t", "gh", "r", "clwmr"):
            col[f"{name}@{p:g}"] = at(name, "isobaric", p)
    for key, (name, lt) in {
        "orog": ("orog", "surface"), "sp": ("sp", "surface"), "cape": ("cape", "surface"),
        "t2m": ("t2m", "surface"), "u10": ("u10", "surface"), "v10": ("v10", "surface"),
        "prate": ("prate", "surface"), "freezing": ("gh", "freezing"),
        "trop_gh": ("gh", "tropopause"), "trop_p": ("pres", "tropopause"),
    }.items():  # fmt: skip
        col[key] = at(name, lt)
    for deck in CLOUD_DECKS:
        col[f"tcc:{deck}"] = at("tcc", f"{deck}_cloud")
        col[f"bot:{deck}"] = at("pres", f"{deck}_cloud_bottom", valid=DECK_PA)
        col[f"top:{deck}"] = at("pres", f"{deck}_cloud_top", valid=DECK_PA)
    return col


def _mix(a: Column, b: Column, w: float) -> Column:
    """Linear in time; a quantity one step lacks is the other's (a deck that forms has no
    base in the step before it: it takes the later step's base as its cover grows)."""
    out: Column = {}
    for key in a.keys() & b.keys():
        va, vb = a[key], b[key]
        if va is None or vb is None:
            out[key] = vb if va is None else va
        else:
            out[key] = va + w * (vb - va)
    return out


def _profile(
    col: Column, lat: float, lon: float, at_utc: datetime, steps: tuple[datetime, ...]
) -> ModelProfile:
    sp_pa = col.get("sp")
    surface_hpa = None if sp_pa is None else sp_pa / 100.0
    levels: list[ProfileLevel] = []
    pressures = sorted({float(k.split("@")[1]) for k in col if k.startswith("u@")}, reverse=True)
    heights = _heights(col, pressures, surface_hpa)
    for p in pressures:
        u, v, t = (col.get(f"{n}@{p:g}") for n in ("u", "v", "t"))
        gh = heights.get(p)
        if u is None or v is None or t is None or gh is None:
            continue
        if surface_hpa is not None and p > surface_hpa:
            continue  # below the ground: extrapolated by the model
        if gh > TOP_M:
            continue
        levels.append(ProfileLevel(p, gh, u, v, t, col.get(f"r@{p:g}"), col.get(f"clwmr@{p:g}")))
    orog = col.get("orog")
    u10, v10, t2m = col.get("u10"), col.get("v10"), col.get("t2m")
    ground = None if orog is None or u10 is None or v10 is None or surface_hpa is None else orog
    if ground is not None and (not levels or levels[0].height_m > ground + 10.0):
        assert orog is not None and u10 is not None and v10 is not None and surface_hpa
        lowest_rh = levels[0].rh_pct if levels else None
        t_k = t2m if t2m is not None else (levels[0].t_k if levels else KELVIN + 15.0)
        levels.insert(0, ProfileLevel(surface_hpa, orog + 10.0, u10, v10, t_k, lowest_rh))
    levels.sort(key=lambda lev: lev.height_m)
    prate = col.get("prate")
    trop_p = col.get("trop_p")
    decks = tuple(
        Deck(
            deck,
            max(0.0, min(100.0, cover)),
            _hpa(col.get(f"bot:{deck}")),
            _hpa(col.get(f"top:{deck}")),
        )
        for deck in CLOUD_DECKS
        if (cover := col.get(f"tcc:{deck}")) is not None
    )
    return ModelProfile(
        lat_deg=lat,
        lon_deg=lon,
        valid_utc=at_utc,
        steps=steps,
        levels=tuple(levels),
        surface_m=orog,
        surface_hpa=surface_hpa,
        t2m_k=t2m,
        cape_jkg=col.get("cape"),
        # kg m-2 s-1 of water is mm/s
        precip_mmph=None if prate is None else max(0.0, prate) * 3600.0,
        freezing_m=col.get("freezing"),
        tropopause_m=col.get("trop_gh"),
        tropopause_hpa=_hpa(trop_p),
        decks=decks,
    )


RD_JKGK = 287.05  # the gas constant of dry air
G0_MPS2 = 9.80665


def _heights(col: Column, pressures: list[float], surface_hpa: float | None) -> dict[float, float]:
    """Each level's height: the model's geopotential height where it gives one; between and
    beyond those, the hypsometric equation through the levels' temperatures (dz = Rd/g0 * T
    * dln p, T the mean of the two levels'), from the nearest level with a height, or from
    the ground (the model's surface height and pressure) where no level has one. Fetching
    `fields = "wind"` gives one level's height only; a file missing some levels' heights is
    mended the same way."""
    temps = {p: col.get(f"t@{p:g}") for p in pressures}
    out = {p: gh for p in pressures if (gh := col.get(f"gh@{p:g}")) is not None}
    orog = col.get("orog")
    if not out and orog is not None and surface_hpa is not None:
        ground_t = col.get("t2m") or next((t for t in temps.values() if t is not None), None)
        below = [p for p in pressures if p <= surface_hpa]
        if ground_t is not None and below and temps.get(below[0]) is not None:
            first = below[0]
            mean_t = 0.5 * (ground_t + float(temps[first] or ground_t))
            out[first] = orog + RD_JKGK / G0_MPS2 * mean_t * math.log(surface_hpa / first)
    if not out:
        # No height anywhere (`fields = "wind"`): the lowest level at its height in the
        # standard atmosphere, off by the day's pressure anomaly (some 8 m a hectopascal)
        known = [p for p in pressures if temps.get(p) is not None]
        if not known:
            return out
        out[known[0]] = _standard_height_m(known[0])
    order = sorted(pressures, reverse=True)  # from the ground up

    def step(a: float, b: float) -> float | None:
        ta, tb = temps.get(a), temps.get(b)
        if ta is None or tb is None or a not in out:
            return None
        return out[a] + RD_JKGK / G0_MPS2 * 0.5 * (ta + tb) * math.log(a / b)

    for i in range(1, len(order)):  # upwards
        if order[i] not in out and (z := step(order[i - 1], order[i])) is not None:
            out[order[i]] = z
    for i in range(len(order) - 2, -1, -1):  # downwards
        if order[i] not in out and (z := step(order[i + 1], order[i])) is not None:
            out[order[i]] = z
    return out


def _standard_height_m(hpa: float) -> float:
    """The ICAO standard atmosphere's height of a pressure in the troposphere."""
    return float(288.15 / 0.0065 * (1.0 - (hpa / 1013.25) ** (RD_JKGK * 0.0065 / G0_MPS2)))


def _hpa(pa: float | None) -> float | None:
    # NCEP writes 9.999e20 (or a bitmap) where a deck has no cloud: not a pressure
    return None if pa is None or not 0.0 < pa < 120_000.0 else pa / 100.0
