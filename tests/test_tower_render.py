"""Towers drawn by the GL pass (render/towers.py; issue 17, items 3 and 4): the marched light
agrees with numpy's, images marched a band at a time are the images marched at once, and a
tower lands in the near layer where its volume is."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wxsky.render.renderer import Renderer
from wxsky.render.towers import BILLOW_SHADOW
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SpriteDraw
from wxsky.scene.sky import sky_params
from wxsky.scene.sprites import SpriteBatch
from wxsky.scene.tower_field import LitVolume, TowerShow, lit_volume
from wxsky.scene.tower_shading import colours_of, tower_light, view_weights
from wxsky.settings.presets import load_preset
from wxsky.towers.volume import TowerSpec
from wxsky.weather.state import WeatherState

# Every test makes renderers of its own.
pytestmark = pytest.mark.gl

# A box of exactly 1 km a side: cells of 1000/64 m in every direction.
SPEC = TowerSpec(weather_seed=3, block=(0, 0), cell=0, width_m=600.0, height_m=900.0)
CENTRE = (0.0, 20_000.0, 3000.0)


class _Ball:
    """A soft ball of cloud as a volume with a `density_of_step`, lit like a tower."""

    def __init__(self) -> None:
        n = SPEC.grid
        z, y, x = np.meshgrid(*(np.arange(n) + 0.5,) * 3, indexing="ij")
        r = np.sqrt((x - 32) ** 2 + (y - 32) ** 2 + (z - 32) ** 2) / 20.0
        self.density = np.clip(1.6 * (1.0 - r), 0.0, 1.0).astype(np.float32)
        self.spec = SPEC

    def density_of_step(self, step_n: int) -> np.ndarray:
        return self.density


def _sky():
    return sky_params(WeatherState().apply(load_preset("towering-cumulus")))


def _show(lit: LitVolume, eye: tuple[float, float, float]) -> TowerShow:
    return TowerShow(
        spec=SPEC,
        layer=0,
        cloud_id=1,
        centre_m=CENTRE,
        age_s=0.0,
        distance_m=math.dist(CENTRE, eye),
        alpha=1.0,
        haze=0.0,
        volumes=(lit,),
    )


def _camera(eye: tuple[float, float, float], fov_deg: float = 4.0) -> Camera:
    return Camera(eye, heading_deg=0.0, pitch_deg=0.0, fov_deg=fov_deg, width_px=320, height_px=240)


def _image(renderer: Renderer, show: TowerShow) -> np.ndarray:
    imp = renderer.towers._shown[show.spec]
    image = imp.images[0]
    w, h = image.texture.size
    return np.frombuffer(image.fbo.read(components=4), np.uint8).reshape(h, w, 4) / 255.0


def test_marched_light_agrees_with_numpy_seen_from_afar() -> None:
    """Seen from 20 km along +y (close to a parallel view), with no detail noise (nor the
    billows' own shade), no sharpening, the light's own extinction and a sample a cell,
    each texel is numpy's cells composited along its ray: premultiplied colours agree to
    0.02 on average."""
    sky = _sky()
    ball = _Ball()
    lit = lit_volume(ball, 0, sky)  # type: ignore[arg-type]
    eye = (0.0, 0.0, 3000.0)
    show = _show(lit, eye)
    with Renderer(64) as r:
        towers = r.towers
        towers.erosion, towers.sharpen, towers.view_extinction = 0.0, 0.0, 1.0
        towers.billow_shadow = 0.0
        towers.march_steps = SPEC.grid
        towers.prepare((show,), _camera(eye), sky, 320)
        got = _image(r, show)
        imp = towers._shown[SPEC]
        assert r.ctx.error == "GL_NO_ERROR"
    # numpy: the cells' colours for this view, composited front (low y) to back.
    light = tower_light(ball.density, sky, SPEC.extinction_per_cell)
    colours = colours_of(light, *view_weights(sky, (0.0, 1.0, 0.0)))
    alpha = 1.0 - np.exp(-SPEC.extinction_per_cell * ball.density)
    n = SPEC.grid
    acc = np.zeros((n, n, 4))
    keep = np.ones((n, n))
    for j in range(n):
        a = alpha[:, j, :]
        acc[..., :3] += (keep * a)[..., None] * colours[:, j, :, :]
        keep *= 1.0 - a
    acc[..., 3] = 1.0 - keep
    # Each texel's ray meets the plane y = 0 of the box at (x, z): the cell there.
    h, w = got.shape[:2]
    u = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    v = (np.arange(h) + 0.5) / h * 2.0 - 1.0
    x = imp.quad.centre_m[0] + u[None, :] * imp.quad.axis_u[0] + v[:, None] * imp.quad.axis_v[0]
    z = imp.quad.centre_m[2] + u[None, :] * imp.quad.axis_u[2] + v[:, None] * imp.quad.axis_v[2]
    # numpy's picture holds the cells' middles; read it between them as the texture is.
    fx = np.clip((x + 500.0) / (1000.0 / n) - 0.5, 0.0, n - 1.0)
    fz = np.clip((z + 500.0) / (1000.0 / n) - 0.5, 0.0, n - 1.0)
    x0, z0 = np.minimum(fx.astype(int), n - 2), np.minimum(fz.astype(int), n - 2)
    tx, tz = (fx - x0)[..., None], (fz - z0)[..., None]
    want = (
        acc[z0, x0] * (1 - tx) * (1 - tz)
        + acc[z0, x0 + 1] * tx * (1 - tz)
        + acc[z0 + 1, x0] * (1 - tx) * tz
        + acc[z0 + 1, x0 + 1] * tx * tz
    )
    cloudy = (want[..., 3] > 0.05) | (got[..., 3] > 0.05)
    assert cloudy.sum() > 0.3 * cloudy.size
    diff = np.abs(got - want)[cloudy]
    assert diff.mean() < 0.02, diff.mean(axis=0)
    # The lit side (the sun is in the south-west, high) is brighter than the far side.
    assert got[..., :3].sum(axis=2)[h // 2 :, : w // 2].mean() > 0.0


def test_images_marched_in_bands_are_the_images_marched_at_once() -> None:
    sky = _sky()
    lit = lit_volume(_Ball(), 0, sky)  # type: ignore[arg-type]
    eye = (1500.0, 2000.0, 2500.0)
    show = _show(lit, eye)
    cam = _camera(eye, 60.0)
    with Renderer(64) as whole, Renderer(64) as banded:
        whole.towers.prepare((show,), cam, sky, 320)
        banded.towers.slice_texels = 1000
        frames = 0
        while not banded.towers.prepare((show,), cam, sky, 320):
            frames += 1
            assert banded.towers.behind == 1
            assert frames < 1000
        assert banded.towers.behind == 0
        w, h = banded.towers._shown[SPEC].quad.size
        assert frames == math.ceil(h / max(1, 1000 // w)) - 1
        assert np.array_equal(_image(whole, show), _image(banded, show))


def test_a_tower_is_drawn_into_the_near_layer_where_it_stands() -> None:
    sky = _sky()
    lit = lit_volume(_Ball(), 0, sky)  # type: ignore[arg-type]
    eye = (0.0, 17_000.0, 3000.0)  # 3 km south of it, level, looking north
    cam = _camera(eye, 60.0)
    show = _show(lit, eye)
    nothing = SpriteDraw(SpriteBatch.empty(), np.zeros((0, 4), np.float32))
    with Renderer(64) as r:
        r._draw_near("near", nothing, cam, (0.0, 0.0, 0.0, 0.0), 0, (show,), sky)
        near = r.read("near") / 255.0
        assert r.ctx.error == "GL_NO_ERROR"
    h, w = near.shape[:2]
    # The ball (radius 20 of 64 cells: 310 m) spans about 12 degrees of the 60 at 3 km.
    assert near[h // 2, w // 2, 3] > 0.9
    assert near[h // 2, 2, 3] == 0.0 and near[2, w // 2, 3] == 0.0
    covered = np.mean(near[..., 3] > 0.1)
    assert covered == pytest.approx(math.pi * (0.2 * w / 2.0) ** 2 / (w * h), rel=0.5)


def test_billows_shade_their_own_far_side_from_the_light() -> None:
    """With the billows' own shade (render.towers.BILLOW_SHADOW) a tower seen from 3 km
    shows lit and shaded billows inside its outline, where without it the inside is an even
    blend of the cells' light; the shade only takes light away."""
    sky = _sky()
    lit = lit_volume(_Ball(), 0, sky)  # type: ignore[arg-type]
    eye = (0.0, 17_000.0, 3000.0)
    show = _show(lit, eye)

    def marched(billows: float) -> np.ndarray:
        with Renderer(64) as r:
            r.towers.billow_shadow = billows
            r.towers.prepare((show,), _camera(eye, 20.0), sky, 320)
            return _image(r, show)

    plain, shaded = marched(0.0), marched(BILLOW_SHADOW)
    inside = (plain[..., 3] > 0.95) & (shaded[..., 3] > 0.95)
    assert inside.sum() > 1000

    def detail(img: np.ndarray) -> float:
        luma = img[..., :3].mean(axis=2)
        pad = np.pad(luma, 2, mode="edge")
        blur = (
            sum(
                pad[2 + dy : 2 + dy + luma.shape[0], 2 + dx : 2 + dx + luma.shape[1]]
                for dy in range(-2, 3)
                for dx in range(-2, 3)
            )
            / 25.0
        )
        return float(np.std((luma - blur)[inside]))

    assert detail(shaded) > 1.5 * detail(plain)
    assert shaded[..., :3][inside].mean() < plain[..., :3][inside].mean()
