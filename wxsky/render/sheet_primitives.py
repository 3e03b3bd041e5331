"""The canvas and the primitives the cloud-sheet painters draw with: the supersampled cell
grid `X`, `Y` (cell units, -1..1, y up), the cell window that is zero in the margin, smooth
steps and superellipse distances, seeded gradient noise with its fractal sum, and a Gaussian
blur. Nothing here knows about cloud kinds; `wxsky.render.sheet_painters` does.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from wxsky.render.sprite_sheet import CELL_PX, MARGIN_PX

F64 = npt.NDArray[np.float64]

SS = 2  # supersampling factor of the painting
N = CELL_PX * SS
PIX = 2.0 / N  # one supersampled pixel in cell units (the cell spans -1..1)
# Inside this radius (cell units, rounded-square metric) the window is 1; outside the
# margin it is exactly 0.
WINDOW_INNER = 0.8
WINDOW_OUTER = 1.0 - 2.0 * MARGIN_PX / CELL_PX


def _grid() -> tuple[F64, F64]:
    c = (np.arange(N) + 0.5) / N * 2.0 - 1.0
    yy, xx = np.meshgrid(-c, c, indexing="ij")  # y up, row 0 at the top
    return xx, yy


X, Y = _grid()


def smoothstep(e0: float, e1: float, v: F64) -> F64:
    t = np.clip((v - e0) / (e1 - e0), 0.0, 1.0)
    out: F64 = t * t * (3.0 - 2.0 * t)
    return out


def superellipse(x: F64, y: F64, p: float) -> F64:
    out: F64 = (np.abs(x) ** p + np.abs(y) ** p) ** (1.0 / p)
    return out


WINDOW: F64 = 1.0 - smoothstep(WINDOW_INNER, WINDOW_OUTER, superellipse(X, Y, 8.0))


class Noise:
    """Gradient (Perlin) noise on a periodic 64 x 64 lattice of random unit gradients."""

    SIZE = 64

    def __init__(self, rng: np.random.Generator) -> None:
        angle = rng.uniform(0.0, 2.0 * math.pi, size=(self.SIZE, self.SIZE))
        self._gx = np.cos(angle)
        self._gy = np.sin(angle)
        self._offsets = rng.uniform(0.0, self.SIZE, size=(8, 2))

    def __call__(self, x: F64, y: F64) -> F64:
        """Noise at (x, y) in lattice units, about -1..1."""
        fx0, fy0 = np.floor(x), np.floor(y)
        fx, fy = x - fx0, y - fy0
        i0 = fx0.astype(np.int64) % self.SIZE
        j0 = fy0.astype(np.int64) % self.SIZE
        i1 = (i0 + 1) % self.SIZE
        j1 = (j0 + 1) % self.SIZE

        def dot(i: npt.NDArray[np.int64], j: npt.NDArray[np.int64], dx: F64, dy: F64) -> F64:
            out: F64 = self._gx[j, i] * dx + self._gy[j, i] * dy
            return out

        u = fx * fx * fx * (fx * (fx * 6.0 - 15.0) + 10.0)
        v = fy * fy * fy * (fy * (fy * 6.0 - 15.0) + 10.0)
        a = dot(i0, j0, fx, fy) + u * (dot(i1, j0, fx - 1.0, fy) - dot(i0, j0, fx, fy))
        b = dot(i0, j1, fx, fy - 1.0) + u * (
            dot(i1, j1, fx - 1.0, fy - 1.0) - dot(i0, j1, fx, fy - 1.0)
        )
        out: F64 = (a + v * (b - a)) * 1.41
        return out

    def fbm(self, x: F64, y: F64, octaves: int, gain: float = 0.5) -> F64:
        """Octaves of noise, each at twice the frequency, turned and shifted so the lattice
        axes do not line up; normalised to about -1..1."""
        total = np.zeros_like(x)
        amp, norm, freq = 1.0, 0.0, 1.0
        for o in range(octaves):
            ang = 0.6 * o
            c, s = math.cos(ang), math.sin(ang)
            ox, oy = self._offsets[o % len(self._offsets)]
            total += amp * self((c * x - s * y) * freq + ox, (s * x + c * y) * freq + oy)
            norm += amp
            amp *= gain
            freq *= 2.0
        out: F64 = total / norm
        return out


def blur(img: F64, sigma_px: float) -> F64:
    """Separable Gaussian blur, zero outside the image."""
    radius = max(1, math.ceil(3.0 * sigma_px))
    k = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma_px) ** 2)
    k /= k.sum()
    out = img
    for axis in (0, 1):
        padded = np.pad(out, [(radius, radius) if a == axis else (0, 0) for a in (0, 1)])
        acc = np.zeros_like(out)
        for i, w in enumerate(k):
            acc += w * (padded[i : i + N, :] if axis == 0 else padded[:, i : i + N])
        out = acc
    return out
