"""Harris's multiple forward scattering ("Real-Time Cloud Rendering", eq. 5-8) and the phase
functions it and the eye scattering (eq. 9) need. Pure numpy; nothing here knows about sprites.

Light reaching particle k along a light's direction, after the particles before it:

    I_k = g_{k-1} + T_{k-1} I_{k-1},   I_1 = I_0                                    (eq. 8)
    T_j = exp(-tau_j),   g_j = a_j (1 - T_j) phi I_j

so each particle passes on the share f_j = T_j + a_j (1 - T_j) phi of the light reaching it, and
I_k = I_0 prod_{j<k} f_j (eq. 7). phi is the share of scattered light that stays in a narrow
forward cone, taken from the phase function. Harris writes g_j = a_j tau_j p(l,-l) I_j / 4pi;
we use 1 - T_j for tau_j (equal while tau_j is small) so a particle never scatters forward more
than it removed from the beam, which his linear form does for tau_j > 1.

Particles are spheres, not points on a ray: particle j shades particle k by the share
w_jk = kernel(lateral distance / r_j) * ramp(depth difference / r_j) of its optical depth, and
the light reaching k is I_0 exp(-sum_j w_jk s_j), with s_j = -ln f_j. Along a column (lateral 0,
particles more than a radius apart) w is 0 or 1 and this is eq. 7 exactly. Harris evaluates the
sum by splatting into a frame buffer in light order; here each cloud is a small dense matrix
(clouds hold tens to a few hundred particles), so the whole sum is a handful of vectorised
array operations per light, with no order to keep and no grid to alias.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
ArrayF = npt.NDArray[np.floating]

ALBEDO = 0.9  # Harris's a: cloud droplets absorb almost nothing
# Light is read this share of a particle's radius from its centre towards the light: a sprite
# shows the light on its lit half, not the dimmer light at its centre.
READ_SHIFT = 0.5
HG_G = 0.8  # asymmetry of cloud droplets (Mie: about 0.85); see hg_phase
# Cloud droplets seen from outside the cloud (`cloud_phase`): a two-lobe Henyey-Greenstein, a
# strong forward lobe (the diffraction peak and forward Mie lobe, Mie's g about 0.85) and a
# weak backward one (the glory and back-scatter that light a cloud's sunlit face toward a
# sun-behind eye): the dual-lobe form real-time cloud renderers use (Hillaire 2016).
CLOUD_G_FORWARD = 0.85
CLOUD_G_BACK = -0.3
CLOUD_FORWARD_WEIGHT = 0.65
# Light scattered many times inside a cloud has lost most of its memory of the sun's
# direction: what leaves the cloud after many events keeps only a weak forward bias.
CLOUD_G_DIFFUSE = 0.2
FORWARD_CONE_DEG = 10.0  # light scattered within this of the beam counts as still in the beam
# Pair matrices are built a chunk of clouds at a time: small enough to stay in cache.
_CHUNK_PAIRS = 1 << 17


def rayleigh_phase(cos_theta: ArrayF | float) -> F64:
    """Rayleigh phase function per steradian (integrates to 1 over the sphere): Harris's eq. 3
    over 4 pi. As much light goes back as forward, so it cannot make a silver lining."""
    c = np.asarray(cos_theta, np.float64)
    out: F64 = 3.0 / (16.0 * math.pi) * (1.0 + c * c)
    return out


def hg_phase(cos_theta: ArrayF | float, g: float = HG_G) -> F64:
    """Henyey-Greenstein phase function per steradian (Harris's eq. 4). With g = 0.8 it has
    the strong forward peak of cloud droplets (729 times the backward value), which is what
    lights a cloud's rim when the sun is behind it."""
    c = np.asarray(cos_theta, np.float64)
    base = np.maximum(1.0 + g * g - 2.0 * g * c, 1e-12)
    # x * sqrt(x), not x ** 1.5: the same to an ulp, and 8 times faster (numpy's float64 pow
    # has no vector code here; a frame's near layer asks for (N, 5) of it).
    denom = base * np.sqrt(base)
    out: F64 = (1.0 - g * g) / (4.0 * math.pi * denom)
    return out


def two_lobe_phase(
    cos_theta: ArrayF | float,
    g_forward: float = CLOUD_G_FORWARD,
    g_back: float = CLOUD_G_BACK,
    forward_weight: float = CLOUD_FORWARD_WEIGHT,
) -> F64:
    """Two-lobe Henyey-Greenstein phase function per steradian (integrates to 1 over the
    sphere): forward_weight of a lobe of g_forward plus the rest of one of g_back."""
    out: F64 = forward_weight * hg_phase(cos_theta, g_forward)
    out += (1.0 - forward_weight) * hg_phase(cos_theta, g_back)
    return out


def cloud_phase(cos_theta: ArrayF | float) -> F64:
    """Cloud droplets' phase function times 4 pi (1 for isotropic scattering), of the cosine
    between the light's direction of travel and the way to the eye (1: the eye looks at the
    light through the droplet): 54 straight on, 0.96 straight back, 0.36 at 90 degrees."""
    out: F64 = 4.0 * math.pi * two_lobe_phase(cos_theta)
    return out


def diffuse_phase(cos_theta: ArrayF | float) -> F64:
    """Phase function times 4 pi of light that has scattered many times in a cloud: a weak
    forward bias (CLOUD_G_DIFFUSE)."""
    out: F64 = 4.0 * math.pi * hg_phase(cos_theta, CLOUD_G_DIFFUSE)
    return out


def hg_forward_share(g: float = HG_G, cone_deg: float = FORWARD_CONE_DEG) -> float:
    """Share of the light Henyey-Greenstein scatters within cone_deg of straight on (the
    closed-form integral of hg_phase over the cone): 0.24 for g = 0.8 and 10 degrees."""
    mu = math.cos(math.radians(cone_deg))
    if g == 0.0:
        return 0.5 * (1.0 - mu)
    k = (1.0 - g * g) / (2.0 * g)
    return k * (1.0 / (1.0 - g) - 1.0 / math.sqrt(1.0 + g * g - 2.0 * g * mu))


FORWARD_SHARE = hg_forward_share()


def pass_on(tau: ArrayF, albedo: float = ALBEDO, forward_share: float = FORWARD_SHARE) -> F64:
    """f = T + a (1 - T) phi: the share of the light reaching a particle that leaves it
    forward along the beam (transmitted plus forward-scattered); 1 for tau = 0."""
    t = np.exp(-np.maximum(np.asarray(tau, np.float64), 0.0))
    out: F64 = t + albedo * (1.0 - t) * forward_share
    return out


def incident_light(
    centre_m: F64,
    radius_m: ArrayF,
    tau: ArrayF,
    cloud_id: I64,
    light_dirs: ArrayF,
    albedo: float = ALBEDO,
    forward_share: float = FORWARD_SHARE,
    read_shift: float = READ_SHIFT,
) -> F32:
    """(N, L) light reaching each particle from each light, as a share of the light outside
    the cloud (0..1). Particles shade only particles of their own cloud.

    centre_m (N, 3); radius_m (N,) the reach of a particle's shadow; tau (N,) its optical depth
    through the centre; cloud_id (N,); light_dirs (L, 3) towards each light (normalised here).
    """
    dirs = np.asarray(light_dirs, np.float64).reshape(-1, 3)
    norms = np.linalg.norm(dirs, axis=1, keepdims=True)
    if not np.all(norms > 0.0) or not np.all(np.isfinite(dirs)):
        raise ValueError("light directions must be finite and non-zero")
    dirs = dirs / norms
    n = int(np.shape(cloud_id)[0])
    out = np.ones((n, len(dirs)), np.float32)
    if n == 0 or len(dirs) == 0:
        return out
    order = np.argsort(cloud_id, kind="stable")
    cid = np.asarray(cloud_id)[order]
    starts = np.flatnonzero(np.r_[True, cid[1:] != cid[:-1]])
    counts = np.diff(np.r_[starts, n])
    # Relative to each cloud's first particle: float32 keeps centimetres over a cloud, not
    # over the 40 km the scene spans.
    centre = np.asarray(centre_m, np.float64)[order]
    rel = (centre - np.repeat(centre[starts], counts, axis=0)).astype(np.float32)
    light_space = rel @ _light_bases(dirs)  # (N, 3L): per light (u, v, depth along the beam)
    r = np.maximum(np.asarray(radius_m, np.float32)[order], np.float32(1e-3))
    read_at = light_space.copy()
    read_at[:, 2::3] -= (read_shift * r)[:, None]
    f = pass_on(np.asarray(tau)[order], albedo, forward_share)
    s = (-np.log(np.maximum(f, 1e-30))).astype(np.float32)  # (N,) optical depth it casts
    inv_r2 = (1.0 / (r * r)).astype(np.float32)
    half_inv_r = (0.5 / r).astype(np.float32)
    padded = _padded_sizes(counts)
    for m in np.unique(padded):
        clouds = np.flatnonzero(padded == m)
        per_chunk = max(1, _CHUNK_PAIRS // int(m * m))
        # One cloud too big for a chunk is done a block of receivers at a time.
        row_step = int(m) if per_chunk > 1 else max(8, _CHUNK_PAIRS // int(m))
        lane = np.arange(m)
        for c0 in range(0, len(clouds), per_chunk):
            chunk = clouds[c0 : c0 + per_chunk]
            valid = lane[None, :] < counts[chunk, None]  # (C, m)
            idx = np.where(valid, starts[chunk, None] + lane[None, :], 0)  # (C, m)
            s_c = np.where(valid, s[idx], np.float32(0.0))  # padding casts nothing
            ls, at = light_space[idx], read_at[idx]
            for r0 in range(0, int(m), row_step):
                rows = slice(r0, r0 + row_step)
                depth = _optical_depth(ls, at, s_c, inv_r2[idx], half_inv_r[idx], rows, read_shift)
                keep = valid[:, rows]
                out[order[idx[:, rows][keep]]] = np.exp(-depth[keep])
    return out


def _optical_depth(
    ls: F32, at: F32, s: F32, inv_r2: F32, half_inv_r: F32, rows: slice, read_shift: float
) -> F32:
    """(C, R, L) summed optical depth in front of the receivers `rows`, per light.
    ls (C, m, 3L) light-space coordinates of the casters, `at` where each reads its light;
    s, inv_r2, half_inv_r (C, m) per caster."""
    n_lights = ls.shape[2] // 3
    s_rows = s[:, rows]
    out = np.empty((*s_rows.shape, n_lights), np.float32)
    caster_r2 = inv_r2[:, None, :]
    caster_half = half_inv_r[:, None, :]
    s_col = s[:, :, None]
    self_share = np.float32(min(1.0, max(0.0, 0.5 - 0.5 * read_shift)))
    for k in range(n_lights):
        u, v, d = ls[:, :, 3 * k], ls[:, :, 3 * k + 1], ls[:, :, 3 * k + 2]
        # (C, receiver, caster): a parabolic kernel in lateral distance...
        w = u[:, rows, None] - u[:, None, :]
        w *= w
        dv = v[:, rows, None] - v[:, None, :]
        dv *= dv
        w += dv
        w *= caster_r2
        np.subtract(1.0, w, out=w)
        np.maximum(w, 0.0, out=w)
        # ...times the share of the caster's sphere lying before the receiver's centre.
        ramp = at[:, rows, 3 * k + 2, None] - d[:, None, :]
        ramp *= caster_half
        ramp += 0.5
        np.clip(ramp, 0.0, 1.0, out=ramp)
        w *= ramp
        depth = np.matmul(w, s_col)[:, :, 0]
        # A particle's own sphere is not in front of it.
        depth -= self_share * s_rows
        out[:, :, k] = np.maximum(depth, 0.0)
    return out


def _light_bases(dirs: F64) -> F32:
    """(3, 3L) columns (u, v, w) per light: u, v across the beam, w along the light's travel
    (away from the light), so depth grows into the cloud. Any direction works, axes included."""
    cols = []
    for d in dirs:
        helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = helper - np.dot(helper, d) * d
        u /= np.linalg.norm(u)
        v = np.cross(d, u)
        cols += [u, v, -d]
    out: F32 = np.stack(cols, axis=1).astype(np.float32)
    return out


def _padded_sizes(counts: npt.NDArray[np.intp]) -> npt.NDArray[np.intp]:
    """Clouds are padded to a few sizes (multiples of 8, then steps of about a quarter) so
    that clouds of one size go through the pair matrices together with little waste."""
    small = ((counts + 7) // 8) * 8
    big = (2.0 ** (np.ceil(np.log2(np.maximum(counts, 1)) * 4.0) / 4.0)).astype(np.intp)
    big = ((np.maximum(big, counts) + 7) // 8) * 8
    out: npt.NDArray[np.intp] = np.where(counts <= 64, small, big)
    return out
