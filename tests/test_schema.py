"""The one settings checker: kinds, tables, located problems, and that every checker takes
its limits from the one owner of each."""

from __future__ import annotations

import math
import random
import re
from pathlib import Path
from typing import Any

import pytest

from wxsky.app import control
from wxsky.errors import ConfigError
from wxsky.scene import camera
from wxsky.scene.cloud_model_files import MODEL_TABLE, load_cloud_model
from wxsky.schema import (
    REQUIRED,
    Bool,
    Field,
    Invalid,
    Items,
    Nullable,
    Number,
    Problem,
    Rule,
    Table,
    Tables,
    Text,
    Tuple,
    format_key,
)
from wxsky.schema.toml_file import check_toml_bytes, key_lines
from wxsky.settings import config as cfg
from wxsky.settings.config import CONFIG_TABLE, load_config
from wxsky.settings.preset_check import PRESET_TABLE, check_preset_file
from wxsky.weather import cockpit, state

WIDTH = Number(16, 8192, integer=True)


@pytest.mark.parametrize(
    ("value", "ok"),
    [(16, True), (8192, True), (15, False), (8193, False), (16.0, False), (True, False),
     ("16", False), (None, False)],
)  # fmt: skip
def test_an_integer_kind_takes_integers_within_its_limits(value: Any, ok: bool) -> None:
    problems: list[Problem] = []
    out = WIDTH.check(value, ("camera", "width"), problems)
    assert (out == value and not problems) if ok else (out is None and len(problems) == 1)
    if not ok:
        assert problems[0].key == "camera.width"
        assert problems[0].message == f"must be an integer in 16..8192, got {value!r}"


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1e400])
def test_a_number_kind_refuses_what_is_not_finite(value: float) -> None:
    with pytest.raises(ValueError, match=r"^x: must be a number in 0\.\.1, got"):
        Number(0.0, 1.0).validate("x", value)


def test_number_texts() -> None:
    assert Number(0.0, 25_000.0, above_lo=True).describe() == (
        "a number in 0..25000 and more than 0"
    )
    assert Number(1).describe() == "a number of at least 1"
    assert Number().describe() == "a number"
    assert Number(0, 2**63 - 1, integer=True).range_text() == "0..9223372036854775807"
    assert Number(-1.5, 0.25).range_text() == "-1.5..0.25"
    assert Number(0.0, 1.0, above_lo=True).contains(0.0) is False
    assert Number(10, 20).clamp_hi(15) == Number(10, 15)


def test_text_kinds() -> None:
    level = Text(choices=("DEBUG", "INFO"))
    assert level.validate("k", "debug") == "DEBUG"
    with pytest.raises(ValueError, match="k: must be one of DEBUG, INFO, got 'LOUD'"):
        level.validate("k", "LOUD")
    icao = Text(pattern=r"[A-Z]{4}", pattern_desc="a 4-letter ICAO id")
    with pytest.raises(ValueError, match="must be a 4-letter ICAO id, got 'LSZ'"):
        icao.validate("k", "LSZ")
    with pytest.raises(ValueError, match="must be a non-empty string"):
        Text(non_empty=True).validate("k", "  ")


def test_items_report_the_bad_item_and_the_shape() -> None:
    span = Items(Number(0.0, 4.0), length=2, ordered=True, what="[lo, hi]")
    assert span.validate("w", [1, 2.5]) == (1.0, 2.5)
    problems: list[Problem] = []
    span.check([1.0, "x"], ("box", 0, "width"), problems)
    assert [str(p) for p in problems] == ["box[0].width[1]: must be a number in 0..4, got 'x'"]
    for bad, fragment in (([2.0, 1.0], "lo <= hi"), ([1.0], "[lo, hi]"), ("ab", "[lo, hi]")):
        with pytest.raises(ValueError, match=fragment):
            span.validate("w", bad)
    with pytest.raises(ValueError, match="at least one item"):
        Items(Text(), min_len=1).validate("t", [])


LAYER = Table(
    {
        "base_m": Field(Number(-500.0, 25_000.0), REQUIRED),
        "top_m": Field(Number(-500.0, 25_000.0), REQUIRED),
        "wet": Field(Bool(), False),
    },
    rules=(
        Rule(
            ("base_m", "top_m"),
            lambda v, path, problems: (
                None
                if v["top_m"] > v["base_m"]
                else problems.append(Problem((*path, "top_m"), "must be above base_m"))
            ),
        ),
    ),
)
DOC = Table({"name": Field(Text(), REQUIRED), "layers": Field(Tables(LAYER, "layers", 2))})


def test_a_table_reports_every_problem_at_once() -> None:
    with pytest.raises(Invalid) as info:
        DOC.values({"nmae": "x", "layers": [{"base_m": 1.0, "top_m": 0.5, "wat": 1}, {}, {}]})
    assert [str(p) for p in info.value.problems] == [
        "nmae: unknown key (did you mean 'name'?)",
        "name: missing key",
        "layers[0].wat: unknown key (did you mean 'wet'?)",
        "layers[0].top_m: must be above base_m",
        "layers[1].base_m: missing key",
        "layers[1].top_m: missing key",
        "layers[2].base_m: missing key",
        "layers[2].top_m: missing key",
        "layers: at most 2 layers, got 3",
    ]
    assert info.value.problems[-1].at == ("layers", 2)


def test_a_rule_runs_when_its_own_keys_are_good() -> None:
    # The wet flag is wrong, but base and top are fine: their rule still speaks.
    with pytest.raises(Invalid) as info:
        LAYER.values({"base_m": 5.0, "top_m": 1.0, "wet": "yes"})
    assert [str(p) for p in info.value.problems] == [
        "wet: must be true or false, got 'yes'",
        "top_m: must be above base_m",
    ]
    # A rule whose key failed stays quiet: its problem would only repeat the key's.
    with pytest.raises(Invalid, match=r"^top_m: must be a number"):
        LAYER.values({"base_m": 5.0, "top_m": "low"})


def test_cross_key_checks_run_once_the_keys_are_good() -> None:
    with pytest.raises(Invalid, match=r"^layers\[0\]\.top_m: must be above base_m$"):
        DOC.values({"name": "x", "layers": [{"base_m": 1.0, "top_m": 0.5}]})
    assert DOC.values({"name": "x", "layers": [{"base_m": 1, "top_m": 2}]}) == {
        "name": "x",
        "layers": ({"base_m": 1.0, "top_m": 2.0, "wet": False},),
    }


def test_problems_are_located_in_the_file(tmp_path: Path) -> None:
    text = (
        'name = "x"\n\n[[layers]]\nbase_m = 1\ntop_m = 2\n\n'
        '[[layers]]\nbase_m = 5\ntop_m = "high"\n'
    )
    checked = check_toml_bytes(tmp_path / "f.toml", text.encode(), DOC)
    assert checked.lines() == [
        f"{tmp_path / 'f.toml'}:9: layers[1].top_m: must be a number in -500..25000, got 'high'"
    ]
    assert key_lines(text)[("layers", 1)] == 7
    assert format_key(("a b", 0, "c")) == '"a b"[0].c'


def test_garbage_truncation_and_random_documents_never_raise(tmp_path: Path) -> None:
    rng = random.Random(12)
    good = b'name = "x"\n[[layers]]\nbase_m = 1.0\ntop_m = 2.0\nwet = true\n'
    samples = [good[:n] for n in range(len(good) + 1)]
    samples += [bytes(rng.randrange(256) for _ in range(rng.randrange(80))) for _ in range(300)]
    values: list[Any] = [None, 1, -1e9, math.nan, "s", True, [], [1, "a"], {}, {"k": []}]
    for _ in range(300):
        doc = {rng.choice(["name", "layers", "x"]): rng.choice(values) for _ in range(3)}
        problems: list[Problem] = []
        out = DOC.check(doc, (), problems)
        assert (out is None) == bool(problems)
        assert all(isinstance(p.message, str) and p.message for p in problems)
    for raw in samples:
        checked = check_toml_bytes(tmp_path / "g.toml", raw, DOC)
        assert checked.ok == (checked.value is not None)
        assert all(line.startswith(str(tmp_path / "g.toml")) for line in checked.lines())


# -- one owner for each limit -------------------------------------------------------------


def test_the_camera_limits_have_one_owner() -> None:
    kinds = cfg.section_kinds(cfg.CameraSection)
    assert kinds["width"] is camera.VIEWPORT_PX and kinds["height"] is camera.VIEWPORT_PX
    assert kinds["fov_deg"] is camera.FOV_DEG and kinds["pitch_deg"] is camera.PITCH_DEG
    output = cfg.section_kinds(cfg.OutputSection)
    assert output["max_width"] is camera.VIEWPORT_PX
    set_camera = control._camera_table((1920, 1080)).fields
    assert set_camera["width"].kind == camera.VIEWPORT_PX.clamp_hi(1920)
    assert set_camera["fov_deg"].kind is camera.FOV_DEG


def test_the_weather_limits_have_one_owner() -> None:
    preset = PRESET_TABLE.fields
    assert preset["visibility_m"].kind is state.VISIBILITY_M
    assert preset["qnh_hpa"].kind is state.QNH_HPA
    assert preset["temperature_c"].kind is preset["dewpoint_c"].kind is state.TEMPERATURE_C
    layers = preset["layers"].kind
    assert isinstance(layers, Tables)
    assert layers.item.fields["base_m"].kind is state.LAYER_HEIGHT_M
    assert layers.max_items == state.MAX_LAYERS
    assert cockpit.RANGES[cockpit.QNH] is state.QNH_HPA
    assert cockpit.RANGES[cockpit.WIND_SPEED] is state.WIND_SPEED_MPS
    models = MODEL_TABLE.fields["min_thickness_m"].kind
    assert isinstance(models, Number) and models.hi == state.LAYER_THICKNESS_M.hi


@pytest.mark.parametrize("kind_name", ["VISIBILITY_M", "QNH_HPA", "TEMPERATURE_C", "SEED"])
def test_a_value_past_a_weather_limit_fails_everywhere_it_can_enter(kind_name: str) -> None:
    kind = getattr(state, kind_name)
    field = {"VISIBILITY_M": "visibility_m", "QNH_HPA": "qnh_hpa",
             "TEMPERATURE_C": "temperature_c", "SEED": "seed"}[kind_name]  # fmt: skip
    past = kind.hi + 1
    with pytest.raises(Invalid, match=f"^{field}: must be"):
        PRESET_TABLE.values({"description": "d", field: past})
    with pytest.raises(ValueError, match=field):
        state.WeatherState(**{field: past})


def test_the_config_drift_is_gone(tmp_path: Path) -> None:
    # `[camera] width = 10000` used to pass the config check and fail inside Camera.
    path = tmp_path / "c.toml"
    path.write_text("[output]\nmax_width = 10000\n[camera]\nwidth = 10000\n", encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value).splitlines() == [
        f"{path}:2: output.max_width: must be an integer in 16..8192, got 10000",
        f"{path}:4: camera.width: must be an integer in 16..8192, got 10000",
    ]
    assert "camera" in CONFIG_TABLE.fields and "serial" in CONFIG_TABLE.fields


def test_tuples_check_each_position_and_nullable_takes_null() -> None:
    position = Tuple((Number(-10, 10), Number(-10, 10), Number(0, 5)), "[east_m, north_m, alt_m]")
    maybe = Nullable(position)
    assert maybe.validate("position_m", None) is None
    assert maybe.validate("position_m", [1, 2, 3]) == (1.0, 2.0, 3.0)
    with pytest.raises(ValueError, match=r"^position_m\[2\]: must be a number in 0\.\.5, got 9$"):
        maybe.validate("position_m", [1, 2, 9])
    with pytest.raises(ValueError, match=r"must be \[east_m, north_m, alt_m\] or null, got 'x'"):
        maybe.validate("position_m", "x")
    with pytest.raises(ValueError, match=r"must be \[east_m, north_m, alt_m\], got \[1, 2\]"):
        maybe.validate("position_m", [1, 2])


def _prefixes(text: str, step: int) -> list[str]:
    """The file cut every `step` characters through its settings, and at the start and the
    middle of each comment line: a cut anywhere in a comment reads as one at its start, and
    the shipped config is nine parts comment (2,690 cuts every 7 characters; these are
    1,271, every 3 through the settings)."""
    cuts = {len(text)}
    start = 0
    for line in text.splitlines(keepends=True):
        if line.lstrip().startswith("#"):
            cuts.update((start, start + len(line) // 2))
        else:
            cuts.update(range(start, start + len(line), step))
        start += len(line)
    return [text[:n] for n in sorted(cuts)]


@pytest.mark.parametrize("which", ["config", "preset", "cloud model"])
def test_every_truncation_of_a_shipped_file_is_an_error_or_a_value(
    tmp_path: Path, which: str
) -> None:
    root = Path(__file__).resolve().parents[1]
    source, load = {
        "config": (root / "configs" / "wxsky.toml", load_config),
        "preset": (root / "wxsky" / "settings" / "presets" / "thunderstorm.toml", None),
        "cloud model": (root / "wxsky" / "scene" / "clouds" / "cumulonimbus.toml", None),
    }[which]
    text = source.read_text(encoding="utf-8")
    rng = random.Random(5)
    samples = _prefixes(text, 3)
    # Out-of-range and mistyped values in place of each number of the file.
    for _ in range(60):
        numbers = list(re.finditer(r"(?<== )-?[0-9][0-9_.]*", text))
        m = rng.choice(numbers)
        bad = rng.choice(["-1e9", "1e9", "nan", "true", '"x"', "[]", "{}"])
        samples.append(text[: m.start()] + bad + text[m.end() :])
    path = tmp_path / source.name
    for sample in samples:
        path.write_text(sample, encoding="utf-8")
        if which == "config":
            assert load is not None
            try:
                load(path)
            except ConfigError as exc:
                assert all(line.startswith(f"{path}:") for line in str(exc).splitlines())
        elif which == "preset":
            check = check_preset_file(path)
            assert (check.patch is None) == bool(check.problems)
            assert all(line.startswith(f"{path}:") for line in check.lines())
        else:
            try:
                load_cloud_model(path)
            except ConfigError as exc:
                assert all(line.startswith(f"{path}:") for line in str(exc).splitlines())
