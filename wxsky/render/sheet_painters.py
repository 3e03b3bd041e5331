"""The painters of the cloud-sheet textures, one family per cloud category: cumulus (lobed
cauliflowers, puffy and flat-bottomed), fog patches, and wisps (straight, hooked and ragged),
each a function from a seeded random generator to colour and alpha on the supersampled grid
of `wxsky.render.sheet_primitives`; `painters()` says which painter fills which sheet slot.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from wxsky.render.sheet_primitives import (
    F64,
    PIX,
    SS,
    N,
    Noise,
    X,
    Y,
    blur,
    smoothstep,
    superellipse,
)
from wxsky.render.sprite_sheet import CELL_PX
from wxsky.scene.texture_slots import TEX_FLAT_BOTTOM, TEX_FOG, TEX_PUFFY, TEX_WISPY

Lobe = tuple[float, float, float, float]  # centre x, centre y, radius, depth of the centre
Painter = Callable[[np.random.Generator], tuple[F64, F64]]

ERODE = 0.06  # how far inside a lobe its alpha reaches one half
LIGHT = np.array([-0.3, 0.8, 0.52]) / np.linalg.norm([-0.3, 0.8, 0.52])


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
    gy, gx = np.gradient(bump, -PIX, PIX)
    nx = nx - 0.016 * gx
    ny = ny - 0.016 * gy
    norm = np.sqrt(nx * nx + ny * ny + nz * nz) + 1e-9
    ndl = (nx * LIGHT[0] + ny * LIGHT[1] + nz * LIGHT[2]) / norm
    diffuse = np.clip((ndl + 0.5) / 1.5, 0.0, 1.0)
    height = np.where(best > -5.0, best, 0.0)
    crease = np.clip((blur(height, 10.0 * SS) - height) / (0.35 * mean_r), 0.0, 1.0)
    b = (0.76 + 0.24 * diffuse) * (1.0 - 0.12 * crease)
    b *= 0.92 + 0.08 * smoothstep(-0.75, 0.45, Y)  # light reaches the lower interior less
    edge = sdf + 0.035 * noise.fbm(X * 6.0 + 11.0, Y * 6.0, 3)  # billowing silhouette
    alpha = 1.0 - smoothstep(-0.13, 0.02, edge)
    alpha *= 0.94 + 0.06 * noise.fbm(X * 4.0 - 7.0, Y * 4.0, 3)
    if base_y is not None:
        b *= 0.93 + 0.07 * smoothstep(base_y, base_y + 0.3, Y)  # the shaded base
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
        r = superellipse(X / rx, Y / ry, p)
        r = r * (1.0 + lump * noise.fbm(X * 1.6, Y * 1.6, 2))
        alpha = 0.84 * (1.0 - smoothstep(0.45, 1.0, r))
        alpha *= 1.0 + texture * noise.fbm(X * 3.0 + 5.0, Y * 3.0, 4)
        shade = 0.95 + 0.03 * noise.fbm(X * 2.5 - 3.0, Y * 2.5, 3)
        shade = shade * (0.96 + 0.04 * smoothstep(-0.8, 0.6, Y))
        # Neutral: the shading model colours a deck (a blue tint here turned every overcast
        # blue-grey whatever the light); the texture only carries its brightness texture.
        return np.repeat(shade[..., None], 3, axis=-1), alpha

    return paint


# -- wisps -------------------------------------------------------------------------------


def _strand_frame(angle: float) -> tuple[F64, F64]:
    c, s = math.cos(angle), math.sin(angle)
    return c * X + s * Y, -s * X + c * Y


def _wisp_colour(density: F64) -> F64:
    b = 0.84 + 0.16 * np.clip(density, 0.0, 1.0)
    b = b * (0.95 + 0.05 * smoothstep(-0.7, 0.5, Y))
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
            along = smoothstep(u0, u0 + 0.4, u) * (1.0 - smoothstep(u1 - 0.4, u1, u))
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
            weights = smoothstep(0.0, 0.3, t) * broken * float(rng.uniform(0.6, 1.0))
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
        body = density - 0.3 + tear_amount * tear * smoothstep(0.03, 0.35, density)
        alpha = 0.88 * smoothstep(0.0, 0.35, body) * (0.45 + 0.55 * fibres)
        return _wisp_colour(np.clip(body * 1.4, 0.0, 1.0)), alpha

    return paint


# -- the sheet ---------------------------------------------------------------------------


def painters() -> dict[int, Painter]:
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
