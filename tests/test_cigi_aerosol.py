"""Aerosol Concentration Responses carry the host's own layer ids: a CIGI host on a real UDP
socket on loopback, wxsky's CIGI part and sky engine in this process (the frames that carry
the answers are published by hand), so the weather's transitions can be stepped at will."""

from __future__ import annotations

import asyncio
import dataclasses
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass

import pytest

from wxsky.app.cigi_part import CigiPart
from wxsky.app.parts import PartContext, PublishedFrame
from wxsky.engine.stages import SkyEngine
from wxsky.inputs.cigi_link import CigiHostSocket
from wxsky.protocols.cigi import Packet, decode_datagram, encode_datagram, make
from wxsky.protocols.cigi_session import HostState, absorb, responses
from wxsky.protocols.cigi_weather import IG_LAYER_IDS_FROM, answer_layer_ids, host_clouds
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.settings.config import CigiSection
from wxsky.weather.atmosphere import PointWeather
from wxsky.weather.geo import geodetic_from_enu
from wxsky.weather.state import CloudLayer, CloudType, Observer, WeatherState
from wxsky.weather.transition import TransitionRates

OBSERVER = Observer(47.4647, 8.5492, 432.0)
# CIGI cloud types: 7 cumulus, 9 stratocumulus, 10 stratus.
CUMULUS, STRATOCUMULUS, STRATUS = 7, 9, 10


def layer(layer_id: int, cloud_type: int, pct: float, base_m: float, thick_m: float) -> Packet:
    return make(
        "weather_control",
        layer_id=layer_id,
        weather_enable=1,
        cloud_type=cloud_type,
        coverage_pct=pct,
        base_elevation_m=base_m,
        thickness_m=thick_m,
    )


def request(request_id: int, alt_m: float) -> Packet:
    return make(
        "environmental_conditions_request",
        request_aerosol=1,
        request_weather=1,
        request_id=request_id,
        lat_deg=OBSERVER.lat_deg,
        lon_deg=OBSERVER.lon_deg,
        alt_m=alt_m,
    )


@dataclass
class Rig:
    engine: SkyEngine
    part: CigiPart
    host: CigiHostSocket
    frame: int = 0

    async def send(self, *packets: Packet) -> None:
        """One host message; returns once the IG has taken it."""
        ig = self.part.igs[0]
        before = ig.stats.messages
        self.frame += 1
        self.host.send([make("ig_control", ig_mode=1, host_frame_number=self.frame), *packets])
        deadline = time.monotonic() + 30.0  # the loop reads the datagram: only a hang waits
        while time.monotonic() < deadline:
            await asyncio.sleep(0.01)
            if ig.stats.messages > before:
                return
        raise AssertionError("the IG never took the host's message")

    async def fly(self, seconds: float) -> None:
        """Run the weather `seconds` on, the host sending a message every 5 s of it (a host
        silent for `[cigi] hold_s` would hand its weather back)."""
        left = seconds
        while left > 0.0:
            self.engine.run_weather(min(5.0, left))
            left -= 5.0
            await self.send()

    async def aerosol(self, request_id: int, alt_m: float) -> dict[int, float]:
        """The Aerosol Concentration Responses to a request at alt_m over the observer, as
        they come back behind the next frame's Start of Frame: layer id -> g/m³."""
        await self.send(request(request_id, alt_m))
        self.part.before_frame()
        self.part.after_frame(PublishedFrame(self.frame, self.engine.state, time.monotonic()))
        got = self.host.receive(10.0)
        assert got is not None, "no Start of Frame came back"
        packets = got[0].packets
        assert packets[0].key == "start_of_frame"
        weather = [p for p in packets if p.key == "weather_conditions_response"]
        assert [int(p["request_id"]) for p in weather] == [request_id]
        out: dict[int, float] = {}
        for p in packets:
            if p.key == "aerosol_concentration_response":
                assert int(p["request_id"]) == request_id
                assert int(p["layer_id"]) not in out, "one answer per layer id"
                out[int(p["layer_id"])] = float(p["aerosol_concentration_gpm3"])
        return out


@asynccontextmanager
async def rig() -> AsyncIterator[Rig]:
    state = dataclasses.replace(WeatherState(), observer=OBSERVER, layers=())
    # The default rates: a host's later changes move the sky over minutes.
    engine = SkyEngine(state, Camera((0.0, 0.0, 500.0)), SceneSettings(), rates=TransitionRates())
    part = CigiPart(CigiSection(), clock_rate=1.0, listen=("udp:127.0.0.1:0",))
    await part.start(PartContext(engine, set_camera=lambda params: params))
    try:
        with CigiHostSocket(("127.0.0.1", part.igs[0].port)) as host:
            yield Rig(engine, part, host)
    finally:
        await part.close(time.monotonic())


def test_a_host_layer_answers_under_its_own_id_wherever_it_lies() -> None:
    async def run() -> tuple[dict[int, float], dict[int, float]]:
        async with rig() as r:
            # The host's layer 1 lies above its layer 2: by rank from the lowest the deck
            # would come back as layer 1.
            await r.send(
                layer(1, STRATOCUMULUS, 40.0, 3000.0, 500.0),
                layer(2, STRATUS, 100.0, 1500.0, 300.0),
            )
            return await r.aerosol(1, 1650.0), await r.aerosol(2, 2500.0)

    in_deck, between = asyncio.run(run())
    assert set(in_deck) == {1, 2}
    assert in_deck[2] > 0.0 and in_deck[1] == 0.0  # the point is in the host's layer 2
    assert between == {1: 0.0, 2: 0.0}


def test_after_the_host_replaces_its_layer_1_its_layer_2_keeps_its_id() -> None:
    """Issue 39: the old layer 1 dissipating and the new one forming made three layers, and
    by rank the host's layer 2 came back as id 3."""

    async def run() -> list[dict[int, float]]:
        async with rig() as r:
            deck = layer(2, STRATUS, 100.0, 1500.0, 300.0)
            await r.send(layer(1, STRATOCUMULUS, 50.0, 600.0, 300.0), deck)
            before = await r.aerosol(1, 1650.0)
            # Another cloud type for layer 1: its stratocumulus dissipates while the cumulus
            # forms, over minutes at the default rates.
            await r.send(layer(1, CUMULUS, 50.0, 1000.0, 400.0), deck)
            await r.fly(30.0)
            types = [lay.type for lay in r.engine.state.layers]
            assert types == [CloudType.STRATOCUMULUS, CloudType.CUMULUS, CloudType.STRATUS]
            during = await r.aerosol(2, 1650.0)
            await r.fly(600.0)
            assert [lay.type for lay in r.engine.state.layers] == types[1:]
            after = await r.aerosol(3, 1650.0)
            return [before, during, after]

    before, during, after = asyncio.run(run())
    assert set(before) == {1, 2} and before[2] > 0.0
    # The cumulus forming is the host's layer 1 now; the stratocumulus on its way out is no
    # layer of the host's: it is numbered among the IG's own ids.
    assert set(during) == {1, 2, IG_LAYER_IDS_FROM}
    assert during[2] > 0.0 and during[1] == 0.0 and during[IG_LAYER_IDS_FROM] == 0.0
    assert set(after) == {1, 2} and after[2] > 0.0


def test_layers_of_other_sources_are_numbered_by_rank() -> None:
    sc = CloudLayer(3.0, 900.0, 1200.0, CloudType.STRATOCUMULUS)
    cu = CloudLayer(2.0, 1500.0, 2500.0, CloudType.CUMULUS)
    ci = CloudLayer(1.0, 8000.0, 8500.0, CloudType.CIRRUS)
    # No host: a METAR's or a preset's layers, 1 from the lowest.
    assert answer_layer_ids((sc, cu, ci), (sc, cu, ci)) == (1, 2, 3)
    # On their way to another source's layers (a preset applied over the host's).
    assert answer_layer_ids((sc, cu), (cu,)) == (1, 2)


def test_a_regions_second_cloud_type_answers_under_the_same_id_summed() -> None:
    """Half-way across a region's perimeter a layer id of another type there is two cloud
    layers, one thinning as the other thickens: the host has one layer 1, and one answer."""
    region = make(
        "environmental_region_control",
        region_id=1,
        region_state=1,
        lat_deg=OBSERVER.lat_deg,
        lon_deg=OBSERVER.lon_deg,
        size_x_m=10_000.0,
        size_y_m=10_000.0,
        transition_perimeter_m=4000.0,
    )
    storm = layer(1, 6, 80.0, 900.0, 8000.0)  # cumulonimbus, the region's layer 1
    storm = make("weather_control", **{**storm.as_dict(), "scope": 1, "entity_or_region_id": 1})
    east, north = 0.0, 5000.0 + 2000.0  # half-way out across the perimeter
    lat, lon = geodetic_from_enu(OBSERVER.lat_deg, OBSERVER.lon_deg, east, north)
    own = make("entity_control", entity_id=0, entity_state=1, lat_deg=lat, lon_deg=lon, alt_m=800.0)
    message = [make("ig_control", ig_mode=1, host_frame_number=1), own, region, storm]
    message.append(layer(1, STRATOCUMULUS, 60.0, 1200.0, 400.0))
    host = absorb(HostState(), decode_datagram(encode_datagram(message))).state
    clouds = host_clouds(host)
    assert sorted((c.type, lid) for c, lid in clouds) == [
        (CloudType.CUMULONIMBUS, 1),
        (CloudType.STRATOCUMULUS, 1),
    ]
    applied = WeatherState(layers=tuple(c for c, _ in clouds)).layers
    ids = answer_layer_ids(applied, applied, (host,))
    assert ids == (1, 1)
    point = PointWeather(5.0, 100.0, 90.0, 3.0, 270.0, 900.0, True, (0.125, 0.25))
    ask = make("environmental_conditions_request", request_aerosol=1, request_id=9)
    (answer,) = responses(ask, point, ids)
    assert answer["layer_id"] == 1
    assert float(answer["aerosol_concentration_gpm3"]) == pytest.approx(0.375)
