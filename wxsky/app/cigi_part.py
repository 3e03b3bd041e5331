"""The daemon's CIGI side: its image-generator listeners (`[cigi] listen`, `--cigi`) turned into
engine changes, and its CIGI weather source (`[cigi] send_to`, `--cigi-send`) fed from each
published frame. Everything runs on the event loop.

The hosts' Environmental Conditions Requests are answered after each published frame, at most
`[cigi] requests_per_frame` of them across the listeners (the rest wait for the next frame, in
a bounded queue), so a flood of requests costs each frame a bounded amount of work and never
stops the frames (issue 40).

What a host sets lands where the other inputs' changes land: the weather in the `cigi` slot
of the precedence stack (`engine.apply`), the camera as `set_camera` places it (a far place
becomes a new site), the clock as `set_time` sets it. The answers to Environmental Conditions
Requests come from the applied weather and the very clouds on show (`scene.conditions`).

A daemon part (`parts.py`): Start of Frame goes out after each published frame, and the
source sends then too.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from wxsky.app.parts import Part, PartContext, PublishedFrame
from wxsky.engine.stages import SkyEngine, enu_from_geodetic
from wxsky.errors import WxskyError
from wxsky.inputs.cigi_link import (
    CigiHostSocket,
    CigiIg,
    IgSettings,
    parse_networks,
    parse_udp,
)
from wxsky.inputs.stats import InputStats
from wxsky.protocols.cigi import ByteOrder, Packet
from wxsky.protocols.cigi_eye import Eye
from wxsky.protocols.cigi_session import responses
from wxsky.protocols.cigi_source import SourceFrame, host_message
from wxsky.protocols.cigi_weather import answer_layer_ids
from wxsky.scene.conditions import BlockMemo, conditions_many
from wxsky.scene.gather import Drift
from wxsky.settings.config import CigiSection
from wxsky.weather.model_profile import temperature_at_height
from wxsky.weather.state import Source, WeatherPatch, WeatherState
from wxsky.weather.stations import StationWeather

log = logging.getLogger("wxsky.app.cigi")

# A view this far or farther from the ownship looks at it from outside (a chase or tower
# view): the near clouds are split at the ownship so the host can draw it between them.
EXTERNAL_VIEW_M = 10.0
# The time the conditions answers may take after a frame, in shares of a daemon tick: what the
# frame left of its tick (the loop would sleep it out; the frame's start plus 0.9 of a tick),
# at least ANSWER_TICK_MIN, so on a renderer that fills its ticks the rate falls by at most
# that (issue 40: a host asking 20 a frame keeps 0.9 of the rate), and at most
# ANSWER_TICK_MAX, so the loop's other inputs wait no longer than that for it.
ANSWER_TICK_MIN = 0.1
ANSWER_TICK_MAX = 0.5


class CigiPart(Part):
    name = "CIGI"

    # Given at start (`PartContext`): a host is heard only after that.
    _engine: SkyEngine
    _publish_target: Callable[[], None]
    _set_camera: Callable[[dict[str, Any]], Any]
    # Whether the host's last weather put anything in the engine's CIGI slot: if so and the
    # slot is empty now, the engine handed it back after a silence (`cigi_heard`).
    _gave_weather = False

    def __init__(
        self,
        section: CigiSection,
        *,
        clock_rate: float,
        listen: Sequence[str] = (),
        send_to: Sequence[str] = (),
        blended: Callable[[], Sequence[StationWeather]] = tuple,
        region_slots: int = 0,
        tick_hz: float = 30.0,
    ) -> None:
        """`listen`, `send_to`: the command line's, besides the section's. `blended` gives the
        METAR stations blended into the weather now; with `region_slots` (the most that can be
        blended) the source sends them as regions."""
        self._clock_rate = clock_rate
        host = (
            parse_udp(section.host_address, "cigi.host_address") if section.host_address else None
        )
        allow = parse_networks(section.allow_from)
        self.igs = [
            CigiIg(
                IgSettings(
                    parse_udp(spec),
                    host,
                    allow,
                    section.view_id,
                    section.requests_per_frame,
                    section.max_regions,
                ),
                self,
            )
            for spec in dict.fromkeys((*section.listen, *listen))
        ]
        self._byte_order: ByteOrder = "little" if section.send_byte_order == "little" else "big"
        self._send_period_s = 1.0 / section.send_rate_hz if section.send_rate_hz > 0 else 0.0
        self._senders = [
            _Sender(CigiHostSocket(parse_udp(spec, "--cigi-send")), spec)
            for spec in dict.fromkeys((*section.send_to, *send_to))
        ]
        self._blended = blended
        self._region_slots = region_slots
        self._started = False
        self._host_frames: list[int | None] = [None] * len(self.igs)
        self._requests_per_frame = section.requests_per_frame
        self._tick_s = 1.0 / tick_hz
        self._first_ig = 0  # the listener served first this frame: turn about
        self._answering = False  # a frame's requests are being answered
        self._batch: _Batch | None = None  # what they share meanwhile

    @property
    def listens(self) -> bool:
        """Whether a host's weather comes in (as an image generator)."""
        return bool(self.igs)

    def inputs(self) -> list[InputStats]:
        return [ig.stats for ig in self.igs] + [s.stats for s in self._senders]

    async def start(self, ctx: PartContext) -> None:
        self._engine = ctx.engine
        self._publish_target = ctx.publish_target
        self._set_camera = ctx.set_camera
        for ig in self.igs:
            await ig.start()
        loop = asyncio.get_running_loop()
        for sender in self._senders:
            loop.add_reader(sender.sock.fileno(), sender.read)
            log.info("CIGI source sending to %s", sender.name)
        self._started = True

    async def close(self, deadline_s: float) -> None:
        for ig in self.igs:
            ig.close()
        if self._started:
            loop = asyncio.get_running_loop()
            for sender in self._senders:
                loop.remove_reader(sender.sock.fileno())
        for sender in self._senders:
            sender.sock.close()
        self._started = False

    def before_frame(self) -> None:
        """Each listener's last host frame, taken before a frame is made: the frame applies
        what had arrived by then."""
        self._host_frames = [ig.last_host_frame for ig in self.igs]

    def after_frame(self, frame: PublishedFrame) -> None:
        self._answer_requests(frame.started_s)
        for ig, host_frame in zip(self.igs, self._host_frames, strict=True):
            ig.start_of_frame(frame.number, host_frame)
        now = time.monotonic()
        for sender in self._senders:
            if now - sender.sent_at >= self._send_period_s:
                regions = self._blended() if self._region_slots else ()
                sender.send(frame.state, self._byte_order, now, regions, self._region_slots)

    def _answer_requests(self, frame_started_s: float) -> None:
        """This frame's share of the queued conditions requests: `requests_per_frame` across
        the listeners, each in turn served first, and none begun once the frame's time for
        them (ANSWER_TICK_MIN..MAX) is spent (a batch begun is finished)."""
        if not self.igs:
            return
        budget = self._requests_per_frame
        now = time.monotonic()
        tick = self._tick_s
        idle_s = frame_started_s + (1.0 - ANSWER_TICK_MIN) * tick - now
        allowed_s = min(ANSWER_TICK_MAX * tick, max(ANSWER_TICK_MIN * tick, idle_s))
        deadline_s = time.perf_counter() + allowed_s
        n = len(self.igs)
        self._answering = True
        try:
            for k in range(n):
                budget -= self.igs[(self._first_ig + k) % n].answer_queued(budget, deadline_s)
        finally:
            self._answering, self._batch = False, None
        self._first_ig = (self._first_ig + 1) % n

    def status(self) -> dict[str, Any]:
        """No keys of its own: brings its inputs' detail up to date."""
        for ig in self.igs:
            ig.refresh_detail()
        for sender in self._senders:
            sender.refresh_detail()
        return {}

    # -- CigiHandler: what a host's datagram changes -------------------------------------

    def cigi_heard(self) -> bool:
        self._engine.heard_cigi()
        return bool(self._engine.sources.cigi) or not self._gave_weather

    def cigi_weather(self, patch: WeatherPatch) -> None:
        first = not self._engine.sources.cigi
        self._engine.apply(patch)
        self._gave_weather = bool(self._engine.sources.cigi)
        if first:
            # A host's first weather (or its first after it fell silent) replaces the sky at
            # once, as a feed's first METAR does: the sky before was a stand-in until the
            # simulation said what it is, not weather to morph out of for minutes.
            self._engine.settle()
        self._publish_target()

    def cigi_camera(self, eye: Eye) -> str | None:
        params: dict[str, Any] = {
            "lat_deg": eye.lat_deg,
            "lon_deg": eye.lon_deg,
            "alt_m": eye.alt_m,
            "heading_deg": eye.heading_deg,
            "pitch_deg": eye.pitch_deg,
            "roll_deg": eye.roll_deg,
        }
        if eye.fov_deg is not None:
            params["fov_deg"] = eye.fov_deg
        try:
            self._set_camera(params)
        except WxskyError as exc:
            return str(exc)  # the listener counts it (`camera_refused`) and logs it
        if eye.offset_m < EXTERNAL_VIEW_M:
            # The pilot's eye: nothing of the aircraft to draw between clouds, and a split
            # would cost a near_front layer every frame for nothing.
            self._engine.set_aircraft(None)
            return None
        obs = self._engine.state.observer
        self._engine.set_aircraft(enu_from_geodetic(obs.lat_deg, obs.lon_deg, *eye.ownship))
        return None

    def cigi_clock(self, time_utc: datetime | None, running: bool | None) -> None:
        if time_utc is not None:
            self._engine.set_time(time_utc, source=Source.CIGI)
        if running is not None:
            self._engine.clock_rate = self._clock_rate if running else 0.0
        self._publish_target()

    def cigi_answers(self, requests: Sequence[Packet]) -> list[Packet]:
        engine = self._engine
        state, drift = engine.state, engine.drift
        # Within one frame's answering the weather stands still: its layer ids and drifted
        # blocks are worked out once for all the frame's requests.
        batch = self._batch
        if batch is None or batch.state is not state or batch.drift is not drift:
            ids = answer_layer_ids(
                state.layers, engine.target.layers, [ig.state for ig in self.igs]
            )
            batch = _Batch(state, drift, ids, BlockMemo())
            if self._answering:
                self._batch = batch
        ids = batch.ids
        obs = state.observer
        points = [
            enu_from_geodetic(
                obs.lat_deg,
                obs.lon_deg,
                float(request["lat_deg"]),
                float(request["lon_deg"]),
                float(request["alt_m"]),
            )
            for request in requests
        ]
        out: list[Packet] = []
        answered = conditions_many(state, drift, points, batch.memo)
        aloft = self._engine.aloft_temperatures
        if aloft:  # model data: its temperature at each height, not the standard atmosphere's
            answered = [
                dataclasses.replace(w, temperature_c=t)
                if (t := temperature_at_height(aloft, p[2])) is not None
                else w
                for w, p in zip(answered, points, strict=True)
            ]
        for request, weather in zip(requests, answered, strict=True):
            out += responses(request, weather, ids)
        return out


@dataclass
class _Batch:
    """What one frame's answers share: the weather they read, its layer ids, its blocks."""

    state: WeatherState
    drift: Drift
    ids: tuple[int, ...]
    memo: BlockMemo


class _Sender:
    """One IG the daemon sends its weather to, and what that IG answers."""

    def __init__(self, sock: CigiHostSocket, spec: str) -> None:
        self.sock = sock
        self.name = f"cigi-send:{spec}"
        self.stats = InputStats(self.name, "cigi-send")
        self.frame = SourceFrame()
        self.sent_at = -1e9
        self.sent = 0
        self.send_errors = 0
        self.refresh_detail()

    def send(
        self,
        state: WeatherState,
        byte_order: ByteOrder,
        now: float,
        stations: Sequence[StationWeather] = (),
        region_slots: int = 0,
    ) -> None:
        self.frame = self.frame.next()
        message = host_message(state, self.frame, stations, region_slots)
        try:
            self.sock.send(message, byte_order)
        except OSError as exc:
            self.send_errors += 1
            self.stats.error(f"send to {self.sock.to}: {exc}")
        self.sent += 1
        self.sent_at = now

    def read(self) -> None:
        got = self.sock.receive(0.0)
        if got is None:
            return
        decoded, _ = got
        if decoded.refused or decoded.direction != "ig_to_host":
            self.stats.error("a datagram that is no IG→host CIGI message", 1)
            return
        self.stats.message()
        self.frame = self.frame.heard(decoded)

    def refresh_detail(self) -> None:
        f = self.frame
        self.stats.detail = {
            "to": f"{self.sock.to[0]}:{self.sock.to[1]}",
            "sent": self.sent,
            "send_errors": self.send_errors,
            "last_ig_frame": f.last_ig_frame,
            "last_response": f.last_response,
        }
