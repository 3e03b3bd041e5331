"""The binary per-frame record stored beside the pixels in each shared-memory slot.

It tells a host, for exactly the pixels in that slot, which camera drew the sky and near
layers and where the 8 ring quads stand, so a reader never pairs pixels with stale geometry.
Layout (little-endian, 920 bytes), documented in docs/protocol.md:

    u32 record_version, u32 reserved
    u64 frame_number
    u64 ring_version          (increments whenever the ring images change)
    f64 time_utc_unix_s
    f64 camera position_m[3]  (ENU metres around the observer, z = MSL)
    f64 camera heading_deg, pitch_deg, roll_deg, fov_deg (horizontal)
    u32 camera width_px, height_px
    f64 sun_direction_enu[3]
    f64 ring centre_m[3], ring radius_m
    f64 ring quads_m[8][4][3] (top-left, top-right, bottom-right, bottom-left seen from the centre)
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.errors import ProtocolError
from wxsky.scene.camera import Camera

RECORD_VERSION = 1
_FORMAT = struct.Struct("<IIQQd3d4dII3d3dd96d")
RECORD_SIZE = _FORMAT.size


@dataclass(frozen=True)
class FrameMeta:
    frame_number: int
    ring_version: int
    time_utc_unix_s: float
    camera: Camera
    sun_direction_enu: tuple[float, float, float]
    ring_centre_m: tuple[float, float, float]
    ring_radius_m: float
    ring_quads_m: npt.NDArray[np.float64]  # (8, 4, 3)

    def pack(self) -> bytes:
        cam = self.camera
        quads = np.asarray(self.ring_quads_m, dtype=np.float64).reshape(-1)
        if quads.shape != (96,):
            raise ValueError("ring_quads_m must have shape (8, 4, 3)")
        return _FORMAT.pack(
            RECORD_VERSION,
            0,
            self.frame_number,
            self.ring_version,
            self.time_utc_unix_s,
            *cam.position_m,
            cam.heading_deg,
            cam.pitch_deg,
            cam.roll_deg,
            cam.fov_deg,
            cam.width_px,
            cam.height_px,
            *self.sun_direction_enu,
            *self.ring_centre_m,
            self.ring_radius_m,
            *quads.tolist(),
        )

    @staticmethod
    def unpack(data: bytes) -> FrameMeta:
        if len(data) < RECORD_SIZE:
            raise ProtocolError(f"frame record is {len(data)} bytes, expected {RECORD_SIZE}")
        v = _FORMAT.unpack_from(data)
        if v[0] != RECORD_VERSION:
            raise ProtocolError(f"frame record version {v[0]}, this reader knows {RECORD_VERSION}")
        try:
            camera = Camera(
                position_m=(v[5], v[6], v[7]),
                heading_deg=v[8],
                pitch_deg=v[9],
                roll_deg=v[10],
                fov_deg=v[11],
                width_px=v[12],
                height_px=v[13],
            )
        except ValueError as exc:
            raise ProtocolError(f"frame record {v[2]}: {exc}") from None
        return FrameMeta(
            frame_number=v[2],
            ring_version=v[3],
            time_utc_unix_s=v[4],
            camera=camera,
            sun_direction_enu=(v[14], v[15], v[16]),
            ring_centre_m=(v[17], v[18], v[19]),
            ring_radius_m=v[20],
            ring_quads_m=np.array(v[21:117]).reshape(8, 4, 3),
        )
