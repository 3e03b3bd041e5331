"""The CAN link on python-can's virtual bus (in process) and udp_multicast (across processes),
and a SocketCAN test that skips itself on machines without kernel CAN."""

from __future__ import annotations

import socket
import subprocess
import sys
import textwrap
import uuid
from collections.abc import Iterator
from datetime import date

import can
import pytest
from cockpit_helpers import Posted, wait_until

from wxsky.inputs.can_link import CanLink
from wxsky.protocols.canaerospace import encode_date, encode_float, encode_time
from wxsky.weather.cockpit import QNH, WIND_DIR, WIND_SPEED, layer_key


def frame(can_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False)


@pytest.fixture
def channel() -> str:
    return f"wxsky-test-{uuid.uuid4().hex[:8]}"


@pytest.fixture
def sender(channel: str) -> Iterator[can.BusABC]:
    with can.Bus(interface="virtual", channel=channel) as bus:
        yield bus


def start(link: CanLink) -> Posted:
    posted = Posted()
    link.start(posted)
    assert wait_until(lambda: link.stats.ok), link.stats.to_dict()
    return posted


def test_frames_on_a_virtual_bus_become_values(channel: str, sender: can.BusABC) -> None:
    with CanLink("virtual", channel) as link:
        posted = start(link)
        sender.send(frame(333, encode_float(333, 12.5, node_id=42, message_code=7)))
        sender.send(frame(334, encode_float(334, -90.0)))
        sender.send(frame(319, encode_float(319, 1001.0)))
        sender.send(frame(1500, encode_float(1500, 5.0, service_code=2)))
        sender.send(frame(1200, encode_time(13, 43, 22)))
        sender.send(frame(1206, encode_date(date(1987, 6, 12))))
        assert posted.wait_for(lambda: any(u.date_utc for u in posted.updates))
        values = posted.values()
        assert values[WIND_SPEED] == 12.5
        assert values[WIND_DIR] == 270.0
        assert values[QNH] == 1001.0
        assert values[layer_key(2, "cover_oktas")] == 5.0
        assert any(u.time_of_day_s == 13 * 3600 + 43 * 60 + 22 for u in posted.updates)
        status = link.stats.to_dict()
        assert (status["kind"], status["messages"], status["errors"]) == ("can", 6, 0)


def test_bad_frames_are_counted_and_never_posted(channel: str, sender: can.BusABC) -> None:
    with CanLink("virtual", channel) as link:
        posted = start(link)
        sender.send(frame(333, encode_float(333, 999.0)))  # wind 999 m/s
        sender.send(frame(333, encode_float(333, float("nan"))))
        sender.send(frame(333, b"\x01\x02"))  # wrong DLC
        sender.send(frame(1500, encode_float(1500, 9.0, service_code=1)))  # 9 oktas
        sender.send(frame(1500, encode_float(1500, 4.0, service_code=7)))  # layer 7
        sender.send(frame(1200, encode_time(25, 0, 0)))  # hour 25
        sender.send(frame(0x123, bytes(8)))  # another avionics box's id
        sender.send(frame(334, encode_float(334, 45.0)))
        assert posted.wait_for(lambda: WIND_DIR in posted.values())
        assert posted.values() == {WIND_DIR: 45.0}
        assert all(u.time_of_day_s is None for u in posted.updates)
        assert link.stats.errors == 6
        assert link.stats.to_dict()["ignored"] == 1


def test_node_filter(channel: str, sender: can.BusABC) -> None:
    with CanLink("virtual", channel, node_ids=(5,)) as link:
        posted = start(link)
        sender.send(frame(333, encode_float(333, 3.0, node_id=9)))
        sender.send(frame(333, encode_float(333, 4.0, node_id=5)))
        assert posted.wait_for(lambda: WIND_SPEED in posted.values())
        assert posted.values()[WIND_SPEED] == 4.0
        assert link.stats.to_dict()["ignored"] == 1


def test_a_lost_bus_is_reopened(channel: str, sender: can.BusABC) -> None:
    with CanLink("virtual", channel) as link:
        posted = start(link)
        link._bus.shutdown()  # the adapter goes away under the reader
        assert wait_until(lambda: link.stats.to_dict()["reopens"] >= 1)
        assert wait_until(lambda: link.stats.ok)
        sender.send(frame(333, encode_float(333, 6.0)))
        assert posted.wait_for(lambda: posted.values().get(WIND_SPEED) == 6.0)


def test_an_interface_that_cannot_open_is_reported_not_raised() -> None:
    with CanLink("socketcan", "wxsky-no-such-can") as link:
        link.start(Posted())
        assert wait_until(lambda: link.stats.to_dict()["state"].startswith("cannot open"))
        assert not link.stats.ok


SENDER = textwrap.dedent(
    """
    import sys, time, can
    from wxsky.protocols.canaerospace import encode_float
    group = sys.argv[1]
    with can.Bus(interface="udp_multicast", channel=group) as bus:
        for i in range(60):  # resend until the reader has surely joined the group
            bus.send(can.Message(arbitration_id=333, data=encode_float(333, 8.5),
                                 is_extended_id=False))
            time.sleep(0.05)
    """
)


# python-can's udp_multicast hears every group on its port: one such test at a time.
@pytest.mark.xdist_group("udp_multicast")
def test_udp_multicast_across_processes() -> None:
    group = "239.74.163.2"
    try:
        link = CanLink("udp_multicast", group)
        posted = Posted()
        link.start(posted)
        if not wait_until(lambda: link.stats.ok, timeout_s=5.0):
            link.close()
            pytest.skip(f"no multicast on this host: {link.stats.to_dict()['state']}")
    except (can.CanError, OSError) as exc:
        pytest.skip(f"no multicast on this host: {exc}")
    try:
        proc = subprocess.run(
            [sys.executable, "-c", SENDER, group], capture_output=True, timeout=30
        )
        if proc.returncode != 0 and b"CanOperationError" in proc.stderr:
            pytest.skip(f"multicast send failed: {proc.stderr.decode()[-200:]}")
        assert proc.returncode == 0, proc.stderr.decode()
        assert posted.wait_for(lambda: posted.values().get(WIND_SPEED) == 8.5)
    finally:
        link.close()


def _have_socketcan() -> tuple[bool, str]:
    try:
        s = socket.socket(socket.PF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except (OSError, AttributeError) as exc:
        return False, f"no kernel CAN support (PF_CAN socket: {exc})"
    s.close()
    try:
        socket.if_nametoindex("vcan0")
    except OSError:
        return False, "no vcan0 interface (modprobe vcan; ip link add vcan0 type vcan)"
    return True, ""


_SOCKETCAN, _NO_SOCKETCAN = _have_socketcan()


@pytest.mark.skipif(not _SOCKETCAN, reason=_NO_SOCKETCAN)
def test_socketcan_vcan0() -> None:
    with (
        CanLink("socketcan", "vcan0") as link,
        can.Bus(interface="socketcan", channel="vcan0") as bus,
    ):
        posted = start(link)
        bus.send(frame(333, encode_float(333, 2.5)))
        assert posted.wait_for(lambda: posted.values().get(WIND_SPEED) == 2.5)
