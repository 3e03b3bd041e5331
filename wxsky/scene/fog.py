"""Fog over the ground (issue 43 item 3, docs/fog.md): one field of extinction made from the
weather's `Fog`, which the renderer draws (`render/fog_pass.py` marches the view ray through
it, fed by `FogField.uniforms()`) and every answer reads (the control channel's `visibility`,
the eye's visibility in the stream, CIGI's conditions requests). Pure numpy.

The field is a sum of at most MAX_BANKS banks, each a Gaussian over the ground (or, with
radius 0, the same everywhere: a fog sheet) of extinction `ext_per_m` up to its top:

    fog(e, n, h) = max(0, sum_i ext_i * exp(-|p - c_i|^2 / r_i^2) * v_i(h)),
    v_i(h) = clamp((d_i - h) / (TOP_FADE * d_i), 0, 1)

with h the height over the ground (the observer's field, `Observer.alt_m`) and d_i the bank's
depth. How far one sees is Koschmieder's: 3.912 over the fog's extinction plus the air's
(3.912 / the weather's visibility), the meteorological optical range.

- A sheet (METAR FG) is one bank of radius 0 whose extinction makes its visibility with the
  air's: 3.912 / visibility - the air's (nothing more where the air alone already sees that
  little).
- Patchy fog (BCFG, PRFG) is PATCH_COUNT banks seeded by the sky's seed: one within
  NEAR_FIELD_M of the field (the report is of fog at the aerodrome), the rest one to a cell
  of a 3 x 3 grid of PATCH_CELL_M around it, its middle cell left out, each 300-650 m in
  radius; between them only the air.
- Runway visual range: each runway with an RVR (no runway database: a runway of
  RUNWAY_LENGTH_M on the field's middle along its designator's heading, true; L and R
  PARALLEL_OFFSET_M to the left and right of the landing direction) gets a bank of
  RVR_BANK_RADIUS_M on its touchdown zone (TOUCHDOWN_M past the threshold), the banks'
  extinctions solved together so that at every touchdown zone, RVR_EYE_M over the runway,
  the visibility is the reported range. A range longer than the fog leaves there is a
  negative bank, a clearing; the air's visibility is the most it can give.

RVR here is the meteorological optical range at the runway (what the fog and air let one
see), not Allard's law with the runway's lights and the background luminance an RVR system
reports with. The fog is where the weather puts it, not drifted by the wind.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.precip_eye import AtEye
from wxsky.scene.sky import KOSCHMIEDER
from wxsky.weather.metar_fog import BANK_VISIBILITY_M
from wxsky.weather.state import Fog, RunwayRvr, WeatherState

F64 = npt.NDArray[np.float64]
ArrayLike = float | npt.NDArray[np.floating]

MAX_BANKS = 16  # the shader's uniform arrays' length (render/shaders/fog.glsl)
TOP_FADE = 0.3  # the top's fade, as a share of a bank's depth
RVR_EYE_M = 2.5  # ICAO Doc 9328: RVR is assessed about 2.5 m over the runway
RUNWAY_LENGTH_M = 3000.0
TOUCHDOWN_M = 300.0  # the touchdown-zone sensor past the threshold
PARALLEL_OFFSET_M = 400.0
RVR_BANK_RADIUS_M = 600.0
RVR_MIN_DEPTH_M = 30.0  # an RVR bank stands at least this high, so that it reaches the eye
PATCH_COUNT = 9
PATCH_CELL_M = 2600.0
NEAR_FIELD_M = 400.0
PATCH_RADIUS_M = (300.0, 650.0)
NEAR_RADIUS_M = 600.0
MAX_RANGE_M = 20_000.0  # a sheet is marched this far; banks as far as they reach
SALT = 0xF06  # the fog's stream of the sky's seed, apart from the clouds'


@dataclass(frozen=True)
class Runway:
    """A runway as the fog places it: its touchdown zone (east, north of the field's middle),
    its landing direction (unit east, north) and its two ends."""

    designator: str
    touchdown_m: tuple[float, float]
    direction: tuple[float, float]
    threshold_m: tuple[float, float]
    end_m: tuple[float, float]

    def points_m(self, count: int) -> F64:
        """(count, 2) points evenly along the runway from threshold to end."""
        s = np.linspace(0.0, 1.0, count)[:, None]
        a, b = np.asarray(self.threshold_m), np.asarray(self.end_m)
        out: F64 = a + s * (b - a)
        return out


def runway(designator: str) -> Runway:
    """The runway `designator` (`14`, `32L`) as the fog places it (the module docstring)."""
    heading = math.radians(int(designator[:2]) * 10.0)
    d = (math.sin(heading), math.cos(heading))
    left = (-d[1], d[0])
    side = {"L": 1.0, "R": -1.0}.get(designator[2:], 0.0) * PARALLEL_OFFSET_M
    centre = (side * left[0], side * left[1])
    half = 0.5 * RUNWAY_LENGTH_M
    threshold = (centre[0] - half * d[0], centre[1] - half * d[1])
    end = (centre[0] + half * d[0], centre[1] + half * d[1])
    touchdown = (threshold[0] + TOUCHDOWN_M * d[0], threshold[1] + TOUCHDOWN_M * d[1])
    return Runway(designator, touchdown, d, threshold, end)


@dataclass(frozen=True, eq=False)
class FogField:
    """The fog's extinction everywhere (the module docstring): `banks` (MAX_BANKS, 4) rows of
    east, north, radius (0: everywhere), extinction per metre; `depth_m` (MAX_BANKS,) their
    tops over the ground; the first `count` hold; `ground_m` the ground MSL; `air_per_m` the
    air's own extinction (the weather's visibility), which the fog adds to. Float32 as the
    shader reads them, so that the answers are the picture's."""

    banks: npt.NDArray[np.float32]
    depth_m: npt.NDArray[np.float32]
    count: int
    ground_m: float
    air_per_m: float

    @property
    def top_m(self) -> float:
        """The highest bank's top over the ground."""
        return float(self.depth_m[: self.count].max()) if self.count else 0.0

    @property
    def reach_m(self) -> float:
        """How far from the field's middle the fog reaches (MAX_RANGE_M for a sheet)."""
        b = self.banks[: self.count].astype(np.float64)
        if not len(b) or (b[:, 2] <= 0.0).any():
            return MAX_RANGE_M
        return float((np.hypot(b[:, 0], b[:, 1]) + 3.0 * b[:, 2]).max())

    def extinction_per_m(
        self, east_m: ArrayLike, north_m: ArrayLike, height_agl_m: ArrayLike
    ) -> F64:
        """The fog's extinction (per metre) at these points, the air's not included: what
        the renderer draws there."""
        e, n, h = np.broadcast_arrays(
            np.asarray(east_m, np.float64),
            np.asarray(north_m, np.float64),
            np.asarray(height_agl_m, np.float64),
        )
        total = np.zeros(e.shape, np.float64)
        for i in range(self.count):
            be, bn, radius, ext = (float(v) for v in self.banks[i])
            depth = float(self.depth_m[i])
            vertical = np.clip((depth - h) / (TOP_FADE * depth), 0.0, 1.0)
            if radius > 0.0:
                d2 = (e - be) ** 2 + (n - bn) ** 2
                total += ext * np.exp(-d2 / (radius * radius)) * vertical
            else:
                total += ext * vertical
        out: F64 = np.maximum(total, 0.0)
        return out

    def visibility_m(self, east_m: ArrayLike, north_m: ArrayLike, height_agl_m: ArrayLike) -> F64:
        """How far one sees at these points: Koschmieder's 3.912 over the fog's extinction
        and the air's."""
        ext = self.extinction_per_m(east_m, north_m, height_agl_m) + self.air_per_m
        out: F64 = KOSCHMIEDER / ext
        return out

    def rvr_m(self, east_m: ArrayLike, north_m: ArrayLike) -> F64:
        """The runway visual range at these points: the visibility RVR_EYE_M over the ground."""
        return self.visibility_m(east_m, north_m, RVR_EYE_M)

    def runway_rvr_m(self, designator: str) -> float:
        """The RVR at a runway's touchdown zone."""
        e, n = runway(designator).touchdown_m
        return float(self.rvr_m(e, n))

    def optical_depth(self, eye_m: tuple[float, float, float], rays: F64, steps: int = 40) -> F64:
        """(N,) the fog's optical depth along N unit rays (N, 3) from the eye (ENU, MSL): the
        march `fog.glsl` makes, step for step, for tests and pictures in numpy."""
        rays = np.asarray(rays, np.float64).reshape(-1, 3)
        h0 = eye_m[2] - self.ground_m
        top = self.top_m
        dz = rays[:, 2]
        t0 = np.zeros(len(rays))
        t1 = np.full(len(rays), MAX_RANGE_M)
        down = dz < 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = np.where(down, np.minimum(t1, max(h0, 0.0) / -dz), t1)
            if h0 > top:
                t0 = np.where(down, (h0 - top) / -dz, np.inf)
            else:
                t1 = np.where(dz > 0.0, np.minimum(t1, (top - h0) / dz), t1)
            flat = np.maximum(np.hypot(rays[:, 0], rays[:, 1]), 1e-4)
            t1 = np.minimum(t1, (math.hypot(eye_m[0], eye_m[1]) + self.reach_m) / flat)
        span = np.where(t1 > t0, t1 - t0, 0.0)
        tau = np.zeros(len(rays))
        for k in range(steps):
            s = (k + 0.5) / steps
            t = np.where(span > 0.0, t0 + span * s * s, 0.0)
            dt = span * 2.0 * s / steps
            p = np.asarray(eye_m)[None, :] + rays * t[:, None]
            tau += self.extinction_per_m(p[:, 0], p[:, 1], p[:, 2] - self.ground_m) * dt
        return tau

    def uniforms(self) -> dict[str, object]:
        """What `render/shaders/fog.glsl` reads of the field, its arrays as the bytes written
        to them (the eye and the view are the frame's)."""
        return {
            "u_fog_banks": self.banks.tobytes(),
            "u_fog_depth_m": self.depth_m.tobytes(),
            "u_fog_count": self.count,
            "u_fog_top_m": self.top_m,
            "u_fog_reach_m": self.reach_m,
        }


def fog_field(state: WeatherState) -> FogField | None:
    """The weather's fog as a field, None when it has none (the same field for the same fog,
    ground, air and seed: made once)."""
    if state.fog is None:
        return None
    field = _field(state.fog, state.observer.alt_m, state.visibility_m, state.seed)
    return field if field.count else None


@functools.lru_cache(maxsize=8)
def _field(fog: Fog, ground_m: float, visibility_m: float, seed: int) -> FogField:
    air = KOSCHMIEDER / max(visibility_m, 1.0)
    rows: list[tuple[float, float, float, float, float]] = []  # east, north, radius, ext, depth
    # Banks take BANK_VISIBILITY_M where no visibility is given; a sheet needs one.
    inside_m = BANK_VISIBILITY_M if fog.patchy and fog.visibility_m is None else fog.visibility_m
    if inside_m is not None:
        ext = max(KOSCHMIEDER / inside_m - air, 0.0)
        if fog.patchy:
            rows += [(e, n, r, ext, fog.depth_m) for e, n, r in _patches(seed)]
        elif ext > 0.0:
            rows.append((0.0, 0.0, 0.0, ext, fog.depth_m))
    rows += _rvr_banks(fog.rvr, rows, max(fog.depth_m, RVR_MIN_DEPTH_M), air)
    return _field_of(rows, ground_m, air)


def _patches(seed: int) -> list[tuple[float, float, float]]:
    """(east, north, radius) of patchy fog's banks, from the sky's seed."""
    rng = np.random.default_rng((seed, SALT))
    out = []
    angle, dist = rng.uniform(0.0, 2.0 * math.pi), NEAR_FIELD_M * math.sqrt(rng.uniform())
    out.append((dist * math.sin(angle), dist * math.cos(angle), NEAR_RADIUS_M))
    for gx in (-1, 0, 1):
        for gy in (-1, 0, 1):
            if gx == gy == 0:
                continue
            jitter = rng.uniform(-0.3, 0.3, 2) * PATCH_CELL_M
            r = rng.uniform(*PATCH_RADIUS_M)
            out.append((gx * PATCH_CELL_M + jitter[0], gy * PATCH_CELL_M + jitter[1], r))
    return out[:PATCH_COUNT]


def _rvr_banks(
    rvr: tuple[RunwayRvr, ...],
    rows: list[tuple[float, float, float, float, float]],
    depth_m: float,
    air_per_m: float,
) -> list[tuple[float, float, float, float, float]]:
    """A bank on each RVR runway's touchdown zone, their extinctions solved together (least
    squares: two runways sharing a touchdown zone ask for one figure there) so that, with the
    fog already there, each zone sees its range."""
    if not rvr:
        return []
    zones = [runway(r.runway).touchdown_m for r in rvr]
    pts = np.asarray(zones, np.float64)
    partial = _field_of(rows)
    have = partial.extinction_per_m(pts[:, 0], pts[:, 1], RVR_EYE_M)
    want = np.array([KOSCHMIEDER / r.rvr_m - air_per_m for r in rvr]) - have
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(axis=2)
    vertical = min(max((depth_m - RVR_EYE_M) / (TOP_FADE * depth_m), 0.0), 1.0)
    gain = np.exp(-d2 / RVR_BANK_RADIUS_M**2) * vertical
    ext = np.linalg.lstsq(gain, want, rcond=None)[0]
    return [
        (z[0], z[1], RVR_BANK_RADIUS_M, float(x), depth_m) for z, x in zip(zones, ext, strict=True)
    ]


def _field_of(
    rows: list[tuple[float, float, float, float, float]],
    ground_m: float = 0.0,
    air_per_m: float = 0.0,
) -> FogField:
    """A field of these banks (east, north, radius, extinction, depth), the first MAX_BANKS."""
    banks = np.zeros((MAX_BANKS, 4), np.float32)
    depth = np.ones(MAX_BANKS, np.float32)
    for i, (e, n, r, x, d) in enumerate(rows[:MAX_BANKS]):
        banks[i] = (e, n, r, x)
        depth[i] = d
    banks.setflags(write=False)
    depth.setflags(write=False)
    return FogField(banks, depth, min(len(rows), MAX_BANKS), ground_m, air_per_m)


def fogged_at_eye(at_eye: AtEye, fog: FogField, eye_m: tuple[float, float, float]) -> AtEye:
    """What falls at the eye with the fog there added to how far one sees: the fog's
    extinction at the eye added to what the air and the precipitation leave."""
    ext = float(fog.extinction_per_m(eye_m[0], eye_m[1], eye_m[2] - fog.ground_m))
    if ext <= 0.0:
        return at_eye
    seen = KOSCHMIEDER / (KOSCHMIEDER / max(at_eye.visibility_m, 1.0) + ext)
    return dataclasses.replace(at_eye, visibility_m=seen)
