"""One way for the daemon's parts to plug in (issue 39): a part is anything the daemon runs
beside its frames (the METAR feeds, the cockpit links, CIGI, FlightGear, the channel bus), and
the daemon knows them only through `Part`, walking one list of them in each of its phases.

In the manner of uvicorn's lifespan (start up, serve, shut down, each bounded) and of
python-can's `BusABC` (one small base class, every hook a default): a part overrides only
what it needs. The daemon calls, on its event loop and in the list's order:

- `inputs()` once, when it is made: the rows the part adds to `status`'s `inputs`;
- `await start(ctx)` once, at start-up, after the renderer, the segment and the control
  socket: the part gets the engine and the daemon's hooks in `ctx`, opens what it reads and
  writes, and returns (what runs on is a task or a thread of its own). A part that raises
  stops the start, and the daemon shuts down;
- `before_frame()` before each frame is made (what that frame is to apply);
- `after_frame(frame)` after each frame is published;
- `status()` whenever a client asks, before `start` too: keys of its own added to
  `status` (none of the daemon's);
- `refusal(method)` before each control command: why the part refuses it, or None;
- `await close(deadline_s)` once, at shutdown, on every part whether or not it started (a
  part whose start failed, or never came, releases what its construction opened). All parts
  close together, each given the same deadline; one still closing a moment after it is
  logged by name and cut (cancelled, not waited for), so shutdown stays within `[daemon]
  shutdown_timeout_s`.

Hooks run on the loop between frames: a hook that blocks holds up every frame after it. Heavy
or blocking work belongs on a task (`asyncio.create_task`) or a thread (`asyncio.to_thread`).
A frame hook that raises is a defect and ends the daemon, as one in the daemon's own code would;
bad input a part reads is its own to count in its inputs' stats and log, rate-limited.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from wxsky.engine.stages import SkyEngine
from wxsky.errors import WxskyError
from wxsky.inputs.stats import InputStats
from wxsky.weather.state import WeatherState


def _nothing() -> None:
    return None


def _no_fps() -> float:
    return 0.0


def _no_broadcast(topic: str, params: dict[str, Any]) -> None:
    return None


async def _no_command(method: str, params: dict[str, Any], stats: InputStats) -> Any:
    raise WxskyError(f"{method}: no daemon to run it")


def _no_status() -> dict[str, Any]:
    return {}


@dataclass(frozen=True)
class PartContext:
    """What a part is given at start."""

    engine: SkyEngine
    # The `set_camera` control command's own handler: a place far from the site becomes the
    # new site. Raises a WxskyError for params it refuses.
    set_camera: Callable[[dict[str, Any]], Any]
    # Tells the stream's clients the target weather, if it changed since they were last told:
    # a part that changes the engine's inputs between frames calls it.
    publish_target: Callable[[], None] = _nothing
    fps: Callable[[], float] = _no_fps  # frames published a second, lately
    # Sends a notification to every stream client (docs/protocol.md): topic, params.
    broadcast: Callable[[str, dict[str, Any]], None] = _no_broadcast
    # Set when the daemon begins to stop: a part's tasks wait on it. A part may set it to
    # stop the daemon.
    stop: asyncio.Event = field(default_factory=asyncio.Event)
    # Runs a control command as the control channel does (the parts' refusals, the same
    # handler, its answer or a WxskyError of one line), counted in `stats`, the caller's.
    command: Callable[[str, dict[str, Any], InputStats], Awaitable[Any]] = _no_command
    status: Callable[[], dict[str, Any]] = _no_status  # the `status` command's answer


@dataclass(frozen=True)
class PublishedFrame:
    """A frame just published, as `after_frame` sees it."""

    number: int  # the frame number in the segment's record, from 1
    state: WeatherState  # the applied weather the frame shows
    # The loop's monotonic clock (`loop.time()`, `time.monotonic()`) when the frame began:
    # the frame's sim time is the clock's at that instant.
    started_s: float


class Part:
    """A part of the daemon. Every hook is a no-op: a part overrides what it needs.

    `name` names the part in the daemon's log (start-up and shutdown lines)."""

    name: str = "part"

    def inputs(self) -> Sequence[InputStats]:
        """The part's rows in `status`'s `inputs`, each named uniquely across the daemon."""
        return ()

    @property
    def holds_site(self) -> bool:
        """True while the part places the camera where a simulator's aircraft is: a preset
        applied at run time then brings its weather here rather than moving the site."""
        return False

    async def start(self, ctx: PartContext) -> None:
        """Open what the part reads and writes; return once it runs."""

    def before_frame(self) -> None:
        """Before each frame is made."""

    def after_frame(self, frame: PublishedFrame) -> None:
        """After each frame is published."""

    def status(self) -> dict[str, Any]:
        """Keys the part adds to `status` (none of the daemon's own)."""
        return {}

    def refusal(self, method: str) -> str | None:
        """Why the part refuses the control command `method` now (one line), or None."""
        return None

    async def close(self, deadline_s: float) -> None:
        """Release everything by `deadline_s` (a `time.monotonic()` reading); idempotent,
        and safe on a part that never started."""
