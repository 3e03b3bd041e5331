"""The one generator of the cloud texture sheet (see `wxsky.render.sprite_sheet`).

Wang's artists painted 16 textures; this paints them procedurally, from a fixed seed:

* cumulus (flat-bottomed, puffy): a cauliflower of spherical lobes, each lobe budding smaller
  ones on its upper side. The lobes' front surfaces are lit from above (bright tops, a silver
  rim, darker undersides), creases between lobes are darkened by a blurred-height occlusion
  term, and the lower interior is a little darker overall. Alpha is the union of the lobes,
  its edge softened and billowed by noise. The flat-bottomed one is cut by a crisp base line.
* fog: a nearly uniform bluish-grey patch with a broad, gentle fade and faint texture.
* wisps: strands whose alpha comes from noise stretched along the strand (fibres), either
  straight bundles, hooked mares' tails (tangent angle curling up at the head), or ragged
  patches of elongated blobs eroded by anisotropic noise.

Each texture is painted at 2x and box-filtered to 128 px (anti-aliasing the crisp base and
the fibres), then multiplied by a rounded-square window that is exactly zero in the outer
`MARGIN_PX` of the cell. The mip levels are 2x2 means of premultiplied colour; the 32 px
level's outer texel straddles that margin and is cleared. Transparent texels get the colour
of the nearby cloud (push-pull per cell), so bilinear filtering never blends in black.

Only numpy: PCG64 streams from `SeedSequence([seed, slot])` (so retuning one slot leaves
the others alone) and elementwise float64 maths, quantised to 8 bits at the end, so every
machine produces the same bytes. A libm or SIMD difference in the last bit of exp or sin
could in principle flip one rounding somewhere; `tools/build_sprite_sheet.py --check`
would say so.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from wxsky.render.sprite_sheet import (
    CELL_PX,
    MARGIN_PX,
    MIP_LEVELS,
    SHEET_SEED,
    level_margin,
)
from wxsky.scene.texture_slots import SHEET_CELLS, TEX_FLAT_BOTTOM, TEX_FOG, TEX_PUFFY, TEX_WISPY

F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]
Lobe = tuple[float, float, float, float]  # centre x, centre y, radius, depth of the centre
Painter = Callable[[np.random.Generator], tuple[F64, F64]]

SS = 2  # supersampling factor of the painting
N = CELL_PX * SS
_PIX = 2.0 / N  # one supersampled pixel in cell units (the cell spans -1..1)
# Inside this radius (cell units, rounded-square metric) the window is 1; outside the
# margin it is exactly 0.
WINDOW_INNER = 0.8
WINDOW_OUTER = 1.0 - 2.0 * MARGIN_PX / CELL_PX
ERODE = 0.06  # how far inside a lobe its alpha reaches one half
LIGHT = np.array([-0.3, 0.8, 0.52]) / np.linalg.norm([-0.3, 0.8, 0.52])
FOG_TINT = np.array([0.90, 0.93, 0.98])


def _grid() -> tuple[F64, F64]:
    c = (np.arange(N) + 0.5) / N * 2.0 - 1.0
    yy, xx = np.meshgrid(-c, c, indexing="ij")  # y up, row 0 at the top
    return xx, yy


X, Y = _grid()


def _smoothstep(e0: float, e1: float, v: F64) -> F64:
    t = np.clip((v - e0) / (e1 - e0), 0.0, 1.0)
    out: F64 = t * t * (3.0 - 2.0 * t)
    return out


def _superellipse(x: F64, y: F64, p: float) -> F64:
    out: F64 = (np.abs(x) ** p + np.abs(y) ** p) ** (1.0 / p)
    return out


WINDOW: F64 = 1.0 - _smoothstep(WINDOW_INNER, WINDOW_OUTER, _superellipse(X, Y, 8.0))


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


def _blur(img: F64, sigma_px: float) -> F64:
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


# -- cumulus ----------------------------------------------------------------------------


def _bud(
    rng: np.random.Generator,
    roots: list[Lobe],
    generations: list[tuple[int, int, float, float]],
    arc: tuple[float, float] = (0.12, 0.88),
) -> list[Lobe]:
    """Cauliflower growth: each lobe of a generation buds k smaller lobes (radius ratio in
    lo..hi) poking out of its upper arc, each a little in front of its parent's surface."""
    lobes = list(roots)
    frontier = list(roots)
    for kmin, kmax, lo, hi in generations:
        buds: list[Lobe] = []
        for cx, cy, r, z0 in frontier:
            k = int(rng.integers(kmin, kmax + 1))
            if k == 0:
                continue
            a0, a1 = arc[0] * math.pi, arc[1] * math.pi
            angles = np.linspace(a0, a1, k) if k > 1 else rng.uniform(a0, a1, 1)
            angles = angles + rng.uniform(-0.1, 0.1, k) * (a1 - a0)
            for a in angles:
                rc = r * float(rng.uniform(lo, hi))
                dist = r - rc * float(rng.uniform(0.15, 0.45))
                surface = math.sqrt(max(r * r - dist * dist, 0.0))
                bx, by = cx + dist * math.cos(a), cy + dist * math.sin(a)
                buds.append((bx, by, rc, z0 + surface - rc * float(rng.uniform(0.3, 0.6))))
        lobes += buds
        frontier = buds
    return lobes


def _extent(lobes: list[Lobe], scale: float) -> tuple[float, float, float, float]:
    """The bounding box (x0, y0, x1, y1) of the lobes as they will show once scaled by
    `scale`: the soft edge eats about ERODE of every lobe, and all of a small bud."""
    erode = ERODE / scale
    shown = [(cx, cy, max(r - erode, 0.0)) for cx, cy, r, _ in lobes]
    return (
        min(cx - r for cx, _, r in shown),
        min(cy - r for _, cy, r in shown),
        max(cx + r for cx, _, r in shown),
        max(cy + r for _, cy, r in shown),
    )


def _scale_to(
    lobes: list[Lobe], limit: Callable[[tuple[float, float, float, float]], float]
) -> float:
    """The scale at which `limit(extent)` holds, found by a few fixed-point rounds (the
    extent itself depends on the scale through the erosion)."""
    s = 1.0
    for _ in range(6):
        s = limit(_extent(lobes, s))
    return s


def _fit(lobes: list[Lobe], box: tuple[float, float, float, float]) -> list[Lobe]:
    """Scale and move lobes uniformly so their shown extent fits `box` (x0, y0, x1, y1),
    centred in it."""

    def limit(e: tuple[float, float, float, float]) -> float:
        return min((box[2] - box[0]) / (e[2] - e[0]), (box[3] - box[1]) / (e[3] - e[1]))

    s = _scale_to(lobes, limit)
    x0, y0, x1, y1 = _extent(lobes, s)
    dx = (box[0] + box[2]) / 2 - s * (x0 + x1) / 2
    dy = (box[1] + box[3]) / 2 - s * (y0 + y1) / 2
    return [(s * cx + dx, s * cy + dy, s * r, s * z0) for cx, cy, r, z0 in lobes]


def _cumulus(
    rng: np.random.Generator, lobes: list[Lobe], base_y: float | None = None
) -> tuple[F64, F64]:
    noise = Noise(rng)
    # A gentle warp of the plane makes the spherical lobes irregular, like real turrets.
    wx = X + 0.035 * noise.fbm(X * 2.5 + 3.0, Y * 2.5, 3)
    wy = Y + 0.035 * noise.fbm(X * 2.5 - 8.0, Y * 2.5 + 5.0, 3)
    scores, normals = [], []
    sdf = np.full_like(X, np.inf)
    for cx, cy, r, z0 in lobes:
        dx, dy = wx - cx, wy - cy
        d = np.sqrt(dx * dx + dy * dy)
        h = np.sqrt(np.maximum(r * r - d * d, 0.0))
        # The front-most lobe surface shows; outside every lobe the nearest one does, so
        # the soft fringe takes that lobe's (sideways) normal.
        scores.append(np.where(d < r, z0 + h, -10.0 - (d - r)))
        normals.append((dx / r, dy / r, h / r))
        sdf = np.minimum(sdf, d - r)
    best = np.max(scores, axis=0)
    # Soft maximum over lobes: where one lobe passes behind another the normal turns over a
    # short distance instead of drawing an outline.
    tau = 0.03
    wsum = np.zeros_like(X)
    nx, ny, nz = np.zeros_like(X), np.zeros_like(X), np.zeros_like(X)
    for score, (lx, ly, lz) in zip(scores, normals, strict=True):
        w = np.exp((score - best) / tau)
        wsum += w
        nx += w * lx
        ny += w * ly
        nz += w * lz
    nx, ny, nz = nx / wsum, ny / wsum, nz / wsum
    mean_r = float(np.mean([r for *_, r, _ in lobes]))
    # Billows on every lobe tilt the normal.
    bump = noise.fbm(X * 5.0, Y * 5.0, 2)
    gy, gx = np.gradient(bump, -_PIX, _PIX)
    nx = nx - 0.016 * gx
    ny = ny - 0.016 * gy
    norm = np.sqrt(nx * nx + ny * ny + nz * nz) + 1e-9
    ndl = (nx * LIGHT[0] + ny * LIGHT[1] + nz * LIGHT[2]) / norm
    diffuse = np.clip((ndl + 0.5) / 1.5, 0.0, 1.0)
    height = np.where(best > -5.0, best, 0.0)
    crease = np.clip((_blur(height, 10.0 * SS) - height) / (0.35 * mean_r), 0.0, 1.0)
    b = (0.76 + 0.24 * diffuse) * (1.0 - 0.12 * crease)
    b *= 0.92 + 0.08 * _smoothstep(-0.75, 0.45, Y)  # light reaches the lower interior less
    edge = sdf + 0.035 * noise.fbm(X * 6.0 + 11.0, Y * 6.0, 3)  # billowing silhouette
    alpha = 1.0 - _smoothstep(-0.13, 0.02, edge)
    alpha *= 0.94 + 0.06 * noise.fbm(X * 4.0 - 7.0, Y * 4.0, 3)
    if base_y is not None:
        b *= 0.93 + 0.07 * _smoothstep(base_y, base_y + 0.3, Y)  # the shaded base
        alpha = np.where(Y - base_y < 0.0, 0.0, alpha)
    rgb = np.stack([b**1.05, b**1.02, b**0.96], axis=-1)  # shadows a little blue
    return rgb, alpha


def _flat_bottom(rng: np.random.Generator) -> tuple[F64, F64]:
    # On a texel edge, so the cut is one texel sharp; below the middle of the sprite but
    # high enough to leave room for the dome.
    base_y = 1.0 - 2.0 * 83 / CELL_PX
    # A dome with two shoulders and a turret, cut through the dome's centre: the
    # condensation level is where the cloud is widest.
    roots = [
        (0.0, 0.0, 1.0, 0.0),
        (-0.55, -0.2, 0.36, -0.05),
        (0.56, -0.15, 0.34, -0.05),
        (0.05, 0.95, 0.55, 0.12),
    ]
    lobes = _bud(rng, roots, [(3, 4, 0.38, 0.5), (1, 3, 0.38, 0.52)], arc=(0.05, 0.95))
    centre_y = base_y + 0.06
    s = _scale_to(lobes, lambda e: min(1.6 / (e[2] - e[0]), (0.86 - centre_y) / e[3]))
    x0, _, x1, _ = _extent(lobes, s)
    dx = -s * (x0 + x1) / 2
    lobes = [(s * cx + dx, s * cy + centre_y, s * r, s * z0) for cx, cy, r, z0 in lobes]
    return _cumulus(rng, lobes, base_y)


def _puffy(variant: int) -> Painter:
    def paint(rng: np.random.Generator) -> tuple[F64, F64]:
        box = (-0.8, -0.78, 0.8, 0.8)
        if variant == 0:  # one big rounded puff, few large lobes
            roots = [(0.0, 0.0, 1.0, 0.0)]
            gens = [(4, 4, 0.45, 0.58), (1, 2, 0.4, 0.5)]
        elif variant == 1:  # many small florets
            roots = [(-0.5, 0.0, 0.55, 0.0), (0.5, 0.0, 0.55, 0.0), (0.0, 0.25, 0.6, 0.1)]
            gens = [(3, 4, 0.4, 0.5), (2, 3, 0.38, 0.5)]
        elif variant == 2:  # a tower (congestus)
            roots = [
                (0.0, -0.45, 0.55, 0.0),
                (0.1, 0.0, 0.47, 0.12),
                (-0.06, 0.4, 0.4, 0.2),
                (0.05, 0.72, 0.3, 0.28),
            ]
            gens = [(2, 3, 0.42, 0.58), (1, 2, 0.38, 0.5)]
            box = (-0.62, -0.8, 0.62, 0.82)
        elif variant == 3:  # a wide, low heap
            dy = rng.uniform(-0.08, 0.08, 4)
            radii = rng.uniform(0.32, 0.42, 4)
            roots = [(-0.7 + 0.45 * i, float(dy[i]), float(radii[i]), 0.0) for i in range(4)]
            gens = [(1, 3, 0.5, 0.68), (1, 2, 0.4, 0.55)]
            box = (-0.82, -0.55, 0.82, 0.62)
        elif variant == 4:  # two heads with a saddle
            roots = [(-0.45, 0.0, 0.55, 0.0), (0.5, 0.3, 0.5, 0.1), (0.0, -0.2, 0.45, -0.05)]
            gens = [(2, 3, 0.45, 0.6), (1, 2, 0.4, 0.5)]
        else:  # lopsided, one big lobe with a shoulder
            roots = [(-0.2, 0.1, 0.7, 0.0), (0.55, -0.15, 0.4, 0.05)]
            gens = [(3, 4, 0.4, 0.55), (1, 3, 0.35, 0.5)]
        return _cumulus(rng, _fit(_bud(rng, roots, gens), box))

    return paint


# -- fog ---------------------------------------------------------------------------------


def _fog(rx: float, ry: float, p: float, lump: float, texture: float) -> Painter:
    def paint(rng: np.random.Generator) -> tuple[F64, F64]:
        noise = Noise(rng)
        r = _superellipse(X / rx, Y / ry, p)
        r = r * (1.0 + lump * noise.fbm(X * 1.6, Y * 1.6, 2))
        alpha = 0.84 * (1.0 - _smoothstep(0.45, 1.0, r))
        alpha *= 1.0 + texture * noise.fbm(X * 3.0 + 5.0, Y * 3.0, 4)
        shade = 0.95 + 0.03 * noise.fbm(X * 2.5 - 3.0, Y * 2.5, 3)
        shade = shade * (0.96 + 0.04 * _smoothstep(-0.8, 0.6, Y))
        return shade[..., None] * FOG_TINT, alpha

    return paint


# -- wisps -------------------------------------------------------------------------------


def _strand_frame(angle: float) -> tuple[F64, F64]:
    c, s = math.cos(angle), math.sin(angle)
    return c * X + s * Y, -s * X + c * Y


def _wisp_colour(density: F64) -> F64:
    b = 0.84 + 0.16 * np.clip(density, 0.0, 1.0)
    b = b * (0.95 + 0.05 * _smoothstep(-0.7, 0.5, Y))
    out: F64 = np.stack([b**1.03, b**1.01, b**0.97], axis=-1)
    return out


def _straight(angle: float, bow: float, strands: int) -> Painter:
    def paint(rng: np.random.Generator) -> tuple[F64, F64]:
        noise = Noise(rng)
        u, v = _strand_frame(angle)
        v = v - bow * u * u
        density = np.zeros_like(X)
        for k in range(strands):
            c = float(rng.uniform(-0.35, 0.35))
            w = float(rng.uniform(0.012, 0.045))
            u0 = float(rng.uniform(-1.0, -0.3))
            u1 = float(rng.uniform(0.3, 1.0))
            along = _smoothstep(u0, u0 + 0.4, u) * (1.0 - _smoothstep(u1 - 0.4, u1, u))
            pulse = 0.5 + 0.5 * noise(u * 2.2 + 9.0 * k, np.full_like(u, 3.7 * k))
            wiggle = 0.03 * noise(u * 1.5 - 5.0 * k, np.full_like(u, 1.3 * k))
            density += (
                float(rng.uniform(0.4, 1.0))
                * along
                * pulse
                * np.exp(-(((v - c - wiggle) / w) ** 2))
            )
        fibres = 0.5 + 0.5 * noise.fbm(u * 2.0, v * 30.0, 3)
        alpha = 0.9 * (1.0 - np.exp(-2.2 * density * (0.3 + 0.9 * fibres)))
        return _wisp_colour(density), alpha

    return paint


def _curve_field(pts: F64, widths: F64, weights: F64) -> tuple[F64, F64, F64]:
    """For a polyline of M points: per pixel, the arc length of the nearest point, the signed
    distance to it, and the strand's profile there (weight * Gaussian of distance / width)."""
    seg = np.diff(pts, axis=0)
    s_at = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
    tangent = np.gradient(pts, axis=0)
    tangent /= np.hypot(tangent[:, 0], tangent[:, 1])[:, None]
    arc = np.empty_like(X)
    signed = np.empty_like(X)
    profile = np.empty_like(X)
    for r0 in range(0, N, 32):  # in row bands, to keep the pixel x point table small
        px = X[r0 : r0 + 32, :, None]
        py = Y[r0 : r0 + 32, :, None]
        d2 = (px - pts[:, 0]) ** 2 + (py - pts[:, 1]) ** 2
        i = np.argmin(d2, axis=-1)
        dist = np.sqrt(np.take_along_axis(d2, i[..., None], axis=-1)[..., 0])
        ex = px[..., 0] - pts[i, 0]
        ey = py[..., 0] - pts[i, 1]
        side = np.sign(tangent[i, 0] * ey - tangent[i, 1] * ex)
        arc[r0 : r0 + 32] = s_at[i]
        signed[r0 : r0 + 32] = side * dist
        profile[r0 : r0 + 32] = weights[i] * np.exp(-((dist / widths[i]) ** 2))
    return arc, signed, profile


def _hooked(strands: int, curl: float) -> Painter:
    """Cirrus uncinus: filaments fanning out of a dense tuft (the head, upper right) that
    curl up into it, trailing long thin fall-streaks to the left."""

    def paint(rng: np.random.Generator) -> tuple[F64, F64]:
        noise = Noise(rng)
        density = np.zeros_like(X)
        fibre_acc = np.zeros_like(X)
        t = np.linspace(0.0, 1.0, 420)
        head = np.array([0.5, 0.42])
        for k in range(strands):
            length = float(rng.uniform(1.1, 1.7))
            phi = float(rng.uniform(-0.2, 0.15)) + curl * float(rng.uniform(0.7, 1.1)) * t**3
            step = length / (len(t) - 1)
            x = np.concatenate([[0.0], np.cumsum(np.cos(phi[:-1]) * step)])
            y = np.concatenate([[0.0], np.cumsum(np.sin(phi[:-1]) * step)])
            x += head[0] - x[-1] + float(rng.uniform(-0.06, 0.06))
            y += head[1] - y[-1] + float(rng.uniform(-0.08, 0.05))
            pts = np.stack([x, y], axis=1)
            widths = float(rng.uniform(0.01, 0.018)) + float(rng.uniform(0.035, 0.055)) * t**3
            broken = 0.55 + 0.45 * noise(t * length * 3.0 + 7.0 * k, np.full_like(t, 2.9 * k))
            weights = _smoothstep(0.0, 0.3, t) * broken * float(rng.uniform(0.6, 1.0))
            arc, signed, profile = _curve_field(pts, widths, weights)
            fib = 0.5 + 0.5 * noise.fbm(arc * 2.5 + 13.0 * k, signed * 50.0, 3)
            density += profile
            fibre_acc += profile * fib
        fibres = fibre_acc / np.maximum(density, 1e-6)
        alpha = 0.9 * (1.0 - np.exp(-1.8 * density * (0.3 + 0.9 * fibres)))
        return _wisp_colour(density), alpha

    return paint


def _ragged(angle: float, bend: float, blobs: int, tear_amount: float) -> Painter:
    """A torn fragment (fractus, a cloud's shredded fringe): elongated blobs eroded by noise
    stretched along one direction, so holes and edges run in streaks."""

    def paint(rng: np.random.Generator) -> tuple[F64, F64]:
        noise = Noise(rng)
        u, v = _strand_frame(angle)
        v = v - bend * u * u
        density = np.zeros_like(X)
        for _ in range(blobs):
            cu, cv = rng.uniform(-0.5, 0.5), rng.uniform(-0.28, 0.28)
            lu, lv = rng.uniform(0.32, 0.55), rng.uniform(0.13, 0.24)
            tilt = float(rng.uniform(-0.3, 0.3))
            du, dv = u - cu, v - cv - tilt * (u - cu)
            density += float(rng.uniform(0.6, 1.0)) * np.exp(-((du / lu) ** 2 + (dv / lv) ** 2))
        density /= density.max()
        tear = noise.fbm(u * 3.0, v * 7.5, 5, gain=0.6)
        fibres = 0.5 + 0.5 * noise.fbm(u * 3.0 + 4.0, v * 22.0, 3)
        # Tearing only near the body: far from it, noise alone would scatter specks.
        body = density - 0.3 + tear_amount * tear * _smoothstep(0.03, 0.35, density)
        alpha = 0.88 * _smoothstep(0.0, 0.35, body) * (0.45 + 0.55 * fibres)
        return _wisp_colour(np.clip(body * 1.4, 0.0, 1.0)), alpha

    return paint


# -- the sheet ---------------------------------------------------------------------------


def _painters() -> dict[int, Painter]:
    fog = [
        _fog(0.86, 0.86, 2.0, 0.0, 0.06),  # round: the stratus workhorse
        _fog(0.9, 0.72, 2.4, 0.07, 0.07),  # a wide oval
        _fog(0.8, 0.76, 2.6, 0.12, 0.1),  # a broader, lumpy patch
    ]
    wisps = [
        _straight(0.42, 0.12, 10),
        _straight(-0.3, -0.22, 8),
        _hooked(6, 1.5),
        _ragged(0.3, 0.35, 7, 0.7),  # a curved, torn remnant
        _ragged(0.35, 0.0, 8, 0.75),
        _ragged(-0.6, 0.0, 9, 1.0),  # broken into pieces
    ]
    out: dict[int, Painter] = {TEX_FLAT_BOTTOM[0]: _flat_bottom}
    out.update(zip(TEX_FOG, fog, strict=True))
    out.update({slot: _puffy(i) for i, slot in enumerate(TEX_PUFFY)})
    out.update(zip(TEX_WISPY, wisps, strict=True))
    return out


def paint_cell(slot: int, seed: int = SHEET_SEED) -> tuple[F64, F64]:
    """One texture at 128 px: premultiplied RGB (H, W, 3) and alpha (H, W), float64."""
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, slot])))
    rgb, alpha = _painters()[slot](rng)
    alpha = np.clip(alpha, 0.0, 1.0) * WINDOW
    prem = np.concatenate([np.clip(rgb, 0.0, 1.0) * alpha[..., None], alpha[..., None]], axis=-1)
    small = prem.reshape(CELL_PX, SS, CELL_PX, SS, 4).mean(axis=(1, 3))
    return small[..., :3], small[..., 3]


def _halve(cells: F64) -> F64:
    """2x2 means of (rows, cols, S, S, C) per-cell images."""
    r, c, s, _, ch = cells.shape
    out: F64 = cells.reshape(r, c, s // 2, 2, s // 2, 2, ch).mean(axis=(3, 5))
    return out


def _to_sheet(cells: F64) -> F64:
    r, c, s, _, ch = cells.shape
    out: F64 = cells.transpose(0, 2, 1, 3, 4).reshape(r * s, c * s, ch)
    return out


def build_levels(seed: int = SHEET_SEED) -> list[U8]:
    """The sheet's mip chain, 512 px first, as straight-alpha RGBA8 (S, S, 4) arrays."""
    n = SHEET_CELLS
    cells = np.zeros((n, n, CELL_PX, CELL_PX, 4))
    for slot in range(n * n):
        rgb, alpha = paint_cell(slot, seed)
        cells[slot // n, slot % n, ..., :3] = rgb
        cells[slot // n, slot % n, ..., 3] = alpha
    pyramid = [cells]
    while pyramid[-1].shape[2] > 1:
        nxt = _halve(pyramid[-1])
        if len(pyramid) < MIP_LEVELS:
            m = level_margin(len(pyramid))
            ring = np.ones(nxt.shape[2], bool)
            ring[m:-m] = False
            nxt[:, :, ring, :, :] = 0.0
            nxt[:, :, :, ring, :] = 0.0
        pyramid.append(nxt)
    # Push-pull: a transparent texel takes the colour of the coarser level's estimate, so it
    # matches the cloud next to it when bilinear filtering mixes the two.
    top = pyramid[-1]
    fill = top[..., :3] / np.maximum(top[..., 3:], 1e-12)
    fills = [fill]
    for level in reversed(pyramid[:-1]):
        up = fills[-1].repeat(2, axis=2).repeat(2, axis=3)
        fills.append(level[..., :3] + (1.0 - level[..., 3:]) * up)
    fills.reverse()
    out = []
    for level, fill in zip(pyramid[:MIP_LEVELS], fills[:MIP_LEVELS], strict=True):
        a = level[..., 3:]
        a8 = np.round(a * 255.0)
        straight = np.where(a8 > 0, level[..., :3] / np.maximum(a, 1e-12), fill)
        rgba = np.concatenate([np.clip(straight, 0.0, 1.0) * 255.0, a8], axis=-1)
        out.append(np.round(_to_sheet(rgba)).astype(np.uint8))
    return out
