"""`wxsky preset ...` as a user runs it: list, show, save, validate, diff against real files in a
private user folder, and apply / save --from-running / release against a real daemon."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import running_daemon

from wxsky.cli import main
from wxsky.host.client import ControlClient
from wxsky.inputs.station_table import report_patch
from wxsky.settings.presets import (
    load_preset,
    load_preset_file,
    patch_from_weather_dict,
)
from wxsky.weather.metar import decode
from wxsky.weather.state import Source

REPO = Path(__file__).resolve().parents[1]
SHIPPED_DIR = REPO / "wxsky" / "settings" / "presets"
METAR = "LSZH 211250Z 24012G25KT 9999 FEW030 BKN080 18/09 Q1012"
FT = 0.3048


@pytest.fixture(autouse=True)
def user_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A private user folder: the real ~/.config is never read or written (a daemon started by
    the test inherits it too)."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    return tmp_path / "config" / "wxsky" / "presets"


def wxsky(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    """Run the CLI in-process: (exit status, stdout, stderr)."""
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(capsys: pytest.CaptureFixture[str], *args: str, status: int = 2) -> str:
    """The one stderr line of a command that fails with `status` (2: the user's mistake, 1: a
    runtime failure)."""
    code, out, err = wxsky(capsys, *args)
    assert code == status, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wxsky: error: "), err
    return lines[0]


# -- list and show ------------------------------------------------------------------------------


def test_list_shows_origin_and_a_user_override(
    capsys: pytest.CaptureFixture[str], user_dir: Path
) -> None:
    user_dir.mkdir(parents=True)
    (user_dir / "clear.toml").write_text('description = "My own clear sky"\nlayers = []\n')
    (user_dir / "mine.toml").write_text('description = "Only mine"\nseed = 4\n')
    code, out, _ = wxsky(capsys, "preset", "list")
    assert code == 0
    rows = {line.split()[0]: line.split(None, 1)[1] for line in out.splitlines()}
    assert rows["clear"].split() == ["user", "(overrides", "builtin)", "My", "own", "clear", "sky"]
    assert rows["mine"].split() == ["user", "Only", "mine"]
    assert rows["thunderstorm"].startswith("builtin ")
    assert "Thunderstorm with heavy rain" in rows["thunderstorm"]
    assert set(rows) >= {p.stem for p in SHIPPED_DIR.glob("*.toml")}

    code, out, _ = wxsky(capsys, "preset", "show", "clear")
    assert code == 0
    assert out.startswith(f"# clear: My own clear sky\n# {user_dir / 'clear.toml'} (user)\n")
    assert json.loads(out[out.index("{") :])["layers"] == []


def test_list_searches_the_config_dirs_first(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    extra = tmp_path / "site"
    extra.mkdir()
    (extra / "clear.toml").write_text('description = "Site clear"\n')
    config = tmp_path / "wxsky.toml"
    config.write_text(f'[presets]\ndirs = ["{extra}"]\n')
    code, out, _ = wxsky(capsys, "preset", "list", "--config", str(config))
    assert code == 0
    [row] = [line for line in out.splitlines() if line.startswith("clear ")]
    assert row.split() == ["clear", str(extra), "(overrides", "builtin)", "Site", "clear"]


# -- save ---------------------------------------------------------------------------------------


def test_save_from_metar_writes_a_preset_with_the_reports_layers(
    capsys: pytest.CaptureFixture[str], user_dir: Path
) -> None:
    code, out, err = wxsky(capsys, "preset", "save", "lszh-now", "--from-metar", METAR)
    assert code == 0, err
    path = user_dir / "lszh-now.toml"
    assert out == f"saved preset 'lszh-now' to {path}\n"
    info, patch = load_preset_file(path)
    assert info.description == f"Saved from METAR {METAR}"
    # Exactly the decoder's weather, and that is the report's: FEW030 and BKN080, over
    # LSZH's field as a feed reads the report.
    expected = report_patch(decode(METAR, year=2000, month=1))
    assert patch == dataclasses.replace(expected, source=Source.PRESET)
    assert patch.layers is not None
    few, bkn = patch.layers
    assert few.cover_oktas < bkn.cover_oktas and bkn.cover_oktas >= 5
    assert bkn.base_m - few.base_m == pytest.approx(5000 * FT)
    assert patch.qnh_hpa == pytest.approx(1012.0)
    assert patch.temperature_c == 18.0 and patch.dewpoint_c == 9.0
    # Found by name afterwards, like any other preset.
    assert load_preset("lszh-now") == patch


def test_save_refuses_to_overwrite_without_force(
    capsys: pytest.CaptureFixture[str], user_dir: Path
) -> None:
    path = user_dir / "mine.toml"
    assert wxsky(capsys, "preset", "save", "mine", "--from-metar", METAR)[0] == 0
    first = path.read_text()
    other = "LSZH 211250Z 00000KT CAVOK 25/10 Q1020"
    error = one_line_error(capsys, "preset", "save", "mine", "--from-metar", other)
    assert error == f"wxsky: error: {path} already exists (use --force to replace it)"
    assert path.read_text() == first
    args = ("preset", "save", "mine", "--from-metar", other, "--force", "--description", "Hot")
    assert wxsky(capsys, *args)[0] == 0
    info, patch = load_preset_file(path)
    assert (info.description, patch.layers, patch.qnh_hpa) == ("Hot", (), 1020.0)


@pytest.mark.parametrize(("length", "saved"), [(64, True), (65, False), (300, False)])
def test_a_preset_name_is_at_most_64_characters(
    capsys: pytest.CaptureFixture[str], user_dir: Path, length: int, saved: bool
) -> None:
    # 300 characters used to reach the file system ("File name too long" from the write).
    name = "a" * length
    if saved:
        assert wxsky(capsys, "preset", "save", name, "--from-metar", METAR)[0] == 0
        assert (user_dir / f"{name}.toml").is_file()
        return
    error = one_line_error(capsys, "preset", "save", name, "--from-metar", METAR)
    assert "1 to 64 lowercase letters" in error and len(error) < 160, error
    assert not user_dir.exists() or not list(user_dir.iterdir())


def test_save_over_a_builtin_name_says_it_overrides(
    capsys: pytest.CaptureFixture[str], user_dir: Path
) -> None:
    code, out, _ = wxsky(capsys, "preset", "save", "clear", "--from-metar", METAR)
    assert code == 0
    assert (
        out == f"saved preset 'clear' to {user_dir / 'clear.toml'} (overrides the builtin preset)\n"
    )
    assert load_preset("clear").qnh_hpa == pytest.approx(1012.0)


def test_save_checks_name_and_source(capsys: pytest.CaptureFixture[str], user_dir: Path) -> None:
    assert "invalid preset name '../x'" in one_line_error(
        capsys, "preset", "save", "../x", "--from-metar", METAR
    )
    assert "METAR" in one_line_error(capsys, "preset", "save", "x", "--from-metar", "!!! ???")
    assert not user_dir.exists() or not any(user_dir.iterdir())
    # argparse's own errors are one line and a return value too, not a SystemExit.
    assert "one of the arguments --from-running --from-metar is required" in one_line_error(
        capsys, "preset", "save", "x"
    )
    assert "not allowed with argument" in one_line_error(
        capsys, "preset", "save", "x", "--from-running", "--from-metar", METAR
    )


# -- validate -----------------------------------------------------------------------------------

THREE_PROBLEMS = """\
description = "three problems"
seed = 5
visiblity_m = 1000.0
[[layers]]
type = "cumulus"
cover_oktas = 3
base_m = 1500.0
top_m = 2400.0
[[layers]]
type = "stratus"
cover_oktas = 12
base_m = 900.0
top_m = 1000.0
[[wind]]
alt_m = 440.0
dir_deg = "west"
speed_mps = 3.0
"""


def test_validate_reports_every_problem_with_line_and_key(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(THREE_PROBLEMS)
    good = SHIPPED_DIR / "thunderstorm.toml"
    code, out, err = wxsky(capsys, "preset", "validate", str(bad), str(good))
    assert code == 2 and err == ""
    assert out.splitlines() == [
        f"{bad}:3: visiblity_m: unknown key (did you mean 'visibility_m'?)",
        f"{bad}:11: layers[1].cover_oktas: must be an integer in 0..8, got 12",
        f"{bad}:16: wind[0].dir_deg: must be a number in 0..360, got 'west'",
        f"{good}: ok",
    ]


def test_validate_good_files_exit_0(capsys: pytest.CaptureFixture[str]) -> None:
    files = sorted(str(p) for p in SHIPPED_DIR.glob("*.toml"))
    code, out, _ = wxsky(capsys, "preset", "validate", *files)
    assert code == 0
    assert out.splitlines() == [f"{f}: ok" for f in files]


def test_validate_garbage_truncated_and_missing_files(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    garbage = tmp_path / "garbage.toml"
    garbage.write_bytes(b'description = "x"\n\x89PNG\r\n\x1a\n\x00\xff\xfe')
    text = (SHIPPED_DIR / "fair-cumulus.toml").read_text()
    truncated = tmp_path / "truncated.toml"
    cut = text[: text.index('type = "cumulus"') + 10]
    truncated.write_text(cut)
    missing = tmp_path / "missing.toml"
    code, out, _ = wxsky(capsys, "preset", "validate", str(garbage), str(truncated), str(missing))
    assert code == 2
    lines = out.splitlines()
    assert len(lines) == 3
    assert lines[0] == f"{garbage}:2: not UTF-8 text"
    last_line = cut.count("\n") + 1
    assert lines[1].startswith(f"{truncated}:{last_line}: invalid TOML: Unterminated string")
    assert lines[2] == f"{missing}: no such file"


# -- diff ---------------------------------------------------------------------------------------


def test_diff_between_two_builtins(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = wxsky(capsys, "preset", "diff", "fair-cumulus", "overcast-stratus")
    assert code == 1
    lines = out.splitlines()
    assert lines[0] == f"--- fair-cumulus ({SHIPPED_DIR / 'fair-cumulus.toml'})"
    assert lines[1] == f"+++ overcast-stratus ({SHIPPED_DIR / 'overcast-stratus.toml'})"
    for expected in (
        "time_utc: 2026-06-21T13:00:00Z -> 2026-11-18T11:00:00Z",
        "seed: 7 -> 23",
        "visibility_m: 30000.0 -> 4000.0",
        'present_weather: [] -> ["BR"]',
        "layers[0].type: cumulus -> stratus",
        "layers[0].cover_oktas: 3 -> 8",
        "layers[0].base_m: 1930.0 -> 830.0",
        "wind[0].dir_deg: 250.0 -> 60.0",
        "wind[0].speed_mps: 4.0 -> 3.0",
        "wind[1].alt_m: 1500.0 -> 1000.0",
    ):
        assert expected in lines
    assert not any(line.startswith("observer.") for line in lines), "same observer"
    assert not any(line.startswith("wind[0].alt_m") for line in lines), "same surface level"


def test_diff_shows_unset_fields_and_takes_paths(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    partial = tmp_path / "partial.toml"
    partial.write_text('description = "p"\nvisibility_m = 4000\n')
    code, out, _ = wxsky(capsys, "preset", "diff", str(partial), "thunderstorm")
    assert code == 1
    lines = out.splitlines()
    assert "visibility_m: 4000.0 -> 3000.0" in lines
    assert "layers[2].type: (unset) -> cumulonimbus" in lines
    assert "wind[0].gust_mps: (unset) -> 20.0" in lines

    code, out, _ = wxsky(capsys, "preset", "diff", "thunderstorm", str(partial), "--json")
    body = json.loads(out)
    assert body["a"] == str(SHIPPED_DIR / "thunderstorm.toml") and body["b"] == str(partial)
    diffs = {d["key"]: (d["a"], d["b"]) for d in body["differences"]}
    assert diffs["visibility_m"] == (3000.0, 4000.0)
    assert diffs["layers[2].cover_oktas"] == (6, None)


def test_diff_of_a_preset_with_itself(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = wxsky(capsys, "preset", "diff", "thunderstorm", "thunderstorm")
    assert (code, out) == (0, "no differences between thunderstorm and thunderstorm\n")
    code, out, _ = wxsky(
        capsys, "preset", "diff", "thunderstorm", str(SHIPPED_DIR / "thunderstorm.toml"), "--json"
    )
    assert code == 0 and json.loads(out)["differences"] == []


def test_diff_of_an_unknown_preset_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert "unknown preset 'nope'" in one_line_error(capsys, "preset", "diff", "nope", "clear")


# -- against a running daemon -------------------------------------------------------------------


# Weather changes at once, so the tests need not wait minutes for clouds to form.
INSTANT = "[transition]\n" + "".join(
    f"{key} = 0.0\n"
    for key in (
        "cover_oktas_per_min",
        "base_m_per_min",
        "wind_mps_per_s",
        "visibility_m_per_s",
        "temperature_c_per_min",
        "qnh_hpa_per_min",
    )
)


def layer_dicts(name: str) -> list[dict[str, Any]]:
    patch = load_preset(name)
    assert patch.layers is not None
    return [
        {
            "type": lay.type.wire_name,
            "cover_oktas": lay.cover_oktas,
            "base_m": lay.base_m,
            "top_m": lay.top_m,
        }
        for lay in sorted(patch.layers, key=lambda lay: lay.base_m)
    ]


def wait_for_layers(client: ControlClient, expected: list[dict[str, Any]]) -> dict[str, Any]:
    """The status weather once its layers are `expected` (the daemon may move there gradually)."""
    deadline = time.monotonic() + 30.0
    while True:
        weather: dict[str, Any] = client.call("status")["weather"]
        if weather["layers"] == expected:
            return weather
        if time.monotonic() > deadline:
            raise AssertionError(f"layers are {weather['layers']}, expected {expected}")
        time.sleep(0.1)


@pytest.mark.gl
def test_apply_and_save_from_running_against_a_real_daemon(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, user_dir: Path
) -> None:
    # A frozen clock, so that the weather the test reads is the weather `save` reads.
    config = "[clock]\nrate = 0.0\n" + INSTANT
    with running_daemon(tmp_path, extra_config=config) as d, d.client() as c:
        code, out, err = wxsky(
            capsys, "preset", "apply", "overcast-stratus", "--control", d.address
        )
        assert code == 0, err
        assert out.startswith(f"applied preset 'overcast-stratus' on the daemon at {d.address}")
        weather = wait_for_layers(c, layer_dicts("overcast-stratus"))
        assert weather["visibility_m"] == 4000.0
        assert weather["present_weather"] == ["BR"]

        code, out, err = wxsky(
            capsys, "preset", "save", "snap", "--from-running", "--control", d.address
        )
        assert code == 0, err
        path = user_dir / "snap.toml"
        assert out == f"saved preset 'snap' to {path}\n"
        info, saved = load_preset_file(path)
        assert info.description == f"Saved from the daemon at {d.address}"
        assert saved == patch_from_weather_dict(c.call("status")["weather"])
        assert saved.layers == load_preset("overcast-stratus").layers
        assert saved.wind == load_preset("overcast-stratus").wind

        # The daemon finds the saved user preset by name too (it shares the user folder).
        assert wxsky(capsys, "preset", "apply", "clear", "--control", d.address)[0] == 0
        wait_for_layers(c, [])
        assert wxsky(capsys, "preset", "apply", "snap", "--control", d.address)[0] == 0
        wait_for_layers(c, layer_dicts("overcast-stratus"))

        assert "no-such-sky" in one_line_error(
            capsys, "preset", "apply", "no-such-sky", "--control", d.address
        )


@pytest.mark.gl
def test_release_hands_the_fields_back(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    with running_daemon(tmp_path, extra_config=INSTANT) as d, d.client() as c:
        start_layers = c.call("status")["weather"]["layers"]
        assert wxsky(capsys, "preset", "apply", "thunderstorm", "--control", d.address)[0] == 0
        wait_for_layers(c, layer_dicts("thunderstorm"))
        code, out, err = wxsky(capsys, "preset", "release", "--control", d.address)
        if code != 0 and "unknown command 'release'" in err:
            pytest.skip("this daemon has no 'release' command yet (it is being added)")
        assert code == 0, err
        assert out.startswith("released ") and "layers" in out
        assert "back to METAR/config sources" in out
        wait_for_layers(c, start_layers)
        code, out, err = wxsky(capsys, "preset", "release", "--control", d.address)
        assert code == 0, err
        assert out.startswith("nothing to release")


def test_apply_without_a_daemon_is_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    # No daemon is a runtime failure, not the user's mistake: status 1.
    address = f"unix:{tmp_path / 'nobody.sock'}"
    assert "cannot connect" in one_line_error(
        capsys, "preset", "apply", "clear", "--control", address, status=1
    )
    assert "cannot connect" in one_line_error(
        capsys, "preset", "release", "--control", address, status=1
    )
    assert "cannot connect" in one_line_error(
        capsys, "preset", "save", "x", "--from-running", "--control", address, status=1
    )
