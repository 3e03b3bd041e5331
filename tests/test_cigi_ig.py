"""wxsky as a CIGI 3.3 image generator, across processes: a real `wxsky run --cigi` and a
host on a real UDP socket, big- and little-endian; and the listener's address filter on a
real socket in this process."""

from __future__ import annotations

import asyncio
import math
import os
import re
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest
from daemon_harness import HANG_S, RunningDaemon, running_daemon, write_config

from wxsky.inputs.cigi_link import CigiHostSocket, CigiIg, IgSettings, parse_networks
from wxsky.protocols.cigi import CigiDatagram, Packet, encode_datagram, encode_packet, make
from wxsky.protocols.cigi_eye import Eye
from wxsky.weather.state import WeatherPatch

LSZH = (47.4647, 8.5492)
CONFIG = """
[camera]
width = 320
height = 180
[transition]
cover_oktas_per_min = 0.0
base_m_per_min = 0.0
wind_mps_per_s = 0.0
visibility_m_per_s = 0.0
temperature_c_per_min = 0.0
qnh_hpa_per_min = 0.0
[cigi]
hold_s = 1.5
"""


@pytest.fixture(scope="module")
def daemon(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningDaemon]:
    tmp = tmp_path_factory.mktemp("cigi")
    with running_daemon(tmp, CONFIG, ("--preset", "clear", "--cigi", "udp:127.0.0.1:0")) as d:
        yield d


def status(d: RunningDaemon) -> dict[str, Any]:
    with d.client() as c:
        result: dict[str, Any] = c.call("status")
    return result


def cigi_input(st: dict[str, Any]) -> dict[str, Any]:
    found: list[dict[str, Any]] = [i for i in st["inputs"] if i["kind"] == "cigi"]
    assert len(found) == 1
    return found[0]


def ig_address(d: RunningDaemon) -> tuple[str, int]:
    host, port = cigi_input(status(d))["listen"].rsplit(":", 1)
    return host, int(port)


def frame(number: int, *body: Packet) -> list[Packet]:
    return [make("ig_control", ig_mode=1, host_frame_number=number), *body]


STRATUS = make(
    "weather_control",
    layer_id=1,
    weather_enable=1,
    cloud_type=10,
    coverage_pct=100.0,
    base_elevation_m=1000.0,
    thickness_m=600.0,
)


def session_body(heading: float) -> list[Packet]:
    return [
        make(
            "entity_control",
            entity_id=0,
            entity_state=1,
            lat_deg=LSZH[0] + 0.01,
            lon_deg=LSZH[1],
            alt_m=700.0,
            yaw_deg=heading,
            pitch_deg=4.0,
        ),
        make(
            "celestial_sphere_control",
            hour=16,
            minute=20,
            date_time_valid=1,
            ephemeris_enable=1,
            date_mmddyyyy=3_15_2026,
        ),
        make(
            "atmosphere_control",
            humidity_pct=60,
            temperature_c=12.0,
            visibility_m=25_000.0,
            wind_speed_mps=4.0,
            wind_dir_deg=200.0,
            pressure_hpa=1008.0,
        ),
        STRATUS,
    ]


def drive(
    host: CigiHostSocket,
    seconds: float,
    order: str,
    body: Sequence[Packet] = (),
    start: int = 1,
    min_answers: int = 1,
) -> tuple[int, list[CigiDatagram]]:
    """Send a message every 1/30 s for `seconds`, and on until the IG has answered
    `min_answers` times (a busy machine publishes fewer frames a second), collecting what
    the IG answers up to its answer from a frame that applied the last message; returns the
    last host frame number sent and the answers."""
    answers: list[CigiDatagram] = []
    number = start
    end = time.monotonic() + seconds
    give_up = time.monotonic() + HANG_S
    while time.monotonic() < end or (len(answers) < min_answers and time.monotonic() < give_up):
        host.send(frame(number, *body), "little" if order == "little" else "big")
        tick = time.monotonic() + 1.0 / 30.0
        while (got := host.receive(max(0.0, tick - time.monotonic()))) is not None:
            answers.append(got[0])
        number += 1
    last = number - 1
    # The IG answers every frame it publishes, host or not: wait for the answer of a frame
    # that had applied the last message (a Start of Frame naming it).
    deadline = time.monotonic() + HANG_S
    while not any(_answers_to(d, last) for d in answers[-1:]):
        got = host.receive(max(0.0, deadline - time.monotonic()))
        assert got is not None, f"no Start of Frame for host frame {last}"
        answers.append(got[0])
    return last, answers


def _answers_to(answer: CigiDatagram, host_frame: int) -> bool:
    first = answer.packets[0] if answer.packets else None
    return (
        first is not None
        and first.key == "start_of_frame"
        and int(first["last_host_frame_number"]) == host_frame
    )


@pytest.mark.gl
@pytest.mark.parametrize("order", ["big", "little"])
def test_a_host_at_30_hz_gets_a_start_of_frame_for_every_frame(
    daemon: RunningDaemon, order: str
) -> None:
    with CigiHostSocket(ig_address(daemon)) as host:
        heading = 40.0 if order == "big" else 250.0
        # Host frame numbers above the other order's run: each run's must only grow.
        start = 1 if order == "big" else 100_000
        last, answers = drive(host, 3.0, order, session_body(heading), start, min_answers=8)
        me = host.address
    sofs = [d.packets[0] for d in answers if d.packets and d.packets[0].key == "start_of_frame"]
    assert len(sofs) == len(answers) >= 8
    assert all(d.byte_order == order for d in answers), "the IG answers in the host's order"
    numbers = [int(p["ig_frame_number"]) for p in sofs]
    # One for every published frame: consecutive IG frame numbers, none skipped.
    assert numbers == list(range(numbers[0], numbers[0] + len(numbers)))
    # What each frame had applied: the host's frames as they arrived (the first answer may
    # still name an earlier host's last frame: that frame had applied it).
    applied = [int(p["last_host_frame_number"]) for p in sofs[1:]]
    assert applied == sorted(applied) and start <= applied[-1] <= last
    assert all(int(p["ig_mode"]) == 1 for p in sofs)
    st = status(daemon)
    entry = cigi_input(st)
    assert entry["byte_order"] == order and entry["last_host_frame"] == last
    assert entry["host_address"] == f"{me[0]}:{me[1]}"
    target = st["target"]
    assert target["layers"] == [
        {"cover_oktas": 8.0, "base_m": 1000.0, "top_m": 1600.0, "type": "stratus"}
    ]
    assert target["sources"]["layers"] == "cigi" and target["sources"]["time_utc"] == "cigi"
    assert target["visibility_m"] == 25_000.0 and target["qnh_hpa"] == pytest.approx(1008.0)
    clock = datetime.fromisoformat(st["weather"]["time_utc"].replace("Z", "+00:00"))
    assert (clock.year, clock.month, clock.day, clock.hour, clock.minute) == (2026, 3, 15, 16, 20)
    cam = st["camera"]
    assert cam["heading_deg"] == pytest.approx(heading, abs=1e-3)
    assert cam["pitch_deg"] == pytest.approx(4.0, abs=1e-3)
    assert cam["position_m"][2] == pytest.approx(700.0, abs=0.01)
    assert cam["position_m"][1] == pytest.approx(1105.4, abs=1.0)  # 0.01° north


@pytest.mark.gl
def test_nan_and_truncated_packets_change_nothing(daemon: RunningDaemon) -> None:
    with CigiHostSocket(ig_address(daemon)) as host:
        drive(host, 0.5, "big", session_body(10.0))
        before = status(daemon)
        bad = bytearray(
            encode_packet(
                make(
                    "weather_control",
                    layer_id=1,
                    weather_enable=1,
                    cloud_type=7,
                    coverage_pct=40.0,
                    base_elevation_m=2000.0,
                    thickness_m=800.0,
                )
            )
        )
        bad[20:24] = struct.pack(">f", math.nan)  # coverage_pct
        nan = encode_datagram(frame(5000)) + bytes(bad)
        truncated = encode_datagram(frame(5001, STRATUS))[:-9]
        host.send_bytes(nan)
        host.send_bytes(truncated)
        host.send_bytes(b"\x01\x18garbage")
        _, answers = drive(host, 0.7, "big", start=5002)
    after = status(daemon)
    assert answers, "the daemon keeps answering"
    assert after["target"]["layers"] == before["target"]["layers"]
    dropped = cigi_input(after)["dropped"]
    old = cigi_input(before)["dropped"]
    assert dropped.get("not_finite", 0) == old.get("not_finite", 0) + 1
    assert dropped.get("truncated", 0) == old.get("truncated", 0) + 1
    assert dropped.get("wrong_version", 0) >= old.get("wrong_version", 0) + 1


def answers_to(host: CigiHostSocket, alt_m: float, request_id: int) -> dict[str, Any]:
    request = make(
        "environmental_conditions_request",
        request_weather=1,
        request_aerosol=1,
        request_id=request_id,
        lat_deg=LSZH[0] + 0.01,
        lon_deg=LSZH[1],
        alt_m=alt_m,
    )
    host.send(frame(9000 + request_id, request))
    found: dict[str, Any] = {"aerosol": {}}
    deadline = time.monotonic() + HANG_S
    while time.monotonic() < deadline and "weather" not in found:
        got = host.receive(0.5)
        for p in got[0].packets if got else ():
            if p.key == "weather_conditions_response" and p["request_id"] == request_id:
                found["weather"] = p.as_dict()
            elif p.key == "aerosol_concentration_response" and p["request_id"] == request_id:
                found["aerosol"][int(p["layer_id"])] = float(p["aerosol_concentration_gpm3"])
    return found


@pytest.mark.gl
def test_conditions_are_answered_in_cloud_and_out_of_it(daemon: RunningDaemon) -> None:
    with CigiHostSocket(ig_address(daemon)) as host:
        drive(host, 0.5, "little", session_body(90.0))
        inside = answers_to(host, 1300.0, 1)
        above = answers_to(host, 3000.0, 2)
    w_in, w_out = inside["weather"], above["weather"]
    assert w_in["visibility_m"] < 600.0 and w_in["humidity_pct"] == 100
    assert inside["aerosol"][1] > 0.0
    assert w_out["visibility_m"] == 25_000.0 and above["aerosol"] == {1: 0.0}
    # Standard atmosphere from the host's 12 °C at the observer (432 m) and 1008 hPa QNH.
    assert w_out["temperature_c"] == pytest.approx(12.0 - 0.0065 * (3000.0 - 432.0), abs=0.01)
    assert w_out["pressure_hpa"] == pytest.approx(
        1008.0 * (1 - 0.0065 * 3000 / 288.15) ** 5.25588, abs=0.05
    )
    assert w_out["wind_dir_deg"] == pytest.approx(200.0, abs=0.5)


@pytest.mark.gl
def test_status_says_which_host_drives_the_ig(daemon: RunningDaemon) -> None:
    with CigiHostSocket(ig_address(daemon)) as host:
        drive(host, 0.3, "little", [*session_body(0.0), make("view_control", view_id=3)])
        me = host.address
    out = subprocess.run(
        [sys.executable, "-m", "wxsky", "status", "--control", daemon.address],
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    ).stdout
    (line,) = [x for x in out.splitlines() if x.startswith("input cigi:")]
    assert f"host {me[0]}:{me[1]} (little)" in line and "Start of Frame sent" in line
    assert re.search(r"ignored \d+ other_view", line), line


@pytest.mark.gl
def test_a_silent_host_hands_its_weather_back(daemon: RunningDaemon) -> None:
    with CigiHostSocket(ig_address(daemon)) as host:
        last, _ = drive(host, 0.3, "big", session_body(0.0))
        # The host's weather, asked for while the host still talks. (A daemon stalled for
        # longer than hold_s drops it at its next frame, before it reads what the host sent
        # meanwhile, and takes it again just after: so ask until it is seen.)
        deadline = time.monotonic() + HANG_S
        while status(daemon)["target"]["sources"]["layers"] != "cigi":
            assert time.monotonic() < deadline, "the host's weather was never taken"
            last += 1
            host.send(frame(last, *session_body(0.0)))
    # Silent now: the weather goes back once [cigi] hold_s = 1.5 has passed.
    deadline = time.monotonic() + HANG_S
    while (target := status(daemon)["target"])["sources"]["layers"] == "cigi":
        assert time.monotonic() < deadline, "the host's weather was never handed back"
        time.sleep(0.1)
    assert target["sources"]["layers"] == "preset" and target["layers"] == []
    # Talking again, with the same weather: it is the host's weather again.
    with CigiHostSocket(ig_address(daemon)) as host:
        last, _ = drive(host, 0.3, "big", session_body(0.0))
        deadline = time.monotonic() + HANG_S
        while (target := status(daemon)["target"])["sources"]["layers"] != "cigi":
            assert time.monotonic() < deadline, "the host's weather was not taken again"
            last += 1
            host.send(frame(last, *session_body(0.0)))
    assert target["layers"][0]["base_m"] == 1000.0


class _Recorder:
    """The daemon's side of the listener, recorded."""

    def __init__(self) -> None:
        self.heard = 0
        self.patches: list[WeatherPatch] = []
        self.held = True  # False: as if the daemon had handed the host's weather back

    def cigi_weather(self, patch: WeatherPatch) -> None:
        self.patches.append(patch)

    def cigi_heard(self) -> bool:
        self.heard += 1
        return self.held

    def cigi_camera(self, eye: Eye) -> None:
        pass

    def cigi_clock(self, time_utc: datetime | None, running: bool | None) -> None:
        pass

    def cigi_answers(self, requests: Sequence[Packet]) -> list[Packet]:
        return []


def test_only_allowed_hosts_are_heard(tmp_path: Path) -> None:
    async def run(allow: tuple[str, ...]) -> tuple[_Recorder, dict[str, Any]]:
        rec = _Recorder()
        ig = CigiIg(IgSettings(("127.0.0.1", 0), None, parse_networks(allow)), rec)
        await ig.start()
        try:
            with CigiHostSocket(("127.0.0.1", ig.port)) as host:
                host.send(frame(1, STRATUS))
                for _ in range(int(HANG_S / 0.01)):
                    await asyncio.sleep(0.01)
                    if ig.stats.messages or ig.stats.errors:
                        break
            return rec, ig.detail()
        finally:
            ig.close()

    rec, detail = asyncio.run(run(("10.1.2.3",)))
    assert rec.heard == 0 and not rec.patches
    assert detail["dropped"] == {"not_allowed": 1} and "127.0.0.1" in detail["last_error"]
    rec, detail = asyncio.run(run(("127.0.0.0/8",)))
    assert rec.heard == 1 and rec.patches and detail["dropped"] == {}


def test_weather_handed_back_after_a_silence_is_given_again_unchanged() -> None:
    """A host that fell silent and talks again sends the same weather (or none, CIGI's state
    being set until changed): the IG gives it again once the daemon says it no longer
    stands, and only then. (It used to give weather only when a datagram changed it, so
    after a silence the host's unchanged weather was never taken again.)"""

    async def run() -> list[int]:
        rec = _Recorder()
        ig = CigiIg(IgSettings(("127.0.0.1", 0)), rec)
        await ig.start()
        given: list[int] = []
        try:
            with CigiHostSocket(("127.0.0.1", ig.port)) as host:
                for number, held in enumerate((True, True, False, True), start=1):
                    rec.held = held
                    host.send(frame(number, STRATUS))
                    for _ in range(int(HANG_S / 0.01)):
                        await asyncio.sleep(0.01)
                        if ig.stats.messages >= number:
                            break
                    given.append(len(rec.patches))
        finally:
            ig.close()
        return given

    # the first weather; the same again (not given); the same, handed back (given); again
    assert asyncio.run(run()) == [1, 1, 2, 2]


def test_the_cigi_part_says_when_the_hosts_weather_was_handed_back() -> None:
    from wxsky.app.cigi_part import CigiPart
    from wxsky.app.parts import PartContext
    from wxsky.engine.stages import SkyEngine
    from wxsky.scene.camera import Camera
    from wxsky.scene.layout import SceneSettings
    from wxsky.settings.config import CigiSection
    from wxsky.weather.state import CloudLayer, CloudType, Source, WeatherState
    from wxsky.weather.transition import TransitionRates

    engine = SkyEngine(
        WeatherState(),
        Camera((0.0, 0.0, 500.0)),
        SceneSettings(),
        rates=TransitionRates(),
        cigi_hold_s=2.0,
    )
    part = CigiPart(CigiSection(), clock_rate=1.0)
    asyncio.run(part.start(PartContext(engine, set_camera=lambda p: p)))
    assert part.cigi_heard()  # no weather given yet: nothing to give again
    part.cigi_weather(WeatherPatch(source=Source.CIGI))  # a host's weather of no fields
    engine.run_weather(3.0)
    assert part.cigi_heard()  # it left nothing to hand back
    deck = (CloudLayer(8.0, 900.0, 1500.0, CloudType.STRATUS),)
    part.cigi_weather(WeatherPatch(source=Source.CIGI, layers=deck))
    engine.run_weather(1.0)
    assert part.cigi_heard() and engine.target.sources.layers is Source.CIGI
    engine.run_weather(3.0)  # silent past the hold
    assert engine.target.sources.layers is not Source.CIGI
    assert not part.cigi_heard()
    part.cigi_weather(WeatherPatch(source=Source.CIGI, layers=deck))
    assert part.cigi_heard() and engine.state.layers == deck  # taken again, at once


def test_a_hosts_first_weather_replaces_the_sky_at_once_later_ones_move() -> None:
    from wxsky.app.cigi_part import CigiPart
    from wxsky.app.parts import PartContext
    from wxsky.engine.stages import SkyEngine
    from wxsky.scene.camera import Camera
    from wxsky.scene.layout import SceneSettings
    from wxsky.settings.config import CigiSection
    from wxsky.weather.state import CloudLayer, CloudType, Source, WeatherState
    from wxsky.weather.transition import TransitionRates

    engine = SkyEngine(
        WeatherState(), Camera((0.0, 0.0, 500.0)), SceneSettings(), rates=TransitionRates()
    )
    part = CigiPart(CigiSection(), clock_rate=1.0)
    asyncio.run(part.start(PartContext(engine, set_camera=lambda p: p)))  # no sockets to open
    deck = (CloudLayer(8.0, 900.0, 1500.0, CloudType.STRATUS),)
    part.cigi_weather(WeatherPatch(source=Source.CIGI, layers=deck))
    assert engine.state.layers == deck
    thinner = (CloudLayer(4.0, 900.0, 1500.0, CloudType.STRATUS),)
    part.cigi_weather(WeatherPatch(source=Source.CIGI, layers=thinner))
    assert engine.state.layers == deck and engine.target.layers == thinner
    engine.run_weather(30.0)  # 2 oktas a minute by default
    assert engine.state.layers[0].cover_oktas == pytest.approx(7.0)


@pytest.mark.gl
def test_a_port_already_taken_stops_the_start_with_one_line(tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        config = write_config(tmp_path / "wxsky.toml", f"wxsky-test-{os.getpid()}-taken")
        run = subprocess.run(
            [
                *(sys.executable, "-m", "wxsky", "run", "--config", str(config)),
                *("--control", f"unix:{tmp_path / 's'}", "--cigi", f"udp:127.0.0.1:{port}"),
            ],
            capture_output=True,
            text=True,
            timeout=60,
            env={**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)},
        )
    assert run.returncode == 1, run.stderr
    errors = [line for line in run.stderr.splitlines() if line.startswith("wxsky: error:")]
    assert errors == [
        f"wxsky: error: cigi:udp:127.0.0.1:{port}: cannot listen: Address already in use; "
        "give another address with --cigi udp:HOST:PORT or [cigi] listen"
    ]


@pytest.mark.gl
def test_one_wxsky_drives_another_over_cigi(tmp_path: Path) -> None:
    """wxsky as a CIGI source (`--cigi-send`) and wxsky as the IG: the IG's sky is the
    source's applied weather, clock and all."""
    (tmp_path / "ig").mkdir()
    (tmp_path / "source").mkdir()
    with running_daemon(
        tmp_path / "ig", CONFIG, ("--preset", "clear", "--cigi", "udp:127.0.0.1:0")
    ) as ig:
        port = ig_address(ig)[1]
        with running_daemon(
            tmp_path / "source",
            "[clock]\nrate = 0.0\n",
            ("--preset", "thunderstorm", "--cigi-send", f"udp:127.0.0.1:{port}"),
        ) as source:
            deadline = time.monotonic() + HANG_S
            while time.monotonic() < deadline:
                sent = status(source)
                sender = next(i for i in sent["inputs"] if i["kind"] == "cigi-send")
                got = status(ig)
                # Until the IG took the weather and the source heard the IG answer.
                if got["target"]["sources"]["layers"] == "cigi" and sender["last_ig_frame"]:
                    break
                time.sleep(0.2)
        target = got["target"]
        assert target["sources"]["layers"] == "cigi"
        assert target["layers"] == sent["weather"]["layers"]
        assert target["visibility_m"] == sent["weather"]["visibility_m"]
        assert target["qnh_hpa"] == pytest.approx(sent["weather"]["qnh_hpa"], abs=0.01)
        assert got["weather"]["time_utc"][:16] == sent["weather"]["time_utc"][:16]
        assert sender["sent"] > 0 and sender["last_ig_frame"] > 0


def _split_distance(d: RunningDaemon, after_s: float) -> float | None:
    """The near layer's split distance in the first frame notification after_s from now."""
    with d.client() as c:
        c.subscribe(["frame"])
        start = time.monotonic()
        while True:
            note = c.next_notification(timeout_s=HANG_S)
            assert note is not None, "no frame notification"
            if note.method == "frame" and time.monotonic() - start >= after_s:
                value = note.params["split_distance_m"]
                return None if value is None else float(value)


@pytest.mark.gl
def test_an_external_view_splits_the_near_layer_at_the_ownship(daemon: RunningDaemon) -> None:
    chase = make(
        "view_control",
        view_id=0,
        entity_id=0,
        x_enable=1,
        z_enable=1,
        x_offset_m=-60.0,  # 60 m behind the ownship
        z_offset_m=-11.0,  # 11 m above it
    )
    pilot = make("view_control", view_id=0, entity_id=0, x_enable=1, z_enable=1)
    with CigiHostSocket(ig_address(daemon)) as host:
        drive(host, 0.5, "big", [*session_body(30.0), chase])
        split = _split_distance(daemon, 0.3)
        drive(host, 0.5, "big", [*session_body(30.0), pilot])
        none = _split_distance(daemon, 0.3)
    assert split == pytest.approx(math.hypot(60.0, 11.0), abs=0.5)
    assert none is None


def test_over_a_deck_is_clear_and_answers_carry_the_hosts_layer_ids(daemon: RunningDaemon) -> None:
    """Issue 39: 100 m above a 600-900 m stratus deck came back as in cloud; and aerosol
    answers numbered the layers by rank, not by the host's ids."""
    high = make(
        "weather_control",
        layer_id=1,
        weather_enable=1,
        cloud_type=9,
        coverage_pct=40.0,
        base_elevation_m=3000.0,
        thickness_m=500.0,
    )
    deck = make(
        "weather_control",
        layer_id=2,
        weather_enable=1,
        cloud_type=10,
        coverage_pct=100.0,
        base_elevation_m=600.0,
        thickness_m=300.0,
    )
    body = [p for p in session_body(0.0) if p.key != "weather_control"]
    with CigiHostSocket(ig_address(daemon)) as host:
        drive(host, 0.5, "big", [*body, high, deck])
        above = answers_to(host, 1000.0, 21)
        inside = answers_to(host, 750.0, 22)
        # The module's other tests fly under the one-layer deck of session_body.
        drive(host, 0.3, "big", [*session_body(0.0), make("weather_control", layer_id=2)])
    assert status(daemon)["target"]["layers"][0]["base_m"] == 1000.0
    w_above, w_in = above["weather"], inside["weather"]
    assert w_above["humidity_pct"] < 100 and w_above["visibility_m"] == 25_000.0
    assert above["aerosol"] == {1: 0.0, 2: 0.0}
    assert w_in["humidity_pct"] == 100 and w_in["visibility_m"] < 600.0
    # The deck is the host's layer 2, though it is the lowest.
    assert inside["aerosol"][2] > 0.0 and inside["aerosol"][1] == 0.0
