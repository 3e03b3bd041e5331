"""Several daemons, one sky (docs/channels.md): a sky master and two display channels, real
`wxsky run` processes on loopback talking over a real Zenoh bus, asked through their real
control sockets as a host would."""

from __future__ import annotations

import contextlib
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import HANG_S, DaemonSpec, RunningDaemon, running_daemon, running_daemons

from wxsky.weather.state import parse_time_utc

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed")

# Every test runs daemons, which draw every frame.
pytestmark = pytest.mark.gl

SMALL = """
[camera]
width = 160
height = 90
pitch_deg = 0.0
[scene]
ring_texture_px = 64
"""

PRESET_APPLY = (sys.executable, "-m", "wxsky", "preset", "apply", "overcast-stratus")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def status(d: RunningDaemon) -> dict[str, Any]:
    with d.client() as c:
        result: dict[str, Any] = c.call("status")
        return result


def wait_for(what: str, check: Callable[[], bool], timeout_s: float = HANG_S) -> float:
    """Seconds until check() holds; fails naming `what` after timeout_s (a hang: the seconds
    are for a message, never for an assertion)."""
    start = time.monotonic()
    while not check():
        if time.monotonic() - start > timeout_s:
            raise AssertionError(f"{what}: not within {timeout_s} s")
        time.sleep(0.05)
    return time.monotonic() - start


def sim_skew_s(a: dict[str, Any], b: dict[str, Any]) -> float:
    """b's sim time minus a's, compared at b's reading of the (shared) monotonic clock."""
    ta = parse_time_utc(a["sim_clock"]["time_utc"])
    tb = parse_time_utc(b["sim_clock"]["time_utc"])
    rate = a["clock_rate"]
    at_b = ta + timedelta(seconds=rate * (b["sim_clock"]["mono_s"] - a["sim_clock"]["mono_s"]))
    return (tb - at_b).total_seconds()


def channel_args(share: str, name: str, yaw_deg: float) -> tuple[str, ...]:
    return ("--join", share, "--channel", name, f"--view-offset={yaw_deg},0,0")


@contextlib.contextmanager
def dome(tmp_path: Path, endpoint: str) -> Iterator[tuple[RunningDaemon, ...]]:
    for name in ("master", "left", "right"):
        (tmp_path / name).mkdir(exist_ok=True)
    share = f"zenoh:{endpoint}"
    # The two channels are started together, after the master (their start-ups overlap).
    channels = [
        DaemonSpec(tmp_path / name, SMALL, channel_args(share, name, yaw))
        for name, yaw in (("left", -60.0), ("right", 60.0))
    ]
    with (
        running_daemon(
            tmp_path / "master", SMALL, ("--share", share, "--preset", "fair-cumulus")
        ) as master,
        running_daemons(channels) as (left, right),
    ):
        yield master, left, right


def test_a_master_and_two_channels_show_one_sky_and_outlive_the_master(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with dome(tmp_path, endpoint) as (master, left, right):
        channels = (left, right)

        def joined() -> bool:
            m = status(master)
            return all(
                (s := status(c))["channel"]["master_alive"] and s["sky_id"] == m["sky_id"]
                for c in channels
            )

        wait_for("channels joined with the master's sky_id", joined)
        m = status(master)
        assert m["channel"]["role"] == "master" and m["sky_id"]
        shown = subprocess.run(
            [sys.executable, "-m", "wxsky", "status", "--control", left.address],
            capture_output=True,
            text=True,
            timeout=30,
            check=True,
        ).stdout
        assert f"sky channel 'left' of site 'default' on zenoh:{endpoint}" in shown
        assert f"sky_id {m['sky_id']}, master alive" in shown
        for c, name in ((left, "left"), (right, "right")):
            s = status(c)
            assert s["channel"]["role"] == "channel" and s["channel"]["name"] == name
            assert s["weather"]["layers"] == m["weather"]["layers"]
            # The clock: the same sim time at one instant, within 10 ms (here both share one
            # monotonic clock, so the channel's estimate of the offset is its error).
            skews = [sim_skew_s(status(master), status(c)) for _ in range(5)]
            assert min(abs(v) for v in skews) < 0.010, skews
            assert abs(s["channel"]["clock_offset_ms"]) < 10.0
            # Through `status` alone: read between two of the master's readings, the channel's
            # sim time lies between them (give or take the 10 ms above), however long the
            # reads take on a busy machine.
            first = parse_time_utc(status(master)["sim_clock"]["time_utc"])
            between = parse_time_utc(status(c)["sim_clock"]["time_utc"])
            last = parse_time_utc(status(master)["sim_clock"]["time_utc"])
            slack = timedelta(milliseconds=10)
            assert first - slack <= between <= last + slack, (first, between, last)
        # The shared camera, turned by each channel's view offset (level: yaw alone).
        with master.client() as c:
            c.call(
                "set_camera",
                {"position_m": [0.0, 0.0, 1500.0], "heading_deg": 90.0, "pitch_deg": 0.0},
            )
        wait_for(
            "channels look 60° either side",
            lambda: (
                abs(status(left)["camera"]["heading_deg"] - 30.0) < 1e-6
                and abs(status(right)["camera"]["heading_deg"] - 150.0) < 1e-6
            ),
        )
        assert status(left)["camera"]["position_m"] == [0.0, 0.0, 1500.0]
        # The weather and the clock are the master's: a channel refuses them, one line.
        for command, params in (
            ("apply_preset", {"name": "overcast-stratus"}),
            ("set_time", {"rate": 2.0}),
            ("set_camera", {"heading_deg": 10.0}),
        ):
            with left.client() as c, pytest.raises(Exception, match="master") as err:
                c.call(command, params)
            assert "\n" not in str(err.value)
        # `wxsky preset apply` on a channel is refused in one line; on the master it reaches
        # both channels' target.
        refused = subprocess.run(
            [*PRESET_APPLY, "--control", left.address],
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert refused.returncode != 0 and "sky master" in refused.stderr
        assert len(refused.stderr.strip().splitlines()) == 1, refused.stderr
        subprocess.run(
            [*PRESET_APPLY, "--control", master.address],
            capture_output=True,
            timeout=30,
            check=True,
        )
        target = status(master)["target"]["layers"]
        for ch in channels:
            wait_for(
                "the master's new target",
                lambda ch=ch: status(ch)["target"]["layers"] == target,  # type: ignore[misc]
            )
        # The master dies: both channels say so and keep publishing frames.
        frames = {ch.shm_name: status(ch)["frames_published"] for ch in channels}
        sky = status(left)["sky_id"]
        master.proc.send_signal(signal.SIGKILL)
        master.proc.wait(timeout=HANG_S)
        for ch in channels:
            wait_for(
                "master_alive false",
                lambda ch=ch: not status(ch)["channel"]["master_alive"],  # type: ignore[misc]
            )
        for ch in channels:
            wait_for(
                "frames after the master died",
                lambda ch=ch: (  # type: ignore[misc]
                    status(ch)["frames_published"] > frames[ch.shm_name] + 5
                ),
            )
            assert status(ch)["sky_id"] == sky  # the last sky, kept
        # A master comes back on the same endpoint: joined and followed.
        (tmp_path / "master2").mkdir()
        with running_daemon(
            tmp_path / "master2", SMALL, ("--share", f"zenoh:{endpoint}", "--preset", "clear")
        ) as again:

            def followed() -> bool:
                m = status(again)
                return all(
                    (s := status(c))["channel"]["master_alive"] and s["sky_id"] == m["sky_id"]
                    for c in channels
                )

            wait_for("the new master followed", followed)
            assert status(left)["target"]["layers"] == status(again)["target"]["layers"] == []


def test_a_second_master_on_a_site_refuses_to_start(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    with running_daemon(tmp_path / "one", SMALL, ("--share", f"zenoh:{endpoint}")):
        with (
            pytest.raises(AssertionError, match="already has a sky master") as err,
            running_daemon(tmp_path / "two", SMALL, ("--share", f"zenoh:{endpoint}")),
        ):
            pass
        assert "exited early (2)" in str(err.value)  # the CLI's exit status for a bad start


def test_a_channel_that_dies_and_restarts_catches_up(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    share = f"zenoh:{endpoint}"
    for name in ("master", "left", "again"):
        (tmp_path / name).mkdir()
    with running_daemon(tmp_path / "master", SMALL, ("--share", share)) as master:
        with running_daemon(tmp_path / "left", SMALL, channel_args(share, "left", -60.0)) as ch:
            wait_for("joined", lambda: status(ch)["sky_id"] == status(master)["sky_id"])
            ch.proc.send_signal(signal.SIGKILL)
            ch.proc.wait(timeout=HANG_S)
        with master.client() as c:  # the sky moves on while the channel is down
            c.call("apply_preset", {"name": "broken-stratocumulus"})
        wait_for("the master's new sky", lambda: status(master)["settled"])
        with running_daemon(tmp_path / "again", SMALL, channel_args(share, "left", -60.0)) as again:
            # Up (its first frame published): it asked for the state before its first frame.
            # (How soon it catches up is a benchmark's business, not this test's.)
            wait_for(
                "caught up",
                lambda: (
                    (s := status(again))["channel"]["master_alive"]
                    and s["sky_id"] == status(master)["sky_id"]
                ),
            )
            assert status(again)["weather"]["layers"] == status(master)["weather"]["layers"]
