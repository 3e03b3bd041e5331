"""A stranger on the channel bus (issue 40, attacks 2-4): a real sky master and a real display
channel (`wxsky run` on loopback), and a Zenoh session of the test's own that forges what the
master sends. A forged tick must not kill the channel, a forged state must not freeze it on
the forger's weather, a flood of health names must not grow the master's peer table, and a
channel killed with SIGKILL must leave that table (docs/channels.md)."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import re
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from typing import Any

import pytest
from daemon_harness import HANG_S, RunningDaemon, running_daemon
from test_channels import PRESET_APPLY, SMALL, channel_args, free_port, sim_skew_s, status, wait_for

from wxsky.output.wire import pack_data, unpack_data
from wxsky.settings.presets import load_preset
from wxsky.share.messages import Health, decode_state, encode_health, encode_state

zenoh = pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed")

# The daemons draw every frame; the tests share one master and channel, in this order.
pytestmark = [pytest.mark.gl, pytest.mark.xdist_group("channels_hostile")]

SITE = "default"


@dataclasses.dataclass
class Dome:
    endpoint: str  # the master's
    master: RunningDaemon
    left: RunningDaemon
    router: Any  # the Zenoh router the channel joins through, a session of the test's


@pytest.fixture(scope="module")
def dome(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Dome]:
    """A master, and a channel joined through a Zenoh router (as docs/channels.md has a big
    site do): the router forwards the master's messages to the channel, and whatever the
    test puts on it: a stranger on the path, or in the master's place."""
    root = tmp_path_factory.mktemp("hostile")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    relay = f"tcp/127.0.0.1:{free_port()}"
    for name in ("master", "left"):
        (root / name).mkdir()
    master_args = ("--share", f"zenoh:{endpoint}", "--preset", "fair-cumulus")
    with (
        running_daemon(root / "master", SMALL, master_args) as master,
        _session(endpoint, mode="router", listen=relay) as router,
        running_daemon(root / "left", SMALL, channel_args(f"zenoh:{relay}", "left", -60.0)) as left,
    ):
        wait_for("the channel joined", lambda: _joined(master, left))
        yield Dome(endpoint, master, left, router)


def _joined(master: RunningDaemon, channel: RunningDaemon) -> bool:
    s = status(channel)
    return bool(s["channel"]["master_alive"]) and s["sky_id"] == status(master)["sky_id"]


@contextlib.contextmanager
def _session(connect: str, mode: str = "peer", listen: str | None = None) -> Iterator[Any]:
    """A Zenoh session of nobody's: no credentials, connected to `connect`."""
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(mode))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("listen/endpoints", json.dumps([listen] if listen else []))
    cfg.insert_json5("connect/endpoints", json.dumps([connect]))
    session = zenoh.open(cfg)
    try:
        yield session
    finally:
        session.close()


def _one_sample(session: Any, key: str) -> dict[str, Any]:
    """The next message the master publishes on `key`, unpacked."""
    got: list[bytes] = []
    ready = threading.Event()

    def take(sample: Any) -> None:
        if not got:
            got.append(sample.payload.to_bytes())
            ready.set()

    sub = session.declare_subscriber(key, take)
    try:
        assert ready.wait(HANG_S), f"nothing on {key}"
    finally:
        sub.undeclare()
    message = unpack_data(got[0])
    assert isinstance(message, dict)
    return message


def test_a_forged_tick_far_from_the_masters_clock_is_dropped_and_the_channel_lives(
    dome: Dome,
) -> None:
    s = dome.router
    real = _one_sample(s, f"wxsky/{SITE}/clock")
    # Issue 40's tick (a monotonic reading the decoder took, then an OverflowError), and
    # one the decoder takes but the clock's bound must not: a day in the master's future.
    for mono_s in (1e12, real["master_mono_s"] + 86_400.0):
        s.put(f"wxsky/{SITE}/clock", pack_data({**real, "master_mono_s": mono_s}))
    frames = status(dome.left)["frames_published"]
    wait_for(
        "both forged ticks counted",
        lambda: status(dome.left)["channel"]["dropped"].get("clock", 0) >= 2,
    )
    assert dome.left.proc.poll() is None, dome.left.log()
    wait_for("frames go on", lambda: status(dome.left)["frames_published"] > frames + 5)
    s_left = status(dome.left)
    assert s_left["channel"]["master_alive"]
    # Its clock is still the master's (the forged tick would have put it a day behind).
    skews = [abs(sim_skew_s(status(dome.master), status(dome.left))) for _ in range(3)]
    assert min(skews) < 1.0, skews
    assert "OverflowError" not in dome.left.log()


def test_a_forged_state_with_the_largest_sequence_cannot_freeze_the_channel(dome: Dome) -> None:
    s = dome.router
    real = decode_state(_one_sample(s, f"wxsky/{SITE}/state"), SITE)
    storm = dataclasses.replace(real.applied, layers=load_preset("thunderstorm").layers or ())
    forged = dataclasses.replace(
        real,
        sequence=2**63 - 1,
        applied=storm,
        target=storm,
        anchor_drift=((0.0, 0.0),) * len(storm.layers),
        tower_epochs=(None,) * len(storm.layers),
    )
    before = status(dome.left)["channel"]["dropped"].get("state", 0)
    # Well-formed, from the live run: only its sequence gives it away.
    s.put(f"wxsky/{SITE}/state", pack_data(encode_state(forged)))
    wait_for(
        "the forged state counted",
        lambda: status(dome.left)["channel"]["dropped"].get("state", 0) > before,
    )
    assert status(dome.left)["sky_id"] == status(dome.master)["sky_id"]
    # The master's next weather still reaches the channel.
    subprocess.run(
        [*PRESET_APPLY, "--control", dome.master.address],
        capture_output=True,
        timeout=30,
        check=True,
    )
    target = status(dome.master)["target"]["layers"]
    wait_for("the master's new target", lambda: status(dome.left)["target"]["layers"] == target)
    assert status(dome.left)["channel"]["master_alive"]


def test_a_flood_of_health_names_and_tokens_leaves_the_peer_table_bounded(dome: Dome) -> None:
    names = [f"ghost{i}" for i in range(3000)]  # MAX_PEERS (64) passed many times over
    with _session(dome.endpoint) as s:  # straight to the master
        for name in names:
            health = Health(SITE, name, "channel", 30.0, 1.0, 1)
            s.put(f"wxsky/{SITE}/health/{name}", pack_data(encode_health(health)))
        # Tokens too: the table holds peers with a live token, at most peers_max of them.
        tokens = [
            s.liveliness().declare_token(f"wxsky/{SITE}/alive/channel/token{i}") for i in range(100)
        ]
        most = 64  # MAX_PEERS, docs/channels.md

        def flooded() -> bool:
            c = status(dome.master)["channel"]
            grown = len(c["peers"]) > most + 1  # the table growing (what issue 40 saw)
            counted = c["dropped"].get("health", 0) >= 1000 and c["refused_peers"] >= 100 - most
            return grown or counted

        wait_for("the flood counted", flooded)
        m = status(dome.master)["channel"]
        assert len(m["peers"]) <= most + 1, len(m["peers"])  # its channels, and its own line
        assert set(m["peers"]) <= {"master", "left"} | {f"token{i}" for i in range(100)}
        assert m["peers_max"] == most
        shown = subprocess.run(
            [sys.executable, "-m", "wxsky", "status", "--control", dome.master.address],
            capture_output=True,
            text=True,
            timeout=30,
            check=True,
        ).stdout
        assert re.search(r"dropped \d+ messages, refused [1-9]\d* peers", shown), shown
        for token in tokens:
            token.undeclare()
    # Tokens gone, peers gone: only the real ones are listed.
    wait_for(
        "the master lists only its real peers",
        lambda: set(status(dome.master)["channel"]["peers"]) == {"master", "left"},
    )


def test_a_channel_killed_with_sigkill_leaves_the_masters_peer_table(dome: Dome) -> None:
    wait_for("the channel listed", lambda: "left" in status(dome.master)["channel"]["peers"])
    dome.left.proc.send_signal(signal.SIGKILL)
    dome.left.proc.wait(timeout=HANG_S)
    wait_for("the channel forgotten", lambda: "left" not in status(dome.master)["channel"]["peers"])
    assert dome.master.proc.poll() is None
