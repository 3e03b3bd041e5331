"""The daemon's METAR feeds (`[metar] feeds`, `--metar-feed`; README.md): each feed's
source polled on a task of its own (`inputs/metar_input.py`), the stations near the camera
picked and their weather applied in the METAR slot of the precedence stack. A daemon part
(`parts.py`): one for all the feeds, since the first weather from any of them settles the sky.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Sequence
from datetime import datetime
from typing import Any

from wxsky.app.parts import Part, PartContext
from wxsky.engine.stages import SkyEngine, geodetic_from_enu
from wxsky.inputs.feed_sources import open_source
from wxsky.inputs.metar_input import MetarFeedInput, MetarSettings
from wxsky.inputs.stats import InputStats
from wxsky.settings.config import MetarSection
from wxsky.weather.state import WeatherPatch, format_time_utc
from wxsky.weather.stations import StationWeather, distance_m
from wxsky.web.view import station_rows

log = logging.getLogger("wxsky.app.metar")


class MetarFeedsPart(Part):
    name = "METAR feeds"

    # Given at start (`PartContext`): no feed is read before.
    _engine: SkyEngine

    def __init__(
        self, section: MetarSection, specs: Sequence[str], *, replay: bool = False
    ) -> None:
        """`specs`: each feed's source (a file, a directory, `-`, a URL); one named twice is
        read once. `replay`: the feeds are an archive, replayed by the sim clock."""
        settings = MetarSettings.from_section(section)
        self.feeds = [
            MetarFeedInput(
                open_source(spec, timeout_s=section.http_timeout_s),
                settings,
                InputStats(f"metar:{spec}", "metar"),
                apply=self._apply,
                position=self._camera_lat_lon,
                replay_clock=self._sim_time if replay else None,
            )
            for spec in dict.fromkeys(specs)
        ]
        self._tasks: list[asyncio.Task[None]] = []
        self._had_weather = False

    def inputs(self) -> list[InputStats]:
        return [feed.stats for feed in self.feeds]

    def blended(self) -> tuple[StationWeather, ...]:
        """The METAR stations blended into the weather now (the first feed that blends)."""
        return next((feed.blended for feed in self.feeds if feed.blended), ())

    def nearest(self) -> tuple[StationWeather, float] | None:
        """The nearest station the METAR weather uses now, with its distance (the first feed
        that gives weather here)."""
        return next((feed.nearest for feed in self.feeds if feed.nearest), None)

    def stations(self) -> list[dict[str, Any]]:
        """The stations the METAR weather is made of now, with their distances from the
        camera and weights (`web.view.station_rows`); [] before the first report."""
        first = next((feed for feed in self.feeds if feed.nearest), None)
        if first is None or first.nearest is None or getattr(self, "_engine", None) is None:
            return []
        stations = first.blended or (first.nearest[0],)
        lat, lon = self._camera_lat_lon()
        return station_rows(
            [
                (
                    s.station,
                    s.lat_deg,
                    s.lon_deg,
                    distance_m(lat, lon, s.lat_deg, s.lon_deg),
                    None if s.observed_utc is None else format_time_utc(s.observed_utc),
                )
                for s in stations
            ]
        )

    async def start(self, ctx: PartContext) -> None:
        self._engine = ctx.engine
        for feed in self.feeds:
            self._tasks.append(asyncio.create_task(feed.run_supervised(ctx.stop)))
            log.info("METAR feed %s", feed.source.name)

    async def close(self, deadline_s: float) -> None:
        """The feeds' tasks end when the daemon's stop is set; one still fetching at the
        deadline (a slow URL, in a worker thread that cannot be interrupted) is abandoned."""
        tasks, self._tasks = self._tasks, []
        if tasks:
            wait_s = max(0.0, deadline_s - time.monotonic())
            done, _ = await asyncio.wait(tasks, timeout=wait_s)
            for feed, task in zip(self.feeds, tasks, strict=True):
                if task not in done:
                    log.warning(
                        "shutdown: METAR feed %s still fetching; abandoned it", feed.source.name
                    )
                    task.cancel()
        for feed in self.feeds:
            feed.close()

    def _apply(self, patch: WeatherPatch) -> None:
        self._engine.apply(patch)
        if not self._had_weather:
            # The first live weather replaces the start-up preset at once: the preset was only
            # a stand-in until the feed answered, not a sky to morph out of for minutes.
            self._had_weather = True
            self._engine.settle()
            log.info("first METAR feed weather applied: %s", self._engine.state.summary())

    def _sim_time(self) -> datetime:
        return self._engine.state.time_utc

    def _camera_lat_lon(self) -> tuple[float, float]:
        obs = self._engine.state.observer
        east, north, _ = self._engine.camera.position_m
        return geodetic_from_enu(obs.lat_deg, obs.lon_deg, east, north)
