"""Cockpit input for soak runs, shared by tools/soak/soak_cockpit.py and tools/soak/soak.py: one
valid value never sent before per period (a wind on serial, a temperature on CAN), the issue's
bad input for each link, and the check of a `target` notification that records the valid values
it shows and names every invalid one that got through.
"""

from __future__ import annotations

import math
import random
from typing import Any

import can

from wxsky.protocols.canaerospace import encode_float, encode_raw, encode_time
from wxsky.protocols.nmea import sentence

FOREIGN_CAN_ID = 0x123  # someone else's id: counted as ignored


def valid_wind(i: int) -> tuple[float, float]:
    """Period i's wind (direction deg, speed m/s): distinct for 504,000 periods, and never the
    12.5 m/s of the bad-checksum sentence below (every speed ends in 5 hundredths)."""
    return float(i % 360), round(0.1 * (i % 1400) + 0.05, 2)


def wind_sentence(wind: tuple[float, float]) -> bytes:
    return sentence(f"WIMWV,{wind[0]:05.1f},T,{wind[1]:.2f},M,A")


def valid_temperature_c(i: int) -> float:
    """Period i's temperature, °C: distinct for 9,000 periods."""
    return round(-40.0 + 0.01 * (i % 9000), 2)


def temperature_frame(temperature_c: float) -> can.Message:
    return can_frame(335, encode_float(335, temperature_c + 273.15))


def bad_nmea(rng: random.Random) -> bytes:
    """Random bytes, a bad checksum, truncation, a 10 kB line without a newline, wind 999 m/s,
    hour 25, 9 oktas and layer 7."""
    junk = bytes(rng.getrandbits(8) for _ in range(200))
    return (
        junk
        + b"\r\n"
        + b"$WIMWV,270.0,T,12.5,M,A*00\r\n"  # bad checksum
        + b"$WIMWV,27"  # truncated ...
        + b"\r\n"
        + b"Q" * 10_000  # a 10 kB line without a newline ...
        + b"\r\n"
        + sentence("WIMWV,090.0,T,999,M,A")  # wind 999 m/s
        + sentence("GPZDA,250000.00,12,06,1987,00,00")  # hour 25
        + sentence("PWXCL,1,9,3000,1000")  # 9 oktas
        + sentence("PWXCL,7,4,3000,1000")  # layer 7
    )


def bad_can_frames() -> list[can.Message]:
    """Frames every CANaerospace decoder must reject (each counts as one error)."""
    return [
        can_frame(333, encode_float(333, 999.0)),
        can_frame(333, encode_raw(333, 2, bytes.fromhex("7fc00000"))),  # NaN
        can_frame(334, b"\x01\x02\x03"),  # wrong DLC
        can_frame(1500, encode_float(1500, 9.0, service_code=1)),  # 9 oktas
        can_frame(1500, encode_float(1500, 4.0, service_code=7)),  # layer 7
        can_frame(1200, encode_time(25, 0, 0)),  # hour 25
    ]


def can_frame(can_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


def look(target: dict[str, Any], seen: set[Any], invalid: list[str]) -> None:
    """Record the cockpit values a `target` map shows in `seen` (temperatures rounded to 0.01,
    winds as (dir, speed)) and append what the bad input above would have set to `invalid`."""
    if target["temperature_c"] is not None:
        seen.add(round(target["temperature_c"], 2))
    if target["wind"]:
        w = target["wind"][0]
        seen.add((round(w["dir_deg"], 3), round(w["speed_mps"], 2)))
        if w["speed_mps"] > 150.0 or not math.isfinite(w["speed_mps"]):
            invalid.append(f"wind {w['speed_mps']}")
    if target["time_utc"].startswith("1987"):
        invalid.append(f"time {target['time_utc']}")
    for lay in target["layers"]:
        if lay["cover_oktas"] > 8.0:
            invalid.append(f"layer {lay}")
