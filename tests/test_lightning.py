"""Lightning (issue 43, item 4): flashes in the cumulonimbus cells, deterministic from the sky's
seed and time, lighting the clouds, and announced to hosts."""

from __future__ import annotations

import dataclasses
import math
from datetime import timedelta

import numpy as np
import pytest

from wxsky.app.snapshot import take_snapshot
from wxsky.engine.stages import SkyEngine
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.scene.lightning import (
    IC_SHARE,
    RETURN_STROKES,
    StormCell,
    flashes_between,
    lit_flashes,
    storm_rate_per_min,
)
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

CELLS = tuple(
    StormCell(
        cloud_id=1000 + k,
        axis_m=(4000.0 * k, 0.0),
        base_m=1500.0,
        top_m=11500.0,
        formed=1.0,
        ground_m=400.0,
    )
    for k in range(8)
)


def test_the_storm_strength_sets_the_rate() -> None:
    base = WeatherState()
    rates = [
        storm_rate_per_min(dataclasses.replace(base, present_weather=codes))
        for codes in ((), ("RA",), ("VCTS",), ("-TSRA",), ("TSRA", "BR"), ("+TSRAGR",))
    ]
    assert rates[0] == 0.0 and rates[1] == 0.0
    assert 0.0 < rates[2] == rates[3] < rates[4] < rates[5]


def test_flashes_are_the_same_however_the_frames_ask() -> None:
    t0 = 1_780_000_000.0
    whole = flashes_between(CELLS, 41, 8.0, t0, t0 + 600.0)
    steps = []
    t = t0
    for dt in np.random.default_rng(3).uniform(0.01, 0.2, size=10_000):
        if t >= t0 + 600.0:
            break
        steps += flashes_between(CELLS, 41, 8.0, t, min(t + dt, t0 + 600.0))
        t += dt
    steps += flashes_between(CELLS, 41, 8.0, t, t0 + 600.0)
    assert [f.id for f in steps] == [f.id for f in whole]
    assert len({f.id for f in whole}) == len(whole)
    # 8 cells at 8 a minute for 10 minutes: 640 on average (Poisson, 4 sigma).
    assert abs(len(whole) - 640) < 4 * math.sqrt(640)
    ic = sum(f.kind == "intra_cloud" for f in whole) / len(whole)
    assert abs(ic - IC_SHARE) < 0.08
    for f in whole:
        assert f.kind in ("intra_cloud", "cloud_to_ground")
        x, y, z = f.position_m
        assert 1500.0 < z < 11500.0 and f.ground_m == 400.0
        assert min(math.hypot(x - c.axis_m[0], y - c.axis_m[1]) for c in CELLS) < 2600.0
        if f.kind == "cloud_to_ground":
            returns = len(f.strokes) - 1  # and the continuing current
            assert RETURN_STROKES[0] <= returns <= RETURN_STROKES[1]
        assert f.glow(f.start_s + f.strokes[0][0] + 0.001) > 0.0
        assert f.glow(f.start_s - 0.001) == 0.0 and f.glow(f.start_s + 1.01) == 0.0
    # Another sky's seed, other flashes; no storm, none.
    assert [f.id for f in flashes_between(CELLS, 42, 8.0, t0, t0 + 600.0)] != [f.id for f in whole]
    assert flashes_between(CELLS, 41, 0.0, t0, t0 + 600.0) == []
    # A cloud not formed does not flash.
    gone = tuple(dataclasses.replace(c, formed=0.0) for c in CELLS)
    assert flashes_between(gone, 41, 8.0, t0, t0 + 600.0) == []
    # What lights the sky at a moment is among the flashes of the second before.
    moment = whole[10].start_s + 0.001
    assert whole[10].id in {f.id for f, _ in lit_flashes(CELLS, 41, 8.0, moment)}


def _storm() -> WeatherState:
    state = WeatherState().apply(load_preset("thunderstorm"))
    return dataclasses.replace(state, present_weather=("+TSRA",))


def test_two_channels_announce_the_same_flashes_in_the_same_frames() -> None:
    """Two engines on the same sky (as two display channels of one master are, docs/
    channels.md) step through a minute of +TSRA: each flash is announced once, in the same
    frame by both, and lights the frames it lasts in."""
    state = _storm()
    settings = SceneSettings(max_towers=2)
    cams = [Camera((0.0, 0.0, state.observer.alt_m + 2.0), h, 10.0) for h in (0.0, 120.0)]
    seen: list[list[tuple[int, tuple[int, ...]]]] = []
    for cam in cams:
        frames = []
        with SkyEngine(state, cam, settings, clock_rate=1.0) as engine:
            for n in range(150):
                plan = engine.advance(0.4)
                frames.append((n, tuple(f.id for f in plan.frame.new_flashes)))
        seen.append(frames)
    assert seen[0] == seen[1]
    ids = [i for _, found in seen[0] for i in found]
    assert len(ids) >= 5, "a minute of +TSRA over the storm flashed less than five times"
    assert len(ids) == len(set(ids))


@pytest.mark.gl
def test_a_flash_lights_the_storm() -> None:
    """The frame a flash lights is brighter in the cumulonimbus than the frame before it."""
    from wxsky.render.renderer import Renderer

    state = dataclasses.replace(_storm(), visibility_m=20_000.0)
    settings = SceneSettings(max_towers=2)
    eye = (0.0, 0.0, state.observer.alt_m + 300.0)
    with SkyEngine(state, Camera(eye), settings, clock_rate=1.0) as engine:
        first = None
        for _ in range(400):
            plan = engine.advance(0.05)
            bright = [(f, g) for f, g in plan.frame.flashes if g > 0.5]
            if bright:
                first = (plan.state.time_utc, bright[0][0])
                break
    assert first is not None, "no flash in 20 s of +TSRA"
    when, flash = first
    x, y, z = flash.position_m
    heading = math.degrees(math.atan2(x - eye[0], y - eye[1]))
    pitch = math.degrees(math.atan2(z - eye[2], math.hypot(x - eye[0], y - eye[1])))
    cam = Camera(eye, heading, min(pitch, 60.0), fov_deg=60.0, width_px=320, height_px=180)
    with Renderer(settings.ring_texture_px) as r:
        lit = take_snapshot(dataclasses.replace(state, time_utc=when), cam, settings, r).image
        before = dataclasses.replace(state, time_utc=when - timedelta(seconds=1.5))
        dark = take_snapshot(before, cam, settings, r).image
    luma = np.array([0.2126, 0.7152, 0.0722])
    centre = (slice(60, 120), slice(110, 210))
    gain = float((lit[centre][..., :3] @ luma).mean() - (dark[centre][..., :3] @ luma).mean())
    assert gain > 8.0, gain


def _flashes_in_a_minute(
    monkeypatch: pytest.MonkeyPatch, settings: SceneSettings
) -> tuple[int, float]:
    """Flashes announced over 60 s of +TSRA stepped frame by frame, and how many the cells
    the frames flashed in should make at the rate asked for: the sum of their formation
    (in twentieths, as `flashes_between` takes it) over the minute."""
    import wxsky.scene.layout as layout

    cells: dict[int, float] = {}
    real = layout.flashes_between

    def spying(found, seed, rate, t0, t1):  # type: ignore[no-untyped-def]
        found = tuple(found)
        for c in found:
            cells[c.cloud_id] = round(c.formed * 20.0) / 20.0
        return real(found, seed, rate, t0, t1)

    monkeypatch.setattr(layout, "flashes_between", spying)
    state = _storm()
    cam = Camera((0.0, 0.0, state.observer.alt_m + 2.0), 0.0, 10.0)
    count = 0
    with SkyEngine(state, cam, settings, clock_rate=1.0) as engine:
        for _ in range(150):
            count += len(engine.advance(0.4).frame.new_flashes)
    return count, sum(cells.values())


def test_the_config_sets_the_rate(monkeypatch: pytest.MonkeyPatch) -> None:
    """`[lightning] flashes_per_min`: 60 s of +TSRA at 30 a minute a cell flash about 30
    times each storm cell's formation (a Poisson count, within 4 sigma), not +TS's 8; at 0
    not at all; and without a storm the key makes none."""
    from wxsky.settings.config import DaemonConfig, LightningSection

    config = DaemonConfig(lightning=LightningSection(flashes_per_min=30))
    settings = dataclasses.replace(config.scene_settings(), max_towers=2)
    assert settings.flashes_per_min == 30.0
    count, formed = _flashes_in_a_minute(monkeypatch, settings)
    assert formed > 0.0, "the thunderstorm preset has no storm cell near the eye"
    expected = 30.0 * formed
    assert abs(count - expected) <= 4.0 * math.sqrt(expected) + 1.0, (count, expected)
    assert count > 2.0 * 8.0 * formed  # well above what +TS alone flashes
    off = dataclasses.replace(settings, flashes_per_min=0.0)
    assert _flashes_in_a_minute(monkeypatch, off)[0] == 0
    calm = dataclasses.replace(_storm(), present_weather=("RA",))
    assert storm_rate_per_min(calm, 30.0) == 0.0
    assert storm_rate_per_min(_storm(), 30.0) == 30.0
    assert storm_rate_per_min(_storm(), None) == 8.0
