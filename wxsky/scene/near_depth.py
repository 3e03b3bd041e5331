"""How near the nearest thing in a frame's `near` layer is to the eye.

The near layer is one picture without depth. A host that draws its own terrain and models
(an OpenSceneGraph application, FlightGear) composites it at one depth: the distance below
which the layer holds nothing. Geometry nearer than that stays in front of the clouds, and
nothing in the layer is drawn behind geometry that is really behind it (docs/protocol.md §4
`near_distance_m`). Each part the layer holds gives a lower bound on its nearest point:

- a sprite: its centre's distance less half its diagonal;
- a tower: its box's centre distance less half the box's diagonal;
- a rain curtain: the horizontal distance to its axis less three e-folding radii (its
  Gaussian is 1 % of the axis' there); drops at the eye, a rain veil under a nimbostratus
  the eye is under, or the in-cloud veil: 0;
- ground fog: 0 inside a bank, else the gap to the nearest bank's top or edge.
"""

from __future__ import annotations

import math

import numpy as np

from wxsky.scene.layout import FrameScene

# A Gaussian curtain is 1 % of its axis' extinction at 3 e-folding radii.
CURTAIN_REACH = 3.0


def near_distance_m(frame: FrameScene) -> float | None:
    """The distance from the eye inside which the frame's near layer draws nothing; None
    when it draws nothing at all."""
    eye = np.asarray(frame.camera.position_m, dtype=np.float64)
    best = math.inf
    if frame.in_cloud.inside or frame.veil_rgba[3] > 0.0:
        return 0.0
    for draw in (frame.near, frame.near_front):
        if draw is None or len(draw) == 0:
            continue
        batch = draw.sprites
        reach = np.linalg.norm(batch.centre_m - eye[None, :], axis=1)
        reach = reach - np.asarray(batch.size_m, dtype=np.float64) * (math.sqrt(2.0) / 2.0)
        best = min(best, float(reach.min()))
    for tower in frame.towers:
        spec = tower.spec
        half = math.hypot(spec.width_m, spec.height_m) / 2.0
        best = min(best, tower.distance_m - half)
    if frame.precip is not None:
        best = min(best, _precip_m(frame, eye))
    if frame.fog is not None and frame.fog.count > 0:
        best = min(best, _fog_m(frame, eye))
    if best == math.inf:
        return None
    return max(0.0, best)


def _precip_m(frame: FrameScene, eye: np.ndarray) -> float:
    precip = frame.precip
    assert precip is not None
    if precip.drops is not None:
        return 0.0
    if precip.veil_per_m > 0.0 and eye[2] <= precip.veil_top_m:
        return 0.0
    best = math.inf
    if precip.veil_per_m > 0.0:
        best = eye[2] - precip.veil_top_m  # looking down into the veil from above it
    for c in precip.curtains:
        across = math.hypot(c.axis_m[0] - eye[0], c.axis_m[1] - eye[1])
        best = min(best, across - CURTAIN_REACH * c.radius_m)
    return float(best)


def _fog_m(frame: FrameScene, eye: np.ndarray) -> float:
    fog = frame.fog
    assert fog is not None
    best = math.inf
    for i in range(fog.count):
        east, north, radius, _ext = (float(v) for v in fog.banks[i])
        top = fog.ground_m + float(fog.depth_m[i])
        above = max(0.0, float(eye[2]) - top)
        across = (
            0.0 if radius <= 0.0 else max(0.0, math.hypot(east - eye[0], north - eye[1]) - radius)
        )
        best = min(best, math.hypot(above, across))
    return best
