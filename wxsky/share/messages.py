"""What a sky master tells its channels, as plain data (the wire module packs it): the sky
state (applied and target weather, the drift's anchor, the clock's rate, the shared camera),
clock ticks and clock pings, and each daemon's health. Pure.

Every message is a map with `v` (SHARE_VERSION), `kind` and `site`; decoding checks each
field's type and range and the weather with the weather state's own checks, and raises
ShareError with one line naming the field. Times travel as integer microseconds since the
Unix epoch, so that a channel's datetimes are the master's to the microsecond and its drift,
computed from them, is the master's to the bit.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

from wxsky.errors import ProtocolError
from wxsky.scene.camera import Camera
from wxsky.scene.gather import Drift
from wxsky.scene.tower_field import LayerEpoch
from wxsky.weather.state import (
    EARLIEST_UTC,
    LATEST_UTC,
    WeatherState,
    weather_from_dict,
    weather_to_dict,
)

SHARE_VERSION = 1
SITE_PATTERN = r"[a-z0-9][a-z0-9_-]{0,63}"
NAME_PATTERN = r"[a-z0-9][a-z0-9_-]{0,63}"
ROLES = ("master", "channel")
_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
_MAX_LAYERS = 64  # drift entries: more than any weather holds
# Every time on the bus lies in the clock's range (weather.state, issue 40): a time near the
# end of year 9999 once killed a daemon that computed ahead of it.
_MIN_US = (EARLIEST_UTC - _EPOCH) // timedelta(microseconds=1)
_MAX_US = (LATEST_UTC - _EPOCH) // timedelta(microseconds=1) - 1
# A master's monotonic reading: a clock that starts near boot; a century of uptime is plenty.
MAX_MONO_S = 3.2e9
SEQUENCE_MAX = 2**63 - 1


class ShareError(ProtocolError):
    """A channel message that is not what this version of wxsky sends."""


def time_to_us(t: datetime) -> int:
    return (t - _EPOCH) // timedelta(microseconds=1)


def time_from_us(us: int) -> datetime:
    return _EPOCH + timedelta(microseconds=us)


@dataclass(frozen=True)
class SkyState:
    """The master's sky: everything a channel needs to build the same cloud field for the
    same sim time. `sequence` bumps with every state a master sends; `master_id` names one
    run of a master (a restarted master is another)."""

    site: str
    master_id: str
    sequence: int
    weather_version: int
    applied: WeatherState
    target: WeatherState
    anchor_utc: datetime  # the drift is anchor_drift, moved by each layer's wind since then
    anchor_drift: Drift
    clock_rate: float
    # Per applied layer, when its weather was set (the towers' ages, scene/tower_field.py);
    # empty from a master that sends none: the channel then times its towers itself.
    tower_epochs: tuple[LayerEpoch | None, ...] = ()


@dataclass(frozen=True)
class ClockTick:
    """The master's sim time at one instant of its monotonic clock (a tick per frame), with
    the frame's shared camera and aircraft."""

    site: str
    master_id: str
    master_mono_s: float
    time_utc: datetime
    rate: float
    sequence: int  # of the latest state the master has sent
    camera: Camera | None  # the shared (ownship) camera; None: each channel keeps its own
    aircraft_m: tuple[float, float, float] | None


@dataclass(frozen=True)
class Health:
    site: str
    name: str
    role: str
    fps: float
    lag_ms: float
    frames: int


def encode_state(s: SkyState) -> dict[str, Any]:
    return {
        **_head("state", s.site),
        "master_id": s.master_id,
        "sequence": s.sequence,
        "weather_version": s.weather_version,
        "applied": weather_to_dict(s.applied),
        "applied_time_us": time_to_us(s.applied.time_utc),
        "target": weather_to_dict(s.target),
        "target_time_us": time_to_us(s.target.time_utc),
        "anchor_us": time_to_us(s.anchor_utc),
        "anchor_drift": [[dx, dy] for dx, dy in s.anchor_drift],
        "clock_rate": s.clock_rate,
        "tower_epochs": [_encode_epoch(e) for e in s.tower_epochs],
    }


def _encode_epoch(e: LayerEpoch | None) -> list[float | int] | None:
    if e is None:
        return None
    cut = -1 if e.cut_utc is None else time_to_us(e.cut_utc)
    return [time_to_us(e.set_utc), e.sun_elevation_deg, cut, e.cover_oktas]


def _decode_epoch(value: object, where: str) -> LayerEpoch | None:
    if value is None:
        return None
    shape = f"state: {where} must be [set_us, sun_elevation_deg, cut_us or -1, cover_oktas]"
    if not isinstance(value, list) or len(value) != 4:
        raise ShareError(shape)
    m = dict(zip(("set_us", "sun_elevation_deg", "cut_us", "cover_oktas"), value, strict=True))
    m["kind"] = f"state: {where}"
    set_us = _int(m, "set_us", _MIN_US, _MAX_US)
    cut_us = _int(m, "cut_us", -1, _MAX_US)
    if 0 <= cut_us < _MIN_US:
        raise ShareError(f"state: {where}: cut_us = {cut_us} is before {EARLIEST_UTC:%Y}")
    return LayerEpoch(
        set_utc=time_from_us(set_us),
        sun_elevation_deg=_float(m, "sun_elevation_deg", -90.0, 90.0),
        cut_utc=None if cut_us < 0 else time_from_us(cut_us),
        cover_oktas=_float(m, "cover_oktas", 0.0, 8.0),
    )


def decode_state(data: object, site: str) -> SkyState:
    m = _message(data, "state", site)
    applied = _weather(m, "applied")
    target = _weather(m, "target")
    applied = _replace_time(applied, time_from_us(_int(m, "applied_time_us", _MIN_US, _MAX_US)))
    target = _replace_time(target, time_from_us(_int(m, "target_time_us", _MIN_US, _MAX_US)))
    drift_items = _list(m, "anchor_drift", _MAX_LAYERS)
    drift = tuple(_pair(v, f"anchor_drift[{i}]") for i, v in enumerate(drift_items))
    if len(drift) != len(applied.layers):
        raise ShareError(
            f"state: anchor_drift has {len(drift)} entries for {len(applied.layers)} layers"
        )
    epochs: tuple[LayerEpoch | None, ...] = ()
    if "tower_epochs" in m:  # a master from before the towers sends none
        items = _list(m, "tower_epochs", _MAX_LAYERS)
        epochs = tuple(_decode_epoch(v, f"tower_epochs[{i}]") for i, v in enumerate(items))
        if len(epochs) != len(applied.layers):
            raise ShareError(
                f"state: tower_epochs has {len(epochs)} entries for {len(applied.layers)} layers"
            )
    return SkyState(
        site=site,
        master_id=_text(m, "master_id", r"[0-9a-f]{8,64}"),
        sequence=_int(m, "sequence", 0, SEQUENCE_MAX),
        weather_version=_int(m, "weather_version", 0, SEQUENCE_MAX),
        applied=applied,
        target=target,
        anchor_utc=time_from_us(_int(m, "anchor_us", _MIN_US, _MAX_US)),
        anchor_drift=drift,
        clock_rate=_float(m, "clock_rate", 0.0, 10_000.0),
        tower_epochs=epochs,
    )


def encode_tick(t: ClockTick) -> dict[str, Any]:
    return {
        **_head("clock", t.site),
        "master_id": t.master_id,
        "master_mono_s": t.master_mono_s,
        "time_us": time_to_us(t.time_utc),
        "rate": t.rate,
        "sequence": t.sequence,
        "camera": None if t.camera is None else _camera_to_dict(t.camera),
        "aircraft_m": None if t.aircraft_m is None else list(t.aircraft_m),
    }


def decode_tick(data: object, site: str) -> ClockTick:
    m = _message(data, "clock", site)
    camera_data = m.get("camera")
    aircraft = m.get("aircraft_m")
    return ClockTick(
        site=site,
        master_id=_text(m, "master_id", r"[0-9a-f]{8,64}"),
        master_mono_s=_float(m, "master_mono_s", 0.0, MAX_MONO_S),
        time_utc=time_from_us(_int(m, "time_us", _MIN_US, _MAX_US)),
        rate=_float(m, "rate", 0.0, 10_000.0),
        sequence=_int(m, "sequence", 0, SEQUENCE_MAX),
        camera=None if camera_data is None else _camera(camera_data),
        aircraft_m=None if aircraft is None else _vec3(aircraft, "aircraft_m"),
    )


def encode_pong(site: str, master_id: str, mono_s: float) -> dict[str, Any]:
    """A ping's answer: the master's monotonic reading."""
    return {**_head("pong", site), "master_id": master_id, "mono_s": mono_s}


def decode_pong(data: object, site: str) -> tuple[str, float]:
    m = _message(data, "pong", site)
    return _text(m, "master_id", r"[0-9a-f]{8,64}"), _float(m, "mono_s", 0.0, MAX_MONO_S)


def encode_health(h: Health) -> dict[str, Any]:
    return {
        **_head("health", h.site),
        "name": h.name,
        "role": h.role,
        "fps": h.fps,
        "lag_ms": h.lag_ms,
        "frames": h.frames,
    }


def decode_health(data: object, site: str) -> Health:
    m = _message(data, "health", site)
    role = _text(m, "role", "|".join(ROLES))
    return Health(
        site=site,
        name=_text(m, "name", NAME_PATTERN),
        role=role,
        fps=_float(m, "fps", 0.0, 100_000.0),
        lag_ms=_float(m, "lag_ms", -1e9, 1e9),
        frames=_int(m, "frames", 0, SEQUENCE_MAX),
    )


def sky_id(state: SkyState) -> str:
    """A digest of what determines the cloud field, equal on a master and its channels: the
    applied weather but its time, the seed, the drift's anchor and the master's run and
    weather version."""
    # Through weather_from_dict and back: its fields typed as the state types them (a preset's
    # 3 oktas and a message's 3.0 are one cover).
    weather = weather_to_dict(weather_from_dict(weather_to_dict(state.applied)))
    weather.pop("time_utc")
    weather.pop("sources")
    basis = {
        "weather": weather,
        "anchor_us": time_to_us(state.anchor_utc),
        "anchor_drift": [[dx, dy] for dx, dy in state.anchor_drift],
        "master_id": state.master_id,
        "weather_version": state.weather_version,
    }
    text = json.dumps(basis, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


# -- checking -------------------------------------------------------------------------------


def _head(kind: str, site: str) -> dict[str, Any]:
    return {"v": SHARE_VERSION, "kind": kind, "site": site}


def _message(data: object, kind: str, site: str) -> Mapping[str, Any]:
    if not isinstance(data, Mapping):
        raise ShareError(f"{kind}: not a map but {type(data).__name__}")
    version = data.get("v")
    if version != SHARE_VERSION:
        raise ShareError(f"{kind}: version {version!r}, this wxsky speaks {SHARE_VERSION}")
    if data.get("kind") != kind:
        raise ShareError(f"{kind}: kind {data.get('kind')!r}")
    if data.get("site") != site:
        raise ShareError(f"{kind}: from site {data.get('site')!r}, not {site!r}")
    return data


def _weather(m: Mapping[str, Any], key: str) -> WeatherState:
    value = m.get(key)
    if not isinstance(value, Mapping):
        raise ShareError(f"state: {key} is not a map")
    try:
        return weather_from_dict(value)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ShareError(f"state: {key}: {_reason(exc)}") from None


def _replace_time(state: WeatherState, time_utc: datetime) -> WeatherState:
    return dataclasses.replace(state, time_utc=time_utc)


def _reason(exc: BaseException) -> str:
    if isinstance(exc, KeyError):
        return f"missing {exc.args[0]!r}"
    return str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__


def _int(m: Mapping[str, Any], key: str, lo: int, hi: int) -> int:
    value = m.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ShareError(f"{m.get('kind')}: {key} must be an integer, got {_shown(value)}")
    if not lo <= value <= hi:
        raise ShareError(f"{m.get('kind')}: {key} = {value} is outside {lo}..{hi}")
    return value


def _float(m: Mapping[str, Any], key: str, lo: float, hi: float) -> float:
    value = m.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ShareError(f"{m.get('kind')}: {key} must be a number, got {_shown(value)}")
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ShareError(f"{m.get('kind')}: {key} = {value} is outside {lo:g}..{hi:g}")
    return float(value)


def _text(m: Mapping[str, Any], key: str, pattern: str) -> str:
    value = m.get(key)
    if not isinstance(value, str) or re.fullmatch(pattern, value) is None:
        raise ShareError(f"{m.get('kind')}: {key} is not a valid value: {_shown(value)}")
    return value


def _list(m: Mapping[str, Any], key: str, most: int) -> list[Any]:
    value = m.get(key)
    if not isinstance(value, list) or len(value) > most:
        raise ShareError(f"{m.get('kind')}: {key} must be a list of at most {most} items")
    return value


def _pair(value: object, where: str) -> tuple[float, float]:
    if not isinstance(value, list) or len(value) != 2:
        raise ShareError(f"state: {where} must be [east_m, north_m]")
    x, y = value
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (x, y)):
        raise ShareError(f"state: {where} must hold two numbers")
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ShareError(f"state: {where} must be finite")
    return (float(x), float(y))


def _vec3(value: object, where: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise ShareError(f"{where} must be [east_m, north_m, up_m]")
    if not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value
    ):
        raise ShareError(f"{where} must hold three finite numbers")
    return (float(value[0]), float(value[1]), float(value[2]))


def _camera_to_dict(cam: Camera) -> dict[str, Any]:
    return {
        "position_m": list(cam.position_m),
        "heading_deg": cam.heading_deg,
        "pitch_deg": cam.pitch_deg,
        "roll_deg": cam.roll_deg,
        "fov_deg": cam.fov_deg,
        "width": cam.width_px,
        "height": cam.height_px,
    }


def _camera(value: object) -> Camera:
    if not isinstance(value, Mapping):
        raise ShareError("clock: camera is not a map")
    m = {**value, "kind": "clock: camera"}
    try:
        return Camera(
            position_m=_vec3(value.get("position_m"), "camera.position_m"),
            heading_deg=_float(m, "heading_deg", -720.0, 720.0) % 360.0,
            pitch_deg=_float(m, "pitch_deg", -90.0, 90.0),
            roll_deg=_float(m, "roll_deg", -180.0, 180.0),
            fov_deg=_float(m, "fov_deg", 1.0, 170.0),
            width_px=_int(m, "width", 16, 8192),
            height_px=_int(m, "height", 16, 8192),
        )
    except ValueError as exc:
        raise ShareError(f"clock: camera: {_reason(exc)}") from None


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."
