"""The instructor station in the browser as one of the daemon's parts (issue 46, docs/web.md).

It serves the page on the daemon's own loop (`web/server.py`), and for every connected page:
- a `view` (`web/view.py`) twice a second, and at once when the target weather changes, so
  a change made on one page shows on every other within a frame or two;
- the live picture: the newest published frame composited as a host does, as a JPEG
  (`web/picture.py`), made in a child process below the frames' priority, never on the
  frame path, only while a page is connected, and spaced so that making them takes at most `[web]
  picture_cpu_share` of one core (and at most `picture_fps` a second);
- the answer to each of its messages. A command runs through the daemon's one command path
  (`PartContext.command`: the same handlers, refusals and checks as the control channel),
  counted in the `web` input's row.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import statistics
import time
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from wxsky.app.parts import Part, PartContext, PublishedFrame
from wxsky.errors import ConfigError, WxskyError
from wxsky.inputs.stats import InputStats
from wxsky.logs import RateLimitedLog, clip
from wxsky.schema import Field, Invalid, Number, Table
from wxsky.settings.config import DaemonConfig, parse_web_listen
from wxsky.weather.state import CloudType
from wxsky.web.access import default_token_file, is_loopback, load_or_create_token
from wxsky.web.messages import (
    COMMANDS,
    MAX_MESSAGE_BYTES,
    MessageError,
    decode_message,
    reply,
    reply_error,
    to_text,
)
from wxsky.web.picture import MAX_WIDTH_PX, MIN_WIDTH_PX, PictureWorker
from wxsky.web.server import WebClient, WebServer
from wxsky.web.view import page_view

log = logging.getLogger(__name__)

# What the page offers for precipitation: METAR groups the weather state takes, each with
# an intensity prefix ("-" light, "" moderate, "+" heavy) for its rate.
PRECIPITATION = ("RA", "SHRA", "TSRA", "DZ", "SN", "SHSN", "FZRA", "GR")
VIEW = Table({"width_px": Field(Number(MIN_WIDTH_PX, MAX_WIDTH_PX, integer=True))})
PICTURE_STEP_PX = 160  # the picture's width goes up in these steps: few distinct sizes
PICTURE_COSTS_KEPT = 50  # the last pictures' costs, for status


class WebPart(Part):
    name = "web station"

    def __init__(
        self,
        config: DaemonConfig,
        listen: str,
        *,
        stations: Callable[[], list[dict[str, Any]]] = list,
    ) -> None:
        self.config = config
        section = config.web
        try:
            self.host, self.port = parse_web_listen(listen)
        except ValueError as exc:
            raise ConfigError(f"[web] listen: {exc}") from None
        self.token: str | None = None
        self.token_file: Path | None = None
        if not is_loopback(self.host):
            # Read (or made) now: a token file others may read stops the start, by name.
            self.token_file = Path(section.token_file) if section.token_file else None
            self.token_file = self.token_file or default_token_file()
            self.token = load_or_create_token(self.token_file)
        self.stats = InputStats("web", "web")
        self._stations = stations
        self._ctx: PartContext | None = None
        self._server: WebServer | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._view_now = asyncio.Event()
        self._has_clients = asyncio.Event()
        self._last_view: str | None = None
        self._picture_exec: concurrent.futures.ThreadPoolExecutor | None = None
        self._maker = PictureWorker(config.output.shm_name)
        self._picture_costs: deque[float] = deque(maxlen=PICTURE_COSTS_KEPT)
        self.pictures = 0
        self._picture_error: str | None = None
        self._target_version = -1
        self._shown_ring: object | None = None
        self._rebuilds = 0
        self._log = RateLimitedLog(log)

    def inputs(self) -> Sequence[InputStats]:
        return [self.stats]

    # -- life -------------------------------------------------------------------------

    async def start(self, ctx: PartContext) -> None:
        self._ctx = ctx
        section = self.config.web
        self._server = WebServer(
            self.host,
            self.port,
            token=self.token,
            on_message=self._on_message,
            on_join=self._on_join,
            on_leave=self._on_leave,
            max_clients=section.max_clients,
        )
        try:
            await self._server.start()
        except OSError as exc:
            raise ConfigError(
                f"[web] listen {self.host}:{self.port}: cannot listen: {exc.strerror or exc}"
            ) from None
        self.port = self._server.port
        self.stats.detail = {"url": self._server.url}
        access = (
            f"token in {self.token_file}"
            if self.token is not None
            else "this machine only (loopback)"
        )
        log.info("web station on %s (%s)", self._server.url, access)
        self._picture_exec = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix="wxsky-web-picture"
        )
        self._tasks = [
            asyncio.create_task(self._push_views(), name="web views"),
            asyncio.create_task(self._push_pictures(), name="web pictures"),
        ]

    async def close(self, deadline_s: float) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._tasks = []
        # The pages and the picture child close side by side, each by the deadline: one
        # after the other, a page slow to answer its close would leave the child none.
        steps = []
        if self._server is not None:
            server, self._server = self._server, None
            steps.append(server.close(deadline_s))
        if self._picture_exec is not None:
            executor, self._picture_exec = self._picture_exec, None
            steps.append(self._close_pictures(executor, deadline_s))
        await asyncio.gather(*steps)

    async def _close_pictures(
        self, executor: concurrent.futures.ThreadPoolExecutor, deadline_s: float
    ) -> None:
        # After a picture in the making (a fraction of a second), on that thread: the child
        # asked to stop, then killed if it does not.
        closing = asyncio.get_running_loop().run_in_executor(executor, self._maker.close)
        with contextlib.suppress(TimeoutError, Exception):
            await asyncio.wait_for(closing, max(0.0, deadline_s - time.monotonic()))
        executor.shutdown(wait=False, cancel_futures=True)

    # -- frames -----------------------------------------------------------------------

    def after_frame(self, frame: PublishedFrame) -> None:
        ctx = self._ctx
        if ctx is None:
            return
        engine = ctx.engine
        # A rebuild is a new whole ring on show (the version also moves with every slice and
        # step of a cross-fade).
        if engine.ring is not self._shown_ring:
            if self._shown_ring is not None:
                self._rebuilds += 1
            self._shown_ring = engine.ring
        if engine.target_version != self._target_version:
            self._target_version = engine.target_version
            self._view_now.set()

    def status(self) -> dict[str, Any]:
        server = self._server
        costs = list(self._picture_costs)
        return {
            "web": {
                "url": server.url if server is not None else None,
                "token": self.token is not None,
                "clients": len(server.clients) if server is not None else 0,
                "max_clients": self.config.web.max_clients,
                "refused": server.refused if server is not None else 0,
                "pictures": self.pictures,
                "picture_ms": 1000.0 * statistics.median(costs) if costs else None,
                "picture_error": self._picture_error,
            }
        }

    # -- the pages --------------------------------------------------------------------

    def _hello(self, client: WebClient) -> str:
        from wxsky import __version__
        from wxsky.settings.presets import list_presets

        return to_text(
            {
                "type": "hello",
                "version": __version__,
                "client_id": client.id,
                "presets": self._presets(list_presets),
                "cloud_types": [t.wire_name for t in CloudType if t is not CloudType.NONE],
                "precipitation": list(PRECIPITATION),
                "commands": list(COMMANDS),
                "max_message_bytes": MAX_MESSAGE_BYTES,
                "picture_fps": self.config.web.picture_fps,
            }
        )

    def _presets(self, list_presets: Callable[..., Any]) -> list[dict[str, str]]:
        return [
            {"name": p.name, "description": p.description, "origin": p.origin}
            for p in list_presets(self.config.presets.dirs)
        ]

    def _on_join(self, client: WebClient) -> None:
        client.send_text(self._hello(client))
        if self._last_view is not None:
            client.send_view(self._last_view)
        self._has_clients.set()
        self._view_now.set()  # every page's count of pages changes

    def _on_leave(self, client: WebClient) -> None:
        if client.closed_why not in (None, "gone"):
            self._log.warning("closed", f"web: closed page {client.id}: {client.closed_why}")
        self._view_now.set()

    async def _on_message(self, client: WebClient, data: str | bytes) -> None:
        ctx = self._ctx
        assert ctx is not None
        try:
            msg = decode_message(data)
        except MessageError as exc:
            self.stats.message()
            self.stats.error(clip(exc))
            self._log.warning("bad message", f"web: page {client.id} ({client.remote}): {exc}")
            client.send_text(reply_error(exc.id, str(exc)))
            return
        if msg.cmd in ("view", "presets"):
            self.stats.message()
            try:
                result = self._page_command(client, msg.cmd, msg.params)
            except Invalid as exc:
                self.stats.error(clip(exc))
                client.send_text(reply_error(msg.id, clip(f"{msg.cmd}: {exc}", 1000)))
                return
            client.send_text(reply(msg.id, result))
            return
        try:
            result = await ctx.command(msg.cmd, msg.params, self.stats)
        except WxskyError as exc:  # counted and logged (rate-limited) by the command path
            client.send_text(reply_error(msg.id, str(exc)))
            return
        client.send_text(reply(msg.id, result))
        self._view_now.set()  # a freeze or a clock rate shows at once too

    def _page_command(self, client: WebClient, cmd: str, params: dict[str, Any]) -> Any:
        if cmd == "presets":
            from wxsky.settings.presets import list_presets

            Table({}).values(params)
            return self._presets(list_presets)
        v = VIEW.values(params)
        if "width_px" in v:
            client.width_px = int(v["width_px"])
        return {"width_px": client.width_px}

    # -- what they are sent -----------------------------------------------------------

    async def _push_views(self) -> None:
        interval = self.config.web.view_interval_s
        while True:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._view_now.wait(), interval)
            self._view_now.clear()
            server = self._server
            if server is None or not server.clients:
                continue
            self._last_view = to_text(self._view(len(server.clients)))
            server.broadcast_view(self._last_view)

    def _view(self, clients: int) -> dict[str, Any]:
        ctx = self._ctx
        assert ctx is not None
        engine = ctx.engine
        ring = {
            "version": engine.ring_version,
            "busy": engine.ring_busy,
            "rebuilds": self._rebuilds,
        }
        return page_view(ctx.status(), engine.sky().to_dict(), ring, self._stations(), clients)

    async def _push_pictures(self) -> None:
        section = self.config.web
        if section.picture_fps <= 0.0:
            return
        loop = asyncio.get_running_loop()
        next_s = 0.0
        while True:
            server = self._server
            if server is None or not server.clients:
                self._has_clients.clear()
                await self._has_clients.wait()
                continue
            await asyncio.sleep(max(0.0, next_s - time.monotonic()))
            if not server.clients:  # the last page left while we waited
                continue
            width = _bucket(max(c.width_px for c in server.clients.values()))
            started = time.monotonic()
            try:
                assert self._picture_exec is not None
                picture = await loop.run_in_executor(self._picture_exec, self._maker.make, width)
            except (WxskyError, OSError) as exc:
                self._picture_error = clip(exc, 300)
                self._log.warning("picture", f"web: no picture: {exc}")
                next_s = time.monotonic() + 1.0
                continue
            self._picture_error = None
            self.pictures += 1
            self._picture_costs.append(picture.took_s)
            server.broadcast_picture(picture.jpeg)
            # The next picture no sooner than the fps allows, nor than keeps their CPU time
            # under the share (a picture of 20 ms at 5 %: one every 0.4 s at most).
            spacing = max(1.0 / section.picture_fps, picture.took_s / section.picture_cpu_share)
            next_s = started + spacing


def _bucket(width_px: int) -> int:
    """The picture width made for pages asking `width_px`: rounded up to a step."""
    steps = -(-width_px // PICTURE_STEP_PX)
    return min(MAX_WIDTH_PX, max(MIN_WIDTH_PX, steps * PICTURE_STEP_PX))
