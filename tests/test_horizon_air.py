"""Issue 41 item 5, the air at the horizon under a deck: where a layer reaches the horizon, the
sky pass's distant band and the ground below the horizon fade into the air the sprites fade
into in the same direction (`SkyParams.haze_toward`: the physical sky right behind, no lower
than HAZE_MIN_ELEVATION_DEG over the horizon, with its aureole and overcast veil), not into
one colour averaged round the horizon. Toward a low sun that air is the bright, orange
forward-scattering haze; averaged, it was bluer and darker than the deck over it, a strip the
deck did not reach (tests/test_horizon_deck.py measures that strip)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from sky_measure import (
    eye_camera,
    horizon_dip_deg,
    pixel_azimuth_deg,
    pixel_elevation_deg,
    preset_state,
    preset_sun,
    relative_luminance,
    srgb_to_linear,
)

from wxsky.app.snapshot import Snapshot, picture
from wxsky.engine.stages import SkyEngine
from wxsky.render import sky_textures
from wxsky.render.renderer import Renderer
from wxsky.scene import sky as scene_sky
from wxsky.scene.atmosphere import sky_view_v
from wxsky.scene.camera import Camera
from wxsky.scene.sky import SkyParams
from wxsky.settings.config import DaemonConfig

EYE_AGL_M = 2.0
PRESET = "broken-stratocumulus"


@contextmanager
def _facing_the_sun(
    renderer: Renderer, sun_deg: float, fov_deg: float, visibility_m: float | None = None
) -> Iterator[tuple[Snapshot, SkyParams, Camera]]:
    """The picture the daemon's stages draw of PRESET (with `visibility_m` where given) with
    the sun `sun_deg` up, looking level toward it from EYE_AGL_M with a `fov_deg` wide view at
    320 x 180, and the sky (with its atmosphere's tables) it was drawn with."""
    sun = preset_sun(PRESET, sun_deg)
    state = preset_state(PRESET, sun.time_utc)
    if visibility_m is not None:
        state = dataclasses.replace(state, visibility_m=visibility_m)
    camera = eye_camera(state, sun.azimuth_deg, 0.0, (320, 180), fov_deg, EYE_AGL_M)
    engine = SkyEngine(state, camera, DaemonConfig().scene.settings(), clock_rate=0.0)
    try:
        plan = engine.advance(0.0)
        assert plan.frame.sky.atmosphere is not None, "the physical sky is the default"
        yield picture(renderer, plan), plan.frame.sky, plan.frame.camera
    finally:
        engine.close()


def _sky_layer(shot: Snapshot) -> np.ndarray:
    """The sky layer's display values, 0..1 (opaque: premultiplied is straight)."""
    return np.asarray(shot.layers["sky"][..., :3], np.float64) / 255.0


@pytest.mark.parametrize(("preset", "reaches"), [(PRESET, True), ("clear", False)])
def test_the_sky_pass_takes_the_sprites_haze_floor(preset: str, reaches: bool) -> None:
    """sky.glsl's air takes the sky no lower over the horizon than the sprites' haze does
    (HAZE_MIN_ELEVATION_DEG) where a layer reaches the horizon, else the eye's level; its
    table row is the table's own for that elevation."""
    sun = preset_sun(preset, 5.0)
    state = preset_state(preset, sun.time_utc)
    camera = eye_camera(state, sun.azimuth_deg, 0.0, (320, 180), 60.0, EYE_AGL_M)
    engine = SkyEngine(state, camera, DaemonConfig().scene.settings(), clock_rate=0.0)
    try:
        plan = engine.advance(0.0)
    finally:
        engine.close()
    sky = plan.frame.sky
    assert sky.atmosphere is not None
    floor_z, floor_v, deck = sky_textures.display_uniforms(plan.frame.camera, sky)["u_air_floor"]
    # Under the broken deck (three quarters) the dome fades into the floor's row throughout.
    assert deck == (1.0 if reaches else 0.0)
    horizon = sky.atmosphere.horizon_rad
    expected = horizon + math.radians(scene_sky.HAZE_MIN_ELEVATION_DEG) if reaches else 0.0
    assert math.asin(floor_z) == pytest.approx(expected, abs=1e-9)
    assert floor_v == pytest.approx(float(sky_view_v(np.array(expected), horizon)), abs=1e-9)


@pytest.mark.gl
def test_under_a_deck_the_horizon_is_the_sprites_air_in_each_direction(
    renderer: Renderer,
) -> None:
    """Broken stratocumulus, the sun 5° up, facing it from 2 m: just above the horizon (the
    deck's distant band, wholly in haze there) each column shows the colour `haze_toward`
    gives a cloud in that direction, and that colour is not one colour all round: the sky
    under the sun is brighter than 25° to its side. Old code: the band was the haze averaged
    round the horizon, the same in every column, 0.2 darker toward the sun."""
    with _facing_the_sun(renderer, 5.0, 60.0) as (shot, sky, camera):
        h = -horizon_dip_deg(EYE_AGL_M)
        el = pixel_elevation_deg(camera)
        rows = np.flatnonzero(((el >= h + 0.05) & (el <= h + 0.4)).all(axis=1))
        assert rows.size >= 1
        shown = _sky_layer(shot)[rows]  # (rows, W, 3)
        rays = camera.pixel_rays()[rows]
        expected = sky.haze_toward(rays.reshape(-1, 3).T * 1000.0).T.reshape(shown.shape)
        diff = np.abs(shown - expected)
        assert float(diff.max()) < 0.05, float(diff.max())
        assert float(diff.mean()) < 0.02, float(diff.mean())
        # Not one colour all round: under the sun against 25° aside.
        az = pixel_azimuth_deg(camera)[rows[0]]
        off = np.abs((az - sky.sun.azimuth_deg + 180.0) % 360.0 - 180.0)
        under = relative_luminance(srgb_to_linear(shown[0][off < 2.0])).mean()
        aside = relative_luminance(srgb_to_linear(shown[0][(off > 24.0) & (off < 28.0)])).mean()
        assert under > 1.2 * aside, (under, aside)


@pytest.mark.gl
def test_the_suns_disc_never_shows_in_the_air(renderer: Renderer) -> None:
    """With the sun 0.3° up behind the deck's distant band (on a 60 km day: on the preset's
    20 km one so low a sun is too dim to see), the air round it (which the band and the
    ground fade into) holds the aureole, not the disc: the pixels on the sun are no brighter
    than those a degree to either side, from the horizon to the haze floor (over it the sky's
    own aureole and the disc's edge show through the band's thinner top). Guards
    `air_behind`'s turn off the disc: the air's ray under the sun lies at the haze floor,
    0.16° from its centre, and without the turn a stripe the disc's width, 2.8 times brighter
    than the band beside it, stood from the horizon to the floor (measured). Old code: the air
    was one colour all round, no stripe."""
    with _facing_the_sun(renderer, 0.3, 10.0, 60_000.0) as (shot, sky, camera):
        linear = srgb_to_linear(_sky_layer(shot))
        el = pixel_elevation_deg(camera)
        az = pixel_azimuth_deg(camera)
        off = (az - sky.sun.azimuth_deg + 180.0) % 360.0 - 180.0
        h = -horizon_dip_deg(EYE_AGL_M)
        # From the horizon to just under the haze floor, where the air is the sky at the floor.
        rows = (el >= h + 0.05) & (el <= h + 0.4)
        on = relative_luminance(linear[rows & (np.abs(off) < 0.25)]).max()
        beside = relative_luminance(linear[rows & (np.abs(np.abs(off) - 1.2) < 0.2)]).mean()
        assert on < 1.2 * beside, (on, beside)


@pytest.mark.parametrize(
    ("preset", "share"),
    [("fair-cumulus", 0.0), ("scattered-cumulus", 0.0), (PRESET, 1.0), ("overcast-stratus", 1.0)],
)
def test_under_a_deck_the_air_is_one_slab_at_every_elevation(preset: str, share: float) -> None:
    """Under broken cloud and more the sprites fade into the air just over the horizon in
    their azimuth whatever their elevation (the haze under a deck is lit alike all through);
    under scattered cloud into the sky right behind each, which rises through the sun's glow;
    from above the layer, never the slab."""
    sun = preset_sun(preset, 5.0)
    state = preset_state(preset, sun.time_utc)
    camera = eye_camera(state, sun.azimuth_deg, 0.0, (320, 180), 60.0, EYE_AGL_M)
    engine = SkyEngine(state, camera, DaemonConfig().scene.settings(), clock_rate=0.0)
    try:
        sky = engine.advance(0.0).frame.sky
    finally:
        engine.close()
    eye_m = camera.position_m[2]
    assert scene_sky.deck_share(sky, eye_m) == share
    assert scene_sky.deck_share(sky, eye_m + 20_000.0) == 0.0  # over the layer
    az = math.radians(sun.azimuth_deg)
    offsets = (
        np.array(
            [
                [math.sin(az) * math.cos(e), math.cos(az) * math.cos(e), math.sin(e)]
                for e in (math.radians(2.0), math.radians(8.0))
            ]
        ).T
        * 20_000.0
    )
    low, high = sky.haze_toward(offsets, eye_m).T
    if share == 1.0:
        assert np.allclose(low, high, atol=1e-9)
    else:
        assert not np.allclose(low, high, atol=2.0 / 255.0)
