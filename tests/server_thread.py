"""A real ControlServer on its own event loop in a background thread, as in the daemon: for
tests that talk to the control channel without a whole daemon."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any, TypeVar

from wxsky.output.transport import ControlServer

T = TypeVar("T")

Handler = Callable[[str, dict[str, Any]], Awaitable[Any]]


class ServerThread:
    def __init__(self, address: str, handler: Handler, **kwargs: Any) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.server = ControlServer(address, handler, **kwargs)
        try:
            self.run(self.server.start())
        except BaseException:
            self.stop()
            raise

    def run(self, coro: Coroutine[Any, Any, T], timeout: float = 10) -> T:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def on_loop(self, fn: Callable[[], T]) -> T:
        async def call() -> T:
            return fn()

        return self.run(call())

    def broadcast(self, method: str, params: dict[str, Any]) -> int:
        return self.on_loop(lambda: self.server.broadcast(method, params))

    def stop(self) -> None:
        """Idempotent: closes the server and the loop."""
        if self.loop.is_closed():
            return
        with contextlib.suppress(Exception):
            self.run(self.server.close())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        self.loop.close()
