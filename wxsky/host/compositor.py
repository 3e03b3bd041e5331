"""The reference compositor: what a host simulator does with wxsky's layers.

Given the sky and near layers (drawn for one camera) and the 8 ring images with their world
quads, it draws, per pixel of that camera: sky, then (optionally) the host's own flat ground,
lit by the sun and darkened by the cloud-shadow map, then the ring quad the view ray meets
where it is nearer than the ground, then the near layer, each premultiplied-alpha "over" the
last. While a rebuilt ring fades in, the
ring is the old one's and the new one's pictures mixed by the fade weight, each seen through
its own quads. Pure numpy, so it is an independent check of the protocol rather than a second
copy of the renderer. Layers are RGBA8 (display values, 0..255) or float (a linear renderer's
scene-linear colour, `composite_linear`), composited alike.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from wxsky.scene.camera import FAR_M, Camera

U8 = npt.NDArray[np.uint8]
F64 = npt.NDArray[np.float64]
# A layer: RGBA8 display values or float scene-linear colour (float16: RGBA16F segment
# layers as read, float32: a linear renderer's read_linear).
Image = npt.NDArray[np.uint8] | npt.NDArray[np.float32] | npt.NDArray[np.float16]


def unit(image: Image) -> F64:
    """A layer's values as float64: RGBA8 as 0..1, a float layer as it is."""
    if image.dtype == np.uint8:
        scaled: F64 = image.astype(np.float64) / 255.0
        return scaled
    return np.asarray(image, np.float64)


@dataclass(frozen=True)
class Layers:
    sky: Image  # (H, W, 4)
    near: Image  # (H, W, 4)
    ring: tuple[Image, ...]  # (8,) of (P, P, 4)
    ring_quads_m: F64  # (8, 4, 3): top-left, top-right, bottom-right, bottom-left
    # The ring fading in, its quads, and its weight; empty when no fade is under way.
    incoming_ring: tuple[Image, ...] = ()
    incoming_quads_m: F64 | None = None
    fade: float = 0.0
    # The near sprites in front of the host's aircraft (drawn after it); None: not split.
    near_front: Image | None = None
    # The cloud-shadow map and where it lies; None: the frame has none (T = 1 everywhere).
    shadow: ShadowMap | None = None


@dataclass(frozen=True)
class ShadowMap:
    """The segment's `shadow` layer with its placement from the frame record (protocol
    "Cloud shadows"): R holds T, the share of direct sunlight the clouds let through, over a
    square of size_m on the plane up = centre_m[2], row 0 its north edge, column 0 its west."""

    image: Image  # (N, N, 4)
    centre_m: tuple[float, float, float]
    size_m: float
    sun_direction_enu: tuple[float, float, float]  # the sun the map was made for

    def transmittance(self, points_m: F64) -> F64:
        """(...) T at world points (..., 3) (east, north, up): each point moved along the
        map's sun to its plane, then the map sampled bilinearly with texel centres at
        (i + 0.5) / N and clamped edges (as GL's LINEAR with CLAMP_TO_EDGE); 1 outside the
        map, or for a sun at or below the horizon. NaN in, NaN out."""
        p = np.asarray(points_m, np.float64)
        s = np.asarray(self.sun_direction_enu, np.float64)
        out = np.ones(p.shape[:-1])
        if not s[2] > 0.0:
            return out
        lift = (self.centre_m[2] - p[..., 2]) / s[2]
        # Across (east, from the west edge) and down (south, from the north edge), 0..1.
        a = (p[..., 0] + s[0] * lift - self.centre_m[0]) / self.size_m + 0.5
        b = 0.5 - (p[..., 1] + s[1] * lift - self.centre_m[1]) / self.size_m
        inside = (a >= 0.0) & (a <= 1.0) & (b >= 0.0) & (b <= 1.0)
        out[inside] = bilinear(self.image, a[inside], b[inside])[:, 0]
        out[np.isnan(a) | np.isnan(b)] = np.nan
        return out


@dataclass(frozen=True)
class Ground:
    """A host's own flat ground at up_m (MSL), Lambertian, lit by the frame's sun:
    colour = rgb (ambient + (1 - ambient) T max(0, n.s)), n = up, T the cloud shadow there:
    what a host does with the shadow map, in its simplest form. Seen from `t` metres off it
    is in aerial perspective as wxsky's own ground band and clouds are: mixed toward
    `air_rgb` by 1 - exp(-t / haze_m) (`in_air_of` takes both from the published sky; the
    default, an endless haze distance, leaves the ground as lit)."""

    up_m: float
    sun_direction_enu: tuple[float, float, float]
    rgb: tuple[float, float, float] = (0.30, 0.38, 0.20)
    ambient: float = 0.35
    haze_m: float = math.inf
    air_rgb: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def in_air_of(self, sky: Mapping[str, Any]) -> Ground:
        """This ground in the air of a published sky (the `scene` message's "sky", as
        SkyParams.to_dict writes it): the surface's haze distance (the dome's
        "surface_haze_m", else "haze_m") and the colour the clouds fade into ("haze_rgb")."""
        dome = sky.get("dome") or {}
        haze_m = float(dome.get("surface_haze_m") or sky["haze_m"])
        r, g, b = (float(v) for v in sky["haze_rgb"])
        return dataclasses.replace(self, haze_m=haze_m, air_rgb=(r, g, b))


def layers_from_images(
    images: Mapping[str, Image],
    ring_quads_m: F64,
    incoming_quads_m: F64 | None = None,
    fade: float = 0.0,
    shadow: tuple[tuple[float, float, float], float, tuple[float, float, float]] | None = None,
) -> Layers:
    """Layers from images named as the daemon names them: sky, near, ring_0 .. ring_7, and
    while a new ring fades in (`incoming_quads_m` given), ring_in_0 .. ring_in_7; with
    `shadow` (the record's map centre, size and sun), the `shadow` image too."""
    shadow_image = images.get("shadow")
    shadow_map = None
    if shadow is not None and shadow_image is not None and shadow_image.size:
        shadow_map = ShadowMap(shadow_image, *shadow)
    n = len(ring_quads_m)
    fading = incoming_quads_m is not None
    front = images.get("near_front")  # absent (0 x 0) unless the near layer is split
    return Layers(
        sky=images["sky"],
        near=images["near"],
        ring=tuple(images[f"ring_{i}"] for i in range(n)),
        ring_quads_m=ring_quads_m,
        incoming_ring=tuple(images[f"ring_in_{i}"] for i in range(n)) if fading else (),
        incoming_quads_m=incoming_quads_m,
        fade=fade if fading else 0.0,
        near_front=front if front is not None and front.size else None,
        shadow=shadow_map,
    )


def composite(
    layers: Layers,
    camera: Camera,
    ground: Ground | None = None,
    cache: CompositeCache | None = None,
) -> U8:
    """(H, W, 4) opaque RGBA8 picture for the camera the sky and near layers were drawn for;
    with `ground`, the host's flat ground drawn over the sky and hiding the ring's clouds
    beyond it (as a host's depth buffer does). `cache`: geometry kept from the last
    composites (`CompositeCache`)."""
    out = _composite(layers, camera, ground, cache)
    result: U8 = np.round(np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)
    return result


def clouds_alpha(images: Mapping[str, Image], ring_quads_m: F64, camera: Camera) -> F64:
    """(H, W) how opaque a frame's clouds are together at each pixel (the layers named as
    `layers_from_images` names them), exactly rather than guessed from colours: composited
    over a black sky and over a white one, the two pictures differ by what the clouds let
    through (premultiplied layers: out = clouds + (1 - alpha) x sky). Not clipped: to the
    8-bit pictures' rounding."""
    seen = []
    for level in (0, 255):
        sky = np.zeros_like(images["sky"])
        sky[..., :3] = level
        sky[..., 3] = 255
        layers = layers_from_images({**images, "sky": sky}, ring_quads_m)
        seen.append(composite(layers, camera)[..., :3].astype(np.float64) / 255.0)
    alpha: F64 = 1.0 - (seen[1] - seen[0]).mean(axis=2)
    return alpha


def composite_linear(
    layers: Layers,
    camera: Camera,
    ground: Ground | None = None,
    cache: CompositeCache | None = None,
) -> F64:
    """(H, W, 3) the composite of float layers (a linear renderer's: scene-linear colour), as
    `composite` makes it, unclipped."""
    out: F64 = _composite(layers, camera, ground, cache)[..., :3]
    return out


class CompositeCache:
    """The geometry of the last composites (which ray meets which ring quad where, where a
    stretched layer's pixels read), kept while the camera and the ring stand still: a host
    compositing again and again from one viewpoint (the web station's live picture) then
    pays only for gathering texels. Each kind keeps its one latest entry."""

    def __init__(self) -> None:
        self._rings: dict[bytes, RingLookup] = {}
        self._stretch: dict[tuple[tuple[int, ...], int, int], Taps] = {}

    def ring(self, quads_m: F64, camera: Camera) -> RingLookup:
        key = repr(camera).encode() + np.ascontiguousarray(quads_m).tobytes()
        found = self._rings.get(key)
        if found is None:
            found = RingLookup.of(quads_m, camera)
            if len(self._rings) >= 2:  # the ring on show and one fading in
                self._rings.pop(next(iter(self._rings)))
            self._rings[key] = found
        return found

    def stretch(self, image: Image, width: int, height: int) -> F64:
        if image.shape[:2] == (height, width):
            return unit(image)
        key = (image.shape, width, height)
        taps = self._stretch.get(key)
        if taps is None:
            taps = stretch_taps(image.shape, width, height)
            if len(self._stretch) >= 2:  # near and its front
                self._stretch.pop(next(iter(self._stretch)))
            self._stretch[key] = taps
        return taps.sample(image).reshape(height, width, 4)


def _composite(
    layers: Layers, camera: Camera, ground: Ground | None, cache: CompositeCache | None = None
) -> F64:
    h, w = camera.height_px, camera.width_px
    if layers.sky.shape[:2] != (h, w):
        raise ValueError(
            f"the sky layer {layers.sky.shape[:2]} must match the camera viewport {(h, w)}"
        )
    out = unit(layers.sky)
    looks = cache or CompositeCache()
    ring, ring_t = looks.ring(layers.ring_quads_m, camera).sample(layers.ring)
    if layers.incoming_quads_m is not None and layers.fade > 0.0:
        incoming, in_t = looks.ring(layers.incoming_quads_m, camera).sample(layers.incoming_ring)
        ring = (1.0 - layers.fade) * ring + layers.fade * incoming
        ring_t = np.minimum(ring_t, in_t)
    if ground is not None:
        hit_t, colour = ground_colour(ground, layers.shadow, camera)
        on_ground = np.isfinite(hit_t)
        out[on_ground] = colour[on_ground]
        ring = np.where((ring_t < hit_t)[..., None], ring, 0.0)
    out = ring + (1.0 - ring[..., 3:4]) * out
    near = looks.stretch(layers.near, w, h)
    out = near + (1.0 - near[..., 3:4]) * out
    # (A host draws its own aircraft here.)
    if layers.near_front is not None:
        front = looks.stretch(layers.near_front, w, h)
        out = front + (1.0 - front[..., 3:4]) * out
    out[..., 3] = 1.0
    return out


def ground_colour(ground: Ground, shadow: ShadowMap | None, camera: Camera) -> tuple[F64, F64]:
    """(H, W) distance along each pixel's ray to the ground (inf: no hit) and (H, W, 4) the
    opaque lit colour there (Ground's formula)."""
    rays = camera.pixel_rays()
    eye = np.asarray(camera.position_m, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ground.up_m - eye[2]) / rays[..., 2]
    # Beyond the far plane a host's depth buffer clips its ground: the sky shows there.
    depth = t * (rays @ camera.basis()[2])
    t = np.where(np.isfinite(t) & (t > 0.0) & (depth <= FAR_M), t, np.inf)
    hit = np.isfinite(t)
    points = eye + rays * np.where(hit, t, 0.0)[..., None]
    sun = np.asarray(ground.sun_direction_enu, np.float64)
    direct = max(0.0, float(sun[2]) / float(np.linalg.norm(sun)))
    shade = np.ones(t.shape) if shadow is None else shadow.transmittance(points)
    light = ground.ambient + (1.0 - ground.ambient) * shade * direct
    colour = np.ones((*t.shape, 4))
    colour[..., :3] = light[..., None] * np.asarray(ground.rgb)
    if math.isfinite(ground.haze_m):
        haze = 1.0 - np.exp(-np.where(hit, t, 0.0) / max(ground.haze_m, 1e-3))
        colour[..., :3] += haze[..., None] * (np.asarray(ground.air_rgb) - colour[..., :3])
    return t, colour


def sample_ring(ring: tuple[Image, ...], quads_m: F64, camera: Camera) -> F64:
    """(H, W, 4) premultiplied colour of a ring (images on their quads) through each pixel."""
    return sample_ring_depth(ring, quads_m, camera)[0]


def sample_ring_depth(ring: tuple[Image, ...], quads_m: F64, camera: Camera) -> tuple[F64, F64]:
    """sample_ring, and (H, W) the distance along each ray to the quad it met (inf: none)."""
    return RingLookup.of(quads_m, camera).sample(ring)


@dataclass(frozen=True)
class Taps:
    """Where a bilinear sample of an image reads, for many points at once: the four texels'
    rows and columns and the weights between them (`bilinear` is `taps(...).sample`). Made
    once for a fixed geometry, it samples any image of that size again for a gather."""

    x0: npt.NDArray[np.intp]
    x1: npt.NDArray[np.intp]
    y0: npt.NDArray[np.intp]
    y1: npt.NDArray[np.intp]
    fx: F64  # (N, 1)
    fy: F64  # (N, 1)

    @classmethod
    def of(cls, shape: tuple[int, ...], a: F64, b: F64) -> Taps:
        """Taps at normalised (a across, b down) of an image of `shape`, texel centres at
        (i + 0.5) / size and edges clamped, as GL's LINEAR filter with CLAMP_TO_EDGE."""
        ph, pw = shape[:2]
        x = np.clip(a * pw - 0.5, 0.0, pw - 1.0)
        y = np.clip(b * ph - 0.5, 0.0, ph - 1.0)
        x0 = np.minimum(x.astype(int), pw - 2) if pw > 1 else np.zeros_like(x, dtype=int)
        y0 = np.minimum(y.astype(int), ph - 2) if ph > 1 else np.zeros_like(y, dtype=int)
        return cls(
            x0,
            np.minimum(x0 + 1, pw - 1),
            y0,
            np.minimum(y0 + 1, ph - 1),
            (x - x0)[:, None],
            (y - y0)[:, None],
        )

    def sample(self, image: Image) -> F64:
        """(N, 4): the four texels gathered first, then made float (a ring image is a
        megapixel, the rays that meet it a fraction of that)."""
        fx, fy = self.fx, self.fy
        top = unit(image[self.y0, self.x0]) * (1 - fx) + unit(image[self.y0, self.x1]) * fx
        bottom = unit(image[self.y1, self.x0]) * (1 - fx) + unit(image[self.y1, self.x1]) * fx
        result: F64 = top * (1 - fy) + bottom * fy
        return result


@dataclass(frozen=True)
class RingLookup:
    """Which pixel's ray meets which quad of a ring, where on it, and how far off: the
    geometry of `sample_ring_depth`, apart from the images, so that a host whose camera and
    ring stand still (the web station's picture) works it out once."""

    shape: tuple[int, int]  # (H, W)
    # Per quad some ray meets, in the ring's order: its index, the pixels' mask, and where
    # on the quad they meet it (a across, b down); a later, nearer quad's hits overwrite.
    hits: tuple[tuple[int, npt.NDArray[np.bool_], F64, F64], ...]
    best_t: F64  # (H, W) distance along each ray to the quad it met (inf: none)

    @classmethod
    def of(cls, quads_m: F64, camera: Camera) -> RingLookup:
        rays = camera.pixel_rays()
        eye = np.asarray(camera.position_m, dtype=np.float64)
        h, w = rays.shape[:2]
        best_t = np.full((h, w), np.inf)
        hits = []
        for k, quad in enumerate(quads_m):
            tl, tr, _br, bl = quad
            u, v = tr - tl, bl - tl
            normal = np.cross(u, v)
            denom = rays @ normal
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((tl - eye) @ normal) / denom
            hit_ok = np.isfinite(t) & (t > 0.0) & (t < best_t)
            p = eye + rays * np.where(hit_ok, t, 0.0)[..., None] - tl
            a = (p @ u) / (u @ u)
            b = (p @ v) / (v @ v)
            hit = hit_ok & (a >= 0.0) & (a <= 1.0) & (b >= 0.0) & (b <= 1.0)
            if not hit.any():
                continue
            hits.append((k, hit, a[hit], b[hit]))
            best_t[hit] = t[hit]
        return cls((h, w), tuple(hits), best_t)

    def sample(self, ring: tuple[Image, ...]) -> tuple[F64, F64]:
        """(H, W, 4) premultiplied colour of the ring's images through each pixel, and the
        distances (`best_t`)."""
        out = np.zeros((*self.shape, 4))
        for k, hit, a, b in self.hits:
            out[hit] = bilinear(ring[k], a, b)
        return out, self.best_t


def stretch(image: Image, width: int, height: int) -> F64:
    """(height, width, 4) 0..1: a layer drawn at another size (the near layers are drawn at a
    fraction of the picture) over the viewport, sampled bilinearly at each pixel's centre
    with edges clamped, as a host's GL does; exact when the sizes agree."""
    if image.shape[:2] == (height, width):
        return unit(image)
    return stretch_taps(image.shape, width, height).sample(image).reshape(height, width, 4)


def stretch_taps(shape: tuple[int, ...], width: int, height: int) -> Taps:
    """`stretch`'s taps of an image of `shape` over a width x height viewport."""
    a = np.broadcast_to((np.arange(width) + 0.5) / width, (height, width)).reshape(-1)
    b = np.broadcast_to(((np.arange(height) + 0.5) / height)[:, None], (height, width))
    return Taps.of(shape, a, b.reshape(-1))


def bilinear(image: Image, a: F64, b: F64) -> F64:
    """Sample (N, 4) from an image at normalised (a across, b down), texel centres at
    (i + 0.5) / size and edges clamped, as GL's LINEAR filter with CLAMP_TO_EDGE does."""
    return Taps.of(image.shape, a, b).sample(image)
