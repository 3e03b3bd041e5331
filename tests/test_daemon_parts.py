"""Issue 39, item 8: the daemon's parts plug in one way (`wxsky/app/parts.py`). A real daemon,
in this process, walks the parts it is given in their order through every phase, lists their
inputs and status keys, asks them about control commands, and at shutdown closes them
together, cutting by name one that overruns the deadline without waiting for it."""

from __future__ import annotations

import asyncio
import logging
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import write_config

from wxsky.app.daemon import Daemon, initial_patches
from wxsky.app.part_factory import PartOptions, parts_from_config
from wxsky.app.parts import Part, PartContext, PublishedFrame
from wxsky.app.share_part import SharePart
from wxsky.errors import ConfigError
from wxsky.host.client import ControlClient, RemoteError
from wxsky.inputs.stats import InputStats
from wxsky.output.transport import parse_address
from wxsky.settings.config import ChannelSection, DaemonConfig, load_config

# `wxsky status --json`'s keys, which hosts and tests read: a part adds keys, never moves these.
STATUS_KEYS = {
    "version",
    "uptime_s",
    "frames_published",
    "fps",
    "weather",
    "target",
    "settled",
    "overrides",
    "inputs",
    "clients",
    "shm_name",
    "camera",
    "clock_rate",
    "clock_at_end",
    "frozen",
    "at_eye",
    "frames",
    "scene_work",
    "segment",
    "block_cache",
    "memory",
    "zero_copy",
    "sky_id",
    "channel",
    "sim_clock",
}
HANG_S = 120.0  # only catches a hang: nothing here waits for time to pass


class Recorder(Part):
    """A part that writes down each call it gets, in one list shared with the others."""

    def __init__(self, name: str, events: list[tuple[Any, ...]]) -> None:
        self.name = name
        self.events = events
        self.stats = InputStats(f"probe:{name}", "probe")
        self.ctx: PartContext | None = None
        self.deadline_s: float | None = None
        self.stop_at_next_frame = threading.Event()  # set by the test's thread

    def inputs(self) -> list[InputStats]:
        return [self.stats]

    async def start(self, ctx: PartContext) -> None:
        self.ctx = ctx
        self.events.append((self.name, "start"))

    def before_frame(self) -> None:
        self.events.append((self.name, "before"))

    def after_frame(self, frame: PublishedFrame) -> None:
        self.events.append((self.name, "after", frame.number))
        self.stats.message()
        if self.stop_at_next_frame.is_set() and self.ctx is not None:
            self.ctx.stop.set()  # a part may stop the daemon

    def status(self) -> dict[str, Any]:
        return {f"probe_{self.name}": {"frames": self.stats.messages}, "version": "not mine"}

    def refusal(self, method: str) -> str | None:
        return f"set_time: {self.name} says no" if method == "set_time" else None

    async def close(self, deadline_s: float) -> None:
        self.deadline_s = deadline_s
        self.events.append((self.name, "close"))


class Stuck(Recorder):
    """A part whose close never ends by itself (a device that never lets go)."""

    async def close(self, deadline_s: float) -> None:
        await super().close(deadline_s)
        try:
            await asyncio.Event().wait()
        except asyncio.CancelledError:
            self.events.append((self.name, "cut"))
            raise


class Broken(Recorder):
    async def close(self, deadline_s: float) -> None:
        await super().close(deadline_s)
        raise RuntimeError("the device fell off")


def _until(what: Any, timeout_s: float = HANG_S) -> None:
    deadline = time.monotonic() + timeout_s
    while not what():
        assert time.monotonic() < deadline, "timed out: a hang"
        time.sleep(0.05)


@pytest.mark.gl
def test_a_real_daemon_walks_its_parts_in_order_and_cuts_one_that_will_not_close(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)
    shm_name = f"wxsky-test-{uuid.uuid4().hex[:10]}"
    config = load_config(write_config(tmp_path / "wxsky.toml", shm_name))
    address = parse_address(f"unix:{tmp_path / 'wx.sock'}")
    events: list[tuple[Any, ...]] = []
    first, second = Recorder("first", events), Recorder("second", events)
    stuck, broken = Stuck("stuck", events), Broken("broken", events)
    probes = [first, second, stuck, broken]
    parts = [*parts_from_config(config), *probes]
    daemon = Daemon(config, initial_patches(config, preset="clear"), parts, address=address)
    assert daemon.parts == parts
    ended: list[Any] = []

    def run() -> None:
        try:
            ended.append(asyncio.run(daemon.run()))
        except BaseException as exc:
            ended.append(exc)

    runner = threading.Thread(target=run, name="test-daemon", daemon=True)
    runner.start()
    _until(lambda: ended or first.stats.messages >= 3)
    assert not ended, ended
    with ControlClient.connect(address) as client:
        status = client.call("status")
        with pytest.raises(RemoteError, match="set_time: first says no"):
            client.call("set_time", {"time_utc": "2024-06-01T12:00:00Z"})
    # The parts' inputs are listed after the daemon's own, their keys added to its own.
    names = [i["name"] for i in status["inputs"]]
    assert names[-4:] == ["probe:first", "probe:second", "probe:stuck", "probe:broken"]
    assert set(status) == STATUS_KEYS | {f"probe_{p.name}" for p in probes}
    assert status["version"] != "not mine"
    assert first.ctx is not None and first.ctx.engine is daemon.engine
    first.stop_at_next_frame.set()
    runner.join(HANG_S)
    assert not runner.is_alive(), "shutdown waited for the stuck part"
    assert ended == [0]

    # Start, then every frame before and after, each phase in the list's order.
    order = [p.name for p in probes]
    assert events[:4] == [(name, "start") for name in order]
    frames = events[4 : events.index(("first", "close"))]
    assert len(frames) % 8 == 0 and len(frames) >= 3 * 8
    numbers = []
    for at in range(0, len(frames), 8):
        before, after = frames[at : at + 4], frames[at + 4 : at + 8]
        assert before == [(name, "before") for name in order]
        assert [e[:2] for e in after] == [(name, "after") for name in order]
        assert len({e[2] for e in after}) == 1
        numbers.append(after[0][2])
    assert numbers == list(range(numbers[0], numbers[0] + len(numbers)))
    # Then each closed once, with one deadline for all; the stuck one was cut, not awaited.
    closing = events[4 + len(frames) :]
    assert sorted(closing) == sorted([*((name, "close") for name in order), ("stuck", "cut")])
    assert len({p.deadline_s for p in probes}) == 1
    lines = [r.getMessage() for r in caplog.records]
    assert "shutdown: stuck did not close in time; cut it" in lines
    assert "shutdown: broken failed to close: the device fell off" in lines
    assert not [line for line in lines if "did not close in time" in line and "stuck" not in line]
    # The rest of the shutdown went on: the segment and the socket are gone.
    assert lines.index("shutdown: stuck did not close in time; cut it") < next(
        i for i, line in enumerate(lines) if line.startswith("stopped after")
    )
    assert not Path(f"/dev/shm/{shm_name}").exists()
    assert not (tmp_path / "wx.sock").exists()


def test_two_inputs_of_one_name_stop_the_start_before_the_sky_is_made() -> None:
    config = DaemonConfig()
    events: list[tuple[Any, ...]] = []
    clash = Recorder("control", events)
    clash.stats = InputStats("control", "probe")  # the control channel's own name
    with pytest.raises(ConfigError, match=r"^two inputs are named 'control'; give one a 'name'$"):
        Daemon(config, initial_patches(config, preset="clear"), [clash])
    assert events == []


def test_the_factory_makes_only_the_parts_asked_for_in_the_daemons_order(tmp_path: Path) -> None:
    feed = tmp_path / "metars.txt"
    feed.write_text("")
    assert [p.name for p in parts_from_config(DaemonConfig())] == ["channel bus"]
    options = PartOptions(
        metar_feeds=(str(feed), str(feed)),
        cigi=("udp:127.0.0.1:0",),
        flightgear_pose="udp:127.0.0.1:0",
    )
    parts = parts_from_config(DaemonConfig(), options)
    assert [p.name for p in parts] == ["METAR feeds", "CIGI", "FlightGear", "channel bus"]
    # A feed named twice is read once; FlightGear's pose holds the site for presets.
    assert [s.name for s in parts[0].inputs()] == [f"metar:{feed}"]
    assert [p.holds_site for p in parts] == [False, False, True, False]
    asyncio.run(parts[1].close(time.monotonic()))  # releases the CIGI part's sockets


def test_a_channel_refuses_other_weather_inputs_in_one_line(tmp_path: Path) -> None:
    feed = tmp_path / "metars.txt"
    feed.write_text("")
    config = DaemonConfig(channel=ChannelSection(join="tcp/127.0.0.1:7447", name="left"))
    options = PartOptions(metar_feeds=(str(feed),), cigi=("udp:127.0.0.1:0",))
    with pytest.raises(ConfigError) as err:
        parts_from_config(config, options)
    assert str(err.value) == (
        "channel 'left' takes its weather from the sky master; it cannot also read "
        "METAR feeds, CIGI (give them to the master)"
    )
    # Sending its weather to an IG is no weather input: a channel may.
    sending = parts_from_config(config, PartOptions(cigi_send=("udp:127.0.0.1:9",)))
    assert [p.name for p in sending] == ["CIGI", "channel bus"]
    asyncio.run(sending[0].close(time.monotonic()))


def test_a_part_answers_status_before_it_starts() -> None:
    """The control socket answers while the parts start: the channel bus has no sky yet."""
    status = SharePart(DaemonConfig()).status()
    assert status["sky_id"] is None and status["sim_clock"]["time_utc"] is None
    assert status["channel"]["role"] == "standalone"
