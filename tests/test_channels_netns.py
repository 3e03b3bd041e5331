"""A sky master and two display channels on three "machines": network namespaces the test
makes itself (each with a veth to a bridge in a fourth, the switch), removed afterwards. The
channels join over the namespaces' network, see the master cut off when its link goes down,
keep drawing, and follow it again, new weather included, when the link comes back. Skips
where namespaces cannot be made (not root, no `ip`, no bridge support)."""

from __future__ import annotations

import contextlib
import shutil
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from daemon_harness import RunningDaemon, running_daemon
from test_channels import SMALL as LOOPBACK_SMALL
from test_channels import channel_args, status, wait_for

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed")

# The daemons draw every frame.
pytestmark = pytest.mark.gl

# Beyond loopback a bus without credentials is refused unless written down as meant (issue
# 40): these namespaces are a private test network.
SMALL = LOOPBACK_SMALL + "[share]\nallow_insecure = true\n[channel]\nallow_insecure = true\n"


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=10)


@contextlib.contextmanager
def network(hosts: list[str]) -> Iterator[dict[str, tuple[str, str]]]:
    """Namespaces named after `hosts`, each with eth0 on 10.213.7.0/24 bridged in a switch
    namespace: {host: (namespace, address)}. Everything is deleted on the way out."""
    if sys.platform != "linux" or shutil.which("ip") is None:
        pytest.skip("network namespaces need Linux and iproute2's ip")
    tag = uuid.uuid4().hex[:6]
    switch = f"wxsw-{tag}"
    made: list[str] = []
    try:
        try:
            _ip("netns", "add", switch)
        except (subprocess.CalledProcessError, OSError) as exc:
            reason = (
                exc.stderr.decode().strip()
                if isinstance(exc, subprocess.CalledProcessError)
                else exc
            )
            pytest.skip(f"cannot make a network namespace here: {reason}")
        made.append(switch)
        try:
            _ip("-n", switch, "link", "add", "br0", "type", "bridge")
        except subprocess.CalledProcessError as exc:
            pytest.skip(f"cannot make a bridge here: {exc.stderr.decode().strip()}")
        _ip("-n", switch, "link", "set", "br0", "up")
        out: dict[str, tuple[str, str]] = {}
        for i, host in enumerate(hosts, start=1):
            ns, port, addr = f"wx{host[:3]}-{tag}", f"p{i}", f"10.213.7.{i}"
            _ip("netns", "add", ns)
            made.append(ns)
            _ip(
                "-n",
                ns,
                "link",
                "add",
                "eth0",
                "type",
                "veth",
                "peer",
                "name",
                port,
                "netns",
                switch,
            )
            _ip("-n", ns, "addr", "add", f"{addr}/24", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "up")
            _ip("-n", ns, "link", "set", "lo", "up")
            _ip("-n", switch, "link", "set", port, "master", "br0")
            _ip("-n", switch, "link", "set", port, "up")
            out[host] = (ns, addr)
        yield out
    finally:
        for ns in reversed(made):
            with contextlib.suppress(subprocess.CalledProcessError, OSError):
                _ip("netns", "del", ns)


def _port_of(hosts: dict[str, tuple[str, str]], host: str) -> str:
    return f"p{list(hosts).index(host) + 1}"


def test_channels_in_other_namespaces_follow_the_master_across_a_partition(tmp_path: Path) -> None:
    with network(["master", "left", "right"]) as hosts:
        switch = "wxsw-" + hosts["master"][0].rsplit("-", 1)[1]
        endpoint = f"tcp/{hosts['master'][1]}:7447"
        share = f"zenoh:{endpoint}"
        for name in hosts:
            (tmp_path / name).mkdir()

        def inside(host: str) -> tuple[str, ...]:
            return ("ip", "netns", "exec", hosts[host][0])

        with (
            running_daemon(
                tmp_path / "master",
                SMALL,
                ("--share", share, "--preset", "fair-cumulus"),
                prefix=inside("master"),
            ) as master,
            running_daemon(
                tmp_path / "left", SMALL, channel_args(share, "left", -60.0), prefix=inside("left")
            ) as left,
            running_daemon(
                tmp_path / "right",
                SMALL,
                channel_args(share, "right", 60.0),
                prefix=inside("right"),
            ) as right,
        ):
            channels: tuple[RunningDaemon, ...] = (left, right)

            def following() -> bool:
                sky = status(master)["sky_id"]
                return all(
                    (s := status(c))["channel"]["master_alive"] and s["sky_id"] == sky
                    for c in channels
                )

            wait_for("channels following across namespaces", following)
            for c in channels:
                assert status(c)["channel"]["endpoint"] == endpoint
            # The master's link goes down: the channels notice and keep drawing (how soon is
            # printed, for a reader; a busy machine may take longer, so nothing asserts it).
            cut = _port_of(hosts, "master")
            _ip("-n", switch, "link", "set", cut, "down")
            start = time.monotonic()
            for c in channels:
                wait_for(
                    "master_alive false across the cut",
                    lambda c=c: not status(c)["channel"]["master_alive"],  # type: ignore[misc]
                )
            noticed_s = time.monotonic() - start
            frames = [status(c)["frames_published"] for c in channels]
            with master.client() as m:  # the weather changes while they cannot hear it
                m.call("apply_preset", {"name": "overcast-stratus"})
            for c, before in zip(channels, frames, strict=True):
                wait_for(  # still drawing
                    "frames during the cut",
                    lambda c=c, before=before: (  # type: ignore[misc]
                        status(c)["frames_published"] > before + 5
                    ),
                )
            want = status(master)["target"]["layers"]
            assert all(status(c)["target"]["layers"] != want for c in channels)
            # The link comes back: followed again, the new weather with it.
            _ip("-n", switch, "link", "set", cut, "up")
            healed = time.monotonic()
            wait_for("followed again after the heal", following)
            for c in channels:
                wait_for(
                    "the weather set during the cut",
                    lambda c=c: status(c)["target"]["layers"] == want,  # type: ignore[misc]
                )
            recovered_s = time.monotonic() - healed
            print(
                f"partition noticed in {noticed_s:.2f} s, followed {recovered_s:.2f} s after heal"
            )
