"""A real daemon reading real GFS data (issue 45): the column at its site in `status` and the
stream, each cloud layer drifting with the wind at its own height, the model's clouds where no
METAR speaks, and a broken file that costs nothing but its own error."""

from __future__ import annotations

import gzip
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import HANG_S, RunningDaemon, running_daemon, wait_status
from grib_fixture import GFS, VALID, needs_gfs

from wxsky.inputs.grib_decode import Window, decode
from wxsky.weather.model_clouds import model_layers
from wxsky.weather.model_fields import merge_steps
from wxsky.weather.model_profile import profile_at

pytestmark = pytest.mark.gl


CONFIG = """
[camera]
width = 160
height = 90
[scene]
ring_texture_px = 64
[grib]
update_s = 0.2
poll_interval_s = 0.5
[transition]
step_s = 0.2
"""


_wait = wait_status


def _air(daemon: RunningDaemon, wanted: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
    """The `air` of the first frame for which `wanted` holds (the cloud lookup behind it runs
    on a thread, five times a second: a frame may carry the answer of a moment before the
    model's temperatures came); the last one seen in the failure."""
    deadline = time.monotonic() + HANG_S
    seen: dict[str, Any] = {}
    with daemon.client() as c:
        c.subscribe(["frame"])
        while time.monotonic() < deadline:
            note = c.next_notification(timeout_s=HANG_S)
            assert note is not None
            if note.method != "frame":
                continue
            seen = note.params["air"]
            if seen["temperature_c"] is not None and wanted(seen):
                return seen
    raise AssertionError(f"no frame with the air wanted; the last: {seen}")


def _grib_input(status: dict[str, Any], name: str) -> dict[str, Any]:
    return next(i for i in status["inputs"] if i["name"] == f"grib:{name}")


@needs_gfs
def test_the_daemon_takes_the_weather_aloft_from_the_model(tmp_path: Path) -> None:
    steps = tmp_path / "steps"
    steps.mkdir()
    shutil.copy(GFS, steps / "gfs-a")
    broken = tmp_path / "broken.grib2"
    broken.write_bytes(GFS.read_bytes()[:1_000_000])
    with running_daemon(
        tmp_path,
        CONFIG,
        # the file's one step is 2011-01-15 12Z: the clock goes there
        args=(
            *("--grib", str(steps), "--grib", str(broken), "--preset", "clear"),
            *("--replay", "2011-01-15T11:00:00Z"),
        ),
    ) as daemon:
        with daemon.client() as watcher:
            watcher.subscribe(["aloft"])
            status = _wait(
                daemon,
                lambda s: (
                    s["grib"]["profile"] is not None and s["target"]["sources"]["wind"] == "grib"
                ),
                "the model's column",
            )
            note = watcher.next_notification(timeout_s=HANG_S)
            assert note is not None and note.method == "aloft"
        profile = status["grib"]["profile"]
        levels = profile["levels"]
        assert len(levels) >= 15  # Zurich stands at 950 hPa: 1000 and 975 are underground
        heights = [lev["height_m"] for lev in levels]
        assert heights == sorted(heights)
        for lev in levels:
            assert {"pressure_hpa", "height_m", "speed_mps", "dir_deg", "t_c"} <= set(lev)
        assert profile["freezing_level_m"] is not None and profile["tropopause_m"] is not None
        assert note.params["levels"][0]["height_m"] == pytest.approx(heights[0])
        # the target's wind is the model's, level by level
        target_wind = status["target"]["wind"]
        assert len(target_wind) == len(levels)
        for w, lev in zip(target_wind, levels, strict=True):
            assert w["alt_m"] == pytest.approx(lev["height_m"], abs=0.2)
            assert w["speed_mps"] == pytest.approx(min(lev["speed_mps"], 150.0), abs=0.05)
        # the good directory decoded; the cut file said why, once, and is left out
        good = _grib_input(status, str(steps))
        assert good["ok"] and good["decoded"] == 1
        # the cut file: what came before the cut is used, the cut said in one line
        bad = _grib_input(status, str(broken))
        assert bad["errors"] >= 1 and str(broken) in bad["last_error"]
        assert "left out" in bad["last_error"] and "\n" not in bad["last_error"]
        assert status["grib"]["steps_utc"] == ["2011-01-15T12:00:00Z"]
        # frames kept coming through it all, each with the air at the aircraft (here the
        # camera) for a flight model: the model's temperature at its height
        first = status["frames_published"]
        _wait(daemon, lambda s: s["frames_published"] > first + 5, "more frames")

        def model_c(alt: float) -> float:
            """The model's temperature at a height, from status's column."""
            if alt < levels[0]["height_m"]:  # under the model's smoothed ground: lapse rate
                return float(levels[0]["t_c"] + 0.0065 * (levels[0]["height_m"] - alt))
            below = max((v for v in levels if v["height_m"] <= alt), key=lambda v: v["height_m"])
            above = min((v for v in levels if v["height_m"] > alt), key=lambda v: v["height_m"])
            f = (alt - below["height_m"]) / (above["height_m"] - below["height_m"])
            return float(below["t_c"] + f * (above["t_c"] - below["t_c"]))

        air = _air(daemon, lambda a: abs(a["temperature_c"] - model_c(a["at_m"][2])) <= 0.05)
        assert len(air["gust_mps"]) == 3 and air["turbulence"]["sigma_w_mps"] > 0.0
        assert air["icing"] is False or air["in_cloud"] is True
        # the model's clouds, where no METAR speaks, are the target's: those the same column
        # makes here
        fields = decode(GFS.read_bytes(), "gfs", Window(profile["lat_deg"], profile["lon_deg"]))
        column = profile_at(
            merge_steps(fields, ("gfs",)), profile["lat_deg"], profile["lon_deg"], VALID
        )
        assert column is not None
        want = [(lay.type.wire_name, lay.cover_oktas, lay.base_m) for lay in model_layers(column)]
        assert want, "the fixture has cloud over the preset's site"
        got = [
            (lay["type"], lay["cover_oktas"], lay["base_m"]) for lay in status["target"]["layers"]
        ]
        assert [g[0] for g in got] == [w[0] for w in want]
        for g, w in zip(got, want, strict=True):
            assert g[1:] == pytest.approx(w[1:], abs=0.01)
        assert status["target"]["sources"]["layers"] == "grib"
        # each layer drifts with the wind at its own height: the stratocumulus's and the
        # cirrus's differ (status says both)
        winds = _wait(
            daemon,
            lambda s: len(s["grib"]["layer_winds"]) == len(want),
            "the model's layers applied",
        )["grib"]["layer_winds"]
        low, high = winds[0], winds[-1]
        assert abs(high["wind_speed_mps"] - low["wind_speed_mps"]) > 5.0

        # a clock far from the forecast: the model is no weather for it, and status says so
        with daemon.client() as c:
            c.call("set_time", {"time_utc": "2011-01-20T12:00:00Z"})
        far = _wait(daemon, lambda s: s["grib"]["profile"] is None, "the model let go")
        assert "more than 6 h from the clock" in far["grib"]["reason"]
        assert far["target"]["sources"]["wind"] != "grib"


# NOAA's cycle file, as tests/data keeps it (gzip; the shared original where present)
CYCLE = GFS.parents[1] / "metar" / "noaa_cycle_2025-07-26_okay_weather_HEAD1500.txt.gz"


@pytest.mark.skipif(not CYCLE.exists(), reason=f"the METAR archive is absent: {CYCLE}")
def test_a_past_day_replays_each_stations_reports_in_their_order(tmp_path: Path) -> None:
    """NOAA's cycle file split in two, as an archive directory; KVCT reported BKN120 at
    15:46Z and BKN033 at 15:51Z. Replayed from 15:48Z at a minute a second, the first
    stands, then the second: never the later report before its time."""
    archive = tmp_path / "archive"
    archive.mkdir()
    records = gzip.decompress(CYCLE.read_bytes()).decode().split("\n\n")
    half = len(records) // 2
    (archive / "15Z.TXT").write_text("\n\n".join(records[:half]) + "\n")
    (archive / "16Z.TXT").write_text("\n\n".join(records[half:]))
    config = CONFIG + '[clock]\nrate = 60.0\n[metar]\nstation = "KVCT"\npoll_interval_s = 0.2\n'
    with running_daemon(
        tmp_path,
        config,
        args=(
            "--replay",
            "2025-07-26T15:48:00Z",
            "--metar-feed",
            str(archive),
            "--preset",
            "clear",
        ),
    ) as daemon:

        def bases(s: dict[str, Any]) -> list[float]:
            return [
                round(lay["base_m"] - s["target"]["observer"]["alt_m"])
                for lay in s["target"]["layers"]
            ]

        first = _wait(daemon, lambda s: s["target"]["sources"]["layers"] == "metar", "the replay")
        assert first["weather"]["time_utc"] < "2025-07-26T15:51"
        metar = next(i for i in first["inputs"] if i["kind"] == "metar")
        assert metar["using"][0]["station"] == "KVCT" and metar["replay_reports"] > 500
        assert max(bases(first)) > 3000  # BKN120, 15:46Z
        later = _wait(daemon, lambda s: max(bases(s), default=0) < 3000, "the 15:51Z report")
        assert later["weather"]["time_utc"] >= "2025-07-26T15:51"


@needs_gfs
def test_a_snapshot_lays_its_metar_over_the_model(tmp_path: Path) -> None:
    """`wxsky snapshot --metar ... --grib FILE`: the METAR's layer below, the model's
    cirrus above what the station reports (docs/gallery/weather-aloft.png)."""
    import subprocess
    import sys

    out = tmp_path / "sky.png"
    metar = "LSZH 151150Z 24008KT 9999 FEW045 07/02 Q1020"
    proc = subprocess.run(
        [
            *(sys.executable, "-m", "wxsky", "snapshot", "--metar", metar),
            *("--grib", str(GFS), "--time", "2011-01-15T12:00:00Z", "--size", "64x36"),
            *("--out", str(out)),
        ],
        capture_output=True,
        text=True,
        timeout=HANG_S,
    )
    assert proc.returncode == 0, proc.stderr
    clouds = proc.stdout.split("clouds ", 1)[1].split()
    assert clouds[0].startswith("cumulus:2/8@") and clouds[1].startswith("cirrus:")
    assert out.stat().st_size > 0


@needs_gfs
def test_a_metar_at_the_site_lies_over_the_model(tmp_path: Path) -> None:
    """Replaying Zurich at 2011-01-15 11:55Z with its 11:50Z report and the GFS step: the
    station is at the site and the report 5 minutes old, so the METAR's weight is 1: its
    wind at the surface and its layer below, the model's cirrus above what it reports."""
    feed = tmp_path / "metar.txt"
    feed.write_text("LSZH 151150Z 24008KT 9999 FEW045 07/02 Q1020\n")
    config = CONFIG + '[metar]\npoll_interval_s = 0.2\nstation = "LSZH"\n'
    with running_daemon(
        tmp_path,
        config,
        args=(
            *("--grib", str(GFS), "--metar-feed", str(feed), "--preset", "clear"),
            *("--replay", "2011-01-15T11:55:00Z"),
        ),
    ) as daemon:
        status = _wait(
            daemon,
            lambda s: (
                s["grib"]["metar_weight"] is not None
                and s["target"]["sources"]["layers"] == "metar"
            ),
            "the METAR over the model",
        )
        assert status["grib"]["metar_weight"] == pytest.approx(1.0)
        layers = status["target"]["layers"]
        assert [lay["type"] for lay in layers] == ["cumulus", "cirrus"]
        assert layers[0]["cover_oktas"] == pytest.approx(2.0)  # FEW: the report's
        wind = status["target"]["wind"]
        assert wind[0]["dir_deg"] == pytest.approx(240.0, abs=0.5)  # 24008KT
        assert wind[0]["speed_mps"] == pytest.approx(8 * 0.514444, abs=0.05)
        assert len(wind) > 10 and wind[-1]["speed_mps"] > 15.0  # the model's aloft
