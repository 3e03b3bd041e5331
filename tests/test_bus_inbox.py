"""The channel bus's inbox: a flood from the bus's threads is bounded before any work is done
on it, liveliness events are never dropped, and what is handled keeps its order."""

from __future__ import annotations

import asyncio
import threading

from wxsky.app.bus_inbox import BusInbox


def _flood(inbox: BusInbox, handler, count: int, threads: int = 4) -> None:  # type: ignore[no-untyped-def]
    def send(t: int) -> None:
        for i in range(count):
            inbox.put("health", handler, (t, i), True)

    workers = [threading.Thread(target=send, args=(t,)) for t in range(threads)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()


def test_a_flood_from_other_threads_is_bounded_and_counted() -> None:
    async def main() -> tuple[list[tuple[int, int]], dict[str, int], int]:
        loop = asyncio.get_running_loop()
        full: dict[str, int] = {}
        handled: list[tuple[int, int]] = []
        inbox = BusInbox(loop, lambda k, n: full.__setitem__(k, full.get(k, 0) + n), limit=100)
        # Flooded from four threads while the loop is blocked here: nothing drains meanwhile.
        _flood(inbox, lambda t, i, _at: handled.append((t, i)), 5000)
        await asyncio.sleep(0.05)
        max_waiting = len(handled)
        return handled, full, max_waiting

    handled, full, max_waiting = asyncio.run(main())
    assert max_waiting <= 100  # never more than the limit waited for one drain
    assert len(handled) + full["health"] == 4 * 5000  # every message handled or counted
    for t in range(4):  # each thread's messages keep their order
        mine = [i for s, i in handled if s == t]
        assert mine == sorted(mine)


def test_liveliness_events_are_never_dropped() -> None:
    async def main() -> tuple[list[str], dict[str, int]]:
        loop = asyncio.get_running_loop()
        full: dict[str, int] = {}
        seen: list[str] = []
        inbox = BusInbox(loop, lambda k, n: full.__setitem__(k, full.get(k, 0) + n), limit=10)

        def fill() -> None:
            for i in range(50):
                inbox.put("health", lambda *_a: None, (i,), True)
            inbox.put(
                "master", lambda m, alive, _at: seen.append(f"{m}:{alive}"), ("m1", False), False
            )

        fill()  # on the loop's thread, which drains only once it awaits
        await asyncio.sleep(0.05)
        return seen, full

    seen, full = asyncio.run(main())
    assert seen == ["m1:False"]
    assert full == {"health": 40}


def test_a_handler_that_raises_costs_only_its_message() -> None:
    async def main() -> list[int]:
        loop = asyncio.get_running_loop()
        got: list[int] = []

        def handle(i: int, _at: float) -> None:
            if i == 1:
                raise ValueError("boom")
            got.append(i)

        inbox = BusInbox(loop, lambda k, n: None)
        for i in range(3):
            inbox.put("state", handle, (i,), True)
        await asyncio.sleep(0.05)
        inbox.close()
        inbox.close()  # idempotent
        inbox.put("state", handle, (9,), True)  # after close: not handled
        await asyncio.sleep(0.05)
        return got

    assert asyncio.run(main()) == [0, 2]
