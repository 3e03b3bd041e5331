"""tests/sky_measure.py, the picture checks' shared measures: the colour maths against the sRGB
standard's own numbers, and regions found by direction on pictures whose answer is known."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sky_measure as sm

from wxsky.png import write_png
from wxsky.scene.camera import Camera


def test_srgb_decoding_follows_the_standard() -> None:
    out = sm.srgb_to_linear(np.array([0, 10, 128, 255], np.uint8))
    # IEC 61966-2-1: linear below 0.04045 (10/255 = 0.0392), the 2.4 power above.
    assert out[0] == 0.0 and out[3] == pytest.approx(1.0)
    assert out[1] == pytest.approx(10 / 255 / 12.92)
    assert out[2] == pytest.approx(0.2158605, abs=1e-6)
    rgba = np.full((2, 2, 4), 255, np.uint8)
    assert sm.srgb_to_linear(rgba).shape == (2, 2, 3)  # alpha dropped


def test_luminance_weights_green_most() -> None:
    assert sm.relative_luminance([1.0, 1.0, 1.0]) == pytest.approx(1.0)
    assert sm.relative_luminance([0.0, 1.0, 0.0]) == pytest.approx(0.7152)


def test_the_horizon_dips_with_height() -> None:
    assert sm.horizon_dip_deg(2.0) == pytest.approx(0.0454, abs=5e-4)
    assert sm.horizon_dip_deg(10_000.0) == pytest.approx(3.21, abs=0.01)
    assert sm.horizon_dip_deg(0.0) == 0.0


def _painted(camera: Camera) -> np.ndarray:
    """Linear picture: blue below 1° elevation, grey above; red in the half facing east."""
    el = sm.pixel_elevation_deg(camera)
    az = sm.pixel_azimuth_deg(camera)
    img = np.where((el < 1.0)[..., None], [0.2, 0.3, 0.5], [0.3, 0.3, 0.3])
    img[(el > 8.0) & (az < 90.0)] = [0.6, 0.1, 0.1]
    return np.asarray(img, np.float64)


def test_regions_are_found_by_direction() -> None:
    camera = Camera((0.0, 0.0, 2.0), heading_deg=90.0, pitch_deg=2.0, width_px=320, height_px=180)
    img = _painted(camera)
    m = sm.horizon_band_vs_deck(img, camera, eye_agl_m=2.0)
    # The band (-1..1°) is mostly the blue below 1°; the deck rows (4.5..5.5°) are grey.
    assert m.deck.blue_over_red == pytest.approx(1.0)
    assert 2.0 < m.band.blue_over_red <= 2.5 and m.bluer > 2.0
    assert m.brighter == pytest.approx(m.band.luminance / m.deck.luminance)
    north_of_east = sm.sky_region(
        img, camera, (10.0, 15.0), azimuth_deg=60.0, azimuth_half_width_deg=20.0
    )
    south_of_east = sm.sky_region(
        img, camera, (10.0, 15.0), azimuth_deg=120.0, azimuth_half_width_deg=20.0
    )
    assert north_of_east.rgb == pytest.approx((0.6, 0.1, 0.1))
    assert south_of_east.rgb == pytest.approx((0.3, 0.3, 0.3))
    with pytest.raises(ValueError, match="no pixels"):
        sm.sky_region(img, camera, (40.0, 50.0))  # above the top of the picture


def test_pictures_load_as_linear_light(tmp_path: Path) -> None:
    rgb = np.array([[[0.25, 0.5, 1.0], [0.0, 0.125, 2.0]], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    np.save(tmp_path / "a.npy", rgb.astype(np.float32))
    assert sm.load_linear(tmp_path / "a.npy") == pytest.approx(rgb)
    # PFM: little-endian (negative scale), bottom row first in the file.
    body = rgb[::-1].astype("<f4").tobytes()
    (tmp_path / "a.pfm").write_bytes(b"PF\n2 2\n-1.0\n" + body)
    assert sm.load_linear(tmp_path / "a.pfm") == pytest.approx(rgb)
    (tmp_path / "b.pfm").write_bytes(b"PF\n2 2\n1.0\n" + rgb[::-1].astype(">f4").tobytes())
    assert sm.load_linear(tmp_path / "b.pfm") == pytest.approx(rgb)
    png = np.full((2, 2, 4), 255, np.uint8)
    png[0, 0, :3] = 128
    write_png(tmp_path / "a.png", png)
    assert sm.load_linear(tmp_path / "a.png")[0, 0, 0] == pytest.approx(0.2158605, abs=1e-6)
    with pytest.raises(ValueError, match=r"not a \.png"):
        sm.load_linear(tmp_path / "a.tif")
