#!/usr/bin/env python3
"""The physical atmosphere against the CIE standard clear sky (CIE S 011 type 12), its colours,
and what its tables cost to build: the tables docs/atmosphere.md quotes.

    PYTHONPATH=$PWD nice -n 19 .venv/bin/python tools/bench/cie_sky.py --png /tmp/cie_sky.png
    PYTHONPATH=$PWD nice -n 19 .venv/bin/python tools/bench/cie_sky.py --colours [--before REF]
    PYTHONPATH=$PWD nice -n 19 .venv/bin/python tools/bench/cie_sky.py --terms --spectral
    PYTHONPATH=$PWD nice -n 19 .venv/bin/python tools/bench/cie_sky.py --build-time [--before REF]

For each visibility and sun elevation: the median and 90th percentile of the relative error of
the model's luminance relative to its zenith against CIE's, over 360 directions 5-80 deg up all
round (tests/test_atmosphere.py holds them to 25 % and 50 %), and the time to build the tables
(the medium's three once per visibility, then the sky view per sun). The PNG shows, per sun
elevation (rows), the model's relative luminance beside CIE's and their ratio, each as a
panorama (azimuth across, the sun in the middle; elevation 0-90 deg up), grey on a log scale
(L / L_zenith of 1/4 black, 16 white; the ratio: 1/2 black, 2 white).

`--colours`: the sky's colour overhead at noon (sun 60 deg), sun 20, 5, -4 and -10 deg (30 km,
60 % humidity, eye 2 m: the tables the daemon makes for fair-cumulus), as radiance (kcd/m^2,
linear sRGB primaries, the sky pass's table as it samples it) with its B/R, and as the display
values the sky layer holds (the atmosphere's exposure, the one tone map); and facing away from
the sun, the R/B 5-15 deg up over that 35-45 deg up (the Belt of Venus over the Earth's shadow
at -4). `--before REF` adds the same table from another revision, run from a temporary
detached worktree of it (its own `wxsky`; removed afterwards).

`--terms`: what makes the noon zenith's colour, term by term (Rayleigh alone, the aerosol's
share, single scattering only, without ozone, the sky pass's aureole there). `--spectral`: the
same model marched at 42 wavelengths (380-790 nm; Rayleigh as lambda^-4, the ozone's measured
cross-sections, the aerosol by its Angstrom exponent) and turned into linear sRGB through the
CIE 1931 observer, white-balanced to the sun above the air as the three-channel model's white
sun is: a reference for what the three channels (680, 550, 440 nm) make of the same air, and
for the ozone's per-channel absorption (`--ozone`).

`--build-time`: build_luts for a new visibility (all four tables) and for a new sun (the sky
view), the median of 5 each, in one process (`--before REF`: the same, in REF's, alternating).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

# The checkout whose `wxsky` this runs (--before runs this file again against another).
ROOT = Path(os.environ.get("WXSKY_BENCH_ROOT") or Path(__file__).resolve().parents[2])
if str(ROOT) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

from wxsky.png import write_png  # noqa: E402
from wxsky.scene import atmosphere as atm  # noqa: E402
from wxsky.scene import cie_sky  # noqa: E402
from wxsky.scene.exposure import display  # noqa: E402

SUN_ELEVATIONS_DEG = (10.0, 30.0, 60.0)
VISIBILITIES_M = (30_000.0, 45_000.0, 60_000.0)
PANORAMA_PX = (90, 360)  # elevation rows, azimuth columns

# The colour table: fair-cumulus's air (30 km; 60 % humidity as the probe).
COLOUR_MOMENTS = (("noon", 60.0), ("sun 20", 20.0), ("sun 5", 5.0), ("sun -4", -4.0),
                  ("sun -10", -10.0))  # fmt: skip
COLOUR_VISIBILITY_M = 30_000.0
COLOUR_HUMIDITY_PCT = 60.0
COLOUR_EYE_M = 2.0

# -- spectral data (10 nm bins from 360 nm, as binned by Bruneton 2017's demo) ---------------
SPECTRUM_FROM_NM = 360
# ASTM G-173 extraterrestrial solar spectral irradiance, W m^-2 nm^-1, 360..830 nm.
SOLAR_W_M2_NM = np.array([
    1.11776, 1.14259, 1.01249, 1.14716, 1.72765, 1.73054, 1.6887, 1.61253, 1.91198, 2.03474,
    2.02042, 2.02212, 1.93377, 1.95809, 1.91686, 1.8298, 1.8685, 1.8931, 1.85149, 1.8504,
    1.8341, 1.8345, 1.8147, 1.78158, 1.7533, 1.6965, 1.68194, 1.64654, 1.6048, 1.52143,
    1.55622, 1.5113, 1.474, 1.4482, 1.41018, 1.36775, 1.34188, 1.31429, 1.28303, 1.26758,
    1.2367, 1.2082, 1.18737, 1.14683, 1.12362, 1.1058, 1.07124, 1.04992,
])  # fmt: skip
# Ozone absorption cross-section, m^2 (Serdyuchenko et al. 2014, 233 K), 360..830 nm.
OZONE_M2 = np.array([
    1.18e-27, 2.182e-28, 2.818e-28, 6.636e-28, 1.527e-27, 2.763e-27, 5.52e-27, 8.451e-27,
    1.582e-26, 2.316e-26, 3.669e-26, 4.924e-26, 7.752e-26, 9.016e-26, 1.48e-25, 1.602e-25,
    2.139e-25, 2.755e-25, 3.091e-25, 3.5e-25, 4.266e-25, 4.672e-25, 4.398e-25, 4.701e-25,
    5.019e-25, 4.305e-25, 3.74e-25, 3.215e-25, 2.662e-25, 2.238e-25, 1.852e-25, 1.473e-25,
    1.209e-25, 9.423e-26, 7.455e-26, 6.566e-26, 5.105e-26, 4.15e-26, 4.228e-26, 3.237e-26,
    2.451e-26, 2.801e-26, 2.534e-26, 1.624e-26, 1.465e-26, 2.078e-26, 1.383e-26, 7.105e-27,
])  # fmt: skip
# 300 Dobson units in the model's tent (15 km wide at full density), molecules m^-3 at its peak.
OZONE_PEAK_PER_M3 = 300.0 * 2.687e20 / 15_000.0
# Rayleigh scattering at sea level at 1 um (Bruneton's; lambda^-4): 13.558e-6 /m at 550 nm.
RAYLEIGH_AT_1UM_PER_M = 1.24062e-6
SPECTRAL_NM = np.arange(380.0, 800.0, 10.0)  # 42: fourteen builds of three
# CIE XYZ -> linear sRGB (IEC 61966-2-1).
XYZ_TO_SRGB = np.array(
    [[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]]
)


def _bin(table: np.ndarray, nm: np.ndarray) -> np.ndarray:
    return np.interp(nm, SPECTRUM_FROM_NM + 10.0 * np.arange(len(table)), table)


def cie_1931(nm: np.ndarray) -> np.ndarray:
    """The CIE 1931 2-degree colour-matching functions (n, 3): Wyman, Sloan and Shirley's
    (2013) multi-lobe fit (within about 1 % of the tables)."""

    def g(mu: float, s1: float, s2: float) -> np.ndarray:
        s = np.where(nm < mu, s1, s2)
        out: np.ndarray = np.exp(-0.5 * ((nm - mu) / s) ** 2)
        return out

    x = 1.056 * g(599.8, 37.9, 31.0) + 0.362 * g(442.0, 16.0, 26.7) - 0.065 * g(501.1, 20.4, 26.2)
    y = 0.821 * g(568.8, 46.9, 40.5) + 0.286 * g(530.9, 16.3, 31.1)
    z = 1.217 * g(437.0, 11.8, 36.0) + 0.681 * g(459.0, 26.0, 13.8)
    return np.stack([x, y, z], axis=-1)


def srgb_of_spectrum(relative: np.ndarray, nm: np.ndarray = SPECTRAL_NM) -> np.ndarray:
    """(..., n) radiance per unit sun irradiance at wavelengths nm -> (..., 3) linear sRGB
    per unit sun, white-balanced so that the sun above the air is (1, 1, 1)."""
    sun = _bin(SOLAR_W_M2_NM, nm)
    cmf = cie_1931(nm)
    rgb = (relative * sun) @ cmf @ XYZ_TO_SRGB.T
    white = sun @ cmf @ XYZ_TO_SRGB.T
    out: np.ndarray = rgb / white
    return out


def _sun(elevation_deg: float) -> np.ndarray:
    e = math.radians(elevation_deg)
    return np.array([0.0, math.cos(e), math.sin(e)])  # due north


def _direction(elevation_deg: float, azimuth_from_sun_deg: float) -> np.ndarray:
    e, a = math.radians(elevation_deg), math.radians(azimuth_from_sun_deg)
    return np.array([math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e)])


def _panorama(luts: atm.AtmosphereLuts, sun: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = PANORAMA_PX
    el = np.radians(90.0 - (np.arange(rows) + 0.5) * 90.0 / rows)  # top row near the zenith
    az = np.radians((np.arange(cols) + 0.5) * 360.0 / cols - 180.0)  # the sun in the middle
    e, a = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1)
    zenith = float(luts.radiance(np.array([0.0, 0.0, 1.0]), sun) @ cie_sky.LUMA)
    model = (luts.radiance(d.reshape(-1, 3), sun) @ cie_sky.LUMA).reshape(rows, cols) / zenith
    ref = cie_sky.relative_luminance(cie_sky.CLEAR_LOW_TURBIDITY, d, sun)
    return model, ref


def _grey(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    t = (np.log(np.maximum(values, 1e-9)) - math.log(lo)) / (math.log(hi) - math.log(lo))
    g = (np.clip(t, 0.0, 1.0) * 255.0).astype(np.uint8)
    return np.stack([g, g, g, np.full_like(g, 255)], axis=-1)


def cie_table(png: Path | None, png_visibility_m: float) -> None:
    dirs = cie_sky.hemisphere_directions()
    print(f"CIE S 011 type 12 against the model: {len(dirs)} directions, elevation 5-80 deg")
    print("visibility_m  sun_deg  median  p90    build_ms (medium + sky view)")
    panels = []
    for vis in VISIBILITIES_M:
        atm._medium_tables = None  # time the medium's tables once per visibility
        for sun_deg in SUN_ELEVATIONS_DEG:
            key = atm.atmosphere_key(sun_deg, vis, 50.0, 2.0)
            start = time.perf_counter()
            luts = atm.build_luts(key)
            build_ms = (time.perf_counter() - start) * 1000.0
            sun = _sun(sun_deg)
            zenith = float(luts.radiance(np.array([0.0, 0.0, 1.0]), sun) @ cie_sky.LUMA)
            lum = luts.radiance(dirs, sun) @ cie_sky.LUMA
            result = cie_sky.compare(lum, zenith, dirs, sun)
            print(
                f"{vis:12.0f}  {sun_deg:7.0f}  {result.median:6.3f}  {result.p90:5.3f}  "
                f"{build_ms:8.0f}"
            )
            if png is not None and vis == png_visibility_m:
                model, ref = _panorama(luts, sun)
                gap = np.full((PANORAMA_PX[0], 4, 4), 255, np.uint8)
                panels.append(
                    np.concatenate(
                        [
                            _grey(model, 0.25, 16.0),
                            gap,
                            _grey(ref, 0.25, 16.0),
                            gap,
                            _grey(model / ref, 0.5, 2.0),
                        ],
                        axis=1,
                    )
                )
    if png is not None and panels:
        bar = np.full((4, panels[0].shape[1], 4), 255, np.uint8)
        sheet = np.concatenate([p for panel in panels for p in (panel, bar)][:-1], axis=0)
        write_png(png, np.ascontiguousarray(sheet))
        print(f"wrote {png}: per sun (10, 30, 60 deg, top down): model | CIE | ratio")


# -- colours ---------------------------------------------------------------------------------


def _away_bands(luts: atm.AtmosphereLuts, sun: np.ndarray) -> tuple[float, float]:
    """R/B of the sky facing away from the sun (azimuth 150-210 from it) 5-15 and 35-45 deg
    up, as tests/test_atmosphere.py measures the Belt of Venus."""

    def band(lo: float, hi: float) -> float:
        dirs = np.array(
            [_direction(e, a) for e in np.linspace(lo, hi, 6) for a in np.linspace(150, 210, 13)]
        )
        rgb = luts.radiance(dirs, sun)
        return float(rgb[:, 0].mean() / rgb[:, 2].mean())

    return band(5.0, 15.0), band(35.0, 45.0)


def colour_table(label: str) -> None:
    print(f"zenith colour ({label}): {COLOUR_VISIBILITY_M / 1000:.0f} km, "
          f"{COLOUR_HUMIDITY_PCT:.0f} % humidity, eye {COLOUR_EYE_M:.0f} m")  # fmt: skip
    print("moment   sun  zenith kcd/m^2 (R, G, B)     B/R   display (R, G, B)    "
          "away R/B 5-15 | 35-45")  # fmt: skip
    for name, sun_deg in COLOUR_MOMENTS:
        luts = atm.build_luts(
            atm.atmosphere_key(sun_deg, COLOUR_VISIBILITY_M, COLOUR_HUMIDITY_PCT, COLOUR_EYE_M)
        )
        sun = _sun(sun_deg)
        z = luts.radiance(np.array([0.0, 0.0, 1.0]), sun)
        shown = display(z, atm.display_exposure(luts))
        low, high = _away_bands(luts, sun)
        print(
            f"{name:7s} {sun_deg:4.0f}  ({z[0]:.3g}, {z[1]:.3g}, {z[2]:.3g})".ljust(45)
            + f"{z[2] / z[0]:5.2f}  ({shown[0]:.2f}, {shown[1]:.2f}, {shown[2]:.2f})"
            + f"   {low:5.2f} | {high:5.2f}"
        )


# -- the noon zenith, term by term -----------------------------------------------------------


def _march(
    med: atm.Medium,
    t_table: np.ndarray,
    ms_table: np.ndarray | None,
    sun_deg: float,
    dirs: list[tuple[float, float]],
    mie_share: float | None = None,
) -> np.ndarray:
    """Radiance per unit sun irradiance (n, 3) marched straight from the eye (COLOUR_EYE_M)
    in directions (elevation, azimuth from the sun) in degrees (no table between), as the
    sky view marches (the aerosol's lobe less its peak, unless mie_share says otherwise)."""
    share = 1.0 - atm.MIE_PEAK_SHARE if mie_share is None else mie_share
    el = np.radians([d[0] for d in dirs])
    az = np.radians([d[1] for d in dirs])
    s = math.radians(sun_deg)
    r = np.full(len(dirs), atm.EARTH_RADIUS_M + max(COLOUR_EYE_M, 1.0))
    nu = np.cos(el) * np.cos(az) * math.cos(s) + np.sin(el) * math.sin(s)
    m = atm._march(
        med, t_table, ms_table, r, np.sin(el), np.full(len(dirs), math.sin(s)), nu,
        atm.SKY_VIEW_STEPS, mie_share=share,
    )  # fmt: skip
    out: np.ndarray = m.luminance
    return out


def _fmt(rgb: np.ndarray) -> str:
    return f"({rgb[0]:.3g}, {rgb[1]:.3g}, {rgb[2]:.3g})  B/R {rgb[2] / rgb[0]:.2f}"


def terms() -> None:
    from wxsky.scene.sky import aureole

    sun_deg = 60.0
    key = atm.atmosphere_key(sun_deg, COLOUR_VISIBILITY_M, COLOUR_HUMIDITY_PCT, COLOUR_EYE_M)
    luts = atm.build_luts(key)
    med = luts.medium
    sun_rgb = atm._sun_rgb()
    zen = [(90.0, 0.0)]
    print(f"the noon zenith (sun {sun_deg:.0f} deg, 30 km, 60 %), kcd/m^2, linear sRGB primaries")
    table = luts.radiance(np.array([0.0, 0.0, 1.0]), _sun(sun_deg))
    print(f"  the table, as the sky pass samples it  {_fmt(table)}")
    full = _march(med, luts.transmittance, luts.multiscatter, sun_deg, zen)[0] * sun_rgb
    print(f"  marched (single + multiple)            {_fmt(full)}")
    whole = _march(med, luts.transmittance, luts.multiscatter, sun_deg, zen, 1.0)[0] * sun_rgb
    print(f"  with the aureole's peak in the lobe    {_fmt(whole)}")
    single = _march(med, luts.transmittance, None, sun_deg, zen)[0] * sun_rgb
    print(f"  single scattering only                 {_fmt(single)}")
    print(f"  multiple scattering's share            {_fmt(full - single)}")
    clean = dataclasses.replace(med, mie_extinction_per_m=0.0)
    t_clean = atm.transmittance_table(clean)
    ms_clean = atm.multiscatter_table(clean, t_clean)
    rayleigh = _march(clean, t_clean, ms_clean, sun_deg, zen)[0] * sun_rgb
    print(f"  Rayleigh (and ozone) alone             {_fmt(rayleigh)}")
    print(f"  so the aerosol's share                 {_fmt(full - rayleigh)}")
    saved = atm.OZONE_ABSORPTION_PER_M
    try:
        atm.OZONE_ABSORPTION_PER_M = np.zeros(3)
        t_no = atm.transmittance_table(med)
        no_ozone = _march(med, t_no, atm.multiscatter_table(med, t_no), sun_deg, zen)[0]
    finally:
        atm.OZONE_ABSORPTION_PER_M = saved
    print(f"  without ozone                          {_fmt(no_ozone * sun_rgb)}")
    grey_med = dataclasses.replace(med, mie_angstrom=0.0)
    t_grey = atm.transmittance_table(grey_med)
    ms_grey = atm.multiscatter_table(grey_med, t_grey)
    grey = _march(grey_med, t_grey, ms_grey, sun_deg, zen)[0]
    grey_whole = _march(grey_med, t_grey, ms_grey, sun_deg, zen, 1.0)
    print(f"  a grey aerosol (Angstrom 0)            {_fmt(grey * sun_rgb)}")
    print(f"  grey and the whole lobe (before's)     {_fmt(grey_whole[0] * sun_rgb)}")
    strength, g = aureole(luts)
    nu = math.sin(math.radians(sun_deg))
    k = 1.0 + g * g - 2.0 * g * nu
    halo = strength * (1.0 - g * g) / (4.0 * math.pi * k * math.sqrt(k))
    share = float(halo @ atm.LUMA / (table @ atm.LUMA))
    print(f"  the sky pass's aureole added there     {_fmt(halo)}: {share:.1%} of the luminance")
    shown = display(table, atm.display_exposure(luts))
    print(f"  shown (exposure {atm.display_exposure(luts):.4f}, the one tone map): "
          f"({shown[0]:.2f}, {shown[1]:.2f}, {shown[2]:.2f})")  # fmt: skip


# -- the spectral reference ------------------------------------------------------------------


@contextlib.contextmanager
def _coefficients(nm: np.ndarray, angstrom: float) -> Iterator[None]:
    """The model's three channels set to the wavelengths nm (three), for a build."""
    saved = (atm.RAYLEIGH_SCATTERING_PER_M, atm.OZONE_ABSORPTION_PER_M, atm.CHANNEL_NM)
    try:
        atm.RAYLEIGH_SCATTERING_PER_M = RAYLEIGH_AT_1UM_PER_M * (nm / 1000.0) ** -4
        atm.OZONE_ABSORPTION_PER_M = OZONE_PEAK_PER_M3 * _bin(OZONE_M2, nm)
        atm.CHANNEL_NM = nm
        yield
    finally:
        atm.RAYLEIGH_SCATTERING_PER_M, atm.OZONE_ABSORPTION_PER_M, atm.CHANNEL_NM = saved


SPECTRAL_DIRECTIONS = [(90.0, 0.0), (10.0, 180.0), (40.0, 180.0)]  # zenith; away 10, 40 up


def spectral_sky(angstrom: float) -> np.ndarray:
    """(moments, SPECTRAL_DIRECTIONS, 3) linear sRGB per unit sun of the spectral model."""
    med = atm.medium(COLOUR_VISIBILITY_M, COLOUR_HUMIDITY_PCT)  # 550 nm's aerosol
    med = dataclasses.replace(med, mie_angstrom=angstrom)
    out = np.zeros((len(COLOUR_MOMENTS), len(SPECTRAL_DIRECTIONS), len(SPECTRAL_NM)))
    for i in range(0, len(SPECTRAL_NM), 3):
        nm = SPECTRAL_NM[i : i + 3]
        with _coefficients(nm, angstrom):
            t_table = atm.transmittance_table(med)
            ms_table = atm.multiscatter_table(med, t_table)
            for k, (_, sun_deg) in enumerate(COLOUR_MOMENTS):
                out[k, :, i : i + 3] = _march(med, t_table, ms_table, sun_deg, SPECTRAL_DIRECTIONS)
    return srgb_of_spectrum(out)


def three_channel_sky() -> np.ndarray:
    """The same directions marched by the three-channel model itself (no table between)."""
    med = atm.medium(COLOUR_VISIBILITY_M, COLOUR_HUMIDITY_PCT)
    t_table = atm.transmittance_table(med)
    ms_table = atm.multiscatter_table(med, t_table)
    return np.stack(
        [_march(med, t_table, ms_table, s, SPECTRAL_DIRECTIONS) for _, s in COLOUR_MOMENTS]
    )


def spectral(angstroms: tuple[float, ...]) -> None:
    print("zenith B/R and away R/B (10 | 40 deg up) of the model in three channels against the")
    print("same model at 42 wavelengths through the CIE observer (linear sRGB, sun-white):")
    rows = {"three channels": three_channel_sky()}
    for a in angstroms:
        rows[f"spectral, Angstrom {a:.2f}"] = spectral_sky(a)
    print("".ljust(26) + "".join(f"{name:>20s}" for name, _ in COLOUR_MOMENTS))
    for label, rgb in rows.items():
        cells = [
            f"{rgb[k, 0, 2] / rgb[k, 0, 0]:5.2f} {rgb[k, 1, 0] / rgb[k, 1, 2]:5.2f}|"
            f"{rgb[k, 2, 0] / rgb[k, 2, 2]:4.2f}"
            for k in range(len(COLOUR_MOMENTS))
        ]
        print(label.ljust(26) + "".join(f"{c:>20s}" for c in cells))
    print("zenith, normalised to its largest channel:")
    for label, rgb in rows.items():
        cells = [
            "(" + ", ".join(f"{v:.2f}" for v in rgb[k, 0] / rgb[k, 0].max()) + ")"
            for k in range(len(COLOUR_MOMENTS))
        ]
        print(label.ljust(26) + "".join(f"{c:>20s}" for c in cells))


def ozone_channels() -> None:
    """The ozone absorption per sRGB channel: the channel's transmittance through `m` ozone
    columns for the light of a Rayleigh sky (the sun's spectrum x lambda^-4), through the CIE
    observer, as an absorption coefficient at the tent's peak (what OZONE_ABSORPTION_PER_M
    holds), against the model's single wavelengths."""
    nm = np.arange(380.0, 781.0, 5.0)
    sky = _bin(SOLAR_W_M2_NM, nm) * (nm / 550.0) ** -4
    channel = cie_1931(nm) @ XYZ_TO_SRGB.T  # (n, 3): each channel's weight per wavelength
    column_per_m2 = OZONE_PEAK_PER_M3 * 15_000.0
    sigma = _bin(OZONE_M2, nm)
    print("ozone absorption at the peak, 1e-6 /m (R, G, B); the model has "
          + ", ".join(f"{v * 1e6:.3f}" for v in atm.OZONE_ABSORPTION_PER_M))  # fmt: skip
    for m in (1.0, 5.0, 20.0, 40.0):
        t = np.exp(-sigma * column_per_m2 * m)
        kept = (sky * t) @ channel / (sky @ channel)
        eff = -np.log(np.clip(kept, 1e-9, None)) / (column_per_m2 * m) * OZONE_PEAK_PER_M3
        print(f"  through {m:4.0f} columns: " + ", ".join(f"{v * 1e6:.3f}" for v in eff))


def med_angstrom() -> float:
    return atm.medium(COLOUR_VISIBILITY_M, COLOUR_HUMIDITY_PCT).mie_angstrom


def fit_ozone() -> None:
    """The three channels' ozone absorption (R, G; B's is negligible) that makes their
    twilight zenith (sun -4 and -10 deg) the colour the spectral model gives it: a grid over
    multiples of the single wavelengths' values, the error that of ln(R/B) and ln(G/B)."""
    twilight = [k for k, (_, s) in enumerate(COLOUR_MOMENTS) if s < 0.0]
    ref = spectral_sky(med_angstrom())[twilight, 0]
    want = np.log(ref[:, :2] / ref[:, 2:])
    med = atm.medium(COLOUR_VISIBILITY_M, COLOUR_HUMIDITY_PCT)
    base = OZONE_PEAK_PER_M3 * _bin(OZONE_M2, atm.CHANNEL_NM)
    print("spectral twilight zenith ln(R/B), ln(G/B): " + "; ".join(
        f"{a:.2f}, {b:.2f}" for a, b in want))  # fmt: skip
    best: tuple[float, np.ndarray] | None = None
    saved = atm.OZONE_ABSORPTION_PER_M
    try:
        for kr in (1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0):
            for kg in (0.6, 0.8, 1.0, 1.2, 1.4):
                ozone = base * np.array([kr, kg, 1.0])
                atm.OZONE_ABSORPTION_PER_M = ozone
                t_table = atm.transmittance_table(med)
                ms_table = atm.multiscatter_table(med, t_table)
                got = np.stack(
                    [
                        _march(med, t_table, ms_table, COLOUR_MOMENTS[k][1], [(90.0, 0.0)])[0]
                        for k in twilight
                    ]
                )
                err = float(np.sum((np.log(got[:, :2] / got[:, 2:]) - want) ** 2))
                print(f"  R x{kr:.1f} G x{kg:.1f}: error {err:.4f}")
                if best is None or err < best[0]:
                    best = (err, ozone)
    finally:
        atm.OZONE_ABSORPTION_PER_M = saved
    assert best is not None
    print(f"best: {', '.join(f'{v * 1e6:.3f}' for v in best[1])} e-6 /m (error {best[0]:.4f})")


# -- build time ------------------------------------------------------------------------------


def build_time(runs: int = 5) -> tuple[float, float]:
    """Median ms of build_luts for a new medium (all four tables) and for a new sun."""
    full, view = [], []
    for i in range(runs):
        atm._medium_tables = None
        start = time.perf_counter()
        atm.build_luts(atm.atmosphere_key(30.0 + i, 30_000.0 + 2_000.0 * i, 50.0, 2.0))
        full.append(time.perf_counter() - start)
        start = time.perf_counter()
        atm.build_luts(atm.atmosphere_key(45.0 + i, 30_000.0 + 2_000.0 * i, 50.0, 2.0))
        view.append(time.perf_counter() - start)
    return float(np.median(full) * 1000.0), float(np.median(view) * 1000.0)


@contextlib.contextmanager
def _worktree(ref: str) -> Iterator[Path]:
    """REF checked out, detached, in a temporary worktree, removed afterwards."""
    path = Path(tempfile.mkdtemp(prefix="cie-sky-")) / "tree"
    subprocess.run(["git", "worktree", "add", "--detach", "-q", str(path), ref], cwd=ROOT,
                   check=True)  # fmt: skip
    try:
        yield path
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(path)], cwd=ROOT,
                       check=False)  # fmt: skip


def _run_in(tree: Path, *flags: str) -> str:
    env = dict(os.environ, WXSKY_BENCH_ROOT=str(tree), PYTHONPATH=str(tree))
    done = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), *flags, "--label", "before"],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return done.stdout


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--png", type=Path, help="write the model-against-CIE picture here")
    parser.add_argument("--png-visibility-m", type=float, default=30_000.0)
    parser.add_argument("--colours", action="store_true", help="the zenith colour table")
    parser.add_argument("--terms", action="store_true", help="the noon zenith term by term")
    parser.add_argument("--spectral", action="store_true", help="against the spectral model")
    parser.add_argument("--ozone", action="store_true", help="ozone absorption per channel")
    parser.add_argument("--fit-ozone", action="store_true", help="fit it to the spectral model")
    parser.add_argument("--build-time", action="store_true", help="median build_luts times")
    parser.add_argument("--before", metavar="REF", help="also REF's --colours / --build-time")
    parser.add_argument("--label", default="this checkout", help=argparse.SUPPRESS)
    args = parser.parse_args()
    label = args.label
    chosen = (
        args.colours or args.terms or args.spectral or args.ozone or args.fit_ozone
        or args.build_time
    )  # fmt: skip
    if not chosen:
        cie_table(args.png, args.png_visibility_m)
    if args.colours:
        if args.before:
            with _worktree(args.before) as tree:
                print(_run_in(tree, "--colours").replace("(before)", f"({args.before})"), end="")
        colour_table(label)
    if args.terms:
        terms()
    if args.spectral:
        spectral((0.0, atm.medium(COLOUR_VISIBILITY_M, COLOUR_HUMIDITY_PCT).mie_angstrom))
    if args.ozone:
        ozone_channels()
    if args.fit_ozone:
        fit_ozone()
    if args.build_time:
        if args.before:
            with _worktree(args.before) as tree:
                for _ in range(2):  # alternating, so a change of load hits both alike
                    print(_run_in(tree, "--build-time"), end="")
                    full_ms, view_ms = build_time()
                    print(f"{label}: medium + sky view {full_ms:.0f} ms, "
                          f"sky view alone {view_ms:.0f} ms")  # fmt: skip
        else:
            full_ms, view_ms = build_time()
            print(f"{label}: medium + sky view {full_ms:.0f} ms, sky view alone {view_ms:.0f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
