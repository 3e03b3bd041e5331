"""The web station served by a real daemon (issue 46, docs/web.md), spoken to over real HTTP
and WebSockets: what a page is sent, its commands through the daemon's one command path,
bad input answered with one line while the frames go on, and who may reach it.

Most checks share one loopback daemon (a start costs seconds of llvmpipe); the token checks
run a second one bound off loopback."""

from __future__ import annotations

import asyncio
import contextlib
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest
from daemon_harness import HANG_S, RunningDaemon, running_daemon, wait_status

pytestmark = pytest.mark.xdist_group("web-daemon")

WEB = """
[web]
listen = "127.0.0.1:0"
max_clients = 6
picture_fps = 8.0
picture_cpu_share = 0.5
view_interval_s = 0.25
"""


@pytest.fixture(scope="module")
def station(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[RunningDaemon, str]]:
    tmp = tmp_path_factory.mktemp("web")
    env = ("env", f"XDG_CONFIG_HOME={tmp / 'config'}")
    with running_daemon(tmp, WEB, prefix=env) as daemon:
        status = wait_status(daemon, lambda s: bool(s.get("web", {}).get("url")), "the web url")
        yield daemon, status["web"]["url"]


def _run(coro: Any) -> Any:
    return asyncio.run(asyncio.wait_for(coro, HANG_S))


class Page:
    """A page's end of the WebSocket: messages by type, pictures apart."""

    def __init__(self, ws: aiohttp.ClientWebSocketResponse) -> None:
        self.ws = ws
        self.next_id = 1
        self.hello: dict[str, Any] | None = None
        self.views: list[dict[str, Any]] = []
        self.pictures: list[bytes] = []
        self.errors: list[str] = []

    async def receive(self) -> dict[str, Any] | None:
        msg = await self.ws.receive(timeout=HANG_S)
        if msg.type == aiohttp.WSMsgType.BINARY:
            self.pictures.append(msg.data)
            return None
        if msg.type != aiohttp.WSMsgType.TEXT:
            raise ConnectionError(f"the WebSocket closed: {msg.type} {msg.data!r} {msg.extra!r}")
        data: dict[str, Any] = json.loads(msg.data)
        if data["type"] == "hello":
            self.hello = data
        elif data["type"] == "view":
            self.views.append(data)
        elif data["type"] == "error":
            self.errors.append(data["error"])
        return data

    async def until(self, check: Any) -> Any:
        while True:
            data = await self.receive()
            if data is not None and check(data):
                return data

    async def call(self, cmd: str, **params: Any) -> dict[str, Any]:
        msg_id, self.next_id = self.next_id, self.next_id + 1
        await self.ws.send_str(json.dumps({"id": msg_id, "cmd": cmd, "params": params}))
        reply: dict[str, Any] = await self.until(
            lambda d: d["type"] == "reply" and d["id"] == msg_id
        )
        return reply


async def _page(session: aiohttp.ClientSession, url: str, **kw: Any) -> Page:
    ws = await session.ws_connect(url + "ws", **kw)
    page = Page(ws)
    await page.until(lambda d: d["type"] == "hello")
    return page


def test_a_page_is_greeted_then_shown_the_daemon_live(station: tuple[RunningDaemon, str]) -> None:
    _, url = station

    async def go() -> Page:
        async with aiohttp.ClientSession() as session:
            async with session.get(url) as resp:
                assert resp.status == 200
                html = await resp.text()
                assert "<html" in html.lower()
                assert "default-src 'self'" in resp.headers["Content-Security-Policy"]
                assert "Access-Control-Allow-Origin" not in resp.headers
            page = await _page(session, url)
            await page.call("view", width_px=320)
            while len(page.pictures) < 2 or len(page.views) < 3:
                await page.receive()
            await page.ws.close()
            return page

    page = _run(go())
    hello = page.hello
    assert hello is not None
    assert "overcast-stratus" in [p["name"] for p in hello["presets"]]
    assert "cumulonimbus" in hello["cloud_types"]
    view = page.views[-1]
    assert view["target"]["visibility_m"] > 0
    assert view["clock"]["time_utc"].endswith("Z")
    assert -90.0 <= view["sun"]["elevation_deg"] <= 90.0
    assert 0.0 <= view["moon"]["illuminated"] <= 1.0
    names = [row["name"] for row in view["inputs"]]
    assert "web" in names and "control" in names
    assert view["clients"] >= 1
    assert view["fps"] > 0.0
    assert view["frames_published"] > page.views[0]["frames_published"]  # live, not a copy
    # Pictures: JPEGs of the frames, about as wide as asked (the next step of 160 px up).
    from io import BytesIO

    from PIL import Image

    pictures = [Image.open(BytesIO(p)) for p in page.pictures]
    assert all(p.format == "JPEG" for p in pictures)
    assert pictures[-1].width == 320
    assert pictures[-1].height == 180


def test_commands_from_a_page_are_the_control_channels_and_every_page_sees_them(
    station: tuple[RunningDaemon, str],
) -> None:
    daemon, url = station

    async def go() -> tuple[dict[str, Any], ...]:
        async with aiohttp.ClientSession() as session:
            one = await _page(session, url)
            two = await _page(session, url)
            applied = await one.call("apply_preset", name="overcast-stratus", now=True)
            # The other page is shown the new target without asking.
            seen = await two.until(
                lambda d: (
                    d["type"] == "view"
                    and [lay["type"] for lay in d["target"]["layers"]] == ["stratus"]
                )
            )
            bad = await one.call("set_weather", visibility_m=-5)
            layers = [
                {"type": "stratocumulus", "cover_oktas": 5, "base_m": 1234.0, "top_m": 1900.0}
            ]
            good = await one.call("set_weather", visibility_m=4321.0, layers=layers)
            frozen = await two.call("freeze", frozen=True)
            still = await one.until(lambda d: d["type"] == "view" and d["clock"]["frozen"])
            thawed = await two.call("freeze", frozen=False)
            released = await one.call("release", now=True)
            return applied, seen, bad, good, frozen, still, thawed, released

    applied, seen, bad, good, frozen, still, thawed, released = _run(go())
    assert applied == {"type": "reply", "id": 1, "ok": True, "result": "overcast-stratus"}
    assert seen["target"]["sources"]["layers"] == "control"
    assert bad["ok"] is False
    assert bad["error"] == "set_weather: visibility_m: must be a number in 0..1000000, got -5"
    assert good["ok"] is True
    assert frozen["result"] == {"frozen": True} and still["clock"]["frozen"] is True
    assert thawed["result"] == {"frozen": False}
    assert released["ok"] and "layers" in released["result"]["released"]
    # The web's commands are counted in its own input row; its bad one is its last error.
    status = wait_status(daemon, lambda s: True, "status")
    web = next(row for row in status["inputs"] if row["name"] == "web")
    assert web["errors"] >= 1 and "visibility_m" in web["last_error"]


def test_the_same_commands_over_the_control_channel(
    station: tuple[RunningDaemon, str], tmp_path: Path
) -> None:
    daemon, _ = station
    with daemon.client() as c:
        assert c.call("freeze", {"frozen": True}) == {"frozen": True}
        time_a = c.call("status")["weather"]["time_utc"]
        time.sleep(0.3)
        assert c.call("status")["weather"]["time_utc"] == time_a  # the clock stands still
        c.call("freeze", {"frozen": False})
        saved = c.call("save_preset", {"name": "web-test-save", "description": "from a test"})
    path = Path(saved["path"])
    assert path.name == "web-test-save.toml" and "from a test" in path.read_text()
    human = subprocess.run(
        [sys.executable, "-m", "wxsky", "status", "--control", daemon.address],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "web station http://127.0.0.1:" in human and "(this machine only)" in human
    with daemon.client() as c, pytest.raises(Exception, match="already exists"):
        c.call("save_preset", {"name": "web-test-save"})


def test_bad_input_is_one_line_to_that_page_and_the_frames_go_on(
    station: tuple[RunningDaemon, str],
) -> None:
    daemon, url = station
    before = wait_status(daemon, lambda s: True, "status")["frames_published"]

    async def go() -> tuple[list[str], list[dict[str, Any]], Any]:
        async with aiohttp.ClientSession() as session:
            page = await _page(session, url)
            for data in ("{bad", "[]", '{"id": 1, "cmd": "nope"}', "x" * 70_000):
                await page.ws.send_str(data)
            replies = []
            for _ in range(4):
                replies.append(
                    await page.until(lambda d: d["type"] in ("error", "reply") and not d.get("ok"))
                )
            # Still connected and answering.
            ok = await page.call("view", width_px=200)
            # Larger than the wire allows: closed with 1009 and a reason, the daemon unmoved.
            await page.ws.send_str("y" * 300_000)
            while True:
                msg = await page.ws.receive(timeout=HANG_S)
                if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED):
                    break
            return [r.get("error", "") for r in replies], [ok], page.ws.close_code

    errors, (ok,), close_code = _run(go())
    assert errors[0].startswith("message: not JSON")
    assert errors[1] == "message: must be a JSON object, got list"
    assert errors[2].startswith('message: cmd: unknown command "nope"')
    assert errors[3] == "message: 70000 bytes, more than 65536"
    assert all("\n" not in e for e in errors)
    assert ok["ok"] is True
    assert close_code == 1009
    after = wait_status(daemon, lambda s: s["frames_published"] > before + 5, "frames going on")
    assert after["fps"] > 0.0


def test_pages_beyond_the_limit_are_refused_and_a_slow_reader_holds_nothing(
    station: tuple[RunningDaemon, str],
) -> None:
    daemon, url = station

    async def go() -> tuple[list[int], int]:
        async with aiohttp.ClientSession() as session:
            held = []
            refused = []
            for _ in range(20):  # max_clients = 6
                try:
                    held.append(await session.ws_connect(url + "ws"))
                except aiohttp.WSServerHandshakeError as exc:
                    refused.append(exc.status)
            # None of these pages reads: the daemon keeps only their newest view and picture.
            await asyncio.sleep(1.0)
            for ws in held:
                await ws.close()
            return refused, len(held)

    refused, held = _run(go())
    assert held == 6
    assert refused == [503] * 14
    status = wait_status(daemon, lambda s: s["web"]["clients"] == 0, "the pages gone")
    assert status["web"]["refused"] >= 14


def test_another_sites_page_and_another_host_name_are_refused(
    station: tuple[RunningDaemon, str],
) -> None:
    _, url = station

    async def go() -> list[int]:
        codes = []
        async with aiohttp.ClientSession() as session:
            try:
                await session.ws_connect(url + "ws", origin="http://evil.example")
            except aiohttp.WSServerHandshakeError as exc:
                codes.append(exc.status)
            async with session.get(url, headers={"Host": "evil.example"}) as resp:
                codes.append(resp.status)
            # No command is reachable by a GET, nor CORS open to anyone.
            async with session.get(url + "apply_preset?name=clear") as resp:
                codes.append(resp.status)
            async with session.options(
                url + "ws",
                headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "GET"},
            ) as resp:
                codes.append(resp.status)
                assert "Access-Control-Allow-Origin" not in resp.headers
            async with session.post(
                url + "login", data={"token": "x"}, headers={"Origin": "http://evil.example"}
            ) as resp:
                codes.append(resp.status)
        return codes

    assert _run(go()) == [403, 421, 404, 403, 403]


def test_off_loopback_every_route_needs_the_token(tmp_path: Path) -> None:
    token_file = tmp_path / "web-token"
    config = WEB.replace("127.0.0.1:0", "0.0.0.0:0") + f'token_file = "{token_file}"\n'
    with running_daemon(tmp_path, config) as daemon:
        status = wait_status(daemon, lambda s: bool(s.get("web", {}).get("url")), "the web url")
        port = int(status["web"]["url"].rsplit(":", 1)[1].strip("/"))
        url = f"http://127.0.0.1:{port}/"
        token = token_file.read_text().strip()
        assert token_file.stat().st_mode & 0o077 == 0

        async def go() -> dict[str, Any]:
            out: dict[str, Any] = {}
            async with aiohttp.ClientSession() as session:
                for path in ("", "index.html", "app.js", "style.css", "ws", "nothing-here"):
                    async with session.get(url + path) as resp:
                        out[path] = resp.status
                        assert resp.headers.get("WWW-Authenticate", "").startswith("Bearer")
                async with session.get(url, headers={"Authorization": "Bearer wrong"}) as resp:
                    out["wrong"] = resp.status
                try:
                    await session.ws_connect(url + "ws")
                except aiohttp.WSServerHandshakeError as exc:
                    out["ws"] = exc.status
                async with session.get(url, headers={"Authorization": f"Bearer {token}"}) as resp:
                    out["bearer"] = resp.status
                async with session.post(url + "login", data={"token": "wrong"}) as resp:
                    out["bad login"] = resp.status
            # The login page's cookie lets a browser in, WebSocket included (a browser keeps
            # a cookie of an IP address; aiohttp only when told to).
            async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as session:
                async with session.post(
                    url + "login", data={"token": token}, allow_redirects=False
                ) as resp:
                    out["login"] = resp.status
                    assert "HttpOnly" in resp.headers["Set-Cookie"]
                    assert "SameSite=Strict" in resp.headers["Set-Cookie"]
                async with session.get(url) as resp:
                    out["with cookie"] = resp.status
                page = await _page(session, url)
                out["command"] = await page.call("freeze", frozen=False)
                # The daemon stops with the page connected: the page is closed, not left. The
                # page reads on meanwhile, as a browser does (its answer to the close is sent
                # as it reads it).
                loop = asyncio.get_running_loop()
                stopping = loop.run_in_executor(None, daemon.stop)
                while not page.ws.closed:
                    with contextlib.suppress(ConnectionError):
                        await page.receive()
                out["exit"], _ = await stopping
            return out

        out = _run(go())
    assert {k: out[k] for k in ("", "index.html", "app.js", "style.css", "nothing-here")} == {
        "": 401,
        "index.html": 401,
        "app.js": 401,
        "style.css": 401,
        "nothing-here": 401,
    }
    assert out["ws"] == 401 and out["wrong"] == 401 and out["bad login"] == 401
    assert out["bearer"] == 200 and out["login"] == 303 and out["with cookie"] == 200
    assert out["command"]["ok"] is True
    assert out["exit"] == 0
    log = daemon.log()
    assert "Traceback" not in log and "did not close in time" not in log, log[-3000:]
