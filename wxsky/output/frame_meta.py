"""The binary per-frame record stored beside the pixels in each shared-memory slot.

It tells a host, for exactly the pixels in that slot, which camera drew the sky and near
layers and where the 8 ring quads stand, so a reader never pairs pixels with stale geometry.
Layout (little-endian, 1800 bytes), documented in docs/protocol.md:

    u32 record_version (3), u32 reserved
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
    -- version 3 from here: the cloud-shadow map (the slot's `shadow` layer) --
    u64 shadow_version        (0: no map in this slot; otherwise changes with the map)
    f64 shadow centre_m[3]    (map centre east, north; up: the plane the map lies on)
    f64 shadow size_m         (edge of the square map)
    f64 shadow sun_direction_enu[3]  (the sun the map was made for: project along it)

    -- from 1800, only while the slot holds a `radar` layer (a longer version 3 record, whose
       extra bytes readers of before ignore) --
    u64 radar_version         (changes with the picture; never 0)
    f64 radar centre_m[3]     (where the picture was taken from: its middle pixel)
    f64 radar range_nm, tilt_deg
    f64 radar time_utc_unix_s (the simulated moment the picture shows)

Readers take version 2 records too (1736 bytes, no shadow map) and refuse other versions.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.errors import ProtocolError
from wxsky.scene.camera import Camera

RECORD_VERSION = 3
_FORMAT_V2 = struct.Struct("<IIQQd3d4dII3d3dd96dIId3dd96d")
_SHADOW = struct.Struct("<Q3dd3d")  # appended by version 3
_FORMAT = struct.Struct("<IIQQd3d4dII3d3dd96dIId3dd96dQ3dd3d")
_NO_QUADS = np.zeros((8, 4, 3))
# _FORMAT in the pieces around the two 96d quad blocks, which are packed as their bytes: one
# record a frame, and handing 192 floats to struct one by one was most of its cost.
_HEAD = struct.Struct("<IIQQd3d4dII3d3dd")
_MIDDLE = struct.Struct("<IId3dd")
assert _HEAD.size + _MIDDLE.size + _SHADOW.size + 2 * 96 * 8 == _FORMAT.size
RECORD_SIZE = _FORMAT.size
# The radar picture's placement, after a version 3 record while the slot holds one.
_RADAR = struct.Struct("<Q3dddd")
RECORD_SIZE_RADAR = RECORD_SIZE + _RADAR.size
RECORD_SIZE_V2 = _FORMAT_V2.size
READ_VERSIONS = (2, 3)


@dataclass(frozen=True)
class ShadowPlacement:
    """Where the slot's cloud-shadow map lies (docs/protocol.md, "Cloud shadows"): a square
    of size_m on the horizontal plane up = centre_m[2], centred at (centre_m[0], centre_m[1]),
    row 0 its north edge; a point P is shaded by the texel at P moved along
    sun_direction_enu to that plane."""

    version: int  # > 0; changes whenever the map's pixels do
    centre_m: tuple[float, float, float]
    size_m: float
    sun_direction_enu: tuple[float, float, float]


@dataclass(frozen=True)
class RadarPlacement:
    """The slot's weather radar picture (docs/protocol.md §1.5, docs/radar.md): north-up,
    the middle pixel at centre_m, the layer's width across twice range_nm; made for the
    simulated moment time_utc_unix_s with the antenna tilted tilt_deg."""

    version: int  # > 0; changes whenever the picture does
    centre_m: tuple[float, float, float]
    range_nm: float
    tilt_deg: float
    time_utc_unix_s: float


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
    # The slot's cloud-shadow map, or None when it has none (or the record is version 2).
    shadow: ShadowPlacement | None = None
    # The slot's radar picture (`[radar] layer`), or None when it holds none.
    radar: RadarPlacement | None = None

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
        head = _HEAD.pack(
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
        )
        middle = _MIDDLE.pack(
            self.ring_set,
            int(self.fading),
            self.ring_fade if self.fading else 0.0,
            *(self.incoming_centre_m or (0.0, 0.0, 0.0)),
            self.incoming_radius_m if self.fading else 0.0,
        )
        return b"".join(
            (
                head,
                quads.astype("<f8", copy=False).tobytes(),
                middle,
                incoming.astype("<f8", copy=False).tobytes(),
                _SHADOW.pack(*_pack_shadow(self.shadow)),
                _pack_radar(self.radar),
            )
        )

    @staticmethod
    def unpack(data: bytes) -> FrameMeta:
        # The version first: a record of another version may well have another length.
        version = struct.unpack_from("<I", data)[0] if len(data) >= 4 else None
        if version is not None and version not in READ_VERSIONS:
            known = " and ".join(map(str, READ_VERSIONS))
            raise ProtocolError(f"frame record version {version}, this reader knows {known}")
        size = RECORD_SIZE_V2 if version == 2 else RECORD_SIZE
        if len(data) < size:
            raise ProtocolError(f"frame record is {len(data)} bytes, expected {size}")
        v = _FORMAT_V2.unpack_from(data)
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
            shadow=_unpack_shadow(data, v[2]) if version == 3 else None,
            radar=_unpack_radar(data, v[2]) if version == 3 else None,
        )


def _pack_shadow(shadow: ShadowPlacement | None) -> tuple[float | int, ...]:
    if shadow is None:
        return (0, *(0.0,) * 7)
    if shadow.version <= 0:
        raise ValueError(f"shadow version must be positive, got {shadow.version}")
    return (shadow.version, *shadow.centre_m, shadow.size_m, *shadow.sun_direction_enu)


def _unpack_shadow(data: bytes, frame_number: int) -> ShadowPlacement | None:
    version, *f = _SHADOW.unpack_from(data, RECORD_SIZE_V2)
    if version == 0:
        return None
    if not all(math.isfinite(x) for x in f) or not f[3] > 0.0:
        raise ProtocolError(
            f"frame record {frame_number}: shadow placement {f} is not finite or has no size"
        )
    return ShadowPlacement(
        version=version,
        centre_m=(f[0], f[1], f[2]),
        size_m=f[3],
        sun_direction_enu=(f[4], f[5], f[6]),
    )


def _pack_radar(radar: RadarPlacement | None) -> bytes:
    if radar is None:
        return b""  # the record of before: a slot without a radar picture
    if radar.version <= 0:
        raise ValueError(f"radar version must be positive, got {radar.version}")
    return _RADAR.pack(
        radar.version, *radar.centre_m, radar.range_nm, radar.tilt_deg, radar.time_utc_unix_s
    )


def _unpack_radar(data: bytes, frame_number: int) -> RadarPlacement | None:
    if len(data) < RECORD_SIZE_RADAR:
        return None
    version, *f = _RADAR.unpack_from(data, RECORD_SIZE)
    if version == 0:
        return None
    if not all(math.isfinite(x) for x in f) or not f[3] > 0.0:
        raise ProtocolError(
            f"frame record {frame_number}: radar placement {f} is not finite or has no range"
        )
    return RadarPlacement(
        version=version,
        centre_m=(f[0], f[1], f[2]),
        range_nm=f[3],
        tilt_deg=f[4],
        time_utc_unix_s=f[5],
    )
