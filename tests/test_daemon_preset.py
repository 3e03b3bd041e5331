"""`wxsky preset apply` and `release` on a real running daemon: the preset's weather comes in
at the [transition] rates with the daemon's own clock, site and cloud seed kept (`--now`
switches at once, `--site` takes the preset's place, date and seed too), and a release goes
back the same way. The daemon is asked as a host asks it, over its control socket, and the
applied weather is read from its `weather` notifications, which it sends after every frame
that changed it."""

from __future__ import annotations

import time
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import RunningDaemon, running_daemon

from wxsky.cli import main
from wxsky.host.client import ControlClient
from wxsky.settings.presets import load_preset
from wxsky.weather.state import parse_time_utc

# Every test runs a daemon, which draws every frame.
pytestmark = pytest.mark.gl

STEP_S = 0.2
# 0.4 okta per 0.2 s step: the stratus deck takes 20 steps to come in, so the first frame
# after the change cannot show it whole however slowly the frames come (one step a frame
# at most, engine.stages).
COVER_PER_MIN = 120.0
HANG_S = 60.0  # only ever reached by a hung daemon

# The daemon's own site, clock and seed, far from the built-in presets' Zurich.
BASE_PRESET = """
description = "Trade-wind cumulus over Honolulu, for the preset tests"
time_utc = "2026-01-10T22:00:00Z"
seed = 99
visibility_m = 20000.0
temperature_c = 26.0
dewpoint_c = 19.0
qnh_hpa = 1016.0

[observer]
lat_deg = 21.3245
lon_deg = -157.9251
alt_m = 4.0

[[layers]]
type = "cumulus"
cover_oktas = 3
base_m = 700.0
top_m = 1500.0

[[wind]]
alt_m = 14.0
dir_deg = 60.0
speed_mps = 6.0
gust_mps = 0.0
"""


def config(preset_dir: Path) -> str:
    return f"""
[clock]
# A frozen clock: the time read after a command is the time before it unless the command
# set it.
rate = 0.0
[presets]
dirs = ["{preset_dir}"]
[camera]
width = 160
height = 90
[scene]
ring_texture_px = 64
[transition]
cover_oktas_per_min = {COVER_PER_MIN}
base_m_per_min = 60000.0
visibility_m_per_s = 0.0
wind_mps_per_s = 0.0
temperature_c_per_min = 0.0
qnh_hpa_per_min = 0.0
step_s = {STEP_S}
"""


@pytest.fixture
def daemon(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[RunningDaemon]:
    # A private user folder: the daemon and the CLI read no one's ~/.config.
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    presets = tmp_path / "presets"
    presets.mkdir()
    (presets / "honolulu-test.toml").write_text(BASE_PRESET)
    args = ("--preset", "honolulu-test")
    with running_daemon(tmp_path, extra_config=config(presets), args=args) as d:
        yield d


def wxsky(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    """The CLI in this process; its stdout (it must succeed)."""
    code = main(list(args))
    out, err = capsys.readouterr()
    assert code == 0, err
    return out


def layers_of(name: str) -> list[dict[str, Any]]:
    """A preset's layers as the status shows them."""
    return [
        {"cover_oktas": lay.cover_oktas, "base_m": lay.base_m, "top_m": lay.top_m}
        | {"type": lay.type.wire_name}
        for lay in sorted(load_preset(name).layers or (), key=lambda lay: lay.base_m)
    ]


def site(weather: dict[str, Any]) -> tuple[Any, datetime, int]:
    """What a transition keeps: the observer, the clock and the cloud seed."""
    return weather["observer"], parse_time_utc(weather["time_utc"]), weather["seed"]


def next_weather(c: ControlClient) -> dict[str, Any]:
    """The applied weather of the next `weather` notification."""
    deadline = time.monotonic() + HANG_S
    while (left := deadline - time.monotonic()) > 0:
        note = c.next_notification(timeout_s=left)
        if note is not None and note.method == "weather":
            return note.params
    raise AssertionError(f"no weather notification within {HANG_S} s")


def weather_until(c: ControlClient, layers: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every applied weather the daemon reports, up to the one with these layers."""
    seen = [next_weather(c)]
    while seen[-1]["layers"] != layers:
        seen.append(next_weather(c))
    return seen


def test_apply_and_release_move_the_weather_at_the_transition_rates(
    daemon: RunningDaemon, capsys: pytest.CaptureFixture[str]
) -> None:
    stratus = layers_of("overcast-stratus")
    with daemon.client() as c:
        before = c.call("status")
        start = before["weather"]
        assert start["layers"] != stratus and before["settled"]
        c.subscribe(["weather"])

        out = wxsky(capsys, "preset", "apply", "overcast-stratus", "--control", daemon.address)
        status = c.call("status")
        # The target is the preset's weather at once, in this sky: the daemon's site, clock
        # and seed.
        assert status["target"]["layers"] == stratus
        assert status["target"]["sources"]["layers"] == "control"
        assert site(status["target"]) == site(start)
        assert site(status["weather"]) == site(start)
        seen = weather_until(c, stratus)
        # The first weather after the change is one step at most from the old: not the preset.
        assert seen[0]["layers"] != stratus
        assert "moves toward it at the [transition] rates" in out
        assert len(seen) > 1
        assert all(site(w) == site(start) for w in seen)
        # Cover comes in gradually: some frame showed the stratus partly formed.
        assert any(
            0.0 < lay["cover_oktas"] < 8.0
            for w in seen
            for lay in w["layers"]
            if lay["type"] == "stratus"
        )
        settled = c.call("status")
        assert settled["settled"] and settled["weather"]["visibility_m"] == 4000.0
        assert site(settled["weather"]) == site(start)

        out = wxsky(capsys, "preset", "release", "--control", daemon.address)
        assert out.startswith("released ") and "at the [transition] rates" in out
        assert c.call("status")["target"]["layers"] == start["layers"]
        seen = weather_until(c, start["layers"])
        assert seen[0]["layers"] != start["layers"] and len(seen) > 1
        assert all(site(w) == site(start) for w in seen)
        assert c.call("status")["settled"]

        # --now: there at once, in the same sky.
        out = wxsky(
            capsys, "preset", "apply", "overcast-stratus", "--now", "--control", daemon.address
        )
        assert "switched to it at once" in out
        status = c.call("status")
        assert status["settled"] and status["weather"]["layers"] == stratus
        assert site(status["weather"]) == site(start)
        out = wxsky(capsys, "preset", "release", "--now", "--control", daemon.address)
        assert out.rstrip().endswith("at once")
        status = c.call("status")
        assert status["settled"] and status["weather"]["layers"] == start["layers"]


def test_apply_with_site_takes_the_presets_place_date_and_seed(
    daemon: RunningDaemon, capsys: pytest.CaptureFixture[str]
) -> None:
    stratus = load_preset("overcast-stratus")
    assert stratus.observer is not None and stratus.time_utc is not None
    with daemon.client() as c:
        start = c.call("status")["weather"]
        out = wxsky(
            capsys, "preset", "apply", "overcast-stratus", "--site", "--control", daemon.address
        )
        assert "at its own site, date and time" in out
        status = c.call("status")
        weather = status["weather"]
        # Another sky, switched to at once: Zurich on a November morning, its own clouds.
        assert status["settled"] and weather["layers"] == layers_of("overcast-stratus")
        assert weather["observer"] == {
            "lat_deg": stratus.observer.lat_deg,
            "lon_deg": stratus.observer.lon_deg,
            "alt_m": stratus.observer.alt_m,
        }
        assert parse_time_utc(weather["time_utc"]) == stratus.time_utc
        assert weather["seed"] == stratus.seed

        # Its release is another sky too: the daemon's own site and seed, at once.
        out = wxsky(capsys, "preset", "release", "--control", daemon.address)
        assert "observer" in out and out.rstrip().endswith("at once")
        status = c.call("status")
        weather = status["weather"]
        assert status["settled"] and weather["layers"] == start["layers"]
        assert (weather["observer"], weather["seed"]) == (start["observer"], start["seed"])
