"""Camera basis, view and projection matrices, pixel rays, and validation.

Reference values are written out by hand from the conventions (ENU metres, heading 0 = north
growing clockwise, pitch up positive, roll positive right wing down, OpenGL view space looking
down -z, projection y flipped so image row 0 is the top).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wxsky.scene.camera import FAR_M, NEAR_M, Camera, camera_basis

S30, C30 = 0.5, math.sqrt(3.0) / 2.0


def _project(cam: Camera, point: np.ndarray) -> np.ndarray:
    """NDC (x, y, z) of a world point through the camera's view-projection."""
    clip = cam.view_projection() @ np.append(point, 1.0)
    assert clip[3] > 0.0, "point is behind the camera"
    return clip[:3] / clip[3]


def _ndc_to_pixel(cam: Camera, ndc: np.ndarray) -> tuple[float, float]:
    """(row, col) of an NDC point in the read-back image (row 0 = NDC y -1 = framebuffer
    row 0), in pixel-centre coordinates."""
    col = (ndc[0] + 1.0) / 2.0 * cam.width_px - 0.5
    row = (ndc[1] + 1.0) / 2.0 * cam.height_px - 0.5
    return row, col


# -- basis --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("heading", "fwd", "right"),
    [
        (0.0, (0, 1, 0), (1, 0, 0)),  # north, right is east
        (90.0, (1, 0, 0), (0, -1, 0)),  # east, right is south
        (180.0, (0, -1, 0), (-1, 0, 0)),  # south, right is west
        (270.0, (-1, 0, 0), (0, 1, 0)),  # west, right is north
        (-90.0, (-1, 0, 0), (0, 1, 0)),  # same as 270
        (450.0, (1, 0, 0), (0, -1, 0)),  # same as 90
    ],
)
def test_basis_for_cardinal_headings(heading: float, fwd: tuple, right: tuple) -> None:
    r, u, f = Camera((0.0, 0.0, 0.0), heading_deg=heading).basis()
    np.testing.assert_allclose(f, fwd, atol=1e-12)
    np.testing.assert_allclose(r, right, atol=1e-12)
    np.testing.assert_allclose(u, (0, 0, 1), atol=1e-12)


def test_pitch_up_raises_forward_and_tilts_up_backwards() -> None:
    r, u, f = camera_basis(0.0, 30.0, 0.0)
    np.testing.assert_allclose(f, (0, C30, S30), atol=1e-12)
    np.testing.assert_allclose(u, (0, -S30, C30), atol=1e-12)
    np.testing.assert_allclose(r, (1, 0, 0), atol=1e-12)


def test_pitch_down_lowers_forward() -> None:
    r, u, f = camera_basis(90.0, -30.0, 0.0)
    np.testing.assert_allclose(f, (C30, 0, -S30), atol=1e-12)
    np.testing.assert_allclose(u, (S30, 0, C30), atol=1e-12)
    np.testing.assert_allclose(r, (0, -1, 0), atol=1e-12)


def test_pitch_straight_up_and_down() -> None:
    _, u, f = camera_basis(0.0, 90.0, 0.0)
    np.testing.assert_allclose(f, (0, 0, 1), atol=1e-12)
    np.testing.assert_allclose(u, (0, -1, 0), atol=1e-12)  # top of the image is behind
    _, u, f = camera_basis(0.0, -90.0, 0.0)
    np.testing.assert_allclose(f, (0, 0, -1), atol=1e-12)
    np.testing.assert_allclose(u, (0, 1, 0), atol=1e-12)


def test_roll_right_wing_down_tilts_up_to_the_right() -> None:
    r, u, f = camera_basis(0.0, 0.0, 30.0)
    np.testing.assert_allclose(f, (0, 1, 0), atol=1e-12)
    # Looking north, right is east: rolling right wing down leans "up" towards east
    # and drops the right vector below the horizon.
    np.testing.assert_allclose(u, (S30, 0, C30), atol=1e-12)
    np.testing.assert_allclose(r, (C30, 0, -S30), atol=1e-12)
    r, u, _ = camera_basis(0.0, 0.0, -30.0)
    np.testing.assert_allclose(u, (-S30, 0, C30), atol=1e-12)
    assert r[2] > 0.0


@pytest.mark.parametrize(
    ("heading", "pitch", "roll"),
    [(0, 0, 0), (37, 12, -8), (200, -45, 60), (315, 80, 170), (123.4, -89, -135)],
)
def test_basis_is_orthonormal_and_right_handed(heading: float, pitch: float, roll: float) -> None:
    r, u, f = camera_basis(heading, pitch, roll)
    m = np.stack([r, u, f])
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    # OpenGL view space: x right, y up, z backwards -> right x up = -forward.
    np.testing.assert_allclose(np.cross(r, u), -f, atol=1e-12)
    # Roll never moves the forward vector.
    np.testing.assert_allclose(f, camera_basis(heading, pitch, 0.0)[2], atol=1e-12)


# -- view and projection ------------------------------------------------------------------


def test_view_matrix_maps_eye_to_origin_and_forward_to_minus_z() -> None:
    cam = Camera((1200.0, -3400.0, 950.0), heading_deg=90.0, pitch_deg=0.0)
    v = cam.view_matrix()
    np.testing.assert_allclose(v @ [1200.0, -3400.0, 950.0, 1.0], (0, 0, 0, 1), atol=1e-9)
    # Heading 90: ahead is east.
    np.testing.assert_allclose(v @ [1300.0, -3400.0, 950.0, 1.0], (0, 0, -100, 1), atol=1e-9)
    # Right is south, up is up.
    np.testing.assert_allclose(v @ [1200.0, -3410.0, 950.0, 1.0], (10, 0, 0, 1), atol=1e-9)
    np.testing.assert_allclose(v @ [1200.0, -3400.0, 960.0, 1.0], (0, 10, 0, 1), atol=1e-9)


def test_view_matrix_with_pitch_and_roll_is_a_rigid_transform() -> None:
    cam = Camera((10.0, 20.0, 30.0), heading_deg=250.0, pitch_deg=20.0, roll_deg=-15.0)
    v = cam.view_matrix()
    _, _, f = cam.basis()
    ahead = np.array([10.0, 20.0, 30.0]) + 500.0 * f
    np.testing.assert_allclose(v @ np.append(ahead, 1.0), (0, 0, -500, 1), atol=1e-9)
    np.testing.assert_allclose(v[:3, :3] @ v[:3, :3].T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(v[3], (0, 0, 0, 1))


def test_projection_flips_y_so_points_above_the_axis_land_in_the_top_half() -> None:
    cam = Camera((0.0, 0.0, 1000.0), heading_deg=0.0, width_px=200, height_px=100)
    above = _project(cam, np.array([0.0, 5000.0, 1500.0]))
    below = _project(cam, np.array([0.0, 5000.0, 500.0]))
    right = _project(cam, np.array([800.0, 5000.0, 1000.0]))
    assert above[1] < 0.0 < below[1]
    assert right[0] > 0.0
    # Framebuffer row 0 (NDC y = -1) is the top of the image.
    assert _ndc_to_pixel(cam, above)[0] < cam.height_px / 2 < _ndc_to_pixel(cam, below)[0]


def test_projection_fov_edges_and_depth_range() -> None:
    cam = Camera((0.0, 0.0, 0.0), fov_deg=90.0, width_px=160, height_px=90)
    # 45° to the right at any distance lies on the right edge (horizontal fov 90°).
    np.testing.assert_allclose(_project(cam, np.array([700.0, 700.0, 0.0]))[0], 1.0, atol=1e-9)
    # Vertical half-extent at depth d is d * tan(45°) * 90 / 160; above it -> top edge (-1).
    np.testing.assert_allclose(
        _project(cam, np.array([0.0, 1600.0, 1600.0 * 90 / 160]))[1], -1.0, atol=1e-9
    )
    np.testing.assert_allclose(_project(cam, np.array([0.0, NEAR_M, 0.0]))[2], -1.0, atol=1e-9)
    np.testing.assert_allclose(_project(cam, np.array([0.0, FAR_M, 0.0]))[2], 1.0, atol=1e-6)
    assert cam.tan_half_fov_x == pytest.approx(1.0)
    assert cam.tan_half_fov_y == pytest.approx(90 / 160)


# -- pixel rays ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("heading", "pitch", "roll", "w", "h"),
    [(0, 0, 0, 160, 90), (200, 15, 0, 240, 135), (73, -40, 25, 64, 48), (310, 85, -170, 31, 17)],
)
def test_pixel_rays_agree_with_the_projection(
    heading: float, pitch: float, roll: float, w: int, h: int
) -> None:
    cam = Camera(
        (500.0, -200.0, 1500.0),
        heading_deg=heading,
        pitch_deg=pitch,
        roll_deg=roll,
        fov_deg=70.0,
        width_px=w,
        height_px=h,
    )
    rays = cam.pixel_rays()
    assert rays.shape == (h, w, 3)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0, atol=1e-12)
    eye = np.asarray(cam.position_m)
    for row, col in [(0, 0), (0, w - 1), (h - 1, 0), (h - 1, w - 1), (h // 3, w // 2), (h // 2, 3)]:
        ndc = _project(cam, eye + 3000.0 * rays[row, col])
        r, c = _ndc_to_pixel(cam, ndc)
        assert (r, c) == pytest.approx((row, col), abs=1e-6)


def test_pixel_rays_top_row_looks_up_and_centre_looks_forward() -> None:
    cam = Camera((0.0, 0.0, 0.0), heading_deg=30.0, fov_deg=60.0, width_px=41, height_px=21)
    rays = cam.pixel_rays()
    _, up, fwd = cam.basis()
    np.testing.assert_allclose(rays[10, 20], fwd, atol=1e-12)  # odd sizes: exact centre
    assert rays[0, 20] @ up > 0.0 > rays[-1, 20] @ up
    assert np.all(np.diff(rays[:, 20, 2]) < 0.0)  # z falls row by row going down
    # Pixel centres: the outermost column is half a pixel inside the 30° half-fov.
    half = math.degrees(math.atan(math.tan(math.radians(30.0)) * (1.0 - 1.0 / 41.0)))
    angle = math.degrees(math.acos(float(rays[10, 0] @ fwd)))
    assert angle == pytest.approx(half, abs=1e-9)


# -- validation ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs",
    [
        {"fov_deg": 0.5},
        {"fov_deg": 171.0},
        {"fov_deg": math.nan},
        {"width_px": 0},
        {"height_px": 0},
        {"width_px": 8193},
        {"height_px": -5},
        {"pitch_deg": 90.5},
        {"pitch_deg": -91.0},
        {"pitch_deg": math.nan},
        {"heading_deg": math.nan},
        {"heading_deg": math.inf},
        {"roll_deg": math.nan},
        {"position_m": (0.0, math.nan, 0.0)},
        {"position_m": (math.inf, 0.0, 0.0)},
    ],
)
def test_invalid_camera_is_rejected(kwargs: dict) -> None:
    args: dict = {"position_m": (0.0, 0.0, 0.0), **kwargs}
    with pytest.raises(ValueError, match="camera"):
        Camera(**args)


def test_boundary_values_are_accepted() -> None:
    Camera((0.0, 0.0, 0.0), fov_deg=1.0, pitch_deg=90.0, width_px=16, height_px=8192)
    Camera((0.0, 0.0, 0.0), fov_deg=170.0, pitch_deg=-90.0, width_px=8192, height_px=16)
