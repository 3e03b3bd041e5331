"""The sky pass's shipped textures: the PNGs hold the generator's output, pixel for pixel
(not byte for byte: zlib builds differ); the tool's --check catches drift; the loaded arrays
have their documented shapes and encodings; the star cells' channels mean what sky_textures
says (R mean intensity, G flicker rate, B variance, A phase); the sunset gradient runs golden
to red along the sunset control and red to pink up the sky, smoothly; and the sky pass tints
the dusk dome from it.
"""

from __future__ import annotations

import dataclasses
import shutil
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from png_helpers import recompressed
from tool_loader import load_tool

from wxsky.app.snapshot import take_snapshot
from wxsky.png import encode_png, read_png
from wxsky.render.renderer import Renderer
from wxsky.render.sky_texture_gen import (
    DOME_FILE,
    DOME_NOISE_PX,
    GALAXY_FILE,
    GALAXY_SIZE_PX,
    SKY_FILES,
    STAR_FACE_PX,
    STAR_FILE,
    SUNSET_FILE,
    SUNSET_SIZE_PX,
    build_sky_textures,
)
from wxsky.render.sky_textures import (
    SkyPass,
    dome_noise_texture,
    galaxy_texture,
    star_texture,
    sunset_texture,
)
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.scene.sky import sky_params
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "wxsky" / "render" / "data"

U8 = npt.NDArray[np.uint8]


TOOL = load_tool("generate/build_sky_textures")


@pytest.fixture(scope="module")
def generated() -> dict[str, U8]:
    return build_sky_textures()


# -- the shipped files ------------------------------------------------------------------


def test_shipped_files_are_the_generators_output(generated: dict[str, U8]) -> None:
    assert tuple(generated) == SKY_FILES == (STAR_FILE, GALAXY_FILE, DOME_FILE, SUNSET_FILE)
    for name, img in generated.items():
        assert name.startswith("sky_") and name.endswith(".png")
        assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 4
        shipped = read_png(DATA / name)
        np.testing.assert_array_equal(shipped, img, err_msg=f"{name} is stale: run the tool")
    np.testing.assert_array_equal(star_texture(), generated[STAR_FILE])
    np.testing.assert_array_equal(galaxy_texture(), generated[GALAXY_FILE][..., 0])
    np.testing.assert_array_equal(dome_noise_texture(), generated[DOME_FILE])
    np.testing.assert_array_equal(sunset_texture(), generated[SUNSET_FILE])


def test_generation_is_deterministic(generated: dict[str, U8]) -> None:
    again = build_sky_textures()
    for name, img in generated.items():
        assert again[name].tobytes() == img.tobytes(), name


def test_check_flag_catches_drift(tmp_path: Path) -> None:
    for name in SKY_FILES:
        shutil.copyfile(DATA / name, tmp_path / name)
    assert TOOL.main(["--check"]) == 0  # the package's own files
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 0
    # The same pixels compressed otherwise (another machine's zlib) are up to date.
    (tmp_path / GALAXY_FILE).write_bytes(recompressed((DATA / GALAXY_FILE).read_bytes()))
    assert (tmp_path / GALAXY_FILE).read_bytes() != (DATA / GALAXY_FILE).read_bytes()
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 0
    changed = read_png(DATA / GALAXY_FILE)
    changed[7, 9, :3] ^= 1
    (tmp_path / GALAXY_FILE).write_bytes(encode_png(changed))
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 1
    (tmp_path / GALAXY_FILE).write_bytes((DATA / GALAXY_FILE).read_bytes()[:-40])
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 1  # cut short
    shutil.copyfile(DATA / GALAXY_FILE, tmp_path / GALAXY_FILE)
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 0
    (tmp_path / STAR_FILE).unlink()
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 1
    shutil.copyfile(DATA / STAR_FILE, tmp_path / STAR_FILE)
    (tmp_path / SUNSET_FILE).unlink()
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 1


def test_tool_writes_the_files(tmp_path: Path) -> None:
    out = tmp_path / "data"
    assert TOOL.main(["--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(SKY_FILES)
    for name in SKY_FILES:
        np.testing.assert_array_equal(read_png(out / name), read_png(DATA / name), err_msg=name)


# -- what the renderer loads ------------------------------------------------------------


def test_loaded_arrays_have_the_documented_shapes() -> None:
    n = STAR_FACE_PX
    w, h = GALAXY_SIZE_PX
    sunset_w, sunset_h = SUNSET_SIZE_PX
    expected = {
        star_texture: (6 * n, n, 4),
        galaxy_texture: (h, w),
        dome_noise_texture: (DOME_NOISE_PX, DOME_NOISE_PX, 4),
        sunset_texture: (sunset_h, sunset_w, 4),
    }
    for load, shape in expected.items():
        arr = load()
        assert arr.shape == shape and arr.dtype == np.uint8, load.__name__
        assert not arr.flags.writeable, load.__name__  # shared through the cache
        assert arr.flags.c_contiguous, load.__name__  # uploaded with tobytes()
        assert load() is arr, load.__name__  # read once


def test_galaxy_file_is_grey_and_opaque(generated: dict[str, U8]) -> None:
    img = generated[GALAXY_FILE]
    assert (img[..., 0] == img[..., 1]).all() and (img[..., 0] == img[..., 2]).all()
    assert (img[..., 3] == 255).all()
    glow = galaxy_texture()
    assert glow.max() == 255  # normalised to its peak
    h = GALAXY_SIZE_PX[1]
    # Brightest along the galactic plane (the middle rows), faint at the poles.
    assert glow[h // 2 - 8 : h // 2 + 8].mean() > 4 * glow[: h // 8].mean()


def test_star_channels_mean_what_they_say() -> None:
    tex = star_texture()
    mean = tex[..., 0]
    has_star = mean > 0
    # R, mean intensity 0..1: mostly dark background (no star in 88-96 % of the cells) ...
    assert 0.88 < 1.0 - has_star.mean() < 0.96
    stars = tex[has_star].astype(int)
    r, g, b, a = (stars[:, k] for k in range(4))
    # ... and some bright stars among many faint ones.
    assert (r >= 200).sum() >= 10
    assert np.median(r) < 32
    # An empty cell is all zero: no flicker, variance or phase without a star.
    assert not tex[~has_star].any()
    # G, flicker rate (0.15-1 of STAR_RATE_SCALE_HZ): spread over its range, never zero.
    assert 0.15 * 255 - 1 <= g.min() < 45 and g.max() > 250
    assert np.histogram(g, bins=8, range=(38, 256))[0].min() > 0.08 * len(g)
    # B, variance: 0.15-0.45 of the mean, so the brightness R + B·sin stays above zero.
    assert (b <= r).all()
    # A, phase 0..1: spread evenly over the whole cycle.
    assert a.min() < 3 and a.max() > 252
    assert np.histogram(a, bins=8, range=(0, 256))[0].min() > 0.1 * len(a)


# -- the sunset gradient ----------------------------------------------------------------


def test_sunset_gradient_is_red_low_down_and_golden_before_sunset() -> None:
    rgb = sunset_texture()[..., :3].astype(float)
    assert (sunset_texture()[..., 3] == 255).all()
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    # Columns: the sunset control, 0 (golden late afternoon) .. 1 (sun on the horizon); rows:
    # the height in the sky, row 0 at the horizon.
    horizon, top = 0, -1
    full, late_afternoon = -1, 0
    # With the sun on the horizon the low cloud is red-orange, the high cloud pinker.
    assert r[horizon, full] / b[horizon, full] > 2.0 * r[top, full] / b[top, full]
    assert r[horizon, full] / b[horizon, full] > 4.0  # deep red-orange
    assert b[top, full] > g[top, full]  # pink-magenta, not orange
    # Before that, golden-yellow at every height: more green for its red than at full sunset.
    yellowness = g / r
    assert (yellowness[:, late_afternoon] > yellowness[:, full] + 0.15).all()
    assert (yellowness[:, late_afternoon] > 0.7).all()
    # Redder all the way as the sun goes down, and towards the horizon at full sunset.
    assert (np.diff(yellowness, axis=1) <= 0.01).all()
    assert (np.diff(r[:, full] / b[:, full]) <= 0).all()


def test_sunset_gradient_is_smooth() -> None:
    """No banding under bilinear filtering: neighbouring texels differ by a few levels, and
    the slope itself changes gently (no creases where the colour stops meet)."""
    tex = sunset_texture()[..., :3].astype(int)
    for axis in (0, 1):
        step = np.diff(tex, axis=axis)
        assert np.abs(step).max() <= 10, axis
        assert np.abs(np.diff(step, axis=axis)).max() <= 4, axis


# -- the sky pass uses it ---------------------------------------------------------------

# High cirrus with the sun 4° up in the west-north-west: Roden & Parberry's sunset control
# near 1, the dome's clouds in view above the horizon.
DUSK = datetime(2026, 6, 21, 18, 55, tzinfo=UTC)


def test_dusk_dome_is_tinted_from_the_sunset_texture_on_unit_4(renderer: Renderer) -> None:
    """The sunset colour is the texture's, bound on unit 4: swap the texture's red and blue
    and the dusk clouds turn from red-orange to blue, while a picture without the dome stays
    the same."""
    assert SkyPass.UNITS["u_sunset_tex"] == 4
    assert sorted(SkyPass.UNITS.values()) == [1, 2, 3, 4, 5, 6]  # unit 0 is the sprite sheet's
    state = dataclasses.replace(WeatherState().apply(load_preset("high-cirrus")), time_utc=DUSK)
    assert sky_params(state).dome.sunset > 0.9
    cam = Camera(
        position_m=(0.0, 0.0, state.observer.alt_m + 2.0),
        heading_deg=300.0,
        pitch_deg=20.0,
        fov_deg=60.0,
        width_px=320,
        height_px=180,
    )
    # The sunset texture is Roden and Parberry's dome's: their sky mode.
    settings = SceneSettings(max_range_m=16_000.0, sky="roden-parberry")

    def sky_layer() -> npt.NDArray[np.int64]:
        return take_snapshot(state, cam, settings, renderer).layers["sky"].astype(np.int64)

    tinted = sky_layer()
    sky_pass = renderer._sky
    swapped = np.ascontiguousarray(sunset_texture()[..., [2, 1, 0, 3]])
    # A texture rewritten behind the renderer's back: the sky it keeps is stale (_draw_sky
    # compares only the numbers a sky is drawn from).
    sky_pass.sunset.write(swapped.tobytes())
    renderer._sky_drawn.clear()
    try:
        blued = sky_layer()
    finally:
        sky_pass.sunset.write(sunset_texture().tobytes())
        renderer._sky_drawn.clear()
    assert np.array_equal(sky_layer(), tinted)  # restored
    changed = np.abs(blued - tinted).max(axis=-1) > 8
    # The cloud, not the whole sky, changes: a broken veil.
    assert 0.1 < changed.mean() < 0.9
    # Where it changed it was red-orange and lost much of its red for blue (the thin cloud
    # lets the orange sky behind it through, so it does not turn fully blue).
    redness, redness_swapped = (img[..., 0] - img[..., 2] for img in (tinted, blued))
    assert np.median(redness[changed]) > 40
    # (Through the hazy layer the dome keeps about 60 % of its own colour at 20 degrees up
    # in 50 km visibility, Koschmieder's haze: so 30 of the 40-odd of redness, not all.)
    assert np.median((redness - redness_swapped)[changed]) > 20
