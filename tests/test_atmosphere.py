"""The physical atmosphere (wxsky/scene/atmosphere.py, issue 41): against the CIE standard clear
sky, at twilight, on bad input, and against closed-form transmittance; and the sky pass drawing
from it (real GL, a float target read back; the `[scene] sky` setting)."""

from __future__ import annotations

import dataclasses
import math
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

import moderngl
import numpy as np
import numpy.typing as npt
import pytest

from wxsky.engine.atmosphere_work import AtmosphereWork
from wxsky.engine.stages import SkyEngine
from wxsky.errors import ConfigError
from wxsky.render import sky_textures
from wxsky.render.context import release_framebuffer
from wxsky.scene import atmosphere as atm
from wxsky.scene import cie_sky
from wxsky.scene import sky as scene_sky
from wxsky.scene.camera import Camera
from wxsky.scene.ephemeris import SunPosition
from wxsky.scene.exposure import display
from wxsky.scene.layout import SceneSettings
from wxsky.scene.sky import sky_params
from wxsky.settings.config import load_config
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

if TYPE_CHECKING:
    from wxsky.render.renderer import Renderer

F64 = npt.NDArray[np.float64]

# CIE S 011 type 12 bounds from the issue: median and 90th percentile of the relative error.
CIE_MEDIAN = 0.25
CIE_P90 = 0.50
CIE_SUN_ELEVATIONS_DEG = (10.0, 30.0, 60.0)


@pytest.fixture(scope="module")
def luts_by_case() -> dict[tuple[float, float], atm.AtmosphereLuts]:
    """Tables for each visibility and sun elevation the tests use (a few seconds each)."""
    return {}


def _luts(
    cache: dict[tuple[float, float], atm.AtmosphereLuts], sun_deg: float, vis_m: float
) -> atm.AtmosphereLuts:
    key = (sun_deg, vis_m)
    if key not in cache:
        cache[key] = atm.build_luts(atm.atmosphere_key(sun_deg, vis_m, 50.0, 2.0))
    return cache[key]


def _sun_dir(elevation_deg: float, azimuth_deg: float = 0.0) -> F64:
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e)])


def _luma(rgb: F64) -> F64:
    out: F64 = np.asarray(rgb) @ cie_sky.LUMA
    return out


# -- (a) the CIE standard clear sky ----------------------------------------------------------


@pytest.mark.parametrize("vis_m", [30_000.0, 60_000.0])
@pytest.mark.parametrize("sun_deg", CIE_SUN_ELEVATIONS_DEG)
def test_clear_sky_luminance_follows_cie_type_12(
    luts_by_case: dict[tuple[float, float], atm.AtmosphereLuts], sun_deg: float, vis_m: float
) -> None:
    """The model's radiance (the sky-view table as the shader samples it) relative to the
    zenith, at 360 directions 5-80 deg up all round (the sun's half and the other)."""
    luts = _luts(luts_by_case, sun_deg, vis_m)
    sun = _sun_dir(sun_deg, 200.0)
    dirs = cie_sky.hemisphere_directions()
    assert len(dirs) >= 200
    toward = dirs[:, :2] @ sun[:2] > 0.0
    assert toward.sum() >= 100 and (~toward).sum() >= 100
    lum = _luma(luts.radiance(dirs, sun))
    zenith = float(_luma(luts.radiance(np.array([0.0, 0.0, 1.0]), sun)))
    result = cie_sky.compare(lum, zenith, dirs, sun)
    assert result.median <= CIE_MEDIAN, f"median error {result.median:.3f}"
    assert result.p90 <= CIE_P90, f"p90 error {result.p90:.3f}"


def test_cie_reference_is_one_at_the_zenith_and_brightest_near_the_sun() -> None:
    """The reference itself: 1 at the zenith, more toward the sun than away from it."""
    sun = _sun_dir(30.0)
    z = cie_sky.relative_luminance(cie_sky.CLEAR_LOW_TURBIDITY, np.array([[0.0, 0.0, 1.0]]), sun)
    assert z[0] == pytest.approx(1.0)
    near, far = cie_sky.relative_luminance(
        cie_sky.CLEAR_LOW_TURBIDITY, np.array([_sun_dir(35.0), _sun_dir(35.0, 180.0)]), sun
    )
    assert near > 3.0 * far


def _render_sky_linear(
    renderer: Renderer, luts: atm.AtmosphereLuts, sun: SunPosition, cam: Camera
) -> F64:
    """The physical sky pass drawn into a float target (no exposure, no tone map): (H, W, 3)
    radiance, rows top first, as the picture."""
    state = WeatherState(time_utc=datetime(2026, 6, 21, 12, 0, tzinfo=UTC))
    sky = dataclasses.replace(sky_params(state), sun=sun).with_atmosphere(luts)
    feats = sky_textures.SkyFeatures(
        stars=False, moon=False, dome=False, physical=True, scene_linear=True
    )
    ctx = renderer.ctx
    renderer._sky.use_atmosphere(luts)
    uniforms = renderer._sky_uniforms(cam, sky, feats, sky_textures.FULL_RECT)
    del uniforms["u_sky_scale"]  # the scene-linear variant has none
    tex = ctx.texture((cam.width_px, cam.height_px), 4, dtype="f4")
    fbo = ctx.framebuffer(color_attachments=[tex])
    try:
        fbo.use()
        ctx.disable(moderngl.BLEND)
        prog, vao = renderer._sky.prepare(feats)
        for name, value in uniforms.items():
            if name == "u_exposure" and prog.get(name, None) is None:
                continue  # display.glsl's: compiled out where unused
            prog[name].value = value  # type: ignore[union-attr]
        vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        data = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32)
    finally:
        release_framebuffer(fbo)
        tex.release()
    img = data.reshape(cam.height_px, cam.width_px, 4)[..., :3].astype(np.float64)
    # GL's rows run bottom up; the shader's NDC y runs down the picture from row 0 (sky.glsl),
    # so the framebuffer's row 0 is the picture's top row already.
    return img


def _camera_rays(cam: Camera) -> F64:
    """Each pixel's view direction, as sky.glsl makes it from gl_FragCoord (row 0 first)."""
    right, up, fwd = (np.asarray(v) for v in cam.basis())
    xs = ((np.arange(cam.width_px) + 0.5) / cam.width_px * 2.0 - 1.0) * cam.tan_half_fov_x
    ys = ((np.arange(cam.height_px) + 0.5) / cam.height_px * 2.0 - 1.0) * cam.tan_half_fov_y
    gx, gy = np.meshgrid(xs, ys)
    ray = fwd + gx[..., None] * right - gy[..., None] * up
    out: F64 = ray / np.linalg.norm(ray, axis=-1, keepdims=True)
    return out


@pytest.mark.gl
@pytest.mark.parametrize("sun_deg", CIE_SUN_ELEVATIONS_DEG)
def test_rendered_sky_read_back_in_float_follows_cie_type_12(
    renderer: Renderer,
    luts_by_case: dict[tuple[float, float], atm.AtmosphereLuts],
    sun_deg: float,
) -> None:
    """The same check on the sky pass itself: four views round the horizon and one straight
    up, drawn into a float framebuffer; the pixels 5 deg and more above the horizon and more
    than 5 deg from the sun (its disc and aureole are not part of CIE's sky)."""
    luts = _luts(luts_by_case, sun_deg, 30_000.0)
    sun = SunPosition(luts.sun_elevation_deg, 200.0)
    sun_dir = np.asarray(sun.direction_enu)
    dirs: list[F64] = []
    lums: list[F64] = []
    for heading in (20.0, 110.0, 200.0, 290.0, None):
        pitch = 90.0 if heading is None else 35.0
        cam = Camera((0.0, 0.0, 2.0), heading or 0.0, pitch, 0.0, 90.0, 48, 48)
        img = _render_sky_linear(renderer, luts, sun, cam)
        assert np.all(np.isfinite(img))
        rays = _camera_rays(cam).reshape(-1, 3)
        lum = _luma(img.reshape(-1, 3))
        keep = (rays[:, 2] >= math.sin(math.radians(5.0))) & (
            rays @ sun_dir < math.cos(math.radians(5.0))
        )
        dirs.append(rays[keep])
        lums.append(lum[keep])
        if heading is None:
            zenith = float(lum.reshape(48, 48)[23:25, 23:25].mean())
    all_dirs = np.concatenate(dirs)
    assert len(all_dirs) >= 200
    result = cie_sky.compare(np.concatenate(lums), zenith, all_dirs, sun_dir)
    assert result.median <= CIE_MEDIAN, f"median error {result.median:.3f}"
    assert result.p90 <= CIE_P90, f"p90 error {result.p90:.3f}"


# -- (b) twilight ----------------------------------------------------------------------------


def _red_over_blue(rgb: F64) -> float:
    return float(np.mean(rgb[..., 0]) / np.mean(rgb[..., 2]))


def test_belt_of_venus_above_the_earths_shadow(
    luts_by_case: dict[tuple[float, float], atm.AtmosphereLuts],
) -> None:
    """Sun at -4 deg, facing away from it: the sky 5-15 deg up is pinker (R/B higher) than
    the sky 30 deg higher (35-45 deg)."""
    luts = _luts(luts_by_case, -4.0, 30_000.0)
    sun = _sun_dir(-4.0, 0.0)
    az = np.radians(np.linspace(150.0, 210.0, 13))  # facing away: azimuth 180 +- 30

    def band(lo: float, hi: float) -> F64:
        els = np.radians(np.linspace(lo, hi, 6))
        e, a = np.meshgrid(els, az)
        d = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1)
        return luts.radiance(d.reshape(-1, 3), sun)

    low, high = band(5.0, 15.0), band(35.0, 45.0)
    assert _red_over_blue(low) > _red_over_blue(high)


def test_zenith_is_daylight_blue_with_the_sun_5_deg_up(
    luts_by_case: dict[tuple[float, float], atm.AtmosphereLuts],
) -> None:
    luts = _luts(luts_by_case, 5.0, 30_000.0)
    zenith = luts.radiance(np.array([0.0, 0.0, 1.0]), _sun_dir(5.0))
    assert zenith[2] > zenith[0]


# A clear noon sky overhead is blue, not whitish: B/R of its linear radiance (sRGB primaries) of
# 1.8 or more at 30 km (an aerosol optical depth of 0.23: the same air marched at 42
# wavelengths through the CIE observer gives 1.80, `tools/bench/cie_sky.py --spectral`) and 2.4
# at 60 km. Before the aerosol's Angstrom law it was 1.30 at 30 km, a whitish blue.
NOON_ZENITH_MIN_B_OVER_R = {30_000.0: 1.8, 60_000.0: 2.4}


@pytest.mark.parametrize("vis_m", [30_000.0, 60_000.0])
def test_noon_zenith_is_deep_blue_and_only_the_sun_and_horizon_whiten(
    luts_by_case: dict[tuple[float, float], atm.AtmosphereLuts], vis_m: float
) -> None:
    """Sun 60 deg up: the zenith's B/R is high, and higher still 64 deg from the sun (30 deg
    up, 90 deg round from it); the sky 10 deg from the sun and 2 deg above the horizon facing
    away are whiter than the zenith."""
    luts = _luts(luts_by_case, 60.0, vis_m)
    sun = _sun_dir(60.0)

    def b_over_r(rgb: F64) -> float:
        return float(rgb[2] / rgb[0])

    zenith = b_over_r(luts.radiance(np.array([0.0, 0.0, 1.0]), sun))
    assert zenith >= NOON_ZENITH_MIN_B_OVER_R[vis_m], f"zenith B/R {zenith:.2f}"
    side = b_over_r(luts.radiance(_sun_dir(30.0, 90.0), sun))
    assert side > zenith
    near_sun = b_over_r(luts.radiance(_sun_dir(50.0, 0.0), sun))
    horizon = b_over_r(luts.radiance(_sun_dir(2.0, 180.0), sun))
    assert near_sun < zenith and horizon < zenith


@pytest.mark.parametrize("sun_deg", [20.0, 5.0, -4.0, -6.0, -10.0])
def test_zenith_is_blue_not_mauve_from_afternoon_to_nautical_twilight(
    luts_by_case: dict[tuple[float, float], atm.AtmosphereLuts], sun_deg: float
) -> None:
    """The zenith is blue (B > G > R, B/R over 2) with the sun 20 and 5 deg up and through
    civil twilight into nautical (-4, -6, -10): the ozone's Chappuis band, absorbing the
    orange and yellow, keeps it so. Mauve (R at or above G under a larger B) was what three
    single wavelengths made of it, the red one (680 nm) beyond most of the band."""
    luts = _luts(luts_by_case, sun_deg, 30_000.0)
    r, g, b = luts.radiance(np.array([0.0, 0.0, 1.0]), _sun_dir(sun_deg))
    assert b > g > r, (r, g, b)
    assert b / r > 2.0, (r, g, b)


# -- (c) no NaN or inf -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("visibility_m", float("nan")),
        ("visibility_m", float("inf")),
        ("visibility_m", -5.0),
        ("visibility_m", 10.0),
        ("humidity_pct", float("nan")),
        ("humidity_pct", 120.0),
        ("humidity_pct", -1.0),
    ],
)
def test_bad_visibility_or_humidity_is_one_line_naming_key_and_range(
    key: str, value: float
) -> None:
    args = {"visibility_m": 20_000.0, "humidity_pct": 50.0} | {key: value}
    with pytest.raises(ValueError) as caught:
        atm.medium(args["visibility_m"], args["humidity_pct"])
    text = str(caught.value)
    assert "\n" not in text
    assert key in text
    kind = atm.VISIBILITY_M if key == "visibility_m" else atm.HUMIDITY_PCT
    assert kind.range_text() in text
    with pytest.raises(ValueError, match=key):
        atm.atmosphere_key(10.0, args["visibility_m"], args["humidity_pct"], 0.0)


@pytest.mark.parametrize(("vis_m", "rh"), [(50.0, 100.0), (1_000_000.0, 0.0)])
def test_tables_and_light_are_finite_at_the_ends_of_every_range(vis_m: float, rh: float) -> None:
    """Thickest fog to the clearest air, the sun from +90 to -90 deg, the eye at the ground and
    high: every table and every function finite (NaN or inf never reaches the shader)."""
    suns = np.array([90.0, 45.0, 5.0, 0.5, 0.0, -0.5, -4.0, -10.0, -18.0, -90.0])
    alts = np.array([0.0, 2.0, 1_000.0, 12_000.0, 20_000.0, 1e6, -100.0])
    for sun in (90.0, 0.0, -18.0):
        luts = atm.build_luts(atm.atmosphere_key(sun, vis_m, rh, 30_000.0 if sun == 0.0 else 0.0))
        for table in (luts.transmittance, luts.multiscatter, luts.ambient, luts.sky_view):
            assert np.all(np.isfinite(table)) and np.all(table >= 0.0)
        assert np.all(np.isfinite(luts.sky_view_radiance()))
        s, a = np.meshgrid(suns, alts)
        above, below = atm.sky_irradiance(luts, a, s)
        for values in (atm.sun_irradiance(luts, a, s), above, below):
            assert np.all(np.isfinite(values)) and np.all(values >= 0.0)
        assert np.all(np.isfinite(atm.moon_irradiance(luts, a, s, 0.5)))
        assert math.isfinite(atm.display_exposure(luts)) and atm.display_exposure(luts) > 0.0
        uniforms = sky_textures.physical_uniforms(luts)
        numbers = np.concatenate([np.ravel(np.asarray(v, np.float64)) for v in uniforms.values()])
        assert np.all(np.isfinite(numbers))


# -- (d) reference values --------------------------------------------------------------------


def test_vertical_transmittance_of_rayleigh_air_is_exp_minus_beta_h() -> None:
    """With (almost) no aerosol and no ozone, straight up from sea level: exp(-beta H)."""
    med = dataclasses.replace(atm.medium(1_000_000.0, 0.0), mie_extinction_per_m=0.0)
    saved = atm.OZONE_ABSORPTION_PER_M
    try:
        atm.OZONE_ABSORPTION_PER_M = np.zeros(3)
        table = atm.transmittance_table(med)
    finally:
        atm.OZONE_ABSORPTION_PER_M = saved
    got = atm._transmittance_to_top(table, np.array(atm.EARTH_RADIUS_M), np.array(1.0))
    want = np.exp(-atm.RAYLEIGH_SCATTERING_PER_M * atm.RAYLEIGH_SCALE_HEIGHT_M)
    np.testing.assert_allclose(got, want, rtol=0.01)
    assert want == pytest.approx(np.exp(-atm.vertical_rayleigh_optical_depth()), rel=1e-4)


def test_sun_reddens_toward_the_horizon_and_sets_higher_up_later() -> None:
    luts = atm.build_luts(atm.atmosphere_key(2.0, 30_000.0, 50.0, 0.0))
    noon, low = atm.sun_irradiance(luts, 0.0, np.array([60.0, 3.0]))
    assert noon[0] / noon[2] < low[0] / low[2]
    # Half a degree below the ground's horizon the ground is in shadow; a deck 3 km up is lit.
    ground, deck = atm.sun_irradiance(luts, np.array([0.0, 3_000.0]), -1.0)
    assert float(ground.max()) == 0.0
    assert float(deck.min()) > 0.0


def test_koschmieder_sets_the_aerosol() -> None:
    """beta_total = 3.912 / visibility at the ground: the aerosol makes up the rest after
    Rayleigh; humidity above 50 % grows it a little."""
    med = atm.medium(20_000.0, 50.0)
    assert med.mie_extinction_per_m + atm.RAYLEIGH_SCATTERING_PER_M[1] == pytest.approx(
        3.912 / 20_000.0
    )
    assert atm.medium(20_000.0, 30.0).mie_extinction_per_m == med.mie_extinction_per_m
    wet = atm.medium(20_000.0, 95.0).mie_extinction_per_m / med.mie_extinction_per_m
    assert 1.5 < wet < 2.0


def test_key_quantises_so_small_moves_do_not_rebuild() -> None:
    a = atm.atmosphere_key(10.0, 30_000.0, 50.0, 2.0)
    assert atm.atmosphere_key(10.05, 30_300.0, 51.0, 10.0) == a
    assert atm.atmosphere_key(10.3, 30_000.0, 50.0, 2.0) != a
    assert atm.atmosphere_key(10.0, 40_000.0, 50.0, 2.0) != a


# -- the setting -----------------------------------------------------------------------------


def test_scene_sky_setting_defaults_to_physical_and_checks_its_value(tmp_path: Path) -> None:
    assert load_config(None).scene.sky == "physical"
    assert SceneSettings().sky == "physical"
    good = tmp_path / "good.toml"
    good.write_text('[scene]\nsky = "roden-parberry"\n', encoding="utf-8")
    assert load_config(good).scene.settings().sky == "roden-parberry"
    bad = tmp_path / "bad.toml"
    bad.write_text('[scene]\nsky = "preetham"\n', encoding="utf-8")
    with pytest.raises(ConfigError) as caught:
        load_config(bad)
    text = str(caught.value)
    assert "sky" in text and "physical" in text and "roden-parberry" in text
    assert "\n" not in text.strip()


# -- off the frame path, and through the engine and renderer ---------------------------------


@pytest.mark.parametrize("process", [False, True], ids=["thread", "process"])
def test_worker_keeps_the_last_tables_until_the_new_ones_are_made(process: bool) -> None:
    """A live engine's frames never wait for a rebuild: the first call makes its tables,
    a moved key gets the last tables at once while the worker (a thread, or a child process
    below the frames) makes its own, and the next call after they are made gets them, under
    a serial no other tables in this process have had."""
    work = AtmosphereWork(wait=False, process=process)
    try:
        first_key = atm.atmosphere_key(20.0, 30_000.0, 50.0, 2.0)
        first = work.luts_for(first_key)
        assert first.key == first_key
        moved = atm.atmosphere_key(25.0, 30_000.0, 50.0, 2.0)
        assert work.luts_for(moved) is first  # not waited for
        deadline = time.monotonic() + 120.0  # only catches a hang
        got = first
        while got is first and time.monotonic() < deadline:
            time.sleep(0.05)
            got = work.luts_for(moved)
        assert got.key == moved
        assert work.builds == 2
        assert got.serial != first.serial
        assert np.array_equal(got.sky_view, atm.build_luts(moved).sky_view)
    finally:
        work.close()
        work.close()  # idempotent


def _sky_layer(renderer: Renderer, sky_mode: str, when: datetime, heading_deg: float) -> F64:
    state = WeatherState(time_utc=when, visibility_m=40_000.0)
    cam = Camera((0.0, 0.0, state.observer.alt_m + 2.0), heading_deg, 20.0, 0.0, 60.0, 96, 54)
    with SkyEngine(state, cam, SceneSettings(sky=sky_mode), render_mode="direct") as engine:
        plan = engine.advance(0.0)
    assert (plan.frame.sky.atmosphere is not None) == (sky_mode == "physical")
    renderer.render_frame(plan.frame)
    return renderer.read("sky")[..., :3].astype(np.float64) / 255.0


@pytest.mark.gl
def test_physical_sky_layer_is_blue_at_noon_and_differs_from_the_gradient(
    renderer: Renderer,
) -> None:
    """Through the engine and the renderer: the physical sky at noon, facing away from the
    sun, is blue overhead and brighter toward the horizon; the gradient mode is drawn as it
    was (its goldens hold it) and is another picture."""
    noon = datetime(2026, 6, 21, 12, 0, tzinfo=UTC)
    physical = _sky_layer(renderer, "physical", noon, 0.0)
    assert np.all(np.isfinite(physical))
    top, horizon = physical[:5].mean(axis=(0, 1)), physical[-12:-8].mean(axis=(0, 1))
    assert top[2] > top[1] > top[0]
    assert float(horizon @ cie_sky.LUMA) > float(top @ cie_sky.LUMA)
    gradient = _sky_layer(renderer, "roden-parberry", noon, 0.0)
    assert float(np.abs(physical - gradient).mean()) > 0.02


def test_overcast_veil_greys_and_dims_only_under_cover() -> None:
    assert scene_sky.overcast_veil(0.0) == (0.0, 1.0)
    assert scene_sky.overcast_veil(0.5) == (0.0, 1.0)
    share, dim = scene_sky.overcast_veil(1.0)
    assert share > 0.5 and dim < 0.5
    # The sky pass's steps of it stay within half a step of it.
    for cover in np.linspace(0.0, 1.0, 41):
        stepped = scene_sky.display_veil(float(cover))
        exact = scene_sky.overcast_veil(float(cover))
        assert max(abs(a - b) for a, b in zip(stepped, exact, strict=True)) <= 0.5 / 512


@pytest.mark.gl
def test_physical_sky_under_overcast_is_grey_not_a_blue_slot(renderer: Renderer) -> None:
    """Under overcast-stratus the physical sky layer (what shows below the deck at the
    horizon) is grey: its B/R within 5 % of 1 (the gradient's slot was B/R 1.22)."""
    state = WeatherState(time_utc=datetime(2026, 6, 21, 12, 0, tzinfo=UTC)).apply(
        load_preset("overcast-stratus")
    )
    cam = Camera((0.0, 0.0, state.observer.alt_m + 2.0), 45.0, 0.0, 0.0, 60.0, 96, 54)
    with SkyEngine(state, cam, SceneSettings(sky="physical"), render_mode="direct") as engine:
        plan = engine.advance(0.0)
    renderer.render_frame(plan.frame)
    sky = renderer.read("sky")[..., :3].astype(np.float64)
    band = sky[20:27].mean(axis=(0, 1))  # just above the horizon (the picture's middle row)
    assert abs(band[2] / band[0] - 1.0) < 0.05, band


@pytest.mark.gl
def test_rendered_twilight_has_the_belt_of_venus_and_a_blue_zenith_at_plus_5(
    renderer: Renderer,
    luts_by_case: dict[tuple[float, float], atm.AtmosphereLuts],
) -> None:
    """The twilight checks on the sky pass itself (float read-back): sun at -4 deg, facing
    away, the pixels 5-15 deg up are pinker than those 35-45 deg up; sun at +5 deg, the
    zenith is blue."""
    luts = _luts(luts_by_case, -4.0, 30_000.0)
    sun = SunPosition(luts.sun_elevation_deg, 0.0)
    cam = Camera((0.0, 0.0, 2.0), 180.0, 25.0, 0.0, 60.0, 64, 64)
    img = _render_sky_linear(renderer, luts, sun, cam).reshape(-1, 3)
    el = np.degrees(np.arcsin(_camera_rays(cam).reshape(-1, 3)[:, 2]))
    low, high = img[(el >= 5.0) & (el <= 15.0)], img[(el >= 35.0) & (el <= 45.0)]
    assert len(low) > 50 and len(high) > 50
    assert _red_over_blue(low) > _red_over_blue(high)
    day = _luts(luts_by_case, 5.0, 30_000.0)
    up = Camera((0.0, 0.0, 2.0), 0.0, 90.0, 0.0, 20.0, 16, 16)
    zenith = _render_sky_linear(renderer, day, SunPosition(day.sun_elevation_deg, 0.0), up)
    mean = zenith.reshape(-1, 3).mean(axis=0)
    assert mean[2] > mean[0]


def test_a_build_marches_in_slices_to_the_same_tables(monkeypatch: pytest.MonkeyPatch) -> None:
    import tracemalloc

    key = atm.atmosphere_key(5.0, 30_000.0, 50.0, 0.0)
    med = atm.medium(key.visibility_m, key.humidity_pct)
    tracemalloc.start()
    try:
        t_table = atm.transmittance_table(med)
        ms = atm.multiscatter_table(med, t_table)
        sliced = atm.sky_view_table(med, t_table, ms, 0.0, 5.0)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # Whole, the sky view's 20,736 rays made 233 MiB of temporaries at once: the daemon's
    # RSS swung by that with every rebuild.
    assert peak < 80 * 2**20
    monkeypatch.setattr(atm, "MARCH_SAMPLES", 10**9)
    whole = atm.sky_view_table(med, atm.transmittance_table(med), ms, 0.0, 5.0)
    assert np.array_equal(sliced, whole)


@pytest.mark.parametrize(("sun_deg", "visibility_m"), [(60.0, 40_000.0), (5.0, 10_000.0)])
def test_baked_display_table_is_within_a_level_of_the_exact_sky(
    sun_deg: float, visibility_m: float
) -> None:
    """The sky pass shows the baked table (`display_sky_view`, filtered) beyond the sun's own
    part: there it is within about a display level of the exact sky (the table's radiance
    filtered, the aureole at the pixel, the tone map); nearer the sun the table's 1-2 deg
    texels facet the aureole, which is why the sun's part is drawn per pixel."""
    luts = atm.build_luts(atm.atmosphere_key(sun_deg, visibility_m, 50.0, 2.0))
    horizon = luts.horizon_rad
    sun_el = math.radians(luts.sun_elevation_deg)
    sun = np.array([0.0, math.cos(sun_el), math.sin(sun_el)])
    strength, g = scene_sky.aureole(luts)
    exposure = atm.display_exposure(luts)
    table = scene_sky.display_sky_view(luts, 0.0)
    rng = np.random.default_rng(4)
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    el = np.arcsin(d[:, 2])
    keep = (el > horizon + 0.01) & (d @ sun < math.cos(math.radians(scene_sky.SUN_EXACT_BLEND_DEG)))
    d, el = d[keep], el[keep]
    u = np.arccos(np.clip(d[:, 1] / np.hypot(d[:, 0], d[:, 1]), -1.0, 1.0)) / math.pi
    v = atm.sky_view_v(el, horizon)
    k = 1.0 + g * g - 2.0 * g * (d @ sun)
    aureole = strength * ((1.0 - g * g) / (4.0 * math.pi * k * np.sqrt(k)))[:, None]
    radiance = atm.sample_table(luts.sky_view_radiance(), u, v) + aureole
    exact = display(radiance, exposure)
    baked = atm.sample_table(table, u, v)
    assert np.abs(baked - exact).max() < 1.5 / 255.0


def test_the_exposure_adapts_to_an_overcast_as_to_the_evening() -> None:
    """Under cover the scene is darker by the overcast veil's dimming, and the automatic
    exposure rises by its square root (the same partial adaptation as to a lower sun): an
    overcast dawn is a grey dawn, not night. Scattered cloud (no veil) leaves it alone."""
    luts = atm.build_luts(atm.atmosphere_key(5.0, 30_000.0, 50.0, 2.0))
    clear = scene_sky.scene_exposure(luts, 0.0)
    assert scene_sky.scene_exposure(luts, 0.5) == clear
    dim = scene_sky.display_veil(1.0)[1]
    assert scene_sky.scene_exposure(luts, 1.0) == pytest.approx(clear / dim**0.5)
    assert clear == atm.display_exposure(luts)
