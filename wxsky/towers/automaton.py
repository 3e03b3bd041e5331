"""Dobashi's cellular automaton for cloud volumes (Dobashi et al., SIGGRAPH 2000, which
Domański's flat-3D-texture clouds take their volumes from: seed 002, section 3).

Every cell of a (nz, ny, nx) grid, z up, holds three bits: vapour (`hum`), a phase-transition
trigger (`act`) and cloud (`cld`). One step applies the growth rules

    hum' = hum and not act
    cld' = cld or act
    act' = not act and hum and f_act

where f_act is true when an `act` neighbour is one cell away along x, y or z, two cells away
along x or y, or two cells *below* (so activity, and the cloud behind it, climbs), and then
extinction and supply (Dobashi's section 4.2): a cloud cell vanishes with probability p_ext,
vapour and triggers appear with p_hum and p_act. Those odds are fields, shaped by ellipsoids
stacked upward as a tower grows (`tower_ellipsoids`). docs/towers.md says which details we
chose where the published versions differ, and why.

The randomness is one numpy PCG64 stream per convective cell, seeded from the weather's seed,
the block and the cell (`cell_rng`): the same volume in every process and on every machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

B = npt.NDArray[np.bool_]
F32 = npt.NDArray[np.float32]

# A tag in every tower seed, so a tower's stream never equals another user of the same key.
_TOWER_STREAM = 0x70_77_65_72  # "towr"
# Dobashi's continuous density: the 0/1 cloud field under a small smoothing filter. A binomial
# 5-tap kernel along each axis (a separable stand-in for his weighted sphere of radius 2).
BUBBLES = 7  # levels of bubbles stacked up a full-grown tower
ANVIL_COLUMN_SHARE = 0.5  # a cumulonimbus's column against its box, over a plain tower's
ANVIL_FROM = 0.7  # the maturity at which its anvil starts to spread
SMOOTH_KERNEL = (1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0)


@dataclass(frozen=True)
class Cells:
    """One state of the automaton: three (nz, ny, nx) boolean fields, z up, and its step."""

    hum: B
    act: B
    cld: B
    step: int = 0

    @staticmethod
    def empty(shape: tuple[int, int, int]) -> Cells:
        return Cells(
            np.zeros(shape, np.bool_), np.zeros(shape, np.bool_), np.zeros(shape, np.bool_)
        )

    @property
    def shape(self) -> tuple[int, int, int]:
        nz, ny, nx = self.cld.shape
        return (nz, ny, nx)

    @property
    def cloud_cells(self) -> int:
        return int(np.count_nonzero(self.cld))


@dataclass(frozen=True)
class Odds:
    """The probabilities of one step's extinction and supply: per cell, (nz, ny, nx) float32
    in 0..1, or one number for every cell."""

    hum: F32 | float
    act: F32 | float
    ext: F32 | float


@dataclass(frozen=True)
class Ellipsoid:
    """An ellipsoid in grid cells: its centre (x, y, z), its semi-axes, and the weight at its
    centre (a bubble growing in starts weak as well as small)."""

    centre: tuple[float, float, float]
    radii: tuple[float, float, float]
    strength: float = 1.0


def activation(act: B) -> B:
    """Dobashi's f_act for every cell: an active neighbour at ±1 along x, y and z, at ±2 along
    x and y, or 2 cells below. Cells beyond the grid are inactive."""
    f = np.zeros_like(act)
    f[:, :, 1:] |= act[:, :, :-1]
    f[:, :, :-1] |= act[:, :, 1:]
    f[:, :, 2:] |= act[:, :, :-2]
    f[:, :, :-2] |= act[:, :, 2:]
    f[:, 1:, :] |= act[:, :-1, :]
    f[:, :-1, :] |= act[:, 1:, :]
    f[:, 2:, :] |= act[:, :-2, :]
    f[:, :-2, :] |= act[:, 2:, :]
    f[1:, :, :] |= act[:-1, :, :]
    f[:-1, :, :] |= act[1:, :, :]
    f[2:, :, :] |= act[:-2, :, :]  # the trigger two cells below: activity climbs
    return f


def grow(cells: Cells) -> Cells:
    """The growth rules alone (no randomness): one step of Dobashi's automaton."""
    f = activation(cells.act)
    return Cells(
        hum=cells.hum & ~cells.act,
        act=~cells.act & cells.hum & f,
        cld=cells.cld | cells.act,
        step=cells.step + 1,
    )


def step(cells: Cells, odds: Odds, rng: np.random.Generator) -> Cells:
    """One step: growth, then extinction (cloud cells vanish with p_ext), then supply (vapour
    with p_hum, triggers with p_act). Draws three float32 per cell, always in that order, so a
    stream gives the same volume whatever the odds are."""
    grown = grow(cells)
    draws = rng.random((3, *cells.shape), dtype=np.float32)
    return Cells(
        hum=grown.hum | (draws[1] < odds.hum),
        act=grown.act | (draws[2] < odds.act),
        cld=grown.cld & ~(draws[0] < odds.ext),
        step=grown.step,
    )


def cell_rng(
    weather_seed: int, block: tuple[int, int], cell: int, stream: int = 0
) -> np.random.Generator:
    """A random stream of one convective cell: the weather's seed, the block (east, north
    index) and the cell's number in it; `stream` 0 is the automaton's draws, others the
    cell's other choices. Negative indices are folded into 32 bits."""
    mask = 0xFFFF_FFFF
    key = [_TOWER_STREAM, weather_seed & mask, block[0] & mask, block[1] & mask, cell & mask]
    key.append(stream & mask)
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(key)))


def ellipsoid_weight(shape: tuple[int, int, int], ellipsoids: tuple[Ellipsoid, ...]) -> F32:
    """(nz, ny, nx) in 0..1: an ellipsoid's strength at its centre, falling as sqrt(1 - r²)
    to 0 at its surface (r its normalised radius), the largest over the ellipsoids; 0 outside
    them. The square root keeps a bubble full almost to its rim, so where two overlap the
    odds do not sag into a seam."""
    nz, ny, nx = shape
    z = np.arange(nz, dtype=np.float32)[:, None, None]
    y = np.arange(ny, dtype=np.float32)[None, :, None]
    x = np.arange(nx, dtype=np.float32)[None, None, :]
    out = np.zeros(shape, np.float32)
    for e in ellipsoids:
        (cx, cy, cz), (rx, ry, rz) = e.centre, e.radii
        # Only the cells of its bounding box can be inside it (the same values, a fraction
        # of the work: most bubbles are small against the grid).
        zs, ys, xs = (
            slice(max(0, math.floor(c - r)), min(n, math.ceil(c + r) + 1))
            for c, r, n in ((cz, rz, nz), (cy, ry, ny), (cx, rx, nx))
        )
        if zs.start >= zs.stop or ys.start >= ys.stop or xs.start >= xs.stop:
            continue
        r2 = ((x[..., xs] - cx) / rx) ** 2 + ((y[:, ys] - cy) / ry) ** 2 + ((z[zs] - cz) / rz) ** 2
        inside = np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))  # full bodies: no seam between bubbles
        part = out[zs, ys, xs]
        np.maximum(part, np.float32(e.strength) * inside, out=part)
    return out


def tower_odds(
    weight: F32, *, hum: float, act: float, ext_inside: float, ext_outside: float
) -> Odds:
    """Dobashi's shaping: vapour and triggers supplied in proportion to the ellipsoid weight
    (most at the centres), extinction from `ext_outside` outside every ellipsoid down to
    `ext_inside` at a centre. Outside, nothing is supplied and cloud decays."""
    return Odds(
        hum=(hum * weight).astype(np.float32),
        act=(act * weight).astype(np.float32),
        ext=(ext_outside + (ext_inside - ext_outside) * weight).astype(np.float32),
    )


def tower_ellipsoids(
    shape: tuple[int, int, int],
    maturity: float,
    turrets: F32 | None = None,
    anvil: bool = False,
) -> tuple[Ellipsoid, ...]:
    """A tower's ellipsoids at `maturity` 0..1: a broad bubble at the base, then bubbles
    stacked upward, narrower and pushed a little sideways, each with a smaller one bulging
    from its flank (the turrets and cauliflower lumps), as many levels as maturity has grown;
    the newest grows in from nothing, so the odds never jump. `turrets`: (K, 4) in -1..1 from
    the cell's stream (per level: sideways lean x and y, size, the lump's bearing); none: a
    plain column. `anvil` (a cumulonimbus): the column takes ANVIL_COLUMN_SHARE of the width
    a plain tower does (its box is that much wider) and, from ANVIL_FROM of maturity on, a
    broad flat bubble spreads at its top: the anvil under the tropopause."""
    nz, ny, nx = shape
    column = ANVIL_COLUMN_SHARE if anvil else 1.0
    levels = BUBBLES if turrets is None else len(turrets)
    grown = min(max(maturity, 0.0), 1.0) * levels
    rise = 0.85 * nz / levels  # each level's share of the tower's height
    out = []
    for k in range(levels):
        part = min(1.0, grown - k)  # the newest level swells in with its share of the growth
        if part <= 0.0:
            break
        dx, dy, size, bearing = (0.0, 0.0, 0.0, 0.0) if turrets is None else turrets[k]
        shrink = (1.0 - 0.45 * k / max(levels - 1, 1)) * (1.0 + 0.15 * float(size))
        lean = 0.3 * column * k / levels  # levels wander off the column as they climb
        cx = 0.5 * nx * (1.0 + float(dx) * lean)
        cy = 0.5 * ny * (1.0 + float(dy) * lean)
        # It grows up from inside the one below it, weak and small at first; grown, it
        # overlaps its neighbours by half, so the tower is one body.
        cz = 2.0 + (k + 0.5 * part) * rise
        rx, ry = 0.3 * column * nx * shrink * part, 0.3 * column * ny * shrink * part
        rz = (0.85 * rise + 1.0) * part
        out.append(Ellipsoid(centre=(cx, cy, cz), radii=(rx, ry, rz), strength=part))
        if turrets is not None:
            # A lump half the size on the level's flank, a little lower: breaks the rim.
            a = math.pi * float(bearing)
            out.append(
                Ellipsoid(
                    centre=(
                        cx + 0.8 * rx * math.cos(a),
                        cy + 0.8 * ry * math.sin(a),
                        cz - 0.2 * rz,
                    ),
                    radii=(0.5 * rx, 0.5 * ry, 0.6 * rz),
                    strength=part,
                )
            )
    if anvil and maturity > ANVIL_FROM:
        spread = min(1.0, (maturity - ANVIL_FROM) / (1.0 - ANVIL_FROM))
        out.append(
            Ellipsoid(
                centre=(0.5 * nx, 0.5 * ny, 0.86 * nz),
                radii=(0.46 * nx * spread, 0.46 * ny * spread, 0.05 * nz + 1.5),
                strength=spread,
            )
        )
    return tuple(out)


def smoothed(cld: B) -> F32:
    """Dobashi's continuous density: the 0/1 cloud field under SMOOTH_KERNEL along each axis
    (zero beyond the grid), 0..1."""
    out = cld.astype(np.float32)
    for axis in range(3):
        out = _filter_axis(out, axis)
    return out


def flat_based(density: F32, rows: int) -> F32:
    """The density with a flat base: in the lowest `rows` rows each column holds the most
    cloud it has from there up to the top of that band, so the band's widest part reaches
    straight down to the grid's floor (the condensation level) and is cut flat there. The
    automaton grows a rounded blob from its bubbles (and the smoothing rounds its floor
    more), where a cumulus is one flat base with the cloud standing on it (issue 42)."""
    if rows <= 0:
        return density
    out = density.copy()
    band = out[:rows][::-1]
    np.maximum.accumulate(band, axis=0, out=band)
    return out


def density_between(before: B, after: B, frac: float) -> F32:
    """The density a fraction `frac` of the way from one state's cloud to the next one's:
    growth looks continuous, not stepwise."""
    t = np.float32(min(max(frac, 0.0), 1.0))
    out: F32 = (np.float32(1.0) - t) * smoothed(before) + t * smoothed(after)
    return out


def _filter_axis(field: F32, axis: int) -> F32:
    n = field.shape[axis]
    half = len(SMOOTH_KERNEL) // 2
    pad = [(0, 0)] * 3
    pad[axis] = (half, half)
    padded = np.pad(field, pad)
    out = np.zeros_like(field)
    for k, w in enumerate(SMOOTH_KERNEL):
        index = [slice(None)] * 3
        index[axis] = slice(k, k + n)
        out += np.float32(w) * padded[tuple(index)]
    return out
