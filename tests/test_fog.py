"""Fog, patchy fog and RVR (issue 43 item 3, docs/fog.md): the METAR's fog and RVR groups, the
fog field the renderer draws and every answer reads, and the one settings checker on it."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from wxsky.app.control import ControlError, set_weather, visibility
from wxsky.inputs.station_table import report_patch
from wxsky.scene.camera import Camera
from wxsky.scene.conditions import conditions_at
from wxsky.scene.fog import (
    MAX_BANKS,
    RVR_EYE_M,
    TOP_FADE,
    fog_field,
    fogged_at_eye,
    runway,
)
from wxsky.scene.precip_eye import AtEye
from wxsky.settings.preset_check import parse_preset_data
from wxsky.weather.metar import decode
from wxsky.weather.metar_fog import SHALLOW_DEPTH_M, metar_fog, rvr_group
from wxsky.weather.state import (
    NO_FOG,
    Fog,
    RunwayRvr,
    Source,
    WeatherPatch,
    WeatherState,
)

KOSCHMIEDER = 3.912
PATCHY = WeatherState(fog=Fog(200.0, 60.0, True), visibility_m=5000.0, seed=7)


def _metar(text: str) -> WeatherState:
    decoded = decode(text, year=2026, month=12)
    return WeatherState().apply(report_patch(decoded, 432.0))


# -- METAR ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("group", "runway_name", "rvr_m", "more", "less", "tendency"),
    [
        ("R14/0600N", "14", 600.0, False, False, "N"),
        ("R32L/P1500", "32L", 1500.0, True, False, None),
        ("R06/0400V0800U", "06", 600.0, False, False, "U"),
        ("R14/M0050", "14", 50.0, False, True, None),
        ("R28L/2400FT", "28L", 2400 * 0.3048, False, False, None),
        ("R28R/1000V1600FT/D", "28R", 1300 * 0.3048, False, False, "D"),
        ("R09C/0350/", "09C", 350.0, False, False, None),
    ],
)
def test_rvr_groups_of_every_form_are_read(
    group: str, runway_name: str, rvr_m: float, more: bool, less: bool, tendency: str | None
) -> None:
    got = rvr_group(group)
    assert got is not None
    assert got.runway == runway_name
    assert got.rvr_m == pytest.approx(rvr_m)
    assert (got.more_than, got.less_than, got.tendency) == (more, less, tendency)


@pytest.mark.parametrize(
    "group", ["R88/0600", "R99/0600", "R00/0600", "R37/0600", "R14/60", "14/0600"]
)
def test_rvr_groups_that_place_nothing_are_none(group: str) -> None:
    assert rvr_group(group) is None


def test_the_decoder_keeps_every_rvr_group() -> None:
    m = decode("LSZH 061020Z 24004KT 0300 R14/0600N R32L/P1500 R06/0400V0800U FG VV001 08/08 Q1020")
    assert m.rvr == ("R14/0600N", "R32L/P1500", "R06/0400V0800U")
    assert not m.partial


@pytest.mark.parametrize(
    ("weather", "patchy", "depth_m", "has_fog"),
    [
        ("BCFG", True, 60.0, True),
        ("PRFG", True, 60.0, True),
        ("MIFG", False, SHALLOW_DEPTH_M, True),
        ("FG", False, 150.0, True),
        ("FZFG", False, 150.0, True),
        ("BR", False, 0.0, False),
        ("VCFG", False, 0.0, False),
    ],
)
def test_fog_groups_make_the_fog(weather: str, patchy: bool, depth_m: float, has_fog: bool) -> None:
    fog = metar_fog(decode(f"LSZH 061020Z 24004KT 0400 {weather} SCT002 08/08 Q1020"))
    if not has_fog:
        assert fog == NO_FOG
        return
    assert (fog.patchy, fog.depth_m) == (patchy, depth_m)
    if weather in ("FG", "FZFG"):
        assert fog.visibility_m == 400.0  # the sheet's visibility is the report's


def test_a_report_without_fog_clears_it() -> None:
    foggy = _metar("LSZH 061020Z 24004KT 3000 BCFG SCT002 08/08 Q1020")
    assert foggy.fog is not None and foggy.fog.patchy
    clear = foggy.apply(
        report_patch(
            decode("LSZH 061050Z 24004KT 9999 FEW030 10/08 Q1020", year=2026, month=12), 432.0
        )
    )
    assert clear.fog is None and fog_field(clear) is None


def test_rvr_groups_give_that_rvr_at_the_touchdown_zone() -> None:
    # Patchy fog, two runways' RVRs, one of them the other end of the same strip.
    state = _metar("LSZH 061020Z 24004KT 4000 BCFG R14/0600N R32/0350 R28/P1500 SCT002 08/08 Q1020")
    field = fog_field(state)
    assert field is not None
    for name, want in (("14", 600.0), ("32", 350.0), ("28", 1500.0)):
        assert field.runway_rvr_m(name) == pytest.approx(want, rel=0.1), name
    # ... and the same through the control command the instructor's station asks.
    answer = visibility(state, {"runway": "14"})
    assert answer["rvr_m"] == pytest.approx(600.0, rel=0.1)


def test_rvr_groups_without_fog_groups_make_fog_only_at_their_runways() -> None:
    state = _metar("LSZH 061020Z 24004KT 2000 BR R14/0500 BKN003 08/08 Q1020")
    field = fog_field(state)
    assert field is not None
    assert field.runway_rvr_m("14") == pytest.approx(500.0, rel=0.1)
    # 6 km off the field there is no fog, only the air's 2 km.
    assert float(field.rvr_m(6000.0, -6000.0)) == pytest.approx(2000.0, rel=0.01)


# -- the field the renderer draws --------------------------------------------------------------


def _twin_extinction(
    uniforms: dict[str, object], points: np.ndarray, height_m: float
) -> np.ndarray:
    """fog.glsl's sum, written again from its uniform arrays' bytes: the density the renderer
    uses, not FogField's own evaluation of it."""
    banks = np.frombuffer(uniforms["u_fog_banks"], np.float32).reshape(MAX_BANKS, 4)  # type: ignore[arg-type]
    depth = np.frombuffer(uniforms["u_fog_depth_m"], np.float32)  # type: ignore[arg-type]
    total = np.zeros(len(points))
    for i in range(int(uniforms["u_fog_count"])):  # type: ignore[call-overload]
        e, n, r, ext = banks[i]
        v = min(max((depth[i] - height_m) / (TOP_FADE * depth[i]), 0.0), 1.0)
        d2 = ((points - (e, n)) ** 2).sum(axis=1)
        across = np.exp(-d2 / (r * r)) if r > 0 else np.ones(len(points))
        total += ext * across * v
    return np.maximum(total, 0.0)


@pytest.mark.parametrize("seed", [1, 7, 42])
@pytest.mark.parametrize("designator", ["05", "14", "27", "32L"])
def test_patchy_fog_rvr_varies_along_a_runway_and_is_the_drawn_fogs(
    seed: int, designator: str
) -> None:
    # The check: for BCFG across a runway, RVR at ten points along it varies by at
    # least a factor of two and is the visibility of the fog drawn there within 10 %.
    state = _metar("LSZH 061020Z 24004KT 5000 BCFG SCT002 08/08 Q1020").apply(
        WeatherPatch(Source.PRESET, seed=seed)
    )
    field = fog_field(state)
    assert field is not None
    points = runway(designator).points_m(10)
    rvr = field.rvr_m(points[:, 0], points[:, 1])
    assert rvr.max() / rvr.min() >= 2.0, rvr
    drawn = _twin_extinction(field.uniforms(), points, RVR_EYE_M)
    seen_drawn = KOSCHMIEDER / (drawn + KOSCHMIEDER / state.visibility_m)
    np.testing.assert_allclose(rvr, seen_drawn, rtol=0.1)
    # The control command answers the same at each point.
    for (e, n), want in zip(points, rvr, strict=True):
        assert visibility(state, {"east_m": float(e), "north_m": float(n)})[
            "rvr_m"
        ] == pytest.approx(want, rel=1e-6)


def test_fog_has_a_top() -> None:
    sheet = fog_field(WeatherState(fog=Fog(200.0, 150.0), visibility_m=10_000.0))
    shallow = fog_field(WeatherState(fog=Fog(200.0, SHALLOW_DEPTH_M), visibility_m=10_000.0))
    assert sheet is not None and shallow is not None
    assert float(sheet.visibility_m(0.0, 0.0, 10.0)) == pytest.approx(200.0, rel=0.01)
    assert float(sheet.visibility_m(0.0, 0.0, 200.0)) == pytest.approx(10_000.0)
    # Shallow fog lies under the eye: dense at half a metre, none at 2.5 m.
    assert float(shallow.visibility_m(0.0, 0.0, 0.5)) < 300.0
    assert float(shallow.rvr_m(0.0, 0.0)) == pytest.approx(10_000.0)


def test_patchy_fog_is_the_same_for_the_same_seed_and_moves_with_another() -> None:
    a, b = fog_field(PATCHY), fog_field(dataclasses.replace(PATCHY, seed=8))
    again = fog_field(dataclasses.replace(PATCHY, time_utc=PATCHY.time_utc.replace(hour=3)))
    assert a is not None and b is not None and again is not None
    assert np.array_equal(a.banks, again.banks)
    assert not np.array_equal(a.banks, b.banks)


def test_no_fog_no_field() -> None:
    assert fog_field(WeatherState()) is None
    assert fog_field(WeatherState(fog=Fog())) is None  # nothing asked of it


def test_the_eye_and_conditions_see_the_fog() -> None:
    field = fog_field(PATCHY)
    assert field is not None
    bank = field.banks[0]
    eye = (float(bank[0]), float(bank[1]), PATCHY.observer.alt_m + 2.0)
    at = fogged_at_eye(AtEye(None, 0.0, None, PATCHY.visibility_m), field, eye)
    assert at.visibility_m == pytest.approx(float(field.visibility_m(*eye[:2], 2.0)))
    assert at.visibility_m < 400.0
    point = conditions_at(PATCHY, (), eye)
    assert point.visibility_m == pytest.approx(at.visibility_m, rel=1e-6)
    assert point.humidity_pct == 100.0
    above = conditions_at(PATCHY, (), (eye[0], eye[1], eye[2] + 500.0))
    assert above.visibility_m == pytest.approx(PATCHY.visibility_m)


def test_cigi_ground_fog_is_the_weathers_fog() -> None:
    from test_cigi_session import layer, ownship, send

    from wxsky.protocols.cigi_session import HostState
    from wxsky.protocols.cigi_weather import weather_patch

    fog = layer(0, cloud_type=0, base_elevation_m=400.0, thickness_m=120.0, visibility_m=300.0)
    s = send(HostState(), ownship(alt=2000.0), fog).state
    patch = weather_patch(s, 47.4647, 8.5492, 2000.0)
    assert patch.fog == Fog(visibility_m=300.0, depth_m=120.0)
    gone = send(s, layer(0, weather_enable=0)).state
    assert weather_patch(gone, 47.4647, 8.5492, 2000.0).fog == NO_FOG


# -- the settings checker ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fog", "where"),
    [
        ({"rvr": [{"runway": "14", "rvr_m": -600.0}]}, "fog.rvr.0.rvr_m"),
        ({"rvr": [{"runway": "41", "rvr_m": 600.0}]}, "fog.rvr.0.runway"),
        ({"visibility_m": 0.0}, "fog.visibility_m"),
        ({"depth_m": -5.0}, "fog.depth_m"),
        ({"patchy": "yes"}, "fog.patchy"),
        ({"thick": True}, "fog.thick"),
        (
            {"rvr": [{"runway": "14", "rvr_m": 600.0}, {"runway": "14", "rvr_m": 500.0}]},
            "fog.rvr.1.runway",
        ),
    ],
)
def test_bad_fog_is_one_line_naming_the_field_and_nothing_is_applied(
    fog: dict[str, Any], where: str
) -> None:
    class Engine:
        def __init__(self) -> None:
            self.applied: list[WeatherPatch] = []

        def apply(self, patch: WeatherPatch) -> None:
            self.applied.append(patch)

        def settle(self) -> None:
            pass

    engine = Engine()
    with pytest.raises(ControlError) as err:
        set_weather(engine, {"fog": fog, "visibility_m": 800.0})  # type: ignore[arg-type]
    message = str(err.value)
    assert "\n" not in message and f"set_weather: {where}:" in message
    assert engine.applied == []


def test_set_weather_sets_fog_and_rvr_and_leaves_it_when_not_named() -> None:
    class Engine:
        def __init__(self) -> None:
            self.applied: list[WeatherPatch] = []

        def apply(self, patch: WeatherPatch) -> None:
            self.applied.append(patch)

        def settle(self) -> None:
            pass

    engine = Engine()
    fog = {
        "visibility_m": 150.0,
        "depth_m": 80.0,
        "patchy": True,
        "rvr": [{"runway": "32L", "rvr_m": 550}],
    }
    assert set_weather(engine, {"fog": fog}) == ["fog"]  # type: ignore[arg-type]
    got = engine.applied[-1].fog
    assert got == Fog(150.0, 80.0, True, (RunwayRvr("32L", 550.0),))
    set_weather(engine, {"visibility_m": 3000.0})  # type: ignore[arg-type]
    assert engine.applied[-1].fog is None  # says nothing of the fog
    state = WeatherState(visibility_m=3000.0).apply(WeatherPatch(Source.CONTROL, fog=got))
    field = fog_field(state)
    assert field is not None and field.runway_rvr_m("32L") == pytest.approx(550.0, rel=0.1)


def test_a_preset_states_its_fog() -> None:
    _, patch, problems = parse_preset_data(
        {"description": "x", "fog": {"visibility_m": 200.0, "patchy": True}}
    )
    assert not problems and patch.fog == Fog(200.0, 100.0, True)
    _, none, _ = parse_preset_data({"description": "x"})
    assert none.fog == NO_FOG


# -- drawn -------------------------------------------------------------------------------------


def test_the_renderer_draws_the_fields_fog(renderer: Any) -> None:
    from wxsky.scene.layout import FrameScene, SpriteDraw
    from wxsky.scene.sky import sky_params
    from wxsky.scene.sprites import SpriteBatch

    state = PATCHY
    field = fog_field(state)
    assert field is not None
    bank = field.banks[0]
    ground = state.observer.alt_m
    # From 70 m, over the banks' 60 m tops, 1 km south of the first bank, looking down at
    # its middle; then turned to look at the ground 1 km off where the fog is thinnest.
    eye = (float(bank[0]), float(bank[1]) - 1000.0, ground + 70.0)
    down = -math.degrees(math.atan2(70.0, 1000.0))
    cam = Camera(eye, 0.0, down, 0.0, 40.0, 320, 180)
    sky = sky_params(state)
    nothing = SpriteDraw(SpriteBatch.empty(), np.zeros((0, 4), np.float32))
    renderer.render_frame(FrameScene(camera=cam, sky=sky, near=nothing, fog=field))
    layer = renderer.read("near").astype(np.float64) / 255.0
    h, w = layer.shape[:2]
    small = dataclasses.replace(cam, width_px=w, height_px=h)
    rays = small.pixel_rays().reshape(-1, 3)
    want = 1.0 - np.exp(-field.optical_depth(cam.position_m, rays).reshape(h, w))
    # The picture's fog is the field's, pixel by pixel (8-bit alpha).
    np.testing.assert_allclose(layer[..., 3], want, atol=3.0 / 255.0)
    into = layer[h // 2, w // 2, 3]
    angles = np.radians(np.arange(0.0, 360.0, 5.0))
    ends = np.stack([eye[0] + 1000 * np.sin(angles), eye[1] + 1000 * np.cos(angles)], axis=1)
    thinnest = float(angles[int(np.argmin(field.extinction_per_m(ends[:, 0], ends[:, 1], 5.0)))])
    cam2 = dataclasses.replace(cam, heading_deg=math.degrees(thinnest))
    renderer.render_frame(FrameScene(camera=cam2, sky=sky, near=nothing, fog=field))
    gap = renderer.read("near").astype(np.float64)[h // 2, w // 2, 3] / 255.0
    assert into > gap + 0.2, (into, gap)
    # No fog: no pass, the layer clear.
    renderer.render_frame(FrameScene(camera=cam, sky=sky, near=nothing))
    assert renderer.read("near")[..., 3].max() == 0
