"""`set_weather` (the control channel) and `wxsky weather set` on a real running daemon: an
instructor's visibility, cloud layers and present weather become the control override (14 CFR
Part 60, Appendix C, Table C3B 9.a: cloud base, density, visibility), held until released;
a bad value is a one-line error naming the field, and nothing of that request is applied."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from daemon_harness import HANG_S, RunningDaemon, running_daemon

from wxsky.cli import main
from wxsky.host.client import RemoteError

pytestmark = pytest.mark.gl

CONFIG = """
[clock]
rate = 0.0
[camera]
width = 160
height = 90
[scene]
ring_texture_px = 64
"""


@pytest.fixture
def daemon(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[RunningDaemon]:
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    with running_daemon(tmp_path, extra_config=CONFIG, args=("--preset", "fair-cumulus")) as d:
        yield d


def test_set_weather_overrides_what_it_names_until_released(daemon: RunningDaemon) -> None:
    with daemon.client() as c:
        before = c.call("status")["target"]
        fields = c.call(
            "set_weather",
            {
                "visibility_m": 1500.0,
                "layers": [
                    {"type": "stratus", "cover_oktas": 6, "base_m": 650.0, "top_m": 900.0},
                    {"type": "cumulus", "cover_oktas": 3, "base_m": 1400.0, "top_m": 2600.0},
                ],
                "present_weather": ["-RA"],
                "now": True,
            },
        )
        assert fields == ["layers", "present_weather", "visibility_m"]
        status = c.call("status")
        t = status["target"]
        assert t["visibility_m"] == 1500.0 and t["present_weather"] == ["-RA"]
        assert [(lay["type"], lay["cover_oktas"], lay["base_m"]) for lay in t["layers"]] == [
            ("stratus", 6, 650.0),
            ("cumulus", 3, 1400.0),
        ]
        assert t["sources"]["visibility_m"] == "control"
        # `now`: the applied weather is there at once.
        assert status["weather"]["layers"] == t["layers"] and status["settled"]
        # What it did not name stays as it was.
        assert t["qnh_hpa"] == before["qnh_hpa"] and t["wind"] == before["wind"]
        # A second request changes only what it names: the layers stay the instructor's.
        c.call("set_weather", {"visibility_m": 8000.0})
        t = c.call("status")["target"]
        assert t["visibility_m"] == 8000.0 and t["layers"][0]["base_m"] == 650.0
        released = c.call("release", {"now": True})["released"]
        assert {"visibility_m", "layers", "present_weather"} <= set(released)
        after = c.call("status")["target"]
        assert after["layers"] == before["layers"]
        assert after["visibility_m"] == before["visibility_m"]


def test_bad_set_weather_names_the_field_and_changes_nothing(daemon: RunningDaemon) -> None:
    with daemon.client() as c:
        before = c.call("status")
        bad = [
            ({"visibility_m": -5.0}, r"^set_weather: visibility_m: must be a number"),
            (
                {"layers": [{"type": "cumulus", "cover_oktas": 9, "base_m": 900.0, "top_m": 2e3}]},
                r"^set_weather: layers\.0\.cover_oktas: must be an integer in 0\.\.8",
            ),
            (
                {"layers": [{"type": "cumulus", "cover_oktas": 4, "base_m": 900.0}]},
                r"^set_weather: layers\.0\.top_m: missing key",
            ),
            # Valid alone, but the request is all or nothing: the visibility is not applied.
            ({"visibility_m": 2000.0, "qnh_hpa": "high"}, r"^set_weather: qnh_hpa: "),
            ({"observer": {"lat_deg": 0.0}}, r"^set_weather: observer: unknown key"),
            ({"now": True}, r"^set_weather: give at least one of visibility_m"),
            ({"visibility_m": 2000.0, "now": "yes"}, r"^set_weather: now: must be true or false"),
        ]
        for params, message in bad:
            with pytest.raises(RemoteError, match=message):
                c.call("set_weather", params)
        deadline = time.monotonic() + HANG_S
        while (after := c.call("status"))["frames_published"] <= before["frames_published"]:
            assert time.monotonic() < deadline, "no frame published after the bad requests"
            time.sleep(0.05)
        assert after["target"] == before["target"]


def test_the_cli_sets_the_weather_of_a_running_daemon(
    daemon: RunningDaemon, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(
        [
            "weather",
            "set",
            "--visibility-m",
            "2500",
            "--layer",
            "stratocumulus:5:800:1300",
            "--present-weather",
            "RA",
            "--control",
            daemon.address,
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "set layers, present_weather, visibility_m" in out
    with daemon.client() as c:
        t = c.call("status")["target"]
    assert t["visibility_m"] == 2500.0 and t["present_weather"] == ["RA"]
    assert [
        (lay["type"], lay["cover_oktas"], lay["base_m"], lay["top_m"]) for lay in t["layers"]
    ] == [("stratocumulus", 5, 800.0, 1300.0)]
    # A bad layer is the CLI's own usage error; a bad value the daemon's, naming the field.
    assert main(["weather", "set", "--layer", "cumulus:4:900", "--control", daemon.address]) == 2
    assert "TYPE:OKTAS:BASE_M:TOP_M" in capsys.readouterr().err
    code = main(["weather", "set", "--visibility-m", "-3", "--control", daemon.address])
    assert code == 2
    assert "visibility_m" in capsys.readouterr().err
