"""Control-channel commands: each turns a request's params into a change of the engine's
inputs. Bad params raise ControlError with one line that names the command and the field.

Every command refuses params it does not take, and every param is bounded, in size as well as
value: the largest legal request is an `apply_metar` with a `METAR_MAX_CHARS` report, which
is what `wire.MAX_REQUEST_SIZE` is sized for (docs/protocol.md §2.2, §5)."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from wxsky.engine.radar_work import Made
from wxsky.engine.stages import SkyEngine, enu_from_geodetic
from wxsky.errors import ProtocolError, WxskyError
from wxsky.logs import clip
from wxsky.scene.camera import FOV_DEG, PITCH_DEG, ROLL_DEG, VIEWPORT_PX, Camera
from wxsky.scene.fog import RVR_EYE_M, fog_field, runway
from wxsky.scene.radar import DBZ_OFFSET, DBZ_STEP, RANGE_NM, SIZE_PX, TILT_DEG
from wxsky.schema import (
    REQUIRED,
    Bool,
    Custom,
    Field,
    Invalid,
    Nullable,
    Number,
    Problem,
    Table,
    Text,
    Tuple,
)
from wxsky.settings.config import CLOCK_RATE, LAYER_FORMAT, PRESET_NAME
from wxsky.weather.metar_clouds import FIELD_ELEVATION_M
from wxsky.weather.state import (
    ALT_M,
    EARLIEST_UTC,
    LAT_DEG,
    LATEST_UTC,
    LON_DEG,
    RUNWAY_PATTERN,
    Source,
    WeatherState,
    parse_time_utc,
)


class ControlError(ProtocolError):
    """A control request whose params are missing, mistyped or out of range."""


# Each command's params, checked by the same kinds as the config and the weather state; the
# camera's width and height are further capped by the output frame (`camera_from_params`).
# A heading is wrapped to 0..360; two turns either way allows a host's unwrapped heading.
_HEADING_DEG = Number(-720.0, 720.0, unit="deg")
# The longest METAR report `apply_metar` takes. A real one is under 300 characters, with
# remarks rarely over 1000; longer text is no report, and decoding it would hold up the loop.
METAR_MAX_CHARS = 4096
# ISO 8601 with fractions and an offset fits in 40 characters.
_TIME_MAX_CHARS = 64
ERROR_MAX_CHARS = 1000  # a command's error, one line: a long value in it is clipped
# A camera or aircraft position: within 1000 km of the observer (the flat local frame is no
# good beyond), from below the Dead Sea shore to the edge of space.
_EN_M = Number(-1e6, 1e6, unit="m")
_POSITION = Tuple((_EN_M, _EN_M, Number(-1000.0, 100_000.0, unit="m")), "[east_m, north_m, alt_m]")
SET_AIRCRAFT = Table({"position_m": Field(Nullable(_POSITION), REQUIRED)})


def _asked_format(value: Any) -> str:
    """The config's kind, with a long string refused by its length: the error quotes the
    value, and a host's 30 KB string is no format."""
    if isinstance(value, str) and len(value) > 16:
        raise ValueError(
            f"must be {LAYER_FORMAT.describe()}, got a string of {len(value)} characters"
        )
    problems: list[Problem] = []
    checked = LAYER_FORMAT.check(value, (), problems)
    if problems:
        raise ValueError(problems[0].message)
    return str(checked)


# `output_format`: the layer format a host asks for (omitted: it only asks what is written).
OUTPUT_FORMAT = Table({"layer_format": Field(Custom(_asked_format, LAYER_FORMAT.describe()))})
# Commands that take no params still refuse any they are given (§5: unknown params are errors).
NO_PARAMS = Table({})


def no_params(command: str, params: dict[str, Any]) -> dict[str, Any]:
    """{} for no params; ControlError naming each one given."""
    return checked_params(command, NO_PARAMS, params)


def _iso_time(value: Any) -> Any:
    if not isinstance(value, str):
        raise ValueError("must be an ISO 8601 string")
    if len(value) > _TIME_MAX_CHARS:
        raise ValueError(
            f"must be an ISO 8601 string of at most {_TIME_MAX_CHARS} characters, "
            f"got {len(value)} characters"
        )
    return parse_time_utc(value)


def _camera_table(max_size: tuple[int, int]) -> Table:
    return Table(
        {
            "position_m": Field(_POSITION),
            "lat_deg": Field(LAT_DEG),
            "lon_deg": Field(LON_DEG),
            "alt_m": Field(ALT_M),
            "heading_deg": Field(_HEADING_DEG),
            "pitch_deg": Field(PITCH_DEG),
            "roll_deg": Field(ROLL_DEG),
            "fov_deg": Field(FOV_DEG),
            "width": Field(VIEWPORT_PX.clamp_hi(max_size[0])),
            "height": Field(VIEWPORT_PX.clamp_hi(max_size[1])),
        }
    )


SET_TIME = Table(
    {"time_utc": Field(Custom(_iso_time, "an ISO 8601 time")), "rate": Field(CLOCK_RATE)}
)
# `now`: switch the sky at once rather than move it at the [transition] rates.
APPLY_PRESET = Table(
    {"name": Field(PRESET_NAME), "keep_site": Field(Bool()), "now": Field(Bool(), False)}
)
RELEASE = Table(
    {
        "source": Field(Text(choices=("control", "cockpit")), "control"),
        "now": Field(Bool(), False),
    }
)
APPLY_METAR = Table(
    {
        "report": Field(Text(max_len=METAR_MAX_CHARS)),
        "field_elevation_m": Field(FIELD_ELEVATION_M),
        "year": Field(Number(EARLIEST_UTC.year, LATEST_UTC.year - 1, integer=True)),
        "month": Field(Number(1, 12, integer=True)),
    }
)


# The weather radar's picture (scene/radar.py): range, antenna tilt, picture size.
RADAR = Table(
    {
        "range_nm": Field(Number(*RANGE_NM, unit="NM"), 40.0),
        "tilt_deg": Field(Number(*TILT_DEG, unit="deg"), 0.0),
        "size_px": Field(Number(*SIZE_PX, integer=True), 256),
    }
)


def radar_reply(made: Made | None, key: tuple[float, float, int]) -> dict[str, Any]:
    """`radar`'s answer: the last picture made for these settings, or `pending`."""
    range_nm, tilt_deg, size_px = key
    out: dict[str, Any] = {"range_nm": range_nm, "tilt_deg": tilt_deg, "size_px": size_px}
    if made is None:
        return out | {"pending": True}
    return out | {"pending": False} | radar_fields(made)


def radar_fields(made: Made, pixels: bytes | None = None) -> dict[str, Any]:
    """What the `radar` answer and the `radar` notification say of a made picture: where and
    when it was taken, how old, how long it took, the byte scale and the bytes (`pixels`: the
    picture's, when the caller has them already)."""
    pic = made.picture
    return {
        "centre_m": list(pic.centre_m),
        "time_utc": made.time_utc,
        "age_s": max(0.0, time.monotonic() - made.made_s),
        "took_s": made.took_s,
        "dbz_offset": DBZ_OFFSET,
        "dbz_step": DBZ_STEP,
        "pixels": pic.to_bytes() if pixels is None else pixels,
    }


MAX_POINT_M = 1e6  # as far from the observer as a camera may stand
# `visibility`: a point of the scene (east, north of the observer; height over the ground) or a
# runway's touchdown zone (docs/fog.md).
VISIBILITY = Table(
    {
        "east_m": Field(Number(-MAX_POINT_M, MAX_POINT_M, unit="m"), 0.0),
        "north_m": Field(Number(-MAX_POINT_M, MAX_POINT_M, unit="m"), 0.0),
        "height_m": Field(Number(0.0, 30_000.0, unit="m"), RVR_EYE_M),
        "runway": Field(
            Text(pattern=RUNWAY_PATTERN, pattern_desc="a runway designator like '14' or '32L'")
        ),
    }
)


def visibility(state: WeatherState, params: dict[str, Any]) -> dict[str, Any]:
    """How far one sees at a point (`height_m` over the ground) and the runway visual range
    there, from the fog the frames draw (`scene.fog`); at a runway's touchdown zone with
    `runway`. Out of fog both are the weather's visibility."""
    v = checked_params("visibility", VISIBILITY, params)
    field = fog_field(state)
    out: dict[str, Any] = {}
    if "runway" in v:
        place = runway(v["runway"])
        east, north = place.touchdown_m
        out["runway"] = v["runway"]
    else:
        east, north = v["east_m"], v["north_m"]
    height = v["height_m"]
    if field is None:
        seen = rvr = state.visibility_m
        ext = 0.0
    else:
        seen = float(field.visibility_m(east, north, height))
        rvr = float(field.rvr_m(east, north))
        ext = float(field.extinction_per_m(east, north, height))
    return out | {
        "east_m": float(east),
        "north_m": float(north),
        "height_m": float(height),
        "visibility_m": seen,
        "rvr_m": rvr,
        "fog_extinction_per_m": ext,
        "in_fog": ext > 0.0,
    }


def radar_key(params: dict[str, Any]) -> tuple[float, float, int]:
    v = checked_params("radar", RADAR, params)
    return float(v["range_nm"]), float(v["tilt_deg"]), int(v["size_px"])


def checked_params(command: str, table: Table, params: dict[str, Any]) -> dict[str, Any]:
    """The params of `command` checked against its table; ControlError lists every problem."""
    try:
        return table.values(params)
    except Invalid as exc:
        raise ControlError(clip(f"{command}: {exc}", ERROR_MAX_CHARS)) from None


def camera_from_params(
    engine: SkyEngine, params: dict[str, Any], max_size: tuple[int, int]
) -> Camera:
    """A new camera: fields the request omits keep their current values."""
    cam = engine.camera
    v = checked_params("set_camera", _camera_table(max_size), params)
    position = cam.position_m
    geodetic = {"lat_deg", "lon_deg"} & set(v)
    if "position_m" in v and (geodetic or "alt_m" in v):
        # Two places in one request: neither would be the one the host meant.
        raise ControlError("set_camera: give position_m or lat_deg + lon_deg (+ alt_m), not both")
    if geodetic and len(geodetic) < 2:
        raise ControlError("set_camera: lat_deg and lon_deg go together")
    if "position_m" in v:
        position = v["position_m"]
    elif geodetic:
        obs = engine.state.observer
        position = enu_from_geodetic(
            obs.lat_deg, obs.lon_deg, v["lat_deg"], v["lon_deg"], v.get("alt_m", position[2])
        )
    elif "alt_m" in v:
        position = (position[0], position[1], v["alt_m"])
    try:
        return Camera(
            position_m=position,
            heading_deg=v.get("heading_deg", cam.heading_deg) % 360.0,
            pitch_deg=v.get("pitch_deg", cam.pitch_deg),
            roll_deg=v.get("roll_deg", cam.roll_deg),
            fov_deg=v.get("fov_deg", cam.fov_deg),
            width_px=v.get("width", cam.width_px),
            height_px=v.get("height", cam.height_px),
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
    v = checked_params("set_aircraft", SET_AIRCRAFT, params)
    position = v["position_m"]
    engine.set_aircraft(position)
    return {"position_m": None if position is None else list(position)}


def output_format(params: dict[str, Any], written: str, segment_version: int) -> dict[str, Any]:
    """`output_format` (docs/protocol.md §5, §1.2): a host asks for a layer format; the answer
    says the one the daemon writes (`written`, its [output] layer_format, fixed for the
    segment's life) and whether that is what was asked for. A format outside the choices is
    an error naming it and them."""
    v = checked_params("output_format", OUTPUT_FORMAT, params)
    wanted = v.get("layer_format", written)
    granted = wanted == written
    reason = None
    if not granted:
        reason = (
            f"this daemon writes {written} layers ([output] layer_format, fixed for the "
            f'segment\'s life): start it with layer_format = "{wanted}" for {wanted} layers; '
            f"read the {written} layers meanwhile"
        )
    return {
        "layer_format": written,
        "granted": granted,
        "reason": reason,
        "segment_version": segment_version,
    }


def set_time(engine: SkyEngine, params: dict[str, Any]) -> None:
    v = checked_params("set_time", SET_TIME, params)
    if not v:
        raise ControlError("set_time: give time_utc (ISO 8601) and/or rate")
    rate = v.get("rate")
    if "time_utc" in v:
        engine.set_time(v["time_utc"], rate)
    elif rate is not None:
        engine.clock_rate = rate


def apply_preset(
    engine: SkyEngine,
    params: dict[str, Any],
    preset_dirs: Sequence[Path],
    keep_site: bool = False,
) -> str:
    """`keep_site` (or the request's): the preset's weather where the camera is, not its own
    site (the default while a simulator's pose places the camera, e.g. FlightGear's): not its
    site, its seed or its time. Its time is its own site's hour (overcast-stratus's 11:00Z is
    late morning at Zurich and 1 a.m. at Honolulu), and without its seed it is a change of
    this sky, made through the transition, not a different sky swapped in at once. `now`
    switches to it at once all the same (a preset with its own site and seed always does:
    that is another sky, not a change of this one)."""
    from wxsky.settings.presets import load_preset

    v = checked_params("apply_preset", APPLY_PRESET, params)
    if "name" not in v:
        raise ControlError("apply_preset: name must be a string")
    # A preset applied at run time is an instructor's override: it beats the METAR feed
    # until released. The clock is the one thing it does not hold.
    patch = dataclasses.replace(load_preset(v["name"], preset_dirs), source=Source.CONTROL)
    if v.get("keep_site", keep_site):
        patch = dataclasses.replace(patch, observer=None, seed=None, time_utc=None)
    engine.apply(patch)
    if v["now"]:
        engine.settle()
    name: str = v["name"]
    return name


def release(engine: SkyEngine, params: dict[str, Any]) -> dict[str, Any]:
    """Hand the fields an override holds back to the sources below it: the sky moves back
    at the [transition] rates, or at once with `now`."""
    v = checked_params("release", RELEASE, params)
    choices = {"control": Source.CONTROL, "cockpit": Source.COCKPIT}
    released = list(engine.release(choices[v["source"]]))
    if v["now"]:
        engine.settle()
    return {"source": v["source"], "released": released}


def apply_metar(engine: SkyEngine, params: dict[str, Any]) -> str:
    """The report becomes the METAR source, its clouds over its station's field (the station
    table's elevation, as a feed's report is read) or over `field_elevation_m`."""
    from wxsky.inputs.station_table import report_patch
    from wxsky.weather.metar import decode

    v = checked_params("apply_metar", APPLY_METAR, params)
    if "report" not in v:
        raise ControlError("apply_metar: report must be a string")
    # The report names only its day; by default it is the latest such day and time not after
    # the simulated clock, as a report never comes from the future.
    decoded = decode(
        v["report"], year=v.get("year"), month=v.get("month"), now_utc=engine.state.time_utc
    ).require_usable()
    patch = report_patch(decoded, v.get("field_elevation_m"), flag="field_elevation_m")
    engine.apply(patch)
    return decoded.station or ""


# The weather an instructor sets directly (14 CFR Part 60, Appendix C, Table C3B 9.a: cloud
# base, density and visibility), in the keys and units of a preset file; the site, the clock
# and the cloud seed are not an instructor's weather (`set_time`, `set_camera`).
SET_WEATHER_KEYS = (
    "visibility_m",
    "layers",
    "wind",
    "temperature_c",
    "dewpoint_c",
    "qnh_hpa",
    "present_weather",
    "fog",
)


def set_weather(engine: SkyEngine, params: dict[str, Any]) -> list[str]:
    """Any of SET_WEATHER_KEYS, checked as a preset's are, become the control channel's
    override (held until `release`; `layers` replaces the whole list, as in a preset); the
    sky moves there at the [transition] rates, or at once with `now`. Returns the fields set.
    A bad value is a one-line error naming the field; nothing of the request is applied."""
    from wxsky.settings.preset_check import parse_preset_data

    weather = {k: v for k, v in params.items() if k != "now"}
    unknown = sorted(k for k in weather if k not in SET_WEATHER_KEYS)
    if unknown:
        raise ControlError(
            f"set_weather: {clip(str(unknown[0]), 64)}: unknown key "
            f"(known: {', '.join(SET_WEATHER_KEYS)}, now)"
        )
    now = params.get("now", False)
    if not isinstance(now, bool):
        raise ControlError(f"set_weather: now: must be true or false, got {clip(repr(now), 64)}")
    if not weather:
        raise ControlError(f"set_weather: give at least one of {', '.join(SET_WEATHER_KEYS)}")
    _, patch, problems = parse_preset_data({"description": "set_weather", **weather})
    if problems:
        first = problems[0]
        where = ".".join(str(part) for part in first.path)
        raise ControlError(clip(f"set_weather: {where}: {first.message}", ERROR_MAX_CHARS))
    if "fog" not in weather:  # a preset without [fog] has none; a request says nothing of it
        patch = dataclasses.replace(patch, fog=None)
    engine.apply(dataclasses.replace(patch, source=Source.CONTROL))
    if now:
        engine.settle()
    return sorted(weather)


FREEZE = Table({"frozen": Field(Bool(), REQUIRED)})
SAVE_PRESET = Table(
    {
        "name": Field(PRESET_NAME, REQUIRED),
        "description": Field(Text(max_len=200), ""),
        "force": Field(Bool(), False),
    }
)


def freeze(engine: SkyEngine, params: dict[str, Any]) -> dict[str, Any]:
    """`frozen`: stop the weather where it stands (the clock, the clouds' drift and growth,
    the transitions), or let it go on; the frames go on either way."""
    v = checked_params("freeze", FREEZE, params)
    engine.frozen = v["frozen"]
    return {"frozen": engine.frozen}


def save_preset(engine: SkyEngine, params: dict[str, Any]) -> dict[str, Any]:
    """The target weather (what the sky is moving to, or shows once settled) as the user
    preset `name` (`wxsky preset save`'s folder), refusing to replace one unless `force`."""
    from datetime import UTC, datetime

    from wxsky.settings.presets import patch_from_weather_dict, preset_to_toml, write_user_preset
    from wxsky.weather.state import weather_to_dict

    v = checked_params("save_preset", SAVE_PRESET, params)
    patch = patch_from_weather_dict(weather_to_dict(engine.target))
    description = v["description"] or f"Saved from the running daemon at {engine.state.summary()}"
    stamp = f"{datetime.now(UTC):%Y-%m-%d %H:%MZ}"
    text = preset_to_toml(patch, description, comment=f"Written by save_preset {stamp}")
    path = write_user_preset(v["name"], text, force=v["force"])
    return {"name": v["name"], "path": str(path)}


def dispatch_table(
    handlers: dict[str, Callable[[dict[str, Any]], Any]],
) -> Callable[[str, dict[str, Any]], Any]:
    def dispatch(method: str, params: dict[str, Any]) -> Any:
        handler = handlers.get(method)
        if handler is None:
            raise ControlError(
                f"unknown command {clip(method, 64)!r} (known: {', '.join(sorted(handlers))})"
            )
        try:
            return handler(params)
        except WxskyError:
            raise
        except ValueError as exc:
            raise ControlError(clip(f"{method}: {exc}", ERROR_MAX_CHARS)) from None

    return dispatch
