"""The kept sky's strips against the dome's band (`sky_layer.plan_sky`, `strip_edges`): the
dome, the dearest part, redraws one strip of its own band a frame at an even cost as it
drifts, and the plain sky is never drawn where the band covers it. Before, the layer's eight
even strips cut the band into 20 to 110 rows a frame, and every plain-sky strip redrawn for
the sun's motion redrew the dome under it too."""

from __future__ import annotations

import numpy as np
import pytest

from wxsky.render.sky_layer import (
    DOME_STRIPS,
    SKY_CATCH_UP,
    SKY_STRIPS,
    SkyPart,
    plan_sky,
    strip_edges,
    strip_rows,
)
from wxsky.render.sky_textures import FULL_RECT, Rect, SkyFeatures

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
