"""The daemon's model data (`[grib] sources`, `wxsky run --grib`; docs/weather-aloft.md):
GRIB2 files, directories of forecast steps or URLs, read into the weather aloft at the site.

On a task of its own, off the frame path:

- every `poll_interval_s`, each source is fetched on a thread (`inputs/grib_sources.py`), and
  what changed is decoded in a child process (`inputs/grib_decode.py`: a corrupt file that
  trips the C decoder costs that file, and the decoder's memory goes with the process), cut
  to `window_deg` around the site; a source that fails keeps its last good fields and says
  why in `status`;
- every `update_s`, the column at the camera's place and the sim clock's time is worked out
  (`weather/model_profile.py`: bilinear in space, linear in time between steps, log-pressure
  in height) and applied as the `grib` source: the wind by height, the model's cloud layers
  (`weather/model_clouds.py`) and the surface temperature. The METAR's weight against it
  (`weather/model_blend.py`) follows the nearest station's distance and its report's age.
  Hosts get the column as an `aloft` notification when it changes, and in `status`.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import math
import multiprocessing
import os
import time
from collections.abc import Callable, Sequence
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

from wxsky.app.parts import Part, PartContext
from wxsky.engine.stages import SkyEngine, geodetic_from_enu
from wxsky.errors import GribError
from wxsky.inputs.grib_decode import Window, decode
from wxsky.inputs.grib_sources import GribBlob, GribSource, open_grib_source
from wxsky.inputs.stats import InputStats
from wxsky.logs import RateLimitedLog
from wxsky.settings.config import GribSection
from wxsky.weather.model_blend import metar_weight
from wxsky.weather.model_clouds import model_layers
from wxsky.weather.model_fields import ModelField, ModelStep, merge_steps
from wxsky.weather.model_profile import KELVIN, ModelProfile, profile_at
from wxsky.weather.state import Source, WeatherPatch, dir_from_deg
from wxsky.weather.stations import StationWeather

log = logging.getLogger("wxsky.app.grib")

Nearest = Callable[[], tuple[StationWeather, float] | None]
# How far beyond its first or last step a forecast is still held (GFS steps are 3 h apart).
MAX_HOLD = timedelta(hours=6)


def cache_dir(section: GribSection) -> Path:
    if section.cache_dir:
        return Path(section.cache_dir).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "wxsky" / "grib"


def _decode_in_child(data: bytes, name: str, window: Window) -> tuple[list[ModelField], list[str]]:
    problems: list[str] = []
    return decode(data, name, window, problems), problems


def _lower_priority() -> None:
    with contextlib.suppress(OSError):
        os.nice(10)


class GribPart(Part):
    name = "model data (GRIB)"

    _engine: SkyEngine
    _ctx: PartContext

    def __init__(
        self, section: GribSection, specs: Sequence[str], nearest: Nearest | None = None
    ) -> None:
        self.section = section
        self.specs = list(dict.fromkeys(specs))
        self._nearest = nearest
        self.stats = [InputStats(f"grib:{spec}", "grib") for spec in self.specs]
        self._sources: list[GribSource] = [
            open_grib_source(
                spec,
                cache_dir=cache_dir(section),
                cache_max_bytes=int(section.cache_max_mb * 1024 * 1024),
                timeout_s=section.http_timeout_s,
                byte_ranges=section.byte_ranges,
                fields=section.fields,
            )
            for spec in self.specs
        ]
        self._blobs: list[list[GribBlob]] = [[] for _ in self.specs]
        # Decoded fields by blob digest, for the window they were cut to.
        self._decoded: dict[str, list[ModelField]] = {}
        self._window: Window | None = None
        self._steps: dict[datetime, ModelStep] = {}
        self._gaps: list[str] = []  # levels left out for want of a field
        self._metar_weight: float | None = None
        self._profile: ModelProfile | None = None
        self._reason = "no model data yet"
        self._pool: concurrent.futures.ProcessPoolExecutor | None = None
        self._task: asyncio.Task[None] | None = None
        self._warn = RateLimitedLog(log)
        self._last_patch: WeatherPatch | None = None

    @property
    def enabled(self) -> bool:
        return bool(self.specs)

    def inputs(self) -> list[InputStats]:
        return list(self.stats)

    @property
    def profile(self) -> ModelProfile | None:
        return self._profile

    async def start(self, ctx: PartContext) -> None:
        self._engine = ctx.engine
        self._ctx = ctx
        for spec in self.specs:
            log.info("model data %s", spec)
        self._task = asyncio.create_task(self._run(ctx.stop))

    def status(self) -> dict[str, Any]:
        p = self._profile
        return {
            "grib": {
                "sources": list(self.specs),
                "steps_utc": [_iso(t) for t in self._steps],
                "window": None
                if self._window is None
                else {
                    "lat_deg": self._window.lat_deg,
                    "lon_deg": self._window.lon_deg,
                    "half_deg": self._window.half_deg,
                },
                # how much the METAR counts against the model; None while no METAR is used
                "metar_weight": self._metar_weight,
                "reason": None if p is not None else self._reason,
                "gaps": list(self._gaps),
                "layer_winds": self._layer_winds(),
                "profile": None if p is None else p.as_json(),
            }
        }

    def _layer_winds(self) -> list[dict[str, Any]]:
        """Each applied cloud layer with the wind it drifts with (at its middle height)."""
        if not hasattr(self, "_engine"):
            return []
        state = self._engine.state
        out = []
        for lay, (e, n) in zip(state.layers, state.layer_winds_mps, strict=True):
            speed = math.hypot(e, n)
            out.append(
                {
                    "type": lay.type.wire_name,
                    "base_m": round(lay.base_m, 1),
                    "top_m": round(lay.top_m, 1),
                    "wind_speed_mps": round(speed, 2),
                    "wind_dir_deg": round(dir_from_deg(e, n), 1) if speed > 0 else 0.0,
                }
            )
        return out

    async def close(self, deadline_s: float) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await asyncio.wait_for(task, max(0.0, deadline_s - time.monotonic()))
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
        for source in self._sources:
            source.close()

    # -- the task ----------------------------------------------------------------------

    async def _run(self, stop: asyncio.Event) -> None:
        next_poll = 0.0
        while not stop.is_set():
            now = time.monotonic()
            moved = self._window_moved()
            if now >= next_poll or moved:
                await self._poll(redecode=moved)
                next_poll = time.monotonic() + self.section.poll_interval_s
            await self._update()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), self.section.update_s)

    def _site(self) -> tuple[float, float]:
        obs = self._engine.state.observer
        east, north, _ = self._engine.camera.position_m
        return geodetic_from_enu(obs.lat_deg, obs.lon_deg, east, north)

    def _window_moved(self) -> bool:
        """The site has left the middle of the window the fields were cut to."""
        lat, lon = self._site()
        w = self._window
        if w is None:
            return True
        turn = (lon - w.lon_deg + 180.0) % 360.0 - 180.0
        return abs(lat - w.lat_deg) > w.half_deg / 2 or abs(turn) > w.half_deg / 2

    async def _poll(self, redecode: bool) -> None:
        lat, lon = self._site()
        window = Window(lat, lon, self.section.window_deg)
        if redecode:
            self._window = window
            self._decoded.clear()
            for source in self._sources:
                source.forget()  # the bytes again: only what was decoded is kept
        for k, (source, stats) in enumerate(zip(self._sources, self.stats, strict=True)):
            try:
                blobs = await asyncio.to_thread(source.fetch)
            except GribError as e:
                self._fail(stats, str(e))
                continue
            if blobs is not None:
                self._blobs[k] = blobs
            stats.ok = True
        await self._decode_all()

    async def _decode_all(self) -> None:
        window = self._window
        assert window is not None
        fields: list[ModelField] = []
        names: list[str] = []
        for k, (blobs, stats) in enumerate(zip(self._blobs, self.stats, strict=True)):
            good = 0
            for blob in blobs:
                got = self._decoded.get(blob.digest)
                if got is None and blob.held:
                    # decoded for another window and not read again: next poll reads it
                    self._sources[k].forget()
                    continue
                if got is None:
                    try:
                        got, problems = await self._decode(blob, window)
                    except GribError as e:
                        self._fail(stats, str(e))
                        continue
                    # what could be used is used; each problem said, the last in status
                    for problem in problems:
                        self._fail(stats, problem, keep_ok=bool(got))
                    self._decoded[blob.digest] = got
                    stats.message()
                good += 1
                fields.extend(got)
                names.append(blob.name)
            stats.detail.update(files=len(blobs), decoded=good)
            # only what was decoded is kept, not the bytes (gigabytes at 0.25 degree)
            self._blobs[k] = [blob.without_data() for blob in blobs]
        live = {b.digest for blobs in self._blobs for b in blobs}
        for digest in [d for d in self._decoded if d not in live]:
            del self._decoded[digest]
        if fields:
            self._steps = merge_steps(fields, tuple(names))
            self._gaps = [gap for step in self._steps.values() for gap in step.gaps()]
            for stats in self.stats:
                stats.detail["steps"] = len(self._steps)
            for gap in self._gaps:
                self._warn.warning("gap", f"model data: {gap}")

    async def _decode(self, blob: GribBlob, window: Window) -> tuple[list[ModelField], list[str]]:
        loop = asyncio.get_running_loop()
        if self._pool is None:
            self._pool = concurrent.futures.ProcessPoolExecutor(
                max_workers=1,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_lower_priority,
            )
        try:
            return await loop.run_in_executor(
                self._pool, _decode_in_child, blob.data, blob.name, window
            )
        except concurrent.futures.process.BrokenProcessPool:
            self._pool = None
            raise GribError(f"{blob.name}: the decoder's process ended on this file") from None

    def _fail(self, stats: InputStats, text: str, keep_ok: bool = False) -> None:
        stats.error(text)
        stats.ok = stats.ok and keep_ok
        self._warn.warning(stats.name, text)

    async def _update(self) -> None:
        if not self._steps:
            return
        lat, lon = self._site()
        at = self._engine.state.time_utc
        steps = self._steps
        first, last = min(steps), max(steps)
        if not first - MAX_HOLD <= at <= last + MAX_HOLD:
            # A forecast for another day is no weather for this one: the sources below speak.
            self._reason = (
                f"the model data's steps ({_iso(first)} to {_iso(last)}) are more than "
                f"{MAX_HOLD.total_seconds() / 3600:g} h from the clock ({_iso(at)})"
            )
            if self._profile is not None or self._last_patch is not None:
                self._warn.warning("far", f"model data: {self._reason}; not used")
                self._engine.release(Source.GRIB)
                self._ctx.publish_target()
            self._profile = None
            self._last_patch = None
            return
        profile = await asyncio.to_thread(profile_at, steps, lat, lon, at)
        if profile is None:
            self._reason = f"no forecast step covers {lat:.2f}, {lon:.2f}"
            self._profile = None
            return
        changed = self._profile is None or profile.levels != self._profile.levels
        self._profile = profile
        self._engine.set_aloft_temperatures(
            tuple((lev.height_m, lev.t_k - KELVIN) for lev in profile.levels)
        )
        self._set_metar_weight(at)
        patch = WeatherPatch(
            source=Source.GRIB,
            layers=model_layers(profile),
            wind=profile.winds() or None,
            temperature_c=None if profile.t2m_k is None else profile.t2m_k - KELVIN,
        )
        if patch != self._last_patch:
            news = self._last_patch is None
            self._engine.apply(patch)
            self._last_patch = patch
            if news and not self._engine.sources.metar:
                # As the METAR feeds' first weather does: the start-up preset was a stand-in
                # until live weather came, not a sky to morph out of for minutes.
                self._engine.settle()
            self._ctx.publish_target()
            if news:
                log.info(
                    "model data applied: %d levels, %d cloud layers, steps %s",
                    len(profile.levels),
                    len(patch.layers or ()),
                    ", ".join(_iso(t) for t in profile.steps),
                )
        if changed:
            self._ctx.broadcast("aloft", profile.as_json())

    def _set_metar_weight(self, at: datetime) -> None:
        near = self._nearest() if self._nearest is not None else None
        if near is None:
            self._metar_weight = None
            return
        station, distance = near
        age = None if station.observed_utc is None else (at - station.observed_utc).total_seconds()
        weight = metar_weight(distance, age)
        self._engine.set_metar_weight(weight)
        self._metar_weight = round(weight, 3)


def _iso(t: datetime) -> str:
    return t.isoformat().replace("+00:00", "Z")
