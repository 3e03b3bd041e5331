"""The reference host: reads wxsky exactly as a simulator would, from the stream and the
shared-memory segment alone, and composites the picture. `snapshot` must produce the same
picture; the tests hold the two to that, which is how we know the protocol is sufficient."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from wxsky.errors import WxskyError
from wxsky.host.client import ControlClient
from wxsky.host.compositor import (
    F64,
    CompositeCache,
    Ground,
    Layers,
    composite,
    composite_linear,
    layers_from_images,
)
from wxsky.output.frame_meta import FrameMeta
from wxsky.output.shm import Frame, FrameReader
from wxsky.output.transport import Address
from wxsky.scene.exposure import LEGACY_EXPOSURE, display

TOPICS = ("frame", "scene", "weather")


@dataclass(frozen=True)
class HostFrame:
    meta: FrameMeta
    layers: Layers

    @property
    def linear(self) -> bool:
        """Whether the picture layers are scene-linear half floats (RGBA16F: a daemon with
        [output] layer_format = "rgba16f") rather than display values."""
        return self.layers.sky.dtype != np.uint8

    def composite(
        self,
        ground: Ground | None = None,
        exposure: float = LEGACY_EXPOSURE,
        cache: CompositeCache | None = None,
    ) -> npt.NDArray[np.uint8]:
        """The opaque RGBA8 picture. RGBA16F layers are composited in linear, then exposed
        (`exposure`, a scale on scene-linear colour) and tone-mapped once, as an HDR host does
        (docs/linear-output.md); RGBA8 layers are composited as they are (`exposure` unused:
        the daemon exposed them)."""
        if not self.linear:
            return composite(self.layers, self.meta.camera, ground, cache)
        rgb = display(self.composite_linear(ground, cache), exposure)
        h, w = rgb.shape[:2]
        out = np.full((h, w, 4), 255, np.uint8)
        out[..., :3] = np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
        return out

    def composite_linear(
        self, ground: Ground | None = None, cache: CompositeCache | None = None
    ) -> F64:
        """(H, W, 3) the scene-linear composite of RGBA16F layers, before exposure and tone
        map (what `wxsky snapshot --linear-out` writes)."""
        if not self.linear:
            raise WxskyError(
                "composite_linear: this frame's layers are rgba8 display values; ask the "
                'daemon for rgba16f ([output] layer_format = "rgba16f")'
            )
        return composite_linear(self.layers, self.meta.camera, ground, cache)

    def shadow_at(self, points_m: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """(...) the cloud shadow T at world points (..., 3): 1 where the frame has no map."""
        if self.layers.shadow is None:
            return np.ones(np.shape(points_m)[:-1])
        return self.layers.shadow.transmittance(points_m)


def host_frame(frame: Frame) -> HostFrame:
    """Pixels and record of one shared-memory frame, ready to composite."""
    meta = FrameMeta.unpack(frame.meta)
    shadow = meta.shadow
    layers = layers_from_images(
        frame.layers,
        meta.ring_quads_m,
        meta.incoming_quads_m,
        meta.ring_fade,
        None if shadow is None else (shadow.centre_m, shadow.size_m, shadow.sun_direction_enu),
    )
    return HostFrame(meta, layers)


class ReferenceHost:
    def __init__(self, client: ControlClient, reader: FrameReader) -> None:
        self.client = client
        self.reader = reader
        self.weather: dict[str, Any] | None = None
        self.scene: dict[str, Any] | None = None
        self._closed = False

    @classmethod
    def connect(cls, address: Address | str, timeout_s: float = 5.0) -> ReferenceHost:
        client = ControlClient.connect(address, timeout_s=timeout_s)
        try:
            client.subscribe(TOPICS)
            scene = client.call("scene")
            reader = FrameReader.open(scene["shm_name"])
        except BaseException:
            client.close()
            raise
        host = cls(client, reader)
        host.scene = scene
        host.weather = client.call("status")["weather"]
        return host

    def call(self, method: str, params: dict[str, Any] | None = None) -> Any:
        return self.client.call(method, params)

    def wait_frame(self, after: int = 0, timeout_s: float = 5.0) -> HostFrame:
        """The first frame published with a number above `after`, following the stream's
        frame notifications and keeping the latest weather and scene they carry."""
        deadline = time.monotonic() + timeout_s
        while True:
            if self.reader.frame_number > after:
                frame = self.read_latest()
                if frame.meta.frame_number > after:
                    return frame
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise WxskyError(f"no frame after #{after} within {timeout_s} s")
            note = self.client.next_notification(timeout_s=min(remaining, 0.5))
            if note is None:
                continue
            if note.method == "weather":
                self.weather = note.params
            elif note.method == "scene":
                self.scene = note.params

    def wait_settled_frame(self, after: int = 0, timeout_s: float = 20.0) -> HostFrame:
        """The first frame after `after` drawn once the ring has settled: no rebuild building,
        rendering or fading in (after a camera, clock or weather change the daemon takes a
        few frames and a cross-fade to bring its ring up to date)."""
        deadline = time.monotonic() + timeout_s
        frame = self.wait_frame(after, timeout_s)
        while self.call("scene")["ring_busy"]:
            if time.monotonic() > deadline:
                raise WxskyError(f"the ring did not settle within {timeout_s} s")
            frame = self.wait_frame(frame.meta.frame_number, deadline - time.monotonic())
        return self.wait_frame(frame.meta.frame_number, max(0.1, deadline - time.monotonic()))

    def radar(
        self,
        range_nm: float = 40.0,
        tilt_deg: float = 0.0,
        size_px: int = 256,
        timeout_s: float = 30.0,
    ) -> npt.NDArray[np.float64]:
        """The daemon's weather radar picture (dBZ, north-up, the camera in the middle: the
        `radar` command), asking again until the first one for these settings is made."""
        params = {"range_nm": range_nm, "tilt_deg": tilt_deg, "size_px": size_px}
        deadline = time.monotonic() + timeout_s
        reply = self.call("radar", params)
        while reply["pending"]:
            if time.monotonic() > deadline:
                raise WxskyError(f"no radar picture within {timeout_s} s")
            time.sleep(0.05)
            reply = self.call("radar", params)
        raw = np.frombuffer(reply["pixels"], np.uint8).reshape(size_px, size_px)
        out: npt.NDArray[np.float64] = raw.astype(np.float64) * float(reply["dbz_step"]) + float(
            reply["dbz_offset"]
        )
        return out

    def read_latest(self) -> HostFrame:
        return host_frame(self.reader.read(timeout_s=1.0))

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.reader.close()
        self.client.close()

    def __enter__(self) -> ReferenceHost:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# A weather radar display's usual colours: green from 20 dBZ, yellow 30, red 40, magenta 50.
RADAR_PALETTE = (
    (20.0, (0, 150, 0)),
    (30.0, (230, 220, 0)),
    (40.0, (230, 30, 0)),
    (50.0, (220, 0, 220)),
)


def radar_display(dbz: npt.NDArray[np.float64], heading_deg: float) -> npt.NDArray[np.uint8]:
    """(N, N, 4) RGBA of a north-up radar picture as a cockpit shows it: turned so that
    `heading_deg` points up, in the usual colours on black, range rings at each quarter of the
    range in grey (nearest pixel)."""
    n = dbz.shape[0]
    half = n / 2.0
    y, x = np.mgrid[0:n, 0:n] + 0.5
    a = math.radians(heading_deg)
    right, up = x - half, half - y
    east = right * math.cos(a) + up * math.sin(a)
    north = -right * math.sin(a) + up * math.cos(a)
    cols = np.clip((east + half).astype(int), 0, n - 1)
    rows = np.clip((half - north).astype(int), 0, n - 1)
    turned = dbz[rows, cols]
    out = np.zeros((n, n, 4), np.uint8)
    out[..., 3] = 255
    r = np.hypot(right, up) / half
    for ring in (0.25, 0.5, 0.75, 1.0):
        out[np.abs(r - ring) < 0.5 / half, :3] = (90, 90, 90)
    for lo, rgb in RADAR_PALETTE:
        out[turned >= lo, :3] = rgb
    return out
