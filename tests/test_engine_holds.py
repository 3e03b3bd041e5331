"""Issue 39: a frame that takes longer than a hold does not expire a source that kept sending
while it was drawn. A daemon's engine stamps an input with the time it arrived, not with the
start of the frame being drawn then (tests/test_cigi_ig.py saw a host's weather dropped for
the preset after one slow frame, then swapped back in at once)."""

from __future__ import annotations

import time

from wxsky.engine.stages import SkyEngine
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.weather.state import CloudLayer, CloudType, Source, WeatherPatch, WeatherState

HOLD_S = 0.2
SETTINGS = SceneSettings(ring_radius_m=8000.0, max_range_m=16_000.0, shadow_map_px=32)
HOST = (CloudLayer(6, 900.0, 1400.0, CloudType.STRATOCUMULUS),)


def _engine(ring_build: str) -> SkyEngine:
    camera = Camera((0.0, 0.0, 600.0), heading_deg=0.0, pitch_deg=5.0, width_px=64, height_px=36)
    return SkyEngine(
        WeatherState(),
        camera,
        SETTINGS,
        cigi_hold_s=HOLD_S,
        ring_build=ring_build,
        ring_worker="thread",
        clock_rate=0.0,
    )


def test_a_host_heard_during_a_slow_frame_keeps_its_weather() -> None:
    engine = _engine("async")
    try:
        engine.apply(WeatherPatch(source=Source.CIGI, layers=HOST))
        engine.heard_cigi()
        engine.advance(0.01)  # a frame starts
        time.sleep(HOLD_S * 1.5)  # ... and is drawn slowly; the host keeps sending:
        engine.heard_cigi()
        engine.advance(HOLD_S * 1.6)  # the next frame, that long after the last
        assert engine.target.layers == HOST
        assert "layers" in engine.sources.holds(engine.wall_s)
    finally:
        engine.close(1.0)


def test_a_silent_host_still_hands_its_weather_back() -> None:
    engine = _engine("async")
    try:
        engine.apply(WeatherPatch(source=Source.CIGI, layers=HOST))
        engine.heard_cigi()
        engine.advance(0.01)
        engine.advance(HOLD_S * 2)  # nothing heard for two holds
        assert engine.target.layers != HOST
    finally:
        engine.close(1.0)


def test_a_snapshots_engine_stamps_with_its_own_steps_alone() -> None:
    engine = _engine("immediate")
    engine.apply(WeatherPatch(source=Source.CIGI, layers=HOST))
    engine.heard_cigi()
    time.sleep(HOLD_S * 1.5)  # real time means nothing to it
    engine.heard_cigi()
    engine.advance(HOLD_S * 1.6)
    assert engine.target.layers != HOST
    engine.close()
