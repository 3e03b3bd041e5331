"""What a cockpit sends over time, as NMEA lines or CANaerospace frames: the emulator's
scripted scenarios (pure functions of scenario time) and their encoders. No I/O."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.protocols.canaerospace import (  # noqa: E402
    encode_float,
    encode_layer,
    encode_utc,
    encode_wind,
)
from wxsky.protocols.nmea import sentence  # noqa: E402
from wxsky.units import FT_TO_M, KT_TO_MPS  # noqa: E402

KELVIN_OFFSET_C = 273.15


# -- scenarios --------------------------------------------------------------------------


class Layer(NamedTuple):
    layer: int  # cockpit layer 1-3
    oktas: float
    base_m: float  # MSL
    thickness_m: float


@dataclass(frozen=True)
class Knobs:
    """What the cockpit's panel is set to at one moment."""

    wind_dir_deg: float  # true, from, 0..360
    wind_speed_mps: float
    layers: tuple[Layer, ...]
    time_utc: datetime
    temperature_c: float | None = None  # None: the panel does not send it
    visibility_m: float | None = None  # CAN only: NMEA 0183 has no visibility field


@dataclass(frozen=True)
class Scenario:
    name: str
    length_s: float
    at: Callable[[float], Knobs]
    summary: str


def _clamp01(x: float) -> float:
    return min(1.0, max(0.0, x))


def _ramp(t_s: float, start_s: float, end_s: float) -> float:
    """0 before start, 1 after end, smooth (smoothstep) between."""
    x = _clamp01((t_s - start_s) / (end_s - start_s))
    return x * x * (3.0 - 2.0 * x)


def _lerp(a: float, b: float, x: float) -> float:
    return a + (b - a) * x


SWEEP_LENGTH_S = 60.0
SWEEP_START_UTC = datetime(2026, 6, 21, 4, 0, tzinfo=UTC)
SWEEP_SKY_S_PER_S = 16 * 3600.0 / SWEEP_LENGTH_S  # 04:00 to 20:00 UTC over the sweep


def sweep_at(t_s: float) -> Knobs:
    f = _clamp01(t_s / SWEEP_LENGTH_S)
    return Knobs(
        wind_dir_deg=360.0 * f,
        wind_speed_mps=25.0 * f,
        layers=(Layer(1, 8.0 * (1.0 - abs(2.0 * f - 1.0)), 1500.0, 800.0),),
        time_utc=SWEEP_START_UTC + timedelta(seconds=f * SWEEP_LENGTH_S * SWEEP_SKY_S_PER_S),
    )


FRONT_LENGTH_S = 120.0
FRONT_START_UTC = datetime(2026, 3, 14, 12, 0, tzinfo=UTC)
FRONT_SKY_S_PER_S = 90.0  # three hours of sky over the two minutes
FRONT_PASSAGE_S = 66.0


def front_at(t_s: float) -> Knobs:
    t = min(max(t_s, 0.0), FRONT_LENGTH_S)
    veer = _ramp(t, FRONT_PASSAGE_S - 8.0, FRONT_PASSAGE_S + 8.0)
    closing = _ramp(t, FRONT_PASSAGE_S - 30.0, FRONT_PASSAGE_S - 6.0)
    clearing = _ramp(t, FRONT_PASSAGE_S + 4.0, FRONT_PASSAGE_S + 30.0)
    # The squall line: the wind peaks as the front goes through, then settles stronger.
    squall = math.exp(-(((t - FRONT_PASSAGE_S) / 12.0) ** 2))
    cirrus = Layer(3, _lerp(_lerp(1.0, 5.0, _ramp(t, 0.0, 30.0)), 0.0, clearing), 8000.0, 600.0)
    altostratus = Layer(
        2,
        _lerp(_lerp(0.0, 7.0, _ramp(t, 15.0, 45.0)), 1.0, clearing),
        _lerp(4500.0, 3000.0, _ramp(t, 15.0, 55.0)),
        1000.0,
    )
    low = Layer(  # closes and lowers into the front's rain, then post-frontal cumulus
        1,
        _lerp(_lerp(0.0, 8.0, closing), 3.0, clearing),
        _lerp(_lerp(1500.0, 500.0, closing), 1200.0, clearing),
        _lerp(_lerp(800.0, 3500.0, closing), 1000.0, clearing),
    )
    return Knobs(
        wind_dir_deg=_lerp(200.0, 300.0, veer),
        wind_speed_mps=6.0 + 9.0 * squall + 3.0 * veer,
        layers=(low, altostratus, cirrus),
        time_utc=FRONT_START_UTC + timedelta(seconds=t * FRONT_SKY_S_PER_S),
        temperature_c=_lerp(18.0, 9.0, veer),
        visibility_m=_lerp(30_000.0, 40_000.0, clearing) - 26_000.0 * squall,
    )


SCENARIOS: dict[str, Scenario] = {
    "sweep": Scenario(
        "sweep", SWEEP_LENGTH_S, sweep_at, "cover, wind and time of day across their ranges"
    ),
    "front": Scenario("front", FRONT_LENGTH_S, front_at, "a cold front passing"),
}


def scenario_at(t_s: float, name: str = "sweep") -> Knobs:
    """The panel at scenario time `t_s` (clamped to the scenario's length)."""
    return SCENARIOS[name].at(t_s)


# -- encoders ---------------------------------------------------------------------------


def _decimal(value: float) -> str:
    """One decimal, without a trailing `.0`: the oktas a panel sends are mostly whole."""
    return f"{value:.1f}".rstrip("0").rstrip(".")


def nmea_lines(knobs: Knobs, *, with_time: bool = True, wind_sentence: str = "mwd") -> list[bytes]:
    """The sentences for `knobs`, each with checksum and CR LF.

    MWD by default: its direction is true, so it does not depend on the receiver's
    `sensor_heading_deg` as MWV's angle does."""
    dir_deg = knobs.wind_dir_deg % 360.0
    speed_mps = knobs.wind_speed_mps
    if wind_sentence == "mwd":
        bodies = [f"WIMWD,{dir_deg:.1f},T,,M,{speed_mps / KT_TO_MPS:.1f},N,{speed_mps:.1f},M"]
    elif wind_sentence == "mwv":
        bodies = [f"WIMWV,{dir_deg:.1f},T,{speed_mps:.1f},M,A"]
    else:
        raise ValueError(f"wind sentence {wind_sentence!r} is not mwd or mwv")
    if knobs.temperature_c is not None:
        mda = [""] * 20  # MDA's 20 fields; only the air temperature is given
        mda[4], mda[5] = f"{knobs.temperature_c:.1f}", "C"
        bodies.append("WIMDA," + ",".join(mda))
    for layer in knobs.layers:
        bodies.append(
            f"PWXCL,{layer.layer},{_decimal(layer.oktas)},"
            f"{layer.base_m / FT_TO_M:.0f},{layer.thickness_m / FT_TO_M:.0f}"
        )
    if with_time:
        utc = knobs.time_utc.astimezone(UTC)
        hundredths = utc.microsecond // 10_000
        bodies.append(f"GPZDA,{utc:%H%M%S}.{hundredths:02d},{utc:%d},{utc:%m},{utc.year:04d},00,00")
    return [sentence(body) for body in bodies]


def can_frames(
    knobs: Knobs, *, with_time: bool = True, node_id: int = 1
) -> list[tuple[int, bytes]]:
    """(CAN id, data field) frames for `knobs`, message codes 0 (see `MessageCodes`)."""
    frames = encode_wind(knobs.wind_speed_mps, knobs.wind_dir_deg % 360.0, node_id=node_id)
    if knobs.temperature_c is not None:
        frames.append(
            (335, encode_float(335, knobs.temperature_c + KELVIN_OFFSET_C, node_id=node_id))
        )
    for layer in knobs.layers:
        frames += encode_layer(
            layer.layer,
            cover_oktas=layer.oktas,
            base_m=layer.base_m,
            thickness_m=layer.thickness_m,
            node_id=node_id,
        )
    if knobs.visibility_m is not None:
        frames.append((1503, encode_float(1503, knobs.visibility_m, node_id=node_id)))
    if with_time:
        frames += encode_utc(knobs.time_utc, node_id=node_id)
    return frames


class MessageCodes:
    """CANaerospace's message code (byte 3): the sender counts every message of an id, so a
    receiver can spot lost frames. Layers share ids, so they share a counter."""

    def __init__(self) -> None:
        self._next: dict[int, int] = {}

    def stamp(self, frames: Sequence[tuple[int, bytes]]) -> list[tuple[int, bytes]]:
        out = []
        for can_id, data in frames:
            code = self._next.get(can_id, 0)
            self._next[can_id] = (code + 1) % 256
            out.append((can_id, data[:3] + bytes((code,)) + data[4:]))
        return out
