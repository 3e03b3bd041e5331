"""The daemon config: a TOML file read into frozen dataclasses, one per section, in SI units.

Every key is optional and has a default; unknown keys, wrong types and out-of-range values are
errors naming the file and the dotted key, because a silently ignored typo in a config is worse
than a daemon that refuses to start.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import tomllib
import typing
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, TypeVar

from wxsky.errors import ConfigError, WxskyError
from wxsky.schema import Number
from wxsky.scene.layout import SceneSettings
from wxsky.scene.shading import DEFAULT_SHADING, SHADING_MODELS
from wxsky.weather.cockpit import ALL_GROUPS
from wxsky.weather.transition import TransitionRates

# Shared with wxsky.settings.presets; it lives here because presets import this module.
PRESET_NAME_PATTERN = r"[a-z0-9-]+"

# The scene generator tiles the cloud field in blocks of this size; noise frequencies, seeds and
# the impostor ring's texel density are all tuned to it, so it is a constant, not a setting.
BLOCK_SIZE_M = 4000.0

# How many nearby METAR stations may be blended (also the bound of `metar fetch --blend`).
BLEND_STATIONS = Number(1, 10, integer=True)

LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")

_T = TypeVar("_T")


@dataclass(frozen=True)
class _Rule:
    """What a config value may be, beyond its type."""

    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()  # matched case-insensitively, stored as spelled here
    pattern: str | None = None  # a regular expression the whole string must match
    pattern_desc: str = ""  # the pattern in words, for the error message
    fixed_reason: str = ""  # non-empty: only the default is accepted, and this says why


def _opt(default: _T, rule: _Rule | None = None) -> _T:
    return field(default=default, metadata={"rule": rule or _Rule()})


class _Section:
    """Validates and normalises every field on construction, so that code building a section
    directly (tests, `dataclasses.replace`) gets the same checks as the file loader."""

    SECTION: ClassVar[str]

    def __post_init__(self) -> None:
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            key = f"{self.SECTION}.{f.name}"
            rule: _Rule = f.metadata["rule"]
            value = _coerce(key, hints[f.name], getattr(self, f.name), rule)
            default: Any = f.default
            if rule.fixed_reason and value != default:
                raise ValueError(
                    f"{key} is fixed at {_fmt(default)}: {rule.fixed_reason}, got {_fmt(value)}"
                )
            object.__setattr__(self, f.name, value)


@dataclass(frozen=True)
class DaemonSection(_Section):
    SECTION: ClassVar[str] = "daemon"

    tick_hz: float = _opt(30.0, _Rule(1.0, 240.0))
    status_interval_s: float = _opt(5.0, _Rule(0.1, 3600.0))
    preset: str = _opt(
        "fair-cumulus",
        _Rule(pattern=PRESET_NAME_PATTERN, pattern_desc="lowercase letters, digits and '-'"),
    )
    log_level: str = _opt("INFO", _Rule(choices=LOG_LEVELS))
    shutdown_timeout_s: float = _opt(1.5, _Rule(0.0, 60.0))


@dataclass(frozen=True)
class CameraSection(_Section):
    SECTION: ClassVar[str] = "camera"

    heading_deg: float = _opt(0.0, _Rule(0.0, 360.0))
    pitch_deg: float = _opt(12.0, _Rule(-90.0, 90.0))
    roll_deg: float = _opt(0.0, _Rule(-180.0, 180.0))
    fov_deg: float = _opt(60.0, _Rule(1.0, 170.0))  # horizontal
    width: int = _opt(960, _Rule(16, 16384))
    height: int = _opt(540, _Rule(16, 16384))
    alt_agl_m: float = _opt(2.0, _Rule(0.0, 20_000.0))  # above the observer's altitude


@dataclass(frozen=True)
class SceneSection(_Section):
    SECTION: ClassVar[str] = "scene"

    ring_radius_m: float = _opt(8000.0, _Rule(100.0, 200_000.0))
    max_range_m: float = _opt(40_000.0, _Rule(1000.0, 500_000.0))
    ring_texture_px: int = _opt(256, _Rule(16, 4096))
    # A new ring cross-fades over the old one for this long (Wang); 0 swaps at once.
    ring_fade_s: float = _opt(1.0, _Rule(0.0, 30.0))
    # Near sprites this far away are drawn at the ring impostors' texel density (0: never).
    far_band_m: float = _opt(3000.0, _Rule(0.0, 200_000.0))
    # Near clouds this far away are drawn as one sprite each (Wang's LOD; 0: never).
    lod_start_m: float = _opt(0.0, _Rule(0.0, 200_000.0))
    # Clouds in the ring this far from its centre go into impostors as one sprite (0: never).
    impostor_lod_m: float = _opt(0.0, _Rule(0.0, 500_000.0))
    # At most this many near sprites a frame: past it the farthest clouds fade out (0: no cap).
    max_near_sprites: int = _opt(20_000, _Rule(0, 10_000_000))
    block_size_m: float = _opt(
        BLOCK_SIZE_M,
        _Rule(fixed_reason="the cloud field is generated in 4 km blocks by design"),
    )
    shading: str = _opt(DEFAULT_SHADING, _Rule(choices=SHADING_MODELS))

    def settings(self) -> SceneSettings:
        """The scene stage's view of this section."""
        return SceneSettings(
            ring_radius_m=self.ring_radius_m,
            max_range_m=self.max_range_m,
            ring_texture_px=self.ring_texture_px,
            shading=self.shading,
            far_band_m=self.far_band_m,
            lod_start_m=self.lod_start_m,
            impostor_lod_m=self.impostor_lod_m,
            max_near_sprites=self.max_near_sprites,
        )


@dataclass(frozen=True)
class ClockSection(_Section):
    SECTION: ClassVar[str] = "clock"

    rate: float = _opt(1.0, _Rule(0.0, 10_000.0))  # simulation seconds per wall second


@dataclass(frozen=True)
class OutputSection(_Section):
    SECTION: ClassVar[str] = "output"

    control: str = _opt("")  # empty: the default unix socket
    shm_name: str = _opt(
        "wxsky",
        _Rule(
            pattern=r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}",
            pattern_desc="1-64 letters, digits, '_', '.' or '-', starting with a letter or digit",
        ),
    )
    max_width: int = _opt(1920, _Rule(16, 16384))
    max_height: int = _opt(1080, _Rule(16, 16384))


@dataclass(frozen=True)
class PreviewSection(_Section):
    SECTION: ClassVar[str] = "preview"

    interval_s: float = _opt(3.0, _Rule(0.1, 3600.0))


@dataclass(frozen=True)
class PresetsSection(_Section):
    SECTION: ClassVar[str] = "presets"

    dirs: tuple[Path, ...] = _opt(())  # searched before the built-in preset directories


FEED_FORMATS = ("auto", "awc-csv", "awc-xml", "tgftp", "lines")


@dataclass(frozen=True)
class MetarSection(_Section):
    SECTION: ClassVar[str] = "metar"

    feeds: tuple[str, ...] = _opt(())  # file paths, "-" for stdin, http(s):// URLs
    format: str = _opt("auto", _Rule(choices=FEED_FORMATS))
    poll_interval_s: float = _opt(60.0, _Rule(0.05, 86_400.0))
    http_timeout_s: float = _opt(10.0, _Rule(0.1, 300.0))
    max_backoff_s: float = _opt(900.0, _Rule(1.0, 86_400.0))
    max_age_min: float = _opt(90.0, _Rule(1.0, 10_000_000.0))
    age_reference: str = _opt("clock", _Rule(choices=("clock", "feed")))
    station: str = _opt(
        "", _Rule(pattern=r"([A-Z][A-Z0-9]{3})?", pattern_desc="empty or a 4-character ICAO id")
    )
    blend_stations: int = _opt(1, _Rule(BLEND_STATIONS.lo, BLEND_STATIONS.hi))
    max_station_distance_km: float = _opt(200.0, _Rule(1.0, 20_000.0))


@dataclass(frozen=True)
class TransitionSection(_Section):
    SECTION: ClassVar[str] = "transition"

    cover_oktas_per_min: float = _opt(2.0, _Rule(0.0, 1000.0))
    base_m_per_min: float = _opt(300.0, _Rule(0.0, 100_000.0))
    wind_mps_per_s: float = _opt(1.0, _Rule(0.0, 1000.0))
    visibility_m_per_s: float = _opt(100.0, _Rule(0.0, 1_000_000.0))
    temperature_c_per_min: float = _opt(2.0, _Rule(0.0, 1000.0))
    qnh_hpa_per_min: float = _opt(2.0, _Rule(0.0, 1000.0))
    step_s: float = _opt(1.0, _Rule(0.0, 60.0))
    cockpit_hold_s: float = _opt(30.0, _Rule(0.1, 86_400.0))

    def rates(self) -> TransitionRates:
        return TransitionRates(
            cover_oktas_per_min=self.cover_oktas_per_min,
            base_m_per_min=self.base_m_per_min,
            wind_mps_per_s=self.wind_mps_per_s,
            visibility_m_per_s=self.visibility_m_per_s,
            temperature_c_per_min=self.temperature_c_per_min,
            qnh_hpa_per_min=self.qnh_hpa_per_min,
        )


HEADING_SOURCES = ("fixed", "hdt", "hdg")


@dataclass(frozen=True)
class SerialInputSection(_Section):
    """One `[[serial]]` table: a cockpit serial line speaking NMEA 0183."""

    SECTION: ClassVar[str] = "serial"

    url: str = _opt("", _Rule(pattern=r".+", pattern_desc="a device path or pyserial URL"))
    baud: int = _opt(4800, _Rule(50, 4_000_000))
    name: str = _opt("")  # empty: "serial:<url>"
    fields: tuple[str, ...] = _opt(ALL_GROUPS, _Rule(choices=ALL_GROUPS))
    max_line_bytes: int = _opt(256, _Rule(82, 65_536))
    allow_missing_checksum: bool = _opt(False)
    sensor_heading_deg: float = _opt(0.0, _Rule(0.0, 360.0))
    heading_source: str = _opt("fixed", _Rule(choices=HEADING_SOURCES))
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
        "", _Rule(pattern=r"[a-z][a-z0-9_]*", pattern_desc="a python-can interface name")
    )
    channel: str = _opt("")  # interface-specific; empty lets the interface choose
    bitrate: int = _opt(0, _Rule(0, 10_000_000))  # 0: the interface's own setting
    name: str = _opt("")  # empty: "can:<interface>:<channel>"
    fields: tuple[str, ...] = _opt(ALL_GROUPS, _Rule(choices=ALL_GROUPS))
    node_ids: tuple[int, ...] = _opt((), _Rule(0, 255))  # empty: every node

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
class DaemonConfig:
    daemon: DaemonSection = field(default_factory=DaemonSection)
    camera: CameraSection = field(default_factory=CameraSection)
    scene: SceneSection = field(default_factory=SceneSection)
    clock: ClockSection = field(default_factory=ClockSection)
    output: OutputSection = field(default_factory=OutputSection)
    preview: PreviewSection = field(default_factory=PreviewSection)
    presets: PresetsSection = field(default_factory=PresetsSection)
    metar: MetarSection = field(default_factory=MetarSection)
    transition: TransitionSection = field(default_factory=TransitionSection)
    serial: tuple[SerialInputSection, ...] = ()  # [[serial]] tables
    can: tuple[CanInputSection, ...] = ()  # [[can]] tables

    def __post_init__(self) -> None:
        cam, out, scene = self.camera, self.output, self.scene
        if cam.width > out.max_width:
            raise ValueError(f"camera.width {cam.width} exceeds output.max_width {out.max_width}")
        if cam.height > out.max_height:
            raise ValueError(
                f"camera.height {cam.height} exceeds output.max_height {out.max_height}"
            )
        if scene.max_range_m <= scene.ring_radius_m:
            raise ValueError(
                f"scene.max_range_m {_fmt(scene.max_range_m)} must be beyond "
                f"scene.ring_radius_m {_fmt(scene.ring_radius_m)}"
            )


def load_config(path: Path | None) -> DaemonConfig:
    """The config in `path`, or the defaults for None. Raises ConfigError naming file and key."""
    if path is None:
        return DaemonConfig()
    path = Path(path)
    data = read_toml_file(path, ConfigError)
    try:
        return _config_from_dict(data, path.parent)
    except ValueError as exc:
        raise ConfigError(f"{path}: {exc}") from None


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


def read_toml_file(path: Path, error: type[WxskyError]) -> dict[str, Any]:
    """A TOML file's top-level table; any failure is an `error` whose message starts with the
    path (and, for syntax errors, carries tomllib's line and column)."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except IsADirectoryError:
        raise error(f"{path}: is a directory, not a file") from None
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise error(f"{path}: not UTF-8 text (bad byte at line {line})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)
        # tomllib gives no line for errors at the end of the input, the usual symptom of a
        # truncated file; the last line is where the reader should look.
        if message.endswith("(at end of document)"):
            message = f"{message[:-1]}, line {text.count(chr(10)) + 1})"
        raise error(f"{path}: invalid TOML: {message}") from None


def unknown_key_message(dotted: str, known: Iterable[str]) -> str:
    """The message for an unknown dotted key, naming the closest known key when one is likely."""
    prefix, _, leaf = dotted.rpartition(".")
    close = difflib.get_close_matches(leaf, list(known), n=1)
    if not close:
        return f"unknown key {dotted!r}"
    suggestion = f"{prefix}.{close[0]}" if prefix else close[0]
    return f"unknown key {dotted!r} (did you mean {suggestion!r}?)"


def _config_from_dict(data: dict[str, Any], base_dir: Path) -> DaemonConfig:
    section_types = typing.get_type_hints(DaemonConfig)
    sections: dict[str, Any] = {}
    for name, table in data.items():
        if name not in section_types:
            raise ValueError(unknown_key_message(name, section_types))
        hint = section_types[name]
        if typing.get_origin(hint) is tuple:
            if not isinstance(table, list) or not all(isinstance(t, dict) for t in table):
                raise ValueError(f"{name} must be an array of tables ([[{name}]]), got {table!r}")
            cls = typing.get_args(hint)[0]
            sections[name] = tuple(
                _section_from_table(cls, f"{name}[{i}]", t) for i, t in enumerate(table, 1)
            )
            continue
        if not isinstance(table, dict):
            raise ValueError(f"{name} must be a table ([{name}]), got {table!r}")
        sections[name] = _section_from_table(hint, name, table)
    cfg = DaemonConfig(**sections)
    # Relative preset dirs mean "next to this config file", not "wherever the daemon was
    # started from", so that a config and its presets can be moved together.
    dirs = tuple((base_dir / d).absolute() for d in cfg.presets.dirs)
    return dataclasses.replace(cfg, presets=PresetsSection(dirs=dirs))


def _section_from_table(cls: Any, label: str, table: dict[str, Any]) -> Any:
    """One section from its table; `label` names it in errors (`serial[2]` for the second
    `[[serial]]`)."""
    known = [f.name for f in dataclasses.fields(cls)]
    for key in table:
        if key not in known:
            raise ValueError(unknown_key_message(f"{label}.{key}", known))
    try:
        section = cls(**table)
    except ValueError as exc:
        message = str(exc)
        prefix = f"{cls.SECTION}."
        if label != cls.SECTION and message.startswith(prefix):
            message = f"{label}.{message[len(prefix) :]}"
        raise ValueError(message) from None
    return section


def _coerce(key: str, hint: Any, value: Any, rule: _Rule) -> Any:
    if hint is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{key} must be true or false, got {value!r}")
        return value
    if hint is float or hint is int:
        return _coerce_number(key, hint, value, rule)
    if hint is str:
        return _coerce_str(key, value, rule)
    if hint == tuple[Path, ...]:
        items = value if isinstance(value, (list, tuple)) else None
        if items is None or not all(isinstance(v, (str, Path)) and str(v) for v in items):
            raise ValueError(f"{key} must be a list of non-empty path strings, got {value!r}")
        return tuple(Path(v).expanduser() for v in items)
    if hint == tuple[str, ...]:
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) and v for v in value):
            raise ValueError(f"{key} must be a list of non-empty strings, got {value!r}")
        if rule.choices:
            return tuple(_coerce_str(key, v, rule) for v in value)
        return tuple(value)
    if hint == tuple[int, ...]:
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{key} must be a list of integers, got {value!r}")
        return tuple(_coerce_number(key, int, v, rule) for v in value)
    raise TypeError(f"{key}: no coercion for config type {hint!r}")


def _coerce_number(key: str, hint: type, value: Any, rule: _Rule) -> float | int:
    kind = "an integer" if hint is int else "a number"
    if rule.lo is not None and rule.hi is not None:
        kind += f" in {_fmt(rule.lo)}..{_fmt(rule.hi)}"
    # bool is an int subclass, but `tick_hz = true` is a mistake, not 1 Hz.
    accepted = (int,) if hint is int else (int, float)
    if not isinstance(value, accepted) or isinstance(value, bool):
        raise ValueError(f"{key} must be {kind}, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{key} must be {kind}, got {value!r}")
    if (rule.lo is not None and value < rule.lo) or (rule.hi is not None and value > rule.hi):
        raise ValueError(f"{key} must be {kind}, got {value!r}")
    return int(value) if hint is int else float(value)


def _coerce_str(key: str, value: Any, rule: _Rule) -> str:
    if rule.choices:
        for choice in rule.choices:
            if isinstance(value, str) and value.casefold() == choice.casefold():
                return choice
        raise ValueError(f"{key} must be one of {', '.join(rule.choices)}, got {value!r}")
    if not isinstance(value, str):
        raise ValueError(f"{key} must be a string, got {value!r}")
    if rule.pattern is not None and not re.fullmatch(rule.pattern, value):
        raise ValueError(f"{key} must be {rule.pattern_desc}, got {value!r}")
    return value


def _to_toml_value(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_to_toml_value(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


def _fmt(x: float) -> str:
    """A bound or value as a person writes it: 240, 0.1, 4000."""
    return str(int(x)) if float(x).is_integer() else str(x)
