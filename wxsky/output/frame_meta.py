"""The binary per-frame record stored beside the pixels in each shared-memory slot.

It tells a host, for exactly the pixels in that slot, which camera drew the sky and near
layers and where the 8 ring quads stand, so a reader never pairs pixels with stale geometry.
Layout (little-endian, 1736 bytes), documented in docs/protocol.md:

    u32 record_version (2), u32 reserved
    u64 frame_number
    u64 ring_version          (increments whenever the ring images or the fade change)
    f64 time_utc_unix_s
    f64 camera position_m[3]  (ENU metres around the observer, z = MSL)
    f64 camera heading_deg, pitch_deg, roll_deg, fov_deg (horizontal)
    u32 camera width_px, height_px
    f64 sun_direction_enu[3]
    f64 ring centre_m[3], ring radius_m
    f64 ring quads_m[8][4][3] (top-left, top-right, bottom-right, bottom-left seen from the centre)
    u32 ring_set              (the texture set, 0 or 1, the current ring lives in)
    u32 fading                (1: the incoming ring's layers are in the slot)
    f64 ring_fade             (weight of the incoming ring, 0..1; 0 unless fading)
    f64 incoming centre_m[3], radius_m, quads_m[8][4][3]  (zeros unless fading)
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.errors import ProtocolError
from wxsky.scene.camera import Camera

RECORD_VERSION = 2
_FORMAT = struct.Struct("<IIQQd3d4dII3d3dd96dIId3dd96d")
_NO_QUADS = np.zeros((8, 4, 3))
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
    ring_set: int = 0
    # While a new ring fades in: its weight, centre, radius and quads (its images are the
    # slot's ring_in_i layers); None when no fade is under way.
    ring_fade: float = 0.0
    incoming_centre_m: tuple[float, float, float] | None = None
    incoming_radius_m: float = 0.0
    incoming_quads_m: npt.NDArray[np.float64] | None = None

    @property
    def fading(self) -> bool:
        return self.incoming_quads_m is not None

    def pack(self) -> bytes:
        cam = self.camera
        quads = np.asarray(self.ring_quads_m, dtype=np.float64).reshape(-1)
        incoming = np.asarray(
            _NO_QUADS if self.incoming_quads_m is None else self.incoming_quads_m, np.float64
        ).reshape(-1)
        if quads.shape != (96,) or incoming.shape != (96,):
            raise ValueError("ring quads must have shape (8, 4, 3)")
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
            self.ring_set,
            int(self.fading),
            self.ring_fade if self.fading else 0.0,
            *(self.incoming_centre_m or (0.0, 0.0, 0.0)),
            self.incoming_radius_m if self.fading else 0.0,
            *incoming.tolist(),
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
            ring_set=v[117],
            ring_fade=v[119] if v[118] else 0.0,
            incoming_centre_m=(v[120], v[121], v[122]) if v[118] else None,
            incoming_radius_m=v[123] if v[118] else 0.0,
            incoming_quads_m=np.array(v[124:220]).reshape(8, 4, 3) if v[118] else None,
        )
