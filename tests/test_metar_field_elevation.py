"""One report, the same clouds, whichever way it comes in: a feed, `wxsky run --metar`,
`wxsky snapshot --metar`, `wxsky preset save --from-metar` and the control channel's
`apply_metar` all read it over its station's field from the station table (or over the field
elevation given). And an archived feed is dated by its own observation times, so that one
station's wrong day group does not make every other station stale."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import uuid
from datetime import UTC, datetime
from pathlib import Path

import pytest
from daemon_harness import write_config

from wxsky.app.control import apply_metar
from wxsky.app.daemon import initial_patches
from wxsky.cli import build_parser, main
from wxsky.cli.daemon_cmd import _weather_patch
from wxsky.engine.stages import SkyEngine
from wxsky.errors import MetarError
from wxsky.inputs.metar_input import MetarSettings, ingest, select
from wxsky.inputs.station_table import station_table
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.settings.config import load_config
from wxsky.settings.presets import load_preset_file
from wxsky.units import FT_TO_M
from wxsky.weather.feeds import parse_feed, read_feed
from wxsky.weather.metar import decode
from wxsky.weather.state import CloudLayer, Observer, WeatherState

DATA = Path(__file__).parent / "data" / "metar"
# A byte-for-byte copy of shared/data/metar/awc_cache_2020-05-02_luasamples.csv (same SHA-256,
# fcf3c7fc...), gzipped: AWC's cache of 1 May 23:26 to 2 May 00:40 UTC, 4,678 rows.
AWC_2020 = DATA / "awc_cache_2020-05-02_luasamples.csv.gz"
# LSZH's row in that file, whose elevation_m column says 432 m; the station table (built from
# the newest corpus, 2022) says 424 m.
LSZH_2020 = "LSZH 012350Z 22004KT 9999 FEW020 BKN075 10/08 Q1009 RESHRA NOSIG"
LSZH_M = 424.0
UNKNOWN = "ZZZZ 211250Z 24012KT 9999 FEW045 18/09 Q1012"


@pytest.fixture(autouse=True)
def user_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A private user folder: `preset save` writes there, not to ~/.config."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    return tmp_path / "config" / "wxsky" / "presets"


def lowest_base_m(layers: tuple[CloudLayer, ...] | None) -> float:
    assert layers
    return min(lay.base_m for lay in layers)


def feed_base_m() -> float:
    """LSZH's FEW020 as the daemon's feed input reads the real 2020 AWC file."""
    stations = ingest(read_feed(AWC_2020)).stations
    assert stations["LSZH"].patch.layers is not None
    return lowest_base_m(stations["LSZH"].patch.layers)


def engine_at_sea_level() -> SkyEngine:
    """A daemon's engine whose site is far below LSZH: the observer's height is no stand-in
    for a report's field."""
    zurich = WeatherState().observer
    site = Observer(zurich.lat_deg, zurich.lon_deg, 0.0)
    return SkyEngine(WeatherState(observer=site), Camera((0.0, 0.0, 2.0)), SceneSettings())


def test_the_table_elevation_comes_before_the_feeds_own() -> None:
    from wxsky.inputs.station_table import field_elevation_m

    assert station_table()["LSZH"].elevation_m == LSZH_M
    assert field_elevation_m("LSZH", feed_m=432.0) == LSZH_M
    assert field_elevation_m("LSZH", 100.0, feed_m=432.0) == 100.0  # given wins
    assert field_elevation_m("ZZZZ", feed_m=1234.0) == 1234.0  # not in the table
    with pytest.raises(MetarError, match=r"ZZZZ: station not in .* give it with --x"):
        field_elevation_m("ZZZZ", flag="--x")


def test_every_path_reads_a_report_over_the_same_field(user_dir: Path) -> None:
    expected = 2000 * FT_TO_M + LSZH_M
    # A feed: the real AWC file, whose own column says 432 m.
    assert feed_base_m() == pytest.approx(expected)
    # wxsky run --metar: the default preset's site (432 m) is not the station's field.
    patches = initial_patches(load_config(None), metar=LSZH_2020)
    assert lowest_base_m(patches[-1].layers) == pytest.approx(expected)
    # apply_metar on a daemon's engine at another height.
    with engine_at_sea_level() as engine:
        assert apply_metar(engine, {"report": LSZH_2020}) == "LSZH"
        assert lowest_base_m(engine.target.layers) == pytest.approx(expected)
    # wxsky snapshot --metar (its weather; the picture is drawn by the gl test below).
    args = build_parser().parse_args(["snapshot", "--metar", LSZH_2020, "--out", "x.png"])
    patch = _weather_patch(args, ())
    assert lowest_base_m(patch.layers) == pytest.approx(expected)
    # ... whose camera stands on that field, so the clouds are as high above it as reported.
    assert patch.observer is not None and patch.observer.alt_m == LSZH_M
    # wxsky preset save --from-metar.
    assert main(["preset", "save", "lszh", "--from-metar", LSZH_2020]) == 0
    _, saved = load_preset_file(user_dir / "lszh.toml")
    assert lowest_base_m(saved.layers) == pytest.approx(expected)


def test_an_explicit_field_elevation_is_used_on_every_path(
    user_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    expected = 4500 * FT_TO_M + 1500.0
    patches = initial_patches(load_config(None), metar=UNKNOWN, field_elevation_m=1500.0)
    assert lowest_base_m(patches[-1].layers) == pytest.approx(expected)
    with engine_at_sea_level() as engine:
        apply_metar(engine, {"report": UNKNOWN, "field_elevation_m": 1500.0})
        assert lowest_base_m(engine.target.layers) == pytest.approx(expected)
    argv = ["snapshot", "--metar", UNKNOWN, "--field-elevation-m", "1500", "--out", "x.png"]
    patch = _weather_patch(build_parser().parse_args(argv), ())
    assert lowest_base_m(patch.layers) == pytest.approx(expected)
    argv = ["preset", "save", "zzzz", "--from-metar", UNKNOWN, "--field-elevation-m", "1500"]
    assert main(argv) == 0
    _, saved = load_preset_file(user_dir / "zzzz.toml")
    assert lowest_base_m(saved.layers) == pytest.approx(expected)
    capsys.readouterr()


def test_a_station_the_table_lacks_needs_a_field_elevation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Where no figure is known, no path guesses one: each says how to give it."""
    with pytest.raises(MetarError, match="give it with --field-elevation-m"):
        initial_patches(load_config(None), metar=UNKNOWN)
    with engine_at_sea_level() as engine, pytest.raises(MetarError, match="field_elevation_m"):
        apply_metar(engine, {"report": UNKNOWN})
    assert main(["preset", "save", "zzzz", "--from-metar", UNKNOWN]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "ZZZZ" in err and "--field-elevation-m" in err, err
    # The daemon refuses to start on it, as a usage error, before it opens anything.
    config = write_config(tmp_path / "wxsky.toml", f"wxsky-test-{uuid.uuid4().hex[:10]}")
    command = ["run", "--config", str(config), "--control", f"unix:{tmp_path / 'wx.sock'}"]
    run = subprocess.run(
        [sys.executable, "-m", "wxsky", *command, "--metar", UNKNOWN],
        capture_output=True,
        text=True,
        timeout=120,  # a hang: the daemon started after all
    )
    err = run.stderr.strip()
    assert run.returncode == 2 and err.count("\n") == 0, err
    assert "ZZZZ" in err and "--field-elevation-m" in err
    # The flag goes with a report only.
    assert main(["preset", "save", "x", "--from-running", "--field-elevation-m", "10"]) == 2
    assert "goes with --from-metar" in capsys.readouterr().err


def test_report_patch_is_what_metar_clouds_makes_over_the_field() -> None:
    from wxsky.inputs.station_table import report_patch

    metar = decode("LSZH 211250Z 24012G25KT 9999 FEW030 BKN080 18/09 Q1012", year=2026, month=6)
    patch = report_patch(metar)
    assert patch.layers is not None
    few, bkn = patch.layers
    assert few.base_m == pytest.approx(3000 * FT_TO_M + LSZH_M)
    assert bkn.base_m - few.base_m == pytest.approx(5000 * FT_TO_M)
    assert patch.qnh_hpa == pytest.approx(1012.0)
    assert patch.wind is not None and patch.wind[0].alt_m == pytest.approx(LSZH_M + 10.0)


@pytest.mark.gl
def test_snapshot_draws_the_report_over_its_station(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "lszh.png"
    argv = ["snapshot", "--metar", LSZH_2020, "--size", "64x36", "--out", str(out)]
    assert main(argv) == 0
    summary = capsys.readouterr().out
    # The summary names each layer's base in whole metres: FEW020 over 424 m.
    bases = [float(m) for m in re.findall(r"@(\d+)m", summary)]
    assert bases and min(bases) == round(2000 * FT_TO_M + LSZH_M), summary
    assert out.stat().st_size > 0


# --- an archived feed dated by its own observation times ----------------------------------------


def test_a_misdated_report_is_dated_by_the_feeds_observation_time() -> None:
    """PTSA's `022350Z` in a file of 1 May 23:26 - 2 May 00:40: AWC's observation_time says
    1 May 23:50. Dated by its day group it was the feed's newest report by a day, and against
    it every other station (4,644 of 4,645) was stale."""
    result = ingest(read_feed(AWC_2020))
    ptsa = result.stations["PTSA"]
    assert ptsa.observed_utc == datetime(2020, 5, 1, 23, 50, tzinfo=UTC)
    assert any(
        "PTSA: time group 022350Z says 2020-05-02T23:50Z" in p and p.endswith("dated by the feed")
        for p in result.problems
    )
    newest = max(s.observed_utc for s in result.stations.values() if s.observed_utc)
    assert newest == datetime(2020, 5, 2, 0, 40, tzinfo=UTC)
    choice = select(result.stations, 47.46, 8.55, MetarSettings(age_reference="feed"))
    assert choice.stale_count == 0 and choice.fresh == len(result.stations) > 4000
    assert choice.used[0][0] == "LSZH" and choice.patch is not None


AWC_XML = """<?xml version="1.0" encoding="UTF-8"?>
<response><data num_results="2">
<METAR><raw_text>{lszh}</raw_text><station_id>LSZH</station_id>
<observation_time>{lszh_time}</observation_time><latitude>47.48</latitude>
<longitude>8.53</longitude><elevation_m>432.0</elevation_m></METAR>
<METAR><raw_text>{zzzz}</raw_text><station_id>ZZZZ</station_id>
<observation_time>2025-07-26T15:50:00Z</observation_time><latitude>10.0</latitude>
<longitude>10.0</longitude><elevation_m>1234.0</elevation_m></METAR>
</data></response>
"""


@pytest.mark.parametrize(
    ("lszh_time", "observed"),
    [
        # Minutes apart: the report's own time stands.
        ("2025-07-26T15:45:00Z", datetime(2025, 7, 26, 15, 50, tzinfo=UTC)),
        # A day apart: the feed's.
        ("2025-07-25T15:50:00Z", datetime(2025, 7, 25, 15, 50, tzinfo=UTC)),
    ],
)
def test_awc_xml_times_and_elevations(lszh_time: str, observed: datetime) -> None:
    text = AWC_XML.format(
        lszh="LSZH 261550Z 24008KT 9999 FEW045 18/09 Q1016",
        zzzz="ZZZZ 261550Z 24008KT 9999 FEW045 18/09 Q1016",
        lszh_time=lszh_time,
    )
    result = ingest(parse_feed(text, format="awc-xml"))
    lszh, zzzz = result.stations["LSZH"], result.stations["ZZZZ"]
    assert lszh.observed_utc == observed
    # The table's 424 m for LSZH, not the row's 432 m; the row's own figure for a station
    # the table lacks.
    assert lszh.elevation_m == LSZH_M and zzzz.elevation_m == 1234.0
    assert lowest_base_m(lszh.patch.layers) == pytest.approx(4500 * FT_TO_M + LSZH_M)
    assert lowest_base_m(zzzz.patch.layers) == pytest.approx(4500 * FT_TO_M + 1234.0)


def test_fetch_of_an_archive_says_how_to_see_it_as_of_its_own_time(
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = ["metar", "fetch", str(AWC_2020), "--lat", "47.46", "--lon", "8.55"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert ": 0 fresh and 4645 stale stations" in out
    note = next(line for line in out.splitlines() if line.startswith("note: "))
    assert "2020-05-02 00:40Z" in note and "--age-reference feed" in note
    assert main([*args, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert "--age-reference feed" in summary["hint"]
    # As the hint says: the archive as of its own time, every station fresh.
    assert main([*args, "--json", "--age-reference", "feed"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["hint"] is None
    assert (summary["fresh"], summary["stale"]) == (4645, 0)
    assert summary["using"][0]["station"] == "LSZH"
