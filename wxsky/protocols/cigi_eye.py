"""The eye of the view wxsky renders for a CIGI host: the ownship's place and attitude with
the view's offset (in the ownship's body axes: x forward, y right, z down) and its angles
relative to the ownship, composed as rotations, not added. Pure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wxsky.protocols.cigi_session import HostState
from wxsky.weather.geo import geodetic_from_enu


@dataclass(frozen=True)
class Eye:
    """Where the rendered view looks from: the ownship with the view's offset and angles."""

    lat_deg: float
    lon_deg: float
    alt_m: float
    heading_deg: float
    pitch_deg: float
    roll_deg: float
    fov_deg: float | None
    ownship: tuple[float, float, float]  # lat_deg, lon_deg, alt_m of the ownship itself
    offset_m: float  # how far the eye is from the ownship (0 for a pilot's eye point)


def eye(host: HostState) -> Eye | None:
    """The rendered view's eye, or None before the host has placed the ownship."""
    own = host.ownship
    if own is None:
        return None
    body = _rotation(own.yaw_deg, own.pitch_deg, own.roll_deg)
    v = host.view
    # Body axes x forward, y right, z down; the local frame east, north, up.
    fwd, right, down = (v.x_m, v.y_m, v.z_m)
    east = body[0][0] * fwd + body[0][1] * right + body[0][2] * down
    north = body[1][0] * fwd + body[1][1] * right + body[1][2] * down
    up = body[2][0] * fwd + body[2][1] * right + body[2][2] * down
    lat, lon = geodetic_from_enu(own.lat_deg, own.lon_deg, east, north)
    view = _rotation(v.yaw_deg, v.pitch_deg, v.roll_deg)
    # The view's axes in the body frame (x forward = north, y right = east, z down = -up at
    # zero angles), then turned with the body.
    in_body = (view[1], view[0], (-view[2][0], -view[2][1], -view[2][2]))
    combined = _matmul(body, in_body)
    heading, pitch, roll = _angles(combined)
    return Eye(
        lat,
        lon,
        own.alt_m + up,
        heading,
        pitch,
        roll,
        host.fov_deg,
        (own.lat_deg, own.lon_deg, own.alt_m),
        math.sqrt(fwd * fwd + right * right + down * down),
    )


Mat3 = tuple[tuple[float, float, float], ...]


def _rotation(yaw_deg: float, pitch_deg: float, roll_deg: float) -> Mat3:
    """Columns: the body's forward, right and down axes in (east, north, up)."""
    y, p, r = (math.radians(a) for a in (yaw_deg, pitch_deg, roll_deg))
    cy, sy, cp, sp, cr, sr = (
        math.cos(y),
        math.sin(y),
        math.cos(p),
        math.sin(p),
        math.cos(r),
        math.sin(r),
    )
    fwd = (sy * cp, cy * cp, sp)
    # Right and down of a level body, then rolled about forward.
    right0 = (cy, -sy, 0.0)
    down0 = (sy * sp, cy * sp, -cp)
    # Roll, right wing down: the right axis turns toward down.
    right = tuple(cr * a + sr * b for a, b in zip(right0, down0, strict=True))
    down = tuple(cr * b - sr * a for a, b in zip(right0, down0, strict=True))
    return tuple((fwd[i], right[i], down[i]) for i in range(3))


def _matmul(a: Mat3, b: Mat3) -> Mat3:
    def cell(i: int, j: int) -> float:
        return a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j]

    return tuple((cell(i, 0), cell(i, 1), cell(i, 2)) for i in range(3))


def _angles(m: Mat3) -> tuple[float, float, float]:
    """Heading (0..360), pitch and roll of a body whose axes are the columns of m."""
    fwd = (m[0][0], m[1][0], m[2][0])
    right = (m[0][1], m[1][1], m[2][1])
    pitch = math.degrees(math.asin(max(-1.0, min(1.0, fwd[2]))))
    if abs(fwd[2]) > 0.999999:  # straight up or down: heading from the right axis
        heading = _wrapped(math.degrees(math.atan2(-right[1], right[0])))
        return heading, pitch, 0.0
    heading = _wrapped(math.degrees(math.atan2(fwd[0], fwd[1])))
    # Roll: how far the right axis has dipped below the horizontal.
    level_right = (math.cos(math.radians(heading)), -math.sin(math.radians(heading)), 0.0)
    up_axis = _cross(level_right, fwd)
    roll = math.degrees(math.atan2(-_dot(right, up_axis), _dot(right, level_right)))
    return heading, pitch, roll


def _wrapped(deg: float) -> float:
    """deg in [0, 360): a tiny negative angle taken modulo 360 rounds to 360 itself (found by
    the fuzzer), which is north again."""
    out = deg % 360.0
    return 0.0 if out >= 360.0 else out


def _cross(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    return sum(x * y for x, y in zip(a, b, strict=True))
