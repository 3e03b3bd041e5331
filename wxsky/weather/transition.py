"""Move the applied weather toward the target at bounded rates, so the sky changes the way
weather does: clouds form and dissipate over minutes, bases creep, wind veers over seconds.

Cloud layers are paired by type (each applied layer with the target layer of its type nearest
in base); a target layer without a partner forms from zero cover at its own base, an applied
layer without one dissipates to zero cover and is then removed. A type change is therefore a
dissipation plus a formation, never a switch of every cloud at once. Wind moves as a velocity
vector at each target level, so a direction change turns through the shorter way and a calm
never flips the direction. Observer, seed, present weather, precipitation and fog change at
once: they are not physical quantities that drift. Everything here is pure:
(applied, target, dt) -> applied.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from wxsky.weather.state import MAX_LAYERS, CloudLayer, WeatherState, WindLayer, dir_from_deg

MIN_THICKNESS_M = 10.0


@dataclass(frozen=True)
class TransitionRates:
    """The fastest each quantity may change. Zero or less means "at once"."""

    cover_oktas_per_min: float = 2.0
    base_m_per_min: float = 300.0
    wind_mps_per_s: float = 1.0  # change of the wind vector, gusts likewise
    visibility_m_per_s: float = 100.0
    temperature_c_per_min: float = 2.0
    qnh_hpa_per_min: float = 2.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not math.isfinite(value):
                raise ValueError(f"transition {f.name} must be finite, got {value}")


INSTANT = TransitionRates(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def step_toward(
    applied: WeatherState, target: WeatherState, dt_s: float, rates: TransitionRates
) -> WeatherState:
    """The applied weather dt_s seconds later. The clock (time_utc) is the applied state's."""
    dt_s = max(0.0, dt_s)
    dt_min = dt_s / 60.0
    temp_step = _rate_step(rates.temperature_c_per_min, dt_min)
    t = target
    return dataclasses.replace(
        applied,
        observer=t.observer,
        seed=t.seed,
        present_weather=t.present_weather,
        precipitation=t.precipitation,
        fog=t.fog,
        sources=t.sources,
        layers=_step_layers(applied.layers, t.layers, dt_s, rates),
        wind=_step_wind(applied, t.wind, dt_s, rates.wind_mps_per_s),
        visibility_m=_approach(
            applied.visibility_m, t.visibility_m, _rate_step(rates.visibility_m_per_s, dt_s)
        ),
        temperature_c=_approach_optional(applied.temperature_c, t.temperature_c, temp_step),
        dewpoint_c=_approach_optional(applied.dewpoint_c, t.dewpoint_c, temp_step),
        qnh_hpa=_approach(applied.qnh_hpa, t.qnh_hpa, _rate_step(rates.qnh_hpa_per_min, dt_min)),
    )


def settled(applied: WeatherState, target: WeatherState) -> bool:
    """True when the applied weather has reached the target (the clock aside)."""
    return dataclasses.replace(applied, time_utc=target.time_utc) == target


def _approach(current: float, goal: float, max_step: float) -> float:
    if abs(goal - current) <= max_step:
        return goal
    return current + math.copysign(max_step, goal - current)


def _approach_optional(current: float | None, goal: float | None, max_step: float) -> float | None:
    if current is None or goal is None:
        return goal
    return _approach(current, goal, max_step)


def _rate_step(rate: float, dt: float) -> float:
    """The largest change allowed in dt (in the rate's time unit); infinite for an instant
    (non-positive) rate."""
    return math.inf if rate <= 0.0 else rate * dt


def _step_layers(
    applied: tuple[CloudLayer, ...],
    target: tuple[CloudLayer, ...],
    dt_s: float,
    rates: TransitionRates,
) -> tuple[CloudLayer, ...]:
    cover_step = _rate_step(rates.cover_oktas_per_min, dt_s / 60.0)
    height_step = _rate_step(rates.base_m_per_min, dt_s / 60.0)
    pairs = pair_layers(applied, target)
    out: list[tuple[bool, CloudLayer]] = []  # (still wanted, layer)
    for now, goal in pairs:
        if now is None:
            assert goal is not None
            now = dataclasses.replace(goal, cover_oktas=0.0)
        goal_cover = 0.0 if goal is None else goal.cover_oktas
        goal_base = now.base_m if goal is None else goal.base_m
        goal_top = now.top_m if goal is None else goal.top_m
        cover = _approach(now.cover_oktas, goal_cover, cover_step)
        if goal is None and cover <= 0.0:
            continue  # fully dissipated
        base = _approach(now.base_m, goal_base, height_step)
        top = max(_approach(now.top_m, goal_top, height_step), base + MIN_THICKNESS_M)
        out.append((goal is not None, CloudLayer(cover, base, top, now.type)))
    if len(out) > MAX_LAYERS:
        # More layers than the state holds while old ones dissipate and new ones form: the
        # thinnest dissipating layers go first (they are nearly invisible already).
        out.sort(key=lambda item: (item[0], item[1].cover_oktas))
        out = out[len(out) - MAX_LAYERS :]
    return tuple(sorted((lay for _, lay in out), key=lambda lay: lay.base_m))


def pair_layers(
    applied: tuple[CloudLayer, ...], target: tuple[CloudLayer, ...]
) -> list[tuple[CloudLayer | None, CloudLayer | None]]:
    """Pairs each target layer with the unpaired applied layer of the same type nearest in
    base; leftovers on either side are paired with None. Order: by base of the target (or of
    the applied layer for leftovers), so the result can be sorted once."""
    free = list(applied)
    pairs: list[tuple[CloudLayer | None, CloudLayer | None]] = []
    for goal in target:
        same = [lay for lay in free if lay.type == goal.type]
        if same:
            best = min(same, key=lambda lay: abs(lay.base_m - goal.base_m))
            free.remove(best)
            pairs.append((best, goal))
        else:
            pairs.append((None, goal))
    pairs += [(lay, None) for lay in free]
    return pairs


def _step_wind(
    applied: WeatherState, target: tuple[WindLayer, ...], dt_s: float, rate_mps_per_s: float
) -> tuple[WindLayer, ...]:
    max_step = _rate_step(rate_mps_per_s, dt_s)
    if not applied.wind or math.isinf(max_step):
        return target
    out = []
    for goal in target:
        ve, vn = applied.wind_at(goal.alt_m)
        ge, gn = goal.velocity_mps()
        de, dn = ge - ve, gn - vn
        dist = math.hypot(de, dn)
        if dist > max_step:
            ve, vn = ve + de * max_step / dist, vn + dn * max_step / dist
        else:
            ve, vn = ge, gn
        speed = math.hypot(ve, vn)
        # Below a few cm/s the direction is noise; keep the one the wind is turning to.
        direction = goal.dir_from_deg if speed < 0.05 else dir_from_deg(ve, vn)
        if (ve, vn) == (ge, gn):
            speed, direction = goal.speed_mps, goal.dir_from_deg
        gust_now = _gust_at(applied.wind, goal.alt_m)
        out.append(
            WindLayer(
                alt_m=goal.alt_m,
                dir_from_deg=direction,
                speed_mps=speed,
                gust_mps=_approach(gust_now, goal.gust_mps, max_step),
                variable=goal.variable,
            )
        )
    return tuple(out)


def _gust_at(wind: tuple[WindLayer, ...], alt_m: float) -> float:
    nearest = min(wind, key=lambda w: abs(w.alt_m - alt_m))
    return nearest.gust_mps
