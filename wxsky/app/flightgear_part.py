"""The daemon's FlightGear side (issue 18; plugins/flightgear/README.md): FlightGear's pose
stream moves the camera (the view's eye, direction and field of view; from a chase view, the
aircraft is where the near layer splits for the host to draw it between clouds) and,
when it owns the clock, sets the sim time; each published frame's applied weather is offered
to FlightGear's props server, so FlightGear sees wxsky's transitions as they happen.

The sockets live in `inputs/flightgear_link.py` on threads of their own; a pose is handed to
the event loop, where the camera is set as `set_camera` sets it (a far place becomes a new
site), so nothing here ever waits for FlightGear. A daemon part (`parts.py`).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import Any

from wxsky.app.parts import Part, PartContext, PublishedFrame
from wxsky.engine.stages import SkyEngine
from wxsky.errors import ConfigError
from wxsky.inputs.cigi_link import parse_udp
from wxsky.inputs.flightgear_link import FlightGearPose, FlightGearWeather
from wxsky.inputs.networks import parse_networks
from wxsky.inputs.stats import InputStats
from wxsky.protocols.flightgear import FgPose
from wxsky.settings.config import FlightGearSection
from wxsky.weather.geo import enu_from_geodetic
from wxsky.weather.state import Source

log = logging.getLogger("wxsky.app.flightgear")

CLOCK_SLACK_S = 1.0  # FlightGear's clock is taken when it is this far from wxsky's


class FlightGearPart(Part):
    name = "FlightGear"

    # Given at start (`PartContext`): a pose arrives only after that.
    engine: SkyEngine
    _set_camera: Callable[[dict[str, Any]], Any]

    def __init__(
        self, section: FlightGearSection, *, props: str | None = None, pose: str | None = None
    ) -> None:
        """`props`, `pose`: the command line's, over the section's."""
        self.section = section
        self.props = props or section.props
        self.pose_at = pose or section.pose
        self._props_addr = parse_tcp(self.props, "--flightgear") if self.props else None
        self._pose_addr = parse_udp(self.pose_at, "--flightgear-pose") if self.pose_at else None
        self._allow_from = parse_networks(section.allow_from, "flightgear.allow_from")
        self._pose: FlightGearPose | None = None
        self._weather: FlightGearWeather | None = None
        self._pose_stats = InputStats("flightgear:pose", "flightgear")
        self._weather_stats = InputStats("flightgear:weather", "flightgear", ok=False)

    @property
    def holds_site(self) -> bool:
        """FlightGear's aircraft places the camera: a preset applied at run time brings its
        weather here rather than moving the site to its own place."""
        return self._pose_addr is not None

    @property
    def enabled(self) -> bool:
        return self._props_addr is not None or self._pose_addr is not None

    def inputs(self) -> list[InputStats]:
        out = []
        if self._pose_addr is not None:
            out.append(self._pose_stats)
        if self._props_addr is not None:
            out.append(self._weather_stats)
        return out

    async def start(self, ctx: PartContext) -> None:
        self.engine = ctx.engine
        self._set_camera = ctx.set_camera
        loop = asyncio.get_running_loop()
        if self._pose_addr is not None:
            host, port = self._pose_addr

            def to_loop(pose: FgPose) -> None:
                loop.call_soon_threadsafe(self._on_pose, pose)

            self._pose = FlightGearPose(
                host,
                port,
                to_loop,
                stats=self._pose_stats,  # the daemon lists these stats
                allow_from=self._allow_from,
            )
            log.info("FlightGear pose stream on udp:%s:%d", host, self._pose.address[1])
        if self._props_addr is not None:
            host, port = self._props_addr
            self._weather = FlightGearWeather(
                host, port, self.section.write_interval_s, stats=self._weather_stats
            )
            log.info("FlightGear weather to its props server at tcp:%s:%d", host, port)

    def after_frame(self, frame: PublishedFrame) -> None:
        """A frame went out: FlightGear gets the weather it applied (only what changed, at
        most every write_interval_s)."""
        if self._weather is not None:
            self._weather.offer(frame.state, self.engine.aloft_temperatures)

    async def close(self, deadline_s: float) -> None:
        """Stop both threads together, waiting for them off the loop until the deadline."""
        links = [link for link in (self._pose, self._weather) if link is not None]
        self._pose = self._weather = None
        wait_s = max(0.0, deadline_s - time.monotonic())
        await asyncio.gather(*(asyncio.to_thread(link.close, wait_s) for link in links))

    def _on_pose(self, pose: FgPose) -> None:
        try:
            # The eye's place first: a far one becomes a new site on FlightGear's terrain
            # height (a preset's site would keep its own, and a descent over the sea would go
            # below wxsky's ground); then the camera there, looking where FlightGear's view
            # looks.
            self.engine.move_observer(
                pose.viewer_lat_deg, pose.viewer_lon_deg, ground_m=pose.ground_m
            )
            self._set_camera(
                {
                    "alt_m": pose.viewer_alt_m,
                    "heading_deg": pose.view_heading_deg,
                    "pitch_deg": pose.view_pitch_deg,
                    "roll_deg": pose.view_roll_deg,
                    "fov_deg": pose.fov_deg,
                }
            )
        except Exception as exc:  # a pose the camera refuses is counted, not fatal
            self._pose_stats.error(f"pose refused by the camera: {exc}")
            return
        if pose.internal:
            # The pilot's eye: no aircraft between the clouds to draw, and a split would cost
            # a near_front layer every frame for nothing.
            self.engine.set_aircraft(None)
        else:
            obs = self.engine.state.observer
            self.engine.set_aircraft(
                enu_from_geodetic(obs.lat_deg, obs.lon_deg, pose.lat_deg, pose.lon_deg, pose.alt_m)
            )
        if self.section.clock == "flightgear":
            ahead = (pose.time_utc - self.engine.state.time_utc).total_seconds()
            if abs(ahead) > CLOCK_SLACK_S:
                self.engine.set_time(pose.time_utc, source=Source.CONTROL)


def parse_tcp(text: str, what: str) -> tuple[str, int]:
    """`tcp:HOST:PORT` (HOST a name or an address; `[::1]` for IPv6)."""
    scheme, sep, rest = text.partition(":")
    host, sep2, port = rest.rpartition(":")
    if scheme != "tcp" or not sep or not sep2 or not host or not port.isdigit():
        raise ConfigError(f"{what} {text!r}: expected tcp:HOST:PORT, e.g. tcp:127.0.0.1:5501")
    number = int(port)
    if not 0 < number <= 65_535:
        raise ConfigError(f"{what} {text!r}: port {number} is outside 1..65535")
    return (host[1:-1] if host.startswith("[") and host.endswith("]") else host), number
