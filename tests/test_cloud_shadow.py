"""The cloud-shadow map (wxsky/scene/cloud_shadow.py): exact values for one sphere, the
splatted map against the closed form at every texel, and against a ray marched numerically
through the density field (every sprite's density summed at points along the ray), for
random spheres and for the scene's own clouds at noon and with a low sun."""

from __future__ import annotations

import dataclasses
import math
from datetime import timedelta

import numpy as np
import numpy.typing as npt
import pytest

from wxsky.scene.cloud_shadow import (
    MIN_SUN_ELEVATION_DEG,
    CloudShadow,
    cloud_shadow,
    layer_reach,
    map_sun,
    optical_depth_along,
    sprite_spheres,
    transmittance_map,
)
from wxsky.scene.clouds import BLOCK_SIZE_M, layer_keys
from wxsky.scene.formation import layer_block
from wxsky.scene.gather import gather_blocks
from wxsky.settings.presets import load_preset
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

F64 = npt.NDArray[np.float64]


def sun_at(elevation_deg: float, azimuth_deg: float) -> tuple[float, float, float]:
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return (math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el))


def texel_points(centre: tuple[float, float, float], size_m: float, px: int) -> F64:
    """(px, px, 3) the texel centres the module doc defines: row 0 north, column 0 west."""
    k = (np.arange(px) + 0.5) * size_m / px
    east, north = np.meshgrid(centre[0] - size_m / 2 + k, centre[1] + size_m / 2 - k)
    out: F64 = np.stack([east, north, np.full_like(east, centre[2])], axis=-1)
    return out


def marched_depth(
    start_m: F64,
    sun: tuple[float, float, float],
    centres: F64,
    radii: F64,
    depths: F64,
    top_m: float,
) -> float:
    """Optical depth from start_m towards the sun up to altitude top_m, by the midpoint rule
    on the density field rho_k(x) = 2 s_k / (pi r_k) sqrt(1 - |x - c_k|^2 / r_k^2), summed
    over every sphere (those whose support the ray misses add zeros and are skipped)."""
    s = np.asarray(sun) / np.linalg.norm(sun)
    length = (top_m - start_m[2]) / s[2]
    w = centres - start_m
    along = w @ s
    near = np.einsum("ij,ij->i", w, w) - along**2 < radii**2
    if not near.any():
        return 0.0
    c, r, k = centres[near], radii[near], depths[near]
    step = 2.0
    t = (np.arange(int(length / step)) + 0.5) * step
    x = start_m + t[:, None] * s  # (M, 3)
    q = 1.0 - np.sum((x[:, None, :] - c[None, :, :]) ** 2, axis=2) / r**2  # (M, K)
    rho = 2.0 * k / (math.pi * r) * np.sqrt(np.maximum(q, 0.0))
    return float(np.sum(rho) * step)


# ---- one sphere: exact values ------------------------------------------------------------


def test_one_sphere_overhead_gives_the_kernel_values() -> None:
    # A sphere 1 km up, radius 200 m, depth 1.2 through its centre, over texel (8, 8) of a
    # 16 px map of 1600 m (texel centres every 100 m, the map centred on the sphere's
    # ground point minus half a texel).
    centre = np.array([[50.0, -50.0, 1000.0]])
    t = transmittance_map(centre, [200.0], [1.2], (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 1600.0, 16)
    assert t[8, 8] == pytest.approx(math.exp(-1.2), abs=1e-6)  # d = 0
    assert t[8, 9] == pytest.approx(math.exp(-1.2 * 0.75), abs=1e-6)  # d = 100 = r / 2
    assert t[7, 9] == pytest.approx(math.exp(-1.2 * 0.5), abs=1e-6)  # d = 141 m
    assert t[8, 10] == 1.0 and t[6, 8] == 1.0  # d = 200 = r: the footprint's edge
    assert np.count_nonzero(t < 1.0) == 9  # d < 200 m: the 3 x 3 texels around it


def test_a_slanted_sun_moves_the_shadow_by_height_over_tan_elevation() -> None:
    # Sun 30 deg up in the west (azimuth 270): the shadow falls 1000 / tan 30 = 1732 m east.
    sun = sun_at(30.0, 270.0)
    centre = np.array([[0.0, 0.0, 1000.0]])
    t = transmittance_map(centre, [150.0], [2.0], sun, (1732.05, 0.0, 0.0), 1000.0, 10)
    assert t[4:6, 4:6].max() < 0.2 and t.max() == 1.0
    # The footprint is an ellipse 1 / sin 30 = 2 times longer east-west than north-south.
    assert np.count_nonzero(t[:, 4] < 1.0) == 2  # 100 m texels: 2 of them in +-150 m
    assert np.count_nonzero(t[4] < 1.0) == 6  # +-300 m


# ---- the map: splatted vs the closed form vs a marched ray ---------------------------------

SUNS = {
    "zenith": (0.0, 0.0, 1.0),
    "afternoon": sun_at(45.0, 210.0),
    "east-low": sun_at(8.0, 95.0),  # rows along the sun: scanned as rows
    "north-low": sun_at(6.0, 350.0),  # scanned as columns (the transposed map)
    "diagonal-low": sun_at(4.0, 135.0),
}


def random_spheres(seed: int, n: int = 400) -> tuple[F64, F64, F64]:
    rng = np.random.default_rng(seed)
    centres = np.column_stack(
        [rng.uniform(-5000, 5000, n), rng.uniform(-5000, 5000, n), rng.uniform(900, 2400, n)]
    )
    return centres, rng.uniform(80.0, 500.0, n), rng.uniform(0.05, 1.5, n)


@pytest.mark.parametrize("sun", SUNS.values(), ids=SUNS.keys())
def test_every_texel_equals_the_closed_form_sum(sun: tuple[float, float, float]) -> None:
    centres, radii, depths = random_spheres(7)
    where = (250.0, -400.0, 300.0)
    t = transmittance_map(centres, radii, depths, sun, where, 4000.0, 80)
    want = np.exp(
        -optical_depth_along(texel_points(where, 4000.0, 80), centres, radii, depths, sun)
    )
    assert np.abs(t - want).max() < 1e-6
    assert t.min() < 0.5 and t.max() == 1.0  # shadows and sun, not a trivial map


@pytest.mark.parametrize("sun", SUNS.values(), ids=SUNS.keys())
def test_texels_equal_a_ray_marched_through_the_density_field(
    sun: tuple[float, float, float],
) -> None:
    centres, radii, depths = random_spheres(11, 300)
    where = (0.0, 0.0, 0.0)
    t = transmittance_map(centres, radii, depths, sun, where, 6000.0, 60)
    points = texel_points(where, 6000.0, 60)
    rng = np.random.default_rng(5)
    # Texels in shade (T < 0.95), the darkest ones and some in full sun.
    shaded = np.argwhere(t < 0.95)
    picks = [*shaded[rng.choice(len(shaded), 25, replace=False)], *np.argwhere(t == t.min())[:2]]
    picks += [*np.argwhere(t == 1.0)[:3]]
    worst = 0.0
    for i, j in picks:
        tau = marched_depth(points[i, j], sun, centres, radii, depths, 3000.0)
        worst = max(worst, abs(float(t[i, j]) - math.exp(-tau)))
    # The midpoint rule on the density's square-root edge: well under this with 2 m steps.
    assert worst < 2e-3, worst


# ---- the scene's clouds --------------------------------------------------------------------


def scattered_cumulus() -> WeatherState:
    return WeatherState().apply(load_preset("scattered-cumulus"))


@pytest.mark.parametrize(
    ("sun", "max_range_m"),
    [(sun_at(62.0, 190.0), 14_000.0), (sun_at(9.0, 250.0), 30_000.0)],
    ids=["noon", "low-sun"],
)
def test_the_scene_clouds_shadow_as_a_ray_through_them(
    sun: tuple[float, float, float], max_range_m: float
) -> None:
    """The map of the preset's clouds, drifted, against rays marched through every sprite of
    every block the scene draws out to max_range_m: with a low sun most shadows come from
    clouds kilometres away, which the map must not miss."""
    state = scattered_cumulus()
    drift = ((1234.5, -678.25),)
    centre = (600.0, -300.0, 1500.0)
    shadow = cloud_shadow(state, drift, centre, sun, 16_000.0, 64, max_range_m)
    assert shadow.centre_m == (600.0, -300.0, state.observer.alt_m)
    sprites = gather_blocks(state, drift, centre, 0.0, max_range_m)
    radii, depths = sprite_spheres(sprites)
    t = shadow.transmittance
    points = texel_points(shadow.centre_m, 16_000.0, 64)
    rng = np.random.default_rng(2)
    shaded, lit = np.argwhere(t < 0.5), np.argwhere(t > 0.9)
    assert len(shaded) > 40 and len(lit) > 40, (len(shaded), len(lit))
    picks = [*shaded[rng.choice(len(shaded), 12, replace=False)]]
    picks += [*lit[rng.choice(len(lit), 6, replace=False)]]
    middle = np.argwhere((t > 0.05) & (t < 0.9))
    picks += [*middle[rng.choice(len(middle), 12, replace=False)]]
    top = float(state.layers[0].top_m) + 600.0
    for i, j in picks:
        tau = marched_depth(points[i, j], sun, sprites.centre_m, radii, depths, top)
        assert abs(float(t[i, j]) - math.exp(-tau)) < 2e-3, (i, j, t[i, j], math.exp(-tau))


def test_block_reach_bounds_hold_for_the_generated_clouds() -> None:
    """layer_reach picks the blocks to read: every sprite lies within its overhang of its
    block and its sphere within its radius."""
    for layer in (
        CloudLayer(6, 1200.0, 3000.0, CloudType.CUMULUS),
        CloudLayer(5, 1500.0, 11_000.0, CloudType.CUMULONIMBUS),
        CloudLayer(8, 800.0, 1300.0, CloudType.STRATUS),
        CloudLayer(3, 9000.0, 10_000.0, CloudType.CIRRUS),
    ):
        state = WeatherState(layers=(layer,))
        overhang, radius = layer_reach(layer)
        for bx, by in ((0, 0), (-1, 2), (3, -2)):
            block = layer_block(bx, by, layer_keys(state.layers)[0], layer, state.seed)
            x, y = block.centre_m[:, 0], block.centre_m[:, 1]
            out = np.max(
                [
                    bx * BLOCK_SIZE_M - x,
                    x - (bx + 1) * BLOCK_SIZE_M,
                    by * BLOCK_SIZE_M - y,
                    y - (by + 1) * BLOCK_SIZE_M,
                ]
            )
            assert out <= overhang, (layer.type, out, overhang)
            assert sprite_spheres(block)[0].max() <= radius * (1 + 1e-6), layer.type


# ---- the sun, the map's pixels and its motion ------------------------------------------------


def test_no_direct_sun_no_shadow_and_a_low_sun_is_raised() -> None:
    state = scattered_cumulus()
    night = cloud_shadow(
        state, ((0.0, 0.0),), (0.0, 0.0, 0.0), sun_at(-5.0, 300.0), 8000.0, 16, 2e4
    )
    assert np.all(night.transmittance == 1.0)
    low = map_sun(sun_at(1.0, 300.0))
    assert low == pytest.approx(sun_at(MIN_SUN_ELEVATION_DEG, 300.0), abs=1e-12)
    assert map_sun(sun_at(20.0, 300.0)) == pytest.approx(sun_at(20.0, 300.0), abs=1e-12)
    with pytest.raises(ValueError, match="finite and non-zero"):
        map_sun((math.nan, 0.0, 1.0))
    with pytest.raises(ValueError, match="px >= 1"):
        transmittance_map(np.zeros((0, 3)), [], [], (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 1.0, 0)


def test_the_layer_pixels_and_the_drift_of_the_map() -> None:
    state = scattered_cumulus()
    shadow = cloud_shadow(state, ((0.0, 0.0),), (0.0, 0.0, 0.0), sun_at(60, 180), 16_000.0, 32, 2e4)
    t8 = np.round(shadow.transmittance * 255.0)
    assert np.array_equal(shadow.rgba[..., 0], t8) and np.array_equal(shadow.rgba[..., 2], t8)
    assert np.all(shadow.rgba[..., 3] == 255)
    # It moves with the layer's wind at mid-height, as the clouds do.
    layer = state.layers[0]
    ve, vn = state.wind_at(0.5 * (layer.base_m + layer.top_m))
    assert shadow.velocity_mps == pytest.approx((ve, vn))
    later = shadow.centre_at(shadow.time_utc + timedelta(seconds=100))
    assert later == pytest.approx((100 * ve, 100 * vn, state.observer.alt_m))
    # Every map has its own, increasing serial (the record's shadow_version).
    again = dataclasses.replace(shadow)
    assert isinstance(again, CloudShadow) and again.serial > shadow.serial
