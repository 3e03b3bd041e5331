"""The daemon config: a TOML file read into frozen dataclasses, one per section, in SI units.

Every key is optional and has a default; unknown keys, wrong types and out-of-range values are
errors naming the file, the line and the dotted key (`FILE:LINE: camera.width: problem`), all
of them at once, because a silently ignored typo in a config is worse than a daemon that
refuses to start. Each key's kind is a `wxsky.schema` kind; limits owned elsewhere (the
camera's viewport, the scene's block size) are taken from their owners, not copied.
"""

from __future__ import annotations

import dataclasses
import functools
import ipaddress
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar, TypeVar

from wxsky.errors import ConfigError
from wxsky.protocols.nmea import HEADING_SOURCES
from wxsky.scene.camera import FOV_DEG, PITCH_DEG, ROLL_DEG, VIEWPORT_PX
from wxsky.scene.cloud_shadow import SHADOW_MAP_PX
from wxsky.scene.clouds import BLOCK_SIZE_M
from wxsky.scene.exposure import AUTO, EXPOSURE
from wxsky.scene.gather import MAX_NEAR_BLOCKS, MAX_RING_BLOCKS, largest_range, scene_blocks
from wxsky.scene.layout import SKY_MODELS, SceneSettings
from wxsky.scene.lightning import MAX_RATE_PER_MIN
from wxsky.scene.radar import RANGE_NM, SIZE_PX, TILT_DEG
from wxsky.scene.shading import DEFAULT_SHADING, SHADING_MODELS
from wxsky.schema import (
    OMIT,
    REQUIRED,
    Bool,
    Custom,
    Field,
    Invalid,
    Items,
    Kind,
    Number,
    Problem,
    Table,
    Tables,
    Text,
    Tuple,
    fmt_number,
)
from wxsky.schema.toml_file import LocatedProblem, check_toml_text, located_error, read_toml
from wxsky.weather.cockpit import ALL_GROUPS
from wxsky.weather.transition import TransitionRates

# Shared with wxsky.settings.presets; it lives here because presets import this module.
# At most 64 characters: a name is a file name (and a longer one is no name a person types).
PRESET_NAME_PATTERN = r"[a-z0-9-]{1,64}"
PRESET_NAME = Text(
    pattern=PRESET_NAME_PATTERN, pattern_desc="1 to 64 lowercase letters, digits and '-'"
)

# How many nearby METAR stations may be blended (also the bound of `metar fetch --blend`).
BLEND_STATIONS = Number(1, 10, integer=True)

LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")
FEED_FORMATS = ("auto", "awc-csv", "awc-xml", "tgftp", "lines")

# The clock's rate, simulation seconds per wall second (also `set_time`'s rate).
CLOCK_RATE = Number(0.0, 10_000.0)
FIELD_GROUPS = Items(Text(choices=ALL_GROUPS), what=f"a list of {', '.join(ALL_GROUPS)}")


def _network(value: Any) -> str:
    if not isinstance(value, str):
        raise ValueError(f"must be an address or network such as 127.0.0.1/32, got {value!r}")
    try:
        ipaddress.ip_network(value, strict=False)
    except ValueError:
        raise ValueError(f"{value!r} is not an address or network such as 127.0.0.1/32") from None
    return value


# Source addresses a UDP input takes datagrams from: addresses or networks, IPv4 or IPv6.
ALLOW_FROM = Items(
    Custom(_network, "an address or network"), what="a list of addresses or networks"
)

_T = TypeVar("_T")
_UDP = r"udp:(\[[0-9A-Fa-f:.]+\]|[^:\[\]]+):[0-9]{1,5}"
CIGI_ADDRESSES = Items(
    Text(pattern=_UDP, pattern_desc="udp:HOST:PORT"), what="a list of udp:HOST:PORT"
)


def _opt(default: _T, kind: Kind | None = None) -> _T:
    """A config key: its default, and its kind when the type hint alone does not say it."""
    return field(default=default, metadata={"kind": kind})


def _num(lo: float, hi: float, unit: str = "") -> Number:
    return Number(lo, hi, unit=unit)


def _int(lo: int, hi: int, unit: str = "") -> Number:
    return Number(lo, hi, integer=True, unit=unit)


def _fixed(value: float, reason: str) -> Kind:
    """A key that only takes its default, and says why."""

    def convert(v: Any) -> float:
        if v != value or isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ValueError(f"is fixed at {fmt_number(value)}: {reason}, got {v!r}")
        return float(v)

    return Custom(convert, f"fixed at {fmt_number(value)}")


def _paths(value: Any) -> tuple[Path, ...]:
    items = value if isinstance(value, (list, tuple)) else None
    if items is None or not all(isinstance(v, (str, Path)) and str(v) for v in items):
        raise ValueError(f"must be a list of non-empty path strings, got {value!r}")
    return tuple(Path(v).expanduser() for v in items)


_KIND_OF_HINT: dict[Any, Kind] = {
    bool: Bool(),
    str: Text(),
    tuple[str, ...]: Items(Text(non_empty=True), what="a list of non-empty strings"),
    tuple[Path, ...]: Custom(_paths, "a list of paths"),
}


class _Section:
    """Validates and normalises every field on construction, so that code building a section
    directly (tests, `dataclasses.replace`) gets the same checks as the file loader."""

    SECTION: ClassVar[str]

    def __post_init__(self) -> None:
        problems: list[Problem] = []
        cls: type = type(self)  # a class is hashable; mypy cannot see it through the dataclass
        for name, kind in section_kinds(cls).items():
            value = kind.check(getattr(self, name), (self.SECTION, name), problems)
            object.__setattr__(self, name, value)
        if problems:
            raise Invalid(problems)


@functools.cache
def section_kinds(cls: type) -> Mapping[str, Kind]:
    """Every key of a section with its kind (worked out once per class: every construction of a
    section checks itself with it)."""
    hints = typing.get_type_hints(cls)
    out: dict[str, Kind] = {}
    for f in dataclasses.fields(cls):
        kind = f.metadata["kind"] or _KIND_OF_HINT.get(hints[f.name])
        if kind is None:
            raise TypeError(f"{cls.__name__}.{f.name}: no kind for {hints[f.name]!r}")
        out[f.name] = kind
    return MappingProxyType(out)


@dataclass(frozen=True)
class DaemonSection(_Section):
    SECTION: ClassVar[str] = "daemon"

    tick_hz: float = _opt(30.0, _num(1.0, 240.0, "Hz"))
    status_interval_s: float = _opt(5.0, _num(0.1, 3600.0, "s"))
    preset: str = _opt("fair-cumulus", PRESET_NAME)
    log_level: str = _opt("INFO", Text(choices=LOG_LEVELS))
    shutdown_timeout_s: float = _opt(1.5, _num(0.0, 60.0, "s"))


@dataclass(frozen=True)
class CameraSection(_Section):
    SECTION: ClassVar[str] = "camera"

    heading_deg: float = _opt(0.0, _num(0.0, 360.0, "deg"))
    pitch_deg: float = _opt(12.0, PITCH_DEG)
    roll_deg: float = _opt(0.0, ROLL_DEG)
    fov_deg: float = _opt(60.0, FOV_DEG)  # horizontal
    width: int = _opt(960, VIEWPORT_PX)
    height: int = _opt(540, VIEWPORT_PX)
    alt_agl_m: float = _opt(2.0, _num(0.0, 20_000.0, "m"))  # above the observer's altitude


@dataclass(frozen=True)
class SceneSection(_Section):
    SECTION: ClassVar[str] = "scene"

    ring_radius_m: float = _opt(8000.0, _num(100.0, 200_000.0, "m"))
    max_range_m: float = _opt(40_000.0, _num(1000.0, 500_000.0, "m"))
    ring_texture_px: int = _opt(512, _int(16, 4096, "px"))
    # A new ring cross-fades over the old one for this long (Wang); 0 swaps at once.
    ring_fade_s: float = _opt(1.0, _num(0.0, 30.0, "s"))
    # A rebuild draws an impostor over as many frames as it takes to spend about this long on
    # it in each (0: one whole impostor a frame, as Wang).
    ring_slice_ms: float = _opt(4.0, _num(0.0, 1000.0, "ms"))
    # Where a rebuild's sprite work runs: a child process below the frames' priority, or a
    # thread of the daemon (shares the GIL with the frames: they stutter while it builds).
    ring_worker: str = _opt("process", Text(choices=("process", "thread")))
    # How far below the frames the worker process runs (0..19, as `nice`).
    ring_worker_nice: int = _opt(19, _int(0, 19))
    # Near sprites this far away are drawn at the ring impostors' texel density (0: never).
    far_band_m: float = _opt(2000.0, _num(0.0, 200_000.0, "m"))
    # Near clouds this far away are drawn as one sprite each (Wang's LOD; 0: never).
    lod_start_m: float = _opt(0.0, _num(0.0, 200_000.0, "m"))
    # Clouds in the ring this far from its centre go into impostors as one sprite (0: never).
    impostor_lod_m: float = _opt(0.0, _num(0.0, 500_000.0, "m"))
    # At most this many near sprites a frame: past it the farthest clouds fade out (0: no cap).
    max_near_sprites: int = _opt(20_000, _int(0, 10_000_000))
    # Texels per side of the cloud-shadow map over the ring's area (the segment's `shadow`
    # layer, made with each ring; 0: no map and no layer).
    shadow_map_px: int = _opt(SHADOW_MAP_PX, _int(0, 4096, "px"))
    # At most this many convective cells a frame grow as volumes (the nearest; the rest stay
    # sprite clouds; 0: none).
    max_towers: int = _opt(6, _int(0, 64))
    block_size_m: float = _opt(
        BLOCK_SIZE_M, _fixed(BLOCK_SIZE_M, "the cloud field is generated in 4 km blocks by design")
    )
    shading: str = _opt(DEFAULT_SHADING, Text(choices=SHADING_MODELS))
    # The sky: a physical atmosphere (Rayleigh, Mie, ozone; docs/atmosphere.md) or Roden &
    # Parberry's gradient and dome controls as before issue 41.
    sky: str = _opt("physical", Text(choices=SKY_MODELS))

    def settings(self) -> SceneSettings:
        """The scene stage's view of this section."""
        return SceneSettings(
            ring_radius_m=self.ring_radius_m,
            max_range_m=self.max_range_m,
            ring_texture_px=self.ring_texture_px,
            shading=self.shading,
            sky=self.sky,
            far_band_m=self.far_band_m,
            lod_start_m=self.lod_start_m,
            impostor_lod_m=self.impostor_lod_m,
            max_near_sprites=self.max_near_sprites,
            shadow_map_px=self.shadow_map_px,
            max_towers=self.max_towers,
        )


# [lightning] flashes_per_min: "weather" (by the storm's strength) or flashes a minute a cell.
WEATHER_RATE = "weather"


def _flash_rate(value: Any) -> float | str:
    if value == WEATHER_RATE:
        return WEATHER_RATE
    top = fmt_number(MAX_RATE_PER_MIN)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(
            f'must be "weather" or a number of flashes a minute in 0..{top}, got {value!r}'
        )
    if not 0.0 <= value <= MAX_RATE_PER_MIN:  # NaN too
        raise ValueError(f"must be in 0..{top} flashes a minute a storm cell, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class LightningSection(_Section):
    """`[lightning]`: how often the storms flash (docs/lightning.md)."""

    SECTION: ClassVar[str] = "lightning"

    # "weather": each storm cell at the rate of the storm's strength (METAR -TS, TS, +TS or a
    # CIGI host's random lightning: 1, 3, 8 a minute); a number: every storm cell's rate
    # instead, while a thunderstorm is reported (0: no lightning). Every display channel of
    # a site must be given the same value, or their flashes differ.
    flashes_per_min: float | str = _opt(
        WEATHER_RATE, Custom(_flash_rate, f'"weather" or 0..{fmt_number(MAX_RATE_PER_MIN)}')
    )

    def rate_per_min(self) -> float | None:
        """The scene's `SceneSettings.flashes_per_min`: None for the weather's rate."""
        rate = self.flashes_per_min
        return None if isinstance(rate, str) else rate


@dataclass(frozen=True)
class RadarSection(_Section):
    """`[radar]`: the weather radar's picture as a segment layer (docs/radar.md); the
    `radar` control command works either way."""

    SECTION: ClassVar[str] = "radar"

    # Publish the radar layer (`radar`, one picture every `every_s`) and the `radar`
    # notification; false: the segment has no such layer.
    layer: bool = _opt(False)
    range_nm: float = _opt(40.0, _num(*RANGE_NM, "NM"))
    tilt_deg: float = _opt(0.0, _num(*TILT_DEG, "deg"))  # the antenna's elevation
    size_px: int = _opt(256, _int(*SIZE_PX, "px"))
    # A new picture is asked for this often (wall-clock); one not made by then is waited
    # for off the frame path, the layer keeping the last.
    every_s: float = _opt(1.0, _num(0.1, 3600.0, "s"))


@dataclass(frozen=True)
class RenderSection(_Section):
    SECTION: ClassVar[str] = "render"

    # "auto" (from the scene's luminance, adapting over about a second) or EV: the scale on
    # scene-linear colour is 2^EV, -20..20; 0 is the look of before issue 41
    # (wxsky/scene/exposure.py).
    exposure: float | str = _opt(AUTO, EXPOSURE)


@dataclass(frozen=True)
class ClockSection(_Section):
    SECTION: ClassVar[str] = "clock"

    rate: float = _opt(1.0, CLOCK_RATE)  # simulation seconds per wall second


# The segment's picture layers (wxsky/output/shm.py LAYER_FORMATS): the config's
# [output] layer_format and the control channel's `output_format` check by this one kind.
LAYER_FORMAT = Text(choices=("rgba8", "rgba16f"))


@dataclass(frozen=True)
class OutputSection(_Section):
    SECTION: ClassVar[str] = "output"

    control: str = _opt("")  # empty: the default unix socket
    shm_name: str = _opt(
        "wxsky",
        Text(
            pattern=r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}",
            pattern_desc="1-64 letters, digits, '_', '.' or '-', starting with a letter or digit",
        ),
    )
    max_width: int = _opt(1920, VIEWPORT_PX)
    max_height: int = _opt(1080, VIEWPORT_PX)
    # The segment's picture layers: "rgba8" display values (exposed, tone-mapped, sRGB) or
    # "rgba16f" scene-linear half floats for hosts with HDR pipelines (docs/linear-output.md;
    # the segment is then protocol version 2, which older readers refuse).
    layer_format: str = _opt("rgba8", LAYER_FORMAT)
    # The `near_depth` layer: the distance of the nearest cloud at each pixel of `near`, for
    # hosts that composite the clouds against their own terrain and models (plugins/osg,
    # FlightGear; docs/protocol.md §1.5). A second pass over the near sprites: off unless such
    # a host is served.
    near_depth: bool = _opt(False, Bool())
    # Control clients served at once (output/transport.py DEFAULT_MAX_CLIENTS); one more is
    # served and the longest-idle one closed to make room. Each holds a file descriptor.
    max_clients: int = _opt(64, _int(1, 1000))
    # A control client that sends nothing and subscribes to nothing for this long is closed
    # (DEFAULT_IDLE_TIMEOUT_S there); 0: never.
    client_idle_timeout_s: float = _opt(300.0, _num(0.0, 86_400.0, "s"))


@dataclass(frozen=True)
class PreviewSection(_Section):
    SECTION: ClassVar[str] = "preview"

    interval_s: float = _opt(3.0, _num(0.1, 3600.0, "s"))


@dataclass(frozen=True)
class PresetsSection(_Section):
    SECTION: ClassVar[str] = "presets"

    dirs: tuple[Path, ...] = _opt(())  # searched before the built-in preset directories


@dataclass(frozen=True)
class MetarSection(_Section):
    SECTION: ClassVar[str] = "metar"

    feeds: tuple[str, ...] = _opt(())  # file paths, "-" for stdin, http(s):// URLs
    format: str = _opt("auto", Text(choices=FEED_FORMATS))
    poll_interval_s: float = _opt(60.0, _num(0.05, 86_400.0, "s"))
    http_timeout_s: float = _opt(10.0, _num(0.1, 300.0, "s"))
    max_backoff_s: float = _opt(900.0, _num(1.0, 86_400.0, "s"))
    max_age_min: float = _opt(90.0, _num(1.0, 10_000_000.0, "min"))
    age_reference: str = _opt("clock", Text(choices=("clock", "feed")))
    station: str = _opt(
        "", Text(pattern=r"([A-Z][A-Z0-9]{3})?", pattern_desc="empty or a 4-character ICAO id")
    )
    blend_stations: int = _opt(1, BLEND_STATIONS)
    max_station_distance_km: float = _opt(200.0, _num(1.0, 20_000.0, "km"))


@dataclass(frozen=True)
class GribSection(_Section):
    """Model data (issue 45, docs/weather-aloft.md): GRIB2 files, directories of forecast steps, or
    URLs, read into winds, temperatures and clouds aloft."""

    SECTION: ClassVar[str] = "grib"

    sources: tuple[str, ...] = _opt(())  # files, directories (one file a step), http(s) URLs
    poll_interval_s: float = _opt(300.0, _num(0.1, 86_400.0, "s"))
    http_timeout_s: float = _opt(30.0, _num(0.1, 600.0, "s"))
    byte_ranges: bool = _opt(True)  # fetch only the messages used, by the .idx inventory
    # which messages: "all" wxsky reads, or "wind" (the wind and temperature profile alone)
    fields: str = _opt("all", Text(choices=("all", "wind")))
    cache_dir: str = _opt("")  # "": $XDG_CACHE_HOME/wxsky/grib (~/.cache/wxsky/grib)
    cache_max_mb: float = _opt(2048.0, _num(1.0, 1_000_000.0, "MiB"))
    window_deg: float = _opt(6.0, _num(1.0, 90.0, "deg"))  # fields kept around the site
    update_s: float = _opt(10.0, _num(0.1, 3600.0, "s"))  # the column worked out again


def _web_listen(value: Any) -> str:
    """HOST:PORT for the web station; '' leaves it off."""
    if not isinstance(value, str):
        raise ValueError(f"must be HOST:PORT such as 127.0.0.1:8080, got {value!r}")
    if value == "":
        return value
    parse_web_listen(value)
    return value


def parse_web_listen(text: str) -> tuple[str, int]:
    """("127.0.0.1", 8080) from "127.0.0.1:8080" ("[::1]:8080" for IPv6); ValueError (one
    line) for anything else. Port 0: one the system picks."""
    host, sep, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or int(port) > 65535 or len(text) > 300:
        raise ValueError(f"{text[:80]!r} is not HOST:PORT such as 127.0.0.1:8080")
    return host, int(port)


@dataclass(frozen=True)
class WebSection(_Section):
    """The instructor station in the browser (issue 46, docs/web.md); off until `listen` is
    given (or `wxsky run --web HOST:PORT`)."""

    SECTION: ClassVar[str] = "web"

    listen: str = _opt("", Custom(_web_listen, "HOST:PORT such as 127.0.0.1:8080"))
    # Off loopback every request needs this file's token (made 0600 on first run); "":
    # $XDG_CONFIG_HOME/wxsky/web-token (~/.config/wxsky/web-token).
    token_file: str = _opt("")
    max_clients: int = _opt(32, Number(1, 256, integer=True))
    picture_fps: float = _opt(4.0, _num(0.0, 30.0, "Hz"))  # 0: no live picture
    # The share of one core the live picture may take; pictures are spaced to keep it (they
    # are made in a child process at nice 10, which yields to the frames).
    picture_cpu_share: float = _opt(0.3, _num(0.01, 1.0))
    view_interval_s: float = _opt(0.5, _num(0.05, 60.0, "s"))  # a view pushed this often


@dataclass(frozen=True)
class TransitionSection(_Section):
    SECTION: ClassVar[str] = "transition"

    cover_oktas_per_min: float = _opt(2.0, _num(0.0, 1000.0, "oktas/min"))
    base_m_per_min: float = _opt(300.0, _num(0.0, 100_000.0, "m/min"))
    wind_mps_per_s: float = _opt(1.0, _num(0.0, 1000.0, "m/s/s"))
    visibility_m_per_s: float = _opt(100.0, _num(0.0, 1_000_000.0, "m/s"))
    temperature_c_per_min: float = _opt(2.0, _num(0.0, 1000.0, "degC/min"))
    qnh_hpa_per_min: float = _opt(2.0, _num(0.0, 1000.0, "hPa/min"))
    step_s: float = _opt(1.0, _num(0.0, 60.0, "s"))
    cockpit_hold_s: float = _opt(30.0, _num(0.1, 86_400.0, "s"))

    def rates(self) -> TransitionRates:
        return TransitionRates(
            cover_oktas_per_min=self.cover_oktas_per_min,
            base_m_per_min=self.base_m_per_min,
            wind_mps_per_s=self.wind_mps_per_s,
            visibility_m_per_s=self.visibility_m_per_s,
            temperature_c_per_min=self.temperature_c_per_min,
            qnh_hpa_per_min=self.qnh_hpa_per_min,
        )


@dataclass(frozen=True)
class SerialInputSection(_Section):
    """One `[[serial]]` table: a cockpit serial line speaking NMEA 0183."""

    SECTION: ClassVar[str] = "serial"

    url: str = _opt("", Text(pattern=r".+", pattern_desc="a device path or pyserial URL"))
    baud: int = _opt(4800, _int(50, 4_000_000, "Bd"))
    name: str = _opt("")  # empty: "serial:<url>"
    fields: tuple[str, ...] = _opt(ALL_GROUPS, FIELD_GROUPS)
    max_line_bytes: int = _opt(256, _int(82, 65_536, "B"))
    allow_missing_checksum: bool = _opt(False)
    sensor_heading_deg: float = _opt(0.0, _num(0.0, 360.0, "deg"))
    heading_source: str = _opt("fixed", Text(choices=HEADING_SOURCES))
    accept_relative_wind: bool = _opt(False)

    @property
    def input_name(self) -> str:
        return self.name or f"serial:{self.url}"

    @classmethod
    def from_spec(cls, spec: str) -> SerialInputSection:
        """`URL[@BAUD]` from the command line (`/dev/ttyUSB0@4800`, `socket://host:4001`)."""
        url, sep, baud = spec.rpartition("@")
        if sep and not url:
            raise ValueError(f"--serial {spec!r}: expected a device path or pyserial URL")
        if sep and url and baud.isdigit():
            return cls(url=url, baud=int(baud))
        if sep and url and "://" not in spec:
            raise ValueError(f"--serial {spec!r}: the baud rate after '@' must be a number")
        return cls(url=spec)


@dataclass(frozen=True)
class CanInputSection(_Section):
    """One `[[can]]` table: a CAN bus speaking CANaerospace, through any python-can interface."""

    SECTION: ClassVar[str] = "can"

    interface: str = _opt(
        "", Text(pattern=r"[a-z][a-z0-9_]*", pattern_desc="a python-can interface name")
    )
    channel: str = _opt("")  # interface-specific; empty lets the interface choose
    bitrate: int = _opt(0, _int(0, 10_000_000, "bit/s"))  # 0: the interface's own setting
    name: str = _opt("")  # empty: "can:<interface>:<channel>"
    fields: tuple[str, ...] = _opt(ALL_GROUPS, FIELD_GROUPS)
    node_ids: tuple[int, ...] = _opt((), Items(_int(0, 255)))  # empty: every node

    @property
    def input_name(self) -> str:
        return self.name or f"can:{self.interface}:{self.channel}"

    @classmethod
    def from_spec(cls, spec: str) -> CanInputSection:
        """`INTERFACE:CHANNEL` from the command line (`socketcan:can0`,
        `udp_multicast:239.74.163.2`). The channel may itself hold colons (an IPv6 group)."""
        interface, sep, channel = spec.partition(":")
        if not interface or not sep:
            raise ValueError(f"--can {spec!r}: expected INTERFACE:CHANNEL, e.g. socketcan:can0")
        return cls(interface=interface, channel=channel)


@dataclass(frozen=True)
class CigiSection(_Section):
    """`[cigi]`: wxsky as a CIGI 3.3 image generator, and as a CIGI weather source."""

    SECTION: ClassVar[str] = "cigi"

    # udp:HOST:PORT addresses to listen on for a CIGI host (also `wxsky run --cigi`).
    listen: tuple[str, ...] = _opt((), CIGI_ADDRESSES)
    # Where replies go; empty: the source address of the host's datagrams.
    host_address: str = _opt("", Text(pattern=rf"({_UDP})?", pattern_desc="empty or udp:HOST:PORT"))
    # Host addresses (or networks) accepted; anything else is dropped and counted.
    allow_from: tuple[str, ...] = _opt(("127.0.0.0/8", "::1"), ALLOW_FROM)
    view_id: int = _opt(0, _int(0, 65_535))  # the View Control/Definition wxsky renders
    # The host's weather is handed back to the sources below after this long without a word.
    hold_s: float = _opt(10.0, _num(0.1, 86_400.0, "s"))
    # CIGI source: IGs to send the applied weather to (also `wxsky run --cigi-send`).
    send_to: tuple[str, ...] = _opt((), CIGI_ADDRESSES)
    send_rate_hz: float = _opt(0.0, _num(0.0, 240.0, "Hz"))  # 0: with every published frame
    send_byte_order: str = _opt("big", Text(choices=("big", "little")))
    # Environmental Conditions Requests answered after each frame, across listeners; the rest
    # wait (up to 4 frames' worth, at least 256) or are dropped and counted (issue 40).
    requests_per_frame: int = _opt(64, _int(1, 4096))
    # Regions (each with its layers) a host keeps; the least recently touched go past it.
    max_regions: int = _opt(256, _int(1, 65_536))


_TCP = r"tcp:(\[[0-9A-Fa-f:.]+\]|[^:\[\]\s]+):[0-9]{1,5}"


@dataclass(frozen=True)
class FlightGearSection(_Section):
    """`[flightgear]`: a FlightGear coupled to wxsky (plugins/flightgear/README.md)."""

    SECTION: ClassVar[str] = "flightgear"

    # FlightGear's telnet/props server, tcp:HOST:PORT, to write the applied weather to (also
    # `wxsky run --flightgear`); empty: none.
    props: str = _opt("", Text(pattern=rf"({_TCP})?", pattern_desc="empty or tcp:HOST:PORT"))
    # Where FlightGear's generic-protocol pose stream arrives, udp:HOST:PORT (also
    # `wxsky run --flightgear-pose`); empty: none. Its aircraft and view move the camera.
    pose: str = _opt("", Text(pattern=rf"({_UDP})?", pattern_desc="empty or udp:HOST:PORT"))
    # Which side owns the sim clock: wxsky's own, or FlightGear's UTC from the pose stream.
    clock: str = _opt("wxsky", Text(choices=("wxsky", "flightgear")))
    # The weather is written at most this often (FlightGear's props server is slow).
    write_interval_s: float = _opt(2.0, _num(0.1, 60.0, "s"))
    # Addresses (or networks) the pose stream is taken from; anything else is dropped and
    # counted (`not_allowed` in the status). Empty: from anywhere.
    allow_from: tuple[str, ...] = _opt(("127.0.0.0/8", "::1"), ALLOW_FROM)


_ZENOH = r"(tcp|udp|quic|tls|unixsock-stream)/[^\s]{1,200}"
ZENOH_ENDPOINT = Text(
    pattern=rf"({_ZENOH})?", pattern_desc="empty or a Zenoh locator such as tcp/127.0.0.1:7447"
)
SHARE_SITE = Text(
    pattern=r"[a-z0-9][a-z0-9_-]{0,63}",
    pattern_desc="1-64 lowercase letters, digits, '_' or '-', starting with a letter or digit",
)
VIEW_OFFSET = Tuple(
    (_num(-180.0, 180.0, "deg"), PITCH_DEG, ROLL_DEG), "[yaw_deg, pitch_deg, roll_deg]"
)


@dataclass(frozen=True)
class ShareSection(_Section):
    """`[share]`: this daemon is its site's sky master, serving the sky on a Zenoh endpoint
    (also `wxsky run --share zenoh:ENDPOINT`); docs/channels.md."""

    SECTION: ClassVar[str] = "share"

    endpoint: str = _opt("", ZENOH_ENDPOINT)  # empty: no sharing
    site: str = _opt("default", SHARE_SITE)  # one key space per site: wxsky/<site>/...
    camera: bool = _opt(True)  # share the camera (the ownship's) with the channels
    # The bus's mutual TLS (a tls/ endpoint; tools/generate/dome_certs.py): PEM paths.
    ca_certificate: str = _opt("")
    certificate: str = _opt("")
    private_key: str = _opt("")
    allow_insecure: bool = _opt(False)  # share beyond loopback without credentials


@dataclass(frozen=True)
class ChannelSection(_Section):
    """`[channel]`: this daemon is a display channel of a sky master's site (also `wxsky run
    --join zenoh:ENDPOINT --channel NAME --view-offset Y,P,R`)."""

    SECTION: ClassVar[str] = "channel"

    join: str = _opt("", ZENOH_ENDPOINT)  # the master's endpoint; empty: not a channel
    name: str = _opt("", Text(pattern=r"([a-z0-9][a-z0-9_-]{0,63})?", pattern_desc="a name"))
    site: str = _opt("default", SHARE_SITE)
    # The channel's view turned from the shared camera, as CIGI View Control turns a view.
    view_offset_deg: tuple[float, float, float] = _opt((0.0, 0.0, 0.0), VIEW_OFFSET)
    fov_deg: float = _opt(0.0, _num(0.0, 170.0, "deg"))  # 0: the [camera] fov_deg
    ca_certificate: str = _opt("")  # the bus's mutual TLS, as in [share]
    certificate: str = _opt("")
    private_key: str = _opt("")
    allow_insecure: bool = _opt(False)


@dataclass(frozen=True)
class DaemonConfig:
    daemon: DaemonSection = field(default_factory=DaemonSection)
    camera: CameraSection = field(default_factory=CameraSection)
    scene: SceneSection = field(default_factory=SceneSection)
    render: RenderSection = field(default_factory=RenderSection)
    clock: ClockSection = field(default_factory=ClockSection)
    output: OutputSection = field(default_factory=OutputSection)
    preview: PreviewSection = field(default_factory=PreviewSection)
    presets: PresetsSection = field(default_factory=PresetsSection)
    metar: MetarSection = field(default_factory=MetarSection)
    grib: GribSection = field(default_factory=GribSection)
    web: WebSection = field(default_factory=WebSection)
    transition: TransitionSection = field(default_factory=TransitionSection)
    serial: tuple[SerialInputSection, ...] = ()  # [[serial]] tables
    can: tuple[CanInputSection, ...] = ()  # [[can]] tables
    cigi: CigiSection = field(default_factory=CigiSection)
    flightgear: FlightGearSection = field(default_factory=FlightGearSection)
    share: ShareSection = field(default_factory=ShareSection)
    channel: ChannelSection = field(default_factory=ChannelSection)
    lightning: LightningSection = field(default_factory=LightningSection)
    radar: RadarSection = field(default_factory=RadarSection)

    def scene_settings(self) -> SceneSettings:
        """The scene stage's settings: `[scene]`'s, with `[lightning]`'s rate."""
        return dataclasses.replace(
            self.scene.settings(), flashes_per_min=self.lightning.rate_per_min()
        )

    def __post_init__(self) -> None:
        cam, out, scene = self.camera, self.output, self.scene
        problems = []
        if self.share.endpoint and self.channel.join:
            problems.append(
                Problem(
                    ("channel", "join"), "a daemon is a sky master ([share]) or a channel, not both"
                )
            )
        if self.channel.join and not self.channel.name:
            problems.append(Problem(("channel", "name"), "a channel needs a name"))
        if self.channel.name == "master":  # the master's health goes by that name
            problems.append(Problem(("channel", "name"), "'master' is the sky master's name"))
        problems.extend(_bus_problems("share", "endpoint", self.share))
        problems.extend(_bus_problems("channel", "join", self.channel))
        if cam.width > out.max_width:
            problems.append(
                Problem(
                    ("camera", "width"), f"{cam.width} exceeds output.max_width {out.max_width}"
                )
            )
        if cam.height > out.max_height:
            problems.append(
                Problem(
                    ("camera", "height"), f"{cam.height} exceeds output.max_height {out.max_height}"
                )
            )
        if scene.max_range_m <= scene.ring_radius_m:
            problems.append(
                Problem(
                    ("scene", "max_range_m"),
                    f"{fmt_number(scene.max_range_m)} must be beyond scene.ring_radius_m "
                    f"{fmt_number(scene.ring_radius_m)}",
                )
            )
        else:
            problems.extend(_scene_block_problems(scene))
        if problems:
            raise Invalid(problems)


def _bus_problems(section: str, key: str, s: ShareSection | ChannelSection) -> list[Problem]:
    """The channel bus's credentials: all three PEM files or none; with them a tls/ endpoint;
    without them loopback only, unless allow_insecure (docs/channels.md)."""
    endpoint = s.endpoint if isinstance(s, ShareSection) else s.join
    files = {
        "ca_certificate": s.ca_certificate,
        "certificate": s.certificate,
        "private_key": s.private_key,
    }
    if not endpoint:
        return []
    missing = [k for k, v in files.items() if not v]
    if missing and len(missing) < len(files):
        return [
            Problem(
                (section, missing[0]),
                "the bus's credentials need all three of "
                "ca_certificate, certificate and private_key",
            )
        ]
    secured = not missing
    if secured and not endpoint.startswith("tls/"):
        return [
            Problem((section, key), f"{endpoint}: with certificates the endpoint is tls/HOST:PORT")
        ]
    if not secured and endpoint.startswith("tls/"):
        return [
            Problem(
                (section, "certificate"),
                f"{endpoint}: a tls/ endpoint needs "
                f"{section}.ca_certificate, certificate and private_key",
            )
        ]
    if not secured and not s.allow_insecure and not _loopback(endpoint):
        return [
            Problem(
                (section, key),
                f"{endpoint} is not a loopback address: without {section}.ca_certificate, "
                "certificate and private_key anyone on that network may join or forge the "
                "sky; set them (docs/channels.md) or write allow_insecure = true",
            )
        ]
    return []


def _loopback(endpoint: str) -> bool:
    """Whether a Zenoh locator stays on this machine (a unix socket, or a loopback host)."""
    proto, _, address = endpoint.partition("/")
    if proto == "unixsock-stream":
        return True
    host = address.split("#", 1)[0].rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _scene_block_problems(scene: SceneSection) -> list[Problem]:
    """The work ring_radius_m and max_range_m imply, in blocks of one cloud layer, against
    the scene's bounds (`gather.MAX_NEAR_BLOCKS`, `gather.MAX_RING_BLOCKS`)."""
    radius, reach = scene.ring_radius_m, scene.max_range_m
    blocks = scene_blocks(radius, reach)
    size = f"{fmt_number(BLOCK_SIZE_M / 1000.0)} km"
    out = []
    if blocks.near > MAX_NEAR_BLOCKS:
        out.append(
            Problem(
                ("scene", "ring_radius_m"),
                f"{fmt_number(radius)} puts {blocks.near} blocks of {size} per cloud layer into "
                f"every frame's near sprites, at most {MAX_NEAR_BLOCKS} "
                f"(ring_radius_m up to {fmt_number(largest_range(0.0, MAX_NEAR_BLOCKS))})",
            )
        )
    if blocks.ring > MAX_RING_BLOCKS:
        out.append(
            Problem(
                ("scene", "max_range_m"),
                f"{fmt_number(reach)} with scene.ring_radius_m {fmt_number(radius)} puts "
                f"{blocks.ring} blocks of {size} per cloud layer into every ring build, at most "
                f"{MAX_RING_BLOCKS} (max_range_m up to "
                f"{fmt_number(largest_range(radius, MAX_RING_BLOCKS))} at this radius)",
            )
        )
    return out


def _config_table() -> Table:
    """The whole file's table, derived from the section dataclasses."""
    fields: dict[str, Field] = {}
    hints = typing.get_type_hints(DaemonConfig)
    for f in dataclasses.fields(DaemonConfig):
        hint = hints[f.name]
        if typing.get_origin(hint) is tuple:
            cls = typing.get_args(hint)[0]
            fields[f.name] = Field(Tables(_section_table(cls, f"[[{f.name}]]"), f.name))
        else:
            fields[f.name] = Field(_section_table(hint, f"[{f.name}]"))
    return Table(fields)


def _section_table(cls: type, header: str) -> Table:
    defaults = {f.name: f.default for f in dataclasses.fields(cls)}
    return Table(
        {
            # A key whose default its own kind refuses (a serial line's url) must be given.
            name: Field(kind, OMIT if _accepts(kind, defaults[name]) else REQUIRED)
            for name, kind in section_kinds(cls).items()
        },
        what=f"a table ({header})",
    )


def _accepts(kind: Kind, value: Any) -> bool:
    problems: list[Problem] = []
    kind.check(value, (), problems)
    return not problems


def load_config(path: Path | None) -> DaemonConfig:
    """The config in `path`, or the defaults for None. Raises ConfigError listing every
    problem as `FILE:LINE: key: problem`, one a line."""
    if path is None:
        return DaemonConfig()
    path = Path(path)
    read = read_toml(path)
    if isinstance(read, LocatedProblem):
        where = f"{path}:{read.line}" if read.line is not None else str(path)
        raise ConfigError(f"{where}: {read.message}")
    text, data = read
    checked = check_toml_text(path, text, data, CONFIG_TABLE)
    if not checked.ok:
        raise ConfigError(checked.error_message())
    try:
        return _config_from_checked(checked.value, path.parent)
    except Invalid as exc:  # the rules across sections
        raise ConfigError(located_error(path, text, exc)) from None


def _config_from_checked(values: dict[str, Any], base_dir: Path) -> DaemonConfig:
    hints = typing.get_type_hints(DaemonConfig)
    sections: dict[str, Any] = {}
    for name, table in values.items():
        hint = hints[name]
        if typing.get_origin(hint) is tuple:
            cls = typing.get_args(hint)[0]
            sections[name] = tuple(cls(**t) for t in table)
        else:
            sections[name] = hint(**table)
    cfg = DaemonConfig(**sections)
    # Relative preset dirs mean "next to this config file", not "wherever the daemon was
    # started from", so that a config and its presets can be moved together.
    dirs = tuple((base_dir / d).absolute() for d in cfg.presets.dirs)
    return dataclasses.replace(cfg, presets=PresetsSection(dirs=dirs))


def config_to_toml_dict(cfg: DaemonConfig) -> dict[str, Any]:
    """The config as TOML-ready plain data, `{section: {key: value}}` (a list of those for the
    `[[serial]]`/`[[can]]` arrays); loading it back gives an equal config."""
    out: dict[str, Any] = {}
    for sf in dataclasses.fields(cfg):
        value = getattr(cfg, sf.name)
        if isinstance(value, tuple):
            out[sf.name] = [_section_dict(v) for v in value]
        else:
            out[sf.name] = _section_dict(value)
    return out


def _section_dict(section: Any) -> dict[str, Any]:
    return {f.name: _to_toml_value(getattr(section, f.name)) for f in dataclasses.fields(section)}


def _to_toml_value(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_to_toml_value(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


CONFIG_TABLE = _config_table()
