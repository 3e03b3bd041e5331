"""Issue 40: a CIGI host's datagrams cost the daemon a bounded amount of work, whatever they
hold. A real `wxsky run --cigi` and a host on a real UDP socket on loopback: a 64 KB datagram
of conditions requests is answered a bounded number a frame while the frames go on, the
rest dropped and counted one by one; 20,000 regions are capped with the least recently
touched evicted and counted; an ownship the camera refuses is counted. No durations are
asserted: the frames' own numbers show the frames went on."""

from __future__ import annotations

import asyncio
import time
from collections import Counter
from collections.abc import Iterator, Sequence
from datetime import datetime
from typing import Any

import pytest
from daemon_harness import HANG_S, RunningDaemon, running_daemon

from wxsky.inputs.cigi_link import CigiHostSocket, CigiIg, IgSettings
from wxsky.protocols.cigi import Packet, encode_datagram, make
from wxsky.protocols.cigi_eye import Eye
from wxsky.weather.state import WeatherPatch

LSZH = (47.4647, 8.5492)
REQUESTS_PER_FRAME = 64  # [cigi] requests_per_frame's default
MAX_QUEUED = 256  # requests that may wait: 4 frames' worth, at least 256
MAX_REGIONS = 256  # [cigi] max_regions's default
# The most a UDP datagram over IPv4 carries.
UDP_MAX = 65_507
CONFIG = """
[camera]
width = 160
height = 90
"""


@pytest.fixture(scope="module")
def daemon(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningDaemon]:
    tmp = tmp_path_factory.mktemp("cigi-bounds")
    with running_daemon(tmp, CONFIG, ("--preset", "clear", "--cigi", "udp:127.0.0.1:0")) as d:
        yield d


def status(d: RunningDaemon) -> dict[str, Any]:
    with d.client() as c:
        result: dict[str, Any] = c.call("status")
    return result


def cigi_input(d: RunningDaemon) -> dict[str, Any]:
    found: list[dict[str, Any]] = [i for i in status(d)["inputs"] if i["kind"] == "cigi"]
    assert len(found) == 1
    return found[0]


def ig_address(d: RunningDaemon) -> tuple[str, int]:
    host, port = cigi_input(d)["listen"].rsplit(":", 1)
    return host, int(port)


def ownship(alt_m: float = 700.0) -> Packet:
    return make(
        "entity_control",
        entity_id=0,
        entity_state=1,
        lat_deg=LSZH[0],
        lon_deg=LSZH[1],
        alt_m=alt_m,
    )


STRATUS = make(
    "weather_control",
    layer_id=1,
    weather_enable=1,
    cloud_type=10,
    coverage_pct=100.0,
    base_elevation_m=1000.0,
    thickness_m=600.0,
)


def request(request_id: int, alt_m: float = 1300.0) -> Packet:
    return make(
        "environmental_conditions_request",
        request_weather=1,
        request_id=request_id % 256,
        lat_deg=LSZH[0] + 0.001 * (request_id % 50),
        lon_deg=LSZH[1],
        alt_m=alt_m,
    )


def send_and_wait(host: CigiHostSocket, number: int, *body: Packet) -> list[Packet]:
    """Send one message as host frame `number` and wait for a Start of Frame of a frame that
    applied it; returns every packet the IG sent meanwhile."""
    data = encode_datagram([make("ig_control", ig_mode=1, host_frame_number=number), *body])
    assert len(data) <= UDP_MAX
    host.send_bytes(data)
    got: list[Packet] = []
    deadline = time.monotonic() + HANG_S
    while True:
        answer = host.receive(max(0.0, deadline - time.monotonic()))
        assert answer is not None, f"no Start of Frame for host frame {number}"
        packets = answer[0].packets
        got += packets
        first = packets[0] if packets else None
        if (
            first is not None
            and first.key == "start_of_frame"
            and int(first["last_host_frame_number"]) == number
        ):
            return got


@pytest.mark.gl
def test_a_64_kb_datagram_of_requests_is_answered_a_bounded_number_a_frame(
    daemon: RunningDaemon,
) -> None:
    """Before: all 2,046 answers were computed on the event loop when the datagram came (the
    frames stopped for seconds), then all but 256 thrown away and counted as one."""
    flood = [request(i) for i in range((UDP_MAX - 24) // 32)]
    assert len(flood) == 2046
    with CigiHostSocket(ig_address(daemon)) as host:
        send_and_wait(host, 1, ownship(), STRATUS)
        before = cigi_input(daemon)
        frames_before = status(daemon)["frames_published"]
        host.send_bytes(
            encode_datagram([make("ig_control", ig_mode=1, host_frame_number=2), *flood])
        )
        # Every answer that was not dropped arrives, each Start of Frame carrying some.
        per_frame: Counter[int] = Counter()
        frame_number = 0
        deadline = time.monotonic() + HANG_S
        while sum(per_frame.values()) < MAX_QUEUED:
            got = host.receive(max(0.0, deadline - time.monotonic()))
            assert got is not None, f"only {sum(per_frame.values())} answers came"
            for p in got[0].packets:
                if p.key == "start_of_frame":
                    frame_number = int(p["ig_frame_number"])
                elif p.key == "weather_conditions_response":
                    per_frame[frame_number] += 1
        after = cigi_input(daemon)
        frames_after = status(daemon)["frames_published"]
    # At most requests_per_frame answers a frame (one each: weather only): the work a frame
    # waits on is bounded, and the frames went on publishing while the queue drained.
    assert max(per_frame.values()) <= REQUESTS_PER_FRAME
    assert len(per_frame) >= MAX_QUEUED // REQUESTS_PER_FRAME
    assert frames_after - frames_before >= MAX_QUEUED // REQUESTS_PER_FRAME
    # What did not fit the queue was dropped and counted per request, not per datagram.
    dropped = after["dropped"].get("requests_full", 0) - before["dropped"].get("requests_full", 0)
    assert dropped == len(flood) - MAX_QUEUED
    assert after["requests_answered"] - before["requests_answered"] == MAX_QUEUED
    assert after["requests_queued"] == 0
    assert after["ok"]


@pytest.mark.gl
def test_20000_regions_are_capped_and_a_normal_datagram_is_still_answered(
    daemon: RunningDaemon,
) -> None:
    """Before: every region and its layers were kept until a reset, each ordinary datagram
    costing more with them."""
    count = 20_000
    per_datagram = (UDP_MAX - 24) // 48
    ids = list(range(count))
    with CigiHostSocket(ig_address(daemon)) as host:
        number = 100
        send_and_wait(host, number, ownship())
        before = cigi_input(daemon)
        for start in range(0, count, per_datagram):
            number += 1
            body = [
                make(
                    "environmental_region_control",
                    region_id=i,
                    region_state=1,
                    lat_deg=LSZH[0] + (i % 100) * 0.01,
                    lon_deg=LSZH[1] + (i // 100) * 0.01,
                    size_x_m=500.0,
                    size_y_m=500.0,
                )
                for i in ids[start : start + per_datagram]
            ]
            send_and_wait(host, number, *body)
        # 300 region ids with a layer and no region; region 0 touched last: it stays.
        layered = [
            make(
                "weather_control",
                scope=1,
                entity_or_region_id=30_000 + k,
                layer_id=1,
                weather_enable=1,
                cloud_type=10,
                coverage_pct=50.0,
                base_elevation_m=1000.0,
                thickness_m=300.0,
            )
            for k in range(300)
        ]
        region_0 = make(
            "environmental_region_control",
            region_id=0,
            region_state=1,
            lat_deg=LSZH[0],
            lon_deg=LSZH[1],
            size_x_m=500.0,
            size_y_m=500.0,
        )
        number += 1
        send_and_wait(host, number, *layered, region_0)
        capped = cigi_input(daemon)
        # An ordinary datagram is still folded in and answered.
        number += 1
        answers = send_and_wait(host, number, ownship(), request(7))
        answers += send_and_wait(host, number + 1, ownship())
    assert any(p.key == "weather_conditions_response" and p["request_id"] == 7 for p in answers)
    # Region 0 and the last 255 layered ids are kept, besides the global layers from before.
    assert before["regions"] == 0
    assert capped["regions"] == 1 and capped["layers"] == before["layers"] + MAX_REGIONS - 1
    evicted = capped["regions_evicted"] - before["regions_evicted"]
    # Region 0 was evicted with the first ones and came back last: 20,301 arrivals in all.
    assert evicted == count + 300 + 1 - MAX_REGIONS


@pytest.mark.gl
def test_an_ownship_the_camera_refuses_is_counted(daemon: RunningDaemon) -> None:
    """Before: logged, and counted nowhere."""
    with CigiHostSocket(ig_address(daemon)) as host:
        send_and_wait(host, 500, ownship())
        before = cigi_input(daemon)
        send_and_wait(host, 501, ownship(alt_m=50_000.0))  # above the camera's 30 km
        after = cigi_input(daemon)
        send_and_wait(host, 502, ownship())
    refused = after["dropped"].get("camera_refused", 0) - before["dropped"].get("camera_refused", 0)
    assert refused == 1
    assert after["errors"] > before["errors"]
    assert "ownship not placed" in after["last_error"]


class _Answers:
    """The daemon's side of an in-process listener: one request id is a wxsky defect."""

    def cigi_weather(self, patch: WeatherPatch) -> None:
        pass

    def cigi_heard(self) -> bool:
        return True

    def cigi_camera(self, eye: Eye) -> str | None:
        return None

    def cigi_clock(self, time_utc: datetime | None, running: bool | None) -> None:
        pass

    def cigi_answers(self, requests: Sequence[Packet]) -> list[Packet]:
        if any(r["request_id"] == 13 for r in requests):
            raise RuntimeError("a defect")
        return [make("weather_conditions_response", request_id=r["request_id"]) for r in requests]


def test_answering_is_bounded_per_call_and_a_defect_in_one_answer_is_counted() -> None:
    """The queue a listener keeps, on a real socket in this process: requests wait until
    the daemon asks for answers (after a frame), at most as many as it asks; an answer that
    raises is counted as `internal_error` and the others still go."""

    async def run() -> tuple[list[int], dict[str, Any]]:
        ig = CigiIg(IgSettings(("127.0.0.1", 0)), _Answers())
        await ig.start()
        try:
            with CigiHostSocket(("127.0.0.1", ig.port)) as host:
                host.send(
                    [
                        make("ig_control", ig_mode=1, host_frame_number=1),
                        *map(request, (12, 13, 14)),
                    ]
                )
                for _ in range(int(HANG_S / 0.01)):
                    await asyncio.sleep(0.01)
                    if ig.stats.messages:
                        break
                waiting = [ig.queued_requests]
                waiting.append(ig.answer_queued(2))  # 12, then 13 raises
                waiting.append(ig.answer_queued(5))  # 14: what is left
                waiting.append(ig.queued_requests)
            return waiting, ig.detail()
        finally:
            ig.close()

    waiting, detail = asyncio.run(run())
    assert waiting == [3, 2, 1, 0]
    assert detail["requests_answered"] == 2 and detail["dropped"] == {"internal_error": 1}
