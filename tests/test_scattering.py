"""Harris's multiple forward scattering (eq. 5-8) and the phase functions: reference values
worked by hand, quadrature over the sphere, and the shapes and edge cases of the precompute."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wxsky.scene import scattering
from wxsky.scene.scattering import (
    ALBEDO,
    FORWARD_SHARE,
    HG_G,
    hg_forward_share,
    hg_phase,
    incident_light,
    pass_on,
    rayleigh_phase,
)

OBLIQUE = np.array([1.0, 2.0, 3.0]) / math.sqrt(14.0)


def _column(n: int, light: np.ndarray, spacing_m: float = 300.0) -> np.ndarray:
    """(n, 3) particles on a line along the light, the first nearest the light."""
    return np.asarray([light * spacing_m * (n - 1 - k) + (5.0e4, -3.0e4, 2.0e3) for k in range(n)])


def _sphere_integral(p: object) -> float:
    """Integral of an axially symmetric phase function over the sphere, 2 pi int p dmu."""
    mu, w = np.polynomial.legendre.leggauss(400)
    return float(2.0 * math.pi * np.sum(w * p(mu)))  # type: ignore[operator]


def test_three_particles_match_eq_8_by_hand() -> None:
    # tau 0.5, 1, 2 along the light, a = 0.9, phi = FORWARD_SHARE (0.2377 for HG 0.8, 10°).
    # I1 = I0 = 1
    # I2 = g1 + T1 I1 = 0.9 (1 - e^-0.5) 0.2377 + e^-0.5                      = 0.690719
    # I3 = g2 + T2 I2 = (0.9 (1 - e^-1) 0.2377 + e^-1) 0.690719 = 0.503128 * 0.690719 = 0.347522
    assert ALBEDO == 0.9
    assert pytest.approx(0.237739, abs=1e-6) == FORWARD_SHARE
    tau = np.array([0.5, 1.0, 2.0])
    got = incident_light(
        _column(3, OBLIQUE), np.full(3, 100.0), tau, np.zeros(3, np.int64), OBLIQUE
    )
    i1 = 1.0
    t1, t2 = math.exp(-0.5), math.exp(-1.0)
    i2 = ALBEDO * (1.0 - t1) * FORWARD_SHARE * i1 + t1 * i1
    i3 = ALBEDO * (1.0 - t2) * FORWARD_SHARE * i2 + t2 * i2
    np.testing.assert_allclose(got[:, 0], [i1, i2, i3], rtol=1e-5)
    np.testing.assert_allclose(got[:, 0], [1.0, 0.690719, 0.347522], atol=1e-6)


def test_column_light_falls_monotonically_with_depth() -> None:
    n = 8
    for light in (OBLIQUE, np.array([0.0, 0.0, 1.0]), np.array([-1.0, 0.0, 0.0])):
        got = incident_light(
            _column(n, light), np.full(n, 100.0), np.full(n, 1.5), np.zeros(n, np.int64), light
        )[:, 0]
        assert got[0] == 1.0
        assert np.all(np.diff(got) < 0.0)
        np.testing.assert_allclose(got, pass_on(1.5) ** np.arange(n), rtol=1e-5)


def test_forward_scattering_keeps_more_light_than_extinction_alone() -> None:
    # Without the forward term the beam would fall to e^-tau per particle.
    assert pass_on(2.0) > math.exp(-2.0)
    assert pass_on(0.0) == 1.0
    assert pass_on(50.0) == pytest.approx(ALBEDO * FORWARD_SHARE)
    assert np.all(pass_on(np.linspace(0.0, 30.0, 50)) <= 1.0)


@pytest.mark.parametrize(
    "phase", [rayleigh_phase, hg_phase, lambda mu: hg_phase(mu, 0.3), lambda mu: hg_phase(mu, -0.5)]
)
def test_phase_functions_integrate_to_one_over_the_sphere(phase: object) -> None:
    assert _sphere_integral(phase) == pytest.approx(1.0, abs=1e-6)


def test_phase_function_forward_backward_ratios() -> None:
    assert rayleigh_phase(1.0) / rayleigh_phase(-1.0) == pytest.approx(1.0)
    assert rayleigh_phase(1.0) / rayleigh_phase(0.0) == pytest.approx(2.0)
    g = HG_G
    assert hg_phase(1.0) / hg_phase(-1.0) == pytest.approx(((1 + g) / (1 - g)) ** 3)  # 729
    assert hg_phase(1.0) / hg_phase(-1.0) == pytest.approx(729.0)
    assert hg_phase(0.3, 0.0) == pytest.approx(1.0 / (4.0 * math.pi))
    # Broadcasts like numpy.
    assert hg_phase(np.zeros((2, 3))).shape == (2, 3)
    assert rayleigh_phase(np.zeros((4, 1))).shape == (4, 1)


def test_forward_share_is_the_phase_integral_over_the_cone() -> None:
    for g, cone in ((0.8, 10.0), (0.8, 20.0), (0.5, 45.0), (0.0, 30.0)):
        mu = np.linspace(math.cos(math.radians(cone)), 1.0, 200_001)
        numeric = 2.0 * math.pi * np.trapezoid(hg_phase(mu, g), mu)
        assert hg_forward_share(g, cone) == pytest.approx(numeric, rel=1e-6)
    assert hg_forward_share(0.8, 180.0) == pytest.approx(1.0)


def test_shapes_and_empty_inputs() -> None:
    empty = incident_light(
        np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0, np.int64), OBLIQUE
    )
    assert empty.shape == (0, 1) and empty.dtype == np.float32
    centres = _column(4, OBLIQUE)
    ids = np.zeros(4, np.int64)
    lights = np.array([OBLIQUE, [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    assert incident_light(centres, np.full(4, 100.0), np.ones(4), ids, lights).shape == (4, 3)
    assert incident_light(centres, np.full(4, 100.0), np.ones(4), ids, np.zeros((0, 3))).shape == (
        4,
        0,
    )
    with pytest.raises(ValueError, match="non-zero"):
        incident_light(centres, np.full(4, 100.0), np.ones(4), ids, np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        incident_light(centres, np.full(4, 100.0), np.ones(4), ids, [np.nan, 0.0, 1.0])


def test_a_cloud_of_one_particle_is_fully_lit_from_everywhere() -> None:
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(20, 3))
    got = incident_light(np.array([[1.0e4, 2.0e4, 1.5e3]]), [50.0], [5.0], [7], dirs)
    np.testing.assert_array_equal(got, np.ones((1, 20), np.float32))


def test_light_exactly_along_a_particle_pair() -> None:
    # Straight down a vertical pair (the axis case of the light-space basis), and along x.
    for light in ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, -1.0, 0.0)):
        d = np.asarray(light)
        centres = np.array([[0.0, 0.0, 2000.0], [0.0, 0.0, 2000.0]]) + np.array([d * 500.0, 0 * d])
        got = incident_light(centres, [200.0, 200.0], [2.0, 2.0], [1, 1], [light, -d])
        assert np.all(np.isfinite(got))
        np.testing.assert_allclose(got[:, 0], [1.0, pass_on(2.0)], rtol=1e-6)
        np.testing.assert_allclose(got[:, 1], [pass_on(2.0), 1.0], rtol=1e-6)
        # Across the pair, each is lit in full.
        side = np.cross(d, [0.3, 0.5, 0.7])
        np.testing.assert_allclose(
            incident_light(centres, [200.0, 200.0], [2.0, 2.0], [1, 1], side), 1.0
        )


def test_particles_shade_only_their_own_cloud_and_order_does_not_matter() -> None:
    n = 5
    centres = _column(n, OBLIQUE)
    alone = incident_light(centres, np.full(n, 120.0), np.ones(n), np.arange(n), OBLIQUE)
    np.testing.assert_array_equal(alone, 1.0)
    rng = np.random.default_rng(1)
    pts = rng.uniform(-400.0, 400.0, size=(60, 3)) + np.array([3.0e4, 1.0e4, 2.5e3])
    ids = rng.integers(0, 3, size=60)
    radius, tau = rng.uniform(80.0, 200.0, 60), rng.uniform(0.2, 3.0, 60)
    lights = np.array([OBLIQUE, [0.2, -0.3, 0.9]])
    base = incident_light(pts, radius, tau, ids, lights)
    perm = rng.permutation(60)
    shuffled = incident_light(pts[perm], radius[perm], tau[perm], ids[perm], lights)
    np.testing.assert_allclose(shuffled, base[perm], atol=1e-5)
    # Moving the clouds (the layer's drift) changes nothing.
    moved = incident_light(pts + np.array([-1234.5, 987.25, 0.0]), radius, tau, ids, lights)
    np.testing.assert_allclose(moved, base, atol=1e-6)
    assert np.all((base > 0.0) & (base <= 1.0))


def test_a_cloud_too_big_for_one_chunk_gives_the_same_light(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rng = np.random.default_rng(5)
    n = 300
    pts = rng.uniform(-1000.0, 1000.0, size=(n, 3))
    radius, tau = rng.uniform(100.0, 300.0, n), rng.uniform(0.5, 2.0, n)
    ids = np.zeros(n, np.int64)
    whole = incident_light(pts, radius, tau, ids, OBLIQUE)
    monkeypatch.setattr(scattering, "_CHUNK_PAIRS", 4096)  # 304 padded: rows in blocks of 13
    blocks = incident_light(pts, radius, tau, ids, OBLIQUE)
    np.testing.assert_allclose(blocks, whole, rtol=1e-5)
    assert whole.min() < 0.1  # deep in a 300-particle cloud


def test_cloud_phase_is_normalised_with_a_strong_forward_peak() -> None:
    from wxsky.scene.scattering import cloud_phase, diffuse_phase, two_lobe_phase

    # Over the sphere: 2 pi times the integral over cos theta from -1 to 1 (midpoint rule on
    # a fine grid: the forward lobe of g 0.85 is narrow).
    n = 400_000
    mu = -1.0 + (np.arange(n) + 0.5) * (2.0 / n)
    assert 2.0 * math.pi * two_lobe_phase(mu).sum() * (2.0 / n) == pytest.approx(1.0, abs=1e-4)
    assert (cloud_phase(mu).sum() * (2.0 / n)) / 2.0 == pytest.approx(1.0, abs=1e-4)
    assert (diffuse_phase(mu).sum() * (2.0 / n)) / 2.0 == pytest.approx(1.0, abs=1e-4)
    # Reference values (closed form): straight on, straight back, at 90 degrees, 4 pi p.
    forward, back, side = (float(cloud_phase(c)) for c in (1.0, -1.0, 0.0))
    g1, g2, w = 0.85, -0.3, 0.65
    hg = lambda c, g: (1 - g * g) / (1 + g * g - 2 * g * c) ** 1.5  # noqa: E731
    assert forward == pytest.approx(w * hg(1, g1) + (1 - w) * hg(1, g2), rel=1e-12)
    assert forward == pytest.approx(53.59, abs=0.01)
    assert back == pytest.approx(0.957, abs=0.001)
    assert side == pytest.approx(0.360, abs=0.001)
    # The silver lining's forward peak against a lit face's back-scatter.
    assert forward / back > 30.0
    # Multiply scattered light keeps only a weak forward bias.
    assert 1.0 < float(diffuse_phase(1.0)) / float(diffuse_phase(-1.0)) < 4.0
