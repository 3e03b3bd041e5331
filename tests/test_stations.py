"""Station choice and inverse-distance blending of METAR weather."""

from __future__ import annotations

import itertools
from datetime import UTC, datetime, timedelta

import pytest

from wxsky.weather.state import CloudLayer, CloudType, Source, WeatherPatch, WindLayer
from wxsky.weather.stations import (
    StationWeather,
    blend,
    distance_m,
    nearest,
    split_by_age,
)

T = datetime(2025, 7, 26, 16, 0, tzinfo=UTC)
CU = CloudType.CUMULUS
ST = CloudType.STRATUS


def _station(
    name: str, lat: float, lon: float, layers: tuple[CloudLayer, ...] | None, **kw: object
) -> StationWeather:
    patch = WeatherPatch(source=Source.METAR, layers=layers, **kw)  # type: ignore[arg-type]
    return StationWeather(name, lat, lon, 400.0, T, patch)


# Two stations 1° of latitude apart (111.2 km) on one meridian.
A = _station(
    "AAAA",
    47.0,
    8.0,
    (CloudLayer(4, 1500.0, 2700.0, CU),),
    wind=(WindLayer(410.0, 270.0, 10.0),),
    visibility_m=10_000.0,
    present_weather=(),
)
B = _station(
    "BBBB",
    48.0,
    8.0,
    (CloudLayer(8, 600.0, 1000.0, ST), CloudLayer(2, 1700.0, 2900.0, CU)),
    wind=(WindLayer(410.0, 90.0, 10.0, gust_mps=8.0),),
    visibility_m=2_000.0,
    present_weather=("-RA",),
)


def test_distance_reference_values() -> None:
    assert distance_m(47.0, 8.0, 48.0, 8.0) == pytest.approx(111_195.0, rel=1e-4)
    # Zurich to Geneva airports: 136 km north-south and 186 km east-west, about 230 km.
    assert distance_m(47.4647, 8.5492, 46.2381, 6.1090) == pytest.approx(230_000.0, rel=0.005)
    assert distance_m(10.0, 20.0, 10.0, 20.0) == 0.0


def test_nearest_orders_and_limits() -> None:
    got = nearest([B, A], 47.2, 8.0, count=2)
    assert [s.station for s, _ in got] == ["AAAA", "BBBB"]
    assert nearest([B, A], 47.2, 8.0, count=1, max_distance_m=30_000.0)[0][0] is A
    assert nearest([B, A], 47.5, 30.0, count=1, max_distance_m=30_000.0) == []


def test_one_station_is_its_own_report() -> None:
    assert blend(nearest([A, B], 47.9, 8.0, 1)) is B.patch
    assert blend([]) == WeatherPatch(source=Source.METAR)


def test_halfway_blend_mixes_cover_and_keeps_each_layer_base() -> None:
    mid = blend(nearest([A, B], 47.5, 8.0, 2))
    assert mid.layers is not None
    by_type = {lay.type: lay for lay in mid.layers}
    # Equal weights: stratus 8 -> 4 oktas; the two cumulus layers (200 m apart) are one layer
    # of (4 + 2) / 2 oktas with the mean base.
    assert by_type[ST].cover_oktas == pytest.approx(4.0, abs=0.01)
    assert by_type[ST].base_m == 600.0
    assert by_type[CU].cover_oktas == pytest.approx(3.0, abs=0.01)
    assert by_type[CU].base_m == pytest.approx(1600.0, abs=1.0)
    assert mid.visibility_m == pytest.approx(6000.0, abs=1.0)
    # Opposite winds of equal speed cancel to (nearly) calm.
    assert mid.wind is not None and mid.wind[0].speed_mps < 0.1
    assert mid.present_weather == ()  # the nearest station's (A, by a hair)


def test_blend_moves_smoothly_between_stations() -> None:
    covers = []
    for i in range(1, 20):
        lat = 47.0 + i / 20.0
        patch = blend(nearest([A, B], lat, 8.0, 2))
        assert patch.layers is not None
        covers.append(next((lay.cover_oktas for lay in patch.layers if lay.type == ST), 0.0))
    assert all(b >= a for a, b in itertools.pairwise(covers))
    assert max(b - a for a, b in itertools.pairwise(covers)) < 1.5
    assert covers[0] < 0.1 and covers[-1] > 7.9


def test_stations_without_a_sky_group_do_not_dilute_the_cover() -> None:
    silent = _station("CCCC", 47.0, 8.0, None)
    patch = blend(nearest([silent, B], 47.5, 8.0, 2))
    assert patch.layers is not None
    assert {lay.type: lay.cover_oktas for lay in patch.layers}[ST] == pytest.approx(8.0)


def test_clear_stations_do_dilute_it() -> None:
    clear = _station("CCCC", 47.0, 8.0, ())
    patch = blend(nearest([clear, B], 47.5, 8.0, 2))
    assert patch.layers is not None
    assert {lay.type: lay.cover_oktas for lay in patch.layers}[ST] == pytest.approx(4.0, abs=0.01)


def test_stale_reports_are_split_off() -> None:
    old = StationWeather("OLD1", 0.0, 0.0, 0.0, T - timedelta(minutes=91), A.patch)
    fresh, stale = split_by_age([A, old], T, 90 * 60.0)
    assert fresh == [A] and stale == [old]


def test_a_report_of_unknown_time_is_always_stale() -> None:
    undated = StationWeather("UNDT", 0.0, 0.0, 0.0, None, A.patch)
    future = StationWeather("FUTR", 0.0, 0.0, 0.0, T + timedelta(minutes=5), A.patch)
    fresh, stale = split_by_age([undated, A, future], T, 1e12)
    assert fresh == [A, future] and stale == [undated]
