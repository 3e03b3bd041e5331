"""The cockpit mailbox: updates from reader threads merge while the loop is busy; a value a
newer one of the same field replaced is counted against the link that sent it."""

from __future__ import annotations

import asyncio

from wxsky.inputs.cockpit_link import Mailbox
from wxsky.inputs.serial_link import SerialLink
from wxsky.weather.cockpit import TEMPERATURE, WIND_DIR, CockpitUpdate


def test_a_value_replaced_while_the_loop_was_busy_is_counted_against_its_sender() -> None:
    serial = SerialLink("loop://")
    can = SerialLink("loop://")  # a second link: only its field kinds matter here
    applied: list[CockpitUpdate] = []

    async def main() -> None:
        box = Mailbox(asyncio.get_running_loop(), applied.append)
        post_serial, post_can = box.poster(serial), box.poster(can)
        # The loop does not run between these posts: all wait in the mailbox together.
        post_serial(CockpitUpdate(values={WIND_DIR: 90.0}))
        post_can(CockpitUpdate(values={TEMPERATURE: 15.0}))
        post_serial(CockpitUpdate(values={WIND_DIR: 120.0}))
        await asyncio.sleep(0.01)
        post_serial(CockpitUpdate(values={WIND_DIR: 130.0}))  # after a drain: replaces nothing
        await asyncio.sleep(0.01)

    asyncio.run(main())
    assert [dict(u.values) for u in applied] == [
        {WIND_DIR: 120.0, TEMPERATURE: 15.0},
        {WIND_DIR: 130.0},
    ]
    assert (serial.superseded, can.superseded) == (1, 0)
