"""A CIGI host's packets as wxsky the IG remembers them, and the weather, camera and clock
they make (`protocols.cigi_session`, `cigi_weather`, `cigi_eye`); every message goes through
the real encoder and decoder, in both byte orders."""

from __future__ import annotations

import math
import random
from datetime import UTC, datetime

import pytest

from wxsky.protocols.cigi import Packet, decode_datagram, encode_datagram, make
from wxsky.protocols.cigi_eye import eye
from wxsky.protocols.cigi_session import Absorbed, HostState, Region, absorb, responses
from wxsky.protocols.cigi_weather import _beyond, region_weight, weather_patch
from wxsky.weather.atmosphere import PointWeather
from wxsky.weather.geo import enu_from_geodetic, geodetic_from_enu
from wxsky.weather.state import CloudType, PrecipKind, Source

ZRH = (47.4647, 8.5492)


def send(state: HostState, *packets: Packet, order: str = "big", view_id: int = 0) -> Absorbed:
    first = make("ig_control", ig_mode=1, host_frame_number=7)
    data = encode_datagram([first, *packets], "little" if order == "little" else "big")
    return absorb(state, decode_datagram(data), view_id)


def ownship(lat: float = ZRH[0], lon: float = ZRH[1], alt: float = 1500.0, **kw: float) -> Packet:
    return make(
        "entity_control", entity_id=0, entity_state=1, lat_deg=lat, lon_deg=lon, alt_m=alt, **kw
    )


def layer(layer_id: int = 1, **kw: float) -> Packet:
    values: dict[str, float] = {
        "weather_enable": 1,
        "cloud_type": 7,
        "coverage_pct": 50.0,
        "base_elevation_m": 1500.0,
        "thickness_m": 1000.0,
    }
    values.update(kw)
    return make("weather_control", layer_id=layer_id, **values)


@pytest.mark.parametrize("order", ["big", "little"])
def test_global_layers_and_atmosphere_make_the_weather(order: str) -> None:
    atm = make(
        "atmosphere_control",
        humidity_pct=50,
        temperature_c=20.0,
        visibility_m=2e7,  # "unlimited": kept at the weather's limit
        wind_speed_mps=5.0,
        wind_dir_deg=270.0,
        pressure_hpa=1005.0,
    )
    got = send(
        HostState(),
        ownship(),
        atm,
        layer(1, wind_speed_mps=12.0, wind_dir_deg=-90.0),
        layer(2, cloud_type=5, coverage_pct=25.0, base_elevation_m=8000.0, thickness_m=500.0),
        order=order,
    )
    assert got.weather_changed and got.camera_changed and not got.dropped
    patch = weather_patch(got.state, *ZRH, 1500.0)
    assert patch.source is Source.CIGI
    assert [
        (c.type, c.cover_oktas, c.base_m, c.top_m)
        for c in sorted(patch.layers or (), key=lambda c: c.base_m)
    ] == [
        (CloudType.CUMULUS, 4.0, 1500.0, 2500.0),
        (CloudType.CIRRUS, 2.0, 8000.0, 8500.0),
    ]
    winds = {
        round(w.alt_m): (round(w.dir_from_deg, 3), round(w.speed_mps, 3)) for w in patch.wind or ()
    }
    # The surface wind from Atmosphere Control; the layer's at its middle, -90 read as 270.
    assert winds == {0: (270.0, 5.0), 2000: (270.0, 12.0)}
    assert patch.visibility_m == 1_000_000.0 and patch.qnh_hpa == 1005.0
    assert patch.temperature_c == 20.0
    # Magnus: 50 % at 20 °C is a dew point of 9.3 °C.
    assert patch.dewpoint_c == pytest.approx(9.26, abs=0.05)


def test_a_layer_stays_until_the_host_disables_it() -> None:
    s = send(HostState(), ownship(), layer(1)).state
    again = send(s)  # nothing said of the layer: it stays
    assert (
        not again.weather_changed and len(weather_patch(again.state, *ZRH, 0.0).layers or ()) == 1
    )
    off = send(s, make("weather_control", layer_id=1, weather_enable=0))
    assert off.weather_changed and weather_patch(off.state, *ZRH, 0.0).layers == ()


@pytest.mark.parametrize(
    ("packet", "reason", "words"),
    [
        (layer(1, thickness_m=0.0), "out_of_range", "thickness_m 0"),
        # Found by the fuzzer: a top a float's step above the base is no layer.
        (layer(1, base_elevation_m=-51.37, thickness_m=1e-6), "out_of_range", "thickness_m 1e-06"),
        (layer(1, base_elevation_m=30_000.0), "out_of_range", "base_elevation_m 30000"),
        (layer(1, wind_speed_mps=400.0), "out_of_range", "wind_speed_mps 400"),
        (
            make("atmosphere_control", temperature_c=15.0, pressure_hpa=0.0),
            "out_of_range",
            "pressure_hpa 0",
        ),
        (
            make("atmosphere_control", temperature_c=150.0, pressure_hpa=1013.0),
            "out_of_range",
            "temperature_c 150",
        ),
    ],
)
def test_what_the_weather_cannot_hold_is_dropped_and_the_last_good_weather_stays(
    packet: Packet, reason: str, words: str
) -> None:
    good = send(HostState(), ownship(), layer(1)).state
    got = send(good, packet)
    assert [r for r, _ in got.dropped] == [reason]
    assert words in got.dropped[0][1]
    assert weather_patch(got.state, *ZRH, 0.0) == weather_patch(good, *ZRH, 0.0)


def test_what_wxsky_does_not_draw_is_counted_not_refused() -> None:
    got = send(
        HostState(),
        make("entity_control", entity_id=3, lat_deg=1.0, lon_deg=1.0),
        layer(8),  # sand
        make("weather_control", scope=2, entity_or_region_id=3, layer_id=1, weather_enable=1),
        layer(1, cloud_type=12),
        make("view_control", view_id=4),
        make("environmental_conditions_request", request_maritime=1, request_id=1),
    )
    assert dict(got.ignored) == {
        "other_entity": 1,
        "layer_not_drawn": 1,
        "entity_scope": 1,
        "cloud_type_other": 1,
        "other_view": 1,
        "surface_request": 1,
    }
    assert not got.dropped and got.requests == () and not got.state.layers


def test_the_clock_is_set_only_when_the_host_changes_it() -> None:
    cel = make(
        "celestial_sphere_control",
        hour=18,
        minute=45,
        date_time_valid=1,
        ephemeris_enable=1,
        date_mmddyyyy=12_03_2026,
    )
    first = send(HostState(), cel)
    assert first.clock_utc == datetime(2026, 12, 3, 18, 45, tzinfo=UTC)
    assert first.clock_running is True
    # The same minute sent every frame must not hold the clock at hh:mm:00.
    again = send(first.state, cel)
    assert again.clock_utc is None and again.clock_running is None
    stopped = send(again.state, make("celestial_sphere_control", ephemeris_enable=0))
    assert stopped.clock_running is False and stopped.clock_utc is None


def test_the_eye_is_the_ownship_with_the_views_offset_and_angles() -> None:
    s = send(
        HostState(),
        ownship(yaw_deg=90.0),
        make(
            "view_control",
            view_id=2,
            entity_id=0,
            x_enable=1,
            z_enable=1,
            yaw_enable=1,
            pitch_enable=1,
            x_offset_m=100.0,  # 100 m ahead of an aircraft heading east
            z_offset_m=-10.0,  # 10 m above it
            yaw_deg=-90.0,  # looking left of its nose: north
            pitch_deg=10.0,
        ),
        make(
            "view_definition",
            view_id=2,
            left_enable=1,
            right_enable=1,
            left_deg=-40.0,
            right_deg=35.0,
        ),
        view_id=2,
    ).state
    e = eye(s)
    assert e is not None
    east, north, up = enu_from_geodetic(*ZRH, e.lat_deg, e.lon_deg, e.alt_m)
    assert (east, north, up) == pytest.approx((100.0, 0.0, 1510.0), abs=0.01)
    assert e.heading_deg == pytest.approx(0.0, abs=1e-6) or e.heading_deg == pytest.approx(360.0)
    assert e.pitch_deg == pytest.approx(10.0) and e.roll_deg == pytest.approx(0.0, abs=1e-6)
    assert e.fov_deg == pytest.approx(75.0)
    assert e.offset_m == pytest.approx(math.hypot(100.0, 10.0))
    assert e.ownship == (ZRH[0], ZRH[1], 1500.0)


@pytest.mark.parametrize(
    ("yaw", "pitch", "roll"), [(0, 0, 0), (30, 10, 0), (200, -20, 15), (45, 60, -30)]
)
def test_an_ownship_seen_from_its_own_eye_keeps_its_attitude(
    yaw: float, pitch: float, roll: float
) -> None:
    e = eye(send(HostState(), ownship(yaw_deg=yaw, pitch_deg=pitch, roll_deg=roll)).state)
    assert e is not None
    assert (e.heading_deg % 360.0, e.pitch_deg, e.roll_deg) == pytest.approx(
        (yaw, pitch, roll), abs=1e-6
    )


def _square(perimeter: float, rotation: float = 0.0, corner: float = 0.0) -> Region:
    return Region(1, True, *ZRH, 10_000.0, 4_000.0, corner, rotation, perimeter)


def at(east: float, north: float) -> tuple[float, float]:
    return geodetic_from_enu(*ZRH, east, north)


def test_a_regions_weight_is_one_inside_and_falls_off_across_its_perimeter() -> None:
    r = _square(2000.0)
    assert region_weight(r, *at(0.0, 4900.0)) == 1.0  # x (north) half-size 5 km
    assert region_weight(r, *at(1900.0, 0.0)) == 1.0  # y (east) half-size 2 km
    assert region_weight(r, *at(3000.0, 0.0)) == pytest.approx(0.5, abs=0.01)  # half the band
    assert region_weight(r, *at(4100.0, 0.0)) == 0.0
    # Turned 90° clockwise, its x axis points east.
    assert region_weight(_square(0.0, rotation=90.0), *at(4900.0, 0.0)) == 1.0
    assert region_weight(_square(0.0, rotation=90.0), *at(0.0, 4900.0)) == 0.0
    # A rounded corner cuts the rectangle's corner off.
    assert region_weight(_square(0.0), *at(1950.0, 4950.0)) == 1.0
    assert region_weight(_square(0.0, corner=1000.0), *at(1950.0, 4950.0)) == 0.0
    inactive = Region(1, False, *ZRH, 1e4, 1e4, 0.0, 0.0, 0.0)
    assert region_weight(inactive, *ZRH) == 0.0


def test_regional_weather_blends_into_the_global_across_the_perimeter() -> None:
    region = make(
        "environmental_region_control",
        region_id=5,
        region_state=1,
        lat_deg=ZRH[0],
        lon_deg=ZRH[1],
        size_x_m=10_000.0,
        size_y_m=4_000.0,
        transition_perimeter_m=2000.0,
    )
    storm = make(
        "weather_control",
        scope=1,
        entity_or_region_id=5,
        layer_id=2,
        weather_enable=1,
        cloud_type=6,
        coverage_pct=100.0,
        base_elevation_m=900.0,
        thickness_m=9000.0,
    )
    same_type = make(
        "weather_control",
        scope=1,
        entity_or_region_id=5,
        layer_id=1,
        weather_enable=1,
        cloud_type=7,
        coverage_pct=100.0,
        base_elevation_m=2500.0,
        thickness_m=1000.0,
    )
    s = send(HostState(), ownship(), region, layer(1), storm, same_type).state

    def clouds(east: float) -> dict[CloudType, tuple[float, float]]:
        layers = weather_patch(s, *at(east, 0.0), 1500.0).layers or ()
        return {c.type: (round(c.cover_oktas, 2), round(c.base_m)) for c in layers}

    assert clouds(0.0) == {CloudType.CUMULUS: (8.0, 2500), CloudType.CUMULONIMBUS: (8.0, 900)}
    # Halfway across the perimeter: the cumulus layer halfway between the two, the storm half.
    assert clouds(3000.0) == {CloudType.CUMULUS: (6.0, 2000), CloudType.CUMULONIMBUS: (4.0, 900)}
    assert clouds(10_000.0) == {CloudType.CUMULUS: (4.0, 1500)}
    destroyed = send(s, make("environmental_region_control", region_id=5, region_state=2))
    assert destroyed.weather_changed and not destroyed.state.regions
    assert {c.type for c in weather_patch(destroyed.state, *ZRH, 0.0).layers or ()} == {
        CloudType.CUMULUS
    }


def test_fog_and_precipitation_layers() -> None:
    fog = layer(
        0,
        cloud_type=0,
        base_elevation_m=400.0,
        thickness_m=100.0,
        visibility_m=300.0,
        transition_band_m=100.0,
    )
    rain = layer(
        4,
        cloud_type=0,
        coverage_pct=80.0,
        base_elevation_m=400.0,
        thickness_m=1500.0,
        severity=5,
        visibility_m=3000.0,
    )
    atm = make("atmosphere_control", temperature_c=10.0, visibility_m=20_000.0, pressure_hpa=1010.0)
    s = send(HostState(), ownship(alt=450.0), fog, rain, atm).state
    inside = weather_patch(s, *ZRH, 450.0)
    assert inside.visibility_m == pytest.approx(300.0)
    assert inside.present_weather == ("+RA", "FG")
    assert inside.precipitation is not None and inside.precipitation[0].kind is PrecipKind.RAIN
    assert inside.precipitation[0].top_m == 1900.0
    # Halfway through the transition band above the fog: between the two, geometrically.
    assert weather_patch(s, *ZRH, 550.0).visibility_m == pytest.approx(math.sqrt(300.0 * 20_000.0))
    assert weather_patch(s, *ZRH, 700.0).visibility_m == 20_000.0


def test_a_reset_after_operating_forgets_the_hosts_world() -> None:
    s = send(HostState(), ownship(), layer(1)).state
    got = absorb(
        s,
        decode_datagram(encode_datagram([make("ig_control", ig_mode=0, host_frame_number=8)])),
    )
    assert got.weather_changed and not got.state.layers and got.state.ownship is None


def test_answers_carry_the_request_id_and_the_point_weather() -> None:
    request = make(
        "environmental_conditions_request", request_weather=1, request_aerosol=1, request_id=77
    )
    point = PointWeather(-5.5, 100.0, 60.0, 9.0, 275.0, 800.0, True, (0.0, 0.31))
    weather, *aerosol = responses(request, point)
    assert weather.key == "weather_conditions_response" and weather["request_id"] == 77
    assert weather["visibility_m"] == 60.0 and weather["humidity_pct"] == 100
    assert [(p["layer_id"], round(float(p["aerosol_concentration_gpm3"]), 3)) for p in aerosol] == [
        (1, 0.0),
        (2, 0.31),
    ]
    only_weather = make("environmental_conditions_request", request_weather=1, request_id=1)
    assert [p.key for p in responses(only_weather, point)] == ["weather_conditions_response"]


def test_blended_stations_sent_as_regions_give_each_station_its_own_clouds() -> None:
    from wxsky.protocols.cigi_source import SourceFrame, host_message
    from wxsky.weather.state import CloudLayer, WeatherPatch, WeatherState
    from wxsky.weather.stations import StationWeather

    def station(name: str, lat: float, lon: float, *layers: CloudLayer) -> StationWeather:
        patch = WeatherPatch(source=Source.METAR, layers=layers)
        return StationWeather(name, lat, lon, 400.0, None, patch)

    zurich = station("LSZH", 47.4647, 8.5492, CloudLayer(2, 1200.0, 1800.0, CloudType.CUMULUS))
    bern = station("LSZB", 46.9141, 7.4971, CloudLayer(8, 600.0, 900.0, CloudType.STRATUS))
    blended = WeatherState().apply(
        WeatherPatch(
            source=Source.METAR, layers=(CloudLayer(5, 900.0, 1500.0, CloudType.STRATOCUMULUS),)
        )
    )
    message = host_message(blended, SourceFrame(1), (zurich, bern), region_slots=3)
    got = absorb(HostState(), decode_datagram(encode_datagram(message)))
    assert not got.dropped and sorted(got.state.regions) == [1, 2]

    def clouds(lat: float, lon: float) -> set[tuple[CloudType, float]]:
        layers = weather_patch(got.state, lat, lon, 500.0).layers or ()
        return {(c.type, c.cover_oktas) for c in layers}

    assert clouds(zurich.lat_deg, zurich.lon_deg) == {(CloudType.CUMULUS, 2.0)}
    assert clouds(bern.lat_deg, bern.lon_deg) == {(CloudType.STRATUS, 8.0)}
    # Far from both, beyond their regions' perimeters: the blended weather.
    assert clouds(47.8, 7.0) == {(CloudType.STRATOCUMULUS, 5.0)}
    # A station leaving the blend is destroyed at the IG with the next message.
    later = host_message(blended, SourceFrame(2), (zurich,), region_slots=3)
    gone = absorb(got.state, decode_datagram(encode_datagram(later)))
    assert sorted(gone.state.regions) == [1]


def _region_packet(rid: int, state: int = 1) -> Packet:
    return make(
        "environmental_region_control",
        region_id=rid,
        region_state=state,
        lat_deg=ZRH[0],
        lon_deg=ZRH[1],
        size_x_m=1000.0,
        size_y_m=1000.0,
    )


def test_regions_past_the_cap_go_least_recently_touched_first_with_their_layers() -> None:
    """Issue 40: a host's regions were kept without end."""
    first = make("ig_control", ig_mode=1, host_frame_number=7)

    def go(state: HostState, *packets: Packet) -> Absorbed:
        return absorb(state, decode_datagram(encode_datagram([first, *packets])), 0, 3)

    s = go(HostState(), *(_region_packet(r) for r in (1, 2, 3))).state
    s = go(s, layer(1, scope=1, entity_or_region_id=1)).state  # region 1 touched again
    got = go(s, _region_packet(4))
    assert got.evicted == 1 and set(got.state.regions) == {1, 3, 4}
    # A layer with no region of its own takes a place too; region 3 goes, then 1 and its layer.
    got = go(got.state, layer(2, scope=1, entity_or_region_id=9), _region_packet(5))
    assert got.evicted == 2 and set(got.state.regions) == {4, 5}
    assert set(got.state.layers) == {(9, 2)} and got.weather_changed
    # Destroyed regions free their places and their layers at once.
    got = go(got.state, _region_packet(5, state=2), layer(2, scope=1, entity_or_region_id=9))
    assert got.evicted == 0 and set(got.state.regions) == {4}
    assert got.state.region_order == (4, 9)


def test_the_quick_reach_check_never_leaves_out_a_region_that_holds() -> None:
    """Issue 40: `_region_at` skips regions surely out of reach before weighing them; a place
    any region weighs more than 0 at is never skipped, near the poles and the antimeridian too."""
    rng = random.Random(40)
    held = 0
    for _ in range(20_000):
        lat = rng.choice([rng.uniform(-89.0, 89.0), rng.uniform(80.0, 89.9), 0.0])
        lon = rng.choice([rng.uniform(-180.0, 180.0), 179.99, -179.99])
        sx, sy = rng.uniform(0.0, 200_000.0), rng.uniform(0.0, 200_000.0)
        region = Region(
            1,
            True,
            lat,
            lon,
            sx,
            sy,
            rng.uniform(0.0, 5000.0),
            rng.uniform(-180.0, 180.0),
            rng.uniform(0.0, 50_000.0),
        )
        reach = sx + sy + region.transition_perimeter_m
        east, north = rng.uniform(-reach, reach), rng.uniform(-reach, reach)
        plat, plon = geodetic_from_enu(lat, lon, east, north)
        if not -90.0 < plat < 90.0:
            continue
        if region_weight(region, plat, plon) > 0.0:
            held += 1
            assert not _beyond(region, plat, plon, math.cos(math.radians(plat))), (
                region,
                plat,
                plon,
            )
    assert held > 1000


def test_random_lightning_makes_a_thunderstorm_of_the_layers_severity() -> None:
    """A cloud layer with random lightning enabled puts a thunderstorm in the present weather
    (`-TS`, `TS`, `+TS` by its severity), which wxsky's lightning flashes at; without it, or
    in a layer of no cloud, none."""
    atm = make("atmosphere_control", temperature_c=25.0, visibility_m=20_000.0)
    for severity, code in ((0, "-TS"), (3, "TS"), (5, "+TS")):
        cb = layer(
            2,
            cloud_type=int(CloudType.CUMULONIMBUS),
            coverage_pct=50.0,
            severity=severity,
            random_lightning_enable=1,
        )
        s = send(HostState(), ownship(), cb, atm).state
        assert weather_patch(s, *ZRH, 1500.0).present_weather == (code,)
    quiet = layer(2, cloud_type=int(CloudType.CUMULONIMBUS), coverage_pct=50.0, severity=5)
    assert (
        weather_patch(send(HostState(), ownship(), quiet, atm).state, *ZRH, 1500.0).present_weather
        == ()
    )
    # A stronger layer wins; a layer of no cloud asks for nothing.
    both = (
        layer(
            1,
            cloud_type=int(CloudType.CUMULUS),
            coverage_pct=30.0,
            severity=1,
            random_lightning_enable=1,
        ),
        layer(
            2,
            cloud_type=int(CloudType.CUMULONIMBUS),
            coverage_pct=50.0,
            severity=4,
            random_lightning_enable=1,
        ),
        layer(4, cloud_type=0, coverage_pct=0.0, severity=5, random_lightning_enable=1),
    )
    s = send(HostState(), ownship(), *both, atm).state
    assert weather_patch(s, *ZRH, 1500.0).present_weather == ("+TS",)
