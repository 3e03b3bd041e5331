"""Control-channel commands: each turns a request's params into a change of the engine's
inputs. Bad params raise ControlError with one line that names the command and the field."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from wxsky.engine.stages import SkyEngine, enu_from_geodetic
from wxsky.errors import ProtocolError, WxskyError
from wxsky.scene.camera import Camera
from wxsky.weather.state import Source, parse_time_utc


class ControlError(ProtocolError):
    """A control request whose params are missing, mistyped or out of range."""


def camera_from_params(
    engine: SkyEngine, params: dict[str, Any], max_size: tuple[int, int]
) -> Camera:
    """A new camera: fields the request omits keep their current values."""
    cam = engine.camera
    allowed = {
        "position_m",
        "lat_deg",
        "lon_deg",
        "alt_m",
        "heading_deg",
        "pitch_deg",
        "roll_deg",
        "fov_deg",
        "width",
        "height",
    }
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise ControlError(f"set_camera: unknown field {unknown[0]!r} (known: {sorted(allowed)})")
    position = cam.position_m
    if "position_m" in params:
        pos = params["position_m"]
        if not isinstance(pos, (list, tuple)) or len(pos) != 3:
            raise ControlError("set_camera: position_m must be [east_m, north_m, alt_m]")
        position = (
            _number("set_camera", "position_m[0]", pos[0]),
            _number("set_camera", "position_m[1]", pos[1]),
            _number("set_camera", "position_m[2]", pos[2]),
        )
    elif {"lat_deg", "lon_deg"} & set(params):
        if not {"lat_deg", "lon_deg"} <= set(params):
            raise ControlError("set_camera: lat_deg and lon_deg go together")
        obs = engine.state.observer
        position = enu_from_geodetic(
            obs.lat_deg,
            obs.lon_deg,
            _number("set_camera", "lat_deg", params["lat_deg"], -90.0, 90.0),
            _number("set_camera", "lon_deg", params["lon_deg"], -180.0, 180.0),
            _number("set_camera", "alt_m", params.get("alt_m", position[2]), -500.0, 30_000.0),
        )
    elif "alt_m" in params:
        position = (position[0], position[1], _number("set_camera", "alt_m", params["alt_m"]))
    width = _integer("set_camera", "width", params.get("width", cam.width_px), 16, max_size[0])
    height = _integer("set_camera", "height", params.get("height", cam.height_px), 16, max_size[1])
    try:
        return Camera(
            position_m=position,
            heading_deg=_number(
                "set_camera", "heading_deg", params.get("heading_deg", cam.heading_deg)
            )
            % 360.0,
            pitch_deg=_number(
                "set_camera", "pitch_deg", params.get("pitch_deg", cam.pitch_deg), -90.0, 90.0
            ),
            roll_deg=_number("set_camera", "roll_deg", params.get("roll_deg", cam.roll_deg)),
            fov_deg=_number(
                "set_camera", "fov_deg", params.get("fov_deg", cam.fov_deg), 1.0, 170.0
            ),
            width_px=width,
            height_px=height,
        )
    except ValueError as exc:
        raise ControlError(f"set_camera: {exc}") from None


def camera_to_dict(cam: Camera) -> dict[str, Any]:
    return {
        "position_m": list(cam.position_m),
        "heading_deg": cam.heading_deg,
        "pitch_deg": cam.pitch_deg,
        "roll_deg": cam.roll_deg,
        "fov_deg": cam.fov_deg,
        "width": cam.width_px,
        "height": cam.height_px,
    }


def set_aircraft(engine: SkyEngine, params: dict[str, Any]) -> dict[str, Any]:
    """`position_m`: [east_m, north_m, alt_m] of the host's own aircraft, or null to stop
    splitting the near layer at it."""
    _only("set_aircraft", params, {"position_m"})
    if "position_m" not in params:
        raise ControlError("set_aircraft: give position_m ([east_m, north_m, alt_m] or null)")
    pos = params["position_m"]
    if pos is None:
        engine.set_aircraft(None)
        return {"position_m": None}
    if not isinstance(pos, (list, tuple)) or len(pos) != 3:
        raise ControlError("set_aircraft: position_m must be [east_m, north_m, alt_m] or null")
    position = (
        _number("set_aircraft", "position_m[0]", pos[0], -1e6, 1e6),
        _number("set_aircraft", "position_m[1]", pos[1], -1e6, 1e6),
        _number("set_aircraft", "position_m[2]", pos[2], -1000.0, 100_000.0),
    )
    engine.set_aircraft(position)
    return {"position_m": list(position)}


def set_time(engine: SkyEngine, params: dict[str, Any]) -> None:
    _only("set_time", params, {"time_utc", "rate"})
    text = params.get("time_utc")
    rate = params.get("rate")
    if text is None and rate is None:
        raise ControlError("set_time: give time_utc (ISO 8601) and/or rate")
    if rate is not None:
        rate = _number("set_time", "rate", rate, 0.0, 10_000.0)
    if text is not None:
        if not isinstance(text, str):
            raise ControlError("set_time: time_utc must be an ISO 8601 string")
        try:
            engine.set_time(parse_time_utc(text), rate)
        except ValueError as exc:
            raise ControlError(f"set_time: {exc}") from None
    elif rate is not None:
        engine.clock_rate = rate


def apply_preset(engine: SkyEngine, params: dict[str, Any], preset_dirs: Sequence[Path]) -> str:
    from wxsky.settings.presets import load_preset

    _only("apply_preset", params, {"name"})
    name = params.get("name")
    if not isinstance(name, str):
        raise ControlError("apply_preset: name must be a string")
    # A preset applied at run time is an instructor's override: it beats the METAR feed
    # until released. The clock is the one thing it does not hold.
    patch = dataclasses.replace(load_preset(name, preset_dirs), source=Source.CONTROL)
    engine.apply(patch)
    return name


def release(engine: SkyEngine, params: dict[str, Any]) -> dict[str, Any]:
    """Hand the fields an override holds back to the sources below it."""
    _only("release", params, {"source"})
    name = params.get("source", "control")
    choices = {"control": Source.CONTROL, "cockpit": Source.COCKPIT}
    if name not in choices:
        raise ControlError(f"release: source must be 'control' or 'cockpit', got {name!r}")
    return {"source": name, "released": list(engine.release(choices[name]))}


def apply_metar(engine: SkyEngine, params: dict[str, Any]) -> str:
    from wxsky.weather.metar import decode
    from wxsky.weather.metar_clouds import metar_to_patch

    _only("apply_metar", params, {"report", "field_elevation_m", "year", "month"})
    report = params.get("report")
    if not isinstance(report, str):
        raise ControlError("apply_metar: report must be a string")
    elevation = _number(
        "apply_metar",
        "field_elevation_m",
        params.get("field_elevation_m", engine.state.observer.alt_m),
        -500.0,
        9000.0,
    )
    # The report names only its day; by default it belongs to the simulated month.
    now = engine.state.time_utc
    year = _integer("apply_metar", "year", params.get("year", now.year), 1, 9999)
    month = _integer("apply_metar", "month", params.get("month", now.month), 1, 12)
    decoded = decode(report, year=year, month=month).require_usable()
    engine.apply(metar_to_patch(decoded, field_elevation_m=elevation))
    return decoded.station or ""


def dispatch_table(
    handlers: dict[str, Callable[[dict[str, Any]], Any]],
) -> Callable[[str, dict[str, Any]], Any]:
    def dispatch(method: str, params: dict[str, Any]) -> Any:
        handler = handlers.get(method)
        if handler is None:
            raise ControlError(f"unknown command {method!r} (known: {', '.join(sorted(handlers))})")
        try:
            return handler(params)
        except WxskyError:
            raise
        except ValueError as exc:
            raise ControlError(f"{method}: {exc}") from None

    return dispatch


def _only(command: str, params: dict[str, Any], allowed: set[str]) -> None:
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise ControlError(f"{command}: unknown field {unknown[0]!r} (known: {sorted(allowed)})")


def _number(
    command: str, name: str, value: Any, lo: float = -math.inf, hi: float = math.inf
) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ControlError(f"{command}: {name} must be a finite number, got {value!r}")
    if not lo <= value <= hi:
        raise ControlError(f"{command}: {name} = {value} is outside {lo}..{hi}")
    return float(value)


def _integer(command: str, name: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ControlError(f"{command}: {name} must be an integer, got {value!r}")
    if not lo <= value <= hi:
        raise ControlError(f"{command}: {name} = {value} is outside {lo}..{hi}")
    return value
