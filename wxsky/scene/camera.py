"""Cameras and their matrices, in the scene's local frame.

The frame is east-north-up (ENU) in metres, centred on the weather observer's latitude and
longitude at mean sea level, so z is altitude MSL. Heading 0 looks north and grows clockwise,
pitch is positive nose up, roll positive right wing down. Matrices follow OpenGL (column
vectors, camera looking down -z), stored row-major as numpy (4, 4) float64.

Images are produced top row first: every projection here flips y, so that reading a
framebuffer back gives rows in the order a host uploads them.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.schema import Number

Vec3 = tuple[float, float, float]
Mat4 = npt.NDArray[np.float64]  # (4, 4)

NEAR_M = 2.0
FAR_M = 200_000.0

# The one source of the camera's limits: the config, the control channel and the command line
# check against these. 8192 is the largest texture every GL 3.3 driver we target allocates.
VIEWPORT_PX = Number(16, 8192, integer=True, unit="px")
FOV_DEG = Number(1.0, 170.0, unit="deg")  # horizontal
PITCH_DEG = Number(-90.0, 90.0, unit="deg")
ROLL_DEG = Number(-180.0, 180.0, unit="deg")  # right wing down positive


@dataclass(frozen=True)
class Camera:
    position_m: Vec3
    heading_deg: float = 0.0
    pitch_deg: float = 0.0
    roll_deg: float = 0.0
    fov_deg: float = 60.0  # horizontal
    width_px: int = 960
    height_px: int = 540

    def __post_init__(self) -> None:
        FOV_DEG.validate("camera fov_deg", self.fov_deg)
        VIEWPORT_PX.validate("camera width", self.width_px)
        VIEWPORT_PX.validate("camera height", self.height_px)
        PITCH_DEG.validate("camera pitch_deg", self.pitch_deg)
        if not all(math.isfinite(v) for v in (*self.position_m, self.heading_deg, self.roll_deg)):
            raise ValueError("camera position and angles must be finite")

    def basis(self) -> tuple[npt.NDArray[np.float64], ...]:
        """(right, up, forward) unit vectors in the ENU frame."""
        return camera_basis(self.heading_deg, self.pitch_deg, self.roll_deg)

    @property
    def tan_half_fov_x(self) -> float:
        return math.tan(math.radians(self.fov_deg) / 2.0)

    @property
    def tan_half_fov_y(self) -> float:
        return self.tan_half_fov_x * self.height_px / self.width_px

    def view_matrix(self) -> Mat4:
        right, up, fwd = self.basis()
        return view_from_basis(np.asarray(self.position_m, dtype=np.float64), right, up, fwd)

    def projection_matrix(self) -> Mat4:
        tx, ty = self.tan_half_fov_x, self.tan_half_fov_y
        return frustum(-tx * NEAR_M, tx * NEAR_M, -ty * NEAR_M, ty * NEAR_M, NEAR_M, FAR_M)

    def view_projection(self) -> Mat4:
        return self.projection_matrix() @ self.view_matrix()

    def pixel_rays(self) -> npt.NDArray[np.float64]:
        """(H, W, 3) unit view rays through each pixel centre, top row first."""
        right, up, fwd = self.basis()
        xs = ((np.arange(self.width_px) + 0.5) / self.width_px * 2.0 - 1.0) * self.tan_half_fov_x
        ys = (1.0 - (np.arange(self.height_px) + 0.5) / self.height_px * 2.0) * self.tan_half_fov_y
        rays = fwd + xs[None, :, None] * right + ys[:, None, None] * up
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        return rays


@functools.lru_cache(maxsize=16)
def camera_basis(
    heading_deg: float, pitch_deg: float, roll_deg: float
) -> tuple[npt.NDArray[np.float64], ...]:
    """(right, up, forward), read-only: kept for the last few orientations, which a frame
    asks for a dozen times and a steady flight holds for many frames."""
    h, p, r = (math.radians(v) for v in (heading_deg, pitch_deg, roll_deg))
    fwd = np.array([math.sin(h) * math.cos(p), math.cos(h) * math.cos(p), math.sin(p)])
    right0 = np.array([math.cos(h), -math.sin(h), 0.0])
    up0 = np.cross(right0, fwd)
    right = right0 * math.cos(r) - up0 * math.sin(r)
    up = up0 * math.cos(r) + right0 * math.sin(r)
    for axis in (right, up, fwd):
        axis.setflags(write=False)
    return right, up, fwd


def view_from_basis(
    eye: npt.NDArray[np.float64],
    right: npt.NDArray[np.float64],
    up: npt.NDArray[np.float64],
    fwd: npt.NDArray[np.float64],
) -> Mat4:
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = right, up, -fwd
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def frustum(left: float, right: float, bottom: float, top: float, near: float, far: float) -> Mat4:
    """glFrustum with y flipped, so row 0 of the framebuffer is the image's top row."""
    m = np.zeros((4, 4))
    m[0, 0] = 2 * near / (right - left)
    m[0, 2] = (right + left) / (right - left)
    m[1, 1] = 2 * near / (top - bottom)
    m[1, 2] = (top + bottom) / (top - bottom)
    m[2, 2] = -(far + near) / (far - near)
    m[2, 3] = -2 * far * near / (far - near)
    m[3, 2] = -1.0
    m[1, :] *= -1.0
    return m


def turned(camera: Camera, yaw_deg: float, pitch_deg: float, roll_deg: float) -> Camera:
    """The camera's view turned by a view offset relative to it (yaw right, pitch up, roll
    right wing down, applied in that order in the camera's own axes, as CIGI View Control
    turns a view from its entity): a display channel's view of the shared camera."""
    right, up, fwd = camera.basis()
    body = np.stack([right, fwd, up], axis=1)  # camera axes (x right, y forward, z up) in ENU
    v_right, _v_up, v_fwd = camera_basis(yaw_deg, pitch_deg, roll_deg)
    f, r = body @ v_fwd, body @ v_right
    pitch = math.degrees(math.asin(max(-1.0, min(1.0, float(f[2])))))
    if abs(float(f[2])) > 0.999999:  # straight up or down: heading from the right axis
        heading = math.degrees(math.atan2(-float(r[1]), float(r[0])))
        roll = 0.0
    else:
        heading = math.degrees(math.atan2(float(f[0]), float(f[1])))
        h = math.radians(heading)
        level_right = np.array([math.cos(h), -math.sin(h), 0.0])
        level_up = np.cross(level_right, f)
        roll = math.degrees(math.atan2(-float(r @ level_up), float(r @ level_right)))
    return dataclasses.replace(
        camera, heading_deg=heading % 360.0, pitch_deg=max(-90.0, min(90.0, pitch)), roll_deg=roll
    )


def spheres_in_view(
    camera: Camera,
    centre_m: npt.NDArray[np.float64],
    radius_m: npt.NDArray[np.float64],
    offsets_m: npt.NDArray[np.float64] | tuple[npt.NDArray[np.float64], ...] | None = None,
    bounds_m: npt.NDArray[np.float64] | None = None,
) -> npt.NDArray[np.bool_]:
    """(N,) whether each sphere (centre, radius) reaches into the camera's view: not wholly
    behind the eye, nor wholly beyond one of the four sides of the view. Conservative: a
    sphere near a corner may pass though it shows nothing. `offsets_m`: (3, N) east, north
    and up of the centres less the eye, where the caller has them; `bounds_m`: the radii's
    `view_bounds` for this camera, where the caller keeps them."""
    if offsets_m is None:
        offsets_m = np.subtract(
            centre_m.T, np.asarray(camera.position_m, np.float64)[:, None], order="C"
        )
    rel = np.asarray(offsets_m, np.float64)
    if bounds_m is None:
        bounds_m = view_bounds(camera, radius_m)
    # Each sphere's centre against the five planes through the eye (the four sides and the
    # eye's own, facing back), positive outside, in one product: it is out beyond a plane its
    # radius does not reach back over.
    out: npt.NDArray[np.bool_] = np.all(view_planes(camera) @ rel < bounds_m, axis=0)
    return out


def view_planes(camera: Camera) -> npt.NDArray[np.float64]:
    """(5, 3), read-only: the outward normals, unnormalised, of the view's four sides
    (x - z tan < 0 and the like, x, y and z along the camera's right, up and forward) and of
    the plane through the eye facing back (-z). Kept, as `camera_basis` is, for the last few
    views."""
    c = camera
    return _view_planes(c.heading_deg, c.pitch_deg, c.roll_deg, c.tan_half_fov_x, c.tan_half_fov_y)


@functools.lru_cache(maxsize=16)
def _view_planes(
    heading_deg: float, pitch_deg: float, roll_deg: float, tx: float, ty: float
) -> npt.NDArray[np.float64]:
    right, up, fwd = camera_basis(heading_deg, pitch_deg, roll_deg)
    out = np.stack([right - tx * fwd, -right - tx * fwd, up - ty * fwd, -up - ty * fwd, -fwd])
    out.flags.writeable = False
    return out


def view_bounds(camera: Camera, radius_m: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """(5, N): how far beyond each of `view_planes` (in its units: the normals are not unit)
    a sphere of each radius still reaches into the view."""
    tx, ty = camera.tan_half_fov_x, camera.tan_half_fov_y
    side = np.array([math.sqrt(1.0 + tx * tx)] * 2 + [math.sqrt(1.0 + ty * ty)] * 2 + [1.0])
    out: npt.NDArray[np.float64] = side[:, None] * radius_m
    return out
