"""The daemon's life in three phases: startup -> main loop -> shutdown.

The asyncio loop owns the engine and the control channel; one render thread owns the GL
context and writes each frame into the shared-memory slot the host will read (through the
writer's private copy and pwrite: `wxsky/output/shm.py`, "Truncation").
The main loop waits on an Event between ticks: a signal wakes it at once.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import faulthandler
import inspect
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from datetime import datetime
from pathlib import Path
from types import FrameType
from typing import Any

from wxsky import __version__
from wxsky.app.control import (
    ControlError,
    apply_metar,
    apply_preset,
    camera_from_params,
    camera_to_dict,
    dispatch_table,
    freeze,
    no_params,
    output_format,
    radar_key,
    radar_reply,
    release,
    save_preset,
    set_aircraft,
    set_time,
    set_weather,
    visibility,
)
from wxsky.app.flight_air import FlightAir
from wxsky.app.frame_publish import draw_ring, frame_layer_specs, publish_plan
from wxsky.app.frame_times import FrameTimes
from wxsky.app.memory import TRIM_EVERY_S, TraceReport, memory_status
from wxsky.app.memory import trim as trim_heap
from wxsky.app.part_factory import parts_from_config
from wxsky.app.parts import Part, PartContext, PublishedFrame
from wxsky.app.radar_layer import RadarLayer
from wxsky.app.trace import TraceWriter
from wxsky.engine.radar_work import RadarWork
from wxsky.engine.stages import FramePlan, SkyEngine
from wxsky.errors import ConfigError, RenderError, WxskyError
from wxsky.inputs.stats import InputStats
from wxsky.logs import RateLimitedLog, clip
from wxsky.output.frame_meta import FrameMeta
from wxsky.output.shm import FrameReader, FrameWriter, LayerSpec, segment_version
from wxsky.output.transport import Address, ControlServer, WithFds, default_address
from wxsky.scene.camera import Camera
from wxsky.scene.cloud_model_files import default_models
from wxsky.scene.clouds import BLOCK_CACHE, BLOCK_SIZE_M
from wxsky.scene.near_depth import near_distance_m
from wxsky.scene.precip_eye import AtEye
from wxsky.settings.config import DaemonConfig
from wxsky.weather.state import Source, WeatherPatch, WeatherState, weather_to_dict

log = logging.getLogger("wxsky.app.daemon")

# A part's close runs this long past the shared deadline before it is cut: its own handling of
# the deadline (a line naming what it abandoned) comes first.
CLOSE_GRACE_S = 0.1


def initial_patches(
    config: DaemonConfig,
    preset: str | None = None,
    metar: str | None = None,
    field_elevation_m: float | None = None,
) -> list[WeatherPatch]:
    """The weather the daemon starts on: a preset (the config's unless named), or a METAR,
    its clouds over its station's field (the station table's, as a feed's report of that
    station is read) unless `field_elevation_m` is given."""
    from wxsky.inputs.station_table import report_patch
    from wxsky.settings.presets import load_preset
    from wxsky.weather.metar import decode

    patches = [load_preset(preset or config.daemon.preset, config.presets.dirs)]
    if metar:
        # The report names only its day: the latest such day not after the start time.
        start = patches[0].time_utc or WeatherState().time_utc
        report = decode(metar, now_utc=start).require_usable()
        patches.append(report_patch(report, field_elevation_m))
    return patches


def layer_specs(config: DaemonConfig) -> list[LayerSpec]:
    out = config.output
    scene = config.scene
    return frame_layer_specs(
        out.max_width,
        out.max_height,
        scene.ring_texture_px,
        scene.shadow_map_px,
        out.layer_format,
        radar_px=config.radar.size_px if config.radar.layer else 0,
        near_depth=out.near_depth,
    )


class Daemon:
    def __init__(
        self,
        config: DaemonConfig,
        patches: list[WeatherPatch],
        parts: Sequence[Part] | None = None,
        *,
        address: Address | None = None,
        preview_dir: Path | None = None,
        trace_path: Path | None = None,
    ) -> None:
        """`parts`: what runs beside the frames (`parts.py`), walked in this order; None for
        the config's own (`parts_from_config`)."""
        self.config = config
        # The parts the daemon walks in each phase, in this order, and their inputs: checked
        # before the sky is made.
        self.parts = list(parts) if parts is not None else parts_from_config(config)
        self.inputs = {
            "initial": InputStats(f"initial:{_source_name(patches)}", "preset", len(patches)),
            "control": InputStats("control", "control"),
        }
        for part in self.parts:
            for stats in part.inputs():
                if stats.name in self.inputs:
                    raise ConfigError(f"two inputs are named {stats.name!r}; give one a 'name'")
                self.inputs[stats.name] = stats
        self._trace_path = trace_path
        self._trace: TraceWriter | None = None
        self.address = address or (
            _parse(config.output.control) if config.output.control else default_address()
        )
        self.preview_dir = preview_dir
        # Read the cloud models now: a broken model file stops the start with its name and
        # key, not the first frame.
        default_models()
        # Presets are the base; a METAR given on the command line is the METAR source, so a
        # feed's reports replace it and a control override beats it.
        state = WeatherState()
        for patch in patches:
            if patch.source in (Source.DEFAULT, Source.PRESET):
                state = state.apply(patch)
        cam = config.camera
        camera = Camera(
            position_m=(0.0, 0.0, state.observer.alt_m + cam.alt_agl_m),
            heading_deg=cam.heading_deg,
            pitch_deg=cam.pitch_deg,
            roll_deg=cam.roll_deg,
            fov_deg=cam.fov_deg,
            width_px=cam.width,
            height_px=cam.height,
        )
        settings = config.scene_settings()
        self.engine = SkyEngine(
            state,
            camera,
            settings,
            clock_rate=config.clock.rate,
            rates=config.transition.rates(),
            transition_step_s=config.transition.step_s,
            cockpit_hold_s=config.transition.cockpit_hold_s,
            cigi_hold_s=config.cigi.hold_s,
            ring_build="async",
            ring_fade_s=config.scene.ring_fade_s,
            ring_slice_ms=config.scene.ring_slice_ms or None,
            ring_worker=config.scene.ring_worker,
            ring_worker_nice=config.scene.ring_worker_nice,
        )
        for patch in patches:
            if patch.source not in (Source.DEFAULT, Source.PRESET):
                self.engine.apply(patch)
        self.engine.settle()
        # The first frame's near layer, made before the loop starts, and the frame itself,
        # which the render thread draws once when it starts (`Renderer.warm_up`).
        self._first_frame = self.engine.warm_up()
        self._target_version = -1
        self.frames_published = 0
        self._frame_times = FrameTimes()
        self._started = time.monotonic()
        self._stop = asyncio.Event()
        self._signals = 0
        self._writer: FrameWriter | None = None
        self._server: ControlServer | None = None
        self._render_exec: concurrent.futures.ThreadPoolExecutor | None = None
        self._renderer: Any = None
        # The automatic exposure, where it meters ([render] exposure "auto" on scene-referred
        # passes, scene/exposure.py); None: the renderer's exposure stays as set.
        self._auto_exposure: Any = None
        # Zero-copy textures (docs/protocol.md §6): what the render context offers (probed
        # with the renderer), and the exported slot textures once a host asked for them.
        self._export_probe: Any = None
        self._export_failed: str | None = None
        self._slot_textures: Any = None
        self._preview_task: asyncio.Future[None] | None = None
        # Freed heap given back once a minute on a worker (`memory.py`): counts for status.
        self._trim_task: asyncio.Future[None] | None = None
        self._trims = 0
        self._trimmed_kib = 0
        self._control_log = RateLimitedLog(log)
        self._radar_work: RadarWork | None = None  # made at the first `radar` request
        self._flight_air = FlightAir()  # the air at the aircraft, in each frame's notification
        # The radar's segment layer (`[radar] layer`), its own thread made at start-up.
        self._radar_layer: RadarLayer | None = None
        self._radar_announced = 0  # the last picture's version sent in a `radar` notification
        self._at_eye: dict[str, Any] | None = None  # the last published frame's
        self._commands: dict[str, Callable[[dict[str, Any]], Any]] = {
            "status": lambda p: no_params("status", p) or self.status(),
            "scene": lambda p: no_params("scene", p) or self.scene_info(),
            "set_camera": self._set_camera,
            "set_aircraft": lambda p: set_aircraft(self.engine, p),
            "set_time": lambda p: set_time(self.engine, p),
            "apply_preset": lambda p: apply_preset(
                self.engine, p, config.presets.dirs, keep_site=self._holds_site()
            ),
            "release": lambda p: release(self.engine, p),
            "apply_metar": lambda p: apply_metar(self.engine, p),
            "set_weather": lambda p: set_weather(self.engine, p),
            "radar": self._radar,
            "visibility": lambda p: visibility(self.engine.state, p),
            "export_textures": self._export_textures,
            "output_format": lambda p: output_format(
                p, config.output.layer_format, self._segment_version()
            ),
            "freeze": lambda p: freeze(self.engine, p),
            "save_preset": lambda p: save_preset(self.engine, p),
        }
        self._dispatch = dispatch_table(self._commands)

    # -- the three phases -------------------------------------------------------------

    async def run(self) -> int:
        with self._capture_signals():
            try:
                await self.startup()
            except BaseException:
                await self.shutdown()
                raise
            try:
                await self.main_loop()
            finally:
                await self.shutdown()
        return 0

    async def startup(self) -> None:
        loop = asyncio.get_running_loop()
        self._render_exec = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix="wxsky-render"
        )
        await loop.run_in_executor(self._render_exec, self._create_renderer)
        if self._trace_path is not None:
            self._trace = TraceWriter(self._trace_path)
            log.info("trace: %s", self._trace_path)
        self._writer = FrameWriter.create(self.config.output.shm_name, layer_specs(self.config))
        if self.config.radar.layer:
            self._radar_layer = RadarLayer(self.config.radar)
        out = self.config.output
        self._server = ControlServer(
            self.address,
            self._handle,
            max_clients=out.max_clients,
            idle_timeout_s=out.client_idle_timeout_s,
        )
        await self._server.start()
        log.info(
            "wxsky %s serving on %s, frames in shm '%s', %s",
            __version__,
            self.address,
            self.config.output.shm_name,
            self.engine.state.summary(),
        )
        if self.preview_dir is not None:
            log.info("preview: %s", (self.preview_dir / "preview.png").resolve())
        context = PartContext(
            self.engine,
            set_camera=self._set_camera,
            publish_target=self._publish_target,
            fps=self.fps,
            stop=self._stop,
            broadcast=self._server_broadcast,
            command=self._command,
            status=self.status,
        )
        for part in self.parts:
            await part.start(context)

    async def main_loop(self) -> None:
        loop = asyncio.get_running_loop()
        period = 1.0 / self.config.daemon.tick_hz
        last = loop.time()
        next_tick = last
        next_status = last + self.config.daemon.status_interval_s
        next_preview = last + 0.5
        next_trim = last + TRIM_EVERY_S
        weather_version = self.engine.weather_version
        shown_ring = None
        while not self._stop.is_set():
            now = loop.time()
            for part in self.parts:
                part.before_frame()
            if self._radar_layer is not None:
                # Never waits: asks every [radar] every_s, takes the newest picture made.
                engine = self.engine
                self._radar_layer.step(now, engine.state, engine.drift, engine.camera.position_m)
            # The scene is built on the render thread too: a ring build takes long enough on a
            # CPU to hold up cockpit input if it ran here.
            plan, meta, published_s = await loop.run_in_executor(
                self._render_exec, self._advance_render_publish, now - last
            )
            last = now
            self._publish_target()
            self._count_frame(published_s)
            self._broadcast_frame(plan, meta, published_s)
            frame = PublishedFrame(meta.frame_number, plan.state, now)
            for part in self.parts:
                part.after_frame(frame)
            if self.engine.ring is not shown_ring:
                shown_ring = self.engine.ring
                self._server_broadcast("scene", self.scene_info())
            if self.engine.weather_version != weather_version:
                weather_version = self.engine.weather_version
                self._server_broadcast("weather", weather_to_dict(self.engine.state))
            now = loop.time()
            if now >= next_status:
                next_status = now + self.config.daemon.status_interval_s
                log.info("%s", self.status_line())
            if self.preview_dir is not None and now >= next_preview and self._preview_idle():
                next_preview = now + self.config.preview.interval_s
                self._preview_task = loop.run_in_executor(None, self._write_preview)
            if now >= next_trim and (self._trim_task is None or self._trim_task.done()):
                next_trim = now + TRIM_EVERY_S
                self._trim_task = loop.run_in_executor(None, self._trim_heap)
            # A late frame starts the next one at once but never tries to catch up a backlog.
            next_tick = max(next_tick + period, loop.time())
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stop.wait(), timeout=next_tick - loop.time())

    async def shutdown(self) -> None:
        """Release everything, bounded by the configured timeout; logs what it had to cut."""
        timeout = self.config.daemon.shutdown_timeout_s
        deadline = time.monotonic() + timeout
        self._stop.set()
        # First, so a ring build in flight gives up while the rest shuts down.
        self.engine.cancel_scene_work()
        if self._radar_work is not None:
            self._radar_work.close(wait_s=max(0.05, timeout / 4))
            self._radar_work = None
        self._flight_air.close()
        if self._radar_layer is not None:
            self._radar_layer.close(wait_s=max(0.05, timeout / 4))
        # Then the parts, together: a master's channels see the bus go at once and keep the
        # last sky; readers and feeds stop.
        await self._close_parts(time.monotonic() + max(0.05, timeout / 4))
        if self._server is not None:
            try:
                await asyncio.wait_for(self._server.close(), timeout=max(0.05, timeout / 2))
            except TimeoutError:
                log.warning("shutdown: control clients did not close in time; dropped them")
            self._server = None
        if self._preview_task is not None and not self._preview_task.done():
            with contextlib.suppress(TimeoutError, Exception):
                await asyncio.wait_for(
                    asyncio.shield(self._preview_task), max(0.05, deadline - time.monotonic())
                )
        if self._render_exec is not None:
            loop = asyncio.get_running_loop()
            try:
                await asyncio.wait_for(
                    loop.run_in_executor(self._render_exec, self._close_renderer),
                    timeout=max(0.05, deadline - time.monotonic()),
                )
            except TimeoutError:
                log.warning("shutdown: render thread did not finish in time; abandoned it")
            self._render_exec.shutdown(wait=False, cancel_futures=True)
            self._render_exec = None
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        cut = self.engine.close(wait_s=max(0.0, deadline - time.monotonic()))
        if cut is not None:
            log.warning("shutdown: abandoned %s", cut)
        if self._trace is not None:
            self._trace.close()
        log.info("stopped after %d frames", self.frames_published)

    # -- the parts --------------------------------------------------------------------

    async def _close_parts(self, deadline_s: float) -> None:
        """Every part's `close`, all at once, each given `deadline_s`: one still closing a
        moment after it is logged by name and cut, not waited for."""
        closing = {
            asyncio.create_task(part.close(deadline_s), name=f"close {part.name}"): part
            for part in self.parts
        }
        if not closing:
            return
        wait_s = max(0.0, deadline_s - time.monotonic()) + CLOSE_GRACE_S
        done, pending = await asyncio.wait(closing, timeout=wait_s)
        for task in pending:
            log.warning("shutdown: %s did not close in time; cut it", closing[task].name)
            task.cancel()
        for task in done:
            exc = None if task.cancelled() else task.exception()
            if exc is not None:
                log.error("shutdown: %s failed to close: %s", closing[task].name, exc)
                log.debug("%s's close", closing[task].name, exc_info=exc)

    def _refusal(self, method: str) -> str | None:
        return next((r for part in self.parts if (r := part.refusal(method)) is not None), None)

    def _holds_site(self) -> bool:
        return any(part.holds_site for part in self.parts)

    # -- render thread ----------------------------------------------------------------

    def _create_renderer(self) -> None:
        from wxsky.render.renderer import Renderer
        from wxsky.render.texture_export import probe
        from wxsky.render.towers import SLICE_TEXELS
        from wxsky.scene.exposure import (
            AUTO,
            SCENE_REFERRED,
            AutoExposure,
            initial_scale,
            needs_variable,
        )

        setting = self.config.render.exposure
        # [output] layer_format "rgba16f": every pass draws scene-linear half floats, which
        # go into the segment as they are (hosts with HDR pipelines expose and tone-map).
        linear = self.config.output.layer_format == "rgba16f"
        self._renderer = Renderer(
            self.config.scene.ring_texture_px,
            variable_exposure=needs_variable(setting),
            output="linear" if linear else "display",
            near_depth=self.config.output.near_depth,
        )
        # [render] exposure: a number of EV fixes it; "auto" holds the legacy exposure while
        # the passes' colours are display-referred (scene/exposure.py).
        self._renderer.exposure = initial_scale(setting)
        self._auto_exposure = AutoExposure() if setting == AUTO and SCENE_REFERRED else None
        # Towers' images are marched a row band a frame, never a whole one in one frame.
        self._renderer.towers.slice_texels = SLICE_TEXELS
        if self._first_frame is not None:
            self._renderer.warm_up(self._first_frame)
            self._first_frame = None
        self._export_probe = probe(self._renderer.ctx)
        if self._export_probe.supported:
            log.info("zero-copy textures: available (%s)", self._export_probe.export)
        else:
            log.info("zero-copy textures: unavailable: %s", self._export_probe.reason)

    def _close_renderer(self) -> None:
        if self._slot_textures is not None:
            self._slot_textures.close()
            self._slot_textures = None
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def _advance_render_publish(self, dt_wall_s: float) -> tuple[FramePlan, FrameMeta, float]:
        """The frame path, on the render thread: the scene stages, drawing and publishing;
        nothing here may wait on work off it (docs/ARCHITECTURE.md, Threads). Returns the
        plan, its record and when its slot was flipped (the daemon's monotonic clock)."""
        plan = self.engine.advance(dt_wall_s)
        meta = self._render_and_publish(plan)
        flipped = time.monotonic()
        if self._auto_exposure is not None and self._renderer is not None:
            # After the hand-off: the meter's draw and few-kilobyte read-back never delay the
            # frame it measures; the next frame is drawn with the adapted exposure.
            ev = self._auto_exposure.update(self._renderer.meter_log_average(), dt_wall_s)
            self._renderer.exposure = self._auto_exposure.scale
            log.debug("auto exposure: EV %.2f", ev)
        return plan, meta, flipped

    def _render_and_publish(self, plan: FramePlan) -> FrameMeta:
        r, writer = self._renderer, self._writer
        assert r is not None and writer is not None
        if plan.rings.render_slice is not None:
            t0 = time.perf_counter()
            draw_ring(r, plan)
            # Drawn to the end where the renderer waits per draw (a CPU one); on a GPU this is
            # what issuing it cost, and slices only grow there.
            self.engine.note_ring_render(time.perf_counter() - t0)
        else:
            draw_ring(r, plan)
        r.render_frame(plan.frame)
        frame_number = self.frames_published + 1
        export = None
        if self._slot_textures is not None:
            from wxsky.render.texture_export import SlotExport

            export = SlotExport(self._slot_textures, r, writer.target_slot)
        radar = self._radar_layer.shown if self._radar_layer is not None else None
        meta = publish_plan(
            r,
            writer,
            plan,
            frame_number,
            self.config.scene.ring_texture_px,
            export,
            radar,
            near_depth=self.config.output.near_depth,
        )
        if self._trace is not None:
            self._trace.write_events(frame_number, plan.frame.camera.position_m, plan.events)
        return meta

    # -- control channel --------------------------------------------------------------

    async def _handle(self, method: str, params: dict[str, Any]) -> Any:
        return await self._command(method, params, self.inputs["control"])

    async def _command(self, method: str, params: dict[str, Any], stats: InputStats) -> Any:
        """Every command, whichever way it came (the control channel, the web station): the
        parts' refusals, the one handler, the errors counted in the caller's `stats`."""
        stats.message()
        try:
            refused = self._refusal(method)
            if refused is not None:
                raise ControlError(refused)
            result = self._dispatch(method, params)
            if inspect.isawaitable(result):  # a command that needs the render thread
                result = await result
            return result
        except WxskyError as exc:
            # Per message, so rate-limited by command (any unknown one is one kind) and
            # clipped: a flood of bad requests is a few lines, a huge param a short quote.
            stats.error(clip(exc))
            kind = method if method in self._commands else "unknown command"
            self._control_log.warning(
                f"rejected:{stats.name}:{kind}",
                f"{stats.name} {clip(method, 64)} rejected: {exc}",
            )
            raise

    def _set_camera(self, params: dict[str, Any]) -> dict[str, Any]:
        out = self.config.output
        camera = camera_from_params(self.engine, params, (out.max_width, out.max_height))
        self.engine.set_camera(camera)
        if "lat_deg" in params:
            # As a cockpit's position: near the site the camera moves under the same sky;
            # far away (where the flat local frame no longer holds) that place becomes the site.
            self.engine.move_observer(params["lat_deg"], params["lon_deg"])
        return camera_to_dict(self.engine.camera)

    async def _export_textures(self, params: dict[str, Any]) -> Any:
        """`export_textures` (protocol §6): the layer textures of both segment slots as
        dma-bufs, the fds sent with the answer, or why not (the host then uses the segment)."""
        no_params("export_textures", params)
        probe = self._export_probe
        reason = self._export_failed or (probe.reason if probe is not None else "no renderer yet")
        if reason is not None:
            return _unsupported(reason)
        loop = asyncio.get_running_loop()
        try:
            textures, fds = await loop.run_in_executor(self._render_exec, self._start_export)
        except RenderError as exc:
            self._export_failed = f"exporting the layer textures failed: {exc}: use the shm segment"
            log.warning("zero-copy textures: %s", self._export_failed)
            return _unsupported(self._export_failed)
        result = {
            "supported": True,
            "slot_count": len({t["slot"] for t in textures}),
            "sync": "seqlock",
            "renderer": probe.gl_renderer,
            "fd_count": len(fds),
            "textures": textures,
        }
        return WithFds(
            result,
            fds,
            without_fds=_unsupported(
                "the control connection is tcp: file descriptors pass only over a unix socket"
            ),
        )

    def _start_export(self) -> tuple[list[dict[str, Any]], tuple[int, ...]]:
        """On the render thread: the slot textures, made and exported at the first request
        (every frame from then on copies its layers into them)."""
        if self._slot_textures is None:
            from wxsky.render.texture_export import DmaBufExporter, SlotTextures

            r = self._renderer
            assert r is not None
            specs = layer_specs(self.config)
            layers = [(s.name, s.max_width, s.max_height) for s in specs]
            self._slot_textures = SlotTextures(
                r.ctx,
                layers,
                2,
                DmaBufExporter.create(),
                formats={s.name: s.format for s in specs},
            )
            log.info("zero-copy textures: exported %d layers x 2 slots", len(layers))
        textures, fds = self._slot_textures.descriptors()
        return textures, fds

    def _segment_version(self) -> int:
        """The layout version of the daemon's segment (1 for RGBA8 layers, 2 with RGBA16F)."""
        return segment_version(layer_specs(self.config))

    def _publish_target(self) -> None:
        if self.engine.target_version != self._target_version:
            self._target_version = self.engine.target_version
            self._server_broadcast("target", weather_to_dict(self.engine.target))

    def _radar(self, params: dict[str, Any]) -> dict[str, Any]:
        """The weather radar's last picture for these settings (or `pending`), and a new one
        set going on the radar's thread from this moment's weather and aircraft."""
        key = radar_key(params)
        if self._radar_work is None:
            self._radar_work = RadarWork()
        engine = self.engine
        made = self._radar_work.ask(key, engine.state, engine.drift, engine.camera.position_m)
        return radar_reply(made, key)

    def status(self) -> dict[str, Any]:
        # The parts' first: one may refresh the detail of its inputs.
        own: dict[str, Any] = {}
        for part in self.parts:
            own.update(part.status())
        status = {
            "version": __version__,
            "uptime_s": time.monotonic() - self._started,
            "frames_published": self.frames_published,
            "fps": self.fps(),
            "weather": weather_to_dict(self.engine.state),
            "target": weather_to_dict(self.engine.target),
            "settled": self.engine.settled,
            "overrides": self.engine.sources.holds(self.engine.wall_s),
            "inputs": [s.to_dict() for s in self.inputs.values()],
            "clients": self._server.client_count if self._server else 0,
            "shm_name": self.config.output.shm_name,
            # Truncations or overwrites of the segment by another process, each written again.
            "segment": self._writer.segment_status() if self._writer is not None else None,
            "camera": camera_to_dict(self.engine.camera),
            "clock_rate": self.engine.clock_rate,
            "clock_at_end": self.engine.clock_at_end,
            "frozen": self.engine.frozen,
            "frames": self._frame_times.to_dict(),
            "at_eye": self._at_eye,
            "scene_work": self.engine.scene_work(),
            "block_cache": BLOCK_CACHE.info().to_dict(),
            "memory": memory_status(self._trims, self._trimmed_kib),
            "zero_copy": {
                "supported": self._export_probe is not None and self._export_probe.supported,
                "reason": self._export_failed
                or (self._export_probe.reason if self._export_probe is not None else None),
                "exported": self._slot_textures is not None,
            },
        }
        for key, value in own.items():
            status.setdefault(key, value)  # a part adds keys; the daemon's stay its own
        return status

    def scene_info(self) -> dict[str, Any]:
        ring = self.engine.ring
        return {
            "shm_name": self.config.output.shm_name,
            "ring_version": self.engine.ring_version,
            "ring_busy": self.engine.ring_busy,
            "ring": ring.geometry.to_dict() if ring is not None else None,
            "ring_texture_px": self.config.scene.ring_texture_px,
            "camera": camera_to_dict(self.engine.camera),
            "sky": self.engine.sky().to_dict(),
            "block_size_m": BLOCK_SIZE_M,
            "layers": [s.name for s in layer_specs(self.config)],
            # The picture layers' format (docs/protocol.md §1.2; `output_format`).
            "layer_format": self.config.output.layer_format,
        }

    def _broadcast_frame(self, plan: FramePlan, meta: FrameMeta, published_s: float) -> None:
        self._at_eye = _at_eye(plan)
        self._server_broadcast(
            "frame",
            {
                "frame_number": meta.frame_number,
                "published_s": published_s,
                "time_utc": _frame_time(plan.state.time_utc),
                "ring_version": meta.ring_version,
                "ring_set": meta.ring_set,
                "ring_fade": meta.ring_fade,
                "split_distance_m": plan.frame.split_distance_m,
                # Where a host with its own geometry composites `near` (scene/near_depth.py).
                "near_distance_m": near_distance_m(plan.frame),
                "camera": camera_to_dict(meta.camera),
                "sun_direction_enu": list(meta.sun_direction_enu),
                **plan.frame.in_cloud.to_dict(),
                # Lightning lighting the clouds in this frame: each flash's id and glow 0..1.
                "flashes": [{"id": f.id, "glow": g} for f, g in plan.frame.flashes],
                # What falls at the eye and how far one sees in it (scene/precip_eye.py).
                "at_eye": self._at_eye,
                # The air at the host's aircraft for its flight model (app/flight_air.py).
                "air": self._flight_air.for_frame(plan, self.engine, published_s),
            },
        )
        for flash in plan.frame.new_flashes:
            self._server_broadcast(
                "lightning", {"frame_number": meta.frame_number, **flash.to_dict()}
            )
        radar = self._radar_layer.shown if self._radar_layer is not None else None
        if (
            radar is not None
            and meta.radar is not None
            and meta.radar.version > self._radar_announced
        ):
            # With the first frame whose slot holds the picture (the record says which).
            self._radar_announced = meta.radar.version
            if radar.version == meta.radar.version:
                self._server_broadcast("radar", radar.notification(meta.frame_number))

    def _server_broadcast(self, topic: str, params: dict[str, Any]) -> None:
        if self._server is not None:
            self._server.broadcast(topic, params)

    # -- bookkeeping ------------------------------------------------------------------

    def _count_frame(self, published_s: float) -> None:
        self.frames_published += 1
        self._frame_times.published(published_s)

    def fps(self) -> float:
        return self._frame_times.fps(time.monotonic())

    def status_line(self) -> str:
        inputs = ", ".join(
            f"{s.name} {s.messages} msgs/{s.errors} errs" + ("" if s.ok else " DOWN")
            for s in self.inputs.values()
        )
        return (
            f"{self.fps():.1f} fps, {self.frames_published} frames, "
            f"{self.engine.state.summary()}; inputs: {inputs}"
        )

    def _preview_idle(self) -> bool:
        return self._preview_task is None or self._preview_task.done()

    def _trim_heap(self) -> None:
        given = trim_heap()
        if given is not None:
            self._trims += 1
            self._trimmed_kib += given

    def _write_preview(self) -> None:
        """Composite the latest published frame the way a host does: from shared memory."""
        from wxsky.host.reference import host_frame
        from wxsky.png import write_png

        assert self.preview_dir is not None
        try:
            with FrameReader.open(self.config.output.shm_name) as reader:
                image = host_frame(reader.read(timeout_s=1.0)).composite()
            write_png(self.preview_dir / "preview.png", image)
        except (WxskyError, OSError) as exc:
            log.warning("preview not written: %s", exc)

    # -- signals ----------------------------------------------------------------------

    @contextlib.contextmanager
    def _capture_signals(self) -> Iterator[None]:
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        loop = asyncio.get_running_loop()
        # A fatal signal that can still happen (a driver's SIGSEGV; SIGBUS from memory other
        # than the frame segment, which is never mapped) leaves "Fatal Python error" and every
        # thread's stack on stderr, the daemon's log, rather than nothing at all.
        if not faulthandler.is_enabled():
            with contextlib.suppress(ValueError, OSError, AttributeError):
                faulthandler.enable(all_threads=True)
        sigs = (signal.SIGINT, signal.SIGTERM)
        original = {sig: signal.getsignal(sig) for sig in sigs}

        def on_signal(sig: int, frame: FrameType | None) -> None:
            loop.call_soon_threadsafe(self._on_signal, sig)

        # SIGUSR2 logs where Python memory grew, when tracemalloc is on (memory.TraceReport).
        traces = TraceReport()
        if hasattr(signal, "SIGUSR2"):
            loop.add_signal_handler(signal.SIGUSR2, lambda: log.info("memory: %s", traces.report()))
        try:
            for sig in sigs:
                signal.signal(sig, on_signal)
            yield
        finally:
            for sig, handler in original.items():
                signal.signal(sig, handler)
            if hasattr(signal, "SIGUSR2"):
                loop.remove_signal_handler(signal.SIGUSR2)

    def _on_signal(self, sig: int) -> None:
        self._signals += 1
        if self._signals > 1 and sig == signal.SIGINT:
            log.warning("second interrupt: forcing exit")
            self._force_cleanup()
            os._exit(130)  # as a shell reports death by SIGINT, and as the CLI does
        log.info("received %s, shutting down", signal.Signals(sig).name)
        self._stop.set()

    def _force_cleanup(self) -> None:
        """Best effort on a forced exit: leave no segment or socket behind."""
        with contextlib.suppress(Exception):
            if self._writer is not None:
                self._writer.close()
        # Only the socket this daemon bound: one that failed to start (another daemon holds
        # the address) must not remove that daemon's socket.
        if self._server is not None:
            self._server.remove_socket_file()


def _frame_time(t: datetime) -> str:
    """ISO 8601 with microseconds; the year padded by hand (strftime writes 857, not 0857)."""
    return f"{t.year:04d}-{t:%m-%dT%H:%M:%S.%f}Z"


def _unsupported(reason: str) -> dict[str, Any]:
    return {"supported": False, "reason": reason, "fallback": "shm"}


def _parse(text: str) -> Address:
    from wxsky.output.transport import parse_address

    return parse_address(text)


def _source_name(patches: list[WeatherPatch]) -> str:
    kinds = {Source.PRESET: "preset", Source.METAR: "metar"}
    return "+".join(kinds.get(p.source, p.source.value) for p in patches)


def _at_eye(plan: FramePlan) -> dict[str, Any]:
    """What falls at the eye in a frame, and how far one sees there: without it (a frame
    not built by `build_frame`), the weather's visibility and nothing falling."""
    at_eye = plan.frame.at_eye or AtEye(None, 0.0, None, plan.state.visibility_m)
    return at_eye.to_dict()
