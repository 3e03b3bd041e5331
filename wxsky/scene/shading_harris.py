"""Harris's cloud shading for sprites: light reaching each particle from the sun (or the moon)
and a few skylights, precomputed by multiple forward scattering (`scattering.incident_light`),
then scattered toward the eye at render time (eq. 9) in two parts: the key light's beam that
reached the particle, through the droplets' forward-peaked phase function (`cloud_phase`), and
the light scattered many times inside the cloud, through a nearly isotropic one. So a particle
deep in a cloud between the eye and a low sun, which the beam does not reach, is dark, and a
thin edge the beam crosses blazes with the forward peak (a silver lining); with the sun behind
the eye the same particles show their lit faces.

The optical depth toward the eye: the sprites composited back to front (eq. 9's recurrence)
let a soft sprite's neighbours show through its gaps far more than a cloud's tens of optical
depths would, and the forward peak (50 times a lit face's light) shines through any gap. So
what a sprite sends toward the eye is first dimmed by the cloud between it and the eye
(`view_depth`: the chord through its cloud, taken as a ball, toward the eye): the beam's
single scattering by exp(-tau). The multiply scattered light, as bright as a lit face at
most, is left to the compositing.

The lights come from `cloud_light.cloud_lights`, the one place the sky hands clouds their
light (sun at the clouds' altitude, sky above, ground below).

The precompute depends on the sprites and the light directions only, so it is kept per batch
of particles in a small cache keyed by the batch's content; a sprite finds its light by its
identity (`particle_keys`), so a ring impostor's bin reads the light its whole cloud received.
Light directions are rounded to 0.001 (0.06°) before use, so a slowly moving sun reuses the
precompute for half a minute of simulated time and the result never depends on the cache.
"""

from __future__ import annotations

import functools
import hashlib
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import NamedTuple, cast

import numpy as np
import numpy.typing as npt

from wxsky.scene.cloud_light import cloud_lights
from wxsky.scene.exposure import display_channels
from wxsky.scene.scattering import ALBEDO, cloud_phase, diffuse_phase, incident_light
from wxsky.scene.sky import SkyParams
from wxsky.scene.sprites import F32, F64, SpriteBatch

U64 = npt.NDArray[np.uint64]

TAU_PER_SPRITE = 2.0  # optical depth through a fully formed sprite's centre
DARK_TAU = 1.0  # grey types (stratus, Cb: darkness 0.5-0.7) are this much denser per darkness
SHADOW_REACH = 0.55  # a sprite's shadow radius over its edge: its texture is soft to the rim
# Harris's forward-only scattering drops the light that many scattering events send back to a
# sun-facing eye (why a cloud's sunlit side is white). Of the key light leaving a particle
# toward the eye, this share is such light (the multiple-scattering octaves of the beam,
# through `diffuse_phase`); the rest is the beam itself through the droplets' `cloud_phase`.
DIFFUSE_SHARE = 0.55
OCTAVES, OCTAVE_GAIN = 3, 0.5  # see multiple_scattering (written out for these values)
EXPOSURE = 3.3  # radiance to display: 1 - exp(-EXPOSURE L) keeps 0..1, rolls off highlights
# ...then e -> e (e + TOE) / (1 + TOE): the curve's shoulder alone squeezed a sunlit top
# (L 0.8) and its base in shade (L 0.3) to 0.89 and 0.57, a light grey; the toe keeps the base
# a darker grey (0.43) and the top white (0.83), as a camera's S-shaped curve does, and the
# darkest clouds (night) at 0.43 of their value, not black.
TOE = 0.6
# A highlight far past white (a silver lining: the forward peak is 50 times a lit face's
# light) bleaches toward white as film and eyes see it, instead of keeping the hue of the
# light at full strength: between these exposed peaks (EXPOSURE times the brightest channel)
# the colour turns from hue-kept to channel by channel.
WHITEN_FROM, WHITEN_TO = 1.5, 5.0
# Skylights (Harris 2.3.1): the zenith and three points a quarter up the sky, one on the sun's
# side and two away from it, so sky-lit shadow sides are not black.
SKY_ELEVATION_DEG = 25.0
SKY_AZIMUTHS_DEG = (0.0, 120.0, 240.0)  # from the sun's azimuth
SKY_GAIN = (0.2, 0.1, 0.1, 0.1)  # zenith, then the three; of the sky colour there
# The low skylight on the sun's side takes this much of the horizon colour (the glow round a
# low sun); the two away from the sun SKY_AWAY_MIX of it: the sky opposite a low sun is the
# blue of the sky overhead more than the sunset horizon's orange, so a cloud's shaded side
# turns blue-grey, not orange.
SKY_HORIZON_MIX = 0.6
SKY_AWAY_MIX = 0.25
# Starlight, airglow and the glow of towns: clouds at night are dark, never black.
NIGHT_FLOOR_RGB = np.array([0.014, 0.016, 0.022])
AMBIENT_SHARE = 0.05  # Harris's small ambient term, of the mean sky colour (the ground apart)
_QUANTUM = 1e-3
# Harris's light on a particle changes slowly with the lights' directions, which the sun
# (and the skylights, set by its azimuth) move 0.1-0.5 degrees a minute: light worked out for
# directions within this angle of the sky's may be used as is (`close_directions`). Rounded
# to 1e-3, one of the 18 components crossed a step every half second, and the frame that saw
# it made the near layer's light again (15-20 ms on a 2-core CPU); now a frame does so every
# minute or two. What the kept light gives differs from light made anew by at most 0.13/255
# on average and 3.4/255 in one sprite (fair-cumulus, scattered-cumulus, thunderstorm).
LIGHT_REUSE_DEG = 0.5
_CACHE_SIZE = 8


@dataclass(frozen=True)
class Lights:
    """The lights a batch is shaded with: the key light (sun or moon) first, then the sky."""

    directions: F64  # (L, 3) unit vectors towards each light, rounded to _QUANTUM
    rgb: F64  # (L, 3) each light's colour and strength
    ambient_rgb: F64  # (3,) on every side of a cloud
    # (3,) the ground's light, on a cloud's base: a sprite at the base takes all of it, one at
    # the top none (`harris_radiance`'s height_frac).
    ground_rgb: F64 = field(default_factory=lambda: np.zeros(3))

    @functools.cached_property
    def sky_rgb(self) -> F64:
        """(3,) the skylights together (every light but the key), read-only: a slab takes
        them as one, and the frames of a sky step share its lights."""
        out: F64 = self.rgb[1:].sum(axis=0)
        out.flags.writeable = False
        return out


@dataclass(frozen=True)
class ParticleLight:
    """Precomputed light per particle, found by particle identity."""

    keys: U64  # (M,) sorted
    # (M, L + BALL_COLUMNS) share of each light reaching the particle, in key order, then its
    # place in its cloud's ball (`cloud_balls`)
    incident: F32
    directions: F64  # (L, 3) the light directions it was computed for

    def lookup(self, batch: SpriteBatch) -> F32 | None:
        """(N, L) for the batch's sprites, or None if one of them was not in the precompute."""
        keys = particle_keys(batch)
        if len(self.keys) == 0:
            return None if len(keys) else np.zeros((0, len(self.directions)), np.float32)
        pos = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
        if not np.array_equal(self.keys[pos], keys):
            return None
        out: F32 = self.incident[pos]
        return out


class Scattered(NamedTuple):
    """The light reaching each sprite of a batch after multiple scattering, for these light
    directions: the first, eye-independent half of Harris's shading, which a caller that
    shades the same sprites frame after frame (the near layer) works out once."""

    directions: F64  # (L, 3) as `Lights.directions`
    rows: F32  # (N, L + BALL_COLUMNS) the precompute's light and ball, a row per sprite

    def take(self, index: npt.NDArray[np.intp] | npt.NDArray[np.bool_]) -> Scattered:
        rows = np.flatnonzero(index) if index.dtype == np.bool_ else index
        return Scattered(self.directions, self.rows.take(rows, axis=0))


def scattered_light(batch: SpriteBatch, lights: Lights) -> Scattered:
    """What Harris's shading lights the batch's sprites with before it looks at the eye."""
    incident = particle_light(batch, lights).lookup(batch)
    assert incident is not None  # the batch's own precompute holds every sprite
    return Scattered(lights.directions, incident)


# The last lights made for each side (below or above the clouds), with what they were made
# from: a frame asks three times for its sky's (the near layer's light, its particles and its
# slabs), and the frames of one sky step share them. Lights are frozen and never written to.
_last_lights: dict[tuple[bool, int | None], tuple[tuple[object, ...], Lights]] = {}


def scene_lights(sky: SkyParams, above_cloud: bool = False, alt_m: float | None = None) -> Lights:
    """The key light, four skylights and the ambient term for this sky; `above_cloud`: the
    skylights of the open sky over every layer (what lights the top of a deck), not the sky
    the eye sees. `alt_m`: the clouds' altitude (MSL) for the physical atmosphere's light
    (`cloud_light.cloud_lights`; None: its default height), rounded to ALT_STEP_M."""
    alt_q = None if alt_m is None or not math.isfinite(alt_m) else round(alt_m / ALT_STEP_M)
    key = (*_light_inputs(sky), alt_q)
    slot = (above_cloud, alt_q)
    last = _last_lights.get(slot)  # one read: another thread may replace it
    if last is not None and last[0] == key:
        return last[1]
    made = _scene_lights(sky, above_cloud, None if alt_q is None else alt_q * ALT_STEP_M)
    if len(_last_lights) > 64:  # a few decks and towers a sky; never grows past a frame's few
        _last_lights.clear()
    _last_lights[slot] = (key, made)
    return made


# The physical light at a cloud's altitude changes little over this (the sun's transmittance
# over 100 m of height at a 2-degree sun: a few per cent): lights are kept per step.
ALT_STEP_M = 100.0


def _light_inputs(sky: SkyParams) -> tuple[object, ...]:
    # What _scene_lights reads: the frames of one sky step share these objects
    # (SkyParams.at_clock), so comparing them is a few identity checks.
    return (
        sky.sun,
        sky.moon,
        sky.sun_rgb,
        sky.moon_rgb,
        sky.zenith_rgb,
        sky.horizon_rgb,
        sky.open_zenith_rgb,
        sky.open_horizon_rgb,
        sky.atmosphere,
        sky.ground_m,
        sky.cover,
    )


def _scene_lights(sky: SkyParams, above_cloud: bool, alt_m: float | None) -> Lights:
    # On plain floats, as sky_params is: a frame makes these anew (the sun moves), and on
    # (3,) arrays the numpy calls cost 0.1 ms a set, twice a frame.
    cl = cloud_lights(sky, above_cloud, alt_m)
    zenith, horizon = cl.sky_zenith_rgb, cl.sky_horizon_rgb
    sunward = [z + (h - z) * SKY_HORIZON_MIX for z, h in zip(zenith, horizon, strict=True)]
    away = [z + (h - z) * SKY_AWAY_MIX for z, h in zip(zenith, horizon, strict=True)]
    dirs = [tuple(cl.key_dir), (0.0, 0.0, 1.0)]
    rgbs = [tuple(cl.key_rgb), tuple(z * SKY_GAIN[0] for z in zenith)]
    el = math.radians(SKY_ELEVATION_DEG)
    for offset, gain in zip(SKY_AZIMUTHS_DEG, SKY_GAIN[1:], strict=True):
        az = math.radians(sky.sun.azimuth_deg + offset)
        dirs.append((math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)))
        rgbs.append(tuple(c * gain for c in (sunward if offset == 0.0 else away)))
    ambient = NIGHT_FLOOR_RGB + AMBIENT_SHARE * 0.5 * (np.asarray(zenith) + np.asarray(horizon))
    return Lights(_quantised(dirs), np.array(rgbs), ambient, np.asarray(cl.ground_rgb))


def particle_light(batch: SpriteBatch, lights: Lights) -> ParticleLight:
    """The precompute for a whole batch, cached by its content and the light directions."""
    all_keys = particle_keys(batch)
    canon = np.lexsort((all_keys, batch.cloud_id))
    cid = batch.cloud_id[canon]
    starts = np.flatnonzero(np.r_[True, cid[1:] != cid[:-1]]) if len(cid) else np.zeros(0, int)
    counts = np.diff(np.r_[starts, len(cid)])
    centre = batch.centre_m[canon]
    # Relative to each cloud's first sprite, to the centimetre: the layer's drift moves every
    # sprite of a cloud alike and must not miss the cache, nor change the result.
    rel = np.round((centre - np.repeat(centre[starts], counts, axis=0)) * 100.0) / 100.0
    tau = tau_of(batch)[canon]
    radius = (SHADOW_REACH * batch.size_m[canon]).astype(np.float32)
    keys = all_keys[canon]
    h = hashlib.blake2b(digest_size=16)
    for arr in (cid, keys, rel, tau, radius, lights.directions):
        h.update(np.ascontiguousarray(arr).tobytes())
    digest = h.digest()
    with _LOCK:
        hit = _CACHE.get(digest)
        if hit is not None:
            _CACHE.move_to_end(digest)
            return hit
    incident = incident_light(rel, radius, tau, cid, lights.directions)
    # Each particle's place in its whole cloud taken as a ball (`view_depth`), carried in the
    # light's last BALL_COLUMNS: a bin or a frame's drawn sprites hold only part of a cloud.
    incident = np.concatenate([incident, cloud_balls(rel, batch.size_m[canon], starts)], axis=1)
    by_key = np.argsort(keys, kind="stable")
    out = ParticleLight(keys[by_key], incident[by_key], lights.directions)
    with _LOCK:
        _CACHE[digest] = out
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return out


def close_directions(a: F64, b: F64, within_deg: float = LIGHT_REUSE_DEG) -> bool:
    """Whether two sets of light directions (`Lights.directions`) are the same lights, each
    within `within_deg` of the other (0: exactly equal)."""
    if a.shape != b.shape:
        return False
    # Frame after frame the lights are the same quantised directions: no sums for those.
    if a is b or a.tobytes() == b.tobytes():
        return True
    if within_deg <= 0.0:
        return bool(np.array_equal(a, b))
    return bool(np.all(np.sum(a * b, axis=1) >= math.cos(math.radians(within_deg))))


def harris_incident(
    batch: SpriteBatch,
    lights: Lights,
    light: ParticleLight | None = None,
    scattered: Scattered | None = None,
) -> F32:
    """(N, L + BALL_COLUMNS) the share of each of `lights`' beam reaching each of the batch's
    sprites, then their place in their clouds (`cloud_balls`):
    `scattered`'s rows where its directions are these within LIGHT_REUSE_DEG, else from
    `light` (a precompute holding these sprites) or a new one."""
    if scattered is not None and close_directions(scattered.directions, lights.directions):
        return scattered.rows
    found = None
    if light is not None and np.array_equal(light.directions, lights.directions):
        found = light.lookup(batch)
    if found is None:
        found = particle_light(batch, lights).lookup(batch)
        assert found is not None  # the batch's own precompute holds every sprite
    return found


# The share of the ground's light a cloud's base sends back down (a thick cloud's diffuse
# reflectance; Bouthors' R_ms of a cumulus).
BASE_REFLECTANCE = 0.6


def harris_radiance(
    view: F64,
    incident: F32,
    lights: Lights,
    height_frac: F32 | F64 | None = None,
    eye_depth: F64 | None = None,
    key_rgb: F64 | None = None,
    limb: F64 | None = None,
) -> F64:
    """(3, N) radiance toward the eye, channel by channel, from the share of each light's beam
    reaching each sprite (`incident`, (N, L) for the L `lights`, `harris_incident`), along
    `view_rays` ((3, N)) from the eye to the sprites (eq. 9): the key light's beam through the
    droplets' phase function, and every light's multiply scattered share through the diffuse
    one; plus the ambient, and the ground's light on the lower part of a cloud (`height_frac`,
    (N,) 0 at its base, 1 at its top; None: half way). `eye_depth`: (N,) the optical depth of
    the sprite's cloud between it and the eye (`view_depth`; None: none). `key_rgb`: (N, 3)
    the key light at each sprite's own altitude (`cloud_light.key_rgb_at`: the physical sun,
    redder at a cloud's base than at its top at sunset); None: the lights' key for all.
    Exposed and given the sprites' opacity as alpha (`shading.sprite_colours`), the renderer's
    back-to-front blending is eq. 9's recurrence, with alpha as 1 - T."""
    return _harris(view, incident, lights, height_frac, eye_depth, key_rgb, False, limb)[0]


def harris_radiance_and_rim(
    view: F64,
    incident: F32,
    lights: Lights,
    height_frac: F32 | F64 | None,
    eye_depth: F64 | None,
    key_rgb: F64 | None,
    limb: F64 | None = None,
) -> tuple[F64, F64]:
    """`harris_radiance`, and (3, N) the radiance of each sprite's thin outer texels (its
    rim): the same light without the cloud between the sprite's centre and the eye on the
    droplets' forward beam. Where a sprite's edge reaches past its cloud's silhouette nothing
    lies between that edge and the eye, and a cloud between the eye and a low sun shows there
    the forward peak undimmed: the silver lining. (Inside the silhouette the sprites in front
    cover the rim.)"""
    out, rim = _harris(view, incident, lights, height_frac, eye_depth, key_rgb, True, limb)
    assert rim is not None
    return out, rim


def _harris(
    view: F64,
    incident: F32,
    lights: Lights,
    height_frac: F32 | F64 | None,
    eye_depth: F64 | None,
    key_rgb: F64 | None,
    want_rim: bool,
    limb: F64 | None = None,
) -> tuple[F64, F64 | None]:
    # Phase angle: between the light's travel and the way to the eye, i.e. between the
    # direction to the light and the view ray: cos 1 with the sprite right before the sun.
    cos = lights.directions @ view  # (L, N)
    beam = incident[:, : len(lights.directions)].T
    weight = diffuse_phase(cos)
    weight *= multiple_scattering(beam)
    weight[0] *= DIFFUSE_SHARE
    forward = (1.0 - DIFFUSE_SHARE) * cloud_phase(cos[0])
    single = forward * beam[0]
    # The rim's beam (the forward peak of a sprite's thin outer texels): without what the
    # cloud in front of the sprite takes off it, and on the silhouette (`limb`) in the sun's
    # undimmed light, as a fringe past the body is (LIMB_FROM). Inside the silhouette the beam's
    # dimming on the way in stays: letting every rim keep it outlined each sprite of a backlit
    # cloud in light.
    rim_single = single if limb is None else forward * (beam[0] + (1.0 - beam[0]) * limb)
    if eye_depth is not None:
        single = single * np.exp(-eye_depth)
    if limb is not None:
        # A sprite on the silhouette is its fringe throughout, not only its thin texels.
        single = single + (rim_single - single) * limb
    weight[0] += single
    out: F64 = lights.rgb.T @ weight
    key = lights.rgb[0][:, None] if key_rgb is None else key_rgb.T
    if key_rgb is not None:
        # The key's part with each sprite's own colour of it instead of the lights' one.
        out += (key - lights.rgb[0][:, None]) * weight[0]
    out *= ALBEDO
    out += lights.ambient_rgb[:, None]
    below = 0.5 if height_frac is None else 1.0 - np.asarray(height_frac, np.float64)
    out += lights.ground_rgb[:, None] * (BASE_REFLECTANCE * below)
    if not want_rim:
        return out, None
    rim: F64 = out + key * (ALBEDO * (rim_single - single))
    return out, rim


# A cloud taken as a ball about its sprites' mean centre: of this radius over the sprites' RMS
# distance from it (a uniform ball's RMS distance is sqrt(3/5) of its radius), plus half a
# sprite (the sprites' own extent).
BALL_FROM_RMS = math.sqrt(5.0 / 3.0)
BALL_COLUMNS = 4  # offset from the cloud's centre (x, y, z) and the cloud's radius
# A sprite's optical depth (`tau_of`) is through its centre; along a chord through a cloud of
# overlapping soft sprites the mean extinction is about half that over a sprite's size.
VIEW_EXTINCTION_SHARE = 0.5


def cloud_balls(rel_m: F64, size_m: F32 | F64, starts: npt.NDArray[np.intp]) -> F32:
    """(N, BALL_COLUMNS) each sprite's offset (x, y, z) from its cloud's mean centre and the
    radius of its cloud taken as a ball, for sprites `rel_m` (N, 3) grouped by cloud, each
    cloud's first at `starts`."""
    n = len(rel_m)
    out = np.zeros((n, BALL_COLUMNS), np.float32)
    if n == 0:
        return out
    counts = np.diff(np.r_[starts, n])
    rel = np.asarray(rel_m, np.float64)
    mean = np.add.reduceat(rel, starts, axis=0) / counts[:, None]
    off = rel - np.repeat(mean, counts, axis=0)
    r2 = np.einsum("ij,ij->i", off, off)
    radius = BALL_FROM_RMS * np.sqrt(np.add.reduceat(r2, starts) / counts)
    radius += 0.5 * np.add.reduceat(np.asarray(size_m, np.float64), starts) / counts
    out[:, :3] = off
    out[:, 3] = np.repeat(radius, counts)
    return out


def batch_balls(batch: SpriteBatch) -> F32:
    """`cloud_balls` of the clouds as this batch holds them (Wang's sprites, which have no
    precompute over whole clouds)."""
    order = np.argsort(batch.cloud_id, kind="stable")
    cid = batch.cloud_id[order]
    starts = np.flatnonzero(np.r_[True, cid[1:] != cid[:-1]]) if len(cid) else np.zeros(0, int)
    balls = cloud_balls(batch.centre_m[order], batch.size_m[order], starts)
    out = np.empty_like(balls)
    out[order] = balls
    return out


def view_depth(batch: SpriteBatch, view: F64, balls: F32 | None = None) -> F64:
    """(N,) optical depth of each sprite's cloud between the sprite and the eye: the chord
    from the sprite's near side toward the eye (against `view`, (3, N) `view_rays`) to the
    edge of its cloud taken as a ball (`balls`, (N, BALL_COLUMNS) from the light's precompute
    over whole clouds; None: `batch_balls`), times the sprite's extinction (its optical
    depth over its size, `tau_of`). Zero for a sprite on its cloud's near face."""
    return _ball_chords(batch, view, balls).depth


class _BallChords(NamedTuple):
    """Each sprite's place in its cloud's ball seen along the view (`_ball_chords`)."""

    depth: F64  # (N,) `view_depth`
    rel: F64  # (N, 3) offset from the ball's centre
    r2: F64  # (N,) |rel|^2
    along: F64  # (N,) rel's part toward the eye
    radius: F64  # (N,) the ball's
    size: F64  # (N,) the sprite's
    extinction: F64  # (N,) per metre


def _ball_chords(batch: SpriteBatch, view: F64, balls: F32 | None) -> _BallChords:
    n = len(batch)
    if n == 0:
        zero = np.zeros(0)
        return _BallChords(zero, np.zeros((0, 3)), zero, zero, zero, zero, zero)
    ball = batch_balls(batch) if balls is None else balls
    rel = ball[:, :3].astype(np.float64)
    r2 = np.einsum("ij,ij->i", rel, rel)
    size = np.asarray(batch.size_m, np.float64)
    radius = ball[:, 3].astype(np.float64)
    extinction = VIEW_EXTINCTION_SHARE * tau_of(batch) / np.maximum(size, 1.0)
    # |rel + t d| = R, d toward the eye (-view): t = -(rel.d) + sqrt((rel.d)^2 - |rel|^2 + R^2).
    along = -np.einsum("ij,ji->i", rel, view)
    disc = along * along - r2 + radius**2
    # From the sprite's near side: its own half is in its texture's alpha already.
    chord = np.maximum(-along + np.sqrt(np.maximum(disc, 0.0)) - 0.5 * size, 0.0)
    return _BallChords(chord * extinction, rel, r2, along, radius, size, extinction)


# A sprite's rim is its cloud's silhouette where the sprite's edge, seen from the eye, reaches
# past this share of its cloud's ball radius (fully at the ball's edge).
LIMB_FROM = 0.65


def view_depth_and_limb(
    batch: SpriteBatch,
    view: F64,
    balls: F32 | None = None,
    toward_light: F64 | None = None,
) -> tuple[F64, F64]:
    """`view_depth`, and (N,) how much of the key light's undimmed beam each sprite's fringe
    gets: how far its outer edge reaches the silhouette of its cloud seen from the eye (0
    inside LIMB_FROM of the ball's radius, 1 at its edge), times what the ball leaves of the
    beam on its way from `toward_light` ((3,) unit; None: all of it) to that edge. A fringe
    past a cloud's body is in the sun's own light wherever the sun's ray to it misses the
    body: a sun theta behind the limb once the fringe is R (1/cos theta - 1) out, 1.5 % of the
    radius at 10 degrees (the silver lining), but not the base's fringe under a high sun."""
    c = _ball_chords(batch, view, balls)
    if len(c.depth) == 0:
        return c.depth, np.zeros(0)
    across = np.sqrt(np.maximum(c.r2 - c.along * c.along, 0.0))
    t = ((across + 0.5 * c.size) / np.maximum(c.radius, 1.0) - LIMB_FROM) / (1.0 - LIMB_FROM)
    t = np.minimum(np.maximum(t, 0.0), 1.0)
    limb: F64 = t * t * (3.0 - 2.0 * t)
    if toward_light is None:
        return c.depth, limb
    # The fringe seen on the silhouette lies on the ball's limb, R out across the view from
    # its centre: a ray from there toward the light crosses the ball over 2 R cos(angle from
    # the inward normal) when it heads inward, and misses it when it heads outward.
    outward = (c.rel + c.along[:, None] * view.T) / np.maximum(across, 1e-6)[:, None]
    inward_cos = np.maximum(-(outward @ np.asarray(toward_light, np.float64)), 0.0)
    limb *= np.exp(-2.0 * c.radius * inward_cos * c.extinction)
    return c.depth, limb


def with_alpha(rgb: F64 | F32, opacity: F32) -> F32:
    """(N, 4) float32 RGBA from (3, N) colours and (N,) alphas, rounded once."""
    out = np.empty((rgb.shape[1], 4), np.float32)
    out[:, :3] = rgb.T
    out[:, 3] = opacity
    return out


def view_rays(centre_m: F64, eye_m: tuple[float, float, float], dist_m: F64 | None = None) -> F64:
    """(3, N) unit rays from the eye to each sprite, channel by channel (zero for one at the
    eye); `dist_m`: (N,) their lengths, where the caller has them. The sprites' light is
    worked out on rows of N, not N rows of three: numpy's loops then run the whole row at
    once, at a third of the time."""
    # order="C": the transpose's own layout would leave each row strided across the sprites.
    ray: F64 = np.subtract(centre_m.T, np.asarray(eye_m, np.float64)[:, None], order="C")
    dist = np.sqrt(np.einsum("ij,ij->j", ray, ray)) if dist_m is None else dist_m
    ray *= np.divide(1.0, dist, out=np.zeros(len(dist)), where=dist > 1e-6)
    return ray


def shown_channels(radiance: F64, sky: SkyParams) -> F64:
    """(3, N) display colour of (3, N) cloud radiance under `sky`: with the physical
    atmosphere, the one tone map every pass shares (`exposure.display`, the sky pass's too;
    the clouds' light is already in exposed units, cloud_light), so a cloud as bright as the
    sky behind it shows as that sky does; under the gradient sky, Harris's own curve
    (`exposed_channels`), the look the goldens hold."""
    if sky.atmosphere is not None:
        return display_channels(radiance, 1.0)
    return exposed_channels(radiance)


def exposed(radiance: F64) -> F64:
    """(N, 3) display colour in 0..1 for (N, 3) radiance. Exposure on the brightest channel,
    the others in proportion: a sunset-lit rim stays orange instead of washing out to white as
    every channel saturates."""
    return exposed_channels(radiance.T).T


def exposed_channels(radiance: F64) -> F64:
    """`exposed` of (3, N) radiance, channel by channel: (3, N). Highlights far past white
    bleach toward it (WHITEN_FROM, WHITEN_TO)."""
    r, g, b = radiance
    peak = np.maximum(np.maximum(np.maximum(r, g), b), 1e-6)
    shown = _toe(1.0 - np.exp(-EXPOSURE * peak))
    out: F64 = radiance * (shown / peak)
    bleach = np.clip((EXPOSURE * peak - WHITEN_FROM) / (WHITEN_TO - WHITEN_FROM), 0.0, 1.0)
    hot = np.flatnonzero(bleach > 0.0)
    if len(hot):
        each = _toe(1.0 - np.exp(-EXPOSURE * radiance[:, hot]))
        out[:, hot] += (each - out[:, hot]) * bleach[hot]
    return out


def _toe(e: F64) -> F64:
    out: F64 = e * (e + TOE) / (1.0 + TOE)
    return out


def multiple_scattering(incident: F32 | F64) -> F32:
    """Light inside a cloud that has been scattered many times, in every direction, fades
    far more slowly with depth than the forward beam. Harris has only the beam; we add
    Wrenninge's octaves (each half as strong and half as attenuated as the one before) on
    its optical depth L = -ln I: I' = sum_i a^i exp(-b^i L) / sum_i a^i, for a = b = 1/2 and
    three octaves (I + I^0.5 / 2 + I^0.25 / 4) / 1.75: square roots, not powers (numpy's
    float pow is eight times slower, and a frame's near layer asks for (5, N) of it)."""
    i = np.minimum(np.maximum(incident, 0.0), 1.0)  # np.clip's wrapper costs more here
    half = np.sqrt(i)
    quarter = np.sqrt(half)
    return cast("F32", (i + 0.5 * half + 0.25 * quarter) / 1.75)


def tau_of(batch: SpriteBatch) -> F32:
    """(N,) optical depth per sprite: forming clouds (low opacity) let more light through."""
    out: F32 = (TAU_PER_SPRITE * batch.opacity * (1.0 + DARK_TAU * batch.darkness)).astype(
        np.float32
    )
    return out


def particle_keys(batch: SpriteBatch) -> U64:
    """(N,) a 64-bit identity per sprite from what never changes with drift, eye or cover:
    its cloud, size, height in the cloud, rotation and texture."""
    k = batch.cloud_id.astype(np.int64).view(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    for arr, mul in (
        (np.asarray(batch.size_m, np.float32), 0xC2B2AE3D27D4EB4F),
        (np.asarray(batch.height_frac, np.float32), 0x165667B19E3779F9),
        (np.asarray(batch.rotation_rad, np.float32), 0xD6E8FEB86659FD93),
        (np.asarray(batch.texture, np.int32), 0xFF51AFD7ED558CCD),
    ):
        bits = np.ascontiguousarray(arr).view(np.uint32).astype(np.uint64)
        k = (k ^ (bits * np.uint64(mul))) * np.uint64(0x94D049BB133111EB)
        k ^= k >> np.uint64(31)
    out: U64 = k
    return out


def _quantised(dirs: list[tuple[float, ...]]) -> F64:
    out = []
    for d in dirs:
        q = [round(c / _QUANTUM) * _QUANTUM for c in d]
        norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
        out.append([c / norm for c in q])
    return np.array(out)


_CACHE: OrderedDict[bytes, ParticleLight] = OrderedDict()
_LOCK = threading.Lock()
