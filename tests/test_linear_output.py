"""Scene-linear output and exposure (issue 41, item 4): the tone map and its inverse, the
float layers behind `snapshot --linear-out`, the files it writes, the `[render] exposure`
override and the automatic exposure."""

from __future__ import annotations

import dataclasses
import itertools
import math
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from wxsky.app.snapshot import Snapshot, linear_picture, read_pfm, take_snapshot, write_linear
from wxsky.engine.stages import SkyEngine
from wxsky.errors import ConfigError
from wxsky.png import read_png
from wxsky.render.renderer import Renderer
from wxsky.scene import exposure as ex
from wxsky.scene.camera import Camera
from wxsky.scene.ephemeris import sun_and_moon
from wxsky.settings.config import DaemonConfig, load_config
from wxsky.settings.presets import load_preset
from wxsky.weather.state import Source, WeatherPatch, WeatherState

SETTINGS = dataclasses.replace(DaemonConfig().scene.settings(), ring_texture_px=128)
W, H = 192, 108


def state_of(preset: str, time_utc: datetime | None = None) -> WeatherState:
    state = WeatherState().apply(load_preset(preset, ()))
    if time_utc is not None:
        state = state.apply(WeatherPatch(source=Source.CONTROL, time_utc=time_utc))
    return state


def camera_for(state: WeatherState, heading_deg: float = 0.0, pitch_deg: float = 12.0) -> Camera:
    return Camera(
        position_m=(0.0, 0.0, state.observer.alt_m + 2.0),
        heading_deg=heading_deg % 360.0,
        pitch_deg=pitch_deg,
        width_px=W,
        height_px=H,
    )


def shot(
    renderer: Renderer,
    state: WeatherState,
    cam: Camera,
    linear: bool = True,
    exposure_setting: float | str = ex.AUTO,
) -> Snapshot:
    return take_snapshot(
        state, cam, SETTINGS, renderer, linear=linear, exposure_setting=exposure_setting
    )


# -- the tone map ------------------------------------------------------------------------------


def test_legacy_colours_come_back_unchanged_at_the_legacy_exposure() -> None:
    levels = np.arange(256, dtype=np.float64) / 255.0
    grid = np.stack(np.meshgrid(levels, levels[::5], levels[::17], indexing="ij"), -1)
    back = ex.display(ex.from_legacy(grid), ex.LEGACY_EXPOSURE)
    assert np.abs(np.round(back * 255.0) - np.round(grid * 255.0)).max() == 0


def test_tone_map_keeps_a_bright_sky_blue_blue_and_rolls_highlights_off() -> None:
    blue = np.array([0.25, 0.45, 0.9])
    for scale in (1.0, 4.0, 8.0):
        out = ex.tone_map(blue * scale)
        # Max-RGB keeps the ratios: no drift to cyan (green catching up with blue).
        assert out[1] / out[2] == pytest.approx(blue[1] / blue[2], rel=1e-9)
        assert out[0] / out[2] == pytest.approx(blue[0] / blue[2], rel=1e-9)
    # Past the curve's white (8 x 0.9 is just under it) a colour burns toward white, not
    # toward cyan: both ratios rise, blue stays the largest, and far past it (the sun's
    # disc) it is nearly white.
    ratios = []
    for scale in (8.0, 16.0, 32.0, 1000.0):
        out = ex.tone_map(blue * scale)
        assert out[2] == pytest.approx(1.0 if scale > 8.0 else out[2]) and out.argmax() == 2
        ratios.append((out[0] / out[2], out[1] / out[2]))
    assert all(a[0] < b[0] and a[1] < b[1] for a, b in itertools.pairwise(ratios))
    assert ratios[-1][0] > 0.9 and ratios[-1][1] > 0.9
    x = np.array([0.5, 1.0, 2.0, 4.0, 7.0])
    y = ex.tone_curve(x)
    assert np.all(np.diff(y) > 0.0) and y[-1] < 1.0  # still rising at 7x: a shoulder, no clip
    assert ex.tone_curve(np.array([ex.TM_WHITE]))[0] == pytest.approx(1.0)
    assert np.allclose(ex.tone_curve(ex.tone_curve_inverse(y)), y)


def test_display_channel_by_channel_is_display() -> None:
    """`display_channels`, the sprites' every-frame form ((3, N), the burn skipped where nothing
    reaches the curve's white), gives `display`'s values: black, the toe, the shoulder, past
    the white (burnt), at two exposures."""
    rng = np.random.default_rng(41)
    for top in (0.01, 3.0, 30.0, 1e4):
        rgb = rng.random((3, 500)) * top
        rgb[:, :4] = 0.0
        rgb[1, 4] = 1e-9
        for scale in (1.0, 0.25):
            np.testing.assert_allclose(
                ex.display_channels(rgb, scale), ex.display(rgb.T, scale).T, rtol=0, atol=1e-12
            )
    assert ex.display_channels(np.zeros((3, 0)), 1.0).shape == (3, 0)


def test_display_glsl_holds_exposure_py_s_constants() -> None:
    """The shader's tone map is exposure.py's: the same numbers, written twice."""
    import re

    text = (Path(ex.__file__).parents[1] / "render" / "shaders" / "display.glsl").read_text()
    found = dict(re.findall(r"const float (\w+) = ([0-9.eE+-]+);", text))
    for name in ("TM_A", "TM_B", "TM_C", "TM_D", "TM_E", "TM_WHITE", "BURN_FULL", "BURN_MAX"):
        assert float(found[name]) == pytest.approx(getattr(ex, name), rel=1e-12), name


# -- float layers and the files ----------------------------------------------------------------


@pytest.mark.gl
def test_linear_snapshot_is_what_the_shaders_computed(renderer: Renderer, tmp_path: Path) -> None:
    # A clear sky: display() of the scene-linear colour the float layer holds (half floats)
    # gives the 8-bit picture back: the shader's from_legacy and this module's display are each
    # other's inverse, within a level.
    state = state_of("clear")
    s = shot(renderer, state, camera_for(state))
    assert s.linear is not None and s.linear.shape == (H, W, 3) and s.linear.dtype == np.float32
    back = np.round(ex.display(s.linear, ex.LEGACY_EXPOSURE) * 255.0)
    assert np.abs(back - s.image[..., :3]).max() <= 1.0
    # And it is the float layer the sky shader wrote, unchanged (no clouds: the composite is
    # the sky layer; half floats widened to float32 exactly).
    with SkyEngine(state, camera_for(state), SETTINGS, clock_rate=0.0) as engine:
        plan = engine.advance(0.0)
    with Renderer(SETTINGS.ring_texture_px, ctx=renderer.ctx, output="linear") as lin:
        lin.render_ring(plan.ring)
        lin.render_frame(plan.frame)
        sky = lin.read_linear("sky")
    assert np.array_equal(s.linear, sky[..., :3]) and (sky[..., 3] == 1.0).all()
    assert np.array_equal(linear_picture(renderer, plan, SETTINGS), s.linear)
    # The files hold exactly that array, in either format.
    for name in ("x.npy", "x.pfm"):
        write_linear(tmp_path / name, s.linear)
    assert np.array_equal(np.load(tmp_path / "x.npy"), s.linear)
    assert np.array_equal(read_pfm(tmp_path / "x.pfm"), s.linear)
    # Clouds: every layer drawn again into float targets and composited as a host does.
    # Blending happens before the tone map there and after it in the 8-bit layers, so only
    # translucent overlaps differ: on average by less than 2 levels.
    state = state_of("fair-cumulus")
    s = shot(renderer, state, camera_for(state))
    assert s.linear is not None
    assert np.isfinite(s.linear).all() and s.linear.min() >= 0.0
    cloud = s.layers["near"][..., 3].astype(np.float64).mean() / 255.0
    assert cloud > 0.05  # the picture has clouds in it
    back = np.round(ex.display(s.linear, ex.LEGACY_EXPOSURE) * 255.0)
    assert np.abs(back - s.image[..., :3]).mean() < 2.0


def sun_top_left_camera(state: WeatherState) -> Camera:
    sun, _ = sun_and_moon(state.time_utc, state.observer.lat_deg, state.observer.lon_deg)
    # The sun 18 deg left of the middle (of 60 across) and 9 up (of ~34 down): top-left.
    return camera_for(state, sun.azimuth_deg + 18.0, sun.elevation_deg - 9.0)


@pytest.mark.gl
def test_pfm_and_npy_put_the_sun_top_left(renderer: Renderer, tmp_path: Path) -> None:
    state = state_of("clear", datetime(2026, 6, 21, 16, 0, tzinfo=UTC))
    s = shot(renderer, state, sun_top_left_camera(state))
    assert s.linear is not None
    lum = ex.luminance(s.linear)
    row, col = np.unravel_index(np.argmax(lum), lum.shape)
    assert row < H // 2 and col < W // 2, (row, col)  # the scene itself is the right way up
    write_linear(tmp_path / "sun.pfm", s.linear)
    write_linear(tmp_path / "sun.npy", s.linear)
    for loaded in (read_pfm(tmp_path / "sun.pfm"), np.load(tmp_path / "sun.npy")):
        lum = ex.luminance(loaded)
        row, col = np.unravel_index(np.argmax(lum), lum.shape)
        assert row < H // 2 and col < W // 2, (row, col)
    # The PFM's own layout, read by hand: rows bottom first, little-endian ("-1.0").
    raw = (tmp_path / "sun.pfm").read_bytes()
    header = f"PF\n{W} {H}\n-1.0\n".encode()
    assert raw.startswith(header)
    first_row = np.frombuffer(raw[len(header) :], "<f4", count=W * 3).reshape(W, 3)
    assert np.array_equal(first_row, s.linear[-1])


def run_snapshot(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """`wxsky snapshot` of the clear preset at 64x36 with `args`, file names in tmp_path."""
    command = [sys.executable, "-m", "wxsky", "snapshot", "--preset", "clear", "--size", "64x36"]
    files = ("--out", "--linear-out")
    given = [str(tmp_path / a) if i > 0 and args[i - 1] in files else a for i, a in enumerate(args)]
    return subprocess.run([*command, *given], capture_output=True, text=True, timeout=600)


@pytest.mark.gl
def test_snapshot_command_writes_linear_files(tmp_path: Path) -> None:
    for name in ("sky.pfm", "sky.npy"):
        out = run_snapshot(tmp_path, "--out", "sky.png", "--linear-out", name)
        assert out.returncode == 0, out.stderr
    png = read_png(tmp_path / "sky.png")
    for loaded in (read_pfm(tmp_path / "sky.pfm"), np.load(tmp_path / "sky.npy")):
        assert loaded.shape == (36, 64, 3)
        back = np.round(ex.display(loaded, ex.LEGACY_EXPOSURE) * 255.0)
        assert np.abs(back - png[..., :3]).max() <= 1.0
    bad = run_snapshot(tmp_path, "--out", "b.png", "--linear-out", "b.exr")
    assert bad.returncode == 2
    assert bad.stderr.strip().count("\n") == 0 and "--linear-out" in bad.stderr
    assert ".pfm or .npy" in bad.stderr
    # --exposure: EV +1 is brighter than the default; out of range, a one-line usage error.
    brighter = run_snapshot(tmp_path, "--out", "ev1.png", "--exposure", "1")
    assert brighter.returncode == 0, brighter.stderr
    ev1 = read_png(tmp_path / "ev1.png")[..., :3].astype(int)
    assert ev1.mean() > png[..., :3].mean() + 10.0 and (ev1 - png[..., :3]).min() >= 0
    for value in ("25", "nan", "bright"):
        refused = run_snapshot(tmp_path, "--out", "x.png", "--exposure", value)
        assert refused.returncode == 2
        assert refused.stderr.strip().count("\n") == 0
        assert '--exposure: must be "auto" or a number of EV in -20..20' in refused.stderr


# -- exposure ----------------------------------------------------------------------------------


@pytest.mark.gl
def test_exposure_override_brightens_the_8bit_layers_monotonically(renderer: Renderer) -> None:
    state = state_of("fair-cumulus")
    cam = camera_for(state)
    pictures, skies = [], []
    for ev in (-2.0, -1.0, 0.0, 1.0, 2.0):
        s = shot(renderer, state, cam, False, ev)
        pictures.append(s.image[..., :3].astype(int))
        skies.append(float(s.layers["sky"][..., :3].mean()))
    means = [float(p.mean()) for p in pictures]
    assert all(b > a + 1.0 for a, b in itertools.pairwise(means)), means
    # The kept sky layer is drawn again when the exposure changes (its uniforms hold it).
    assert all(b > a + 1.0 for a, b in itertools.pairwise(skies)), skies
    for a, b in itertools.pairwise(pictures):
        # Per pixel too (the near layer's stretch and blends allow a level).
        assert (b - a).min() >= -1, (b - a).min()
    # EV 0 is today's look, bit for bit ("auto" holds it while the colours are legacy).
    assert np.array_equal(pictures[2], shot(renderer, state, cam, False).image[..., :3])
    assert renderer.exposure == ex.LEGACY_EXPOSURE  # the shared renderer got its own back


@pytest.mark.gl
def test_exposure_never_takes_nan_or_inf(renderer: Renderer) -> None:
    before = renderer.exposure
    for bad in (math.nan, math.inf, -math.inf, 0.0, -1.0, 2.0**21):
        with pytest.raises(ValueError, match="exposure scale"):
            renderer.exposure = bad
        assert renderer.exposure == before
    for ev in (math.nan, math.inf, 21.0):
        with pytest.raises(ValueError, match="exposure"):
            ex.scale_of_ev(ev)
    # A renderer made for EV 0 only (its legacy round trip compiled out) says so.
    assert not renderer.variable_exposure
    with pytest.raises(ValueError, match="EV 0 only"):
        renderer.exposure = 2.0
    assert renderer.exposure == before
    with Renderer(ring_texture_px=16, ctx=renderer.ctx, variable_exposure=True) as variable:
        variable.exposure = 2.0
        assert variable.exposure == 2.0
        with pytest.raises(ValueError, match="exposure scale"):
            variable.exposure = math.nan
        assert variable.exposure == 2.0


@pytest.mark.parametrize(
    ("value", "shown"),
    [('"bright"', "'bright'"), ("nan", "nan"), ("inf", "inf"), ("25", "25"), ("true", "True")],
)
def test_render_exposure_config_errors_name_the_key_and_range(
    tmp_path: Path, value: str, shown: str
) -> None:
    path = tmp_path / "x.toml"
    path.write_text(f"[render]\nexposure = {value}\n", encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}:2: render.exposure:"), message
    assert '"auto" or a number of EV in -20..20' in message and shown in message


def test_render_exposure_config_accepts_auto_and_ev(tmp_path: Path) -> None:
    assert load_config(None).render.exposure == ex.AUTO
    path = tmp_path / "x.toml"
    path.write_text("[render]\nexposure = -2.5\n", encoding="utf-8")
    assert load_config(path).render.exposure == -2.5


@pytest.mark.gl
def test_auto_exposure_gives_a_dark_scene_more_than_a_bright_one(renderer: Renderer) -> None:
    metered, meter = {}, {}
    for name, hour in (("noon", 12), ("dusk", 20)):
        state = state_of("clear", datetime(2026, 6, 21, hour, 0, tzinfo=UTC))
        s = shot(renderer, state, camera_for(state, 180.0))
        assert s.linear is not None
        metered[name] = ex.log_average_luminance(s.linear)
        # The daemon's meter: the 8-bit sky and near layers the snapshot's display renderer
        # holds, sampled at 64x36 on the GPU and read back, turned back into scene-linear.
        meter[name] = renderer.meter_log_average()
    assert metered["dusk"] < metered["noon"] / 2.0, metered
    for name, value in meter.items():
        assert value == pytest.approx(metered[name], rel=0.1), (meter, metered)
    assert ex.auto_target_ev(metered["dusk"]) > ex.auto_target_ev(metered["noon"]) + 1.0
    # An eye adapting: from the noon exposure, the dusk frames move it a little at first and
    # nearly all the way within about a second (30 frames a second).
    eye = ex.AutoExposure(ev=ex.auto_target_ev(metered["noon"]))
    start, target = eye.ev, ex.auto_target_ev(metered["dusk"])
    first = eye.update(metered["dusk"], 1.0 / 30.0)
    assert start < first < start + 0.2 * (target - start)
    for _ in range(35):
        eye.update(metered["dusk"], 1.0 / 30.0)
    assert abs(eye.ev - target) < 0.06 * (target - start)
    # Nothing non-finite gets in: a NaN picture meters as the floor, a bad dt moves nothing.
    assert math.isfinite(ex.log_average_luminance(np.full((4, 4, 3), np.nan)))
    assert eye.update(math.nan, math.nan) == eye.ev
    assert math.isfinite(eye.update(math.inf, 1.0))


@pytest.mark.gl
def test_the_daemon_draws_at_the_configured_exposure(tmp_path: Path) -> None:
    from daemon_harness import DaemonSpec, running_daemons

    from wxsky.host.reference import ReferenceHost

    # Small pictures and impostors (the default 960x540 and 512 texels drew far more than the
    # sky's mean needs): both daemons alike, only the exposure differs.
    small = f"[camera]\nwidth = {W}\nheight = {H}\n[scene]\nring_texture_px = 128\n"
    specs = []
    for name, extra in (("ev0", ""), ("ev1", "[render]\nexposure = 1.0\n")):
        (tmp_path / name).mkdir()
        specs.append(DaemonSpec(tmp_path / name, extra_config=small + extra))
    skies = []
    with running_daemons(specs) as daemons:
        for d in daemons:
            with ReferenceHost.connect(d.address) as host:
                frame = host.wait_frame(timeout_s=120.0)
                skies.append(frame.layers.sky[..., :3].astype(np.float64))
    # Same preset, camera and sun: the EV +1 daemon's sky is brighter everywhere it is not
    # already white, and never darker.
    assert skies[1].mean() > skies[0].mean() + 10.0, (skies[0].mean(), skies[1].mean())
    assert (skies[1] - skies[0]).min() >= -2.0


def test_the_memory_check_counts_the_linear_picture() -> None:
    from wxsky.app.snapshot import snapshot_bytes

    settings = DaemonConfig().scene.settings()
    extra = snapshot_bytes(1920, 1080, settings, linear=True) - snapshot_bytes(1920, 1080, settings)
    # `--linear-out` raised a clear 1920x1080 snapshot's peak by 76 MB (snapshot.py).
    assert extra >= 76 * 2**20


def test_the_tone_curve_keeps_dark_values_apart() -> None:
    """The toe has a slope of 1: a level field under a low sun, a tenth of the sky's
    luminance, shows at about a tenth of its display light, not crushed toward black (the
    ACES fit's own toe, slope 0.21, showed it at a twentieth to a fortieth)."""
    x = np.geomspace(1e-5, 1e-2, 16)
    slope = ex.tone_curve(x) / x
    assert np.all(slope > 0.9) and np.all(slope < 1.2)
    mid = 0.12  # an exposed mid-tone: the automatic exposure's sky mean
    for share in (0.1, 0.05):
        shown = ex.tone_curve(np.array([share * mid]))[0] / ex.tone_curve(np.array([mid]))[0]
        assert shown > 0.5 * share, (share, shown)
