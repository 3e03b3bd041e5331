"""The daemon's cockpit links (`[[serial]]`, `[[can]]`, `--serial`, `--can`; docs/cockpit.md):
each link's reader thread decodes its device and posts merged updates to the event loop
through one mailbox (`inputs/cockpit_link.py`), where they change the engine's target at once
rather than at the next frame. A daemon part (`parts.py`): one for all the links, which share
the mailbox.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Sequence

from wxsky.app.parts import Part, PartContext
from wxsky.engine.stages import SkyEngine
from wxsky.inputs.cockpit_link import CockpitLink, Mailbox
from wxsky.inputs.stats import InputStats
from wxsky.weather.cockpit import CockpitUpdate

log = logging.getLogger("wxsky.app.cockpit")

# What the gathered closes get beyond each link's own wait: the threads' joins end them.
JOIN_SLACK_S = 0.05


class CockpitPart(Part):
    name = "cockpit links"

    # Given at start (`PartContext`): no reader posts before.
    _engine: SkyEngine
    _publish_target: Callable[[], None]

    def __init__(self, links: Sequence[CockpitLink]) -> None:
        self.links = list(links)

    def inputs(self) -> list[InputStats]:
        return [link.stats for link in self.links]

    async def start(self, ctx: PartContext) -> None:
        self._engine = ctx.engine
        self._publish_target = ctx.publish_target
        mailbox = Mailbox(asyncio.get_running_loop(), self._apply)
        for link in self.links:
            link.start(mailbox.poster(link))
            log.info("cockpit input %s (%s)", link.name, link.kind)

    async def close(self, deadline_s: float) -> None:
        """Stop every reader thread, together, by the deadline."""
        remaining_s = max(0.0, deadline_s - time.monotonic())
        per_link_s = max(0.05, remaining_s - 0.02)
        try:
            await asyncio.wait_for(
                asyncio.gather(*(asyncio.to_thread(link.close, per_link_s) for link in self.links)),
                timeout=per_link_s + JOIN_SLACK_S,
            )
        except TimeoutError:
            log.warning("shutdown: cockpit readers did not stop in time; abandoned them")

    def _apply(self, update: CockpitUpdate) -> None:
        """Runs on the loop (posted by a reader thread): the target, and the stream's copy
        of it, change at once rather than at the next frame."""
        self._engine.apply_cockpit(update)
        self._publish_target()
