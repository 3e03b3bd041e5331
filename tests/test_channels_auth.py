"""The channel bus's credentials (issue 40; docs/channels.md): Zenoh's mutual TLS with a
dome's certificates (tools/generate/dome_certs.py, openssl) and the master's access control.
Real Zenoh sessions on loopback: a session without the dome's certificates can neither
publish nor subscribe, a channel with them joins, a channel's certificate cannot speak for
the master, a wrong certificate is refused with one log line; and without credentials a bus
beyond loopback is a config error unless `allow_insecure = true`."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import HANG_S, DaemonSpec, running_daemons
from test_channels import SMALL, channel_args, free_port, status, wait_for
from tool_loader import load_tool

from wxsky.errors import ConfigError
from wxsky.settings.config import load_config

zenoh = pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed")

SITE = "dome"
MASTER_ID = "0123456789abcdef"


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The dome's certificates, and another CA's (a stranger's look-alike set)."""
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed (apt install openssl)")
    tool = load_tool("generate/dome_certs")
    root = tmp_path_factory.mktemp("certs")
    dome, other = root / "dome", root / "other"
    tool.generate(dome, ["127.0.0.1", "localhost"], ["left", "right"], 30)
    tool.generate(other, ["127.0.0.1", "localhost"], ["left"], 30)
    return dome, other


def _creds(folder: Path, name: str) -> Any:
    from wxsky.share.credentials import Credentials

    return Credentials(
        str(folder / "ca.pem"), str(folder / f"{name}.pem"), str(folder / f"{name}.key")
    )


def _raw(endpoint: str, tls: dict[str, Any] | None = None) -> Any:
    """A Zenoh session of the test's own, connecting to `endpoint`."""
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps("peer"))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("listen/endpoints", "[]")
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    for key, value in (tls or {}).items():
        cfg.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    return zenoh.open(cfg)


class Inbox:
    """What a subscriber got, with an event per arrival."""

    def __init__(self) -> None:
        self.items: list[bytes] = []
        self.arrived = threading.Event()

    def __call__(self, payload: bytes) -> None:
        self.items.append(payload)
        self.arrived.set()


@pytest.fixture
def master(certs: tuple[Path, Path]) -> Iterator[Any]:
    from wxsky.share.zenoh_bus import ShareBus

    endpoint = f"tls/127.0.0.1:{free_port()}"
    bus = ShareBus(
        endpoint, role="master", site=SITE, name="master", credentials=_creds(certs[0], "master")
    )
    try:
        bus.claim_master(MASTER_ID)
        bus.serve(lambda: b"the state", lambda: b"the clock")
        yield bus
    finally:
        bus.close()


def test_a_channel_with_the_domes_certificate_joins_and_may_do_only_a_channels_part(
    certs: tuple[Path, Path], master: Any
) -> None:
    from wxsky.share.zenoh_bus import ShareBus

    healths: list[str] = []
    master.on_health(lambda name, _payload: healths.append(name))
    forged_states = Inbox()
    master._subscribe(master.key("state"), forged_states)  # what reaches the master's side
    with ShareBus(
        master.endpoint,
        role="channel",
        site=SITE,
        name="left",
        credentials=_creds(certs[0], "left"),
    ) as left:
        assert left.master_alive(wait_s=HANG_S)
        assert left.fetch_state() == b"the state"
        pong = left.ping()
        assert pong is not None and pong[1] == b"the clock"
        ticks = Inbox()
        left.on_tick(ticks)
        wait_for("the tick subscription", lambda: _put_until(master.publish_tick, ticks))
        left.announce_channel()
        wait_for("the channel's health", lambda: _put(left.publish_health, healths, "left"))
        # A channel's certificate does not make it a master: its state and a master token of
        # its own are refused by the master's access control.
        left._state_pub.put(b"forged")
        token = left._session.liveliness().declare_token(left.key("alive", "master", "f" * 16))
        left.publish_health(b"after")  # ordered after the forgeries on the same link
        wait_for("the health after", lambda: len(healths) >= 2)
        assert forged_states.items == []
        masters = list(master._session.liveliness().get(master.key("alive", "master", "*")))
        assert [str(r.ok.key_expr) for r in masters if r.ok is not None] == [
            master.key("alive", "master", MASTER_ID)
        ]
        token.undeclare()  # type: ignore[no-untyped-call]


def _put_until(publish: Any, inbox: Inbox) -> bool:
    publish(b"tick")
    return inbox.arrived.wait(0.2)


def _put(publish: Any, seen: list[str], name: str) -> bool:
    publish(b"health")
    time.sleep(0.1)
    return name in seen


@pytest.mark.parametrize("who", ["no certificate", "tcp", "another CA's certificate"])
def test_a_session_without_the_domes_certificate_can_neither_subscribe_nor_publish(
    certs: tuple[Path, Path], master: Any, who: str
) -> None:
    dome, other = certs
    endpoint = master.endpoint
    tls: dict[str, Any] | None = None
    if who == "tcp":
        endpoint = endpoint.replace("tls/", "tcp/")
    elif who == "no certificate":
        tls = {"root_ca_certificate": str(dome / "ca.pem")}
    else:
        tls = {
            "root_ca_certificate": str(other / "ca.pem"),
            "connect_certificate": str(other / "left.pem"),
            "connect_private_key": str(other / "left.key"),
            "enable_mtls": True,
        }
    got = Inbox()
    healths: list[str] = []
    master.on_health(lambda name, _payload: healths.append(name))
    session = _raw(endpoint, tls)
    try:
        # The master's ticks (the session's own puts come back to it locally: not those).
        sub = session.declare_subscriber(f"wxsky/{SITE}/clock", lambda s: got(s.payload.to_bytes()))
        alive = list(session.liveliness().get(f"wxsky/{SITE}/alive/**", timeout=1.0))
        assert [r for r in alive if r.ok is not None] == []
        for _ in range(10):
            master.publish_tick(b"tick")
            session.put(f"wxsky/{SITE}/health/stranger", b"x")
            session.put(f"wxsky/{SITE}/state", b"forged")
            time.sleep(0.05)
        assert not got.arrived.wait(0.5)
        assert healths == []
        sub.undeclare()
    finally:
        session.close()


@pytest.mark.gl  # the daemons draw every frame
def test_a_channel_with_a_wrong_certificate_is_refused_with_one_log_line(
    tmp_path: Path, certs: tuple[Path, Path]
) -> None:
    dome, other = certs
    endpoint = f"tls/127.0.0.1:{free_port()}"
    share = f"zenoh:{endpoint}"

    def tls(section: str, folder: Path, name: str) -> str:
        pem, key = folder / f"{name}.pem", folder / f"{name}.key"
        return (
            f"[{section}]\nca_certificate = '{folder / 'ca.pem'}'\n"
            f"certificate = '{pem}'\nprivate_key = '{key}'\n"
        )

    for name in ("master", "left", "right"):
        (tmp_path / name).mkdir()
    specs = [
        DaemonSpec(tmp_path / "master", SMALL + tls("share", dome, "master"), ("--share", share)),
        DaemonSpec(
            tmp_path / "left", SMALL + tls("channel", dome, "left"), channel_args(share, "left", 0)
        ),
        DaemonSpec(
            tmp_path / "right",
            SMALL + tls("channel", other, "left"),
            channel_args(share, "right", 60.0),
        ),
    ]
    with running_daemons(specs) as (master, left, right):
        wait_for(
            "the channel with the dome's certificate joined",
            lambda: (
                (s := status(left))["channel"]["master_alive"]
                and s["sky_id"] == status(master)["sky_id"]
            ),
        )
        wait_for("the refused channel's line", lambda: "no sky master" in right.log())
        assert right.log().count("no sky master") == 1
        assert "refused this channel's certificate" in right.log()
        assert not status(right)["channel"]["master_alive"]
        assert "right" not in status(master)["channel"]["peers"]


def _config_error(tmp_path: Path, text: str) -> str:
    path = tmp_path / "wxsky.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    return str(err.value)


def test_a_bus_beyond_loopback_needs_credentials_or_allow_insecure(tmp_path: Path) -> None:
    error = _config_error(tmp_path, '[share]\nendpoint = "tcp/0.0.0.0:7447"\n')
    assert "share.endpoint" in error and "allow_insecure" in error and "\n" not in error
    error = _config_error(tmp_path, '[channel]\njoin = "tcp/10.0.0.1:7447"\nname = "left"\n')
    assert "channel.join" in error and "not a loopback address" in error
    written = tmp_path / "insecure.toml"
    written.write_text('[share]\nendpoint = "tcp/0.0.0.0:7447"\nallow_insecure = true\n')
    assert load_config(written).share.allow_insecure
    for loopback in ("tcp/127.0.0.1:7447", "tcp/[::1]:7447", "tcp/localhost:7447"):
        written.write_text(f'[share]\nendpoint = "{loopback}"\n')
        assert load_config(written).share.endpoint == loopback
    # Credentials: all three, on a tls/ endpoint.
    error = _config_error(
        tmp_path, '[share]\nendpoint = "tls/10.0.0.1:7447"\nca_certificate = "ca.pem"\n'
    )
    assert "share.certificate" in error and "all three" in error
    error = _config_error(
        tmp_path,
        '[share]\nendpoint = "tcp/10.0.0.1:7447"\nca_certificate = "a"\ncertificate = "b"\n'
        'private_key = "c"\n',
    )
    assert "share.endpoint" in error and "tls/" in error
    error = _config_error(tmp_path, '[channel]\njoin = "tcp/127.0.0.1:7447"\nname = "master"\n')
    assert "channel.name" in error and "sky master" in error
    # The command line goes through the same check: one line, exit status 2.
    run = subprocess.run(
        [sys.executable, "-m", "wxsky", "run", "--share", f"zenoh:tcp/0.0.0.0:{free_port()}"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wxsky: error:") and "allow_insecure" in lines[0]
