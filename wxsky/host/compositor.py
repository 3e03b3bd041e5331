"""The reference compositor: what a host simulator does with wxsky's layers.

Given the sky and near layers (drawn for one camera) and the 8 ring images with their world
quads, it draws, per pixel of that camera: sky, then the ring quad the view ray meets, then
the near layer, each premultiplied-alpha "over" the last. While a rebuilt ring fades in, the
ring is the old one's and the new one's pictures mixed by the fade weight, each seen through
its own quads. Pure numpy, so it is an independent check of the protocol rather than a second
copy of the renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.scene.camera import Camera

U8 = npt.NDArray[np.uint8]
F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Layers:
    sky: U8  # (H, W, 4)
    near: U8  # (H, W, 4)
    ring: tuple[U8, ...]  # (8,) of (P, P, 4)
    ring_quads_m: F64  # (8, 4, 3): top-left, top-right, bottom-right, bottom-left
    # The ring fading in, its quads, and its weight; empty when no fade is under way.
    incoming_ring: tuple[U8, ...] = ()
    incoming_quads_m: F64 | None = None
    fade: float = 0.0
    # The near sprites in front of the host's aircraft (drawn after it); None: not split.
    near_front: U8 | None = None


def layers_from_images(
    images: dict[str, U8],
    ring_quads_m: F64,
    incoming_quads_m: F64 | None = None,
    fade: float = 0.0,
) -> Layers:
    """Layers from images named as the daemon names them: sky, near, ring_0 .. ring_7, and
    while a new ring fades in (`incoming_quads_m` given), ring_in_0 .. ring_in_7."""
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
    )


def composite(layers: Layers, camera: Camera) -> U8:
    """(H, W, 4) opaque RGBA8 picture for the camera the sky and near layers were drawn for."""
    h, w = camera.height_px, camera.width_px
    if layers.sky.shape[:2] != (h, w) or layers.near.shape[:2] != (h, w):
        raise ValueError(
            f"sky {layers.sky.shape[:2]} and near {layers.near.shape[:2]} layers must match "
            f"the camera viewport {(h, w)}"
        )
    out = layers.sky.astype(np.float64) / 255.0
    ring = sample_ring(layers.ring, layers.ring_quads_m, camera)
    if layers.incoming_quads_m is not None and layers.fade > 0.0:
        incoming = sample_ring(layers.incoming_ring, layers.incoming_quads_m, camera)
        ring = (1.0 - layers.fade) * ring + layers.fade * incoming
    out = ring + (1.0 - ring[..., 3:4]) * out
    near = layers.near.astype(np.float64) / 255.0
    out = near + (1.0 - near[..., 3:4]) * out
    # (A host draws its own aircraft here.)
    if layers.near_front is not None:
        front = layers.near_front.astype(np.float64) / 255.0
        out = front + (1.0 - front[..., 3:4]) * out
    out[..., 3] = 1.0
    result: U8 = np.round(np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)
    return result


def sample_ring(ring: tuple[U8, ...], quads_m: F64, camera: Camera) -> F64:
    """(H, W, 4) premultiplied colour of a ring (images on their quads) through each pixel."""
    rays = camera.pixel_rays()
    eye = np.asarray(camera.position_m, dtype=np.float64)
    h, w = rays.shape[:2]
    out = np.zeros((h, w, 4))
    best_t = np.full((h, w), np.inf)
    for quad, image in zip(quads_m, ring, strict=True):
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
        out[hit] = bilinear(image, a[hit], b[hit])
        best_t[hit] = t[hit]
    return out


def bilinear(image: U8, a: F64, b: F64) -> F64:
    """Sample (N, 4) from an image at normalised (a across, b down), texel centres at
    (i + 0.5) / size and edges clamped, as GL's LINEAR filter with CLAMP_TO_EDGE does."""
    ph, pw = image.shape[:2]
    x = np.clip(a * pw - 0.5, 0.0, pw - 1.0)
    y = np.clip(b * ph - 0.5, 0.0, ph - 1.0)
    x0 = np.minimum(x.astype(int), pw - 2) if pw > 1 else np.zeros_like(x, dtype=int)
    y0 = np.minimum(y.astype(int), ph - 2) if ph > 1 else np.zeros_like(y, dtype=int)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    img = image.astype(np.float64) / 255.0
    x1 = np.minimum(x0 + 1, pw - 1)
    y1 = np.minimum(y0 + 1, ph - 1)
    top = img[y0, x0] * (1 - fx) + img[y0, x1] * fx
    bottom = img[y1, x0] * (1 - fx) + img[y1, x1] * fx
    result: F64 = top * (1 - fy) + bottom * fy
    return result
