"""The daemon config: defaults, the documented default file, and every kind of bad input."""

from __future__ import annotations

import dataclasses
import json
import re
import tomllib
from pathlib import Path
from typing import Any

import pytest

from wxsky.errors import ConfigError
from wxsky.settings.config import (
    BLOCK_SIZE_M,
    CameraSection,
    CanInputSection,
    DaemonConfig,
    SerialInputSection,
    config_to_toml_dict,
    load_config,
)

REPO = Path(__file__).resolve().parents[1]
DEFAULT_FILE = REPO / "configs" / "wxsky.toml"


def write(tmp_path: Path, text: str, name: str = "x.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def load_error(tmp_path: Path, text: str) -> str:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert message.startswith(f"{path}:"), message
    return message


def to_toml(data: dict[str, Any]) -> str:
    """Just enough of a TOML writer for config_to_toml_dict's output."""
    lines = []
    for section, value in data.items():
        tables = value if isinstance(value, list) else [value]
        for table in tables:
            lines.append(f"[[{section}]]" if isinstance(value, list) else f"[{section}]")
            lines.extend(f"{key} = {json.dumps(v)}" for key, v in table.items())
    return "\n".join(lines) + "\n"


def test_defaults() -> None:
    cfg = load_config(None)
    assert cfg == DaemonConfig()
    assert cfg.daemon.tick_hz == 30.0
    assert cfg.daemon.status_interval_s == 5.0
    assert cfg.daemon.preset == "fair-cumulus"
    assert cfg.daemon.log_level == "INFO"
    assert cfg.daemon.shutdown_timeout_s == 1.5
    assert cfg.camera == CameraSection(0.0, 12.0, 0.0, 60.0, 960, 540, 2.0)
    assert cfg.scene.ring_radius_m == 8000.0
    assert cfg.scene.max_range_m == 40000.0
    assert cfg.scene.ring_texture_px == 512
    assert cfg.scene.block_size_m == BLOCK_SIZE_M == 4000.0
    assert cfg.clock.rate == 1.0
    assert cfg.output.control == ""
    assert cfg.output.shm_name == "wxsky"
    assert (cfg.output.max_width, cfg.output.max_height) == (1920, 1080)
    assert cfg.preview.interval_s == 3.0
    assert cfg.presets.dirs == ()


def test_sections_are_frozen() -> None:
    cfg = load_config(None)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.camera.fov_deg = 90.0  # type: ignore[misc]


def test_default_file_equals_defaults() -> None:
    assert load_config(DEFAULT_FILE) == load_config(None)


def test_default_file_documents_every_key() -> None:
    raw = tomllib.loads(DEFAULT_FILE.read_text(encoding="utf-8"))
    expected = {
        name: table
        for name, table in config_to_toml_dict(load_config(None)).items()
        if isinstance(table, dict)  # the [[serial]]/[[can]] arrays are empty by default
    }
    assert {s: set(t) for s, t in raw.items()} == {s: set(t) for s, t in expected.items()}
    lines = DEFAULT_FILE.read_text(encoding="utf-8").splitlines()
    for i, line in enumerate(lines):
        if re.match(r"(#! )?[a-z_]+ = ", line):
            assert lines[i - 1].startswith(("#", "#! #")), f"no comment above line {i + 1}: {line}"


def test_default_file_cockpit_examples_load_and_name_every_key(tmp_path: Path) -> None:
    text = DEFAULT_FILE.read_text(encoding="utf-8")
    example = "\n".join(
        line.removeprefix("#!").removeprefix(" ")
        for line in text.splitlines()
        if line.startswith("#!")
    )
    cfg = load_config(write(tmp_path, example))
    assert [s.url for s in cfg.serial] == ["/dev/ttyUSB0"]
    assert [(c.interface, c.channel) for c in cfg.can] == [("socketcan", "can0")]
    raw = tomllib.loads(example)
    for name in ("serial", "can"):
        documented = set(raw[name][0])
        assert documented == set(config_to_toml_dict(cfg)[name][0]), name


def test_empty_file_is_defaults(tmp_path: Path) -> None:
    assert load_config(write(tmp_path, "")) == load_config(None)


def test_values_are_read_and_normalised(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """
        [daemon]
        tick_hz = 60
        log_level = "debug"
        preset = "thunderstorm"
        [camera]
        fov_deg = 90
        width = 1280
        height = 720
        [clock]
        rate = 0
        """,
    )
    cfg = load_config(path)
    assert cfg.daemon.tick_hz == 60.0 and isinstance(cfg.daemon.tick_hz, float)
    assert cfg.daemon.log_level == "DEBUG"
    assert cfg.daemon.preset == "thunderstorm"
    assert (cfg.camera.fov_deg, cfg.camera.width, cfg.camera.height) == (90.0, 1280, 720)
    assert cfg.clock.rate == 0.0
    assert cfg.camera.pitch_deg == 12.0  # untouched keys keep their defaults


def test_preset_dirs_are_relative_to_the_config_file(tmp_path: Path) -> None:
    path = write(tmp_path, '[presets]\ndirs = ["mine", "/abs/presets"]\n')
    cfg = load_config(path)
    assert cfg.presets.dirs == (tmp_path / "mine", Path("/abs/presets"))


def test_round_trip_through_toml_dict(tmp_path: Path) -> None:
    original = load_config(
        write(
            tmp_path,
            '[camera]\nfov_deg = 75.5\n[presets]\ndirs = ["/p"]\n'
            '[[serial]]\nurl = "loop://"\nbaud = 9600\nfields = ["wind"]\n'
            '[[can]]\ninterface = "virtual"\nchannel = "c"\nnode_ids = [3]\n',
            "a.toml",
        )
    )
    data = config_to_toml_dict(original)
    assert data["presets"]["dirs"] == ["/p"]
    assert data["serial"][0]["baud"] == 9600 and data["can"][0]["node_ids"] == [3]
    assert load_config(write(tmp_path, to_toml(data), "b.toml")) == original


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("fovv = 1\n", "'fovv'"),
        ("[camra]\nfov_deg = 1\n", "'camra'"),
        ("[camera]\nfovv = 1\n", "'camera.fovv'"),
        ("[daemon]\ntick = 1\n", "'daemon.tick'"),
        ('[[serial]]\nurl = "x"\n[[serial]]\nurl = "y"\nbuad = 1\n', "'serial[1].buad'"),
        ('[[can]]\ninterface = "virtual"\nnodes = [1]\n', "'can[0].nodes'"),
    ],
)
def test_unknown_key_is_named(tmp_path: Path, text: str, key: str) -> None:
    assert f"{key.strip(chr(39))}: unknown key" in load_error(tmp_path, text)


def test_unknown_key_message_format(tmp_path: Path) -> None:
    path = write(tmp_path, "[camera]\nfovv = 1\n")
    with pytest.raises(ConfigError, match=re.escape(f"{path}:2: camera.fovv: unknown key")):
        load_config(path)


def test_wrong_type(tmp_path: Path) -> None:
    message = load_error(tmp_path, '[camera]\nfov_deg = "wide"\n')
    assert message.endswith("camera.fov_deg: must be a number in 1..170, got 'wide'")


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("[daemon]\ntick_hz = true\n", "daemon.tick_hz: must be a number in 1..240, got True"),
        ("[camera]\nwidth = 960.5\n", "camera.width: must be an integer in 16..8192"),
        ('[daemon]\nlog_level = "LOUD"\n', "daemon.log_level: must be one of DEBUG, INFO"),
        (
            "[daemon]\npreset = 3\n",
            "daemon.preset: must be 1 to 64 lowercase letters, digits and '-', got 3",
        ),
        ('[presets]\ndirs = "x"\n', "presets.dirs: must be a list"),
        ("[presets]\ndirs = [1]\n", "presets.dirs: must be a list"),
        ("camera = 3\n", "camera: must be a table"),
        ("serial = 3\n", "serial: must be an array of tables ([[serial]])"),
        ('[[serial]]\nurl = "x"\nallow_missing_checksum = 1\n', "must be true or false"),
        ('[[serial]]\nurl = "x"\nfields = "wind"\n', "serial[0].fields: must be a list"),
        (
            '[[can]]\ninterface = "virtual"\nnode_ids = ["1"]\n',
            "can[0].node_ids[0]: must be an integer in 0..255, got '1'",
        ),
    ],
)
def test_wrong_types(tmp_path: Path, text: str, fragment: str) -> None:
    assert fragment in load_error(tmp_path, text)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("[daemon]\ntick_hz = 0.5\n", "daemon.tick_hz: must be a number in 1..240, got 0.5"),
        ("[daemon]\ntick_hz = 241\n", "daemon.tick_hz: must be a number in 1..240, got 241"),
        ("[daemon]\ntick_hz = nan\n", "daemon.tick_hz: must be a number in 1..240, got nan"),
        ("[camera]\nfov_deg = 171\n", "camera.fov_deg: must be a number in 1..170, got 171"),
        ("[camera]\npitch_deg = -91\n", "camera.pitch_deg"),
        ("[clock]\nrate = -1\n", "clock.rate: must be a number in 0..10000, got -1"),
        ("[output]\nmax_width = 8\n", "output.max_width: must be an integer in 16..8192"),
        ('[daemon]\npreset = "../etc"\n', "daemon.preset: must be 1 to 64 lowercase letters"),
        ('[output]\nshm_name = "a/b"\n', "output.shm_name: must be"),
        ("[camera]\nwidth = 2000\n", "camera.width: 2000 exceeds output.max_width 1920"),
        ('[[serial]]\nurl = "x"\nbaud = 10\n', "serial[0].baud: must be an integer in 50..4000000"),
        ("[[serial]]\nbaud = 4800\n", "serial[0].url: missing key"),
        ('[[serial]]\nurl = "x"\nfields = ["rain"]\n', "serial[0].fields[0]: must be one of wind"),
        ('[[serial]]\nurl = "x"\nheading_source = "gps"\n', "must be one of fixed, hdt, hdg"),
        (
            '[[can]]\ninterface = "virtual"\nnode_ids = [256]\n',
            "can[0].node_ids[0]: must be an integer in 0..255, got 256",
        ),
        ('[[can]]\ninterface = "Bad Name"\n', "can[0].interface: must be a python-can interface"),
        (
            "[scene]\nring_radius_m = 50000\n",
            "scene.max_range_m: 40000 must be beyond scene.ring_radius_m 50000",
        ),
    ],
)
def test_out_of_range(tmp_path: Path, text: str, fragment: str) -> None:
    assert fragment in load_error(tmp_path, text)


def test_block_size_is_fixed(tmp_path: Path) -> None:
    message = load_error(tmp_path, "[scene]\nblock_size_m = 2000.0\n")
    assert "scene.block_size_m: is fixed at 4000" in message
    assert "4 km blocks by design" in message
    assert load_config(write(tmp_path, "[scene]\nblock_size_m = 4000\n", "ok.toml")) == (
        load_config(None)
    )


def test_malformed_toml_reports_line(tmp_path: Path) -> None:
    message = load_error(tmp_path, "[daemon]\ntick_hz = 30\nlog_level = INFO\n")
    assert "invalid TOML" in message
    assert "line 3" in message


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "x.toml"
    path.write_bytes(b"[daemon]\n\xff\xfe\x00garbage\n")
    with pytest.raises(ConfigError, match=re.escape(f"{path}:2: not UTF-8 text")):
        load_config(path)


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match=re.escape(f"{path}: no such file")):
        load_config(path)


def test_directory_instead_of_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="is a directory"):
        load_config(tmp_path)


def test_sections_validate_when_built_directly() -> None:
    with pytest.raises(ValueError, match=re.escape("camera.fov_deg: must be a number in 1..170")):
        CameraSection(fov_deg=0.0)


@pytest.mark.parametrize(
    ("spec", "url", "baud"),
    [
        ("/dev/ttyUSB0@4800", "/dev/ttyUSB0", 4800),
        ("/dev/ttyUSB0", "/dev/ttyUSB0", 4800),
        ("loop://", "loop://", 4800),
        ("socket://localhost:4001@9600", "socket://localhost:4001", 9600),
        ("rfc2217://user@host:2217", "rfc2217://user@host:2217", 4800),
    ],
)
def test_serial_spec(spec: str, url: str, baud: int) -> None:
    section = SerialInputSection.from_spec(spec)
    assert (section.url, section.baud) == (url, baud)
    assert section.input_name == f"serial:{url}"


@pytest.mark.parametrize(
    ("spec", "interface", "channel"),
    [
        ("socketcan:can0", "socketcan", "can0"),
        ("udp_multicast:239.74.163.2", "udp_multicast", "239.74.163.2"),
        (
            "udp_multicast:ff15:7079:7468:6f6e:6465:6d6f:6d63:6173",
            "udp_multicast",
            "ff15:7079:7468:6f6e:6465:6d6f:6d63:6173",
        ),
        ("virtual:", "virtual", ""),
    ],
)
def test_can_spec(spec: str, interface: str, channel: str) -> None:
    section = CanInputSection.from_spec(spec)
    assert (section.interface, section.channel) == (interface, channel)


@pytest.mark.parametrize(
    ("spec", "fragment"),
    [("/dev/ttyUSB0@fast", "baud rate after '@' must be a number"), ("@4800", "device path")],
)
def test_bad_serial_spec(spec: str, fragment: str) -> None:
    with pytest.raises(ValueError, match=fragment):
        SerialInputSection.from_spec(spec)


@pytest.mark.parametrize("spec", ["socketcan", ":can0"])
def test_bad_can_spec(spec: str) -> None:
    with pytest.raises(ValueError, match="INTERFACE:CHANNEL"):
        CanInputSection.from_spec(spec)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "[lightning]\nflashes_per_min = 61\n",
            "x.toml:2: lightning.flashes_per_min: must be in 0..60",
        ),
        (
            "[lightning]\nflashes_per_min = -1\n",
            "x.toml:2: lightning.flashes_per_min: must be in 0..60",
        ),
        (
            '[lightning]\nflashes_per_min = "lots"\n',
            'lightning.flashes_per_min: must be "weather" or',
        ),
        (
            "[lightning]\nflashes_per_min = true\n",
            'lightning.flashes_per_min: must be "weather" or',
        ),
        ("[lightning]\nrate = 3\n", "x.toml:2: lightning.rate: unknown key"),
        ("[radar]\nrange_nm = 400\n", "x.toml:2: radar.range_nm: must be a number in 10..320"),
        ("[radar]\nrange_nm = 5\n", "x.toml:2: radar.range_nm: must be a number in 10..320"),
        ("[radar]\ntilt_deg = -20\n", "x.toml:2: radar.tilt_deg: must be a number in -15..15"),
        ("[radar]\nsize_px = 2048\n", "x.toml:2: radar.size_px: must be an integer in 64..1024"),
        ("[radar]\nevery_s = 0\n", "x.toml:2: radar.every_s: must be a number in 0.1..3600"),
        ("[radar]\nlayer = 1\n", "x.toml:2: radar.layer: must be"),
    ],
)
def test_lightning_and_radar_keys_are_checked(tmp_path: Path, text: str, expected: str) -> None:
    message = load_error(tmp_path, text)
    assert expected in message, message
    assert "\n" not in message.strip()


def test_lightning_and_radar_keys_reach_their_users(tmp_path: Path) -> None:
    cfg = load_config(None)
    assert cfg.lightning.flashes_per_min == "weather"
    assert cfg.scene_settings().flashes_per_min is None  # by the storm's strength
    assert cfg.scene_settings() == cfg.scene.settings()
    assert not cfg.radar.layer
    text = (
        "[lightning]\nflashes_per_min = 12\n[radar]\nlayer = true\nrange_nm = 80\ntilt_deg = -2.5\n"
    )
    cfg = load_config(write(tmp_path, text))
    assert cfg.scene_settings().flashes_per_min == 12.0
    assert (cfg.radar.layer, cfg.radar.range_nm, cfg.radar.tilt_deg) == (True, 80.0, -2.5)
    assert load_config(write(tmp_path, to_toml(config_to_toml_dict(cfg)), "y.toml")) == cfg
