"""The web station's picture is made from a reduced frame (wxsky/web/picture.py): each of its
pixels the mean of a block of the frame's, so detail finer than a block (a far rain
curtain's sheets, a cloud's edge) comes out as its mean, never as stripes of whichever
pixel was picked."""

from __future__ import annotations

import numpy as np

from wxsky.host.compositor import Layers
from wxsky.host.reference import HostFrame
from wxsky.output.frame_meta import FrameMeta
from wxsky.scene.camera import Camera
from wxsky.web.picture import box_reduced, reduced


def test_box_reduced_averages_each_block_and_repeats_the_edge() -> None:
    image = np.arange(5 * 5, dtype=np.uint8).reshape(5, 5, 1) * 10
    got = box_reduced(image, 2)
    assert got.shape == (3, 3, 1) and got.dtype == np.uint8
    # (0+10+50+60)/4 = 30; the last column's blocks are its own column twice
    # ((40+40+90+90)/4 = 65); the last row's its own row twice ((200+210+200+210)/4 = 205).
    assert got[0, 0, 0] == 30 and got[0, 2, 0] == 65 and got[2, 0, 0] == 205
    assert got[2, 2, 0] == 240  # the corner pixel alone
    half = np.full((4, 6, 4), 0.25, np.float16)
    half[:, ::2] = 0.75
    out = box_reduced(half, 2)
    assert out.dtype == np.float16 and out.shape == (2, 3, 4)
    assert np.allclose(out, 0.5)


def _striped_frame(width_px: int, height_px: int) -> HostFrame:
    """A sky of one-pixel black and white columns; a ring and near layer that show nothing."""
    camera = Camera((0.0, 0.0, 500.0), fov_deg=60.0, width_px=width_px, height_px=height_px)
    sky = np.zeros((height_px, width_px, 4), np.uint8)
    sky[..., 3] = 255
    sky[:, ::2, :3] = 255
    quads = np.zeros((8, 4, 3))
    for i in range(8):  # a ring far around the eye, each quad facing it
        a0, a1 = np.radians(45.0 * i), np.radians(45.0 * (i + 1))
        for j, (a, z) in enumerate(((a0, 3000.0), (a1, 3000.0), (a1, 0.0), (a0, 0.0))):
            quads[i, j] = (20000.0 * np.sin(a), 20000.0 * np.cos(a), z)
    clear = np.zeros((16, 16, 4), np.uint8)
    layers = Layers(
        sky=sky,
        near=np.zeros((height_px // 2, width_px // 2, 4), np.uint8),
        ring=(clear,) * 8,
        ring_quads_m=quads,
    )
    meta = FrameMeta(
        frame_number=7,
        ring_version=1,
        time_utc_unix_s=0.0,
        camera=camera,
        sun_direction_enu=(0.0, 0.0, 1.0),
        ring_centre_m=(0.0, 0.0, 0.0),
        ring_radius_m=20000.0,
        ring_quads_m=quads,
    )
    return HostFrame(meta, layers)


def test_the_pictures_frame_shows_fine_stripes_as_their_mean() -> None:
    frame = _striped_frame(640, 360)
    small = reduced(frame, 160)
    cam = small.meta.camera
    assert (cam.width_px, cam.height_px) == (160, 90) == small.layers.sky.shape[1::-1]
    assert cam.fov_deg == frame.meta.camera.fov_deg  # the same view over fewer pixels
    rgb = small.composite()[..., :3].astype(int)
    # Every pixel the stripes' mean grey: a pixel taken every 4th would be all white.
    assert np.abs(rgb - 128).max() <= 1
    whole = box_reduced(frame.composite(), 4)[..., :3].astype(int)
    assert np.abs(rgb - whole).max() <= 1
    assert reduced(frame, 640) is frame  # wide enough already: the frame as it is
