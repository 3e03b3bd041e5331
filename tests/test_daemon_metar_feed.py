"""A real daemon following a real METAR feed file: new weather at the next poll, changes
through bounded transitions, control overrides held until released, bad feeds survived."""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import HANG_S, running_daemon, wait_status
from metar_helpers import gzip_bomb

# Every test runs a daemon, which draws every frame.
pytestmark = pytest.mark.gl

# The default preset's observer is Zurich airport, LSZH; LSZH's position comes from the
# shipped station table, since plain-line feeds carry none.
STEP_S = 0.2
# 0.4 okta per 0.2 s step: a new overcast layer takes 20 steps (4 s) to come in.
COVER_PER_MIN = 120.0

CONFIG = f"""
[camera]
width = 320
height = 180
[scene]
ring_texture_px = 64
[metar]
poll_interval_s = 0.2
[transition]
cover_oktas_per_min = {COVER_PER_MIN}
base_m_per_min = 60000.0
# Only clouds move gradually here; the rest switches at once so "settled" comes quickly.
visibility_m_per_s = 0.0
wind_mps_per_s = 0.0
temperature_c_per_min = 0.0
qnh_hpa_per_min = 0.0
step_s = {STEP_S}
"""


def _report(clouds: str, when: datetime | None = None) -> str:
    t = when or datetime.now(UTC)
    return f"LSZH {t:%d%H%M}Z 24008KT 9999 {clouds} 18/09 Q1016\n"


def _write(path: Path, text: str) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)  # as feed tools do: the reader never sees half a file


_wait = wait_status


def _metar_input(status: dict[str, Any]) -> dict[str, Any]:
    return next(i for i in status["inputs"] if i["kind"] == "metar")


def _covers(weather: dict[str, Any]) -> list[tuple[str, float]]:
    return [(lay["type"], lay["cover_oktas"]) for lay in weather["layers"]]


def test_feed_rewrite_reaches_status_and_changes_through_transitions(tmp_path: Path) -> None:
    feed = tmp_path / "metar.txt"
    _write(feed, _report("SCT040"))
    with running_daemon(
        tmp_path, CONFIG, args=("--metar-feed", str(feed), "--preset", "clear")
    ) as daemon:
        status = _wait(
            daemon,
            lambda s: s["target"]["sources"]["layers"] == "metar" and s["settled"],
            "the first report",
        )
        assert _covers(status["target"]) == [("cumulus", 4.0)]
        info = _metar_input(status)
        assert info["ok"] and info["messages"] >= 1 and info["using"][0]["station"] == "LSZH"
        assert info["stale"] is False and 0.0 <= info["last_message_s"] < 60.0

        with daemon.client() as watcher:
            watcher.subscribe(["weather"])
            _write(feed, _report("BKN040 OVC080"))
            status = _wait(daemon, lambda s: len(s["target"]["layers"]) == 2, "the new report")
            covers = []
            deadline = time.monotonic() + HANG_S
            while time.monotonic() < deadline:
                note = watcher.next_notification(timeout_s=HANG_S)
                assert note is not None
                weather = note.params
                covers.append(dict(_covers(weather)))
                if weather["layers"] and _covers(weather) == _covers(status["target"]):
                    break
        # Every published step moved each layer's cover by at most one step's worth.
        limit = COVER_PER_MIN / 60.0 * STEP_S
        for before, after in itertools.pairwise(covers):
            for kind in set(before) | set(after):
                assert abs(after.get(kind, 0.0) - before.get(kind, 0.0)) <= limit + 1e-6
        assert len(covers) > 10  # it took many steps, not one jump
        assert covers[-1] == dict(_covers(status["target"]))


def test_preset_apply_holds_against_the_feed_until_released(tmp_path: Path) -> None:
    feed = tmp_path / "metar.txt"
    _write(feed, _report("FEW030"))
    with running_daemon(tmp_path, CONFIG, args=("--metar-feed", str(feed))) as daemon:
        _wait(daemon, lambda s: s["target"]["sources"]["layers"] == "metar", "the report")
        with daemon.client() as c:
            c.call("apply_preset", {"name": "overcast-stratus"})
        status = _wait(daemon, lambda s: s["target"]["sources"]["layers"] == "control", "preset")
        assert _covers(status["target"]) == [("stratus", 8.0)]
        assert status["overrides"]["layers"]["source"] == "control"
        polls = _metar_input(status)["fetches"]
        _write(feed, _report("SCT050"))
        status = _wait(daemon, lambda s: _metar_input(s)["fetches"] >= polls + 3, "three polls")
        with daemon.client() as c:
            assert _covers(status["target"]) == [("stratus", 8.0)]
            released = c.call("release", {})
        assert "layers" in released["released"]
        status = _wait(daemon, lambda s: s["target"]["sources"]["layers"] == "metar", "release")
        assert [k for k, _ in _covers(status["target"])] == ["cumulus"]


def test_stale_and_broken_feeds_keep_the_last_weather(tmp_path: Path) -> None:
    feed = tmp_path / "metar.txt"
    # Only a report five hours old: too old for the 90-minute limit, so the start-up preset
    # stays and the input says why.
    _write(feed, _report("OVC005", datetime.now(UTC) - timedelta(hours=5)))
    with running_daemon(tmp_path, CONFIG, args=("--metar-feed", str(feed))) as daemon:
        status = _wait(daemon, lambda s: _metar_input(s)["stale"], "stale")
        assert status["target"]["sources"]["layers"] == "preset"
        assert "older than 90 min" in _metar_input(status)["reason"]
        _write(feed, _report("OVC010"))
        good = _wait(daemon, lambda s: s["target"]["sources"]["layers"] == "metar", "report")
        assert _metar_input(good)["stale"] is False
        _write(feed, "<!DOCTYPE html><html><body>502 Bad Gateway</body></html>\n")
        status = _wait(daemon, lambda s: _metar_input(s)["errors"] > 0, "the error count")
        assert "html" in _metar_input(status)["last_error"].lower()
        assert not _metar_input(status)["ok"]  # the feed as a whole failed
        assert status["target"]["layers"] == good["target"]["layers"]
        feed.unlink()
        status = _wait(
            daemon, lambda s: "no such file" in _metar_input(s)["last_error"], "the missing file"
        )
        assert not _metar_input(status)["ok"]
        assert status["target"]["layers"] == good["target"]["layers"]
    assert "Traceback" not in daemon.log()


def _write_bytes(path: Path, data: bytes) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def test_bombed_and_half_written_feeds_fail_until_fixed(tmp_path: Path) -> None:
    feed = tmp_path / "metar.txt"
    _write(feed, _report("SCT040"))
    with running_daemon(
        tmp_path, CONFIG, args=("--metar-feed", str(feed), "--preset", "clear")
    ) as daemon:
        good = _wait(daemon, lambda s: s["target"]["sources"]["layers"] == "metar", "report")
        bad: list[dict[str, Any]] = []  # every status seen once the bad file was read

        def after_three_more_polls(check: Callable[[dict[str, Any]], bool], what: str) -> None:
            first = _wait(daemon, check, what)
            bad.append(first)
            polls = _metar_input(first)["fetches"]
            _wait(
                daemon,
                lambda s: bad.append(s) is None and _metar_input(s)["fetches"] >= polls + 3,
                "three more polls",
            )

        # 300 kB of gzip that unpacks to 64 MiB, twice the limit.
        _write_bytes(feed, gzip_bomb(64 * 1024 * 1024))
        after_three_more_polls(lambda s: _metar_input(s)["oversize"] == 1, "the refusal")
        assert "byte limit" in _metar_input(bad[-1])["last_error"]
        assert _metar_input(bad[-1])["oversize"] == 1  # refused once, not unpacked again
        # Caught half-written: the station and time, nothing more.
        _write(feed, _report("")[: len("LSZH 011731Z")] + "\n")
        after_three_more_polls(
            lambda s: "nothing after the time group" in _metar_input(s)["last_error"], "the cut"
        )
        assert [s for s in bad if _metar_input(s)["ok"]] == []
        assert all(s["target"]["layers"] == good["target"]["layers"] for s in bad)
        _write(feed, _report("BKN040 OVC080"))
        fixed = _wait(daemon, lambda s: len(s["target"]["layers"]) == 2, "the good report")
        assert _metar_input(fixed)["ok"] and _metar_input(fixed)["state"] == "running"
    assert "Traceback" not in daemon.log()
