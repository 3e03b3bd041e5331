"""Precipitation at the eye (issue 43, item 2, first part): what falls where the camera is and
how far one sees in it, by the documented relations (scene/precip_eye.py)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from wxsky.engine.stages import SkyEngine
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.scene.precip_eye import (
    Shaft,
    precipitation_at,
    rain_visibility_m,
    snow_visibility_m,
)
from wxsky.settings.presets import load_preset
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

FAR = 1e9  # air with nothing in it


def test_rain_and_snow_visibility_follow_the_documented_relations() -> None:
    # Marshall & Palmer drops, twice their cross-section each: 0.365 R^0.63 per km.
    for rate, expected_m in ((2.5, 6017.0), (10.0, 2519.0), (50.0, 905.0)):
        assert rain_visibility_m(rate, FAR) == pytest.approx(expected_m, rel=0.01)
    # The air's own extinction adds: 10 mm/h in 5 km air.
    both = 3.912 / (3.912 / 5000.0 + 3.912 / 2519.0)
    assert rain_visibility_m(10.0, 5000.0) == pytest.approx(both, rel=0.01)
    # The handbook's snow: light, moderate, heavy leave 1200, 600, 300 m.
    assert snow_visibility_m(0.35, FAR) == pytest.approx(1200.0, rel=1e-5)
    assert snow_visibility_m(1.0, FAR) == pytest.approx(300.0, rel=1e-5)
    assert snow_visibility_m(1.0, 10_000.0) < 300.0


def _weather(codes: tuple[str, ...], visibility_m: float = 8000.0) -> WeatherState:
    cb = CloudLayer(3, 1500.0, 11_000.0, CloudType.CUMULONIMBUS)
    return dataclasses.replace(
        WeatherState(), layers=(cb,), present_weather=codes, visibility_m=visibility_m
    )


SHAFTS = (Shaft((0.0, 0.0), 1200.0, 1500.0), Shaft((6000.0, 0.0), 1200.0, 1500.0))


def test_under_a_storm_in_heavy_rain_one_sees_less_than_the_metar_says() -> None:
    state = _weather(("+TSRA",))
    at = precipitation_at(state, (100.0, 50.0, 600.0), SHAFTS)
    assert at.kind == "rain" and at.intensity == "+"
    assert at.rate_mm_h > 7.6
    assert at.visibility_m == pytest.approx(rain_visibility_m(at.rate_mm_h, 8000.0))
    assert at.visibility_m < 0.6 * state.visibility_m
    # Toward the shaft's edge the rain thins; out of it nothing falls, above the base none.
    edge = precipitation_at(state, (1500.0, 0.0, 600.0), SHAFTS)
    assert 0.0 < edge.rate_mm_h < at.rate_mm_h and edge.visibility_m > at.visibility_m
    for eye in ((3000.0, 3000.0, 600.0), (0.0, 0.0, 2000.0)):
        dry = precipitation_at(state, eye, SHAFTS)
        assert dry.kind is None and dry.rate_mm_h == 0.0 and dry.visibility_m == 8000.0
    # Nothing reported falling: nothing at the eye, under the storm or not.
    assert precipitation_at(_weather(()), (0.0, 0.0, 600.0), SHAFTS).kind is None


def test_snow_is_named_by_what_it_leaves_to_see() -> None:
    at = precipitation_at(_weather(("+SN",), 20_000.0), (0.0, 0.0, 600.0), SHAFTS)
    assert at.kind == "snow" and at.intensity == "+"
    assert at.visibility_m < 400.0
    light = precipitation_at(_weather(("-SN",), 20_000.0), (900.0, 0.0, 600.0), SHAFTS)
    assert light.kind == "snow" and light.visibility_m > at.visibility_m


def test_rain_falls_everywhere_under_a_nimbostratus_deck() -> None:
    ns = CloudLayer(8, 900.0, 3500.0, CloudType.NIMBOSTRATUS)
    state = dataclasses.replace(WeatherState(), layers=(ns,), present_weather=("RA",))
    for eye in ((0.0, 0.0, 500.0), (40_000.0, -7000.0, 850.0)):
        at = precipitation_at(state, eye, ())
        assert at.kind == "rain" and at.intensity == "" and 2.5 < at.rate_mm_h <= 7.6
    assert precipitation_at(state, (0.0, 0.0, 4000.0), ()).kind is None


def test_the_engine_reports_the_rain_under_its_storms() -> None:
    """Under the thunderstorm preset's storm the frame says heavy rain and less to see than
    the report's 3 km; flown out from under every shaft, nothing."""
    state = WeatherState().apply(load_preset("thunderstorm"))
    settings = SceneSettings(max_towers=2)
    eye = (0.0, 0.0, state.observer.alt_m + 300.0)
    with SkyEngine(state, Camera(eye), settings, clock_rate=0.0) as engine:
        frame = engine.advance(0.0).frame
        storms = [t for t in frame.towers if t.spec.anvil]
        assert storms, "no cumulonimbus near the field"
        cx, cy, _ = storms[0].centre_m
        engine.set_camera(Camera((cx, cy, state.observer.alt_m + 300.0)))
        under = engine.advance(0.0).frame.at_eye
        assert under is not None and under.kind == "rain" and under.intensity == "+"
        assert under.visibility_m < state.visibility_m
        engine.set_camera(Camera((cx, cy, 12_000.0)))
        above = engine.advance(0.0).frame.at_eye
        assert above is not None and above.kind is None
        assert above.visibility_m == state.visibility_m
        assert math.isfinite(under.rate_mm_h)
