"""The CIE standard general sky (CIE S 011/E:2003, ISO 15469) as a reference for the physical
atmosphere (`wxsky.scene.atmosphere`): a sky's luminance relative to its zenith, and how far a
model's sky is from it over the visible hemisphere. Used by tests/test_atmosphere.py and
tools/bench/cie_sky.py (docs/atmosphere.md).

    L(Z, chi) / L_zenith = f(chi) phi(Z) / (f(Z_s) phi(0))
    phi(Z) = 1 + a exp(b / cos Z)            (gradation; phi(0) at the zenith)
    f(chi) = 1 + c (exp(d chi) - exp(d pi/2)) + e cos^2 chi     (indicatrix)

Z is a direction's zenith angle, chi its angle from the sun, Z_s the sun's zenith angle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class CieSkyType:
    name: str
    a: float
    b: float
    c: float
    d: float
    e: float


# Type 12: "CIE standard clear sky, low luminance turbidity".
CLEAR_LOW_TURBIDITY = CieSkyType("12 clear, low turbidity", -1.0, -0.32, 10.0, -3.0, 0.45)
LUMA = np.array([0.2126, 0.7152, 0.0722])


def relative_luminance(sky: CieSkyType, directions: F64, sun_direction: F64) -> F64:
    """L / L_zenith in unit directions (..., 3) (z up) with the sun in sun_direction."""
    d = np.asarray(directions, np.float64)
    s = np.asarray(sun_direction, np.float64)
    cos_z = np.clip(d[..., 2], 1e-6, 1.0)
    chi = np.arccos(np.clip(d @ s, -1.0, 1.0))
    zs = math.acos(min(max(float(s[2]), -1.0), 1.0))

    def phi(cos_zenith: F64 | float) -> F64:
        out: F64 = 1.0 + sky.a * np.exp(sky.b / np.asarray(cos_zenith, np.float64))
        return out

    def f(angle: F64 | float) -> F64:
        a = np.asarray(angle, np.float64)
        out: F64 = (
            1.0
            + sky.c * (np.exp(sky.d * a) - math.exp(sky.d * math.pi / 2.0))
            + sky.e * np.cos(a) ** 2
        )
        return out

    out: F64 = f(chi) * phi(cos_z) / (f(zs) * phi(1.0))
    return out


def hemisphere_directions(count_az: int = 36, elevations_deg: tuple[float, ...] = ()) -> F64:
    """Directions over the whole visible hemisphere at elevations >= 5 deg: `count_az`
    azimuths (the sun's half and the opposite half alike) at each elevation, (N, 3).
    Default elevations 5, 10, 15, 20, 30, 40, 50, 60, 70, 80 deg (360 directions)."""
    els = elevations_deg or (5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0)
    out = []
    for el in els:
        e = math.radians(el)
        for k in range(count_az):
            az = 2.0 * math.pi * (k + 0.5) / count_az
            out.append((math.cos(e) * math.sin(az), math.cos(e) * math.cos(az), math.sin(e)))
    return np.asarray(out, np.float64)


@dataclass(frozen=True)
class CieComparison:
    """A model's relative luminance against the standard's at the same directions."""

    directions: F64  # (N, 3)
    model: F64  # (N,) L / L_zenith of the model
    reference: F64  # (N,) of the standard

    @property
    def errors(self) -> F64:
        """|model - reference| / reference, (N,)."""
        out: F64 = np.abs(self.model - self.reference) / self.reference
        return out

    @property
    def median(self) -> float:
        return float(np.median(self.errors))

    @property
    def p90(self) -> float:
        return float(np.percentile(self.errors, 90.0))


def compare(
    luminance: F64,
    zenith_luminance: float,
    directions: F64,
    sun_direction: F64,
    sky: CieSkyType = CLEAR_LOW_TURBIDITY,
) -> CieComparison:
    """Compare luminances (N,) at directions (N, 3) (zenith_luminance: the model's at the
    zenith) with the standard sky."""
    model = np.asarray(luminance, np.float64) / zenith_luminance
    return CieComparison(directions, model, relative_luminance(sky, directions, sun_direction))
