"""The web station's HTTP and WebSocket server on the daemon's own asyncio loop: the **only**
aiohttp user (docs/web.md).

aiohttp rather than Starlette on uvicorn: one library that serves files, HTTP and WebSockets
from the loop it is given, where uvicorn wants a loop and a server of its own; the daemon's
loop already runs frames, the control socket and every part.

Routes: the page's static files, `/login` (POST, when a token is needed) and `/ws`. No route
acts on a GET: the page's commands come only as WebSocket messages, and the handshake that
opens the WebSocket must come from the station's own page (its Origin). No CORS headers are
ever sent, so another site's scripts can read nothing from here.

Each page is a `WebClient` with a bounded mailbox: its replies in order (at most
`MAX_QUEUED_REPLIES`), and only the newest view and picture, so a page that reads slowly
misses views and pictures but never makes the daemon hold more; one that takes longer than
`SEND_TIMEOUT_S` to take a message is closed."""

from __future__ import annotations

import asyncio
import base64
import collections
import contextlib
import hashlib
import itertools
import logging
import time
from collections.abc import Awaitable, Callable
from pathlib import Path

from aiohttp import WSMsgType, web

from wxsky.logs import RateLimitedLog
from wxsky.web.access import (
    COOKIE,
    bearer,
    host_allowed,
    is_loopback,
    origin_allowed,
    token_matches,
)
from wxsky.web.messages import MAX_MESSAGE_BYTES, reply_error

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).parent / "static"
SEND_TIMEOUT_S = 10.0  # a page that takes no message in this long is not reading: closed
MAX_QUEUED_REPLIES = 64  # replies waiting for a page; more and the page is not reading
# aiohttp closes a WebSocket (1009) on a message larger than this; a message between the
# page's limit and this gets a one-line error and the page stays connected.
WIRE_MAX_BYTES = 4 * MAX_MESSAGE_BYTES
MESSAGES_PER_S = 50.0  # a page's sustained rate (a person taps a few a second)
MESSAGE_BURST = 100
HEARTBEAT_S = 20.0
LOGIN_MAX_BYTES = 4096
# The page's own files and images made from blobs; nothing from anywhere else, no framing.
SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'self'; img-src 'self' blob: data:; connect-src 'self'; "
        "frame-ancestors 'none'; base-uri 'none'; form-action 'self'"
    ),
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}


class WebClient:
    """One connected page."""

    def __init__(self, client_id: int, ws: web.WebSocketResponse, remote: str) -> None:
        self.id = client_id
        self.ws = ws
        self.remote = remote
        self.width_px = 640  # how wide the page shows the picture (its `view` message)
        self.dropped_views = 0
        self.dropped_pictures = 0
        self.over_rate = 0  # messages dropped for coming faster than MESSAGES_PER_S
        self._replies: collections.deque[str] = collections.deque()
        self._view: str | None = None
        self._picture: bytes | None = None
        self._wake = asyncio.Event()
        self._tokens = float(MESSAGE_BURST)
        self._tokens_at = time.monotonic()
        self.closed_why: str | None = None

    def send_text(self, text: str) -> bool:
        """Queue a reply; False (and the page is closed) when it has not read the last
        MAX_QUEUED_REPLIES."""
        if len(self._replies) >= MAX_QUEUED_REPLIES:
            self.close_soon(f"{MAX_QUEUED_REPLIES} replies unread")
            return False
        self._replies.append(text)
        self._wake.set()
        return True

    def send_view(self, text: str) -> None:
        """The newest view replaces one not yet sent."""
        if self._view is not None:
            self.dropped_views += 1
        self._view = text
        self._wake.set()

    def send_picture(self, jpeg: bytes) -> None:
        if self._picture is not None:
            self.dropped_pictures += 1
        self._picture = jpeg
        self._wake.set()

    @property
    def waiting_picture(self) -> bool:
        """A picture is queued and unsent: the page has not taken the last one yet."""
        return self._picture is not None

    def allow_message(self) -> bool:
        """The page's token bucket: True while it sends at most MESSAGES_PER_S."""
        now = time.monotonic()
        self._tokens = min(
            float(MESSAGE_BURST), self._tokens + (now - self._tokens_at) * MESSAGES_PER_S
        )
        self._tokens_at = now
        if self._tokens < 1.0:
            return False
        self._tokens -= 1.0
        return True

    def close_soon(self, why: str) -> None:
        if self.closed_why is None:
            self.closed_why = why
        self._wake.set()

    async def run_sender(self) -> None:
        """Sends what is queued, replies first, until the page goes or stops reading."""
        ws = self.ws
        while not ws.closed and self.closed_why is None:
            await self._wake.wait()
            self._wake.clear()
            while self.closed_why is None and not ws.closed:
                if self._replies:
                    send: Awaitable[None] = ws.send_str(self._replies.popleft())
                elif self._view is not None:
                    send, self._view = ws.send_str(self._view), None
                elif self._picture is not None:
                    send, self._picture = ws.send_bytes(self._picture), None
                else:
                    break
                try:
                    await asyncio.wait_for(send, SEND_TIMEOUT_S)
                except TimeoutError:
                    self.closed_why = f"took no message in {SEND_TIMEOUT_S:.0f} s"
                except (ConnectionError, RuntimeError):
                    return  # gone; the reader sees it too
        if self.closed_why is not None and not ws.closed:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(
                    ws.close(message=self.closed_why[:120].encode()), SEND_TIMEOUT_S
                )


MessageHandler = Callable[[WebClient, str | bytes], Awaitable[None]]


def login_page(static_dir: Path) -> tuple[str, str]:
    """login.html with the page's stylesheet put inside it, and the Content-Security-Policy
    that allows that one style by its hash."""
    html = (static_dir / "login.html").read_text(encoding="utf-8")
    css = (static_dir / "style.css").read_text(encoding="utf-8")
    link = '<link rel="stylesheet" href="/style.css">'
    if link not in html:
        raise ValueError(f"{static_dir / 'login.html'}: no {link} to put the style in place of")
    html = html.replace(link, f"<style>{css}</style>")
    digest = base64.b64encode(hashlib.sha256(css.encode("utf-8")).digest()).decode()
    csp = (
        f"default-src 'none'; style-src 'sha256-{digest}'; img-src data:; "
        "form-action 'self'; frame-ancestors 'none'; base-uri 'none'"
    )
    return html, csp


class WebServer:
    """Serves the station at host:port. `token`: what every request must carry (None: none,
    allowed on loopback only). `on_join(client)` is called as a page connects, `on_message`
    with each message it sends (in order, one at a time per page), `on_leave` as it goes."""

    def __init__(
        self,
        host: str,
        port: int,
        *,
        token: str | None,
        on_message: MessageHandler,
        on_join: Callable[[WebClient], None],
        on_leave: Callable[[WebClient], None],
        max_clients: int = 32,
        static_dir: Path = STATIC_DIR,
    ) -> None:
        if token is None and not is_loopback(host):
            raise ValueError(f"web: {host} is not loopback: a token is needed")
        self.host = host
        self.port = port
        self.token = token
        self.max_clients = max_clients
        self.static_dir = static_dir
        self._on_message = on_message
        self._on_join = on_join
        self._on_leave = on_leave
        self.clients: dict[int, WebClient] = {}
        self.refused = 0  # pages turned away: too many, wrong origin, no token
        self._ids = itertools.count(1)
        self._runner: web.AppRunner | None = None
        self._log = RateLimitedLog(log)
        self.url = ""
        self._login_html = login_page(static_dir)

    # -- life -------------------------------------------------------------------------

    async def start(self) -> None:
        app = web.Application(middlewares=[self._guard], client_max_size=LOGIN_MAX_BYTES)
        app.router.add_get("/ws", self._websocket)
        app.router.add_post("/login", self._login)
        app.router.add_get("/", self._index)
        app.router.add_static("/", self.static_dir, show_index=False, follow_symlinks=False)
        # No access log: a flood of requests must not be a flood of lines.
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port, reuse_address=True)
        await site.start()
        server = site._server
        sockets = getattr(server, "sockets", None) or ()
        if sockets:
            self.port = sockets[0].getsockname()[1]  # port 0: the one the system chose
        shown = f"[{self.host}]" if ":" in self.host else self.host
        self.url = f"http://{shown}:{self.port}/"

    async def close(self, deadline_s: float) -> None:
        """Closes every page and the listener by `deadline_s` (time.monotonic()); idempotent."""
        for client in list(self.clients.values()):
            client.close_soon("the daemon is stopping")
        runner, self._runner = self._runner, None
        if runner is not None:
            left = max(0.0, deadline_s - time.monotonic())
            try:
                await asyncio.wait_for(runner.cleanup(), left)
            except TimeoutError:
                log.warning("web: pages did not close in time; dropped them")

    # -- what the pages are sent ------------------------------------------------------

    def broadcast_view(self, text: str) -> None:
        for client in self.clients.values():
            client.send_view(text)

    def broadcast_picture(self, jpeg: bytes) -> None:
        """One picture for every page (made as wide as the widest asks; a browser scales)."""
        for client in self.clients.values():
            client.send_picture(jpeg)

    # -- HTTP -------------------------------------------------------------------------

    def _authorized(self, request: web.Request) -> bool:
        if self.token is None:
            return True
        given = bearer(request.headers.get("Authorization")) or request.cookies.get(COOKIE)
        return token_matches(given, self.token)

    @web.middleware
    async def _guard(
        self,
        request: web.Request,
        handler: Callable[[web.Request], Awaitable[web.StreamResponse]],
    ) -> web.StreamResponse:
        response: web.StreamResponse
        if not host_allowed(request.headers.get("Host"), self.host, self.port):
            self.refused += 1
            response = web.Response(status=421, text="wxsky: not this station's host name\n")
        elif not self._authorized(request) and request.path != "/login":
            self.refused += 1
            response = self._login_page(failed=False)
        elif request.method not in ("GET", "HEAD") and not origin_allowed(
            request.headers.get("Origin"), request.headers.get("Host")
        ):
            self.refused += 1
            response = web.Response(status=403, text="wxsky: not from this station's page\n")
        else:
            try:
                response = await handler(request)
            except web.HTTPException as exc:
                response = web.Response(status=exc.status, text=f"wxsky: {exc.reason}\n")
        if not response.prepared:  # a WebSocket's headers went with its handshake
            for key, value in SECURITY_HEADERS.items():
                response.headers.setdefault(key, value)
        return response

    def _login_page(self, failed: bool) -> web.Response:
        """The sign-in form, as the body of a 401: whole in itself, its style inside it (no
        other file is served without the token) and allowed by its hash alone."""
        html, csp = self._login_html
        if failed:
            html = html.replace(
                'class="login-failed" role="alert" hidden', 'class="login-failed" role="alert"'
            )
        return web.Response(
            status=401,
            text=html,
            content_type="text/html",
            headers={
                "WWW-Authenticate": 'Bearer realm="wxsky"',
                **SECURITY_HEADERS,
                "Content-Security-Policy": csp,
            },
        )

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(self.static_dir / "index.html")

    async def _login(self, request: web.Request) -> web.StreamResponse:
        if self.token is None:
            raise web.HTTPSeeOther("/")
        try:
            form = await request.post()
        except (ValueError, web.HTTPException):
            form = {}  # type: ignore[assignment]
        given = form.get("token")
        if not isinstance(given, str) or not token_matches(given.strip(), self.token):
            self.refused += 1
            self._log.warning("login", f"web: wrong token from {request.remote}")
            return self._login_page(failed=True)
        response = web.HTTPSeeOther("/")
        secure = request.secure or request.headers.get("X-Forwarded-Proto") == "https"
        response.set_cookie(
            COOKIE, self.token, httponly=True, samesite="Strict", secure=secure, path="/"
        )
        return response

    # -- the WebSocket ----------------------------------------------------------------

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        if not origin_allowed(request.headers.get("Origin"), request.headers.get("Host")):
            self.refused += 1
            self._log.warning("origin", f"web: refused a page from {request.headers['Origin']!r}")
            return web.Response(status=403, text="wxsky: not from this station's page\n")
        if len(self.clients) >= self.max_clients:
            self.refused += 1
            self._log.warning(
                "full", f"web: {self.max_clients} pages connected ([web] max_clients); refused more"
            )
            return web.Response(
                status=503, text=f"wxsky: {self.max_clients} pages connected, the most allowed\n"
            )
        ws = web.WebSocketResponse(
            max_msg_size=WIRE_MAX_BYTES, heartbeat=HEARTBEAT_S, compress=False
        )
        await ws.prepare(request)
        client = WebClient(next(self._ids), ws, request.remote or "?")
        self.clients[client.id] = client
        sender = asyncio.create_task(client.run_sender(), name=f"web page {client.id}")
        try:
            self._on_join(client)
            await self._read(client)
        finally:
            self.clients.pop(client.id, None)
            self._on_leave(client)
            client.close_soon("gone")
            with contextlib.suppress(Exception):
                await asyncio.wait_for(sender, SEND_TIMEOUT_S)
            if not sender.done():
                sender.cancel()
            if not ws.closed:
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(ws.close(), 1.0)
        return ws

    async def _read(self, client: WebClient) -> None:
        warned_rate = 0.0
        async for msg in client.ws:
            if client.closed_why is not None:
                return
            if msg.type in (WSMsgType.TEXT, WSMsgType.BINARY):
                if not client.allow_message():
                    client.over_rate += 1
                    if client.over_rate > MESSAGE_BURST:
                        # A flood, not a person: reading it would cost the frames.
                        why = f"sent more than {MESSAGES_PER_S:.0f} messages a second"
                        self._log.warning("flood", f"web: page {client.id} ({client.remote}) {why}")
                        client.close_soon(why)
                        return
                    now = time.monotonic()
                    if now - warned_rate >= 1.0:
                        warned_rate = now
                        client.send_text(
                            reply_error(
                                None,
                                f"message: more than {MESSAGES_PER_S:.0f} a second; "
                                f"some were dropped",
                            )
                        )
                    continue
                await self._on_message(client, msg.data)
            elif msg.type == WSMsgType.ERROR:
                # Too large a message (1009), a broken frame: aiohttp closes the socket.
                self._log.warning(
                    "ws-error", f"web: page {client.id} ({client.remote}): {client.ws.exception()}"
                )
                return
