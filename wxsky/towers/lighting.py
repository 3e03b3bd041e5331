"""Slice lighting of a tower's density (Domański's Algorithm 1, seed 002, section 5), in numpy.

The volume is cut into slices across the grid axis closest to the light. A buffer of the
light still unabsorbed starts full on the light's side; slice by slice, each cell takes the
light the buffer holds where the light's ray crosses that slice, spread a little over the
neighbouring texels (the algorithm's radius r: light scattered forward leaves its ray at small
angles), and the slice then dims the buffer by what it absorbs. One pass gives the light at
every cell; it is worked out again when the volume or the light moves.
"""

from __future__ import annotations

import numpy as np

from wxsky.towers.automaton import F32

# Extinction per cell of full density, for a 64-cell tower a few kilometres tall (about 50 m a
# cell): a full cell passes exp(-0.35) = 70 % of a beam, a 10-cell core 3 %.
EXTINCTION_PER_CELL = 0.35
# Share of a slice's light that spreads to the four texels beside it (Domański's radius r).
SPREAD = 0.2


def slice_light(
    density: F32,
    light_dir: tuple[float, float, float],
    extinction: float = EXTINCTION_PER_CELL,
    spread: float = SPREAD,
) -> F32:
    """(nz, ny, nx) light reaching each cell of `density` (z up) from a distant light in
    `light_dir` (x, y, z: the direction toward the light), 1 where nothing is in the way.
    Light arriving from below the grid's bottom (a light under the horizon) is lit the same
    way from below."""
    lx, ly, lz = (float(c) for c in light_dir)
    norm = (lx * lx + ly * ly + lz * lz) ** 0.5
    if not norm > 0.0:
        raise ValueError(f"light direction {light_dir} has no length")
    axis = int(np.argmax(np.abs([lz, ly, lx])))  # 0 z, 1 y, 2 x: the volume's axes
    along = (lz, ly, lx)[axis]
    # Move the light's axis first, its far side last: slices then run from the light inward.
    vol = np.moveaxis(density, axis, 0)
    if along > 0.0:
        vol = vol[::-1]
    across = [c for k, c in enumerate((lz, ly, lx)) if k != axis]
    # How far the ray moves across the slices per slice, in cells (toward the light's side
    # going back up the stack, so away from it going down).
    shift = (-across[0] / abs(along), -across[1] / abs(along))
    n = vol.shape[0]
    out = np.empty_like(vol, dtype=np.float32)
    buffer = np.ones(vol.shape[1:], np.float32)
    for k in range(n):
        if k:
            buffer = _shifted(buffer, shift)
            buffer = _spread(buffer, spread)
        out[k] = buffer
        # Half the slice's own absorption lights its cell: the light is in its middle.
        out[k] *= np.exp(-0.5 * extinction * vol[k] / abs(along) * norm)
        buffer = buffer * np.exp(-extinction * vol[k] / abs(along) * norm)
    if along > 0.0:
        out = out[::-1]
    result: F32 = np.ascontiguousarray(np.moveaxis(out, 0, axis))
    return result


def _shifted(buffer: F32, shift: tuple[float, float]) -> F32:
    """The buffer moved by a fractional (rows, columns) shift; light from beyond its edge is
    the unabsorbed 1 (open sky around the tower)."""
    out = buffer
    for axis, s in enumerate(shift):
        if s == 0.0:
            continue
        whole = int(np.floor(s))
        frac = np.float32(s - whole)
        a = _roll_fill(out, whole, axis)
        b = _roll_fill(out, whole + 1, axis)
        out = (np.float32(1.0) - frac) * a + frac * b
    return out


def _roll_fill(buffer: F32, by: int, axis: int) -> F32:
    out = np.roll(buffer, by, axis=axis)
    index = [slice(None), slice(None)]
    if by > 0:
        index[axis] = slice(0, by)
        out[tuple(index)] = 1.0
    elif by < 0:
        index[axis] = slice(by, None)
        out[tuple(index)] = 1.0
    return out


def _spread(buffer: F32, spread: float) -> F32:
    if spread <= 0.0:
        return buffer
    padded = np.pad(buffer, 1, constant_values=1.0)
    neighbours = (
        padded[:-2, 1:-1] + padded[2:, 1:-1] + padded[1:-1, :-2] + padded[1:-1, 2:]
    ) * np.float32(0.25)
    out: F32 = (np.float32(1.0 - spread) * buffer + np.float32(spread) * neighbours).astype(
        np.float32
    )
    return out
