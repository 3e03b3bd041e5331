"""GRIB2 model data (issue 45): the decoder on the real GFS file, the column at a place, the
model's clouds and a METAR laid over the model.

The decoder's values are checked against the real file only (its README gives the peak 250 hPa
wind); interpolation in time and height, which needs two steps the fixture does not have, is
checked on fields made here from the real one."""

from __future__ import annotations

import dataclasses
import itertools
import math
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest
from grib_fixture import GFS, LONDON, SHARED_GFS, VALID, needs_gfs

from wxsky.errors import GribError
from wxsky.inputs.grib_decode import Window, decode, inventory
from wxsky.weather import model_blend
from wxsky.weather.model_clouds import cover_from_rh, model_layers, rh_crit_pct
from wxsky.weather.model_fields import ModelField, merge_steps
from wxsky.weather.model_profile import ModelProfile, ProfileLevel, profile_at
from wxsky.weather.precedence import SourceStack
from wxsky.weather.state import CloudLayer, CloudType, Source, WeatherPatch, WeatherState, WindLayer

pytestmark = needs_gfs


@pytest.fixture(scope="module")
def data() -> bytes:
    return GFS.read_bytes()


@pytest.fixture(scope="module")
def whole(data: bytes) -> list[ModelField]:
    return decode(data, "gfs")


def _field(fields: list[ModelField], key: tuple[str, str, float]) -> ModelField:
    return next(f for f in fields if f.key == key)


def test_every_pressure_level_has_both_winds_and_the_peak_jet_is_the_files(
    whole: list[ModelField],
) -> None:
    """NCEP packs u and v in one message: without multi-field support v would be missing."""
    levels = {
        n: {f.level for f in whole if f.name == n and f.level_type == "isobaric"} for n in "uv"
    }
    assert len(levels["u"]) == 21 and levels["u"] == levels["v"]  # 1000..100 of its 26
    u = _field(whole, ("u", "isobaric", 250.0))
    v = _field(whole, ("v", "isobaric", 250.0))
    assert u.values.shape == (73, 144)  # 2.5 degrees, pole to pole
    assert float(np.nanmax(np.hypot(u.values, v.values))) == pytest.approx(97.9, abs=0.05)
    assert all(f.valid_utc == VALID for f in whole)
    assert u.grid.wraps and u.grid.lats_deg[0] == -90.0 and u.grid.lats_deg[-1] == 90.0


def test_a_window_holds_the_same_values_as_the_whole_grid(
    data: bytes, whole: list[ModelField]
) -> None:
    """Cut around Honolulu (across no seam) and around Greenwich (across the grid's 0/360
    seam): every point of the window is the whole grid's."""
    for lat, lon in ((21.3, -157.9), LONDON):
        cut = decode(data, "gfs", Window(lat, lon, 6.0))
        assert {f.key for f in cut} == {f.key for f in whole}
        for f in cut:
            g = _field(whole, f.key)
            assert f.grid.covers(lat, lon)
            for i, la in enumerate(f.grid.lats_deg):
                for j, lo in enumerate(f.grid.lons_deg):
                    gi = int(np.searchsorted(g.grid.lats_deg, la))
                    gj = round((lo % 360.0) / 2.5) % 144
                    np.testing.assert_equal(f.values[i, j], g.values[gi, gj])
            assert f.at(lat, lon) == pytest.approx(g.at(lat, lon), rel=1e-6, nan_ok=True)


def test_bilinear_at_grid_points_and_between() -> None:
    t = datetime(2020, 1, 1, tzinfo=UTC)
    from wxsky.weather.model_fields import Grid

    grid = Grid(np.array([10.0, 12.5]), np.array([350.0, 352.5, 355.0]), wraps=True)
    vals = np.array([[0.0, 10.0, 20.0], [100.0, 110.0, 120.0]], dtype=np.float32)
    f = ModelField("t", "isobaric", 500.0, t, grid, vals)
    assert f.at(10.0, -10.0) == pytest.approx(0.0)  # -10 east is 350
    assert f.at(12.5, 355.0) == pytest.approx(120.0)
    assert f.at(11.25, -8.75) == pytest.approx(55.0)
    # a deck's pressure: the "no cloud" corner left out, not averaged in
    holey = vals.copy()
    holey[0, 0] = 9.999e20
    g = ModelField("pres", "low_cloud_top", 0.0, t, grid, holey)
    assert g.at(11.25, -8.75, valid=(0.0, 1000.0)) == pytest.approx((10 + 100 + 110) / 3)


def test_the_column_over_london_goes_up_from_the_ground(data: bytes) -> None:
    steps = merge_steps(decode(data, "gfs", Window(*LONDON)), ("gfs",))
    p = profile_at(steps, *LONDON, VALID)
    assert p is not None
    heights = [lev.height_m for lev in p.levels]
    assert heights == sorted(heights) and heights[0] < 50.0 and heights[-1] <= 30_000.0
    assert all(lev.pressure_hpa <= p.surface_hpa + 1e-6 for lev in p.levels[1:])  # type: ignore[operator]
    # the lowest level is the model's 10 m wind over its ground
    assert p.surface_m is not None and heights[0] == pytest.approx(p.surface_m + 10.0)
    # temperature falls through the troposphere and the freezing level lies where it crosses 0
    assert p.freezing_m is not None and p.tropopause_m is not None
    crossing = next(
        a.height_m + (b.height_m - a.height_m) * (a.t_k - 273.15) / (a.t_k - b.t_k)
        for a, b in zip(p.levels, p.levels[1:], strict=False)
        if a.t_k >= 273.15 > b.t_k
    )
    assert abs(crossing - p.freezing_m) < 300.0
    assert 9_000.0 < p.tropopause_m < 14_000.0
    # the jet over southern England: westerly, strongest near the tropopause
    jet = max(p.levels, key=lambda lev: lev.speed_mps)
    assert 200.0 <= jet.pressure_hpa <= 300.0 and 225.0 < jet.dir_deg < 315.0


def test_between_levels_height_goes_with_log_pressure(data: bytes) -> None:
    steps = merge_steps(decode(data, "gfs", Window(*LONDON)), ("gfs",))
    p = profile_at(steps, *LONDON, VALID)
    assert p is not None
    a, b = (next(lev for lev in p.levels if lev.pressure_hpa == hpa) for hpa in (700.0, 650.0))
    mid_hpa = math.sqrt(700.0 * 650.0)  # half-way in log-pressure
    h = p.height_of_pressure(mid_hpa)
    assert h == pytest.approx(0.5 * (a.height_m + b.height_m))
    at = p.at_height(h)
    assert at is not None and at.pressure_hpa == pytest.approx(mid_hpa)
    assert at.u_mps == pytest.approx(0.5 * (a.u_mps + b.u_mps))


def _shifted(fields: list[ModelField], hours: float, wind_scale: float) -> list[ModelField]:
    """The same fields six hours on, the wind scaled: a second step made from the real one."""
    out = []
    for f in fields:
        values = f.values * wind_scale if f.name in ("u", "v", "u10", "v10") else f.values
        out.append(
            dataclasses.replace(f, valid_utc=f.valid_utc + timedelta(hours=hours), values=values)
        )
    return out


def test_between_steps_the_column_moves_linearly_and_without_a_jump(data: bytes) -> None:
    first = decode(data, "gfs", Window(*LONDON))
    steps = merge_steps([*first, *_shifted(first, 6.0, 2.0)], ("a", "b"))
    assert len(steps) == 2

    def jet_speed(at: datetime) -> float:
        p = profile_at(steps, *LONDON, at)
        assert p is not None
        return next(lev.speed_mps for lev in p.levels if lev.pressure_hpa == 250.0)

    s0 = jet_speed(VALID)
    assert jet_speed(VALID + timedelta(hours=3)) == pytest.approx(1.5 * s0, rel=1e-4)
    assert jet_speed(VALID + timedelta(hours=6)) == pytest.approx(2.0 * s0, rel=1e-4)
    # a second after a step, the column has moved a second's worth, no more: no jump;
    # outside the steps, it is held at the nearest
    rate = s0 / (6 * 3600.0)
    assert abs(jet_speed(VALID + timedelta(seconds=1)) - s0) <= 1.01 * rate
    assert jet_speed(VALID - timedelta(days=2)) == pytest.approx(s0)
    assert jet_speed(VALID + timedelta(days=2)) == pytest.approx(2.0 * s0, rel=1e-4)


def test_the_models_decks_make_the_layers_over_london(data: bytes) -> None:
    steps = merge_steps(decode(data, "gfs", Window(*LONDON)), ("gfs",))
    p = profile_at(steps, *LONDON, VALID)
    assert p is not None
    layers = model_layers(p)
    decks = {d.name: d for d in p.decks}
    assert [lay.type for lay in layers] == [
        CloudType.STRATOCUMULUS,
        CloudType.ALTOCUMULUS,
        CloudType.CIRROSTRATUS,
    ]
    for lay, name in zip(layers, ("low", "middle", "high"), strict=True):
        d = decks[name]
        assert lay.cover_oktas == pytest.approx(8.0 * d.cover_pct / 100.0)
        assert lay.base_m == pytest.approx(p.height_of_pressure(d.base_hpa))  # type: ignore[arg-type]
        assert lay.top_m == pytest.approx(p.height_of_pressure(d.top_hpa))  # type: ignore[arg-type]


def test_humidity_makes_cloud_where_the_model_gives_no_deck_heights() -> None:
    assert rh_crit_pct(1013.25) == pytest.approx(90.0) and rh_crit_pct(300.0) == pytest.approx(70.0)
    assert cover_from_rh(85.0, 90.0) == 0.0 and cover_from_rh(100.0, 90.0) == 1.0
    rh = {1000: 60, 925: 97, 850: 98, 700: 50, 500: 40, 300: 85, 250: 60}
    levels = tuple(
        ProfileLevel(hpa, 8000.0 * math.log(1013.0 / hpa), 5.0, 0.0, 280.0, r)
        for hpa, r in rh.items()
    )
    p = ModelProfile(
        51.0, 0.0, VALID, (VALID,), levels, 0.0, 1013.0, 285.0, 0.0, 0.0, 2000.0, 11000.0, 250.0, ()
    )
    layers = model_layers(p)
    assert len(layers) == 2
    low, high = layers
    assert low.base_m < levels[1].height_m < levels[2].height_m < low.top_m
    assert low.type in (CloudType.STRATUS, CloudType.STRATOCUMULUS) and low.cover_oktas > 5.0
    assert high.type in (CloudType.CIRRUS, CloudType.CIRROSTRATUS)
    assert high.base_m < levels[5].height_m < high.top_m


def test_a_corrupt_or_foreign_file_is_one_line(data: bytes) -> None:
    with pytest.raises(GribError) as e:
        decode(data[: len(data) // 2 + 17], "half.grib2")
    assert "half.grib2" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(GribError, match="no GRIB messages"):
        decode(b"METAR EGLL 151150Z 21010KT" * 10, "metar.txt")
    # the first message's grid definition said to be Lambert conformal (template 30)
    lambert = bytearray(data)
    sec3 = _section_offset(data, 3)
    lambert[sec3 + 12 : sec3 + 14] = (30).to_bytes(2, "big")
    with pytest.raises(GribError) as e:
        decode(bytes(lambert), "lambert.grib2")
    text = str(e.value)
    assert "grid template 30" in text and "message 1" in text and "\n" not in text


def _section_offset(data: bytes, number: int) -> int:
    """Where section `number` of the first message starts (GRIB2: each section's length is its
    first 4 octets, its number the 5th)."""
    at = 16
    while at < len(data):
        length = int.from_bytes(data[at : at + 4], "big")
        if data[at + 4] == number:
            return at
        at += length
    raise AssertionError(f"no section {number}")


def test_the_inventory_lists_shared_messages_as_wgrib2_does(data: bytes) -> None:
    lines = inventory(data).splitlines()
    assert len(lines) == 343  # 307 messages, the u/v pairs two lines each
    assert lines[3].startswith("4.1:25975:d=2011011012:UGRD:10 mb:120 hour fcst")
    assert lines[4].startswith("4.2:25975:d=2011011012:VGRD:10 mb:")
    assert any(":TCDC:low cloud layer:" in ln for ln in lines)


# -- a METAR over the model ---------------------------------------------------------------


def test_the_metars_weight_falls_with_distance_and_age() -> None:
    assert model_blend.metar_weight(5_000.0, 600.0) == 1.0
    assert model_blend.metar_weight(85_000.0, 600.0) == pytest.approx(0.5)
    assert model_blend.metar_weight(5_000.0, 2 * 3600.0) == pytest.approx(0.5)
    assert model_blend.metar_weight(200_000.0, 0.0) == 0.0
    assert model_blend.metar_weight(5_000.0, None) == 0.0  # an unknown age counts as old


MODEL_WIND = tuple(
    WindLayer(h, 270.0, s) for h, s in ((10.0, 5.0), (500.0, 12.0), (1500.0, 20.0), (9000.0, 50.0))
)
MODEL_LAYERS = (
    CloudLayer(4.0, 900.0, 1800.0, CloudType.CUMULUS),
    CloudLayer(6.0, 7500.0, 9500.0, CloudType.CIRROSTRATUS),
)
METAR_WIND = (WindLayer(10.0, 180.0, 10.0),)
METAR_LAYERS = (CloudLayer(7.0, 1200.0, 1500.0, CloudType.STRATOCUMULUS),)


def _stack(weight: float) -> SourceStack:
    model = WeatherPatch(
        source=Source.GRIB, layers=MODEL_LAYERS, wind=MODEL_WIND, temperature_c=4.0
    )
    metar = WeatherPatch(
        source=Source.METAR, layers=METAR_LAYERS, wind=METAR_WIND, visibility_m=8000.0
    )
    stack = SourceStack(base=WeatherState()).with_patch(model, 0.0).with_patch(metar, 0.0)
    return stack.with_metar_weight(weight)


def test_near_a_fresh_metar_it_wins_below_and_the_model_above() -> None:
    t = _stack(1.0).target()
    assert t.wind[0].dir_from_deg == pytest.approx(180.0) and t.wind[0].speed_mps == pytest.approx(
        10.0
    )
    assert t.wind[-1] == MODEL_WIND[-1]  # aloft: the model's
    assert [lay.type for lay in t.layers] == [CloudType.STRATOCUMULUS, CloudType.CIRROSTRATUS]
    sc = t.layers[0]
    assert (sc.cover_oktas, sc.base_m) == (7.0, 1200.0)
    assert sc.top_m == 1800.0  # the top a METAR never gives: the model's
    assert t.sources.layers is Source.METAR and t.visibility_m == 8000.0
    assert t.temperature_c == 4.0 and t.sources.temperature_c is Source.GRIB


def test_far_from_stations_the_model_stands() -> None:
    t = _stack(0.0).target()
    assert t.wind == MODEL_WIND and t.layers == MODEL_LAYERS
    assert t.sources.wind is Source.GRIB and t.sources.layers is Source.GRIB
    half = _stack(0.5).target()
    low = half.layers[0]
    assert low.cover_oktas == pytest.approx(5.5) and low.base_m == pytest.approx(1050.0)
    e, n = half.wind[0].velocity_mps()
    assert (e, n) == (pytest.approx(2.5), pytest.approx(5.0))  # half of each, as vectors


# -- the checks by hand -------------------------------------------------------------

# Near a grid corner (47.5 N 7.5 E is one), across the date line (between 177.5 E and
# 177.5 W, the grid's 180 between), near the north pole (between 87.5 N and the pole row).
POINTS = ((47.49, 7.52), (-16.3, -178.9), (88.9, 33.3))


def _by_hand(data: bytes) -> dict[tuple[str, float], np.ndarray]:
    """eccodes' own values of u, v and t at 850, 500 and 250 hPa, as (lat, lon) grids from the
    north pole row down, 0 E first: read here, not through wxsky's decoder."""
    import os

    import eccodes

    out: dict[tuple[str, float], np.ndarray] = {}
    eccodes.codes_grib_multi_support_on()
    fd = os.memfd_create("fixture")
    with os.fdopen(fd, "w+b") as f:
        f.write(data)
        f.seek(0)
        while (h := eccodes.codes_grib_new_from_file(f)) is not None:
            try:
                name = eccodes.codes_get(h, "shortName")
                level = float(eccodes.codes_get(h, "level"))
                iso = eccodes.codes_get(h, "typeOfLevel") == "isobaricInhPa"
                if iso and name in ("u", "v", "t") and level in (850.0, 500.0, 250.0):
                    nj, ni = eccodes.codes_get(h, "Nj"), eccodes.codes_get(h, "Ni")
                    out[(name, level)] = eccodes.codes_get_values(h).reshape(nj, ni)
            finally:
                eccodes.codes_release(h)
    return out


def _bilinear_by_hand(grid: np.ndarray, lat: float, lon: float) -> float:
    """The fixture's grid: rows from 90 N down by 2.5 degrees, columns from 0 E east."""
    y = (90.0 - lat) / 2.5
    x = (lon % 360.0) / 2.5
    j0, i0 = math.floor(y), math.floor(x)
    fy, fx = y - j0, x - i0
    j1, i1 = min(j0 + 1, grid.shape[0] - 1), (i0 + 1) % grid.shape[1]
    i0 %= grid.shape[1]
    top = (1 - fx) * grid[j0, i0] + fx * grid[j0, i1]
    bottom = (1 - fx) * grid[j1, i0] + fx * grid[j1, i1]
    return float((1 - fy) * top + fy * bottom)


@pytest.mark.parametrize("point", POINTS, ids=["grid-corner", "date-line", "pole"])
def test_the_profile_is_eccodes_values_interpolated(
    data: bytes, whole: list[ModelField], point: tuple[float, float]
) -> None:
    lat, lon = point
    raw = _by_hand(data)
    p = profile_at(merge_steps(decode(data, "gfs", Window(lat, lon)), ("gfs",)), lat, lon, VALID)
    assert p is not None
    for hpa in (850.0, 500.0, 250.0):
        lev = next(lev for lev in p.levels if lev.pressure_hpa == hpa)
        assert lev.u_mps == pytest.approx(_bilinear_by_hand(raw[("u", hpa)], lat, lon), abs=0.1)
        assert lev.v_mps == pytest.approx(_bilinear_by_hand(raw[("v", hpa)], lat, lon), abs=0.1)
        assert lev.t_k == pytest.approx(_bilinear_by_hand(raw[("t", hpa)], lat, lon), abs=0.1)
    # between levels: pressure falls with height, and winds and temperatures lie between
    # the levels' own, as the log-pressure interpolation keeps them
    for a, b in itertools.pairwise(p.levels):
        heights = np.linspace(a.height_m, b.height_m, 7)
        pressures = [p.at_height(float(h)).pressure_hpa for h in heights]  # type: ignore[union-attr]
        assert all(x > y for x, y in itertools.pairwise(pressures))
        for h in heights[1:-1]:
            at = p.at_height(float(h))
            assert at is not None
            for name in ("u_mps", "v_mps", "t_k"):
                lo, hi = sorted((getattr(a, name), getattr(b, name)))
                assert lo - 1e-9 <= getattr(at, name) <= hi + 1e-9


def test_each_layer_drifts_with_the_wind_at_its_middle() -> None:
    """Two layers, the model's wind from the west at one's middle and from the south at the
    other's: after ten minutes each has gone its own way, 90 degrees apart."""
    from wxsky.scene.gather import advance_drift, zero_drift

    wind = (
        WindLayer(100.0, 270.0, 4.0),
        WindLayer(1500.0, 270.0, 12.0),  # the low layer's middle
        WindLayer(6000.0, 180.0, 20.0),  # the high layer's middle
        WindLayer(9000.0, 180.0, 30.0),
    )
    layers = (
        CloudLayer(4.0, 1000.0, 2000.0, CloudType.CUMULUS),
        CloudLayer(5.0, 5500.0, 6500.0, CloudType.ALTOCUMULUS),
    )
    state = dataclasses.replace(WeatherState(), wind=wind, layers=layers)
    drift = advance_drift(state, zero_drift(state), 600.0)
    (le, ln), (he, hn) = drift
    assert (le, ln) == (pytest.approx(12.0 * 600.0), pytest.approx(0.0, abs=1e-6))
    assert (he, hn) == (pytest.approx(0.0, abs=1e-6), pytest.approx(20.0 * 600.0))


def test_at_the_station_the_metar_and_200_km_away_the_model() -> None:
    at_station = _stack(model_blend.metar_weight(0.0, 300.0)).target()
    assert at_station.wind[0].speed_mps == pytest.approx(10.0)
    assert at_station.wind[0].dir_from_deg == pytest.approx(180.0)
    assert next((lay.type, lay.cover_oktas, lay.base_m) for lay in at_station.layers) == (
        CloudType.STRATOCUMULUS,
        7.0,
        1200.0,
    )
    far = _stack(model_blend.metar_weight(200_000.0, 300.0)).target()
    assert far.wind == MODEL_WIND and far.layers == MODEL_LAYERS


def test_absurd_values_leave_out_their_field_and_the_rest_is_used(
    data: bytes, whole: list[ModelField]
) -> None:
    """A copy of the real file whose 250 hPa u field is shifted by 10,000 m/s (its packing's
    reference value changed): that field is named and left out, v beside it in the same
    message and every other field stay."""
    import struct

    offset = next(
        int(line.split(":")[1]) for line in inventory(data).splitlines() if ":UGRD:250 mb:" in line
    )
    absurd = bytearray(data)
    at = offset + 16
    while absurd[at + 4] != 5:  # to the u field's data representation section
        at += int.from_bytes(absurd[at : at + 4], "big")
    absurd[at + 11 : at + 15] = struct.pack(">f", 10_000.0)  # its reference value
    problems: list[str] = []
    fields = decode(bytes(absurd), "absurd.grib2", Window(*LONDON), problems)
    keys = {f.key for f in fields}
    assert ("u", "isobaric", 250.0) not in keys and ("v", "isobaric", 250.0) in keys
    assert ("u", "isobaric", 300.0) in keys
    (problem,) = problems
    assert problem.startswith("absurd.grib2: message ") and "u at 250 hPa" in problem
    assert "outside -150..150 m/s" in problem and "\n" not in problem
    with pytest.raises(GribError, match="u at 250 hPa"):
        decode(bytes(absurd), "absurd.grib2", Window(*LONDON))
    # that file was given up between a message's u and its v: the next file read is its own,
    # not the abandoned v first (eccodes keeps a message's rest across files)
    assert [f.key for f in decode(data, "gfs")] == [f.key for f in whole]
    # the level without its u is said, and left out of the column
    steps = merge_steps(fields, ("absurd",))
    (gap,) = next(iter(steps.values())).gaps()
    assert "250 hPa: v, t but no u" in gap
    p = profile_at(steps, *LONDON, VALID)
    assert p is not None and 250.0 not in {lev.pressure_hpa for lev in p.levels}


def test_a_truncated_file_gives_what_came_before_the_cut(data: bytes) -> None:
    problems: list[str] = []
    fields = decode(data[: len(data) // 2 + 17], "half.grib2", Window(*LONDON), problems)
    assert fields and len(problems) == 1
    assert problems[0].startswith("half.grib2: message ") and "left out" in problems[0]


def test_crossing_a_step_the_target_moves_no_faster_than_the_transitions(data: bytes) -> None:
    """Three steps six hours apart (the later two made from the real one, their winds
    doubled, then back): the grib source's target, worked out every 10 s as the daemon does
    ([grib] update_s) from ten minutes before the middle step to ten after, never moves
    further in one update than the default [transition] rates allow in that time."""
    from wxsky.weather.model_clouds import model_layers as layers_of
    from wxsky.weather.transition import TransitionRates

    rates = TransitionRates()
    first = decode(data, "gfs", Window(*LONDON))
    later = [*_shifted(first, 6.0, 2.0), *_shifted(first, 12.0, 1.0)]
    steps = merge_steps([*first, *later], ("a", "b", "c"))
    assert len(steps) == 3
    update_s = 10.0
    before: WeatherState | None = None
    middle = VALID + timedelta(hours=6)
    t = middle - timedelta(minutes=10)
    while t <= middle + timedelta(minutes=10):
        p = profile_at(steps, *LONDON, t)
        assert p is not None
        patch = WeatherPatch(source=Source.GRIB, wind=p.winds(), layers=layers_of(p))
        target = SourceStack(base=WeatherState()).with_patch(patch, 0.0).target()
        if before is not None:
            for a, b in zip(before.wind, target.wind, strict=True):
                ae, an = a.velocity_mps()
                be, bn = b.velocity_mps()
                assert math.hypot(be - ae, bn - an) <= rates.wind_mps_per_s * update_s
            for a, b in zip(before.layers, target.layers, strict=True):
                assert a.type == b.type
                cover_step = rates.cover_oktas_per_min * update_s / 60.0
                assert abs(b.cover_oktas - a.cover_oktas) <= cover_step
                assert abs(b.base_m - a.base_m) <= rates.base_m_per_min * update_s / 60.0
        before = target
        t += timedelta(seconds=update_s)


def test_a_steep_lapse_rate_heaps_the_low_cloud_up() -> None:
    """The same wet low levels: in air cooling 9 K a kilometre (conditionally unstable) the
    cloud is cumulus; in air cooling 5 K a kilometre, stratocumulus."""
    from wxsky.weather.model_clouds import lapse_k_per_km

    def column(lapse_k_per_km: float) -> ModelProfile:
        rh = {1000: 60, 925: 97, 850: 98, 700: 50, 500: 40}
        levels = []
        for hpa, r in rh.items():
            h = 8000.0 * math.log(1013.0 / hpa)
            levels.append(ProfileLevel(hpa, h, 5.0, 0.0, 290.0 - lapse_k_per_km * h / 1000.0, r))
        return ModelProfile(
            51.0, 0.0, VALID, (VALID,), tuple(levels), 0.0, 1013.0, 290.0, 0.0, 0.0, 2000.0,
            11000.0, 250.0, (),
        )  # fmt: skip

    steep, gentle = column(9.0), column(5.0)
    assert lapse_k_per_km(steep) == pytest.approx(9.0) and lapse_k_per_km(gentle) == pytest.approx(
        5.0
    )
    assert model_layers(steep)[0].type is CloudType.CUMULUS
    assert model_layers(gentle)[0].type is CloudType.STRATOCUMULUS


def test_the_kept_copy_is_the_shared_file() -> None:
    """tests/data/grib holds a byte-for-byte copy of ../shared/data/grib's file."""
    if not SHARED_GFS.exists():
        pytest.skip(f"the shared original is not present at {SHARED_GFS}")
    assert GFS.read_bytes() == SHARED_GFS.read_bytes()
