"""Dobashi's automaton (wxsky/towers): the rules cell by cell against a plain reading of them,
growth with supply and no extinction, decay at the rate p_ext sets, the density's smoothing
and interpolation, and the same volume from the same seed in two processes."""

from __future__ import annotations

import hashlib
import itertools
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wxsky.towers.automaton import (
    Cells,
    Odds,
    activation,
    cell_rng,
    density_between,
    ellipsoid_weight,
    flat_based,
    grow,
    smoothed,
    step,
    tower_ellipsoids,
    tower_odds,
)
from wxsky.towers.volume import STEP_S, TowerSpec, TowerVolume

ROOT = Path(__file__).resolve().parents[1]
SHAPE = (16, 12, 10)  # z, y, x: unequal, so a swapped axis shows


def reference_activation(act: np.ndarray) -> np.ndarray:
    """f_act read straight off Dobashi's formula, one cell at a time."""
    nz, ny, nx = act.shape
    out = np.zeros_like(act)
    offsets = [
        (0, 0, 1), (0, 0, -1), (0, 1, 0), (0, -1, 0), (1, 0, 0), (-1, 0, 0),  # ±1 in x, y, z
        (0, 0, 2), (0, 0, -2), (0, 2, 0), (0, -2, 0),  # ±2 in x and y
        (-2, 0, 0),  # two cells below
    ]  # fmt: skip
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                for dz, dy, dx in offsets:
                    zz, yy, xx = z + dz, y + dy, x + dx
                    if 0 <= zz < nz and 0 <= yy < ny and 0 <= xx < nx and act[zz, yy, xx]:
                        out[z, y, x] = True
    return out


def test_activation_is_dobashis_neighbourhood_on_random_fields() -> None:
    rng = np.random.default_rng(17)
    for density in (0.02, 0.2):
        act = rng.random(SHAPE) < density
        assert np.array_equal(activation(act), reference_activation(act))


def test_activity_climbs_two_cells_up_but_never_two_down() -> None:
    cells = Cells.empty(SHAPE)
    hum = np.ones(SHAPE, np.bool_)
    act = np.zeros(SHAPE, np.bool_)
    act[8, 6, 5] = True
    after = grow(Cells(hum, act, cells.cld))
    assert after.act[10, 6, 5] and not after.act[6, 6, 5]  # z+2 yes, z-2 no
    assert after.act[9, 6, 5] and after.act[7, 6, 5]  # ±1 vertically
    assert after.act[8, 6, 7] and after.act[8, 4, 5]  # ±2 sideways
    assert not after.act[8, 6, 5]  # a trigger fires once: act' needs not act
    assert after.cld[8, 6, 5] and after.cld.sum() == 1  # its cell became cloud
    assert not after.hum[8, 6, 5] and after.hum.sum() == hum.size - 1  # and spent its vapour


def test_no_vapour_no_new_triggers() -> None:
    act = np.zeros(SHAPE, np.bool_)
    act[8, 6, 5] = True
    after = grow(Cells(np.zeros(SHAPE, np.bool_), act, np.zeros(SHAPE, np.bool_)))
    assert not after.act.any() and after.cld.sum() == 1


def test_with_supply_and_no_extinction_the_cloud_grows_and_never_shrinks() -> None:
    shape = (32, 32, 32)
    rng = cell_rng(1, (0, 0), 0)
    weight = ellipsoid_weight(shape, tower_ellipsoids(shape, 1.0))
    odds = tower_odds(weight, hum=0.1, act=0.01, ext_inside=0.0, ext_outside=0.0)
    cells = Cells.empty(shape)
    counts = []
    previous = cells.cld
    for _ in range(18):  # three minutes at STEP_S
        cells = step(cells, odds, rng)
        assert not (previous & ~cells.cld).any()  # no cloud cell is ever lost
        previous = cells.cld
        counts.append(cells.cloud_cells)
    assert all(b > a for a, b in itertools.pairwise(counts)), counts
    # Only where the ellipsoids supply vapour: nothing grows outside them.
    assert not (cells.cld & (weight <= 0.0)).any()


def test_without_supply_cloud_decays_at_the_rate_p_ext_sets() -> None:
    shape = (24, 24, 24)
    rng = np.random.default_rng(5)
    cld = rng.random(shape) < 0.5
    cells = Cells(np.zeros(shape, np.bool_), np.zeros(shape, np.bool_), cld)
    p_ext, steps = 0.1, 10
    for _ in range(steps):
        cells = step(cells, Odds(hum=0.0, act=0.0, ext=p_ext), rng)
    expected = int(cld.sum()) * (1.0 - p_ext) ** steps
    # Binomial: 5 standard deviations of the survivors' count.
    sd = np.sqrt(int(cld.sum()) * (1.0 - p_ext) ** steps * (1.0 - (1.0 - p_ext) ** steps))
    assert abs(cells.cloud_cells - expected) < 5.0 * sd


def test_a_cut_supply_decays_the_edges_first() -> None:
    """Air clearing: no more vapour, and cloud vanishes at p_ext_clearing at the ellipsoids'
    centres rising to p_ext_outside at their rims, so the rim goes first."""
    spec = TowerSpec(weather_seed=3, block=(1, 2), cell=0, mature_s=300.0, supplied_s=600.0)
    tower = TowerVolume(spec)
    cut = int(600.0 / STEP_S)
    grown = tower.cells_at(cut)
    later = tower.cells_at(cut + 6)  # a minute on
    assert later.cloud_cells < 0.7 * grown.cloud_cells
    weight = ellipsoid_weight(spec.shape, tower.ellipsoids_at(cut))
    core, rim = grown.cld & (weight > 0.95), grown.cld & (weight < 0.5)
    assert core.sum() > 100 and rim.sum() > 100
    kept_core = (later.cld & core).sum() / core.sum()
    kept_rim = (later.cld & rim).sum() / rim.sum()
    # Measured: 0.80 of the core left, 0.27 of the rim (expected at the very centre: 0.83).
    assert kept_core > 0.6 and kept_rim < 0.5 * kept_core


def test_smoothing_keeps_the_total_inside_and_spreads_a_cell() -> None:
    cld = np.zeros(SHAPE, np.bool_)
    cld[8, 6, 5] = True
    d = smoothed(cld)
    assert d.dtype == np.float32
    assert d.sum() == pytest.approx(1.0, abs=1e-6)  # far from the edges nothing is lost
    assert d[8, 6, 5] == pytest.approx((6.0 / 16.0) ** 3)
    assert d[8, 6, 7] == pytest.approx((6.0 / 16.0) ** 2 / 16.0)
    assert d[8, 6, 8] == 0.0
    full = smoothed(np.ones(SHAPE, np.bool_))
    assert full[8, 6, 5] == pytest.approx(1.0) and full[0, 0, 0] < 1.0  # the edge thins


def test_density_between_two_steps_is_continuous() -> None:
    rng = np.random.default_rng(9)
    a = rng.random(SHAPE) < 0.3
    b = a | (rng.random(SHAPE) < 0.1)
    assert np.array_equal(density_between(a, b, 0.0), smoothed(a))
    assert np.allclose(density_between(a, b, 1.0), smoothed(b))
    mid = density_between(a, b, 0.5)
    assert np.allclose(mid, 0.5 * (smoothed(a) + smoothed(b)), atol=1e-6)


def test_the_tower_grows_taller_as_it_matures() -> None:
    shape = (64, 64, 64)
    tops = []
    for maturity in (0.2, 0.6, 1.0):
        w = ellipsoid_weight(shape, tower_ellipsoids(shape, maturity))
        tops.append(int(np.flatnonzero(w.max(axis=(1, 2)) > 0.0).max()))
    assert tops[0] < tops[1] < tops[2] < 64
    assert ellipsoid_weight(shape, tower_ellipsoids(shape, 0.0)).max() == 0.0
    # The newest bubble swells in: the odds change with maturity continuously, no jump.
    w = [ellipsoid_weight(shape, tower_ellipsoids(shape, m)) for m in (0.5, 0.5001, 0.501, 0.51)]
    steps = [float(np.abs(b - a).max()) for a, b in zip(w[:1] * 3, w[1:], strict=True)]
    assert 0.0 < steps[0] < steps[1] < steps[2] and steps[0] < 0.05


def test_a_cumulonimbus_spreads_an_anvil_at_its_top_as_it_matures() -> None:
    shape = (64, 64, 64)

    def widths(maturity: float, anvil: bool) -> np.ndarray:
        w = ellipsoid_weight(shape, tower_ellipsoids(shape, maturity, anvil=anvil))
        return (w > 0.0).sum(axis=2).max(axis=1)  # cells across, per level

    young, grown = widths(0.6, True), widths(1.0, True)
    top = int(np.flatnonzero(grown).max())
    # Young, a column half a plain tower's width, no anvil; grown, its top is the widest.
    assert young.max() <= 0.6 * widths(0.6, False).max() + 1
    assert grown[top - 6 : top + 1].max() > 2.0 * grown[: top // 2].max()
    assert grown[top - 6 : top + 1].max() >= 0.8 * 64
    # Its box is twice as wide, for the same base.
    plain = TowerSpec(weather_seed=1, block=(0, 0), cell=0)
    cb = TowerSpec(weather_seed=1, block=(0, 0), cell=0, anvil=True)
    assert cb.box_size_m[0] == pytest.approx(2.0 * plain.box_size_m[0])
    assert cb.box_size_m[2] == plain.box_size_m[2]


def test_a_volume_is_the_same_however_its_moment_is_reached() -> None:
    spec = TowerSpec(weather_seed=11, block=(-4, 7), cell=2, grid=64, mature_s=600.0)
    straight = TowerVolume(spec).density_at(455.0)
    wandering = TowerVolume(spec)
    wandering.density_at(700.0)  # later first: asking for 455 s starts again from birth
    wandering.density_at(100.0)
    assert np.array_equal(wandering.density_at(455.0), straight)
    other_cell = TowerVolume(TowerSpec(weather_seed=11, block=(-4, 7), cell=3, mature_s=600.0))
    assert not np.array_equal(other_cell.density_at(455.0), straight)


@pytest.mark.parametrize("age_s", [-1.0, float("nan"), float("inf")])
def test_bad_ages_and_grids_are_errors(age_s: float) -> None:
    tower = TowerVolume(TowerSpec(weather_seed=1, block=(0, 0), cell=0))
    with pytest.raises(ValueError, match="not a time"):
        tower.density_at(age_s)
    with pytest.raises(ValueError, match="grid must be one of"):
        TowerVolume(TowerSpec(weather_seed=1, block=(0, 0), cell=0, grid=48))


_DIGEST = """
import hashlib, sys
from wxsky.towers.volume import TowerSpec, TowerVolume
spec = TowerSpec(weather_seed=2026, block=(-3, 5), cell=1, mature_s=900.0)
print(hashlib.sha256(TowerVolume(spec).density_at(612.5).tobytes()).hexdigest())
"""


def test_same_seed_same_volume_in_two_processes() -> None:
    out = [
        subprocess.run(
            [sys.executable, "-c", _DIGEST], capture_output=True, text=True, check=True, cwd=ROOT
        ).stdout.strip()
        for _ in range(2)
    ]
    spec = TowerSpec(weather_seed=2026, block=(-3, 5), cell=1, mature_s=900.0)
    here = hashlib.sha256(TowerVolume(spec).density_at(612.5).tobytes()).hexdigest()
    assert out[0] == out[1] == here


def test_flat_based_stands_the_band_on_its_floor() -> None:
    """In the lowest rows each column takes the most cloud it has up to the band's top; above
    the band nothing changes, and nothing is made where a column has no cloud in the band."""
    rng = np.random.default_rng(5)
    density = rng.random((12, 6, 6)).astype(np.float32)
    density[:, 0, 0] = 0.0  # a clear column stays clear
    out = flat_based(density, 4)
    for z in range(4):
        np.testing.assert_array_equal(out[z], density[z:4].max(axis=0))
    np.testing.assert_array_equal(out[4:], density[4:])
    assert not out[:, 0, 0].any()
    assert np.array_equal(flat_based(density, 0), density)


def test_a_grown_tower_has_one_flat_base() -> None:
    """A cumulus's base is flat at the condensation level (issue 42): at 20 minutes a
    congestus's floor row holds as much cloud as the widest row in the 400 m above it, where
    the automaton's bubbles alone leave the floor a few percent of it."""
    spec = TowerSpec(weather_seed=7, block=(2, -1), cell=0, mature_s=1800.0)
    tower = TowerVolume(spec)
    density = tower.density_at(1200.0)
    rows = tower.flat_base_rows
    assert 4 <= rows <= 8  # 400 m of a 4.4 km box in 64 rows
    area = (density > 0.3).sum(axis=(1, 2))
    assert area[0] > 0 and area[0] == area[:rows].max()
    bare = smoothed(tower.cells_at(120).cld)
    bare_area = (bare > 0.3).sum(axis=(1, 2))
    assert bare_area[0] < 0.5 * bare_area[:rows].max()
