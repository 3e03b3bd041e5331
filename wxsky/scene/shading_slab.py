"""Bouthors' slab shading for stratiform layers ("Real-time realistic illumination and shading
of stratiform clouds", 2006): a stratus or altostratus deck is locally a plane-parallel slab
of thickness H, so the light it sends toward the eye depends on H, the key light's angle to
the slab's normal (mu_l) and the view's (mu_v), and on which side of the slab the eye is. Every
sprite of such a layer gets the slab's colour for the ray from the eye through it, so a deck
of overlapping sprites reads as one continuous sheet instead of a pile of lit balls.

Terms, per unit key-light irradiance, in the radiance units the particle models use (a white
Lambertian surface facing the light is 1):
- single and double scattering, analytic along the ray (Bouthors 4.3, 4.4) with the
  modified-Mie phase function: the droplets' forward peak (P_f = 51 % within 5 degrees) folded
  into the extinction, which leaves a Henyey-Greenstein lobe of the delta-scaled asymmetry
  g_S = (g - P_f) / (1 - P_f); double scattering takes the phase convolved with itself, which
  for Henyey-Greenstein is exactly the lobe of g_S squared, weighted by the 1D model's ratio
  of double to single scattered energy;
- three and more scattering events, diffuse, with the energy the paper's 1D model leaves for
  them (Appendix A, fitted parameters of Appendix B): T_3+ = T_ms - T_0 - T_1 - T_2 and
  R_3+ = R_ms - R_1 - R_2. The paper spreads it as mu_l / (4 pi mu_v), which grows without
  bound toward the horizon; a sprite deck is seen edge-on there, so we spread it with
  Eddington's limb law (1 + 1.5 mu_v) / 2 instead: an overcast sky three times brighter at
  the zenith than at the horizon, as measured overcast skies are (the CIE overcast sky);
- the sky's light (Harris's four skylights, summed) reflected with R_ms and transmitted with
  T_ms, diffuse (Bouthors 4.6);
- the ground under the deck (albedo GROUND_ALBEDO) and the cloud base reflecting each other's
  light: between two uniform infinite planes the paper's radiosity passes sum to a geometric
  series, 1 / (1 - albedo R_ms).

The direct sun seen through a thin deck (T_0 and its 5-degree forward peak) is left to the sky
pass behind the sprites. Pure numpy, vectorised over sprites.
"""

from __future__ import annotations

import functools
import math
import threading
from collections import OrderedDict

import numpy as np
import numpy.typing as npt

from wxsky.scene.cloud_light import key_rgb_at
from wxsky.scene.scattering import ALBEDO, hg_phase
from wxsky.scene.shading_harris import NIGHT_FLOOR_RGB, scene_lights
from wxsky.scene.sky import SkyParams
from wxsky.scene.sprites import F32, F64, B

# Bouthors' droplet size distribution (Appendix B): N0 = 300 cm^-3, r_e = 7 um.
DROPLETS_PER_M3 = 300e6
EFFECTIVE_RADIUS_M = 7e-6
FORWARD_PEAK_SHARE = 0.51  # P_f: share of Mie scattering within 5 degrees of straight on
MIE_ASYMMETRY = 0.86  # g of cloud droplets
# Modified-Mie extinction: the forward peak no longer counts as an extinction event.
KAPPA_S_PER_M = (1.0 - FORWARD_PEAK_SHARE) * math.pi * EFFECTIVE_RADIUS_M**2 * DROPLETS_PER_M3
G_S = (MIE_ASYMMETRY - FORWARD_PEAK_SHARE) / (1.0 - FORWARD_PEAK_SHARE)
BETA = 0.9961  # T_ms of a 1 m slab (Appendix B)
# Appendix B, per angle of the light to the normal: b, c (the thin-slab correction of T_ms),
# kappa_c, t and r (the 1D single- and double-scattering column).
_TABLE_DEG = np.arange(0.0, 91.0, 10.0)
_TABLE = np.array(
    [
        (1.1796, 0.0138, 0.0265, 0.8389, 0.0547),
        (1.1293, 0.0154, 0.0262, 0.8412, 0.0547),
        (1.1382, 0.0131, 0.0272, 0.8334, 0.0552),
        (1.0953, 0.0049, 0.0294, 0.8208, 0.0564),
        (0.9808, 0.0012, 0.0326, 0.8010, 0.0603),
        (0.9077, 0.0047, 0.0379, 0.7774, 0.0705),
        (0.7987, 0.0207, 0.0471, 0.7506, 0.0984),
        (0.6629, 0.0133, 0.0616, 0.7165, 0.1700),
        (0.5043, 0.0280, 0.0700, 0.7149, 0.3554),
        (0.3021, 0.0783, 0.0700, 0.1000, 0.9500),
    ]
)
GROUND_ALBEDO = 0.15  # fields and towns; we know nothing of the ground under the deck
MIN_MU = 0.02  # views and lights closer than ~1 degree to the slab's plane count as 1 degree
# Scud under a deck (`BoxTemplate.under_base`): the light under a deck is diffuse, from
# above, and a ragged fragment 100-300 m thick sends down what its own thickness lets through
# of it (diffuse transmission of a thin cloud, about half to two thirds): seen from below it
# is darker than the base behind it, the dark shreds a pilot sees under nimbostratus.
SCUD_TRANSMITTANCE = 0.6
# Light from a uniformly bright hemisphere crosses a slab on average as a beam 60 degrees from
# the normal does (its mean cosine is 1/2).
DIFFUSE_ANGLE_DEG = 60.0


def slab_energy(thickness_m: F64, light_angle_deg: float) -> dict[str, F64]:
    """The 1D model's transmitted and reflected energy per order (Bouthors, Appendix A), for
    slabs of these thicknesses lit at this angle from the normal: T_ms, R_ms, T_0, T_1, T_2,
    R_1, R_2, T_3+ and R_3+, each shaped like thickness_m."""
    h = np.maximum(np.asarray(thickness_m, np.float64), 0.0)
    angle = min(max(light_angle_deg, 0.0), 90.0)
    b, c, kc, t, r = (np.interp(angle, _TABLE_DEG, _TABLE[:, i]) for i in range(5))
    mu_l = max(math.cos(math.radians(angle)), MIN_MU)
    t_ms = np.clip((b + (1.0 - b) * np.exp(-c * h)) * BETA / (h - (h - 1.0) * BETA), 0.0, 1.0)
    tau_1, tau_2, tau_3 = np.exp(-kc * h), np.exp(-2.0 * kc * h), np.exp(-3.0 * kc * h)
    t_0 = np.exp(-KAPPA_S_PER_M * h / mu_l)
    t_1 = t * h * kc * tau_1
    t_2 = (
        0.5 * (kc * t * h) ** 2 * tau_1
        + 0.25 * r * r * (1.0 + (2.0 * h * kc - 1.0) * tau_2) * tau_3
    )
    r_1 = 0.5 * r * (1.0 - tau_2)
    r_2 = 0.5 * r * t * (1.0 - (2.0 * h * kc + 1.0) * tau_2)
    r_ms = 1.0 - t_ms
    return {
        "t_ms": t_ms,
        "r_ms": r_ms,
        "t_0": t_0,
        "t_1": t_1,
        "t_2": t_2,
        "r_1": r_1,
        "r_2": r_2,
        "t_3": np.maximum(t_ms - t_0 - t_1 - t_2, 0.0),
        "r_3": np.maximum(r_ms - r_1 - r_2, 0.0),
    }


# The energies of the last few (thicknesses, angle) asked for: a frame's slab sprites are of
# a deck or two, and the key light's direction is quantised (shading_harris.scene_lights), so
# frame after frame asks for the same few, and working them out was a fifth of a deck's
# shading.
_ENERGY_KEPT = 8
_energies: OrderedDict[tuple[bytes, float], dict[str, F64]] = OrderedDict()
_energies_lock = threading.Lock()


def kept_energy(thickness_m: F64, light_angle_deg: float) -> dict[str, F64]:
    """`slab_energy`, kept for the last few thicknesses and angles asked for (read-only), with
    what slab_radiance derives from it: `ratio_r` (R_2 / R_1), `ratio_t` (T_2 / T_1), and
    `bounce` (the series of bounces between the ground and the deck's base)."""
    h = np.asarray(thickness_m, np.float64)
    key = (h.tobytes(), light_angle_deg)
    with _energies_lock:
        found = _energies.get(key)
        if found is not None:
            _energies.move_to_end(key)
            return found
    made = slab_energy(h, light_angle_deg)
    # What slab_radiance derives from them per deck, kept with them: on arrays of a deck or
    # two, the work is all numpy's overhead, frame after frame.
    made["ratio_r"] = np.divide(
        made["r_2"], made["r_1"], out=np.zeros_like(h), where=made["r_1"] > 1e-12
    )
    made["ratio_t"] = np.divide(
        made["t_2"], made["t_1"], out=np.zeros_like(h), where=made["t_1"] > 1e-12
    )
    made["bounce"] = GROUND_ALBEDO / (1.0 - GROUND_ALBEDO * made["r_ms"])
    for value in made.values():
        value.flags.writeable = False
    with _energies_lock:
        _energies[key] = made
        while len(_energies) > _ENERGY_KEPT:
            _energies.popitem(last=False)
    return made


def distinct(values: F64) -> tuple[F64, npt.NDArray[np.intp] | None]:
    """(K,) the distinct values and (N,) where each value is among them, or None where all N
    are one value (then the (1,) array broadcasts as they would). A frame's slab sprites are
    of a deck or two, each of one thickness: what depends on the thickness alone is worked
    out once a deck, to the bit what it would be sprite by sprite."""
    if len(values) == 0 or bool(np.all(values == values[0])):
        return values[:1], None
    found, where = np.unique(values, return_inverse=True)
    return found, where


def limb(mu_v: F64) -> F64:
    """Eddington's angular spread of light leaving a thick scattering layer, per Lambertian
    radiance: 1.25 along the normal, 0.5 edge-on, and the same flux as a Lambertian surface."""
    out: F64 = (1.0 + 1.5 * mu_v) / 2.0
    return out


def slab_radiance(
    thickness_m: F64,
    mu_l: float,
    mu_v: F64,
    cos_phase: F64,
    reflected: B,
) -> tuple[F64, F64]:
    """(key, sky): radiance toward the eye per unit key-light and per unit skylight irradiance,
    each (N,). mu_l is the key light's cosine to the slab's normal on its lit side (0 when the
    light is below the slab's plane), mu_v the view's, cos_phase the cosine between the view ray
    (eye to slab) and the direction to the light; `reflected` is True where the eye is on the
    lit side."""
    h_all = np.asarray(thickness_m, np.float64)
    h, where = distinct(h_all)  # what depends on the thickness alone: once per deck

    def each(per_deck: F64) -> F64:
        return per_deck if where is None else per_deck[where]

    mu_v = np.maximum(np.asarray(mu_v, np.float64), MIN_MU)
    lit = mu_l > 0.0
    mu_light = max(mu_l, MIN_MU)
    e = kept_energy(h, math.degrees(math.acos(min(mu_light, 1.0))))
    p_1 = 4.0 * math.pi * hg_phase(cos_phase, G_S)
    p_2 = 4.0 * math.pi * hg_phase(cos_phase, G_S * G_S)
    k = KAPPA_S_PER_M
    spread = limb(mu_v)
    lit_count = int(np.count_nonzero(reflected))
    on_lit_side, on_far_side = lit_count > 0, lit_count < np.size(reflected)
    # Single scattering reflected / transmitted along the ray (Bouthors 4.3), in units where
    # the Lambertian white is 1: I = a P mu_l / (4 (mu_v +- mu_l)) (1 - tau ...). Each side
    # is worked out only for the sprites on it: a deck is mostly seen from one side.
    refl = trans = np.zeros(0)
    if on_lit_side:
        ratio_r = each(e["ratio_r"])
        h_l, h_v = each(h / mu_light), each(h) / mu_v
        refl_geo = mu_light / (4.0 * (mu_v + mu_light)) * (1.0 - np.exp(-k * (h_l + h_v)))
        refl = ALBEDO * (p_1 + ratio_r * p_2) * refl_geo
    if on_far_side:
        ratio_t = each(e["ratio_t"])
        kh = k * h
        beam = each(np.exp(-kh / mu_light))  # along the light's path: once per deck
        trans_geo = mu_light / 4.0 * _exp_difference(each(kh), mu_v, mu_light, beam)
        trans = ALBEDO * (p_1 + ratio_t * p_2) * trans_geo

    def by_side(lit_side: F64, far_side: F64) -> F64:
        # A deck is mostly seen from one side: then no select over every sprite.
        if not on_far_side:
            return lit_side
        if not on_lit_side:
            return far_side
        out: F64 = np.where(reflected, lit_side, far_side)
        return out

    # Everything else a sprite sends is its deck's, per side, times the limb law's spread:
    # worked out a deck at a time (`_diffuse_terms`), it is one product per sprite.
    key_lit, key_far, sky_lit, sky_far = _diffuse_terms(h.tobytes(), mu_light)
    sky_total: F64 = by_side(each(sky_lit), each(sky_far)) * spread
    if not lit:
        return np.zeros(len(mu_v)), sky_total
    key_total: F64 = by_side(refl, trans) + by_side(each(key_lit), each(key_far)) * spread
    return key_total, sky_total


@functools.lru_cache(maxsize=_ENERGY_KEPT)
def _diffuse_terms(thickness_m: bytes, mu_light: float) -> tuple[F64, F64, F64, F64]:
    """Per deck of these thicknesses (float64 bytes), lit at mu_light: the diffuse key light
    (three and more scatterings, and what the ground sends back up of the light through the
    deck) and sky light leaving the deck, on its lit side and its far side, per unit of the
    limb law's spread. Kept like `kept_energy`, for the frames of one light."""
    h = np.frombuffer(thickness_m, np.float64)
    e = kept_energy(h, math.degrees(math.acos(min(mu_light, 1.0))))
    # Sky and ground light arrive from a whole hemisphere: the slab passes it as it passes a
    # beam at DIFFUSE_ANGLE_DEG, not at the sun's angle (at dawn the sun grazes the deck, the
    # sky does not).
    d = kept_energy(h, DIFFUSE_ANGLE_DEG)
    r_ms, t_ms = d["r_ms"], d["t_ms"]
    # Ground and base light each other: irradiance on the ground from the key light and the
    # sky through the deck, times the series of bounces between the two planes. Light the
    # ground sends up leaves the deck on the ground's side by reflection and on the far side
    # by transmission: the opposite of the light from above.
    key_to_ground = e["t_ms"] * mu_light * d["bounce"]
    sky_to_ground = t_ms * d["bounce"]
    out = (
        e["r_3"] * mu_light + key_to_ground * t_ms,
        e["t_3"] * mu_light + key_to_ground * r_ms,
        r_ms + sky_to_ground * t_ms,
        t_ms + sky_to_ground * r_ms,
    )
    for value in out:
        value.flags.writeable = False
    return out


def slab_view_radiance(
    centre_z_m: F64, slab_m: F32, view: F64, sky: SkyParams, eye_z_m: float
) -> F64:
    """(3, N) radiance toward the eye, channel by channel, from sprites of stratiform layers at
    heights `centre_z_m` (their `slab_m`: base and top MSL), along `view_rays` ((3, N)) from
    the eye. The eye is above a sprite's slab above its top, below it under its base, and
    inside it on the side of the sprite it looks at. Only the arrays it reads, so a frame's
    slab sprites among others need no sub-batch of every field."""
    base_m = slab_m[:, 0].astype(np.float64)
    top_m = slab_m[:, 1].astype(np.float64)
    # The deck is lit from the open sky above it, whatever the eye under it sees of the sky;
    # with the physical atmosphere, the sun and sky at its top (a deck's top keeps the sun
    # after the ground has lost it), each sprite's deck its own (`key_rgb_at`).
    lights = scene_lights(
        sky, above_cloud=True, alt_m=float(np.median(top_m)) if len(top_m) else None
    )
    key_dir = lights.directions[0]
    sky_rgb = lights.sky_rgb
    key_at_top = key_rgb_at(sky, top_m)
    key_rgb = lights.rgb[0][:, None] if key_at_top is None else key_at_top.T
    eye_above: B
    if len(top_m) and eye_z_m >= top_m.max():  # over every deck (or under): one side for all
        eye_above = np.ones(len(top_m), np.bool_)
    elif len(base_m) and eye_z_m <= base_m.min():
        eye_above = np.zeros(len(top_m), np.bool_)
    else:
        eye_above = np.where(
            eye_z_m >= top_m, True, np.where(eye_z_m <= base_m, False, centre_z_m <= eye_z_m)
        )
    # The light is on the top side whenever it is up; the deck is lit from below never.
    mu_l = float(key_dir[2])
    reflected = eye_above  # the key light is above every deck
    key, sky_share = slab_radiance(top_m - base_m, mu_l, np.abs(view[2]), key_dir @ view, reflected)
    # The sky term is the slab's own ambient: only the night floor (starlight, towns) is added.
    # (3, 1) by (N,): the same products as np.multiply.outer, at a quarter of the time.
    out: F64 = key_rgb * key
    out += sky_rgb[:, None] * sky_share
    out += NIGHT_FLOOR_RGB[:, None]
    # Scud under the base (a box's `under_base`): a small cloud in the light the deck lets
    # through, seen from below through its own thickness, darker than the base behind it.
    under = centre_z_m < base_m
    if under.any():
        out[:, under] *= SCUD_TRANSMITTANCE
    return out


def _exp_difference(kh: F64, mu_v: F64, mu_l: float, beam: F64) -> F64:
    """(exp(-kh / mu_v) - exp(-kh / mu_l)) / (mu_v - mu_l), and its limit kh / mu^2 exp(-kh/mu)
    where the two cosines meet (Bouthors' I_1^t with the view along the light's path);
    `beam` is exp(-kh / mu_l), which the caller works out once a deck."""
    diff = mu_v - mu_l
    near = np.abs(diff) < 1e-4
    safe = np.where(near, 1.0, diff)
    far: F64 = (np.exp(-kh / mu_v) - beam) / safe
    if not near.any():
        return far
    mid = 0.5 * (mu_v + mu_l)
    limit = kh / (mid * mid) * np.exp(-kh / mid)
    out: F64 = np.where(near, limit, far)
    return out
