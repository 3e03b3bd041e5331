"""The serial link on real pty pairs, a real TCP socket and pyserial's loop://: values arrive,
bad input is counted, a pulled device is reopened, and close() stops the reader."""

from __future__ import annotations

import random
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from cockpit_helpers import Posted, Pty, wait_until

from wxsky.inputs.serial_link import SerialLink
from wxsky.protocols.nmea import sentence
from wxsky.weather.cockpit import TEMPERATURE, WIND_DIR, WIND_SPEED, layer_key


@pytest.fixture
def pty() -> Iterator[Pty]:
    p = Pty()
    yield p
    p.close()


def open_link(url: str, **kwargs: object) -> tuple[SerialLink, Posted]:
    link = SerialLink(url, **kwargs)  # type: ignore[arg-type]
    posted = Posted()
    link.start(posted)
    assert wait_until(lambda: link.stats.ok), link.stats.to_dict()
    return link, posted


def test_sentences_on_a_pty_become_values(pty: Pty) -> None:
    link, posted = open_link(pty.path, baud=4800)
    try:
        pty.write(sentence("WIMWV,090.0,T,10.0,M,A"))
        pty.write(sentence("PWXCL,2,6,5000,1500,ALTOCUMULUS"))
        assert posted.wait_for(lambda: layer_key(2, "cover_oktas") in posted.values())
        values = posted.values()
        assert values[WIND_DIR] == 90.0 and values[WIND_SPEED] == 10.0
        assert values[layer_key(2, "base_m")] == pytest.approx(1524.0)
        status = link.stats.to_dict()
        assert (status["kind"], status["ok"], status["messages"], status["errors"]) == (
            "serial",
            True,
            2,
            0,
        )
        assert status["last_message_s"] is not None and status["last_message_s"] < 5.0
    finally:
        assert link.close()
    assert link.close()  # idempotent


def test_bad_input_is_counted_and_good_values_survive(pty: Pty) -> None:
    link, posted = open_link(pty.path)
    rng = random.Random(4)
    try:
        pty.write(bytes(rng.getrandbits(8) for _ in range(4000)) + b"\r\n")
        pty.write(b"X" * 10_000)  # a 10 kB line without a newline
        pty.write(b"\r\n")
        pty.write(b"$WIMWV,270.0,T,12.5,M,A*00\r\n")  # bad checksum
        pty.write(sentence("WIMWV,270.0,T,999,M,A"))  # out of range
        pty.write(sentence("PWXCL,7,4,3000,1000"))  # no layer 7
        pty.write(sentence("GPGSV,3,1,11"))  # not a sentence wxsky uses
        pty.write(b"12:00:01.123 " + sentence("WIMDA,,,1.0132,B,21.5,C,,,,,,,,,,,,,,"))
        assert posted.wait_for(lambda: TEMPERATURE in posted.values())
        values = posted.values()
        assert values[TEMPERATURE] == 21.5
        assert WIND_SPEED not in values  # the 999 m/s never got through
        assert link.stats.errors >= 4
        assert link.stats.to_dict()["ignored"] >= 1
        assert link.stats.ok
    finally:
        link.close()


def test_fields_not_allowed_are_not_posted(pty: Pty) -> None:
    link, posted = open_link(pty.path, fields=("clouds",))
    try:
        pty.write(sentence("WIMWV,090.0,T,10.0,M,A"))
        pty.write(sentence("PWXCL,1,3,3000,1000"))
        assert posted.wait_for(lambda: layer_key(1, "cover_oktas") in posted.values())
        assert WIND_SPEED not in posted.values()
        assert link.stats.to_dict()["ignored"] == 1
    finally:
        link.close()


def test_a_pulled_device_is_reopened(tmp_path: Path) -> None:
    # A udev by-id symlink stands for the device: the replug gets a new pty, the same name.
    first = Pty()
    device = tmp_path / "ttyUSB-panel"
    device.symlink_to(first.path)
    link, posted = open_link(str(device))
    second: Pty | None = None
    try:
        first.write(sentence("WIMWV,010.0,T,3.0,M,A"))
        assert posted.wait_for(lambda: posted.values().get(WIND_DIR) == 10.0)
        first.close()  # the cable is pulled
        assert wait_until(lambda: not link.stats.ok)
        state = link.stats.to_dict()["state"]
        assert state.startswith(("lost", "cannot open")), state
        second = Pty()
        device.unlink()
        device.symlink_to(second.path)
        assert wait_until(lambda: link.stats.ok)
        second.write(sentence("WIMWV,020.0,T,4.0,M,A"))
        assert posted.wait_for(lambda: posted.values().get(WIND_DIR) == 20.0)
        assert link.stats.to_dict()["reopens"] >= 1
    finally:
        assert link.close()
        if second is not None:
            second.close()


def test_a_missing_device_is_retried_until_it_appears(tmp_path: Path) -> None:
    device = tmp_path / "not-yet"
    link = SerialLink(str(device))
    posted = Posted()
    link.start(posted)
    pty = Pty()
    try:
        assert wait_until(lambda: link.stats.to_dict()["state"].startswith("cannot open"))
        assert not link.stats.ok
        device.symlink_to(pty.path)
        assert wait_until(lambda: link.stats.ok)
        pty.write(sentence("GPZDA,134322.00,12,06,1987,00,00"))
        assert posted.wait_for(lambda: any(u.time_utc for u in posted.updates))
    finally:
        assert link.close()
        pty.close()


def test_socket_url_reads_from_a_tcp_device() -> None:
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    accepted: list[socket.socket] = []
    thread = threading.Thread(target=lambda: accepted.append(server.accept()[0]))
    thread.start()
    link, posted = open_link(f"socket://127.0.0.1:{port}")
    try:
        thread.join(5.0)
        accepted[0].sendall(sentence("WIMWD,200.0,T,,M,,N,7.5,M"))
        assert posted.wait_for(lambda: posted.values().get(WIND_DIR) == 200.0)
        assert posted.values()[WIND_SPEED] == 7.5
    finally:
        link.close()
        for conn in accepted:
            conn.close()
        server.close()


def test_loop_url_echoes_what_the_port_writes() -> None:
    link, posted = open_link("loop://")
    try:
        # loop:// is a port that hears itself: what the link's own port writes comes back.
        link._port.write(sentence("WIMWV,045.0,T,20.0,N,A"))
        assert posted.wait_for(lambda: WIND_DIR in posted.values())
        assert posted.values()[WIND_SPEED] == pytest.approx(20.0 * 1852.0 / 3600.0)
    finally:
        link.close()


def test_two_values_of_a_field_in_one_read_count_one_superseded(pty: Pty) -> None:
    link, posted = open_link(pty.path)
    try:
        # One write: the reader gets both winds in one read, as a reader that fell behind does.
        pty.write(sentence("WIMWV,090.0,T,10.0,M,A") + sentence("WIMWV,120.0,T,12.0,M,A"))
        assert posted.wait_for(lambda: posted.values().get(WIND_DIR) == 120.0)
        pty.write(sentence("WIMWV,130.0,T,13.0,M,A"))  # a later read refreshes the detail
        assert posted.wait_for(lambda: posted.values().get(WIND_DIR) == 130.0)
        # The first wind (direction and speed, one update) was replaced before being applied.
        assert link.stats.to_dict()["superseded"] == 1
    finally:
        link.close()
