"""The one generator of the sky pass's texture images, from fixed seeds (Roden & Parberry).

`build_sky_textures` makes every image, (H, W, 4) uint8 as shipped, by file name;
`tools/generate/build_sky_textures.py` writes them to `data/sky_*.png`, and
`wxsky.render.sky_textures` (which says what each channel means to the shader) only loads
them. Numpy only: seeded PCG64 streams and float64 maths quantised to 8 bits at the end, so
every machine makes the same bytes (the tool's `--check` would say if one did not).

- stars: a share of the cube-map cells hold a star, three times as many along the Milky Way,
  with power-law brightnesses, flicker rates, variances and phases.
- galaxy: the glow of the galactic plane, wider and brighter at the bulge, with a dark rift.
- dome noise: three tileable spectral-noise fields of different roughness and the finest
  drawn out into fibres.
- sunset: the dome cloud's tint at dusk, a smooth gradient over the `sunset` control and the
  height in the sky (see `_make_sunset` for its axes and colours); no noise.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

U8 = npt.NDArray[np.uint8]
F64 = npt.NDArray[np.float64]

STAR_FACE_PX = 256  # cells along a cube face: 0.35° each
GALAXY_SIZE_PX = (512, 256)  # longitude, latitude
DOME_NOISE_PX = 256
SUNSET_SIZE_PX = (64, 32)  # sunset control, elevation
# Cirrus fibres (the dome noise's A): the detail noise this many times finer across the wind
# (the texture's y) than along it; a whole number, so the fibres tile as the detail does.
FIBRE_ACROSS = 6
FIBRE_CONTRAST = 1.4

SEED_STARS = 0x5EED_57A2
SEED_GALAXY = 0x5EED_6A1A
SEED_DOME = 0x5EED_D0E0

# The images' names, as shipped in wxsky/render/data/.
STAR_FILE = "sky_stars.png"
GALAXY_FILE = "sky_galaxy.png"
DOME_FILE = "sky_dome_noise.png"
SUNSET_FILE = "sky_sunset.png"
SKY_FILES = (STAR_FILE, GALAXY_FILE, DOME_FILE, SUNSET_FILE)

# J2000 equatorial to galactic (rows: galactic x towards the centre, y, z to the north pole).
GALACTIC_FROM_EQUATORIAL = np.array(
    [
        [-0.0548755604, -0.8734370902, -0.4838350155],
        [0.4941094279, -0.4448296300, 0.7469822445],
        [-0.8676661490, -0.1980763734, 0.4559837762],
    ]
)

# Each cube face: the major axis and the two axes its (u, v) run along, as the shader has them.
_FACES = (
    ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    ((-1, 0, 0), (0, 1, 0), (0, 0, 1)),
    ((0, 1, 0), (1, 0, 0), (0, 0, 1)),
    ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
    ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
    ((0, 0, -1), (1, 0, 0), (0, 1, 0)),
)


def build_sky_textures() -> dict[str, U8]:
    """The one generator: every sky file's image, (H, W, 4) uint8 as shipped, by file name.
    Deterministic (seeded PCG64, numpy only), about 0.1 s."""
    galaxy = _make_galaxy()
    return {
        STAR_FILE: _make_stars(galaxy),
        GALAXY_FILE: np.concatenate(
            [np.repeat(galaxy[..., None], 3, axis=-1), np.full((*galaxy.shape, 1), 255, np.uint8)],
            axis=-1,
        ),
        DOME_FILE: _make_dome_noise(),
        SUNSET_FILE: _make_sunset(),
    }


def _make_galaxy() -> U8:
    """(H, W) glow of the Milky Way: columns are galactic longitude -180°..180°, rows
    latitude -90°..90° (row 0 at -90°)."""
    w, h = GALAXY_SIZE_PX
    rng = np.random.default_rng(SEED_GALAXY)
    lon = ((np.arange(w) + 0.5) / w * 360.0 - 180.0)[None, :]
    lat = ((np.arange(h) + 0.5) / h * 180.0 - 90.0)[:, None]
    clumps = _spectral_noise(rng, (h, w), beta=2.4)
    lanes = _spectral_noise(rng, (h, w), beta=2.0)
    # Wider and brighter towards the centre (the bulge), a second bright stretch in Cygnus,
    # fainter towards the anticentre.
    width_deg = 5.0 + 9.0 * np.exp(-((lon / 30.0) ** 2))
    strength = (
        0.35 + 0.65 * np.exp(-((lon / 60.0) ** 2)) + 0.25 * np.exp(-(((lon - 80.0) / 25.0) ** 2))
    )
    band = np.exp(-((lat / width_deg) ** 2)) * strength * (0.35 + 1.1 * clumps)
    # The Great Rift: dust along the plane from Cygnus to Sagittarius.
    rift = np.exp(-(((lat - 1.0) / 2.5) ** 2)) * np.exp(-(((lon - 30.0) / 45.0) ** 2))
    band *= 1.0 - 0.75 * rift * (0.4 + 0.6 * lanes)
    band += 0.12 * np.exp(-((lat / 25.0) ** 2))
    band /= band.max()
    return np.round(np.clip(band, 0.0, 1.0) * 255.0).astype(np.uint8)


def _make_stars(galaxy: U8) -> U8:
    """(6·N, N, 4) star cells, faces stacked (face f's row j at f·N + j, column i), denser
    where `galaxy` (the generated glow) is bright."""
    n = STAR_FACE_PX
    rng = np.random.default_rng(SEED_STARS)
    dirs = cube_cell_directions(n)  # (6, n, n, 3)
    glow = _galaxy_at(dirs.reshape(-1, 3), galaxy).reshape(6, n, n)
    # About 31 000 stars over the sphere, three times as dense along the Milky Way.
    chance = 0.065 + 0.13 * glow
    has_star = rng.random((6, n, n)) < chance
    count = int(has_star.sum())
    # Brightness follows the usual star counts, three times as many stars per magnitude, so
    # N(> I) ~ I^-1.2 between a faint floor and 1 (the power law truncated there, so that
    # only a handful of stars come out at full white).
    floor, slope = 0.028, 1.2
    top = floor**slope
    mean = floor * (1.0 - rng.random(count) * (1.0 - top)) ** (-1.0 / slope)
    rate = rng.uniform(0.15, 1.0, count)
    variance = mean * rng.uniform(0.15, 0.45, count)
    phase = rng.random(count)
    cells = np.zeros((6, n, n, 4), np.uint8)
    values = np.stack([mean, rate, variance, phase], -1)
    packed = np.round(np.clip(values, 0.0, 1.0) * 255.0).astype(np.uint8)
    packed[:, 0] = np.maximum(packed[:, 0], 1)  # a star's R is never 0, which means "none"
    cells[has_star] = packed
    return cells.reshape(6 * n, n, 4)


def _make_dome_noise() -> U8:
    """(N, N, 4) tileable noise: R, G cloud shapes (R is the moon's maria too); B detail;
    A cirrus fibres, the detail drawn out along x (`_fibres`)."""
    n = DOME_NOISE_PX
    rng = np.random.default_rng(SEED_DOME)
    shape1 = _spectral_noise(rng, (n, n), beta=3.0, min_cycles=2)
    shape2 = _spectral_noise(rng, (n, n), beta=2.7, min_cycles=2)
    detail = _spectral_noise(rng, (n, n), beta=2.0, min_cycles=8)
    out = np.stack([shape1, shape2, detail, _fibres(detail, FIBRE_ACROSS)], -1)
    return np.round(out * 255.0).astype(np.uint8)


def _fibres(detail: F64, across: int) -> F64:
    """`detail` at (x, across * y), band-limited (the rows' frequencies past the grid's
    Nyquist left out, not folded back; along x, what the fetch at those coordinates kept),
    about the detail's mean: the fibres the dome once fetched at those coordinates, now in
    the same fetch as the detail (sky.glsl `cloud_dome`; one texture read fewer for every
    dome pixel)."""
    h, w = detail.shape
    spectrum = np.fft.fft2(detail - detail.mean())
    ky = np.fft.fftfreq(h)[:, None] * h
    kx = np.fft.fftfreq(w)[None, :] * w
    # Along x as smooth as the stretched fetch's mip level made it (a level log2(across)
    # coarser: long strands, not grain), across y as fine as the grid holds.
    # A Gaussian roll-off (down to e^-4 at the band's edge) as a mip chain's filtering is,
    # not a brick wall, which rang into ripples beside every strand.
    band = (ky * across / (h / 2)) ** 2 + (kx * across / (w / 2)) ** 2
    weight = np.where(band < 1.0, np.exp(-4.0 * band), 0.0)
    smooth = np.fft.ifft2(spectrum * weight).real
    # Not flattened again: the filtering narrows the values toward the mean as the mip
    # levels did, which is the strands' soft contrast (FIBRE_CONTRAST of it: crisper than
    # the stretched fetch's, which blurred them across the wind too, and no harsher, or
    # they flicker as they drift).
    deviation = FIBRE_CONTRAST * smooth[(np.arange(h) * across) % h]
    result: F64 = np.clip(detail.mean() + deviation, 0.0, 1.0)
    return result


# The sunset gradient's stops (RGB tints, 0..1, as the shader mixes them). With the sun on
# the horizon: deep red-orange low down, where the light reaching the far cloud has crossed the
# most air; orange at mid height (near the hard-coded tint this texture replaced, which is what
# typical dusk views show); pink-magenta high up. While the sun is still well up: golden,
# paler higher up.
SUNSET_HORIZON_RGB = (1.0, 0.34, 0.16)
SUNSET_MID_RGB = (1.0, 0.54, 0.30)
SUNSET_TOP_RGB = (0.94, 0.50, 0.64)
SUNSET_MID_V = 0.45
GOLDEN_HORIZON_RGB = (1.0, 0.76, 0.40)
GOLDEN_TOP_RGB = (1.0, 0.84, 0.58)


def _make_sunset() -> U8:
    """(H, W, 4) Roden & Parberry's sunset gradient, the tint of the dome's cloud at dusk.
    Column i is u = i/(W-1), the `sunset` control (0: golden late afternoon, 1: the sun on
    the horizon); row j is v = j/(H-1), the dome point's height in the sky as
    v = sqrt(sin elevation) (row 0 the horizon, the last row the zenith; the square root gives
    the low sky, where the colour changes fastest, the most rows). RGB is the tint, A = 255:
    how much of it to apply is the shader's (sunset and the direction to the sun). Smooth,
    C1 along both axes, no noise."""
    w, h = SUNSET_SIZE_PX
    u = np.linspace(0.0, 1.0, w)[None, :, None]
    v = np.linspace(0.0, 1.0, h)[:, None, None]
    horizon, mid, top = (
        np.asarray(c) for c in (SUNSET_HORIZON_RGB, SUNSET_MID_RGB, SUNSET_TOP_RGB)
    )
    red = (
        horizon
        + (mid - horizon) * _smoothstep(0.0, SUNSET_MID_V, v)
        + (top - mid) * _smoothstep(SUNSET_MID_V, 1.0, v)
    )
    gold_lo, gold_hi = np.asarray(GOLDEN_HORIZON_RGB), np.asarray(GOLDEN_TOP_RGB)
    golden = gold_lo + (gold_hi - gold_lo) * _smoothstep(0.0, 1.0, v)
    rgb = golden + (red - golden) * _smoothstep(0.0, 1.0, u)
    out = np.full((h, w, 4), 255, np.uint8)
    out[..., :3] = np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
    return out


def _smoothstep(lo: float, hi: float, x: F64) -> F64:
    t = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
    result: F64 = t * t * (3.0 - 2.0 * t)
    return result


def cube_cell_directions(n: int) -> F64:
    """(6, n, n, 3) unit vectors through the cell centres of the equi-angular cube map, indexed
    [face, v, u]; the inverse of sky.glsl's cube_cell."""
    w = ((np.arange(n) + 0.5) / n) * 2.0 - 1.0
    t = np.tan(w * math.pi / 4.0)
    tv, tu = np.meshgrid(t, t, indexing="ij")
    out = np.empty((6, n, n, 3))
    for f, (major, ax_u, ax_v) in enumerate(_FACES):
        v = (
            np.asarray(major, float)[None, None, :]
            + tu[..., None] * np.asarray(ax_u, float)
            + tv[..., None] * np.asarray(ax_v, float)
        )
        out[f] = v / np.linalg.norm(v, axis=-1, keepdims=True)
    return out


def _galaxy_at(celestial: F64, galaxy: U8) -> F64:
    """The galaxy texture's value (0..1) in celestial directions (..., 3), nearest texel."""
    g = celestial @ GALACTIC_FROM_EQUATORIAL.T
    lon = np.degrees(np.arctan2(g[..., 1], g[..., 0]))
    lat = np.degrees(np.arcsin(np.clip(g[..., 2], -1.0, 1.0)))
    w, h = GALAXY_SIZE_PX
    col = np.clip(((lon + 180.0) / 360.0 * w).astype(int), 0, w - 1)
    row = np.clip(((lat + 90.0) / 180.0 * h).astype(int), 0, h - 1)
    result: F64 = galaxy[row, col] / 255.0
    return result


def _spectral_noise(
    rng: np.random.Generator, shape: tuple[int, int], beta: float, min_cycles: int = 1
) -> F64:
    """Tileable noise with a power spectrum falling as f^-beta, flattened to a uniform
    distribution on 0..1 (so a threshold at 1 - x keeps a share x of the texels)."""
    h, w = shape
    fy = np.fft.fftfreq(h)[:, None] * h
    fx = np.fft.rfftfreq(w)[None, :] * w
    f = np.hypot(fx, fy)
    amp = np.where(f >= min_cycles, np.maximum(f, 1e-9) ** (-beta / 2.0), 0.0)
    spectrum = amp * (rng.standard_normal(amp.shape) + 1j * rng.standard_normal(amp.shape))
    field = np.fft.irfft2(spectrum, s=shape)
    ranks = np.empty(field.size)
    ranks[np.argsort(field, axis=None)] = np.arange(field.size)
    result: F64 = (ranks / (field.size - 1)).reshape(shape)
    return result
