"""The kept sky's strips against the dome's band (`sky_layer.plan_sky`, `strip_edges`): the
dome, the dearest part, redraws one strip of its own band a frame at an even cost as it
drifts, and the plain sky is never drawn where the band covers it. Before, the layer's eight
even strips cut the band into 20 to 110 rows a frame, and every plain-sky strip redrawn for
the sun's motion redrew the dome under it too."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wxsky.render.sky_layer import (
    DOME_STRIPS,
    FLAT_SUN_TOLERANCE_RAD,
    SKY_CATCH_UP,
    SKY_STRIPS,
    SkyPart,
    dome_offset_tolerance,
    plan_sky,
    strip_edges,
    strip_rows,
)
from wxsky.render.sky_textures import FULL_RECT, Rect, SkyFeatures, pixel_rad, view_top_sin
from wxsky.scene import atmosphere as atm
from wxsky.scene.camera import Camera
from wxsky.scene.sky import SUN_EXACT_DEG, display_sky_view, sky_params, sky_view_elevation
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

PLAIN = SkyFeatures(stars=False, moon=False, dome=False)
DOME = SkyFeatures(stars=False, moon=False, dome=True)
BAND: Rect = (-1.0, -0.083, 1.0, 0.306)  # fair-cumulus's, level at 1,500 m (NDC, y down)
HEIGHT_PX = 720


def _part(name: str, feats: SkyFeatures, rect: Rect, value: float) -> SkyPart:
    # One number each, its tolerance 1: a part's drift is its value's change.
    return SkyPart.of(name, feats, rect, {"u_x": value}, {"u_x": 1.0})


def _rows(rect: Rect) -> float:
    return (rect[3] - rect[1]) / 2.0 * HEIGHT_PX


def _frames(
    sky_rate: float, dome_rate: float, band: Rect, frames: int = 60
) -> list[list[tuple[str, Rect]]]:
    """The draws of each frame while the plain sky and the dome drift at these rates (in
    tolerances a frame), after the first (which draws everything)."""
    kept = None
    out = []
    for k in range(frames):
        parts = [
            _part("sky", PLAIN, FULL_RECT, sky_rate * k),
            _part("sky dome", DOME, band, dome_rate * k),
        ]
        draws, kept = plan_sky(kept, 7, parts)
        if k:
            out.append([(part.pass_name, rect) for part, rect in draws])
    return out


def test_the_strips_meet_the_dome_bands_edges_and_hold_at_least_three_strips_of_it() -> None:
    edges = strip_edges([_part("sky", PLAIN, FULL_RECT, 0.0), _part("d", DOME, BAND, 0.0)])
    assert edges[0] == -1.0 and edges[-1] == 1.0 and list(edges) == sorted(edges)
    assert BAND[1] in edges and BAND[3] in edges
    inside = [e for e in edges if BAND[1] < e < BAND[3]]
    assert len(inside) + 1 >= DOME_STRIPS
    # Outside the band, strips about as tall as the even ones.
    tallest = float(np.diff(edges).max())
    assert tallest <= 1.5 * 2.0 / SKY_STRIPS
    # Without a band across the picture (the moon's disc only, or no later part): even strips.
    moon: Rect = (0.6, -0.8, 0.7, -0.7)
    even = strip_edges([_part("sky", PLAIN, FULL_RECT, 0.0), _part("m", DOME, moon, 0.0)])
    assert np.allclose(np.diff(even), 2.0 / SKY_STRIPS)


def test_a_drifting_dome_redraws_one_strip_of_its_band_a_frame_and_never_the_sky_under_it() -> None:
    # fair-cumulus's rates: the sun 0.1 of a tolerance a frame, the dome's offsets 0.63.
    frames = _frames(0.102, 0.628, BAND)
    band_rows = _rows(BAND)
    dome_rows = []
    for draws in frames:
        for name, rect in draws:
            if name == "sky":
                # Nowhere inside the band: the dome draws over all of it.
                assert rect[3] <= BAND[1] + 1e-12 or rect[1] >= BAND[3] - 1e-12, rect
        dome_rows.append(sum(_rows(rect) for name, rect in draws if name == "sky dome"))
    steady = dome_rows[5:]
    # A strip of the band a frame, every frame: the same cost each frame.
    assert max(steady) <= band_rows / DOME_STRIPS + 1e-6
    assert min(steady) >= band_rows / DOME_STRIPS - 1e-6


@pytest.mark.parametrize("dome_rate", [0.05, 0.628, 1.5])
def test_every_strip_stays_within_catch_up_of_the_latest_numbers(dome_rate: float) -> None:
    """However fast the dome drifts (below a jump), no strip of any part falls more than
    SKY_CATCH_UP tolerances behind: the plan keeps up by drawing more strips a frame."""
    kept = None
    for k in range(80):
        parts = [
            _part("sky", PLAIN, FULL_RECT, 0.102 * k),
            _part("sky dome", DOME, BAND, dome_rate * k),
        ]
        _, kept = plan_sky(kept, 7, parts)
        edges = kept.edges
        for p, (part, held) in enumerate(zip(parts, kept.strips, strict=True)):
            for i, values in enumerate(held):
                strip: Rect = (-1.0, edges[i], 1.0, edges[i + 1])
                covered = p == 0 and BAND[1] <= strip[1] and strip[3] <= BAND[3]
                overlaps = part.rect[1] < strip[3] and strip[1] < part.rect[3]
                if overlaps and not covered:  # a strip the part shows in
                    assert part.drift_from(values) <= SKY_CATCH_UP, (k, part.pass_name, i)


def test_strip_rows_hold_every_row_their_rectangle_rasterises_to() -> None:
    # Edges on row boundaries: exactly those rows; between rows: one more at that end.
    assert strip_rows(-1.0, -0.75, 720) == (0, 90)
    assert strip_rows(-0.083, 0.306, 720) == (329, 472)
    for top, bottom in ((-1.0, -0.083), (-0.083, 0.306), (0.306, 1.0)):
        first, stop = strip_rows(top, bottom, 357)
        centres = (np.arange(357) + 0.5) / 357 * 2.0 - 1.0
        inside = np.flatnonzero((centres >= top) & (centres < bottom))
        assert first <= inside[0] and inside[-1] < stop


def test_a_sky_that_moves_in_steps_is_redrawn_evenly_not_in_bursts() -> None:
    """The sky's numbers move on the sky step (scene.sky.SKY_STEP_US): a jump every fourth
    frame at 30 fps, still while the rest. The strips are drawn again at the mean rate, a
    couple a frame, not eight in a step's frame and one in the others."""
    kept = None
    strips_drawn = []
    for k in range(120):
        parts = [_part("sky", PLAIN, FULL_RECT, 0.48 * (k // 4))]  # 0.12 a frame, on average
        draws, kept = plan_sky(kept, 7, parts)
        strip_rows_px = 2.0 / SKY_STRIPS / 2.0 * HEIGHT_PX
        strips_drawn.append(round(sum(_rows(rect) for _, rect in draws) / strip_rows_px))
        for values in kept.strips[0]:
            assert parts[0].drift_from(values) <= SKY_CATCH_UP
    steady = strips_drawn[20:]
    assert max(steady) <= 3
    # Every strip is drawn again in time: as many as the drift asks for, over the frames.
    assert sum(steady) >= len(steady) * 0.12 * SKY_STRIPS / (SKY_CATCH_UP - 1.0) * 0.9


@pytest.mark.parametrize(
    ("sun_deg", "visibility_m"),
    [(5.0, 60_000.0), (5.0, 8_000.0), (20.0, 30_000.0), (60.0, 60_000.0), (-4.0, 30_000.0)],
)
def test_a_sun_turned_by_its_tolerance_moves_the_baked_sky_by_under_a_third_of_a_level(
    sun_deg: float, visibility_m: float
) -> None:
    """The physical sky's kept strips are drawn again once the sun's azimuth has turned by
    FLAT_SUN_TOLERANCE_RAD: that turn of the baked table (read across its columns as the sky
    pass reads it, linearly) changes no pixel outside the sun part's rectangle by a third of a
    display level, low sun and hazy air included (where the sky's colour changes fastest
    round the horizon)."""
    luts = atm.build_luts(atm.atmosphere_key(sun_deg, visibility_m, 50.0, 1_500.0))
    table = display_sky_view(luts, 0.0) * 255.0
    rows, cols = table.shape[:2]
    el = sky_view_elevation((np.arange(rows) + 0.5) / rows, luts.horizon_rad)[:, None]
    az = np.linspace(0.0, math.pi, 4 * cols)[None, :]

    def read(azimuth: np.ndarray) -> np.ndarray:
        at = np.clip(azimuth / math.pi * cols - 0.5, 0.0, cols - 1.0)
        lo = np.minimum(np.floor(at).astype(int), cols - 2)
        w = (at - lo)[..., None]
        picked = np.arange(rows)[:, None]
        return np.asarray(table[picked, lo] * (1.0 - w) + table[picked, lo + 1] * w)

    turned = np.abs(read(az + FLAT_SUN_TOLERANCE_RAD) - read(az)).max(axis=2)
    sun = math.radians(sun_deg)
    cos_sun = np.cos(el) * np.cos(az) * math.cos(sun) + np.sin(el) * math.sin(sun)
    # Beyond the sun part (SUN_EXACT_DEG round the sun, less the azimuth turned).
    outside = cos_sun < math.cos(math.radians(SUN_EXACT_DEG) - FLAT_SUN_TOLERANCE_RAD)
    assert float(turned[outside].max()) < 1.0 / 3.0


@pytest.mark.parametrize(
    ("pitch_deg", "roll_deg"), [(0.0, 0.0), (10.0, 0.0), (0.0, 30.0), (45.0, 45.0), (-20.0, 0.0)]
)
def test_the_view_top_is_never_below_the_highest_ray_of_the_picture(
    pitch_deg: float, roll_deg: float
) -> None:
    """`view_top_sin`, which sets how far the kept dome may drift (the nearest dome the picture
    shows), against every pixel's ray of a 1280 x 720 picture: not lower (that would let the
    dome drift visibly), and close (within a degree)."""
    cam = Camera((0.0, 0.0, 1_500.0), 90.0, pitch_deg, roll_deg, 60.0, 1280, 720)
    right, up, fwd = cam.basis()
    a, b = np.meshgrid(np.linspace(-1.0, 1.0, 1280), np.linspace(-1.0, 1.0, 720))
    rays = (
        fwd[:, None, None]
        + a * cam.tan_half_fov_x * right[:, None, None]
        - b * cam.tan_half_fov_y * up[:, None, None]
    )
    highest = float((rays[2] / np.linalg.norm(rays, axis=0)).max())
    top = view_top_sin(cam)
    assert top >= highest
    assert math.asin(min(top, 1.0)) - math.asin(highest) < math.radians(1.0)
    # The zenith in the picture: the top is the zenith.
    assert view_top_sin(Camera((0.0, 0.0, 0.0), 0.0, 80.0, 0.0, 60.0, 1280, 720)) == 1.0


def test_a_level_view_lets_high_cover_drift_as_far_as_its_nearest_visible_dome_allows() -> None:
    """Under high cover the dome nearest the eye is overhead; a level view's picture ends some
    18 deg up, where the dome is 1 / sin(18 deg) as far: its offsets may move that much more
    before any pixel it shows has moved DOME_REUSE_PX."""
    state = WeatherState().apply(load_preset("high-cirrus"))
    sky = sky_params(state)
    level = Camera((0.0, 0.0, 1_500.0), 90.0, 0.0, 0.0, 60.0, 1280, 720)
    up = Camera((0.0, 0.0, 1_500.0), 90.0, 80.0, 0.0, 60.0, 1280, 720)
    px = pixel_rad(level)
    overhead = dome_offset_tolerance(px, sky, 1_500.0, view_top_sin(up))
    ahead = dome_offset_tolerance(px, sky, 1_500.0, view_top_sin(level))
    assert overhead > 0.0
    assert ahead == pytest.approx(overhead / view_top_sin(level))
    assert dome_offset_tolerance(px, sky, 1_500.0) == overhead  # the default: the zenith


def test_a_part_s_numbers_and_tolerances_follow_its_uniforms() -> None:
    """`SkyPart.of` flattens every uniform (numbers, tuples, nested tuples, arrays) in order,
    gives each number its uniform's own tolerance, none to what always redraws, the colour
    tolerance relative past 1 to the rest, and leaves the rectangle out."""
    part = SkyPart.of(
        "sky",
        PLAIN,
        FULL_RECT,
        {
            "u_rect": (-1.0, -1.0, 1.0, 1.0),
            "u_a": 0.5,
            "u_big": (2.0e6, -3.0),
            "u_m": ((1.0, 2.0), (3.0, 4.0)),
            "u_arr": np.array([7.0, 8.0]),
            "u_star_clock_s": 12.5,
            "u_flat_sun": (0.6, 0.8),
            "u_own": (1.0, 100.0),
        },
        {"u_own": 0.25},
    )
    tol = 5e-5
    assert part.values.tolist() == [
        *(0.5, 2.0e6, -3.0, 1.0, 2.0, 3.0, 4.0, 7.0, 8.0, 12.5, 0.6, 0.8, 1.0, 100.0)
    ]
    expected = [tol, tol * 2.0e6, tol * 3.0, tol, tol * 2.0, tol * 3.0, tol * 4.0, tol * 7.0]
    expected += [tol * 8.0, 0.0, FLAT_SUN_TOLERANCE_RAD, FLAT_SUN_TOLERANCE_RAD, 0.25, 0.25]
    np.testing.assert_allclose(part.tolerance, expected)
    assert "u_rect" not in part.uniforms
