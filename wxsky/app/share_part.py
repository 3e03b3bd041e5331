"""The daemon's side of one sky shared by several daemons (docs/channels.md): a sky master
publishes its sky state, a clock tick per frame and its health; a display channel follows
them, its engine taking the master's weather, drift anchor and clock, its camera the shared
camera turned by its view offset.

Zenoh delivers on its own threads; everything here runs on the daemon's event loop
(callbacks hop over through a bounded inbox, `bus_inbox.py`), and the frame hooks run
between frames. A
daemon part (`parts.py`), always in the daemon's list: a standalone daemon's `status` has its
keys too.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import secrets
import time
from collections.abc import Callable
from datetime import datetime, timedelta
from typing import Any

from wxsky.app.bus_inbox import INBOX_LIMIT, BusInbox
from wxsky.app.parts import Part, PartContext, PublishedFrame
from wxsky.engine.stages import SharedSky, SkyEngine
from wxsky.logs import RateLimitedLog
from wxsky.output.wire import WireError, pack_data, unpack_data
from wxsky.scene.camera import Camera, turned
from wxsky.settings.config import DaemonConfig
from wxsky.share.clock import ClockFollower
from wxsky.share.credentials import Credentials
from wxsky.share.errors import BusError
from wxsky.share.messages import (
    ClockTick,
    Health,
    ShareError,
    SkyState,
    decode_pong,
    decode_state,
    decode_tick,
    encode_health,
    encode_pong,
    encode_state,
    encode_tick,
    sky_id,
)
from wxsky.weather.state import format_time_utc

log = logging.getLogger(__name__)

# A master not heard from (no tick) for this long is taken for dead, token or no token: a
# network cut leaves the token in place until Zenoh's lease runs out (10 s).
MASTER_SILENT_S = 2.0
STATE_REPEAT_S = 1.0  # the state is sent again this often (a partition heals by itself)
HEALTH_EVERY_S = 1.0
# How many channels a site may have: peers beyond it are refused and counted. A dome has 3
# to 12; 64 leaves room and keeps `status` small (each peer is a few dozen bytes).
MAX_PEERS = 64
# A master's sequence bumps once per change of its weather, at most once a frame: a state
# further ahead of the last than this (plus this per second since) is not the master's
# (issue 40: one forged state with sequence 2^63-1 froze every channel on its weather).
MAX_SEQUENCE_STEP = 1000
# A state older than the latest is a repeat overtaken by it only this soon after; later, the
# latest was not the master's (it repeats its own every second) and the older one is taken.
OVERTAKEN_WITHIN_S = 1.5
# A channel that sees no master this long after joining says so, once (not started, or it
# refused this channel's certificate: Zenoh does not tell the refused side why).
NO_MASTER_WARN_S = 5.0
WEATHER_COMMANDS = ("apply_preset", "apply_metar", "set_weather", "release", "set_time")


class SharePart(Part):
    """`role`: "master", "channel" or "standalone" (neither: nothing is shared)."""

    name = "channel bus"

    def __init__(self, config: DaemonConfig) -> None:
        self._engine: SkyEngine | None = None
        share, channel = config.share, config.channel
        self.role = "master" if share.endpoint else "channel" if channel.join else "standalone"
        self.endpoint = share.endpoint or channel.join
        self.site = share.site if share.endpoint else channel.site
        self.channel_name = channel.name if channel.join else "master"
        self._share_camera = share.camera
        self._view_offset = channel.view_offset_deg
        # A channel's own size and field of view (the daemon's camera as configured), which a
        # shared camera does not change.
        self._fov_deg = channel.fov_deg or config.camera.fov_deg
        self._size_px = (config.camera.width, config.camera.height)
        self._master_id = secrets.token_hex(8)
        section = share if share.endpoint else channel
        self._credentials = Credentials.of(
            section.ca_certificate, section.certificate, section.private_key
        )
        self._section = "share" if share.endpoint else "channel"
        self._bus: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._sequence = 0
        self._sent_version: tuple[int, int, float] | None = None
        self._sent_at = 0.0
        self._latest_state: bytes | None = None
        self._state: SkyState | None = None  # a channel's latest good one (a master's own)
        self._follower = ClockFollower()
        self._tick_at: float | None = None  # local monotonic of the latest tick
        self._fetching = False  # a state query in flight
        # The masters' tokens on the site (run id -> when seen), and the one followed: the
        # earliest still alive. Ticks, states and pongs of any other run are dropped.
        self._masters: dict[str, float] = {}
        self._live_master: str | None = None
        self._state_at = 0.0  # local monotonic of the latest state taken
        self._drops: dict[str, int] = {}
        self._inbox: BusInbox | None = None
        self._drop_log = RateLimitedLog(log)
        # The peers: channels whose token is alive, at most MAX_PEERS; their health.
        self._channels: set[str] = set()
        self._refused = 0
        self._health: dict[str, dict[str, Any]] = {}
        self._frames = 0
        self._last_frame: tuple[float, datetime] | None = None  # (monotonic, sim time)
        self._fps: Callable[[], float] = lambda: 0.0

    @property
    def shared(self) -> bool:
        return self.role != "standalone"

    @property
    def engine(self) -> SkyEngine:
        if self._engine is None:
            raise RuntimeError("the channel bus part has not started")
        return self._engine

    # -- life ---------------------------------------------------------------------------

    async def start(self, ctx: PartContext) -> None:
        """Open the bus (a master claims its site first: a second master refuses to start)."""
        self._engine = ctx.engine
        self._fps = ctx.fps
        if not self.shared:
            return
        from wxsky.share.zenoh_bus import ShareBus

        loop = self._loop = asyncio.get_running_loop()
        self._inbox = BusInbox(loop, self._inbox_full)
        self._check_credentials()
        open_bus = functools.partial(
            ShareBus,
            self.endpoint,
            role=self.role,
            site=self.site,
            name=self.channel_name,
            credentials=self._credentials,
        )
        try:
            self._bus = await loop.run_in_executor(None, open_bus)
        except BusError:
            if self.role == "master":  # the endpoint is taken: by this site's master?
                await loop.run_in_executor(None, self._no_master_there)
            raise
        bus = self._bus
        if self.role == "master":
            try:
                await loop.run_in_executor(None, bus.claim_master, self._master_id)
            except BaseException:
                bus.close()
                self._bus = None
                raise
            bus.serve(lambda: self._latest_state, self._pong)
            self._publish_state(time.monotonic(), force=True)
        else:
            bus.on_state(self._hop("state", self._got_state))
            bus.on_tick(self._hop("tick", self._got_tick))
            bus.on_master(self._hop("master", self._master_seen, droppable=False))
            bus.announce_channel()
            self._tasks.append(asyncio.create_task(self._pinger()))
            self._tasks.append(asyncio.create_task(self._warn_without_master()))
            first = await loop.run_in_executor(None, bus.fetch_state)
            if first is not None:
                self._got_state(first, time.monotonic())
        bus.on_channel(self._hop("channel", self._channel_seen, droppable=False))
        bus.on_health(self._hop("health", self._got_health))
        self._tasks.append(asyncio.create_task(self._heartbeat()))
        log.info(
            "sky %s on zenoh:%s, site %r%s",
            self.role,
            self.endpoint,
            self.site,
            f", channel {self.channel_name!r}" if self.role == "channel" else "",
        )

    async def close(self, deadline_s: float) -> None:
        """Leave the bus (a master's channels see it go at once); idempotent."""
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._tasks.clear()
        bus, self._bus = self._bus, None
        self._loop = None
        if self._inbox is not None:
            self._inbox.close()
        if bus is None:
            return
        leave = asyncio.get_running_loop().run_in_executor(None, bus.close)
        try:
            await asyncio.wait_for(leave, timeout=max(0.0, deadline_s - time.monotonic()))
        except TimeoutError:
            log.warning("shutdown: the channel bus did not close in time; left it")

    # -- the frame hooks ------------------------------------------------------------------

    def before_frame(self) -> None:
        """A channel's engine takes the master's sim time and shared camera for this frame."""
        if self.role != "channel":
            return
        now = time.monotonic()
        when = self._follower.time_at(now)
        if when is not None and self._state is not None:
            self.engine.follow_time(when)
        tick = self._follower.latest
        if tick is not None and tick.camera is not None and self.master_alive:
            self.engine.set_camera(self._view_of(tick.camera))
            self.engine.set_aircraft(tick.aircraft_m)

    def after_frame(self, frame: PublishedFrame) -> None:
        """After a frame: a master ticks its sim time and the instant it began (not the later
        moment of publishing), and sends its state when it changed or is due again."""
        time_utc, frame_mono_s = frame.state.time_utc, frame.started_s
        self._frames += 1
        self._last_frame = (frame_mono_s, time_utc)
        if self.role != "master" or self._bus is None:
            return
        now = frame_mono_s
        self._publish_state(time.monotonic())
        sky = self.engine.shared()
        tick = ClockTick(
            site=self.site,
            master_id=self._master_id,
            master_mono_s=now,
            time_utc=time_utc,
            rate=sky.clock_rate,
            sequence=self._sequence,
            camera=sky.camera if self._share_camera else None,
            aircraft_m=sky.aircraft_m if self._share_camera else None,
        )
        self._bus.publish_tick(pack_data(encode_tick(tick)))

    # -- what the daemon asks -------------------------------------------------------------

    def refusal(self, method: str) -> str | None:
        """Why a channel refuses a control command (the weather is the master's; the camera
        too while the master shares one), or None."""
        if self.role != "channel":
            return None
        if method in WEATHER_COMMANDS:
            return (
                f"{method}: this daemon is channel {self.channel_name!r} of a shared sky; the "
                f"weather and the clock belong to the sky master at zenoh:{self.endpoint}"
            )
        tick = self._follower.latest
        if method == "set_camera" and tick is not None and tick.camera is not None:
            return (
                f"set_camera: channel {self.channel_name!r} shows the master's shared camera "
                "turned by its view offset; set the camera on the master"
            )
        return None

    @property
    def master_alive(self) -> bool:
        if self.role == "master":
            return True
        if self.role != "channel" or self._live_master is None or self._tick_at is None:
            return False
        return time.monotonic() - self._tick_at <= MASTER_SILENT_S

    def status(self) -> dict[str, Any]:
        """`sky_id`, `channel` and `sim_clock` for `status` (before start, no sky: None)."""
        now = time.monotonic()
        offset = self._follower.offset_s
        tick = self._follower.latest
        lag_ms = None
        if self.role == "channel" and tick is not None and offset is not None:
            lag_ms = 1000.0 * (now + offset - tick.master_mono_s)
        state = self._state if self.role == "channel" else self._own_state()
        when = self.sim_time(now)
        return {
            "sky_id": None if state is None else sky_id(state),
            "channel": {
                "name": self.channel_name if self.shared else None,
                "role": self.role,
                "site": self.site if self.shared else None,
                "endpoint": self.endpoint or None,
                "master_alive": self.master_alive,
                "lag_ms": lag_ms,
                "clock_offset_ms": None if offset is None else 1000.0 * offset,
                "rtt_ms": None if self._follower.rtt_s is None else 1000.0 * self._follower.rtt_s,
                "dropped": dict(self._drops),
                "peers": dict(self._health),
                "peers_max": MAX_PEERS,
                "refused_peers": self._refused,
            },
            # The sim time at this instant of this process's monotonic clock: two daemons'
            # readings compared at one instant give their clock skew.
            "sim_clock": {
                "mono_s": now,
                "time_utc": None if when is None else _iso_us(when),
            },
        }

    def sim_time(self, local_s: float) -> datetime | None:
        """This daemon's sim time at a local monotonic reading."""
        if self.role == "channel":
            return self._follower.time_at(local_s)
        if self._engine is None:
            return None
        sky = self.engine.shared()
        at = self._last_frame
        if at is None:
            return sky.applied.time_utc
        mono, t = at
        return t + timedelta(seconds=sky.clock_rate * (local_s - mono))

    # -- a master -------------------------------------------------------------------------

    def _own_state(self) -> SkyState | None:
        if self._engine is None:
            return None
        sky = self.engine.shared()
        return _sky_state(self.site, self._master_id, self._sequence, sky)

    def _publish_state(self, now: float, force: bool = False) -> None:
        sky = self.engine.shared()
        version = (sky.weather_version, self.engine.target_version, sky.clock_rate)
        if not force and version == self._sent_version and now - self._sent_at < STATE_REPEAT_S:
            return
        if version != self._sent_version:
            self._sequence += 1
        self._sent_version, self._sent_at = version, now
        state = _sky_state(self.site, self._master_id, self._sequence, sky)
        payload = pack_data(encode_state(state))
        self._latest_state = payload
        if self._bus is not None:
            self._bus.publish_state(payload)

    def _no_master_there(self) -> None:
        """BusError if a master of this site answers on the endpoint (as a channel would)."""
        from wxsky.share.zenoh_bus import ShareBus

        with ShareBus(
            self.endpoint,
            role="channel",
            site=self.site,
            name="probe",
            credentials=self._credentials,
        ) as probe:
            if probe.master_alive(wait_s=1.0):
                raise BusError(
                    f"zenoh:{self.endpoint}: site {self.site!r} already has a sky master there"
                )

    def _pong(self) -> bytes:
        return pack_data(encode_pong(self.site, self._master_id, time.monotonic()))

    # -- a channel ------------------------------------------------------------------------

    def _hop(
        self, kind: str, handler: Callable[..., None], droppable: bool = True
    ) -> Callable[..., None]:
        """A bus callback (Zenoh's thread) that runs `handler(*values, arrival)` on the loop,
        through the bounded inbox (`bus_inbox.py`): a `droppable` message that finds it full
        is dropped and counted as a `kind` drop."""

        def deliver(*values: Any) -> None:
            inbox = self._inbox
            if inbox is not None:
                inbox.put(kind, handler, values, droppable)

        return deliver

    def _inbox_full(self, kind: str, count: int) -> None:
        self._drops[kind] = self._drops.get(kind, 0) + count
        self._drop_log.warning(
            f"share-{kind}",
            f"dropped {count} {kind} messages from the bus: {INBOX_LIMIT} were waiting already",
        )

    def _from_live_master(self, what: str, master_id: str) -> bool:
        """Whether a message's run id is the followed master's token's; if not, counted."""
        if master_id == self._live_master:
            return True
        live = "none" if self._live_master is None else repr(self._live_master)
        self._drop(what, f"from master run {master_id!r}, not the live master's token ({live})")
        return False

    def _got_state(self, payload: bytes, arrived: float) -> None:
        try:
            state = decode_state(unpack_data(payload), self.site)
        except (WireError, ShareError) as exc:
            self._drop("state", exc)
            return
        if not self._from_live_master("state", state.master_id):
            return
        latest = self._state
        if latest is not None and state.master_id == latest.master_id:
            ahead = state.sequence - latest.sequence
            bound = MAX_SEQUENCE_STEP * (1.0 + max(0.0, arrived - self._state_at))
            if ahead > bound:
                self._drop(
                    "state",
                    f"sequence {state.sequence} jumps {ahead} past {latest.sequence} "
                    f"(at most {bound:.0f} now)",
                )
                return
            if ahead < 0 and arrived - self._state_at < OVERTAKEN_WITHIN_S:
                return  # overtaken (a repeat from before a newer one)
        self._state, self._state_at = state, arrived
        self.engine.follow(
            SharedSky(
                applied=state.applied,
                target=state.target,
                anchor_utc=state.anchor_utc,
                anchor_drift=state.anchor_drift,
                clock_rate=state.clock_rate,
                weather_version=state.weather_version,
                camera=self.engine.camera,
                aircraft_m=None,
                tower_epochs=state.tower_epochs,
            )
        )

    def _got_tick(self, payload: bytes, arrived: float) -> None:
        try:
            tick = decode_tick(unpack_data(payload), self.site)
        except (WireError, ShareError) as exc:
            self._drop("clock", exc)
            return
        if not self._from_live_master("clock", tick.master_id):
            return
        dropped = self._follower.tick(tick, arrived)
        if dropped is not None:
            self._drop("clock", dropped)
            return
        self._tick_at = arrived
        new_master = self._state is None or self._state.master_id != tick.master_id
        if new_master and self._bus is not None and not self._fetching:
            # A master we have no state from (it restarted): ask for it, once at a time.
            self._fetching = True
            self._tasks.append(asyncio.create_task(self._fetch_state()))

    def _master_seen(self, master_id: str, alive: bool, arrived: float) -> None:
        """A master's token came or went: the one followed is the earliest still alive."""
        if alive:
            if master_id not in self._masters and len(self._masters) >= MAX_PEERS:
                self._refuse(f"a master token {master_id!r}: {MAX_PEERS} are there already")
                return
            self._masters.setdefault(master_id, arrived)
        else:
            self._masters.pop(master_id, None)
        live = min(self._masters, key=self._masters.__getitem__, default=None)
        if live != self._live_master:
            if live is None:
                log.info("sky master gone: keeping the last sky")
            else:
                log.info("sky master joined (run %s)", live)
            self._live_master = live
            self._tick_at = None  # alive again only by a tick of the new run
            self._health.pop("master", None)

    def _channel_seen(self, name: str, alive: bool, _arrived: float) -> None:
        """A channel's token came or went: the peer table holds the live ones, MAX_PEERS."""
        if not alive:
            self._channels.discard(name)
            self._health.pop(name, None)
            return
        if name in self._channels:
            return
        if len(self._channels) >= MAX_PEERS:
            self._refuse(f"channel {name!r}: the site has {MAX_PEERS} channels already")
            return
        self._channels.add(name)

    def _refuse(self, why: str) -> None:
        self._refused += 1
        self._drop_log.warning("share-refused", f"refused a peer on the bus: {why}")

    def _got_health(self, name: str, payload: bytes, _arrived: float) -> None:
        from wxsky.share.messages import decode_health

        master = self.role == "master" or self._live_master is not None
        if name not in self._channels and not (name == "master" and master):
            # Only a peer whose token is alive is kept: a stranger's names cannot grow the
            # table (issue 40: 100,000 names made `status` too big to send).
            self._drop("health", f"from {name[:64]!r}, which has no token on the bus")
            return
        try:
            health = decode_health(unpack_data(payload), self.site)
        except (WireError, ShareError) as exc:
            self._drop("health", exc)
            return
        if health.name != name or (health.role == "master") != (name == "master"):
            self._drop("health", f"{health.role} {health.name!r} on the key of {name[:64]!r}")
            return
        self._health[name] = {
            "role": health.role,
            "fps": health.fps,
            "lag_ms": health.lag_ms,
            "frames": health.frames,
        }

    async def _fetch_state(self) -> None:
        try:
            if self._bus is None or self._loop is None:
                return
            payload = await self._loop.run_in_executor(None, self._bus.fetch_state)
            if payload is not None:
                self._got_state(payload, time.monotonic())
        finally:
            self._fetching = False
            self._tasks = [t for t in self._tasks if not t.done()]

    async def _pinger(self) -> None:
        assert self._loop is not None
        while True:
            bus = self._bus
            if bus is not None:
                answer = await self._loop.run_in_executor(None, bus.ping)
                if answer is not None:
                    sent, payload, received = answer
                    try:
                        master_id, mono_s = decode_pong(unpack_data(payload), self.site)
                    except (WireError, ShareError) as exc:
                        self._drop("pong", exc)
                    else:
                        if self._from_live_master("pong", master_id):
                            dropped = self._follower.ping(sent, mono_s, received, master_id)
                            if dropped is not None:
                                self._drop("pong", dropped)
            await asyncio.sleep(self._follower.wait_before_ping_s())

    async def _heartbeat(self) -> None:
        while True:
            await asyncio.sleep(HEALTH_EVERY_S)
            bus = self._bus
            if bus is None:
                continue
            lag = self.status()["channel"]["lag_ms"]
            health = Health(
                self.site, self.channel_name, self.role, self._fps(), lag or 0.0, self._frames
            )
            bus.publish_health(pack_data(encode_health(health)))
            if self.role == "master":
                self._publish_state(time.monotonic())

    def _view_of(self, shared: Camera) -> Camera:
        view = turned(shared, *self._view_offset)
        return Camera(
            position_m=view.position_m,
            heading_deg=view.heading_deg,
            pitch_deg=view.pitch_deg,
            roll_deg=view.roll_deg,
            fov_deg=self._fov_deg,
            width_px=self._size_px[0],
            height_px=self._size_px[1],
        )

    async def _warn_without_master(self) -> None:
        """One line when no master is seen soon after joining: Zenoh tells the side whose
        certificate is refused nothing, so this is where a wrong one shows."""
        await asyncio.sleep(NO_MASTER_WARN_S)
        if self._live_master is None:
            cause = (
                "it refused this channel's certificate (channel.ca_certificate, certificate, "
                "private_key)"
                if self._credentials is not None
                else "it is on another site or endpoint"
            )
            log.warning(
                "no sky master on zenoh:%s site %r after %g s: it is not running, or %s",
                self.endpoint,
                self.site,
                NO_MASTER_WARN_S,
                cause,
            )

    def _check_credentials(self) -> None:
        creds = self._credentials
        if creds is None:
            return
        for key, path in (
            ("ca_certificate", creds.ca_certificate),
            ("certificate", creds.certificate),
            ("private_key", creds.private_key),
        ):
            try:
                with open(path, "rb") as f:
                    f.read(1)
            except OSError as exc:
                raise BusError(f"{self._section}.{key}: {path}: {exc.strerror or exc}") from None

    def _drop(self, what: str, exc: Exception | str) -> None:
        self._drops[what] = self._drops.get(what, 0) + 1
        self._drop_log.warning(f"share-{what}", f"dropped a {what} message from the bus: {exc}")


def _sky_state(site: str, master_id: str, sequence: int, sky: SharedSky) -> SkyState:
    return SkyState(
        site=site,
        master_id=master_id,
        sequence=sequence,
        weather_version=sky.weather_version,
        applied=sky.applied,
        target=sky.target,
        anchor_utc=sky.anchor_utc,
        anchor_drift=sky.anchor_drift,
        clock_rate=sky.clock_rate,
        tower_epochs=sky.tower_epochs,
    )


def _iso_us(t: datetime) -> str:
    return format_time_utc(t)[:-1] + f".{t.microsecond:06d}Z"
