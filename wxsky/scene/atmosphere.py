"""A physical atmosphere: Rayleigh, Mie and ozone over a spherical Earth, precomputed into
small look-up tables in numpy (no GL), after Bruneton (2017) and Hillaire (2020).

The sky pass samples the sky-view table; the cloud lighting takes the sun's transmitted light
and the sky's ambient irradiance at an altitude from the same tables (`sun_irradiance`,
`sky_irradiance`, `moon_irradiance`).

Medium (Hillaire 2020's Earth, Bruneton 2017's parameters):

- Rayleigh scattering (5.802, 13.558, 33.1)e-6 /m at sea level (R, G, B: 680, 550, 440 nm),
  exponential with an 8 km scale height; phase 3/(16 pi) (1 + cos^2).
- Ozone absorption (0.650, 1.881, 0.085)e-6 /m at its peak, in a tent 30 km wide around 25 km:
  it keeps the zenith blue at twilight (without it the twilight zenith turns grey-yellow).
- Mie (aerosol): extinction at the ground from the visibility by Koschmieder,
  beta = 3.912 / visibility_m, less Rayleigh's share at 550 nm (the air alone gives a
  visibility near 290 km), never below a clean-air floor; exponential with a 1.2 km scale
  height (not Hillaire's 1.2 km: see MIE_SCALE_HEIGHT_M); single-scattering albedo 0.9;
  phase Cornette-Shanks with g = 0.76; extinction as lambda^-1.3 (Angstrom) across the
  channels, the visibility's at 550 nm (`Medium.mie_spectral`).
- Humidity grows the aerosol (hygroscopic growth, Hanel): the extinction is multiplied by
  ((1 - RH_ref) / (1 - RH))^0.25 with RH_ref = 50 % and RH capped at 95 % (so 1.0 at and
  below 50 %, 1.3 at 85 %, 1.78 at 95 %), and its phase grows a little more forward
  (g from 0.76 to 0.80 at 95 %) and greyer (Angstrom from 1.3 to 0.3 with the growth).
  Reported visibility is the optical state near the ground,
  so the growth is kept small: it stands for the damp haze aloft the visibility misses.

Units: radiance in kcd/m^2 (luminance Y = 0.2126 R + 0.7152 G + 0.0722 B is cd/m^2 / 1000),
irradiance in klx: the sun at the top of the atmosphere gives SUN_ILLUMINANCE_KLX on a surface
facing it. Scene-linear values: the exposure (`display_exposure`) and the one tone map every
pass shares (`exposure.display`) turn them into a picture.

Tables (rows first, float32, RGB):

- transmittance (TRANSMITTANCE_SIZE = 64 radii x 256 view angles) from a radius to the top of
  the atmosphere, Bruneton's parametrisation (rays that miss the ground only);
- multiple scattering (32 x 32: radius x cos sun zenith), Hillaire's isotropic second-order
  approximation Psi = L2 / (1 - f_ms), with a Lambertian ground (GROUND_ALBEDO);
- ambient (AMBIENT_SIZE: altitudes x cos sun zenith x (above, below)), the cosine-weighted sky
  irradiance on an upward and a downward facing surface;
- sky view (SKY_VIEW_SIZE = 108 elevations x 192 azimuths) around the eye: columns are the
  azimuth from the sun's 0..180 deg (the sky is symmetric about the sun's vertical), rows the
  elevation through a square-root mapping about the horizon (as seen from the eye's altitude,
  below 0 deg when above the ground), so that the horizon falls on a texel edge and rows are
  finest there (`sky_view_v`).

`AtmosphereKey` quantises what the tables are made from; `build_luts` makes them (some 0.1 to
0.5 s in numpy on a slow CPU: never on the frame path; wxsky/engine/atmosphere_work.py builds
them on a thread and the renderer keeps the last until the next is ready).
"""

from __future__ import annotations

import functools
import io
import math
import zipfile
from dataclasses import dataclass, field, fields

import numpy as np
import numpy.typing as npt

from wxsky.schema import Number

F64 = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]

EARTH_RADIUS_M = 6_360_000.0
TOP_RADIUS_M = 6_460_000.0
RAYLEIGH_SCATTERING_PER_M = np.array([5.802e-6, 13.558e-6, 33.1e-6])
RAYLEIGH_SCALE_HEIGHT_M = 8_000.0
# Ozone absorption per channel at the tent's peak (300 Dobson units), not at single wavelengths:
# each channel's transmittance through ozone for a Rayleigh sky's light through the CIE 1931
# observer (`tools/bench/cie_sky.py --ozone`, the same within 2 % for 1 to 40 ozone columns).
# The Chappuis band peaks at 600 nm, inside the red channel: at 680 nm alone (Bruneton's 0.650)
# red lost a third of what it does and green the most, and the twilight zenith turned mauve.
OZONE_ABSORPTION_PER_M = np.array([2.893e-6, 1.841e-6, 0.096e-6])
OZONE_CENTRE_M = 25_000.0
OZONE_HALF_WIDTH_M = 15_000.0
# 2 km, within the observed 1-2 km: with Hillaire's 1.2 km the clean 60 km sky at a 60 deg
# sun had too dark a zenith against CIE type 12 (p90 error 0.66; docs/atmosphere.md).
MIE_SCALE_HEIGHT_M = 2_000.0
MIE_ALBEDO = 0.9  # single-scattering albedo of the aerosol
# The channels' wavelengths (R, G, B), nm: Rayleigh's coefficients above are at these.
CHANNEL_NM = np.array([680.0, 550.0, 440.0])
# The aerosol's extinction falls with wavelength as lambda^-alpha (Angstrom): 1.3 for
# continental aerosol (Angstrom's own value, Preetham et al. 1999's turbidity model; AERONET
# sites over land 1.0-1.6), the visibility setting it at 550 nm. Taken as grey (alpha 0), a
# 30 km sky's aerosol, twice the air's optical depth at 550 nm, lit the noon zenith as
# brightly in red as in blue: B/R 1.3, a whitish blue (docs/atmosphere.md, "Colour").
# Humidity swells the particles and flattens the law (hygroscopic growth): with the growth
# of the extinction, toward MIE_ANGSTROM_WET at HUMIDITY_CAP_PCT, the near-grey of a mist's
# droplets (fog is grey; 1.23 at 60 %, 0.85 at 85 %).
MIE_ANGSTROM = 1.3
MIE_ANGSTROM_WET = 0.3
MIE_G = 0.76
# The share of the aerosol's phase function in its narrow forward (diffraction) peak, a few
# degrees wide, which the sky view's smooth lobe and 1 deg texels cannot hold: the sky pass
# draws it as the aureole (scene.sky AUREOLE_SHARE is this) and the sky view keeps the rest,
# so the aerosol's light is counted once. It was counted 1.12 times: the aureole on top of the
# whole lobe, which alone lit the noon zenith, 30 deg from the sun, with too much white.
MIE_PEAK_SHARE = 0.12
MIE_G_WET = 0.80  # at HUMIDITY_CAP_PCT
# Clean continental air aloft never quite lacks aerosol: Hillaire's Mie extinction (4.4e-6 /m)
# as the floor, a visibility of some 200 km with the air's share.
MIE_MIN_EXTINCTION_PER_M = 4.4e-6
KOSCHMIEDER = 3.912  # -ln(0.02): the contrast threshold that defines visibility
HUMIDITY_REF_PCT = 50.0
HUMIDITY_CAP_PCT = 95.0
HANEL_EXPONENT = 0.25
GROUND_ALBEDO = 0.1  # Bruneton's; vegetated land is 0.1-0.2
# The sun at the top of the atmosphere: illuminance (klx) and its colour, white: the picture is
# white-balanced to sunlight above the air, as an eye adapted to daylight sees it (the 5900 K
# body itself, a touch warmer than D65, tinted every sky grey-yellow in 8-bit).
SUN_ILLUMINANCE_KLX = 128.0
SUN_COLOUR = np.array([1.0, 1.0, 1.0])
SUN_ANGULAR_RADIUS_RAD = math.radians(0.2667)
# Full moon against the sun (0.25 lx against 128 klx); a half moon gives about a tenth of a
# full one (the opposition surge), which illuminated_fraction^3 follows closely enough.
MOON_TO_SUN = 2.0e-6
LUMA = np.array([0.2126, 0.7152, 0.0722])

TRANSMITTANCE_SIZE = (64, 256)  # radii, view angles
MULTISCATTER_SIZE = (32, 32)  # radii, sun angles
AMBIENT_SIZE = (16, 32)  # altitudes, sun angles
SKY_VIEW_SIZE = (108, 192)  # elevations (even: the horizon on a texel edge), azimuths
# Ray-march steps: per table, enough that halving them moves no value by 1 %.
TRANSMITTANCE_STEPS = 40
MULTISCATTER_STEPS = 12
MULTISCATTER_DIRECTIONS = 32
AMBIENT_STEPS = 12
AMBIENT_DIRECTIONS = (6, 8)  # elevations, azimuths per hemisphere
SKY_VIEW_STEPS = 24
# Ray samples marched at once (rays x steps): bounds a table build's temporaries to some
# 40 MiB of float64 (twenty (rays, steps, 3) arrays).
MARCH_SAMPLES = 100_000

# Inputs and their limits (the one-line errors name them).
VISIBILITY_M = Number(50.0, 1_000_000.0, unit="m")
HUMIDITY_PCT = Number(0.0, 100.0, unit="%")
SUN_ELEVATION_DEG = Number(-90.0, 90.0, unit="deg")
EYE_ALT_M = Number(-500.0, 90_000.0, unit="m")

# The key's steps: a rebuild when something moved by more than half of one.
SUN_STEP_DEG = 0.25
VISIBILITY_STEP = 0.05  # of the logarithm: 5 % steps
HUMIDITY_STEP_PCT = 5.0
EYE_STEP_M = 50.0  # below EYE_STEP_FROM_M, then EYE_STEP_SHARE of the altitude
EYE_STEP_FROM_M = 1_000.0
EYE_STEP_SHARE = 0.05

MAX_ALT_M = TOP_RADIUS_M - EARTH_RADIUS_M - 1.0


@dataclass(frozen=True)
class Medium:
    """The aerosol of one visibility and humidity (Rayleigh and ozone are fixed)."""

    visibility_m: float
    humidity_pct: float
    mie_extinction_per_m: float  # at the ground, at 550 nm
    mie_g: float
    mie_angstrom: float = MIE_ANGSTROM

    @property
    def mie_scattering_per_m(self) -> float:
        return self.mie_extinction_per_m * MIE_ALBEDO

    @property
    def mie_spectral(self) -> F64:
        """The aerosol's extinction in each channel relative to 550 nm's (Angstrom's law)."""
        out: F64 = (CHANNEL_NM / 550.0) ** -self.mie_angstrom
        return out


def medium(visibility_m: float, humidity_pct: float) -> Medium:
    """The aerosol for a visibility and humidity (see the module's notes); a one-line
    ValueError naming the key and its range for a value out of range, NaN or inf."""
    vis = _checked(VISIBILITY_M, "visibility_m", visibility_m)
    rh = _checked(HUMIDITY_PCT, "humidity_pct", humidity_pct)
    beta = KOSCHMIEDER / vis - float(RAYLEIGH_SCATTERING_PER_M[1])
    rh_capped = min(rh, HUMIDITY_CAP_PCT)
    growth = ((100.0 - HUMIDITY_REF_PCT) / (100.0 - max(rh_capped, HUMIDITY_REF_PCT))) ** (
        HANEL_EXPONENT
    )
    wet = max(0.0, rh_capped - HUMIDITY_REF_PCT) / (HUMIDITY_CAP_PCT - HUMIDITY_REF_PCT)
    # The Angstrom law flattens as the particles swell: with the growth, not the humidity.
    cap_growth = ((100.0 - HUMIDITY_REF_PCT) / (100.0 - HUMIDITY_CAP_PCT)) ** HANEL_EXPONENT
    swollen = (growth - 1.0) / (cap_growth - 1.0)
    return Medium(
        vis,
        rh,
        max(beta, MIE_MIN_EXTINCTION_PER_M) * growth,
        MIE_G + (MIE_G_WET - MIE_G) * wet,
        MIE_ANGSTROM + (MIE_ANGSTROM_WET - MIE_ANGSTROM) * swollen,
    )


def _checked(kind: Number, key: str, value: float) -> float:
    try:
        return float(kind.validate(key, value))
    except ValueError as exc:
        raise ValueError(f"atmosphere: {exc}") from None


# -- the medium at a height ------------------------------------------------------------------


def _densities(alt_m: F64) -> tuple[F64, F64, F64]:
    """(Rayleigh, Mie, ozone) density profiles at alt_m, each 0..1."""
    h = np.maximum(alt_m, 0.0)
    rayleigh = np.exp(-h / RAYLEIGH_SCALE_HEIGHT_M)
    mie = np.exp(-h / MIE_SCALE_HEIGHT_M)
    ozone = np.maximum(0.0, 1.0 - np.abs(h - OZONE_CENTRE_M) / OZONE_HALF_WIDTH_M)
    return rayleigh, mie, ozone


def _extinction(med: Medium, alt_m: F64) -> tuple[F64, F64, F64]:
    """(extinction, Rayleigh scattering, Mie scattering) per metre, (..., 3) each."""
    rayleigh, mie, ozone = _densities(alt_m)
    r_sca = rayleigh[..., None] * RAYLEIGH_SCATTERING_PER_M
    m_ext = (mie * med.mie_extinction_per_m)[..., None] * med.mie_spectral
    ext = r_sca + m_ext + ozone[..., None] * OZONE_ABSORPTION_PER_M
    return ext, r_sca, m_ext * MIE_ALBEDO


def rayleigh_phase(nu: F64) -> F64:
    out: F64 = 3.0 / (16.0 * math.pi) * (1.0 + nu * nu)
    return out


def mie_phase(nu: F64, g: float) -> F64:
    """Cornette-Shanks: Henyey-Greenstein with Rayleigh's (1 + cos^2), normalised."""
    k = 3.0 / (8.0 * math.pi) * (1.0 - g * g) / (2.0 + g * g)
    out: F64 = k * (1.0 + nu * nu) / np.power(1.0 + g * g - 2.0 * g * nu, 1.5)
    return out


# -- geometry --------------------------------------------------------------------------------

_H = math.sqrt(TOP_RADIUS_M**2 - EARTH_RADIUS_M**2)


def _distance_to_top(r: F64, mu: F64) -> F64:
    disc = r * r * (mu * mu - 1.0) + TOP_RADIUS_M**2
    out: F64 = np.maximum(-r * mu + np.sqrt(np.maximum(disc, 0.0)), 0.0)
    return out


def _distance_to_ground(r: F64, mu: F64) -> F64:
    disc = r * r * (mu * mu - 1.0) + EARTH_RADIUS_M**2
    out: F64 = np.maximum(-r * mu - np.sqrt(np.maximum(disc, 0.0)), 0.0)
    return out


def _hits_ground(r: F64, mu: F64) -> npt.NDArray[np.bool_]:
    out: npt.NDArray[np.bool_] = (mu < 0.0) & (r * r * (mu * mu - 1.0) + EARTH_RADIUS_M**2 >= 0.0)
    return out


def _horizon_mu(r: F64) -> F64:
    """Cosine of the zenith angle of the horizon from radius r (below 0 above the ground)."""
    out: F64 = -np.sqrt(
        np.maximum(0.0, 1.0 - (EARTH_RADIUS_M / np.maximum(r, EARTH_RADIUS_M)) ** 2)
    )
    return out


# -- transmittance ---------------------------------------------------------------------------


def _transmittance_rmu(u: F64, v: F64) -> tuple[F64, F64]:
    """Bruneton's (r, mu) at table coordinates u (view angle), v (radius), both 0..1."""
    rho = _H * v
    r = np.sqrt(rho * rho + EARTH_RADIUS_M**2)
    d_min = TOP_RADIUS_M - r
    d_max = rho + _H
    d = d_min + u * (d_max - d_min)
    mu = np.where(d == 0.0, 1.0, (_H * _H - rho * rho - d * d) / np.maximum(2.0 * r * d, 1e-9))
    return r, np.clip(mu, -1.0, 1.0)


def _transmittance_uv(r: F64, mu: F64) -> tuple[F64, F64]:
    r = np.clip(r, EARTH_RADIUS_M, TOP_RADIUS_M)
    rho = np.sqrt(np.maximum(r * r - EARTH_RADIUS_M**2, 0.0))
    d = _distance_to_top(r, mu)
    d_min = TOP_RADIUS_M - r
    d_max = rho + _H
    u = (d - d_min) / np.maximum(d_max - d_min, 1e-9)
    return np.clip(u, 0.0, 1.0), np.clip(rho / _H, 0.0, 1.0)


def _optical_depth(med: Medium, r: F64, mu: F64, length: F64, steps: int) -> F64:
    """Optical depth (..., 3) along a ray from radius r, cos zenith mu, over `length`."""
    if r.ndim and r.size * steps > MARCH_SAMPLES and r.shape[0] > 1:  # in slices, as _march
        n = max(1, MARCH_SAMPLES // (steps * (r.size // r.shape[0])))
        return np.concatenate(
            [
                _optical_depth(med, r[i : i + n], mu[i : i + n], length[i : i + n], steps)
                for i in range(0, r.shape[0], n)
            ]
        )
    s = (np.arange(steps) + 0.5) / steps
    t = length[..., None] * s  # (..., S)
    ri = np.sqrt(r[..., None] ** 2 + t * t + 2.0 * r[..., None] * mu[..., None] * t)
    ext, _, _ = _extinction(med, ri - EARTH_RADIUS_M)
    out: F64 = ext.sum(axis=-2) * (length / steps)[..., None]
    return out


def transmittance_table(med: Medium) -> F64:
    """(rows radii, cols view angles, 3) transmittance to the top of the atmosphere."""
    rows, cols = TRANSMITTANCE_SIZE
    v, u = np.meshgrid(
        (np.arange(rows) + 0.5) / rows, (np.arange(cols) + 0.5) / cols, indexing="ij"
    )
    r, mu = _transmittance_rmu(u, v)
    depth = _optical_depth(med, r, mu, _distance_to_top(r, mu), TRANSMITTANCE_STEPS)
    out: F64 = np.exp(-depth)
    return out


def _bilinear(table: F64, u: F64, v: F64) -> F64:
    """Sample table (rows, cols, C) at u (cols) and v (rows) in 0..1, texel centres at
    (i + 0.5) / n, clamped at the edges (as GL's CLAMP_TO_EDGE with LINEAR)."""
    rows, cols = table.shape[:2]
    x = np.minimum(np.maximum(u * cols - 0.5, 0.0), cols - 1.0)
    y = np.minimum(np.maximum(v * rows - 0.5, 0.0), rows - 1.0)
    x0 = np.minimum(x.astype(np.intp), cols - 2)  # x >= 0: the cast is the floor
    y0 = np.minimum(y.astype(np.intp), rows - 2)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    # Four gathers of whole texels from the table as rows of C: a fifth of the time of
    # indexing it by (row, column) for a frame's few hundred sprites.
    flat = table.reshape(rows * cols, -1)
    at = y0 * cols + x0
    t00, t01 = flat.take(at, axis=0), flat.take(at + 1, axis=0)
    t10, t11 = flat.take(at + cols, axis=0), flat.take(at + cols + 1, axis=0)
    top = t00 + (t01 - t00) * fx
    bottom = t10 + (t11 - t10) * fx
    out: F64 = (top + (bottom - top) * fy).reshape(*np.shape(x), *table.shape[2:])
    return out


def sample_table(table: F64 | F32, u: F64, v: F64) -> F64:
    """`table` (rows, cols, C) at u (cols) and v (rows) in 0..1 as the GPU samples a texture of
    it (LINEAR, CLAMP_TO_EDGE)."""
    as_f64: F64 = np.asarray(table, np.float64)  # no copy when it is float64 already
    return _bilinear(as_f64, u, v)


def _transmittance_to_top(table: F64, r: F64, mu: F64) -> F64:
    u, v = _transmittance_uv(r, mu)
    return _bilinear(table, u, v)


def _sun_transmittance(table: F64, r: F64, mu_s: F64) -> F64:
    """Transmittance of sunlight to radius r with the sun at cos zenith mu_s, with the part
    of the sun's disc above the horizon (the Earth's shadow, soft over the disc)."""
    horizon = _horizon_mu(r)
    sin_h = np.sqrt(np.maximum(0.0, 1.0 - horizon * horizon))
    # Above the horizon by this many sun radii (small angles).
    over = (mu_s - horizon) / np.maximum(sin_h * SUN_ANGULAR_RADIUS_RAD, 1e-9)
    visible = np.clip(0.5 + 0.5 * over, 0.0, 1.0)
    return _transmittance_to_top(table, r, np.maximum(mu_s, horizon)) * visible[..., None]


# -- ray marching ----------------------------------------------------------------------------


@dataclass(frozen=True)
class _March:
    luminance: F64  # (..., 3) in-scattered, per unit sun irradiance
    transmittance: F64  # (..., 3) to the ray's end
    multi: F64  # (..., 3) f_ms: light scattered once along the ray, isotropically
    ground: npt.NDArray[np.bool_]
    end_r: F64
    end_mu_s: F64


def _march(
    med: Medium,
    t_table: F64,
    ms_table: F64 | None,
    r: F64,
    mu: F64,
    mu_s: F64,
    nu: F64,
    steps: int,
    isotropic: bool = False,
    mie_share: float = 1.0,
) -> _March:
    """In-scattered light along rays (all arrays broadcast alike): single scattering by the
    phase functions (isotropic: 1 / 4 pi, for the multiple-scattering table; the aerosol's
    by mie_share of its lobe, the sky view leaving its narrow peak to the sky pass's aureole),
    plus the multiple-scattering table's Psi where given. Samples crowd the ray's start
    (quadratic spacing), where the dense air is on a horizontal ray."""
    r, mu, mu_s, nu = np.broadcast_arrays(r, mu, mu_s, nu)
    if r.ndim and r.size * steps > MARCH_SAMPLES and r.shape[0] > 1:
        # In slices along the first axis: a ray's samples make some twenty (rays, steps, 3)
        # temporaries, and the sky view's 20,736 rays at once took 233 MiB for a moment, a
        # swing of the daemon's RSS with every rebuild (issue 40's soak).
        per_row = r.size // r.shape[0]
        n = max(1, MARCH_SAMPLES // (steps * per_row))
        parts = [
            _march(
                med, t_table, ms_table, r[i : i + n], mu[i : i + n], mu_s[i : i + n],
                nu[i : i + n], steps, isotropic, mie_share,
            )
            for i in range(0, r.shape[0], n)
        ]  # fmt: skip
        return _March(
            *(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(_March))
        )
    ground = _hits_ground(r, mu)
    length = np.where(ground, _distance_to_ground(r, mu), _distance_to_top(r, mu))
    edges = (np.arange(steps + 1) / steps) ** 2
    t0 = length[..., None] * edges[:-1]
    t1 = length[..., None] * edges[1:]
    t = 0.5 * (t0 + t1)
    dt = t1 - t0
    rr, mm, ss, nn = (a[..., None] for a in (r, mu, mu_s, nu))
    ri = np.sqrt(np.maximum(rr * rr + t * t + 2.0 * rr * mm * t, EARTH_RADIUS_M**2))
    mu_si = np.clip((rr * ss + t * nn) / ri, -1.0, 1.0)
    ext, r_sca, m_sca = _extinction(med, ri - EARTH_RADIUS_M)
    depth = ext * dt[..., None]
    before = np.cumsum(depth, axis=-2) - depth  # optical depth to each step's start
    t_start = np.exp(-before)
    through = (1.0 - np.exp(-depth)) / np.maximum(ext, 1e-30)  # integral of T over a step
    sun_t = _sun_transmittance(t_table, ri, mu_si)
    if isotropic:
        single = (r_sca + m_sca) * (1.0 / (4.0 * math.pi))
    else:
        mie = mie_phase(nn, med.mie_g) * mie_share
        single = r_sca * rayleigh_phase(nn)[..., None] + m_sca * mie[..., None]
    source = single * sun_t
    if ms_table is not None:
        source = source + (r_sca + m_sca) * _multiscatter_at(ms_table, ri, mu_si)
    weight = t_start * through
    lum = (source * weight).sum(axis=-2)
    multi = ((r_sca + m_sca) * weight).sum(axis=-2)
    total = np.exp(-depth.sum(axis=-2))
    end_r = np.sqrt(np.maximum(r * r + length * length + 2.0 * r * mu * length, EARTH_RADIUS_M**2))
    end_mu_s = np.clip((r * mu_s + length * nu) / end_r, -1.0, 1.0)
    return _March(lum, total, multi, ground, end_r, end_mu_s)


# -- multiple scattering ---------------------------------------------------------------------


def _sun_u_of(mu_s: F64) -> F64:
    """Table coordinate 0..1 of the cosine of the sun's zenith angle, square-rooted about the
    horizon (0.5): the light under a low sun falls by 20 times within 4 degrees, and even
    columns 3.6 degrees apart, blended linearly, lit the Earth's shadow with the glow of a
    sun still up."""
    m = np.clip(mu_s, -1.0, 1.0)
    out: F64 = 0.5 + 0.5 * np.sign(m) * np.sqrt(np.abs(m))
    return out


def _sun_mu_of(u: F64) -> F64:
    """The inverse of `_sun_u_of`."""
    a = 2.0 * np.asarray(u, np.float64) - 1.0
    out: F64 = np.sign(a) * a * a
    return out


def _sphere_directions(n: int) -> F64:
    """n nearly even directions on the unit sphere (a Fibonacci lattice): (n, 3)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = math.pi * (1.0 + math.sqrt(5.0)) * i
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=-1)


def multiscatter_table(med: Medium, t_table: F64) -> F64:
    """(rows radii, cols cos sun zenith (`_sun_u_of`), 3) Hillaire's Psi_ms: the isotropic light of
    all orders beyond the first, per unit sun irradiance and unit scattering coefficient."""
    rows, cols = MULTISCATTER_SIZE
    alt = (np.arange(rows) + 0.5) / rows * (TOP_RADIUS_M - EARTH_RADIUS_M)
    mu_s = _sun_mu_of((np.arange(cols) + 0.5) / cols)
    dirs = _sphere_directions(MULTISCATTER_DIRECTIONS)
    r = (EARTH_RADIUS_M + alt)[:, None, None]
    ms = mu_s[None, :, None]
    sun = np.stack([np.sqrt(1.0 - mu_s * mu_s), np.zeros_like(mu_s), mu_s], axis=-1)  # (cols, 3)
    mu = dirs[None, None, :, 2]
    nu = (sun @ dirs.T)[None, :, :]
    m = _march(med, t_table, None, r, mu, ms, nu, MULTISCATTER_STEPS, isotropic=True)
    # The ground under a ray that meets it, lit by the sun (Lambertian).
    ground_sun = (
        _sun_transmittance(t_table, m.end_r, m.end_mu_s) * np.maximum(m.end_mu_s, 0.0)[..., None]
    )
    ground = np.where(
        m.ground[..., None], m.transmittance * ground_sun * GROUND_ALBEDO / math.pi, 0.0
    )
    l2 = (m.luminance + ground).mean(axis=-2)  # the mean over the sphere: the 1 / 4 pi phase
    f_ms = m.multi.mean(axis=-2)
    out: F64 = l2 / np.maximum(1.0 - f_ms, 1e-3)
    return out


def _multiscatter_at(table: F64, r: F64, mu_s: F64) -> F64:
    v = (r - EARTH_RADIUS_M) / (TOP_RADIUS_M - EARTH_RADIUS_M)
    u = _sun_u_of(mu_s)
    return _bilinear(table, np.clip(u, 0.0, 1.0), np.clip(v, 0.0, 1.0))


# -- ambient ---------------------------------------------------------------------------------


def _ambient_alt(v: F64) -> F64:
    """Table altitudes: squared, crowding the low air where the clouds are (0..20 km)."""
    out: F64 = 20_000.0 * v * v
    return out


def ambient_table(med: Medium, t_table: F64, ms_table: F64) -> F64:
    """(altitudes, cos sun zenith (`_sun_u_of`), 2, 3) sky irradiance per unit sun irradiance on a
    surface facing up ([..., 0, :]) and down ([..., 1, :]); below, the ground's Lambertian
    light (sun and sky on it) comes in through the air too."""
    rows, cols = AMBIENT_SIZE
    alt = _ambient_alt(np.arange(rows) / (rows - 1))
    mu_s = _sun_mu_of(np.arange(cols) / (cols - 1))
    n_el, n_az = AMBIENT_DIRECTIONS
    # Cosine-weighted hemisphere directions: sin(el)^2 even in (0, 1) gives weights alike.
    q = (np.arange(n_el) + 0.5) / n_el
    sin_el = np.sqrt(q)
    cos_el = np.sqrt(1.0 - q)
    az = (np.arange(n_az) + 0.5) / n_az * 2.0 * math.pi
    dx = (cos_el[:, None] * np.cos(az)[None, :]).ravel()
    dz = (sin_el[:, None] * np.ones(n_az)[None, :]).ravel()
    r = (EARTH_RADIUS_M + alt)[:, None, None]
    ms = mu_s[None, :, None]
    sun_x = np.sqrt(1.0 - mu_s * mu_s)[None, :, None]
    out = np.zeros((rows, cols, 2, 3))
    for k, sign in enumerate((1.0, -1.0)):
        mu = (sign * dz)[None, None, :]
        nu = sun_x * dx[None, None, :] + ms * (sign * dz)[None, None, :]
        m = _march(med, t_table, ms_table, r, mu, ms, nu, AMBIENT_STEPS)
        lum = m.luminance
        if sign < 0.0:
            # The ground: sun on it, and the sky's light above it (this table's first row).
            sun_on = (
                _sun_transmittance(t_table, m.end_r, m.end_mu_s)
                * np.maximum(m.end_mu_s, 0.0)[..., None]
            )
            sky_on = _bilinear_rows(out[:, :, 0], np.zeros_like(m.end_r), m.end_mu_s)
            ground = m.transmittance * (sun_on + sky_on) * GROUND_ALBEDO / math.pi
            lum = lum + np.where(m.ground[..., None], ground, 0.0)
        # Cosine-weighted sampling: E = pi * mean(L).
        out[:, :, k] = math.pi * lum.mean(axis=-2)
    return out


def _bilinear_rows(table: F64, alt_m: F64, mu_s: F64) -> F64:
    """Sample an ambient-shaped table (altitudes, mu_s, 3) at alt_m and mu_s."""
    rows, cols = table.shape[:2]
    v = np.sqrt(np.clip(alt_m, 0.0, 20_000.0) / 20_000.0)
    u = _sun_u_of(mu_s)
    # Texels sit at i / (n - 1): move to the centres' convention of _bilinear.
    return _bilinear(table, (u * (cols - 1) + 0.5) / cols, (v * (rows - 1) + 0.5) / rows)


# -- sky view --------------------------------------------------------------------------------


def horizon_elevation_rad(eye_alt_m: float) -> float:
    """The geometric horizon's elevation from eye_alt_m (0 at the ground, below above it)."""
    r = EARTH_RADIUS_M + min(max(eye_alt_m, 0.0), MAX_ALT_M)
    return -math.acos(min(1.0, EARTH_RADIUS_M / r))


def sky_view_v(elevation_rad: F64, horizon_rad: float) -> F64:
    """Row coordinate 0..1 of the sky-view table for an elevation: 0.5 at the horizon, the
    square root of the angle from it either way, 1 at the zenith and 0 at the nadir."""
    below = np.sqrt(
        np.clip((horizon_rad - elevation_rad) / (horizon_rad + 0.5 * math.pi), 0.0, 1.0)
    )
    out: F64 = np.where(
        elevation_rad >= horizon_rad,
        sky_view_v_above(elevation_rad, horizon_rad),
        0.5 - 0.5 * below,
    )
    return out


def sky_view_v_above(elevation_rad: F64 | float, horizon_rad: float) -> F64:
    """`sky_view_v` for elevations at or above the horizon (below it: the horizon's row),
    without the other branch: the sprites' haze asks it of a frame's sprites every frame."""
    a = (np.asarray(elevation_rad, np.float64) - horizon_rad) * (
        1.0 / (0.5 * math.pi - horizon_rad)
    )
    out: F64 = 0.5 + 0.5 * np.sqrt(np.minimum(np.maximum(a, 0.0), 1.0))
    return out


def sky_view_elevation(v: F64, horizon_rad: float) -> F64:
    """The inverse of `sky_view_v`."""
    a = 2.0 * v - 1.0
    out: F64 = np.where(
        a >= 0.0,
        horizon_rad + a * a * (0.5 * math.pi - horizon_rad),
        horizon_rad - a * a * (horizon_rad + 0.5 * math.pi),
    )
    return out


def sky_view_table(
    med: Medium, t_table: F64, ms_table: F64, eye_alt_m: float, sun_elevation_deg: float
) -> F64:
    """(rows elevations, cols azimuths from the sun 0..pi, 3) sky radiance per unit sun
    irradiance seen from eye_alt_m (rows up the sky: `sky_view_v`; below the horizon, the
    air in front of the ground and the ground itself, lit by the sun)."""
    rows, cols = SKY_VIEW_SIZE
    horizon = horizon_elevation_rad(eye_alt_m)
    v = (np.arange(rows) + 0.5) / rows
    el = sky_view_elevation(v, horizon)[:, None]
    az = ((np.arange(cols) + 0.5) / cols * math.pi)[None, :]
    sun_el = math.radians(sun_elevation_deg)
    r = np.array(EARTH_RADIUS_M + min(max(eye_alt_m, 1.0), MAX_ALT_M))
    mu = np.sin(el) * np.ones_like(az)
    mu_s = np.array(math.sin(sun_el))
    nu = np.cos(el) * np.cos(az) * math.cos(sun_el) + np.sin(el) * math.sin(sun_el)
    m = _march(
        med, t_table, ms_table, r, mu, mu_s, nu, SKY_VIEW_STEPS, mie_share=1.0 - MIE_PEAK_SHARE
    )
    sun_on = (
        _sun_transmittance(t_table, m.end_r, m.end_mu_s) * np.maximum(m.end_mu_s, 0.0)[..., None]
    )
    ground = m.transmittance * sun_on * GROUND_ALBEDO / math.pi
    out: F64 = m.luminance + np.where(m.ground[..., None], ground, 0.0)
    return out


# -- the tables together ---------------------------------------------------------------------


@dataclass(frozen=True, order=True)
class AtmosphereKey:
    """What the tables are made from, quantised (`atmosphere_key`): a rebuild happens only
    when one of these changes, i.e. when the input moved by about a step."""

    sun_elevation_q: int  # SUN_STEP_DEG
    visibility_q: int  # VISIBILITY_STEP of ln(visibility_m)
    humidity_q: int  # HUMIDITY_STEP_PCT
    eye_alt_m: float  # on its step (EYE_STEP_M, then EYE_STEP_SHARE)

    @property
    def sun_elevation_deg(self) -> float:
        return self.sun_elevation_q * SUN_STEP_DEG

    @property
    def visibility_m(self) -> float:
        return math.exp(self.visibility_q * VISIBILITY_STEP)

    @property
    def humidity_pct(self) -> float:
        return self.humidity_q * HUMIDITY_STEP_PCT

    @property
    def medium_key(self) -> tuple[int, int]:
        """The part of the key the transmittance, multiple-scattering and ambient tables
        depend on (not the sun, not the eye)."""
        return (self.visibility_q, self.humidity_q)


def atmosphere_key(
    sun_elevation_deg: float, visibility_m: float, humidity_pct: float, eye_alt_m: float
) -> AtmosphereKey:
    """The quantised key for these inputs; one-line ValueErrors for values out of range."""
    sun = _checked(SUN_ELEVATION_DEG, "sun_elevation_deg", sun_elevation_deg)
    vis = _checked(VISIBILITY_M, "visibility_m", visibility_m)
    rh = _checked(HUMIDITY_PCT, "humidity_pct", humidity_pct)
    eye = _checked(EYE_ALT_M, "eye_alt_m", eye_alt_m)
    eye = min(max(eye, 0.0), MAX_ALT_M - 1000.0)
    if eye < EYE_STEP_FROM_M:
        eye_q = round(eye / EYE_STEP_M) * EYE_STEP_M
    else:
        # Logarithmic steps above: a step of EYE_STEP_SHARE of the altitude.
        k = round(math.log(eye / EYE_STEP_FROM_M) / math.log1p(EYE_STEP_SHARE))
        eye_q = EYE_STEP_FROM_M * (1.0 + EYE_STEP_SHARE) ** k
    return AtmosphereKey(
        round(sun / SUN_STEP_DEG),
        round(math.log(vis) / VISIBILITY_STEP),
        round(rh / HUMIDITY_STEP_PCT),
        float(eye_q),
    )


@dataclass(frozen=True, eq=False)
class AtmosphereLuts:
    """One set of tables (read-only arrays) and what they were made from. Radiance per unit
    sun irradiance in the tables; the functions below scale by the sun (SUN_ILLUMINANCE_KLX,
    SUN_COLOUR). Compared by identity: a new set is a new object."""

    key: AtmosphereKey
    medium: Medium
    transmittance: F64
    multiscatter: F64
    ambient: F64
    sky_view: F64
    serial: int = field(default=0)

    @property
    def sun_elevation_deg(self) -> float:
        return self.key.sun_elevation_deg

    @property
    def eye_alt_m(self) -> float:
        return self.key.eye_alt_m

    @property
    def horizon_rad(self) -> float:
        return horizon_elevation_rad(self.key.eye_alt_m)

    def sky_view_radiance(self) -> F32:
        """The sky-view table in kcd/m^2 (float32, rows up the sky), as the sky pass takes it."""
        out: F32 = (self.sky_view * _sun_rgb()).astype(np.float32)
        return out

    def radiance(self, direction_enu: F64, sun_direction_enu: F64) -> F64:
        """Sky radiance (kcd/m^2, (..., 3)) from the table in directions (..., 3), for a sun
        in sun_direction_enu (its elevation should be the table's; its azimuth is free), as
        the sky pass samples it (bilinear, clamped), without the sun's disc."""
        d = np.asarray(direction_enu, np.float64)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        s = np.asarray(sun_direction_enu, np.float64)
        el = np.arcsin(np.clip(d[..., 2], -1.0, 1.0))
        flat = d[..., :2]
        sun_flat = s[:2] / max(float(np.linalg.norm(s[:2])), 1e-9)
        norm = np.maximum(np.linalg.norm(flat, axis=-1), 1e-9)
        cos_az = np.clip((flat @ sun_flat) / norm, -1.0, 1.0)
        u = np.arccos(cos_az) / math.pi
        v = sky_view_v(el, self.horizon_rad)
        out: F64 = _bilinear(self.sky_view, u, v) * _sun_rgb()
        return out


def _sun_rgb() -> F64:
    out: F64 = SUN_ILLUMINANCE_KLX * SUN_COLOUR
    return out


_medium_tables: tuple[tuple[int, int], tuple[Medium, F64, F64, F64]] | None = None
_serial = 0


def build_luts(key: AtmosphereKey) -> AtmosphereLuts:
    """The tables for a key. The medium's three (which neither the sun nor the eye changes)
    are kept from the last call with the same visibility and humidity."""
    global _medium_tables
    last = _medium_tables  # one read: a worker thread may replace it
    if last is not None and last[0] == key.medium_key:
        med, t_table, ms_table, amb = last[1]
    else:
        med = key_medium(key)
        t_table = transmittance_table(med)
        ms_table = multiscatter_table(med, t_table)
        amb = ambient_table(med, t_table, ms_table)
        _medium_tables = (key.medium_key, (med, t_table, ms_table, amb))
    view = sky_view_table(med, t_table, ms_table, key.eye_alt_m, key.sun_elevation_deg)
    return luts_of(key, med, (t_table, ms_table, amb, view))


TABLE_SHAPES = {
    "transmittance": (*TRANSMITTANCE_SIZE, 3),
    "multiscatter": (*MULTISCATTER_SIZE, 3),
    "ambient": (*AMBIENT_SIZE, 2, 3),
    "sky_view": (*SKY_VIEW_SIZE, 3),
}


def luts_to_bytes(luts: AtmosphereLuts) -> bytes:
    """The four tables as one `.npz` (exact float64), for a cache to keep."""
    out = io.BytesIO()
    np.savez(out, **{name: getattr(luts, name) for name in TABLE_SHAPES})
    return out.getvalue()


def luts_from_bytes(key: AtmosphereKey, data: bytes) -> AtmosphereLuts:
    """A set kept by `luts_to_bytes`, for `key`; ValueError where the bytes are not one
    (cut short, another layout, a table misshapen or not finite)."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as kept:
            tables = tuple(np.asarray(kept[name]) for name in TABLE_SHAPES)
        return luts_of(key, key_medium(key), tables)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, ArithmeticError) as exc:
        raise ValueError(f"not a set of atmosphere tables: {exc}") from None


def key_medium(key: AtmosphereKey) -> Medium:
    """The medium a key's tables are made in."""
    # The key's step may land a hair outside the range the visibility was checked against.
    vis_lo, vis_hi = VISIBILITY_M.bounds
    return medium(min(max(key.visibility_m, vis_lo), vis_hi), key.humidity_pct)


def luts_of(key: AtmosphereKey, med: Medium, tables: tuple[F64, ...]) -> AtmosphereLuts:
    """One set of tables (transmittance, multiple scattering, ambient, sky view: TABLE_SHAPES'
    order), made read-only, under a fresh serial; ArithmeticError for a non-finite or
    misshapen table (a set read back from a cache is checked as a set made here)."""
    if len(tables) != len(TABLE_SHAPES):
        raise ArithmeticError(f"atmosphere: {len(tables)} tables for {key}, not 4")
    for (name, shape), table in zip(TABLE_SHAPES.items(), tables, strict=True):
        if table.shape != shape or table.dtype != np.float64:
            raise ArithmeticError(f"atmosphere: {name} table {table.shape} for {key}")
        if not np.all(np.isfinite(table)):
            raise ArithmeticError(f"atmosphere: non-finite {name} table for {key}")
        table.flags.writeable = False
    t_table, ms_table, amb, view = tables
    return AtmosphereLuts(key, med, t_table, ms_table, amb, view, fresh_serial())


def fresh_serial() -> int:
    """A serial no set of tables made in this process has had (`AtmosphereLuts.serial`)."""
    global _serial
    _serial += 1
    return _serial


# -- what the clouds take from it ------------------------------------------------------------


def _sun_mu(sun_elevation_deg: F64 | float) -> F64:
    el = np.clip(np.asarray(sun_elevation_deg, np.float64), -90.0, 90.0)
    return np.sin(np.radians(el))


def sun_irradiance(luts: AtmosphereLuts, alt_m: F64 | float, sun_elevation_deg: F64 | float) -> F64:
    """The sun's transmitted light (klx, RGB (..., 3)) on a surface facing it at alt_m above
    the ground (the model's ground is the observer's, as the engine builds the tables), with
    the sun at sun_elevation_deg (as seen at the ground; +90 to -90): the atmosphere's
    transmittance along the path, so a deck's top is lit (red) while the ground is in
    twilight. Finite for every finite input."""
    alt = np.clip(np.asarray(alt_m, np.float64), 0.0, MAX_ALT_M)
    r = EARTH_RADIUS_M + alt
    mu_s = _sun_mu(sun_elevation_deg)
    r, mu_s = np.broadcast_arrays(r, mu_s)
    out: F64 = _sun_transmittance(luts.transmittance, r, mu_s) * _sun_rgb()
    return out


def sky_irradiance(
    luts: AtmosphereLuts, alt_m: F64 | float, sun_elevation_deg: F64 | float
) -> tuple[F64, F64]:
    """The sky's ambient irradiance (klx, RGB (..., 3)) at alt_m above the ground on a
    horizontal surface facing up (the sky above) and facing down (the air and the lit ground
    below), with the sun at sun_elevation_deg. Finite for every finite input."""
    alt = np.clip(np.asarray(alt_m, np.float64), 0.0, 20_000.0)
    mu_s = _sun_mu(sun_elevation_deg)
    alt, mu_s = np.broadcast_arrays(alt, mu_s)
    above = _bilinear_rows(luts.ambient[:, :, 0], alt, mu_s) * _sun_rgb()
    below = _bilinear_rows(luts.ambient[:, :, 1], alt, mu_s) * _sun_rgb()
    return above, below


def moon_irradiance(
    luts: AtmosphereLuts,
    alt_m: F64 | float,
    moon_elevation_deg: F64 | float,
    illuminated_fraction: float,
) -> F64:
    """The moon's transmitted light (klx, RGB): sunlight scaled by MOON_TO_SUN and the phase
    (illuminated_fraction^3: a half moon gives about a tenth of a full one)."""
    frac = (
        min(max(float(illuminated_fraction), 0.0), 1.0)
        if math.isfinite(illuminated_fraction)
        else 0.0
    )
    return sun_irradiance(luts, alt_m, moon_elevation_deg) * (MOON_TO_SUN * frac**3)


def vertical_rayleigh_optical_depth() -> F64:
    """tau of the Rayleigh air straight up from the ground: beta * H (for the tests)."""
    out: F64 = (
        RAYLEIGH_SCATTERING_PER_M
        * RAYLEIGH_SCALE_HEIGHT_M
        * (1.0 - math.exp(-(TOP_RADIUS_M - EARTH_RADIUS_M) / RAYLEIGH_SCALE_HEIGHT_M))
    )
    return out


@functools.lru_cache(maxsize=8)  # a frame asks for it several times; a table is immutable
def display_exposure(luts: AtmosphereLuts, dim: float = 1.0) -> float:
    """The automatic exposure: a scale from kcd/m^2 to exposed units, before the one tone map
    (`exposure.display`; sky.glsl's `u_sky_scale`; the clouds' light is made in these units,
    cloud_light), from the scene's luminance: the mean luminance of the sky above the
    horizon, adapting only partly (a power of 0.5), so that noon is bright, the low sun golden
    and twilight dark blue rather than lifted to noon's brightness; capped so the night stays
    night. `dim`: the share of that light the cover over the eye leaves (scene.sky's overcast
    veil, `scene_exposure`): an overcast scene is darker, and the eye adapts to it as to the
    sun's going down (the same power), so an overcast dawn is grey, not night."""
    y = _sky_mean_kcd(luts) * min(max(dim, 0.0), 1.0)
    return float(EXPOSURE_KEY / max(y, EXPOSURE_FLOOR_KCD) ** EXPOSURE_ADAPT)


@functools.lru_cache(maxsize=8)
def _sky_mean_kcd(luts: AtmosphereLuts) -> float:
    rows = luts.sky_view.shape[0]
    upper = luts.sky_view[rows // 2 :]
    return float((upper @ LUMA).mean() * (_sun_rgb() @ LUMA))


# Set for the tone curve + sRGB (it was 0.25 for the sky's Reinhard + gamma 2, 0.12 for the
# ACES fit's own toe): a clear noon sky's mean at about 0.36 of display white, the horizon
# paler, the zenith deeper.
EXPOSURE_KEY = 0.10
EXPOSURE_ADAPT = 0.5
EXPOSURE_FLOOR_KCD = 1e-4
