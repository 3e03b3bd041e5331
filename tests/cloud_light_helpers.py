"""Helpers for the cloud-lighting picture checks (tests/test_cloud_backlit.py): where the sun
is at a preset's site, and luminance measured on a rendered picture.

Pictures are measured through `picture_luminance`, the one place that turns what a snapshot
wrote into relative linear luminance: today the 8-bit sRGB PNG, decoded to linear; when
scene-linear output lands, only this function changes.
"""

from __future__ import annotations

from datetime import datetime, timedelta

import numpy as np
import numpy.typing as npt

from wxsky.scene.ephemeris import sun_position
from wxsky.scene.exposure import display_inverse

F64 = npt.NDArray[np.float64]


def time_for_sun_elevation(
    day_utc: datetime, lat_deg: float, lon_deg: float, elevation_deg: float, evening: bool = True
) -> tuple[datetime, float]:
    """The time on day_utc's date when the sun, setting (evening) or rising, stands at
    elevation_deg at this site, by bisection between local noon and local midnight; and the
    sun's azimuth then (degrees, clockwise from north)."""
    midnight = datetime(day_utc.year, day_utc.month, day_utc.day, tzinfo=day_utc.tzinfo)
    noon = midnight + timedelta(hours=12.0 - lon_deg / 15.0)
    lo, hi = (noon, noon + timedelta(hours=12)) if evening else (noon - timedelta(hours=12), noon)

    def above(t: datetime) -> bool:
        return sun_position(t, lat_deg, lon_deg).elevation_deg > elevation_deg

    # The sun is above the target at noon and below it at midnight.
    for _ in range(40):
        mid = lo + (hi - lo) / 2
        if above(mid) == evening:
            lo = mid
        else:
            hi = mid
    t = lo + (hi - lo) / 2
    return t, sun_position(t, lat_deg, lon_deg).azimuth_deg


def noon_time(day_utc: datetime, lat_deg: float, lon_deg: float) -> tuple[datetime, float, float]:
    """Local solar noon on day_utc's date (within a minute): time, sun elevation and azimuth."""
    midnight = datetime(day_utc.year, day_utc.month, day_utc.day, tzinfo=day_utc.tzinfo)
    guess = midnight + timedelta(hours=12.0 - lon_deg / 15.0)
    times = [guess + timedelta(minutes=m) for m in range(-40, 41)]
    best = max(times, key=lambda t: sun_position(t, lat_deg, lon_deg).elevation_deg)
    sun = sun_position(best, lat_deg, lon_deg)
    return best, sun.elevation_deg, sun.azimuth_deg


def srgb_to_linear(srgb8: npt.NDArray[np.uint8]) -> F64:
    """8-bit sRGB to linear 0..1 (IEC 61966-2-1)."""
    c = np.asarray(srgb8, np.float64) / 255.0
    out: F64 = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return out


def picture_luminance(rgba8: npt.NDArray[np.uint8]) -> F64:
    """(H, W) relative scene-linear luminance (Rec. 709 weights) of a rendered picture: its
    8-bit values through the inverse of the one tone map every pass shares under the physical
    sky (`exposure.display_inverse`: sRGB decode, then ACES's inverse), so a ratio of two
    regions is the ratio of their radiance, not of what the tone curve made of it. Exact up
    to the 8-bit steps and to the layers being composited after the tone map (the sun's disc
    and anything else past the curve's white read as that white)."""
    lin = display_inverse(rgba8[..., :3].astype(np.float64) / 255.0, 1.0)
    out: F64 = lin @ np.array([0.2126, 0.7152, 0.0722])
    return out


LUMA = np.array([0.2126, 0.7152, 0.0722])


def distance_inside(mask: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:
    """(H, W) for each pixel of mask, how many 4-neighbour erosions it survives plus one (1 on
    the mask's edge), 0 outside: its distance from the edge in pixels (city-block)."""
    out = np.zeros(mask.shape, np.int64)
    cur = mask.copy()
    step = 0
    while cur.any():
        step += 1
        out[cur] = step
        inner = cur.copy()
        inner[1:, :] &= cur[:-1, :]
        inner[:-1, :] &= cur[1:, :]
        inner[:, 1:] &= cur[:, :-1]
        inner[:, :-1] &= cur[:, 1:]
        # The picture's border is not the cloud's edge: a cloud cut by it keeps its depth.
        cur = inner
    return out


def components(mask: npt.NDArray[np.bool_]) -> list[npt.NDArray[np.intp]]:
    """The 4-connected components of mask, each as flat pixel indices, largest first."""
    h, w = mask.shape
    flat = mask.ravel()
    seen = np.zeros(flat.shape, np.bool_)
    found = []
    for start in np.flatnonzero(flat):
        if seen[start]:
            continue
        seen[start] = True
        stack, pixels = [int(start)], []
        while stack:
            p = stack.pop()
            pixels.append(p)
            y, x = divmod(p, w)
            for q, ok in ((p - w, y > 0), (p + w, y < h - 1), (p - 1, x > 0), (p + 1, x < w - 1)):
                if ok and flat[q] and not seen[q]:
                    seen[q] = True
                    stack.append(q)
        found.append(np.array(pixels, np.intp))
    found.sort(key=len, reverse=True)
    return found


def grow(mask: npt.NDArray[np.bool_], px: int) -> npt.NDArray[np.bool_]:
    """mask dilated by px pixels (4-neighbour steps)."""
    out = mask.copy()
    for _ in range(px):
        cur = out.copy()
        out[1:, :] |= cur[:-1, :]
        out[:-1, :] |= cur[1:, :]
        out[:, 1:] |= cur[:, :-1]
        out[:, :-1] |= cur[:, 1:]
    return out


def cloud_regions(
    luminance: F64,
    alpha: F64,
    within: npt.NDArray[np.bool_] | None = None,
    min_radius_px: int = 4,
    whole: bool = True,
) -> list[dict[str, float]]:
    """Every cloud (alpha over 1/2, 4-connected) in a picture at least min_radius_px deep,
    largest first: its radius (deepest pixel's distance from its edge), the mean luminance
    of its core (more than 30 % of the radius from its edge), of its rim (the outer 10 %, at
    least its edge pixels) and of that rim's brightest tenth, of its top third and bottom
    tenth (by rows), of its brightest half, and of the clear sky beside it (alpha under 0.05
    within a quarter of its radius outside it). With `within` (H, W), only clouds with 200
    pixels or more there, measured there only. `whole`: only clouds wholly in the picture
    (not touching its border)."""
    h, w = alpha.shape
    cloud = alpha > 0.5
    clear = alpha < 0.05
    out = []
    for pixels in components(cloud):
        ys, xs = np.divmod(pixels, w)
        edge = ys.min() == 0 or xs.min() == 0 or ys.max() == h - 1 or xs.max() == w - 1
        if whole and edge:
            continue
        if within is not None and np.count_nonzero(within.ravel()[pixels]) < 200:
            continue
        mask = np.zeros((h, w), np.bool_)
        mask.ravel()[pixels] = True
        depth = distance_inside(mask)
        radius = int(depth.max())
        if radius < min_radius_px:
            continue
        lum = luminance
        core = mask & (depth > 0.3 * radius)
        rim = mask & (depth <= max(1.0, 0.1 * radius))
        beside = grow(mask, max(2, radius // 4)) & ~mask & clear
        if within is not None:
            core, rim, beside = core & within, rim & within, beside & within
        if not (beside.any() and core.any() and rim.any()):
            continue
        top, bottom = ys.min(), ys.max()
        rows = np.arange(h)[:, None]
        tall = bottom - top + 1
        top_third = mask & (rows < top + tall / 3.0)
        bottom_tenth = mask & (rows > bottom - tall / 10.0)
        vals = np.sort(lum[mask])
        rim_vals = np.sort(lum[rim])
        out.append(
            {
                "radius_px": float(radius),
                "pixels": float(len(pixels)),
                "core": float(lum[core].mean()),
                "rim": float(lum[rim].mean()),
                "rim_bright": float(rim_vals[int(0.9 * len(rim_vals)) :].mean()),
                "top_third": float(lum[top_third].mean()),
                "bottom_tenth": float(lum[bottom_tenth].mean()),
                "bright_half": float(vals[len(vals) // 2 :].mean()),
                "sky": float(lum[beside].mean()),
                "row_top": float(top),
                "row_bottom": float(bottom),
            }
        )
    return out
