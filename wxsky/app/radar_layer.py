"""The weather radar as a segment layer (issue 43, item 5; `[radar] layer = true`).

Besides the `radar` command, a host may read the radar's picture from the shared-memory
segment every time a new one is made: the `radar` layer (`size_px` square, RGBA8, the dBZ
byte of the command's picture in R, G and B and 255 in A: a grey map, as the `shadow` layer),
its placement after the frame record (`frame_meta.RadarPlacement`), and a `radar`
notification with the first frame that carries it (the picture's bytes too, for a host that
reads no segment). The pictures are made on a thread of their own (`engine.radar_work`),
asked for every `every_s` from the moment's weather, drift and camera; each frame only looks
for the newest made, so the frames never wait on the radar and a picture slower than
`every_s` (a long range) is simply shown when it is done.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np
import numpy.typing as npt

from wxsky.app.control import radar_fields
from wxsky.engine.radar_work import Made, RadarKey, RadarWork
from wxsky.output.frame_meta import RadarPlacement
from wxsky.settings.config import RadarSection
from wxsky.weather.state import WeatherState

LAYER = "radar"

U8 = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class RadarShow:
    """A picture the layer shows: its pixels (size_px, size_px, 4), read-only, and where it
    lies; `version` counts the pictures shown, from 1."""

    version: int
    rgba: U8
    codes: bytes  # one dBZ byte a pixel, as the `radar` command's `pixels`
    placement: RadarPlacement
    made: Made

    @property
    def px(self) -> int:
        return int(self.rgba.shape[0])

    def notification(self, frame_number: int) -> dict[str, Any]:
        """The `radar` notification (docs/protocol.md §4), with the first frame carrying it."""
        p = self.placement
        return {
            "frame_number": frame_number,
            "version": self.version,
            "range_nm": p.range_nm,
            "tilt_deg": p.tilt_deg,
            "size_px": self.px,
        } | radar_fields(self.made, self.codes)


def shown(version: int, made: Made, key: RadarKey) -> RadarShow:
    """A made picture as the layer's pixels and placement."""
    codes = made.picture.to_bytes()
    px = key[2]
    grey = np.frombuffer(codes, np.uint8).reshape(px, px)
    rgba = np.empty((px, px, 4), np.uint8)
    rgba[..., :3] = grey[..., None]
    rgba[..., 3] = 255
    rgba.flags.writeable = False  # handed to the render thread: never changed after this
    pic = made.picture
    placement = RadarPlacement(
        version=version,
        centre_m=pic.centre_m,
        range_nm=key[0],
        tilt_deg=pic.tilt_deg,
        time_utc_unix_s=datetime.fromisoformat(made.time_utc).timestamp(),
    )
    return RadarShow(version, rgba, codes, placement, made)


class RadarLayer:
    """`step` once a frame on the daemon's loop; `shown` is the picture for the frame path to
    publish (None until the first is made); `close` stops the radar's thread."""

    def __init__(self, section: RadarSection) -> None:
        self.key: RadarKey = (section.range_nm, section.tilt_deg, section.size_px)
        self.every_s = section.every_s
        self.shown: RadarShow | None = None
        self._work = RadarWork()
        self._next_ask_s = float("-inf")
        self._made: Made | None = None

    def step(
        self,
        now_s: float,
        state: WeatherState,
        drift: Sequence[tuple[float, float]],
        centre_m: tuple[float, float, float],
    ) -> RadarShow | None:
        """Ask for a picture of this moment every `every_s` (a request still waiting is
        replaced: the thread makes the newest), and take the newest one made as `shown`."""
        if now_s >= self._next_ask_s:
            self._next_ask_s = now_s + self.every_s
            made = self._work.ask(self.key, state, drift, centre_m)
        else:
            made = self._work.latest(self.key)
        if made is not None and made is not self._made:
            self._made = made
            version = 1 if self.shown is None else self.shown.version + 1
            self.shown = shown(version, made, self.key)
        return self.shown

    @property
    def made_count(self) -> int:
        return self._work.made_count

    @property
    def failed(self) -> int:
        return self._work.failed

    def close(self, wait_s: float) -> None:
        self._work.close(wait_s)
