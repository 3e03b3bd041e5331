"""One-shot render: the daemon's stages and the reference host's compositing, in one process.

`wxsky snapshot` and the daemon share everything from the weather state to the composited
picture: the same engine plan, the same renderer passes, the same compositor.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.engine.stages import DEFAULT_TRANSITION_STEP_S, FramePlan, SkyEngine
from wxsky.host.compositor import composite, layers_from_images
from wxsky.output import memory
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.cloud_shadow import CloudShadow
from wxsky.scene.layout import SceneSettings
from wxsky.scene.ring import RING_SIZE
from wxsky.weather.state import Source, WeatherPatch, WeatherState
from wxsky.weather.transition import TransitionRates

# The renderer's layers. A snapshot's `layers` also hold "shadow", the ring's cloud-shadow
# map (the segment's `shadow` layer), except in direct mode (no ring) or with
# [scene] shadow_map_px 0.
LAYER_NAMES: tuple[str, ...] = ("sky", "near", *(f"ring_{i}" for i in range(RING_SIZE)))

U8 = npt.NDArray[np.uint8]

Progress = Callable[[str], None]
"""Told what a snapshot is doing now, in a few words ("drawing the far clouds")."""


def _quiet(what: str) -> None:
    pass


# What a snapshot takes at its peak, calibrated from the peak resident memory of
# `/usr/bin/time -v wxsky snapshot --preset clear --size WxH` on llvmpipe: 145 MiB at 16x16,
# then 261 to 267 bytes more a pixel from 960x540 to 3840x2160 (the renderer's layers and
# their readback, the compositor's float64 RGBA arrays, the PNG's rows), and 12 bytes more a
# texel of the eight impostors (ring_texture_px 256 -> 2048). The base also covers a default
# range's cloud work (a thunderstorm's three layers: 212 MiB at 16x16).
SNAPSHOT_BASE_BYTES = 224 * memory.MIB
SNAPSHOT_BYTES_PER_PX = 280
SNAPSHOT_BYTES_PER_RING_TEXEL = 13


@dataclass(frozen=True)
class Snapshot:
    image: U8  # (H, W, 4) composited, opaque
    layers: dict[str, U8]  # raw premultiplied layers by name (LAYER_NAMES, "shadow")
    ring_quads_m: npt.NDArray[np.float64]  # (8, 4, 3)
    state: WeatherState  # the applied weather the picture shows
    shadow: CloudShadow | None = None  # the ring's cloud-shadow map (layers["shadow"])


@dataclass(frozen=True)
class Transition:
    """A picture taken `elapsed_s` after the weather target changed to `to`: the applied
    weather has moved toward it at `rates`, in steps of `step_s`, as in the daemon. The clock
    and the clouds' drift stand still meanwhile, so that only the change of weather differs
    between pictures at different `elapsed_s`."""

    to: WeatherPatch
    elapsed_s: float
    rates: TransitionRates = dataclasses.field(default_factory=TransitionRates)
    step_s: float = DEFAULT_TRANSITION_STEP_S


def take_snapshot(
    state: WeatherState,
    camera: Camera,
    settings: SceneSettings,
    renderer: Renderer | None = None,
    transition: Transition | None = None,
    drift_s: float = 0.0,
    mode: str = "ring",
    position_deg: tuple[float, float] | None = None,
    progress: Progress = _quiet,
) -> Snapshot:
    """`drift_s`: how long the wind has blown the clouds since the weather was set (a picture
    later than its preset's time shows them moved on, the same in every process). `mode`:
    "ring" (far clouds in impostors, as the daemon draws them) or "direct" (every cloud as a
    sprite, to compare). `position_deg`: (lat, lon) of the camera, placed as the daemon's
    `set_camera` places it (near the site: under the same sky; far: a new site).
    `progress` is told each step as it starts (the command line shows it: a towering sky
    takes minutes on a CPU).
    Raises RuntimeFailure, before anything is built, if the picture would not fit in the
    memory available (`snapshot_bytes`)."""
    check_snapshot_memory(camera.width_px, camera.height_px, settings)
    progress("building the clouds")
    engine = SkyEngine(state, camera, settings, clock_rate=0.0, render_mode=mode)
    if drift_s:
        engine.drift_for(drift_s)
    if position_deg is not None:
        engine.move_observer(*position_deg)
    if transition is not None:
        engine.rates = transition.rates
        engine.transition_step_s = transition.step_s
        # The new weather arrives as a run-time preset would and beats the picture's base; it
        # changes this sky, so the site, the clock and the cloud seed stay the first one's.
        change = dataclasses.replace(
            transition.to, source=Source.CONTROL, time_utc=None, observer=None, seed=None
        )
        engine.apply(change)
        engine.run_weather(transition.elapsed_s)
    plan = engine.advance(0.0)
    own = renderer is None
    if own:
        progress("starting the renderer")
    r = renderer if renderer is not None else Renderer(settings.ring_texture_px)
    try:
        return picture(r, plan, progress=progress)
    finally:
        if own:
            r.close()


def snapshot_bytes(width: int, height: int, settings: SceneSettings) -> int:
    """About the most memory a snapshot of width x height takes (see SNAPSHOT_BASE_BYTES)."""
    texels = RING_SIZE * settings.ring_texture_px**2
    return (
        SNAPSHOT_BASE_BYTES
        + SNAPSHOT_BYTES_PER_PX * width * height
        + SNAPSHOT_BYTES_PER_RING_TEXEL * texels
    )


def check_snapshot_memory(width: int, height: int, settings: SceneSettings) -> None:
    """RuntimeFailure, one line with the estimate and what is available, if a snapshot of
    width x height would not fit in memory."""
    memory.require(
        snapshot_bytes(width, height, settings),
        f"snapshot {width}x{height}",
        memory.memory_headroom(),
    )


def picture(
    renderer: Renderer, plan: FramePlan, draw_ring: bool = True, progress: Progress = _quiet
) -> Snapshot:
    """Draw a plan (its whole ring too, unless `draw_ring` is False because the renderer
    already holds it) and composite it as a host would."""
    if draw_ring:
        progress("drawing the far clouds (the impostor ring)")
        renderer.render_ring(plan.ring)
    progress("drawing the near clouds and the sky")
    renderer.render_frame(plan.frame)
    progress("compositing")
    images = {name: renderer.read(name) for name in LAYER_NAMES}
    if plan.ring.shadow is not None:
        images["shadow"] = np.array(plan.ring.shadow.rgba)
    quads = plan.ring.geometry.corners_m()
    return Snapshot(
        image=composite(layers_from_images(images, quads), plan.frame.camera),
        layers=images,
        ring_quads_m=quads,
        state=plan.state,
        shadow=plan.ring.shadow,
    )
