"""Weather presets: the shipped ones are valid and plausible; lookup and parsing reject junk."""

from __future__ import annotations

import dataclasses
import math
import shutil
from datetime import UTC, datetime
from pathlib import Path

import pytest

from wxsky.config import load_config
from wxsky.errors import PresetError
from wxsky.presets import (
    builtin_preset_dirs,
    list_presets,
    load_preset,
    load_preset_file,
)
from wxsky.weather.state import CloudType, Observer, Source, WeatherState

REPO = Path(__file__).resolve().parents[1]
SHIPPED_DIR = REPO / "configs" / "presets"
SHIPPED = sorted(p.stem for p in SHIPPED_DIR.glob("*.toml"))
REQUIRED = [
    "clear",
    "fair-cumulus",
    "scattered-cumulus",
    "broken-stratocumulus",
    "overcast-stratus",
    "thunderstorm",
    "high-cirrus",
]
LSZH = Observer(47.4647, 8.5492, 432.0)

MINIMAL = 'description = "minimal"\n'
GOOD = """
description = "A test preset"
time_utc = "2026-06-21T13:00:00Z"
seed = 5
visibility_m = 20000
temperature_c = 20.0
dewpoint_c = 10.0
qnh_hpa = 1015.0
present_weather = ["-RA"]
[observer]
lat_deg = 47.0
lon_deg = 8.0
alt_m = 400.0
[[layers]]
type = "cumulus"
cover_oktas = 3
base_m = 1500.0
top_m = 2400.0
[[wind]]
alt_m = 410.0
dir_deg = 250.0
speed_mps = 4.0
"""


def write(directory: Path, name: str, text: str) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def preset_error(tmp_path: Path, text: str | bytes) -> str:
    path = tmp_path / "bad.toml"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    with pytest.raises(PresetError) as info:
        load_preset("bad", [tmp_path])
    message = str(info.value)
    assert message.startswith(f"{path}: "), message
    return message


def sun_elevation_deg(obs: Observer, t: datetime) -> float:
    """Approximate solar elevation (NOAA low-precision formulas, good to about a degree)."""
    day = t.timetuple().tm_yday
    hours = t.hour + t.minute / 60.0
    gamma = 2.0 * math.pi / 365.0 * (day - 1 + (hours - 12.0) / 24.0)
    decl = (
        0.006918
        - 0.399912 * math.cos(gamma)
        + 0.070257 * math.sin(gamma)
        - 0.006758 * math.cos(2 * gamma)
        + 0.000907 * math.sin(2 * gamma)
    )
    eqtime_min = 229.18 * (
        0.000075
        + 0.001868 * math.cos(gamma)
        - 0.032077 * math.sin(gamma)
        - 0.014615 * math.cos(2 * gamma)
        - 0.040849 * math.sin(2 * gamma)
    )
    solar_min = hours * 60.0 + eqtime_min + 4.0 * obs.lon_deg
    hour_angle = math.radians(solar_min / 4.0 - 180.0)
    lat = math.radians(obs.lat_deg)
    sin_el = math.sin(lat) * math.sin(decl) + math.cos(lat) * math.cos(decl) * math.cos(hour_angle)
    return math.degrees(math.asin(sin_el))


def test_required_presets_are_shipped() -> None:
    assert set(REQUIRED) <= set(SHIPPED)


def test_checkout_dir_is_searched_first_among_builtins() -> None:
    assert builtin_preset_dirs()[0] == SHIPPED_DIR


def test_list_presets_sorted_with_descriptions() -> None:
    infos = list_presets()
    names = [p.name for p in infos]
    assert names == sorted(names)
    assert set(SHIPPED) <= set(names)
    for info in infos:
        assert info.description
        assert info.path.name == f"{info.name}.toml"


def test_default_config_preset_is_shipped() -> None:
    assert load_config(None).daemon.preset in SHIPPED


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_preset_gives_valid_state(name: str) -> None:
    patch = load_preset(name)
    assert patch.source is Source.PRESET
    # A preset sets every field, so switching presets never leaves another's weather behind.
    for f in dataclasses.fields(patch):
        assert getattr(patch, f.name) is not None, f"{name} leaves {f.name} unset"
    state = WeatherState().apply(patch)
    assert state.sources.layers is Source.PRESET
    assert state.observer == LSZH


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_preset_is_plausible(name: str) -> None:
    state = WeatherState().apply(load_preset(name))
    assert sun_elevation_deg(state.observer, state.time_utc) > 10.0, "the sun should be up"
    assert state.temperature_c is not None and state.dewpoint_c is not None
    assert state.dewpoint_c <= state.temperature_c
    assert 2 <= len(state.wind) <= 3
    assert state.wind[0].alt_m - state.observer.alt_m < 50.0, "the first level is the surface"
    speeds = [w.speed_mps for w in state.wind]
    assert speeds == sorted(speeds) and speeds[-1] > speeds[0], "wind increases with height"
    for layer in state.layers:
        assert layer.base_m > state.observer.alt_m


def test_shipped_seeds_are_distinct() -> None:
    seeds = [WeatherState().apply(load_preset(n)).seed for n in SHIPPED]
    assert len(set(seeds)) == len(seeds)


def layers_of(name: str) -> list[tuple[CloudType, int, float, float]]:
    state = WeatherState().apply(load_preset(name))
    return [(lay.type, lay.cover_oktas, lay.base_m, lay.top_m) for lay in state.layers]


def test_clear_has_no_clouds_and_clears_a_cloudy_state() -> None:
    cloudy = WeatherState().apply(load_preset("thunderstorm"))
    cleared = cloudy.apply(load_preset("clear"))
    assert cleared.layers == ()
    assert cleared.present_weather == ()


def test_fair_cumulus() -> None:
    [(kind, cover, _, _)] = layers_of("fair-cumulus")
    assert kind is CloudType.CUMULUS and 2 <= cover <= 3


def test_scattered_cumulus() -> None:
    [(kind, cover, _, _)] = layers_of("scattered-cumulus")
    assert kind is CloudType.CUMULUS and 3 <= cover <= 4


def test_broken_stratocumulus() -> None:
    [(kind, cover, _, _)] = layers_of("broken-stratocumulus")
    assert kind is CloudType.STRATOCUMULUS and 5 <= cover <= 7


def test_overcast_stratus() -> None:
    state = WeatherState().apply(load_preset("overcast-stratus"))
    [layer] = state.layers
    assert layer.type is CloudType.STRATUS and layer.cover_oktas == 8
    assert 300.0 <= layer.base_m - state.observer.alt_m <= 600.0
    assert state.visibility_m < 10_000.0


def test_thunderstorm() -> None:
    state = WeatherState().apply(load_preset("thunderstorm"))
    cb = [lay for lay in state.layers if lay.type is CloudType.CUMULONIMBUS]
    assert len(cb) == 1
    assert any(lay.base_m < cb[0].base_m for lay in state.layers), "lower layers below the Cb"
    assert any("TS" in w and "RA" in w for w in state.present_weather)
    assert state.wind[0].gust_mps > state.wind[0].speed_mps


def test_high_cirrus() -> None:
    layers = layers_of("high-cirrus")
    assert layers
    for kind, cover, base_m, _ in layers:
        assert kind in (CloudType.CIRRUS, CloudType.CIRROSTRATUS)
        assert 1 <= cover <= 4 and base_m > 7000.0


def test_partial_preset_sets_only_what_it_gives(tmp_path: Path) -> None:
    write(tmp_path, "partial", 'description = "only vis"\nvisibility_m = 1234\n')
    patch = load_preset("partial", [tmp_path])
    assert patch.visibility_m == 1234.0
    assert patch.layers is None and patch.wind is None and patch.observer is None
    state = WeatherState().apply(patch)
    assert state.sources.visibility_m is Source.PRESET
    assert state.sources.layers is Source.DEFAULT


def test_full_preset_parses(tmp_path: Path) -> None:
    write(tmp_path, "good", GOOD)
    info, patch = load_preset_file(tmp_path / "good.toml")
    assert (info.name, info.description) == ("good", "A test preset")
    assert patch.time_utc == datetime(2026, 6, 21, 13, tzinfo=UTC)
    assert patch.observer == Observer(47.0, 8.0, 400.0)
    assert patch.present_weather == ("-RA",)
    assert patch.wind is not None and patch.wind[0].dir_from_deg == 250.0
    assert patch.wind[0].gust_mps == 0.0


def test_native_toml_datetime(tmp_path: Path) -> None:
    write(tmp_path, "t", 'description = "t"\ntime_utc = 2026-06-21T15:00:00+02:00\n')
    assert load_preset("t", [tmp_path]).time_utc == datetime(2026, 6, 21, 13, tzinfo=UTC)


def test_unknown_preset_lists_known_names() -> None:
    with pytest.raises(PresetError) as info:
        load_preset("no-such-preset")
    message = str(info.value)
    assert "unknown preset 'no-such-preset'" in message
    for name in REQUIRED:
        assert name in message


@pytest.mark.parametrize(
    "name", ["../x", "../configs/presets/clear", "/etc/passwd", "Clear", "a b", "", "x.toml"]
)
def test_path_tricks_rejected(name: str) -> None:
    with pytest.raises(PresetError, match="invalid preset name"):
        load_preset(name)


def test_extra_dir_overrides_builtin(tmp_path: Path) -> None:
    write(tmp_path, "clear", 'description = "my clear"\nvisibility_m = 7777\n')
    assert load_preset("clear", [tmp_path]).visibility_m == 7777.0
    assert load_preset("clear").visibility_m != 7777.0
    [info] = [p for p in list_presets([tmp_path]) if p.name == "clear"]
    assert info.description == "my clear"
    assert info.path == tmp_path / "clear.toml"


def test_first_extra_dir_wins(tmp_path: Path) -> None:
    write(tmp_path / "a", "mine", 'description = "a"\n')
    write(tmp_path / "b", "mine", 'description = "b"\nseed = 2\n')
    assert load_preset("mine", [tmp_path / "a", tmp_path / "b"]).seed is None
    assert load_preset("mine", [str(tmp_path / "b"), tmp_path / "a"]).seed == 2


def test_missing_extra_dir_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(PresetError, match="does not exist"):
        load_preset("clear", [tmp_path / "nope"])


def test_files_with_invalid_names_are_ignored(tmp_path: Path) -> None:
    write(tmp_path, "Upper", MINIMAL)
    write(tmp_path, "under_score", MINIMAL)
    names = {p.name for p in list_presets([tmp_path])}
    assert "Upper" not in names and "under_score" not in names


def test_garbage_bytes(tmp_path: Path) -> None:
    assert "not UTF-8" in preset_error(tmp_path, b"\x89PNG\r\n\x1a\n\x00\xff\xfe garbage")


def test_binary_but_utf8_garbage(tmp_path: Path) -> None:
    assert "invalid TOML" in preset_error(tmp_path, "\x00\x01\x02 = = [[\n")


def test_truncated_file(tmp_path: Path) -> None:
    text = (SHIPPED_DIR / "fair-cumulus.toml").read_text(encoding="utf-8")
    message = preset_error(tmp_path, text[: text.index('type = "cumulus"') + 10])
    assert "invalid TOML" in message and "line" in message


def test_truncated_after_a_whole_line(tmp_path: Path) -> None:
    text = (SHIPPED_DIR / "fair-cumulus.toml").read_text(encoding="utf-8")
    cut = text.index("cover_oktas = 3")
    assert "missing key 'layers[0].cover_oktas'" in preset_error(tmp_path, text[:cut])


def test_oktas_out_of_range(tmp_path: Path) -> None:
    message = preset_error(tmp_path, GOOD.replace("cover_oktas = 3", "cover_oktas = 9"))
    assert "layers[0].cover_oktas must be an integer in 0..8, got 9" in message


def test_top_below_base(tmp_path: Path) -> None:
    message = preset_error(tmp_path, GOOD.replace("top_m = 2400.0", "top_m = 1000.0"))
    assert "layers[0].top_m 1000 must be above base_m 1500" in message


@pytest.mark.parametrize(
    ("old", "new", "fragment"),
    [
        ('description = "A test preset"', "", "missing key 'description'"),
        ("seed = 5", "sed = 5", "unknown key 'sed'"),
        ("alt_m = 400.0", "alt_m = 400.0\nheight_m = 1", "unknown key 'observer.height_m'"),
        ("top_m = 2400.0", "top_m = 2400.0\ncolour = 1", "unknown key 'layers[0].colour'"),
        ("speed_mps = 4.0", "speed_mps = 4.0\nspd = 1", "unknown key 'wind[0].spd'"),
        ('type = "cumulus"', 'type = "cumulous"', "layers[0].type: unknown cloud type"),
        ('type = "cumulus"', 'type = "none"', "layers[0].type must be a cloud type"),
        ("visibility_m = 20000", 'visibility_m = "far"', "visibility_m must be a number"),
        ("qnh_hpa = 1015.0", "qnh_hpa = 500.0", "qnh_hpa must be a number in 850..1100"),
        ("dewpoint_c = 10.0", "dewpoint_c = 25.0", "dewpoint_c 25 is above temperature_c 20"),
        ("lat_deg = 47.0", "lat_deg = 95.0", "observer.lat_deg must be a number in -90..90"),
        ("lat_deg = 47.0", "", "missing key 'observer.lat_deg'"),
        ("dir_deg = 250.0", "dir_deg = 361.0", "wind[0].dir_deg must be a number in 0..360"),
        ("speed_mps = 4.0", "speed_mps = 4.0\ngust_mps = 2.0", "wind[0].gust_mps 2 must be"),
        ("seed = 5", "seed = -1", "seed must be an integer"),
        ('time_utc = "2026-06-21T13:00:00Z"', 'time_utc = "noon"', "time_utc: not an ISO"),
        ('time_utc = "2026-06-21T13:00:00Z"', "time_utc = 2026-06-21", "a date without a time"),
        ('present_weather = ["-RA"]', 'present_weather = ["rain"]', "METAR weather groups"),
        ('present_weather = ["-RA"]', 'present_weather = "-RA"', "must be a list"),
    ],
)
def test_malformed_values_name_the_key(tmp_path: Path, old: str, new: str, fragment: str) -> None:
    assert old in GOOD
    assert fragment in preset_error(tmp_path, GOOD.replace(old, new))


def test_layers_must_be_an_array_of_tables(tmp_path: Path) -> None:
    message = preset_error(tmp_path, 'description = "x"\nlayers = 3\n')
    assert "layers must be an array of tables" in message


def test_too_many_layers(tmp_path: Path) -> None:
    layer = '[[layers]]\ntype = "stratus"\ncover_oktas = 1\nbase_m = {b}\ntop_m = {t}\n'
    text = 'description = "x"\n' + "".join(
        layer.format(b=1000 + 500 * i, t=1200 + 500 * i) for i in range(7)
    )
    assert "at most 6 cloud layers" in preset_error(tmp_path, text)


def test_repeated_wind_level(tmp_path: Path) -> None:
    wind = "[[wind]]\nalt_m = 500\ndir_deg = 10\nspeed_mps = 3\n"
    message = preset_error(tmp_path, 'description = "x"\n' + wind + wind)
    assert "wind[1].alt_m 500 repeats wind[0].alt_m" in message


def test_malformed_file_fails_listing(tmp_path: Path) -> None:
    write(tmp_path, "broken", "description = \n")
    with pytest.raises(PresetError, match=r"broken\.toml"):
        list_presets([tmp_path])


def test_copied_preset_dir_works(tmp_path: Path) -> None:
    """Presets are plain files: a copy of the shipped ones loads identically elsewhere."""
    copy = tmp_path / "copy"
    shutil.copytree(SHIPPED_DIR, copy)
    for name in SHIPPED:
        assert load_preset(name, [copy]) == load_preset(name)
