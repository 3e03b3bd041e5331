"""Weather presets: the shipped ones are valid and plausible; lookup and parsing reject junk
with `FILE:LINE: key: problem`; the user folder overrides built-ins; written presets load back
equal; diffs name the fields."""

from __future__ import annotations

import dataclasses
import math
import re
import shutil
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest

from wxsky.errors import PresetError
from wxsky.settings.config import load_config
from wxsky.settings.preset_check import check_preset_file, format_key, key_line
from wxsky.settings.preset_write import preset_diff, preset_to_toml
from wxsky.settings.presets import (
    builtin_preset_dirs,
    find_preset,
    list_presets,
    load_preset,
    load_preset_file,
    patch_from_weather_dict,
    preset_search_path,
    resolve_preset,
    user_preset_dir,
    write_user_preset,
)
from wxsky.weather.state import (
    NO_FOG,
    CloudLayer,
    CloudType,
    Observer,
    Source,
    WeatherPatch,
    WeatherState,
    WindLayer,
    weather_to_dict,
)

REPO = Path(__file__).resolve().parents[1]
SHIPPED_DIR = REPO / "wxsky" / "settings" / "presets"
SHIPPED = sorted(p.stem for p in SHIPPED_DIR.glob("*.toml"))
REQUIRED = [
    "clear",
    "fair-cumulus",
    "scattered-cumulus",
    "broken-stratocumulus",
    "overcast-stratus",
    "thunderstorm",
    "high-cirrus",
    "towering-cumulus",
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


@pytest.fixture(autouse=True)
def user_dir(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Every test gets an empty user folder of its own: the real ~/.config is never read."""
    config_home = tmp_path_factory.mktemp("xdg-config")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(config_home))
    return config_home / "wxsky" / "presets"


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
    assert "\n" not in message
    assert re.match(rf"{re.escape(str(path))}:\d+: ", message), message
    return message[len(str(path)) + 1 :]


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
        if f.name == "precipitation":
            continue  # presets hold no precipitation layers yet (only a CIGI host sets them)
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
    message = preset_error(tmp_path, b"\x89PNG\r\n\x1a\n\x00\xff\xfe garbage")
    assert message == "1: not UTF-8 text"
    message = preset_error(tmp_path, b'description = "x"\nseed = \xff\xfe\n')
    assert message == "2: not UTF-8 text"


def test_binary_but_utf8_garbage(tmp_path: Path) -> None:
    message = preset_error(tmp_path, "\x00\x01\x02 = = [[\n")
    assert message.startswith("1: invalid TOML: "), message


def test_truncated_file(tmp_path: Path) -> None:
    text = (SHIPPED_DIR / "fair-cumulus.toml").read_text(encoding="utf-8")
    cut = text[: text.index('type = "cumulus"') + 10]
    message = preset_error(tmp_path, cut)
    # tomllib says "at end of document"; the line is the last one, where the cut is.
    assert message.startswith(f"{cut.count(chr(10)) + 1}: invalid TOML: "), message
    assert "Unterminated string" in message


def test_truncated_after_a_whole_line(tmp_path: Path) -> None:
    text = (SHIPPED_DIR / "fair-cumulus.toml").read_text(encoding="utf-8")
    cut = text[: text.index("cover_oktas = 3")]
    header_line = cut.splitlines().index("[[layers]]") + 1
    message = preset_error(tmp_path, cut)
    # Missing keys point at their table's header; base_m and top_m are missing too.
    assert message == f"{header_line}: layers[0].cover_oktas: missing key (and 2 more problems)"


def test_oktas_out_of_range(tmp_path: Path) -> None:
    message = preset_error(tmp_path, GOOD.replace("cover_oktas = 3", "cover_oktas = 9"))
    assert message == "16: layers[0].cover_oktas: must be an integer in 0..8, got 9"


def test_top_below_base(tmp_path: Path) -> None:
    message = preset_error(tmp_path, GOOD.replace("top_m = 2400.0", "top_m = 1000.0"))
    assert message == "18: layers[0].top_m: 1000 must be above base_m 1500"


@pytest.mark.parametrize(
    ("old", "new", "expected"),
    [
        ('description = "A test preset"', "", "1: description: missing key"),
        ("seed = 5", "sed = 5", "4: sed: unknown key (did you mean 'seed'?)"),
        ("alt_m = 400.0", "alt_m = 400.0\nheight_m = 1", "14: observer.height_m: unknown key"),
        ("top_m = 2400.0", "top_m = 2400.0\ncolour = 1", "19: layers[0].colour: unknown key"),
        ("speed_mps = 4.0", "speed_mps = 4.0\nspd = 1", "23: wind[0].spd: unknown key"),
        ('type = "cumulus"', 'type = "cumulous"', "15: layers[0].type: unknown cloud type"),
        ('type = "cumulus"', 'type = "none"', "15: layers[0].type: must be a cloud type"),
        ("visibility_m = 20000", 'visibility_m = "far"', "5: visibility_m: must be a number"),
        ("qnh_hpa = 1015.0", "qnh_hpa = 500.0", "8: qnh_hpa: must be a number in 850..1100"),
        ("dewpoint_c = 10.0", "dewpoint_c = 25.0", "7: dewpoint_c: 25 is above temperature_c 20"),
        ("lat_deg = 47.0", "lat_deg = 95.0", "11: observer.lat_deg: must be a number in -90..90"),
        ("lat_deg = 47.0", "", "10: observer.lat_deg: missing key"),
        ("dir_deg = 250.0", "dir_deg = 361.0", "21: wind[0].dir_deg: must be a number in 0..360"),
        ("speed_mps = 4.0", "speed_mps = 4.0\ngust_mps = 2.0", "23: wind[0].gust_mps: 2 must"),
        ("seed = 5", "seed = -1", "4: seed: must be an integer"),
        ('time_utc = "2026-06-21T13:00:00Z"', 'time_utc = "noon"', "3: time_utc: not an ISO"),
        (
            'time_utc = "2026-06-21T13:00:00Z"',
            "time_utc = 2026-06-21",
            "3: time_utc: must be an ISO 8601 date-time, got a date without a time",
        ),
        (
            'present_weather = ["-RA"]',
            'present_weather = ["rain"]',
            "9: present_weather[0]: must be a METAR weather group",
        ),
        ('present_weather = ["-RA"]', 'present_weather = "-RA"', "9: present_weather: must be a"),
    ],
)
def test_malformed_values_name_line_and_key(
    tmp_path: Path, old: str, new: str, expected: str
) -> None:
    assert old in GOOD
    assert preset_error(tmp_path, GOOD.replace(old, new)).startswith(expected)


def test_layers_must_be_an_array_of_tables(tmp_path: Path) -> None:
    message = preset_error(tmp_path, 'description = "x"\nlayers = 3\n')
    assert message == "2: layers: must be an array of tables ([[layers]]), got 3"


LAYER = '[[layers]]\ntype = "stratus"\ncover_oktas = 1\nbase_m = {b}\ntop_m = {t}\n'


def test_too_many_layers_points_at_the_first_layer_too_many(tmp_path: Path) -> None:
    text = 'description = "x"\n' + "".join(
        LAYER.format(b=1000 + 500 * i, t=1200 + 500 * i) for i in range(7)
    )
    # Layer i's header is on line 2 + 5 * i; the seventh (index 6) is one too many.
    assert preset_error(tmp_path, text) == "32: layers: at most 6 cloud layers, got 7"


def test_repeated_wind_level(tmp_path: Path) -> None:
    wind = "[[wind]]\nalt_m = 500\ndir_deg = 10\nspeed_mps = 3\n"
    message = preset_error(tmp_path, 'description = "x"\n' + wind + wind)
    assert message == "7: wind[1].alt_m: 500 repeats wind[0].alt_m"


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


# -- every problem, with its line -------------------------------------------------------------


def line_of(text: str, needle: str, occurrence: int = 0) -> int:
    """The 1-based line of the `occurrence`-th line of `text` that starts with `needle`."""
    hits = [n for n, line in enumerate(text.splitlines(), 1) if line.strip().startswith(needle)]
    return hits[occurrence]


def test_key_line_on_a_multi_layer_file() -> None:
    text = (SHIPPED_DIR / "thunderstorm.toml").read_text(encoding="utf-8")
    assert key_line(text, ("layers", 0, "cover_oktas")) == line_of(text, "cover_oktas", 0)
    assert key_line(text, ("layers", 1, "cover_oktas")) == line_of(text, "cover_oktas", 1)
    assert key_line(text, ("layers", 2, "top_m")) == line_of(text, "top_m", 2)
    assert key_line(text, ("wind", 2, "speed_mps")) == line_of(text, "speed_mps", 2)
    assert key_line(text, ("observer", "alt_m")) == line_of(text, "alt_m", 0)
    assert key_line(text, ("seed",)) == line_of(text, "seed")
    assert key_line(text, ("layers",)) == line_of(text, "[[layers]]", 0)
    # Not spelled out: the nearest enclosing table's header.
    assert key_line(text, ("layers", 1, "nonsense")) == line_of(text, "[[layers]]", 1)
    assert key_line(text, ("wind", 1)) == line_of(text, "[[wind]]", 1)
    assert key_line(text, ("nonsense",)) is None


def test_key_line_other_spellings() -> None:
    text = (
        'description = """\n'
        "[[layers]]\n"  # inside a multi-line string: not a header
        'cover_oktas = 1"""\n'
        "observer.lat_deg = 47.0\n"
        '"seed" = 3\n'
        "layers = [\n"
        '  { type = "cumulus", cover_oktas = 2, base_m = 1, top_m = 2 },\n'
        "]\n"
        "[ wind ] # a comment\n"
        "'alt_m' = 3\n"
    )
    assert key_line(text, ("description",)) == 1
    assert key_line(text, ("observer", "lat_deg")) == 4
    assert key_line(text, ("observer",)) == 4
    assert key_line(text, ("seed",)) == 5
    # Entries of an inline array point at the array's key.
    assert key_line(text, ("layers", 0, "cover_oktas")) == 6
    assert key_line(text, ("wind", "alt_m")) == 10


def test_format_key() -> None:
    assert format_key(("layers", 1, "cover_oktas")) == "layers[1].cover_oktas"
    assert format_key(("observer", "lat_deg")) == "observer.lat_deg"
    assert format_key(("a b",)) == '"a b"'
    assert format_key(()) == ""


def test_check_reports_every_problem_in_file_order(tmp_path: Path) -> None:
    text = (SHIPPED_DIR / "thunderstorm.toml").read_text(encoding="utf-8")
    text = text.replace("cover_oktas = 4", "cover = 4")  # layer 1: unknown key + missing key
    text = text.replace("speed_mps = 18.0", "speed_mps = -1.0")  # wind 2
    text = text.replace("seed = 41", 'seed = "x"')
    path = tmp_path / "storm.toml"
    path.write_text(text, encoding="utf-8")
    check = check_preset_file(path)
    assert check.patch is None
    assert check.lines() == [
        f"{path}:{line_of(text, 'seed')}: seed: must be an integer in "
        "0..9223372036854775807, got 'x'",
        f"{path}:{line_of(text, '[[layers]]', 1)}: layers[1].cover_oktas: missing key",
        f"{path}:{line_of(text, 'cover = 4')}: layers[1].cover: unknown key "
        "(did you mean 'cover_oktas'?)",
        f"{path}:{line_of(text, 'speed_mps', 2)}: wind[2].speed_mps: must be a number in "
        "0..150, got -1.0",
    ]
    with pytest.raises(PresetError) as info:
        load_preset_file(path)
    assert str(info.value) == check.lines()[0] + " (and 3 more problems)"


def test_check_of_a_good_file_has_the_patch() -> None:
    check = check_preset_file(SHIPPED_DIR / "clear.toml")
    assert check.problems == ()
    assert check.patch == load_preset("clear")


def test_check_of_a_missing_file(tmp_path: Path) -> None:
    assert check_preset_file(tmp_path / "nope.toml").lines() == [
        f"{tmp_path / 'nope.toml'}: no such file"
    ]


# -- the user folder ----------------------------------------------------------------------------


def test_user_dir_follows_xdg_config_home(user_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert user_preset_dir() == user_dir
    monkeypatch.setenv("XDG_CONFIG_HOME", "relative/dir")  # ignored, as the XDG spec says
    monkeypatch.setenv("HOME", "/home/someone")
    assert user_preset_dir() == Path("/home/someone/.config/wxsky/presets")
    monkeypatch.delenv("XDG_CONFIG_HOME")
    assert user_preset_dir() == Path("/home/someone/.config/wxsky/presets")


def test_search_order_extra_then_user_then_builtin(tmp_path: Path, user_dir: Path) -> None:
    extra = tmp_path / "extra"
    extra.mkdir()
    assert preset_search_path([extra]) == (extra, user_dir, *builtin_preset_dirs())


def test_user_preset_overrides_builtin_and_extra_dir_overrides_user(
    tmp_path: Path, user_dir: Path
) -> None:
    write(user_dir, "clear", 'description = "my clear"\nvisibility_m = 7777\n')
    assert load_preset("clear").visibility_m == 7777.0
    assert find_preset("clear") == (user_dir / "clear.toml", "user")
    [info] = [p for p in list_presets() if p.name == "clear"]
    assert (info.origin, info.overrides, info.description) == ("user", ("builtin",), "my clear")
    [other] = [p for p in list_presets() if p.name == "thunderstorm"]
    assert (other.origin, other.overrides) == ("builtin", ())

    write(tmp_path / "extra", "clear", 'description = "extra clear"\nvisibility_m = 5555\n')
    assert load_preset("clear", [tmp_path / "extra"]).visibility_m == 5555.0
    [info] = [p for p in list_presets([tmp_path / "extra"]) if p.name == "clear"]
    assert info.origin == str(tmp_path / "extra")
    assert info.overrides == ("user", "builtin")


def test_write_user_preset_refuses_to_overwrite(user_dir: Path) -> None:
    path = write_user_preset("mine", 'description = "one"\n')
    assert path == user_dir / "mine.toml"
    with pytest.raises(PresetError, match="already exists"):
        write_user_preset("mine", 'description = "two"\n')
    assert load_preset_file(path)[0].description == "one"
    write_user_preset("mine", 'description = "two"\n', force=True)
    assert load_preset_file(path)[0].description == "two"
    assert [p.name for p in user_dir.iterdir()] == ["mine.toml"], "no temporary files left"
    with pytest.raises(PresetError, match="invalid preset name"):
        write_user_preset("../escape", 'description = "x"\n')


def test_resolve_preset_by_name_or_path(tmp_path: Path) -> None:
    info, patch = resolve_preset("clear")
    assert (info.name, info.origin, patch) == ("clear", "builtin", load_preset("clear"))
    path = write(tmp_path, "elsewhere", 'description = "e"\nseed = 9\n')
    info, patch = resolve_preset(str(path))
    assert (info.name, info.origin, patch.seed) == ("elsewhere", "file", 9)


# -- writing presets ----------------------------------------------------------------------------


@pytest.mark.parametrize("name", SHIPPED)
def test_written_preset_loads_back_equal(tmp_path: Path, name: str) -> None:
    info, original = load_preset_file(SHIPPED_DIR / f"{name}.toml")
    path = tmp_path / f"{name}.toml"
    path.write_text(preset_to_toml(original, info.description), encoding="utf-8")
    loaded_info, loaded = load_preset_file(path)
    assert loaded == original
    assert loaded_info.description == info.description


def test_written_preset_text_matches_the_shipped_layout() -> None:
    text = preset_to_toml(load_preset("fair-cumulus"), "Fair", comment="made by a test")
    assert text.startswith('# made by a test\ndescription = "Fair"\ntime_utc = "2026-06-21T13')
    assert "\n[observer]\nlat_deg = 47.4647\nlon_deg = 8.5492\nalt_m = 432.0\n" in text
    assert '\n[[layers]]\ntype = "cumulus"\ncover_oktas = 3\nbase_m = 1930.0\n' in text
    assert text.count("[[wind]]") == 3
    # Top-level keys all come before the first table.
    assert text.index("present_weather = []") < text.index("[observer]")


def write_and_load(tmp_path: Path, weather: WeatherPatch | WeatherState, desc: str) -> Any:
    path = tmp_path / "w.toml"
    path.write_text(preset_to_toml(weather, desc), encoding="utf-8")
    return load_preset_file(path)


def test_writer_edge_cases_round_trip(tmp_path: Path) -> None:
    patch = WeatherPatch(
        source=Source.PRESET,
        time_utc=datetime(2026, 1, 2, 3, 4, 5, 678901, tzinfo=UTC),
        layers=(),  # "no clouds" must survive, it is not the same as unset
        wind=(WindLayer(10.0, 0.0, 2.5, 7.25, variable=True), WindLayer(1e4, 359.9, 0.1)),
        temperature_c=-0.0,
        present_weather=("+TSRA", "VCSH"),
        fog=NO_FOG,  # a preset file without [fog] states no fog
        seed=2**63 - 1,
    )
    description = 'Quotes " and \\ backslash, tab\t, newline\n, bell \x07 and DEL \x7f ünïcode'
    info, loaded = write_and_load(tmp_path, patch, description)
    assert loaded == patch
    assert info.description == description.strip()


def test_writer_takes_a_state(tmp_path: Path) -> None:
    state = WeatherState().apply(load_preset("thunderstorm"))
    _, loaded = write_and_load(tmp_path, state, "from a state")
    assert WeatherState().apply(loaded) == dataclasses.replace(
        state, sources=WeatherState().apply(loaded).sources
    )


def test_writer_refuses_what_a_preset_cannot_hold() -> None:
    with pytest.raises(ValueError, match="description"):
        preset_to_toml(load_preset("clear"), "  ")
    layer = CloudLayer(2, 1000.0, 1500.0, CloudType.CUMULUS)
    object.__setattr__(layer, "cover_oktas", 2.5)  # as a state in mid-transition holds it
    with pytest.raises(ValueError, match="whole number of oktas"):
        preset_to_toml(WeatherPatch(source=Source.PRESET, layers=(layer,)), "x")


def test_patch_from_weather_dict_is_the_state_as_a_preset() -> None:
    state = WeatherState().apply(load_preset("thunderstorm"))
    weather = weather_to_dict(state)
    patch = patch_from_weather_dict(weather)
    assert patch.layers == state.layers and patch.wind == state.wind
    assert patch.observer == state.observer and patch.seed == state.seed
    assert patch.time_utc == state.time_utc
    assert patch.present_weather == state.present_weather


def test_patch_from_weather_dict_rounds_oktas_and_drops_unknowns() -> None:
    weather = weather_to_dict(WeatherState().apply(load_preset("fair-cumulus")))
    weather["layers"][0]["cover_oktas"] = 2.6
    weather["temperature_c"] = None
    patch = patch_from_weather_dict(weather)
    assert patch.layers is not None and patch.layers[0].cover_oktas == 3
    assert patch.temperature_c is None
    weather["layers"][0]["base_m"] = "high"
    with pytest.raises(PresetError, match=r"layers\[0\]\.base_m: must be a number"):
        patch_from_weather_dict(weather)


# -- comparing presets --------------------------------------------------------------------------


def test_diff_of_two_builtins() -> None:
    diffs = {
        d.key: (d.a, d.b) for d in preset_diff(load_preset("clear"), load_preset("fair-cumulus"))
    }
    assert diffs["seed"] == (3, 7)
    assert diffs["visibility_m"] == (60000.0, 30000.0)
    assert diffs["layers"] == ([], None)
    assert diffs["layers[0].type"] == (None, "cumulus")
    assert diffs["layers[0].cover_oktas"] == (None, 3)
    assert diffs["wind[0].dir_deg"] == (60.0, 250.0)
    assert diffs["wind[0].speed_mps"] == (3.0, 4.0)
    assert "observer.lat_deg" not in diffs  # the same in both
    assert "wind[0].alt_m" not in diffs


def test_diff_compares_by_height_and_is_empty_for_equal_weather() -> None:
    storm = load_preset("thunderstorm")
    assert storm.layers is not None
    shuffled = dataclasses.replace(storm, layers=tuple(reversed(storm.layers)))
    assert preset_diff(storm, shuffled) == []
    assert preset_diff(storm, storm) == []


def test_diff_of_a_partial_preset_shows_unset_fields() -> None:
    partial = WeatherPatch(source=Source.PRESET, visibility_m=1000.0)
    diffs = {d.key: (d.a, d.b) for d in preset_diff(partial, load_preset("overcast-stratus"))}
    assert diffs["visibility_m"] == (1000.0, 4000.0)
    assert diffs["present_weather"] == (None, ["BR"])
    assert diffs["observer.alt_m"] == (None, 432.0)
    assert diffs["wind[2].speed_mps"] == (None, 8.0)
