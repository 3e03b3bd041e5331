"""Wang's octagonal impostor ring: 8 views of 45° around a fixed centre.

Each impostor is a vertical quad at the ring radius facing the centre, rendered through an
off-axis frustum whose apex is the ring centre and whose window is the quad itself, so the
quad shows exactly what lies behind it as seen from the centre. The window is fitted
vertically to the clouds it holds (Wang translates the impostor up or down to follow them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

from wxsky.scene.camera import FAR_M, NEAR_M, Mat4, frustum, view_from_basis
from wxsky.scene.clouds import SpriteBatch

RING_SIZE = 8
HALF_ANGLE_RAD = math.pi / RING_SIZE  # 22.5°
# Regenerate after the camera leaves this share of the radius (Wang: 15 % and 2 %).
MOVE_HORIZONTAL_FRAC = 0.15
MOVE_VERTICAL_FRAC = 0.02
# Clouds more than 10,000 ft above or below the ring's centre are not put into impostors (Wang):
# seen that steeply their impostors' parallax shows as soon as the camera moves.
IMPOSTOR_VERTICAL_REACH_M = 3048.0


# What drawing an impostor's sprite costs, in units of one sprite's vertex work: the sprite
# itself, plus this much per whole window it covers (its fill). Measured on llvmpipe, where
# spreading a rebuild over frames matters: about 1 µs a sprite, and 0.5 ms to fill the window
# once through the sprite shader.
WINDOW_FILL_COST = 500.0


def moved_reason(
    centre_m: tuple[float, float, float],
    eye_m: tuple[float, float, float],
    radius_m: float,
    horizontal_frac: float = MOVE_HORIZONTAL_FRAC,
    vertical_frac: float = MOVE_VERTICAL_FRAC,
) -> str | None:
    """ "moved_horizontal" or "moved_vertical" once the eye has left the share of the radius
    around a ring's centre that its impostors serve (Wang: 15 % and 2 %), else None."""
    dx, dy = eye_m[0] - centre_m[0], eye_m[1] - centre_m[1]
    if math.hypot(dx, dy) > horizontal_frac * radius_m:
        return "moved_horizontal"
    if abs(eye_m[2] - centre_m[2]) > vertical_frac * radius_m:
        return "moved_vertical"
    return None


def in_impostors(base_m: float, top_m: float, centre_z_m: float) -> bool:
    """Whether a layer from base_m to top_m is close enough in altitude to the ring's centre
    to go into impostors; if not, its far clouds are drawn directly as near sprites."""
    reach = IMPOSTOR_VERTICAL_REACH_M
    return base_m - reach <= centre_z_m <= top_m + reach


def ring_target_name(index: int, ring_set: int = 0) -> str:
    """The layer holding impostor `index` of texture set 0 (`ring_i`, what snapshots and a
    settled daemon read) or 1 (`ring_b_i`)."""
    if ring_set not in (0, 1):
        raise ValueError(f"ring set must be 0 or 1, got {ring_set}")
    return f"ring_{index}" if ring_set == 0 else f"ring_b_{index}"


@dataclass(frozen=True)
class RingGeometry:
    centre_m: tuple[float, float, float]
    radius_m: float
    bottom_m: tuple[float, ...]  # (8,) window bottom relative to the centre's altitude
    top_m: tuple[float, ...]  # (8,) window top relative to the centre's altitude

    def heading_deg(self, i: int) -> float:
        return i * 360.0 / RING_SIZE

    def axes(self, i: int) -> tuple[npt.NDArray[np.float64], ...]:
        """(right, up, forward) of impostor i."""
        h = math.radians(self.heading_deg(i))
        fwd = np.array([math.sin(h), math.cos(h), 0.0])
        right = np.array([math.cos(h), -math.sin(h), 0.0])
        return right, np.array([0.0, 0.0, 1.0]), fwd

    @property
    def half_width_m(self) -> float:
        return self.radius_m * math.tan(HALF_ANGLE_RAD)

    def corners_m(self) -> npt.NDArray[np.float64]:
        """(8, 4, 3) world corners of each quad: top-left, top-right, bottom-right, bottom-left
        as seen from the centre (texture row 0 is the quad's top edge). Read-only: made once
        per ring, and every published frame carries them."""
        return self._corners_m

    @cached_property
    def _corners_m(self) -> npt.NDArray[np.float64]:
        out = np.zeros((RING_SIZE, 4, 3))
        c = np.asarray(self.centre_m)
        w = self.half_width_m
        for i in range(RING_SIZE):
            right, up, fwd = self.axes(i)
            mid = c + fwd * self.radius_m
            top, bottom = self.top_m[i], self.bottom_m[i]
            out[i] = [
                mid - right * w + up * top,
                mid + right * w + up * top,
                mid + right * w + up * bottom,
                mid - right * w + up * bottom,
            ]
        out.setflags(write=False)
        return out

    def view_matrix(self, i: int) -> Mat4:
        right, up, fwd = self.axes(i)
        return view_from_basis(np.asarray(self.centre_m), right, up, fwd)

    def projection_matrix(self, i: int) -> Mat4:
        k = NEAR_M / self.radius_m
        w = self.half_width_m
        return frustum(-w * k, w * k, self.bottom_m[i] * k, self.top_m[i] * k, NEAR_M, FAR_M)

    def needs_regeneration(self, eye_m: tuple[float, float, float]) -> bool:
        return moved_reason(self.centre_m, eye_m, self.radius_m) is not None

    def to_dict(self) -> dict[str, object]:
        return {
            "centre_m": list(self.centre_m),
            "radius_m": self.radius_m,
            "quads_m": self.corners_m().tolist(),
        }


def bin_far_sprites(
    far: SpriteBatch, centre_m: tuple[float, float, float], radius_m: float
) -> tuple[RingGeometry, tuple[SpriteBatch, ...]]:
    """Assign far sprites to the impostors whose 45° wedge they touch, and fit each window."""
    geometry, index = bin_indices(far, centre_m, radius_m)
    return geometry, tuple(far.take(idx) for idx in index)


def bin_indices(
    far: SpriteBatch, centre_m: tuple[float, float, float], radius_m: float
) -> tuple[RingGeometry, tuple[npt.NDArray[np.intp], ...]]:
    """`bin_far_sprites` as (8,) ascending index arrays into `far`, so a sorted batch's bins
    keep its order."""
    c = np.asarray(centre_m)
    rel = far.centre_m - c
    azimuth = np.arctan2(rel[:, 0], rel[:, 1])  # from north, clockwise
    dist_h = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), 1.0)
    half_extent = np.arctan(0.75 * far.size_m / dist_h)  # angular half-size, rotation included
    bins: list[npt.NDArray[np.intp]] = []
    bottoms: list[float] = []
    tops: list[float] = []
    default_half = radius_m * math.tan(HALF_ANGLE_RAD)
    for i in range(RING_SIZE):
        axis_az = i * 2.0 * HALF_ANGLE_RAD
        delta = np.abs((azimuth - axis_az + math.pi) % (2.0 * math.pi) - math.pi)
        idx = np.nonzero(delta <= HALF_ANGLE_RAD + half_extent)[0]
        bins.append(idx)
        if len(idx) == 0:
            bottoms.append(-default_half)
            tops.append(default_half)
            continue
        along = np.maximum(rel[idx, 0] * math.sin(axis_az) + rel[idx, 1] * math.cos(axis_az), 1.0)
        scale = radius_m / along
        reach = 0.75 * far.size_m[idx]
        bottoms.append(float(np.min((rel[idx, 2] - reach) * scale)))
        tops.append(float(np.max((rel[idx, 2] + reach) * scale)))
    geometry = RingGeometry(
        centre_m=(float(c[0]), float(c[1]), float(c[2])),
        radius_m=radius_m,
        bottom_m=tuple(bottoms),
        top_m=tuple(tops),
    )
    return geometry, tuple(bins)


def impostor_costs(
    geometry: RingGeometry, index: int, sprites: SpriteBatch
) -> npt.NDArray[np.float64]:
    """(N,) what each sprite of impostor `index` costs to draw, in sprite units (see
    WINDOW_FILL_COST): 1 plus the share of the window its square covers, seen from the centre
    and at most the whole window. Enough to cut an impostor into slices of about equal cost."""
    if len(sprites) == 0:
        return np.zeros(0)
    _right, _up, fwd = geometry.axes(index)
    rel = sprites.centre_m - np.asarray(geometry.centre_m)
    along = np.maximum(rel @ fwd, 1.0)
    side_m = sprites.size_m * (geometry.radius_m / along)
    window_m2 = (
        2.0 * geometry.half_width_m * max(geometry.top_m[index] - geometry.bottom_m[index], 1.0)
    )
    share = np.minimum(side_m.astype(np.float64) ** 2 / window_m2, 1.0)
    out: npt.NDArray[np.float64] = 1.0 + WINDOW_FILL_COST * share
    return out


class ImpostorCuts:
    """Cuts impostor `index`'s back-to-front sprite list into consecutive slices of about a
    given cost (`impostor_costs`), for a rebuild drawn over several frames."""

    def __init__(self, geometry: RingGeometry, index: int, sprites: SpriteBatch) -> None:
        self._cum = np.cumsum(impostor_costs(geometry, index, sprites))

    def __len__(self) -> int:
        return len(self._cum)

    @property
    def total(self) -> float:
        return float(self._cum[-1]) if len(self._cum) else 0.0

    def cut(self, start: int, units: float) -> tuple[int, float]:
        """(stop, cost) of the slice from sprite `start` holding as many sprites as fit in
        `units`, and at least one (none only when no sprite is left)."""
        n = len(self._cum)
        done = float(self._cum[start - 1]) if start > 0 else 0.0
        stop = int(np.searchsorted(self._cum, done + units, side="right"))
        stop = min(n, max(stop, start + 1))
        cost = (float(self._cum[stop - 1]) if stop > 0 else 0.0) - done
        return stop, cost
