"""`wxsky bench`: render N frames along a camera path exactly as the daemon would, and time
each stage of every frame.

Stages, in frame order (each ends with the GPU idle, so its time is its own):

    scene           weather step, ring schedule, gathering, shading (engine.advance less sort)
    sort            the near sprites back to front
    impostor_slice  the ring impostor (or slice of one) this frame renders (none in most
                    frames, or direct mode)
    near_pass       the sky and the near sprites (renderer.render_frame)
    publish         reading the layers into a real shared-memory slot and publishing it

Timed frames are paced by simulated time (one every 1/fps s of it), not by the wall clock:
the benchmark runs as fast as it can. In ring mode the ring is built on its worker as in the
daemon, so a rebuild costs the frames the CPU time it takes from them; the timed frames start
once the first ring is shown (untimed lead-in frames until then, one a tick as the daemon's:
its first seconds draw no far clouds), unless `--from-start`. `--mode direct` draws every
cloud within range as sprites every frame, and no ring.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import statistics
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from wxsky.app.camera_path import CameraPath
from wxsky.app.frame_publish import draw_ring, frame_layer_specs, publish_plan
from wxsky.app.trace import TraceWriter
from wxsky.engine.ring_schedule import DEFAULT_SLICE_MS
from wxsky.engine.ring_worker import DEFAULT_NICE
from wxsky.engine.stages import FramePlan, SkyEngine
from wxsky.output.shm import FrameWriter
from wxsky.scene.camera import Camera
from wxsky.scene.exposure import AUTO, initial_scale, needs_variable
from wxsky.scene.layout import FrameScene, SceneSettings, SpriteDraw
from wxsky.scene.shading_harris import particle_keys
from wxsky.weather.state import WeatherState

if TYPE_CHECKING:
    from wxsky.render.renderer import Renderer

STAGES = ("scene", "sort", "impostor_slice", "near_pass", "publish")
# The stages that are the frame's own CPU work (issue 19): with a GPU drawing, what is left of
# the frame on the CPU.
CPU_STAGES = ("scene", "sort", "publish")
# How long the lead-in waits for the first ring (a 2-core CPU renderer takes 3-10 s).
LEAD_IN_LIMIT_S = 300.0

log = logging.getLogger(__name__)


class _StageTimes:
    """Seconds per stage for the frame being timed (a `StageClock`)."""

    def __init__(self) -> None:
        self.frame: dict[str, float] = {}

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.frame[name] = self.frame.get(name, 0.0) + time.perf_counter() - t0


@dataclass
class BenchResult:
    preset: str
    mode: str
    width: int
    height: int
    path: str
    renderer: str
    startup_s: float
    frames_s: float
    stage_s: dict[str, list[float]] = field(default_factory=dict)  # per frame, by stage
    frame_s: list[float] = field(default_factory=list)
    # Per frame, the CPU the calling thread spent in CPU_STAGES (time.thread_time): their
    # wall time less what the machine's other threads took from it (llvmpipe's raster
    # threads share its cores).
    cpu_stages_s: list[float] = field(default_factory=list)
    events: dict[str, int] = field(default_factory=dict)
    build_s: list[float] = field(default_factory=list)  # ring builds on the worker thread
    sprites: list[int] = field(default_factory=list)  # near sprites drawn per frame
    dropped: list[int] = field(default_factory=list)  # near sprites the cap left out
    # With check_order: per frame after the first, whether the near sprites' order differs
    # from the previous frame's (for the sprites in both), and the largest change (0..255) in
    # any channel of the near layer that the new order makes against the old one.
    order_changed: list[bool] = field(default_factory=list)
    order_diff: list[int] = field(default_factory=list)
    # With profile: one row per renderer pass (render.profile.PassProfiler.rows) and the fill
    # limits, in Mpix/s, measured on this machine at the frame's size.
    passes: list[dict[str, Any]] = field(default_factory=list)
    fill_limits: dict[str, float] = field(default_factory=dict)
    # Untimed frames before the timed ones, until the first ring was shown (`lead_in`).
    lead_in_frames: int = 0
    lead_in_s: float = 0.0
    # Convective towers: how many a frame drew (median), and the tower thread's work (the
    # automaton, smoothing and lighting of lit steps) during the timed frames.
    towers: list[int] = field(default_factory=list)
    tower_work_s: float = 0.0
    tower_steps_lit: int = 0

    @property
    def frames(self) -> int:
        return len(self.frame_s)

    def to_dict(self) -> dict[str, Any]:
        return {
            "preset": self.preset,
            "mode": self.mode,
            "size": [self.width, self.height],
            "path": self.path,
            "renderer": self.renderer,
            "frames": self.frames,
            "startup_s": self.startup_s,
            "lead_in_frames": self.lead_in_frames,
            "lead_in_s": self.lead_in_s,
            "frames_s": self.frames_s,
            "stages_ms": {name: _summary(v) for name, v in self.stage_s.items()},
            "frame_ms": _summary(self.frame_s),
            "cpu_stages_ms": {
                "wall": _summary(
                    [sum(f) for f in zip(*(self.stage_s[n] for n in CPU_STAGES), strict=True)]
                ),
                "thread_cpu": _summary(self.cpu_stages_s),
            },
            "near_sprites": {
                "median": statistics.median(self.sprites) if self.sprites else 0,
                "max": max(self.sprites, default=0),
                "capped_frames": sum(d > 0 for d in self.dropped),
                "most_dropped": max(self.dropped, default=0),
            },
            "ring_events": dict(self.events),
            "ring_build_ms": _summary(self.build_s),
            "towers": {
                "median": statistics.median(self.towers) if self.towers else 0,
                "steps_lit": self.tower_steps_lit,
                "work_ms_per_frame": 1000.0 * self.tower_work_s / max(1, self.frames),
                "work_ms_per_step": 1000.0 * self.tower_work_s / max(1, self.tower_steps_lit),
            },
            **(
                {
                    "order_check": {
                        "frames": len(self.order_diff),
                        "frames_with_order_change": sum(self.order_changed),
                        "max_pixel_change": max(self.order_diff, default=0),
                        "frames_over_8": sum(d > 8 for d in self.order_diff),
                    }
                }
                if self.order_diff
                else {}
            ),
            **(
                {"passes": self.passes, "fill_limits_mpix_per_s": self.fill_limits}
                if self.passes
                else {}
            ),
        }

    def table(self) -> str:
        d = self.to_dict()
        lines = [
            f"wxsky bench: {self.preset}, {self.mode} mode, {self.width}x{self.height}, "
            f"{self.frames} frames, {self.path} ({self.renderer})",
            f"{'stage':<16}{'median ms':>11}{'p95 ms':>10}",
        ]
        for name in STAGES:
            s = d["stages_ms"][name]
            lines.append(f"{name:<16}{s['median']:>11.2f}{s['p95']:>10.2f}")
        f = d["frame_ms"]
        lines.append(f"{'frame':<16}{f['median']:>11.2f}{f['p95']:>10.2f}")
        c = d["cpu_stages_ms"]
        lines.append(
            f"CPU stages ({' + '.join(CPU_STAGES)}): median {c['wall']['median']:.2f} ms wall, "
            f"{c['thread_cpu']['median']:.2f} ms of the frame thread's CPU"
        )
        lines.append(
            f"near sprites per frame: median {d['near_sprites']['median']:.0f}, "
            f"max {d['near_sprites']['max']}; frames over the cap "
            f"{d['near_sprites']['capped_frames']} (at most {d['near_sprites']['most_dropped']}"
            " left out)"
        )
        if self.mode == "ring":
            b = d["ring_build_ms"]
            lines.append(
                f"ring: {self.events.get('ring_rebuild_start', 0)} rebuilds started, "
                f"{self.events.get('impostor_rendered', 0)} impostors rendered, "
                f"{self.events.get('crossfade_done', 0)} fades done; builds on the worker "
                f"median {b['median']:.0f} ms"
            )
        t = d["towers"]
        if t["median"]:
            lines.append(
                f"towers: median {t['median']:.0f} a frame; {t['steps_lit']} steps lit on their "
                f"thread ({t['work_ms_per_step']:.0f} ms of CPU each), "
                f"{t['work_ms_per_frame']:.2f} ms of that work a frame"
            )
        if self.order_diff:
            o = d["order_check"]
            lines.append(
                f"order check: {o['frames_with_order_change']} of {o['frames']} frames changed "
                f"the near sprites' order; largest pixel change from it {o['max_pixel_change']}"
                f"/255; frames over 8/255: {o['frames_over_8']}"
            )
        lead = (
            f", {self.lead_in_frames} untimed frames {self.lead_in_s:.2f} s until the first "
            "ring was shown"
            if self.lead_in_frames
            else ""
        )
        lines.append(
            f"startup {self.startup_s:.2f} s{lead}, {self.frames} frames {self.frames_s:.2f} s"
        )
        if self.passes:
            lines.extend(self.pass_table())
        return "\n".join(lines)

    def pass_table(self) -> list[str]:
        limits = ", ".join(f"{k} {v:.0f}" for k, v in self.fill_limits.items())
        lines = [
            "",
            f"passes (each timed to an idle GPU; fill limits here, Mpix/s: {limits})",
            f"{'pass':<22}{'calls/frame':>12}{'median ms':>11}{'ms/frame':>10}"
            f"{'Mpix/call':>11}{'Mpix/s':>9}{'limit':>17}{'ratio':>7}",
        ]
        for r in self.passes:
            lines.append(
                f"{r['pass']:<22}{r['calls_per_frame']:>12.2f}{r['median_ms']:>11.2f}"
                f"{r['total_ms_per_frame']:>10.2f}{r['mpix_per_call']:>11.3f}"
                f"{r['mpix_per_s']:>9.0f}{r['limit']:>17}{r['ratio']:>7.2f}"
            )
        return lines


def run_bench(
    state: WeatherState,
    settings: SceneSettings,
    path: CameraPath,
    frames: int,
    mode: str,
    size: tuple[int, int],
    *,
    preset: str = "",
    fov_deg: float = 60.0,
    fps: float = 30.0,
    ring_fade_s: float = 1.0,
    ring_slice_ms: float | None = DEFAULT_SLICE_MS,
    ring_build: str = "async",
    ring_worker: str = "process",
    ring_worker_nice: int = DEFAULT_NICE,
    trace: TraceWriter | None = None,
    started_s: float | None = None,
    check_order: bool = False,
    profile: bool = False,
    lead_in: bool = True,
    progress: Callable[[str], None] | None = None,
    exposure_setting: float | str = AUTO,
    near_depth: bool = False,
) -> BenchResult:
    """Render `frames` frames along `path`; `started_s`: the perf_counter reading the process's
    startup is counted from (default: now). `check_order`: also measure what each change in the
    near sprites' back-to-front order does to the picture (see `order_change`), outside the
    timed stages. `profile`: also time and count the fragments of every renderer pass (which
    makes the stages slower: each pass then waits for the GPU) and measure the fill limits.
    `ring_build="sync"` builds rings in the frame that needs them (deterministic frames, for
    tests) instead of on the worker as the daemon does. `lead_in` (ring mode): first render
    untimed frames, the camera at the path's start, until the first ring has been built,
    drawn and faded in, so the timed frames are the daemon's steady state and not its first
    seconds (which draw no far clouds); False times the frames from the daemon's start.
    `progress` is told what is being done as it starts (the command line shows it).
    `near_depth`: draw and publish the near layer's depth too ([output] near_depth)."""
    from wxsky.render.context import describe
    from wxsky.render.renderer import Renderer
    from wxsky.render.towers import SLICE_TEXELS

    t_start = time.perf_counter() if started_s is None else started_s
    say = progress if progress is not None else _quiet
    say("starting the renderer and the scene")
    width, height = size
    dt_s = 1.0 / fps

    def camera_at(t_s: float) -> Camera:
        pose = path.at(t_s)
        return Camera(
            position_m=pose.position_m,
            heading_deg=pose.heading_deg,
            pitch_deg=pose.pitch_deg,
            roll_deg=pose.roll_deg,
            fov_deg=fov_deg,
            width_px=width,
            height_px=height,
        )

    build_s: list[float] = []
    times = _StageTimes()
    shm_name = f"wxsky-bench-{os.getpid()}"
    specs = frame_layer_specs(
        width, height, settings.ring_texture_px, settings.shadow_map_px, near_depth=near_depth
    )
    with (
        Renderer(
            settings.ring_texture_px,
            variable_exposure=needs_variable(exposure_setting),
            near_depth=near_depth,
        ) as renderer,
        FrameWriter.create(shm_name, specs) as writer,
        SkyEngine(
            state,
            camera_at(0.0),
            settings,
            clock_rate=1.0,
            render_mode=mode,
            ring_build=ring_build,
            ring_fade_s=ring_fade_s,
            ring_slice_ms=ring_slice_ms,
            ring_worker=ring_worker,
            ring_worker_nice=ring_worker_nice,
        ) as engine,
    ):
        # [render] exposure as the daemon takes it (the display path costs more off EV 0).
        renderer.exposure = initial_scale(exposure_setting)
        engine.time_ring_builds(build_s)
        if ring_build == "async":
            renderer.towers.slice_texels = SLICE_TEXELS  # as the daemon draws them
        first = engine.warm_up()
        if first is not None:
            renderer.warm_up(first)
        result = BenchResult(
            preset=preset,
            mode=mode,
            width=width,
            height=height,
            path=path.name,
            renderer=describe(renderer.ctx),
            startup_s=time.perf_counter() - t_start,
            frames_s=0.0,
            stage_s={name: [] for name in STAGES},
        )
        drawn = 0  # frames rendered, lead-in included (the trace's frame numbers)

        def draw(t_s: float, dt: float) -> FramePlan:
            nonlocal drawn
            engine.set_camera(camera_at(t_s))
            times.frame = {}
            t0, cpu0 = time.perf_counter(), time.thread_time()
            plan = engine.advance(dt, times)
            times.frame["scene"] = time.perf_counter() - t0 - times.frame.get("sort", 0.0)
            cpu_s = time.thread_time() - cpu0
            with times.stage("impostor_slice"):
                if plan.rings.render or plan.rings.current is None:
                    draw_ring(renderer, plan)
                    renderer.finish()
            if plan.rings.render_slice is not None:
                engine.note_ring_render(times.frame["impostor_slice"])
            with times.stage("near_pass"):
                renderer.render_frame(plan.frame)
                renderer.finish()
            cpu0 = time.thread_time()
            with times.stage("publish"):
                publish_plan(
                    renderer,
                    writer,
                    plan,
                    drawn + 1,
                    settings.ring_texture_px,
                    near_depth=near_depth,
                )
            times.frame["cpu"] = cpu_s + time.thread_time() - cpu0
            times.frame["frame"] = time.perf_counter() - t0
            drawn += 1
            if trace is not None:
                trace.write_events(drawn, plan.frame.camera.position_m, plan.events)
            return plan

        if lead_in and mode == "ring":
            t_lead = time.perf_counter()
            while True:
                say(f"untimed frames until the first ring is shown: {drawn}")
                t_frame = time.perf_counter()
                plan = draw(0.0, dt_s if drawn else 0.0)
                # Paced as the daemon's frames are, one a tick: unpaced, these frames took
                # the cores from the idle-class worker building the ring they wait for (a
                # clear sky at 64x36: 22 s of frames idle, 141 s beside stress-ng).
                time.sleep(max(0.0, dt_s - (time.perf_counter() - t_frame)))
                ring_shown = plan.rings.current is not None and plan.rings.incoming is None
                # ... and every tower drawn, with no lit step still owed to it (the steady state
                # lights a step per tower every 10 s of sim time, not minutes of them at once).
                if ring_shown and renderer.towers.behind == 0 and engine.towers_pending == 0:
                    break
                if time.perf_counter() - t_lead > LEAD_IN_LIMIT_S:
                    log.warning(
                        "bench: the first ring was not shown within %.0f s; timing from here",
                        LEAD_IN_LIMIT_S,
                    )
                    break
            result.lead_in_frames = drawn
            result.lead_in_s = time.perf_counter() - t_lead
        previous_keys: npt.NDArray[np.uint64] | None = None
        profiler = renderer.start_profile() if profile else None
        work_before, lit_before = engine.tower_work_s, engine.tower_steps_lit
        loop_start = time.perf_counter()
        for k in range(frames):
            say(f"frame {k + 1} of {frames}")
            plan = draw(k * dt_s, dt_s if drawn else 0.0)
            result.frame_s.append(times.frame["frame"])
            result.cpu_stages_s.append(times.frame["cpu"])
            if profiler is not None:
                profiler.frame_done()
            for name in STAGES:
                result.stage_s[name].append(times.frame.get(name, 0.0))
            result.sprites.append(len(plan.frame.near))
            result.towers.append(len(plan.frame.towers))
            for e in plan.events:
                result.events[e.event] = result.events.get(e.event, 0) + 1
            result.dropped.append(plan.frame.near_dropped)
            if check_order:
                keys = particle_keys(plan.frame.near.sprites)
                if previous_keys is not None:
                    changed, diff = order_change(renderer, plan.frame, previous_keys, keys)
                    result.order_changed.append(changed)
                    result.order_diff.append(diff)
                previous_keys = keys
        result.frames_s = time.perf_counter() - loop_start
        result.tower_work_s = engine.tower_work_s - work_before
        result.tower_steps_lit = engine.tower_steps_lit - lit_before
        result.build_s = list(build_s)
        if profiler is not None:
            from wxsky.render.profile import measure_fill_limits

            say("measuring this machine's fill limits")
            result.fill_limits = measure_fill_limits(renderer.ctx, size, renderer.finish)
            result.passes = profiler.rows(result.fill_limits)
    return result


def _quiet(what: str) -> None:
    pass


def order_change(
    renderer: Renderer,
    frame: FrameScene,
    previous_keys: npt.NDArray[np.uint64],
    keys: npt.NDArray[np.uint64],
) -> tuple[bool, int]:
    """Whether the frame's near sprites are drawn in a different order than the previous frame
    drew the same sprites, and if so the largest change in any channel of the near layer
    between drawing this frame in its own order and in the previous one (sprites new this
    frame keep their place after the sprite before them). 0 when the order is the same."""
    rank_of = {int(k): r for r, k in enumerate(previous_keys)}
    ranks = np.empty(len(keys))
    last = -1.0
    for i, k in enumerate(keys):
        r = rank_of.get(int(k))
        last = float(r) if r is not None else last + 1e-6
        ranks[i] = last
    old_order = np.argsort(ranks, kind="stable")
    if np.array_equal(old_order, np.arange(len(keys))):
        return False, 0
    renderer.render_frame(frame)
    mine = renderer.read("near").astype(np.int16)
    near = frame.near
    normals = None if near.normals is None else near.normals[old_order]
    reordered = SpriteDraw(near.sprites.take(old_order), near.rgba[old_order], normals)
    renderer.render_frame(dataclasses.replace(frame, near=reordered))
    theirs = renderer.read("near").astype(np.int16)
    return True, int(np.abs(mine - theirs).max())


def _summary(values: list[float]) -> dict[str, float]:
    if not values:
        return {"median": 0.0, "p95": 0.0, "max": 0.0}
    ordered = sorted(values)
    p95 = ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]
    return {
        "median": 1000.0 * statistics.median(ordered),
        "p95": 1000.0 * p95,
        "max": 1000.0 * ordered[-1],
    }
