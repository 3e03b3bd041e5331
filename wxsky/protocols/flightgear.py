"""FlightGear's side of the coupling (issue 18; plugins/flightgear/): the pose FlightGear streams
with its generic protocol (`plugins/flightgear/Protocol/wxsky.xml`), and the properties that
set FlightGear's weather from wxsky's applied weather.

FlightGear has no plugin interface for external textures; it has state interfaces. Its generic
protocol writes a line of chosen properties per frame (here: position, attitude, the view's
offsets and field of view, the sim's UTC), and its telnet/props server sets any property. Both
are text: this module is pure, parses and formats only, and never raises on a line.

Units at this edge are FlightGear's (feet, knots, inHg, degrees); wxsky's inside are SI.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from datetime import UTC, datetime

from wxsky.units import FT_TO_M, INHG_TO_HPA, KT_TO_MPS
from wxsky.weather.geo import enu_from_geodetic
from wxsky.weather.model_profile import temperature_at_height
from wxsky.weather.state import (
    TIME_RANGE_TEXT,
    CloudLayer,
    CloudType,
    WeatherState,
    dir_from_deg,
    time_in_range,
)

# The generic protocol's chunks, in the order Protocol/wxsky.xml writes them.
OLD_FIELDS = 11  # before the viewer's place and view-internal
POSE_FIELDS = (
    "latitude-deg",
    "longitude-deg",
    "altitude-ft",
    "heading-deg",
    "pitch-deg",
    "roll-deg",
    "view-heading-offset-deg",
    "view-pitch-offset-deg",
    "field-of-view",
    "ground-elev-ft",
    "viewer-lat-deg",
    "viewer-lon-deg",
    "viewer-elev-ft",
    "view-internal",
    "gmt",
)
MAX_LINE = 512  # characters: a pose line is about 160
ALT_FT = (-1500.0, 100_000.0)  # FlightGear writes -9999 and nan while it resets
FOV_DEG = (1.0, 170.0)
GROUND_FT = (-1500.0, 30_000.0)
MIN_CHASE_M = 0.5  # an outside eye nearer the aircraft than this looks where it heads
MAX_LAYERS = 5  # /environment/clouds/layer[0..4]
MAX_ALOFT = 3  # /environment/config/aloft/entry[0..2]


@dataclass(frozen=True)
class FgPose:
    """One frame of FlightGear's aircraft and view, SI inside."""

    lat_deg: float
    lon_deg: float
    alt_m: float
    heading_deg: float  # the aircraft's, true
    pitch_deg: float
    roll_deg: float
    view_heading_offset_deg: float  # FlightGear's: positive turns the view left
    view_pitch_offset_deg: float  # positive up
    fov_deg: float  # horizontal
    ground_m: float  # the terrain under the aircraft, MSL
    viewer_lat_deg: float  # where the view's eye is: the pilot's seat, or a chase camera's
    viewer_lon_deg: float
    viewer_alt_m: float  # MSL
    internal: bool  # a view from inside the aircraft (FlightGear's /sim/current-view/internal)
    time_utc: datetime

    @property
    def view_heading_deg(self) -> float:
        """Where the eye looks, true. From inside: the aircraft's heading less the view's
        offset (FlightGear's offset turns the view left: 90 from a northbound aircraft looks
        west, measured against its view quaternion). From outside: toward the aircraft, as
        FlightGear's chase and tower views look."""
        toward = self._toward_aircraft
        if toward is not None:
            return toward[0]
        return (self.heading_deg - self.view_heading_offset_deg) % 360.0

    @property
    def view_pitch_deg(self) -> float:
        toward = self._toward_aircraft
        if toward is not None:
            return toward[1]
        return max(-90.0, min(90.0, self.pitch_deg + self.view_pitch_offset_deg))

    @property
    def view_roll_deg(self) -> float:
        """A view from outside is level; one from inside rolls with the aircraft."""
        return self.roll_deg if self._toward_aircraft is None else 0.0

    @functools.cached_property
    def _toward_aircraft(self) -> tuple[float, float] | None:
        """(heading, pitch) from an outside eye to the aircraft; None from inside, or from
        an eye so near the aircraft that the direction means nothing. Made once a pose: the
        view's heading, pitch and roll each ask."""
        if self.internal:
            return None
        east_m, north_m, up_m = enu_from_geodetic(
            self.viewer_lat_deg, self.viewer_lon_deg, self.lat_deg, self.lon_deg, self.alt_m
        )
        up_m -= self.viewer_alt_m
        level_m = math.hypot(east_m, north_m)
        if math.hypot(level_m, up_m) < MIN_CHASE_M:
            return None
        heading = math.degrees(math.atan2(east_m, north_m)) % 360.0
        return heading, math.degrees(math.atan2(up_m, level_m))


@dataclass(frozen=True)
class PoseLine:
    """A line parsed: the pose, or one line saying why it was dropped."""

    pose: FgPose | None = None
    error: str = ""


def parse_pose(line: str | bytes) -> PoseLine:
    """One line of the generic protocol's output; never raises."""
    if isinstance(line, bytes):
        try:
            line = line.decode("ascii")
        except UnicodeDecodeError:
            return PoseLine(error="pose line is not ASCII")
    text = line.strip()
    if len(text) > MAX_LINE:
        return PoseLine(error=f"pose line of {len(text)} characters (at most {MAX_LINE})")
    parts = text.split(",")
    if len(parts) != len(POSE_FIELDS):
        older = " (an older Protocol/wxsky.xml?)" if len(parts) == OLD_FIELDS else ""
        return PoseLine(
            error=f"pose line has {len(parts)} fields, expected {len(POSE_FIELDS)}{older}"
        )
    values: list[float] = []
    for name, raw in zip(POSE_FIELDS[:-1], parts[:-1], strict=True):
        try:
            v = float(raw)
        except ValueError:
            return PoseLine(error=f"pose {name} is not a number: {raw.strip()[:24]!r}")
        if not math.isfinite(v):
            return PoseLine(error=f"pose {name} is {raw.strip()[:24]} (FlightGear resetting?)")
        values.append(v)
    lat, lon, alt_ft, hdg, pitch, roll, v_hdg, v_pitch, fov, ground_ft = values[:10]
    v_lat, v_lon, v_alt_ft, internal = values[10:]
    checks = (
        ("latitude-deg", lat, -90.0, 90.0),
        ("longitude-deg", lon, -180.0, 180.0),
        ("altitude-ft", alt_ft, *ALT_FT),
        ("heading-deg", hdg, -360.0, 720.0),
        ("pitch-deg", pitch, -90.0, 90.0),
        ("roll-deg", roll, -180.0, 180.0),
        ("view-heading-offset-deg", v_hdg, -360.0, 720.0),
        ("view-pitch-offset-deg", v_pitch, -90.0, 90.0),
        ("field-of-view", fov, *FOV_DEG),
        ("ground-elev-ft", ground_ft, *GROUND_FT),
        ("viewer-lat-deg", v_lat, -90.0, 90.0),
        ("viewer-lon-deg", v_lon, -180.0, 180.0),
        ("viewer-elev-ft", v_alt_ft, *ALT_FT),
        ("view-internal", internal, 0.0, 1.0),
    )
    for name, v, lo, hi in checks:
        if not lo <= v <= hi:
            return PoseLine(error=f"pose {name} = {v:g} is outside {lo:g}..{hi:g}")
    when = _gmt(parts[-1].strip())
    if when is None:
        return PoseLine(error=f"pose gmt is not a time: {parts[-1].strip()[:32]!r}")
    if not time_in_range(when):
        return PoseLine(
            error=f"pose gmt {parts[-1].strip()} is outside the clock's range {TIME_RANGE_TEXT}"
        )
    return PoseLine(
        FgPose(
            lat_deg=lat,
            lon_deg=lon,
            alt_m=alt_ft * FT_TO_M,
            heading_deg=hdg % 360.0,
            pitch_deg=pitch,
            roll_deg=roll,
            view_heading_offset_deg=v_hdg,
            view_pitch_offset_deg=v_pitch,
            fov_deg=fov,
            ground_m=ground_ft * FT_TO_M,
            viewer_lat_deg=v_lat,
            viewer_lon_deg=v_lon,
            viewer_alt_m=v_alt_ft * FT_TO_M,
            internal=internal >= 0.5,
            time_utc=when,
        )
    )


def _gmt(text: str) -> datetime | None:
    """FlightGear's /sim/time/gmt: `YYYY-MM-DDTHH:MM:SS`, UTC (exactly: a cut line's
    `...:3` would read as 3 seconds)."""
    if len(text) != 19:
        return None
    try:
        when = datetime.strptime(text, "%Y-%m-%dT%H:%M:%S")
    except ValueError:
        return None
    return when.replace(tzinfo=UTC)


# -- wxsky's weather as FlightGear's properties ---------------------------------------------

# Properties that stop FlightGear's own weather from overwriting what wxsky sets (its basic
# weather reverts cloud layers within about 12 s otherwise).
TAKE_OVER = (
    ("/environment/params/metar-updates-environment", "0"),
    ("/environment/config/enabled", "0"),
)
CIRRUS_FAMILY = frozenset({CloudType.CIRRUS, CloudType.CIRROSTRATUS, CloudType.CIRROCUMULUS})


def coverage_name(layer: CloudLayer) -> str:
    """FlightGear's coverage word for a layer: by oktas as METAR counts them, and "cirrus" for
    the cirrus family short of overcast (FlightGear's thin high-cloud layer)."""
    oktas = layer.cover_oktas
    if oktas <= 0.0:
        return "clear"
    if layer.type in CIRRUS_FAMILY and oktas < 8.0:
        return "cirrus"
    if oktas <= 2.0:
        return "few"
    if oktas <= 4.0:
        return "scattered"
    if oktas < 8.0:
        return "broken"
    return "overcast"


def weather_properties(
    state: WeatherState, aloft_c: tuple[tuple[float, float], ...] = ()
) -> tuple[tuple[str, str], ...]:
    """Every property that puts `state` (wxsky's applied weather) into FlightGear, in the
    order to set them: its cloud layers (lowest first; the rest cleared), visibility, surface
    wind and temperatures, pressure, and the winds aloft, with model data's temperatures
    there (`aloft_c`, ((height_m, degC), ...) from the ground up) where it is read."""
    out: list[tuple[str, str]] = []
    layers = sorted((lay for lay in state.layers if lay.cover_oktas > 0.0), key=_base)
    for i in range(MAX_LAYERS):
        path = f"/environment/clouds/layer[{i}]"
        if i < len(layers):
            lay = layers[i]
            out.append((f"{path}/coverage", coverage_name(lay)))
            out.append((f"{path}/elevation-ft", _num(lay.base_m / FT_TO_M)))
            out.append((f"{path}/thickness-ft", _num(lay.thickness_m / FT_TO_M)))
        else:
            out.append((f"{path}/coverage", "clear"))
    out.append(("/environment/visibility-m", _num(state.visibility_m)))
    surface = state.observer.alt_m
    heading, speed = _wind(state, surface)
    boundary = "/environment/config/boundary/entry[0]"
    out.append((f"{boundary}/elevation-ft", _num(surface / FT_TO_M)))
    out.append((f"{boundary}/wind-from-heading-deg", _num(heading)))
    out.append((f"{boundary}/wind-speed-kt", _num(speed)))
    out.append((f"{boundary}/visibility-m", _num(state.visibility_m)))
    if state.temperature_c is not None:
        out.append((f"{boundary}/temperature-degc", _num(state.temperature_c)))
    if state.dewpoint_c is not None:
        out.append((f"{boundary}/dewpoint-degc", _num(state.dewpoint_c)))
    if state.qnh_hpa is not None:
        out.append((f"{boundary}/pressure-sea-level-inhg", f"{state.qnh_hpa / INHG_TO_HPA:.2f}"))
    out.append(("/environment/wind-from-heading-deg", _num(heading)))
    out.append(("/environment/wind-speed-kt", _num(speed)))
    # Aloft: the wind at the levels FlightGear's own aloft table uses, above the field.
    for i, above_ft in enumerate((3000.0, 9000.0, 24000.0)[:MAX_ALOFT]):
        alt_m = surface + above_ft * FT_TO_M
        heading, speed = _wind(state, alt_m)
        entry = f"/environment/config/aloft/entry[{i}]"
        out.append((f"{entry}/elevation-ft", _num(alt_m / FT_TO_M)))
        out.append((f"{entry}/wind-from-heading-deg", _num(heading)))
        out.append((f"{entry}/wind-speed-kt", _num(speed)))
        out.append((f"{entry}/visibility-m", _num(state.visibility_m)))
        temperature = temperature_at_height(aloft_c, alt_m)
        if temperature is not None:
            out.append((f"{entry}/temperature-degc", _num(temperature)))
    return tuple(out)


def _base(layer: CloudLayer) -> float:
    return layer.base_m


def _wind(state: WeatherState, alt_m: float) -> tuple[float, float]:
    """(from heading, true degrees; speed, knots) of the state's wind at `alt_m` MSL."""
    ve, vn = state.wind_at(alt_m)
    speed = math.hypot(ve, vn)
    return (dir_from_deg(ve, vn) if speed > 0.0 else 0.0), speed / KT_TO_MPS


def _num(value: float) -> str:
    """A property value as FlightGear's props server takes it: plain decimal, no exponent,
    to a hundredth."""
    text = f"{value:.2f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text
