"""tools/bench/banding.py (issue 42's streaking measure): the band is the one asked for, and
the figure reads stripes down the picture high, stripes across it low and noise near 1."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tool_loader import load_tool

banding = load_tool("bench/banding")
SIZE = (320, 180)


def _picture(luma: np.ndarray) -> np.ndarray:
    grey = np.clip(np.rint(luma * 255.0), 0, 255).astype(np.uint8)
    return np.repeat(grey[..., None], 4, axis=2)


def test_the_rays_climb_from_the_pitch_at_the_middle_to_half_the_field_at_the_top() -> None:
    """With a 60 deg field across 16:9 and the eye 4 deg up, the middle rows look 4 deg up,
    the top row about 4 + 17.5, the bottom about 4 - 17.5; the corners of a row are lower
    than its middle above the level and higher below it (perspective)."""
    el = banding.ray_elevation_deg((1280, 720), 4.0, 60.0)
    half_v = math.degrees(math.atan(math.tan(math.radians(30.0)) * 720 / 1280))
    assert el[359:361, 639:641].mean() == pytest.approx(4.0, abs=0.05)
    assert el[0, 640] == pytest.approx(4.0 + half_v, abs=0.1)
    assert el[-1, 640] == pytest.approx(4.0 - half_v, abs=0.1)
    assert el[0, 0] < el[0, 640]
    assert el[-1, 0] > el[-1, 640]


def test_stripes_across_read_high_stripes_down_low_and_noise_near_one() -> None:
    rng = np.random.default_rng(42)
    el = banding.ray_elevation_deg(SIZE, 4.0, 60.0)
    rows = np.arange(SIZE[1])[:, None] * np.ones((1, SIZE[0]))
    cols = np.ones((SIZE[1], 1)) * np.arange(SIZE[0])[None, :]
    noise = rng.random((SIZE[1], SIZE[0])) * 0.1
    across = _picture(0.5 + 0.2 * (rows % 2) + noise)  # stacked slices: horizontal stripes
    down = _picture(0.5 + 0.2 * (cols % 2) + noise)
    plain = _picture(0.3 + 4.0 * noise)
    band = banding.BAND_DEG
    assert banding.banding(across, el, band) > 5.0
    assert banding.banding(down, el, band) < 0.2
    assert banding.banding(plain, el, band) == pytest.approx(1.0, abs=0.15)
    # Stripes outside the band do not count.
    outside = _picture(0.3 + 4.0 * noise + 0.2 * ((rows % 2) * (el < 0.0)))
    assert banding.banding(outside, el, band) == pytest.approx(1.0, abs=0.15)
    assert math.isnan(banding.banding(_picture(np.full((SIZE[1], SIZE[0]), 0.4)), el, band))
