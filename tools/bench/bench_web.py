#!/usr/bin/env python3
"""The web station's cost and speed (issue 46, docs/web.md, docs/performance.md). Starts a
private daemon with the station on loopback and a serial link on a pty pair, and measures:

    fps          frames a second with no page, with N pages connected (each taking every
                 view and picture), and with N pages while hostile clients flood bad
                 messages, open a thousand connections every ten seconds and never read
                 (five of them): windows taken in turn
                 (none, pages, hostile, none, pages, hostile, ...), the ratios window pair
                 by window pair;
    cpu          the daemon process's own CPU time a frame in each window (the picture's
                 child apart): on 2 cores the clients' processes take the machine's CPU
                 too, and this says what the daemon itself spent;
    picture      what one live picture costs the daemon (its thread's CPU time), and how
                 many a second the pages got;
    preset       a page's `apply_preset` -> the daemon's `status` showing the new target
                 (polled every 5 ms), and -> the page's own view showing it;
    pulled line  the serial line's pty closed -> a page's view showing the link down.

The pages run in a child process of their own (aiohttp clients that read and parse every
message as a browser would, without drawing), so their own CPU is not the daemon's; on a
2-core machine they still share its cores, which makes the ratio a pessimistic one.

    .venv/bin/python tools/bench/bench_web.py [--pages 10] [--window-s 10] [--rounds 4]
        [--json docs/performance-web.json]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.host.client import ControlClient  # noqa: E402
from wxsky.protocols.nmea import sentence  # noqa: E402

PRESETS = ("overcast-stratus", "scattered-cumulus")


# -- the pages' process ---------------------------------------------------------------


async def _pages(url: str, count: int, hostile: bool) -> None:
    """`count` pages reading everything until stdin closes; with `hostile`, besides them a
    client flooding junk, a thousand connections every ten seconds and five pages that never
    read."""
    import aiohttp

    got = {"views": 0, "pictures": 0}

    async def page(session: aiohttp.ClientSession) -> None:
        async with session.ws_connect(url + "ws") as ws:
            await ws.send_str(json.dumps({"id": 1, "cmd": "view", "params": {"width_px": 960}}))
            async for msg in ws:
                if msg.type == aiohttp.WSMsgType.TEXT:
                    json.loads(msg.data)
                    got["views"] += 1
                elif msg.type == aiohttp.WSMsgType.BINARY:
                    got["pictures"] += 1

    async def flood(session: aiohttp.ClientSession) -> None:
        """Junk as fast as the socket takes it; the daemon closes a flooder: back in 1 s."""
        junk = ["{bad", "[]", '{"id": 1, "cmd": "nope"}', "x" * 70_000, '{"id":1}']
        while True:
            with contextlib.suppress(aiohttp.ClientError, ConnectionError, RuntimeError):
                async with session.ws_connect(url + "ws") as ws:
                    n = 0
                    while not ws.closed:
                        await ws.send_str(junk[n % len(junk)])
                        n += 1
            await asyncio.sleep(1.0)

    async def knock(session: aiohttp.ClientSession) -> None:
        """A thousand WebSocket connections at once, every ten seconds (most refused: the
        station holds [web] max_clients)."""
        gate = asyncio.Semaphore(100)

        async def one() -> None:
            async with gate:
                with contextlib.suppress(aiohttp.ClientError, ConnectionError):
                    ws = await session.ws_connect(url + "ws")
                    await asyncio.sleep(1.0)
                    await ws.close()

        while True:
            await asyncio.gather(*(one() for _ in range(1000)))
            await asyncio.sleep(10.0)

    async def slow_reader() -> None:
        """A page that opens the WebSocket and never reads a byte of it."""
        host, port = url.split("//")[1].strip("/").rsplit(":", 1)
        _reader, writer = await asyncio.open_connection(host, int(port))
        writer.write(
            f"GET /ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
            "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n".encode()
        )
        await writer.drain()
        await asyncio.sleep(3600.0)

    async with aiohttp.ClientSession() as session:
        tasks = [asyncio.create_task(page(session)) for _ in range(count)]
        if hostile:
            tasks += [asyncio.create_task(flood(session)), asyncio.create_task(knock(session))]
            tasks += [asyncio.create_task(slow_reader()) for _ in range(5)]
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, sys.stdin.read)  # until the parent closes it
        for t in tasks:
            t.cancel()
        print(json.dumps(got), flush=True)


@contextlib.contextmanager
def pages_process(url: str, count: int, hostile: bool = False) -> Iterator[dict[str, Any]]:
    out: dict[str, Any] = {}
    cmd = [sys.executable, __file__, "--pages-worker", url, "--pages", str(count)]
    if hostile:
        cmd.append("--hostile")
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        yield out
    finally:
        assert proc.stdin is not None and proc.stdout is not None
        proc.stdin.close()
        line = proc.stdout.readline()
        proc.wait(30)
        with contextlib.suppress(ValueError):
            out.update(json.loads(line))


# -- the daemon -----------------------------------------------------------------------


def frames(client: ControlClient) -> tuple[int, float]:
    return int(client.call("status")["frames_published"]), time.monotonic()


def cpu_s(pid: int) -> float:
    """The process's CPU time so far, all its threads (its children apart)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def window_fps(client: ControlClient, seconds: float, pid: int) -> tuple[float, float]:
    """Frames a second over the window, and the daemon's own CPU ms a frame."""
    n0, t0 = frames(client)
    c0 = cpu_s(pid)
    time.sleep(seconds)
    n1, t1 = frames(client)
    c1 = cpu_s(pid)
    return (n1 - n0) / (t1 - t0), 1000.0 * (c1 - c0) / max(1, n1 - n0)


async def preset_latency(url: str, client: ControlClient, changes: int) -> dict[str, list[float]]:
    """A page applies presets in turn: ms to the daemon's status target, ms to its view."""
    import aiohttp

    to_status: list[float] = []
    to_view: list[float] = []
    async with aiohttp.ClientSession() as session, session.ws_connect(url + "ws") as ws:
        for k in range(changes):
            name = PRESETS[k % 2]
            want = "stratus" if name == "overcast-stratus" else "cumulus"
            # Drain what is waiting, so the view timed is one sent after the command.
            with contextlib.suppress(TimeoutError):
                while True:
                    await asyncio.wait_for(ws.receive(), 0.05)
            t0 = time.monotonic()
            await ws.send_str(
                json.dumps({"id": k + 1, "cmd": "apply_preset", "params": {"name": name}})
            )
            seen_status = seen_view = None
            while seen_status is None or seen_view is None:
                if seen_status is None:
                    target = client.call("status")["target"]
                    if [lay["type"] for lay in target["layers"]][:1] == [want]:
                        seen_status = time.monotonic()
                with contextlib.suppress(TimeoutError):
                    msg = await asyncio.wait_for(ws.receive(), 0.005)
                    if msg.type == aiohttp.WSMsgType.TEXT and seen_view is None:
                        data = json.loads(msg.data)
                        layers = (data.get("target") or {}).get("layers") or [{}]
                        if data["type"] == "view" and layers[0].get("type") == want:
                            seen_view = time.monotonic()
            to_status.append(1000.0 * (seen_status - t0))
            to_view.append(1000.0 * (seen_view - t0))
    return {"status_ms": to_status, "view_ms": to_view}


async def pulled_line_latency(url: str, device: Path, pulls: int) -> list[float]:
    """The pty behind the serial link closed: ms until a page's view shows the link down;
    then a new pty under the same name, and the link up again before the next pull."""
    import aiohttp

    out = []
    async with aiohttp.ClientSession() as session, session.ws_connect(url + "ws") as ws:

        async def serial_ok() -> bool:
            while True:
                msg = await ws.receive()
                data = json.loads(msg.data) if msg.type == aiohttp.WSMsgType.TEXT else {}
                if data.get("type") == "view":
                    rows = [r for r in data["inputs"] if r["kind"] == "serial"]
                    return bool(rows and rows[0]["ok"])

        for _ in range(pulls):
            master, slave = os.openpty()
            tty = Path(os.ttyname(slave))
            with contextlib.suppress(FileNotFoundError):
                device.unlink()
            device.symlink_to(tty)
            while not await serial_ok():
                os.write(master, sentence("WIMWV,010.0,T,3.0,M,A"))
            await asyncio.sleep(0.5)
            t0 = time.monotonic()
            os.close(master)
            os.close(slave)
            while await serial_ok():
                pass
            out.append(1000.0 * (time.monotonic() - t0))
    return out


def summary(values: list[float]) -> dict[str, float]:
    return {
        "median": statistics.median(values),
        "min": min(values),
        "max": max(values),
        "n": len(values),
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pages", type=int, default=10, help="pages connected (default 10)")
    p.add_argument("--window-s", type=float, default=10.0, help="seconds a window (default 10)")
    p.add_argument("--rounds", type=int, default=4, help="rounds of windows (default 4)")
    p.add_argument("--changes", type=int, default=20, help="presets applied (default 20)")
    p.add_argument("--pulls", type=int, default=3, help="serial lines pulled (default 3)")
    p.add_argument(
        "--picture-fps", type=float, help="the station's [web] picture_fps (default: its own)"
    )
    p.add_argument(
        "--picture-cpu-share",
        type=float,
        help="the station's [web] picture_cpu_share (default: its own)",
    )
    p.add_argument(
        "--tick-hz",
        type=float,
        help="the daemon's [daemon] tick_hz (default: its own, 30): above what the machine "
        "draws, every frame's cost shows in the rate",
    )
    p.add_argument("--json", type=Path, help="write the results there too")
    p.add_argument("--pages-worker", metavar="URL", help=argparse.SUPPRESS)
    p.add_argument("--hostile", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.pages_worker:
        asyncio.run(_pages(args.pages_worker, args.pages, args.hostile))
        return 0
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        sock, cfg, device = tmp / "wx.sock", tmp / "wxsky.toml", tmp / "ttyUSB-bench"
        master, slave = os.openpty()
        device.symlink_to(os.ttyname(slave))
        cfg.write_text(
            f'[output]\nshm_name = "wxsky-bench-web-{uuid.uuid4().hex[:8]}"\n'
            + (f"[daemon]\ntick_hz = {args.tick_hz}\n" if args.tick_hz is not None else "")
            + '[web]\nlisten = "127.0.0.1:0"\n'
            + (f"picture_fps = {args.picture_fps}\n" if args.picture_fps is not None else "")
            + (
                f"picture_cpu_share = {args.picture_cpu_share}\n"
                if args.picture_cpu_share is not None
                else ""
            )
        )
        env = dict(os.environ, XDG_CONFIG_HOME=str(tmp / "config"))
        cmd = [sys.executable, "-m", "wxsky", "run", "--config", str(cfg)]
        cmd += ["--control", f"unix:{sock}", "--serial", str(device)]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        try:
            while not sock.exists():
                if proc.poll() is not None:
                    print("daemon exited early", file=sys.stderr)
                    return 1
                time.sleep(0.1)
            with ControlClient.connect(f"unix:{sock}") as client:
                while not client.call("status").get("web", {}).get("url"):
                    time.sleep(0.1)
                url = client.call("status")["web"]["url"]
                time.sleep(5.0)  # past start-up and the first ring build
                fps: dict[str, list[float]] = {"none": [], "pages": [], "hostile": []}
                cpu: dict[str, list[float]] = {"none": [], "pages": [], "hostile": []}
                got: dict[str, list[dict[str, Any]]] = {"pages": [], "hostile": []}
                for r in range(args.rounds):
                    rate, per_frame = window_fps(client, args.window_s, proc.pid)
                    fps["none"].append(rate)
                    cpu["none"].append(per_frame)
                    for kind in ("pages", "hostile"):
                        with pages_process(url, args.pages, kind == "hostile") as counts:
                            time.sleep(2.0)  # the pages connected and their pictures going
                            rate, per_frame = window_fps(client, args.window_s, proc.pid)
                            fps[kind].append(rate)
                            cpu[kind].append(per_frame)
                        got[kind].append(counts)
                    print(
                        f"round {r + 1}: "
                        + ", ".join(f"{k} {v[-1]:.2f} fps" for k, v in fps.items()),
                        flush=True,
                    )
                web = client.call("status")["web"]
                latency = asyncio.run(preset_latency(url, client, args.changes))
            os.close(master)
            os.close(slave)
            pulled = asyncio.run(pulled_line_latency(url, device, args.pulls))
        finally:
            proc.terminate()
            proc.wait(30)
    ratios = {
        k: [b / a for a, b in zip(fps["none"], fps[k], strict=True)] for k in ("pages", "hostile")
    }
    window = args.window_s + 2.0
    result = {
        "tick_hz": args.tick_hz or 30.0,
        "pages": args.pages,
        "window_s": args.window_s,
        "fps": {k: summary(v) for k, v in fps.items()},
        "fps_ratio": {k: summary(v) for k, v in ratios.items()},
        # The daemon process's own CPU a frame (the picture's child apart): what the pages
        # cost it, whatever the clients' own processes take of the machine.
        "daemon_cpu_ms_per_frame": {k: summary(v) for k, v in cpu.items()},
        "pictures_per_s_per_page": statistics.median(
            g.get("pictures", 0) / window / args.pages for g in got["pages"]
        ),
        "picture_ms": web["picture_ms"],
        "preset_to_status_ms": summary(latency["status_ms"]),
        "preset_to_view_ms": summary(latency["view_ms"]),
        "pulled_line_to_view_ms": summary(pulled),
    }
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
