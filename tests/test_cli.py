"""The `wxsky` command line as a user runs it: separate processes, real files."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pytest

from wxsky.cli.common import parse_size
from wxsky.png import read_png


def wxsky(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run(
        [sys.executable, "-m", "wxsky", *args], capture_output=True, text=True, timeout=120
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"wxsky {' '.join(args)} -> {proc.returncode}\n{proc.stderr}")
    return proc


def assert_one_line_error(proc: subprocess.CompletedProcess[str], *needles: str) -> None:
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


def test_preset_list_names_every_shipped_preset() -> None:
    out = wxsky("preset", "list").stdout
    names = {line.split()[0] for line in out.splitlines()}
    assert {
        "clear",
        "fair-cumulus",
        "scattered-cumulus",
        "broken-stratocumulus",
        "overcast-stratus",
        "thunderstorm",
        "high-cirrus",
    } <= names


def test_preset_show_prints_the_weather_it_makes() -> None:
    out = wxsky("preset", "show", "thunderstorm").stdout
    body = json.loads(out[out.index("{") :])
    assert any(lay["type"] == "cumulonimbus" for lay in body["layers"])


def test_metar_decode_json() -> None:
    out = wxsky(
        "metar",
        "decode",
        "KJFK 211651Z 31015G25KT 1 1/2SM -RA BR BKN008 OVC015 12/11 A2992",
        "--json",
    ).stdout
    d = json.loads(out)
    assert d["station"] == "KJFK"
    assert d["visibility_m"] == pytest.approx(1.5 * 1609.344)
    assert d["altimeter_hpa"] == pytest.approx(29.92 * 33.8639, abs=0.05)


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (("snapshot", "--preset", "no-such", "--out", "x.png"), ("no-such",)),
        (("snapshot", "--preset", "clear", "--size", "big", "--out", "x.png"), ("--size", "big")),
        (("snapshot", "--preset", "clear", "--size", "10x99999", "--out", "x.png"), ("--size",)),
        (("metar", "decode", ""), ("METAR",)),
        (("metar", "decode", "!!!! ???"), ("METAR",)),
        (("preset", "show", "../etc"), ("preset",)),
        (("snapshot", "--preset", "clear", "--time", "noon", "--out", "x.png"), ("noon",)),
        (
            ("snapshot", "--preset", "clear", "--elapsed-s", "60", "--out", "x.png"),
            ("--elapsed-s",),
        ),
        (
            ("snapshot", "--preset", "clear", "--transition-to", "no-such", "--out", "x.png"),
            ("no-such",),
        ),
        (
            (
                "snapshot",
                "--preset",
                "clear",
                "--transition-to",
                "fair-cumulus",
                "--elapsed-s",
                "-5",
                "--out",
                "x.png",
            ),
            ("--elapsed-s", "-5"),
        ),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    args: tuple[str, ...], needles: tuple[str, ...], tmp_path: Path
) -> None:
    assert_one_line_error(wxsky(*args, check=False), *needles)


def test_config_with_unknown_key_is_named(tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[camera]\nfovv = 3\n")
    proc = wxsky("run", "--config", str(cfg), check=False)
    assert_one_line_error(proc, "camera.fovv", str(cfg))


def test_parse_size() -> None:
    assert parse_size("960x540") == (960, 540)
    assert parse_size(" 32X16 ") == (32, 16)
    for bad in ("", "x", "960", "960x", "-5x5", "1e3x5", "8x8", "99999x10"):
        with pytest.raises(ValueError):
            parse_size(bad)


SKY_30_UP = (
    "--pitch-deg",
    "30",
    "--heading-deg",
    "180",
    "--time",
    "2026-07-08T12:00:00Z",
    "--size",
    "480x270",
)


def _cloud_fraction(tmp_path: Path, preset: str) -> float:
    """The share of the picture where the clouds visibly change the preset's own sky (its
    sky layer: the physical sky differs from one preset's weather to another's, so another
    preset's clear sky is no reference)."""
    cloudy = tmp_path / f"{preset}.png"
    wxsky(
        "snapshot",
        "--preset",
        preset,
        *SKY_30_UP,
        "--out",
        str(cloudy),
        "--layers-out",
        str(tmp_path / preset),
    )
    a = read_png(tmp_path / preset / "sky.png").astype(int)[..., :3]
    b = read_png(cloudy).astype(int)[..., :3]
    # A visible difference, not the faint haze at a cloud's edge.
    return float((np.abs(a - b).max(axis=2) > 16).mean())


@pytest.mark.gl
def test_overcast_fills_the_sky_looking_up(tmp_path: Path) -> None:
    # Under a deck the sky layer itself is the deck's grey (what shows through any gap), so
    # the clouds are measured by their own layer: they, not just a greyer sky, cover it.
    _cloud_fraction(tmp_path, "overcast-stratus")
    near = read_png(tmp_path / "overcast-stratus" / "near.png")
    assert (near[..., 3] > 0).mean() >= 0.90


@pytest.mark.gl
def test_scattered_cumulus_leaves_blue_sky(tmp_path: Path) -> None:
    fraction = _cloud_fraction(tmp_path, "scattered-cumulus")
    assert 0.10 <= fraction <= 0.70, fraction


@pytest.mark.gl
@pytest.mark.parametrize("time", [None, "2026-07-08T12:30:00Z"], ids=["preset-time", "drifted"])
def test_snapshot_layers_are_pixel_identical_across_processes(
    tmp_path: Path, time: str | None
) -> None:
    runs = []
    for n in range(2):
        out = tmp_path / f"run{n}"
        out.mkdir()  # --out goes into a directory that exists
        wxsky(
            "snapshot",
            *(("--time", time) if time else ()),
            "--preset",
            "broken-stratocumulus",
            "--size",
            "320x180",
            "--heading-deg",
            "45",
            "--seed",
            "99",
            "--out",
            str(out / "sky.png"),
            "--layers-out",
            str(out / "layers"),
        )
        runs.append(out / "layers")
    names = sorted(p.name for p in runs[0].iterdir())
    assert names == sorted(
        ["sky.png", "near.png", *(f"ring_{i}.png" for i in range(8)), "shadow.png"]
    )
    for name in names:
        # Pixels, not file bytes: the PNG's compressed stream depends on the zlib build.
        np.testing.assert_array_equal(read_png(runs[0] / name), read_png(runs[1] / name), name)
    # And the layers hold something: clouds in the near layer and in several impostors.
    assert read_png(runs[0] / "near.png")[..., 3].max() > 0
    assert sum(read_png(runs[0] / f"ring_{i}.png")[..., 3].max() > 0 for i in range(8)) >= 4


@pytest.mark.gl
def test_a_later_time_shows_the_clouds_blown_on(tmp_path: Path) -> None:
    preset_time = tomllib.loads(
        (
            Path(__file__).resolve().parents[1] / "wxsky/settings/presets/fair-cumulus.toml"
        ).read_text()
    )["time_utc"]
    base = datetime.fromisoformat(preset_time.replace("Z", "+00:00"))
    later = (base + timedelta(seconds=0.5)).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    much_later = (base + timedelta(minutes=10)).strftime("%Y-%m-%dT%H:%M:%SZ")
    near = {}
    for name, when in (("at", None), ("later", later), ("much", much_later)):
        out = tmp_path / name
        out.mkdir()
        wxsky(
            "snapshot",
            "--preset",
            "fair-cumulus",
            "--size",
            "320x180",
            *(("--time", when) if when else ()),
            "--out",
            str(out / "sky.png"),
            "--layers-out",
            str(out / "layers"),
        )
        near[name] = read_png(out / "layers" / "near.png")[..., 3].astype(int)
    moved = np.abs(near["much"] - near["at"]).mean()
    assert moved > 5.0 * max(np.abs(near["later"] - near["at"]).mean(), 0.01)
