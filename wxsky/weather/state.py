"""The weather state: one immutable snapshot of the atmosphere around the observer, in SI units.

Every input (preset, METAR, cockpit hardware, control channel) produces a `WeatherPatch` naming
only the fields it knows; `WeatherState.apply` merges it and records where each field came from.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Any

from wxsky.schema import Number

MAX_LAYERS = 6

# The weather's limits, each written once: the state checks itself against them, and preset
# files, cockpit values and control requests are checked against the same kinds.
LAT_DEG = Number(-90.0, 90.0, unit="deg")
LON_DEG = Number(-180.0, 180.0, unit="deg")
ALT_M = Number(-500.0, 30_000.0, unit="m")  # the observer and wind levels, MSL
LAYER_HEIGHT_M = Number(-500.0, 25_000.0, unit="m")  # cloud bases and tops, MSL
LAYER_THICKNESS_M = Number(0.0, 25_000.0, unit="m", above_lo=True)
# Reports and presets give whole oktas; the applied weather moves between them continuously.
COVER_OKTAS = Number(0.0, 8.0, unit="oktas")
WHOLE_OKTAS = Number(0, 8, integer=True, unit="oktas")
WIND_DIR_DEG = Number(0.0, 360.0, unit="deg")  # from, true
WIND_SPEED_MPS = Number(0.0, 150.0, unit="m/s")
GUST_MPS = Number(0.0, 200.0, unit="m/s")
VISIBILITY_M = Number(0.0, 1_000_000.0, unit="m")
TEMPERATURE_C = Number(-90.0, 60.0, unit="degC")  # also the dew point
QNH_HPA = Number(850.0, 1100.0, unit="hPa")
SEED = Number(0, 2**63 - 1, integer=True)
COVERAGE_PCT = Number(0.0, 100.0, unit="%")
SEVERITY = Number(0, 5, integer=True)
MAX_PRECIPITATION = 4  # one of each kind
# Fog (issue 43 item 3, docs/fog.md): how far one sees inside it, how high its top stands over
# the ground, and the runway visual range by runway. A METAR gives at most four RVR groups.
FOG_VISIBILITY_M = Number(10.0, 10_000.0, unit="m")
FOG_DEPTH_M = Number(1.0, 1_000.0, unit="m")
RVR_M = Number(10.0, 10_000.0, unit="m")
MAX_RVR = 4
# A runway designator: its heading in tens of degrees (01-36), L, C or R for parallel ones.
RUNWAY_PATTERN = r"(?:0[1-9]|[12][0-9]|3[0-6])[LCR]?"


class CloudType(enum.IntEnum):
    """Cloud types, numbered as CIGI's Weather Control packet numbers them."""

    NONE = 0
    ALTOCUMULUS = 1
    ALTOSTRATUS = 2
    CIRROCUMULUS = 3
    CIRROSTRATUS = 4
    CIRRUS = 5
    CUMULONIMBUS = 6
    CUMULUS = 7
    NIMBOSTRATUS = 8
    STRATOCUMULUS = 9
    STRATUS = 10

    @property
    def wire_name(self) -> str:
        return self.name.lower()

    @classmethod
    def from_name(cls, name: str) -> CloudType:
        try:
            return cls[name.strip().upper()]
        except KeyError:
            known = ", ".join(t.wire_name for t in cls if t is not cls.NONE)
            raise ValueError(f"unknown cloud type {name!r} (known: {known})") from None


class Source(enum.StrEnum):
    """Where a field of the weather state came from."""

    DEFAULT = "default"
    PRESET = "preset"
    METAR = "metar"
    GRIB = "grib"  # numerical model data (issue 45), below METAR
    COCKPIT = "cockpit"
    CONTROL = "control"
    CIGI = "cigi"


@dataclass(frozen=True)
class Observer:
    lat_deg: float
    lon_deg: float
    alt_m: float

    def __post_init__(self) -> None:
        LAT_DEG.validate("observer.lat_deg", self.lat_deg)
        LON_DEG.validate("observer.lon_deg", self.lon_deg)
        ALT_M.validate("observer.alt_m", self.alt_m)


@dataclass(frozen=True)
class CloudLayer:
    # Reports and presets give whole oktas; the applied weather moves between them continuously
    # while clouds form and dissipate, so fractions are valid here.
    cover_oktas: float
    base_m: float  # MSL
    top_m: float  # MSL
    type: CloudType

    def __post_init__(self) -> None:
        COVER_OKTAS.validate("cloud layer cover_oktas", self.cover_oktas)
        LAYER_HEIGHT_M.validate("cloud layer base_m", self.base_m)
        LAYER_HEIGHT_M.validate("cloud layer top_m", self.top_m)
        if self.top_m <= self.base_m:
            raise ValueError(f"cloud layer top_m {self.top_m} must be above base_m {self.base_m}")
        # Not a bare number or name: the scene looks its models up by the type's members.
        if not isinstance(self.type, CloudType):
            raise ValueError(f"cloud layer type must be one of CloudType, got {self.type!r}")

    @property
    def thickness_m(self) -> float:
        return self.top_m - self.base_m


class PrecipKind(enum.IntEnum):
    """Kinds of precipitation layer, numbered as CIGI's Weather Control layer ids."""

    RAIN = 4
    SNOW = 5
    SLEET = 6
    HAIL = 7

    @property
    def wire_name(self) -> str:
        return self.name.lower()

    @property
    def metar_code(self) -> str:
        """The METAR present-weather code (ice pellets for sleet, as ICAO names it)."""
        return {4: "RA", 5: "SN", 6: "PL", 7: "GR"}[self.value]


@dataclass(frozen=True)
class PrecipLayer:
    """A layer of falling precipitation: the scene hangs shafts of it under cumulonimbus and
    nimbostratus (`scene.rain`). `severity` is CIGI's 0 (lightest) to 5 (heaviest)."""

    kind: PrecipKind
    base_m: float  # MSL
    top_m: float  # MSL
    coverage_pct: float
    severity: int
    visibility_m: float  # inside the precipitation

    def __post_init__(self) -> None:
        LAYER_HEIGHT_M.validate("precipitation base_m", self.base_m)
        LAYER_HEIGHT_M.validate("precipitation top_m", self.top_m)
        if self.top_m <= self.base_m:
            raise ValueError(f"precipitation top_m {self.top_m} must be above base_m {self.base_m}")
        COVERAGE_PCT.validate("precipitation coverage_pct", self.coverage_pct)
        SEVERITY.validate("precipitation severity", self.severity)
        VISIBILITY_M.validate("precipitation visibility_m", self.visibility_m)

    @property
    def metar_code(self) -> str:
        """As a METAR group: `-RA` (severity 0-1), `RA` (2-3), `+RA` (4-5)."""
        return ("-", "-", "", "", "+", "+")[self.severity] + self.kind.metar_code


@dataclass(frozen=True)
class RunwayRvr:
    """A runway visual range: the runway's designator (`14`, `32L`) and the range at its
    touchdown zone, metres (`scene.fog` places the runway and its touchdown zone)."""

    runway: str
    rvr_m: float

    def __post_init__(self) -> None:
        if not isinstance(self.runway, str) or re.fullmatch(RUNWAY_PATTERN, self.runway) is None:
            raise ValueError(
                f"fog rvr runway must be a designator like 14 or 32L, got {self.runway!r}"
            )
        RVR_M.validate("fog rvr rvr_m", self.rvr_m)


@dataclass(frozen=True)
class Fog:
    """Fog over the ground (docs/fog.md): `visibility_m` inside it where it is densest (None:
    no fog but what the RVRs ask for), its top `depth_m` over the ground, `patchy` for banks
    with clear air between (METAR BCFG, PRFG) instead of one sheet, and runway visual ranges
    the fog is shaped to give at their touchdown zones."""

    visibility_m: float | None = None
    depth_m: float = 100.0
    patchy: bool = False
    rvr: tuple[RunwayRvr, ...] = ()

    def __post_init__(self) -> None:
        if self.visibility_m is not None:
            FOG_VISIBILITY_M.validate("fog visibility_m", self.visibility_m)
        FOG_DEPTH_M.validate("fog depth_m", self.depth_m)
        if len(self.rvr) > MAX_RVR:
            raise ValueError(f"at most {MAX_RVR} fog rvr runways, got {len(self.rvr)}")
        names = [r.runway for r in self.rvr]
        if len(set(names)) < len(names):
            raise ValueError(f"fog rvr names a runway twice: {', '.join(names)}")

    def to_dict(self) -> dict[str, Any]:
        return {
            "visibility_m": self.visibility_m,
            "depth_m": self.depth_m,
            "patchy": self.patchy,
            "rvr": [{"runway": r.runway, "rvr_m": r.rvr_m} for r in self.rvr],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Fog:
        vis = data.get("visibility_m")
        return cls(
            visibility_m=None if vis is None else float(vis),
            depth_m=float(data["depth_m"]),
            patchy=bool(data["patchy"]),
            rvr=tuple(RunwayRvr(str(r["runway"]), float(r["rvr_m"])) for r in data["rvr"]),
        )


@dataclass(frozen=True)
class WindLayer:
    alt_m: float  # MSL
    dir_from_deg: float  # direction the wind blows from, true
    speed_mps: float
    gust_mps: float = 0.0  # 0 when no gusts were reported
    variable: bool = False  # METAR VRB: direction not steady

    def __post_init__(self) -> None:
        ALT_M.validate("wind alt_m", self.alt_m)
        WIND_DIR_DEG.validate("wind dir_from_deg", self.dir_from_deg)
        WIND_SPEED_MPS.validate("wind speed_mps", self.speed_mps)
        GUST_MPS.validate("wind gust_mps", self.gust_mps)

    def velocity_mps(self) -> tuple[float, float]:
        """(east, north) velocity of the air; the wind blows *from* dir_from_deg."""
        to_rad = math.radians(self.dir_from_deg + 180.0)
        return (self.speed_mps * math.sin(to_rad), self.speed_mps * math.cos(to_rad))


def dir_from_deg(east_mps: float, north_mps: float) -> float:
    """The direction (0..360, true) a wind of this (east, north) velocity blows from: the
    inverse of `WindLayer.velocity_mps`. The velocity points where the air goes; the wind is
    named for where it comes from."""
    return (math.degrees(math.atan2(east_mps, north_mps)) + 180.0) % 360.0


@dataclass(frozen=True)
class Provenance:
    """The source of each top-level field of a WeatherState."""

    observer: Source = Source.DEFAULT
    time_utc: Source = Source.DEFAULT
    layers: Source = Source.DEFAULT
    wind: Source = Source.DEFAULT
    visibility_m: Source = Source.DEFAULT
    temperature_c: Source = Source.DEFAULT
    dewpoint_c: Source = Source.DEFAULT
    qnh_hpa: Source = Source.DEFAULT
    present_weather: Source = Source.DEFAULT
    precipitation: Source = Source.DEFAULT
    fog: Source = Source.DEFAULT
    seed: Source = Source.DEFAULT


@dataclass(frozen=True)
class WeatherPatch:
    """A partial update from one source; None means "this source says nothing about it"."""

    source: Source
    observer: Observer | None = None
    time_utc: datetime | None = None
    layers: tuple[CloudLayer, ...] | None = None
    wind: tuple[WindLayer, ...] | None = None
    visibility_m: float | None = None
    temperature_c: float | None = None
    dewpoint_c: float | None = None
    qnh_hpa: float | None = None
    present_weather: tuple[str, ...] | None = None
    precipitation: tuple[PrecipLayer, ...] | None = None
    # A source that says "no fog" gives NO_FOG, not None (which says nothing).
    fog: Fog | None = None
    seed: int | None = None


# A patch's word for "no fog" (the state holds None): a report without fog clears the fog.
NO_FOG = Fog(visibility_m=None, depth_m=1.0)


# The clock's valid range, for every input that sets time (issue 40): wide enough for any
# training scenario and any replayed archive, far enough inside datetime's years 1..9999 that
# whatever looks ahead or behind (the sun and moon smoothing, forecasts, channel clocks) never
# leaves them. Inputs are checked against it at the edge; code that computes ahead clamps.
EARLIEST_UTC = datetime(1900, 1, 1, tzinfo=UTC)
LATEST_UTC = datetime(2200, 1, 1, tzinfo=UTC)  # exclusive


# The last moment the clock may show: a clock run up to the end stops here.
LAST_UTC = LATEST_UTC - timedelta(microseconds=1)
TIME_RANGE_TEXT = "1900-01-01T00:00:00Z up to (not including) 2200-01-01T00:00:00Z"
CLOCK_YEARS = f"{EARLIEST_UTC.year}..{LATEST_UTC.year - 1}"  # the range as whole years


def time_in_range(time_utc: datetime) -> bool:
    """Whether an aware time lies in [EARLIEST_UTC, LATEST_UTC)."""
    return EARLIEST_UTC <= time_utc < LATEST_UTC


def year_in_range(year: int) -> bool:
    """Whether every moment of a calendar year lies in the clock's range (a date's check)."""
    return EARLIEST_UTC.year <= year < LATEST_UTC.year


def check_time_range(what: str, time_utc: datetime) -> datetime:
    """`time_utc` when it is in the clock's range, else ValueError naming `what` and the range
    (one line, for an input's error)."""
    if not time_in_range(time_utc):
        shown = time_utc.isoformat().replace("+00:00", "Z")
        raise ValueError(f"{what} {shown} is outside the clock's range {TIME_RANGE_TEXT}")
    return time_utc


def clamped_time(time_utc: datetime, ahead_s: float) -> datetime:
    """`time_utc` moved by ahead_s (negative: back), held inside [EARLIEST_UTC, LAST_UTC]: what
    computes ahead or behind of the clock (its own running, a drift, a tower's age) can never
    leave datetime's years, whatever the rate or the step."""
    t = min(max(time_utc, EARLIEST_UTC), LAST_UTC)
    if math.isnan(ahead_s):
        return t
    if ahead_s >= (LAST_UTC - t).total_seconds():
        return LAST_UTC
    if -ahead_s >= (t - EARLIEST_UTC).total_seconds():
        return EARLIEST_UTC
    return t + timedelta(seconds=ahead_s)


def _check_utc(time_utc: datetime) -> None:
    if time_utc.tzinfo is None or time_utc.utcoffset() != UTC.utcoffset(None):
        raise ValueError("time_utc must be timezone-aware UTC")


@dataclass(frozen=True)
class WeatherState:
    observer: Observer = field(default_factory=lambda: Observer(47.4647, 8.5492, 432.0))
    time_utc: datetime = field(default_factory=lambda: datetime(2026, 6, 21, 12, 0, tzinfo=UTC))
    layers: tuple[CloudLayer, ...] = ()  # sorted by base_m
    wind: tuple[WindLayer, ...] = ()  # sorted by alt_m
    visibility_m: float = 10_000.0
    temperature_c: float | None = 15.0
    dewpoint_c: float | None = 5.0
    qnh_hpa: float = 1013.25
    present_weather: tuple[str, ...] = ()  # METAR weather groups, e.g. ("-RA", "BR")
    precipitation: tuple[PrecipLayer, ...] = ()  # sorted by base_m; shafts (scene.rain)
    fog: Fog | None = None  # None: no fog (scene.fog)
    seed: int = 1
    sources: Provenance = field(default_factory=Provenance)

    def __post_init__(self) -> None:
        _check_utc(self.time_utc)
        if len(self.layers) > MAX_LAYERS:
            raise ValueError(f"at most {MAX_LAYERS} cloud layers, got {len(self.layers)}")
        if len(self.precipitation) > MAX_PRECIPITATION:
            raise ValueError(
                f"at most {MAX_PRECIPITATION} precipitation layers, got {len(self.precipitation)}"
            )
        VISIBILITY_M.validate("visibility_m", self.visibility_m)
        QNH_HPA.validate("qnh_hpa", self.qnh_hpa)
        if self.temperature_c is not None:
            TEMPERATURE_C.validate("temperature_c", self.temperature_c)
        if self.dewpoint_c is not None:
            TEMPERATURE_C.validate("dewpoint_c", self.dewpoint_c)
        SEED.validate("seed", self.seed)
        object.__setattr__(self, "layers", tuple(sorted(self.layers, key=lambda lay: lay.base_m)))
        object.__setattr__(self, "wind", tuple(sorted(self.wind, key=lambda w: w.alt_m)))
        object.__setattr__(
            self, "precipitation", tuple(sorted(self.precipitation, key=lambda p: p.base_m))
        )

    def apply(self, patch: WeatherPatch) -> WeatherState:
        """A new state with every field the patch sets taken from it, provenance updated."""
        changes: dict[str, Any] = {}
        sources: dict[str, Source] = {}
        for f in dataclasses.fields(Provenance):
            value = getattr(patch, f.name)
            if value is not None:
                changes[f.name] = None if value == NO_FOG else value
                sources[f.name] = patch.source
        if not changes:
            return self
        return dataclasses.replace(
            self, **changes, sources=dataclasses.replace(self.sources, **sources)
        )

    def at_time(self, time_utc: datetime) -> WeatherState:
        """This state at another moment. The daemon's clock moves the weather every frame,
        and checking every other field again on the way (dataclasses.replace) was a twentieth
        of a frame's scene stage: nothing else changed, so only the time is checked."""
        _check_utc(time_utc)
        out = object.__new__(WeatherState)
        out.__dict__.update(self.__dict__)  # copy.copy's result, at a fifth of its cost
        out.__dict__["time_utc"] = time_utc
        return out

    @functools.cached_property
    def _wind_profile(self) -> tuple[list[float], list[tuple[float, float]]]:
        # Asked for by every layer's drift and the dome, every frame: worked out once a state.
        return [w.alt_m for w in self.wind], [w.velocity_mps() for w in self.wind]

    @functools.cached_property
    def layer_winds_mps(self) -> tuple[tuple[float, float], ...]:
        """(east, north) wind at each layer's mid altitude, the wind its clouds drift with:
        worked out once a state (`at_time` keeps it), not every frame."""
        return tuple(self.wind_at(0.5 * (lay.base_m + lay.top_m)) for lay in self.layers)

    def wind_at(self, alt_m: float) -> tuple[float, float]:
        """(east, north) wind velocity at an altitude, linear between reported levels."""
        if not self.wind:
            return (0.0, 0.0)
        alts, vel = self._wind_profile
        if alt_m <= alts[0]:
            return vel[0]
        if alt_m >= alts[-1]:
            return vel[-1]
        for i in range(1, len(alts)):
            if alt_m <= alts[i]:
                t = (alt_m - alts[i - 1]) / (alts[i] - alts[i - 1])
                return (
                    vel[i - 1][0] + t * (vel[i][0] - vel[i - 1][0]),
                    vel[i - 1][1] + t * (vel[i][1] - vel[i - 1][1]),
                )
        return vel[-1]

    def summary(self) -> str:
        """One line for logs and status lines."""
        clouds = " ".join(
            f"{lay.type.wire_name}:{lay.cover_oktas:.3g}/8@{lay.base_m:.0f}m" for lay in self.layers
        )
        wind = self.wind[0] if self.wind else None
        wind_txt = f"{wind.dir_from_deg:03.0f}/{wind.speed_mps:.1f}mps" if wind else "calm"
        return (
            f"{format_time_utc(self.time_utc)[:-4]}Z wind {wind_txt} vis {self.visibility_m:.0f}m "
            f"clouds {clouds or 'none'}"
        )


def weather_to_dict(state: WeatherState) -> dict[str, Any]:
    """The weather state as plain data, with the field names of the status/stream protocol."""
    return {
        "time_utc": format_time_utc(state.time_utc),
        "observer": {
            "lat_deg": state.observer.lat_deg,
            "lon_deg": state.observer.lon_deg,
            "alt_m": state.observer.alt_m,
        },
        "wind": [
            {
                "alt_m": w.alt_m,
                "dir_deg": w.dir_from_deg,
                "speed_mps": w.speed_mps,
                "gust_mps": w.gust_mps,
                "variable": w.variable,
            }
            for w in state.wind
        ],
        "visibility_m": state.visibility_m,
        "temperature_c": state.temperature_c,
        "dewpoint_c": state.dewpoint_c,
        "qnh_hpa": state.qnh_hpa,
        "present_weather": list(state.present_weather),
        "layers": [
            {
                "cover_oktas": lay.cover_oktas,
                "base_m": lay.base_m,
                "top_m": lay.top_m,
                "type": lay.type.wire_name,
            }
            for lay in state.layers
        ],
        "precipitation": [
            {
                "kind": p.kind.wire_name,
                "base_m": p.base_m,
                "top_m": p.top_m,
                "coverage_pct": p.coverage_pct,
                "severity": p.severity,
                "visibility_m": p.visibility_m,
            }
            for p in state.precipitation
        ],
        "fog": None if state.fog is None else state.fog.to_dict(),
        "seed": state.seed,
        "sources": {
            f.name: getattr(state.sources, f.name).value for f in dataclasses.fields(Provenance)
        },
    }


def weather_from_dict(data: Mapping[str, Any]) -> WeatherState:
    """`weather_to_dict`'s map (the status `weather`, a `weather` notification) back as the
    state, fractional cover and precipitation included; `sources` may be left out. Raises
    KeyError, TypeError or ValueError when the map is not weather."""
    obs = data["observer"]
    return WeatherState(
        observer=Observer(float(obs["lat_deg"]), float(obs["lon_deg"]), float(obs["alt_m"])),
        time_utc=parse_time_utc(str(data["time_utc"])),
        layers=tuple(
            CloudLayer(
                float(lay["cover_oktas"]),
                float(lay["base_m"]),
                float(lay["top_m"]),
                CloudType.from_name(str(lay["type"])),
            )
            for lay in data["layers"]
        ),
        wind=tuple(
            WindLayer(
                float(w["alt_m"]),
                float(w["dir_deg"]),
                float(w["speed_mps"]),
                float(w["gust_mps"]),
                bool(w["variable"]),
            )
            for w in data["wind"]
        ),
        visibility_m=float(data["visibility_m"]),
        temperature_c=_float_or_none(data["temperature_c"]),
        dewpoint_c=_float_or_none(data["dewpoint_c"]),
        qnh_hpa=float(data["qnh_hpa"]),
        present_weather=tuple(str(group) for group in data["present_weather"]),
        precipitation=tuple(
            PrecipLayer(
                PrecipKind[str(p["kind"]).upper()],
                float(p["base_m"]),
                float(p["top_m"]),
                float(p["coverage_pct"]),
                int(p["severity"]),
                float(p["visibility_m"]),
            )
            for p in data["precipitation"]
        ),
        fog=None if data.get("fog") is None else Fog.from_dict(data["fog"]),
        seed=int(data["seed"]),
        sources=Provenance(
            **{name: Source(value) for name, value in dict(data.get("sources") or {}).items()}
        ),
    )


def _float_or_none(value: Any) -> float | None:
    return None if value is None else float(value)


def format_time_utc(t: datetime) -> str:
    """ISO 8601 with a Z suffix, seconds precision."""
    t = t.astimezone(UTC)
    # The year padded by hand: strftime writes year 857 as `857`, which is not ISO 8601.
    return f"{t.year:04d}-{t:%m-%dT%H:%M:%S}Z"


def parse_time_utc(text: str) -> datetime:
    """ISO 8601 date-time; a naive value is taken as UTC. Raises ValueError naming the text."""
    try:
        t = datetime.fromisoformat(text.strip().replace("Z", "+00:00").replace("z", "+00:00"))
    except ValueError:
        raise ValueError(f"not an ISO 8601 time: {text!r}") from None
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    try:
        t = t.astimezone(UTC)
    except OverflowError:  # 0001-01-01T00:00+01:00 is in year 0 in UTC
        raise ValueError(f"{text!r} is outside the years 1..9999 in UTC") from None
    if not time_in_range(t):
        raise ValueError(f"{text.strip()!r} is outside the clock's range {TIME_RANGE_TEXT}")
    return t
