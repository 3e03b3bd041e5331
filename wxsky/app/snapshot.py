"""One-shot render: the daemon's stages and the reference host's compositing, in one process.

`wxsky snapshot` and the daemon share everything from the weather state to the composited
picture: the same engine plan, the same renderer passes, the same compositor.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from wxsky.engine.stages import DEFAULT_TRANSITION_STEP_S, FramePlan, SkyEngine
from wxsky.host.compositor import composite, composite_linear, layers_from_images
from wxsky.output import memory
from wxsky.render.renderer import Renderer
from wxsky.scene import exposure
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
F32 = npt.NDArray[np.float32]

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
# `linear` adds a second renderer's RGBA16F layers, their float32 read-back and the float
# composite: `--linear-out` raised the peak of a clear 1920x1080 snapshot by 76 MB (768 ->
# 844 MB, llvmpipe), 37 bytes a pixel with the ring's 8 x 256^2 texels in it; with room to
# spare, and the impostors' float copies (8 B on the GPU, 8 + 16 read back) counted apart.
LINEAR_BYTES_PER_PX = 40
LINEAR_BYTES_PER_RING_TEXEL = 32


@dataclass(frozen=True)
class Snapshot:
    image: U8  # (H, W, 4) composited, opaque
    layers: dict[str, U8]  # raw premultiplied layers by name (LAYER_NAMES, "shadow")
    ring_quads_m: npt.NDArray[np.float64]  # (8, 4, 3)
    state: WeatherState  # the applied weather the picture shows
    shadow: CloudShadow | None = None  # the ring's cloud-shadow map (layers["shadow"])
    # (H, W, 3) the composite's scene-linear colour before exposure and tone map, rows top
    # first (take_snapshot's `linear`); None when not asked for.
    linear: F32 | None = None


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
    linear: bool = False,
    exposure_setting: float | str = exposure.AUTO,
) -> Snapshot:
    """`drift_s`: how long the wind has blown the clouds since the weather was set (a picture
    later than its preset's time shows them moved on, the same in every process). `mode`:
    "ring" (far clouds in impostors, as the daemon draws them) or "direct" (every cloud as a
    sprite, to compare). `position_deg`: (lat, lon) of the camera, placed as the daemon's
    `set_camera` places it (near the site: under the same sky; far: a new site).
    `progress` is told each step as it starts (the command line shows it: a towering sky
    takes minutes on a CPU). `linear`: also draw the frame into float layers and keep their
    composite (Snapshot.linear; the same camera and plan as the picture). `exposure_setting`:
    the `[render] exposure` the picture is drawn with (a renderer passed in gets its own
    exposure back afterwards).
    Raises RuntimeFailure, before anything is built, if the picture would not fit in the
    memory available (`snapshot_bytes`)."""
    check_snapshot_memory(camera.width_px, camera.height_px, settings, linear)
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
    own = renderer is None or (
        exposure.needs_variable(exposure_setting) and not renderer.variable_exposure
    )
    if own:
        progress("starting the renderer")
    # A renderer passed in that draws at EV 0 only lends its context to one that need not.
    r = (
        Renderer(
            settings.ring_texture_px,
            ctx=None if renderer is None else renderer.ctx,
            variable_exposure=exposure.needs_variable(exposure_setting),
        )
        if own
        else renderer
    )
    assert r is not None
    kept_exposure = r.exposure
    try:
        r.exposure = exposure.initial_scale(exposure_setting)
        shot = picture(r, plan, progress=progress)
        if linear:
            progress("drawing the scene-linear layers")
            shot = dataclasses.replace(shot, linear=linear_picture(r, plan, settings))
        return shot
    finally:
        r.exposure = kept_exposure
        if own:
            r.close()


def snapshot_bytes(width: int, height: int, settings: SceneSettings, linear: bool = False) -> int:
    """About the most memory a snapshot of width x height takes (see SNAPSHOT_BASE_BYTES),
    with `linear` its scene-linear picture too."""
    texels = RING_SIZE * settings.ring_texture_px**2
    per_px = SNAPSHOT_BYTES_PER_PX + (LINEAR_BYTES_PER_PX if linear else 0)
    per_texel = SNAPSHOT_BYTES_PER_RING_TEXEL + (LINEAR_BYTES_PER_RING_TEXEL if linear else 0)
    return SNAPSHOT_BASE_BYTES + per_px * width * height + per_texel * texels


def check_snapshot_memory(
    width: int, height: int, settings: SceneSettings, linear: bool = False
) -> None:
    """RuntimeFailure, one line with the estimate and what is available, if a snapshot of
    width x height (with `linear`, its scene-linear picture too) would not fit in memory."""
    memory.require(
        snapshot_bytes(width, height, settings, linear),
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


def linear_picture(renderer: Renderer, plan: FramePlan, settings: SceneSettings) -> F32:
    """(H, W, 3) float32 scene-linear composite of a plan, rows top first: drawn again, ring
    and all, by a linear renderer on `renderer`'s context into float layers, and composited
    as `picture` composites (the host's way), before exposure and tone map."""
    with Renderer(settings.ring_texture_px, ctx=renderer.ctx, output="linear") as lin:
        lin.render_ring(plan.ring)
        lin.render_frame(plan.frame)
        images = {name: lin.read_linear(name) for name in LAYER_NAMES}
    quads = plan.ring.geometry.corners_m()
    out: F32 = composite_linear(layers_from_images(images, quads), plan.frame.camera).astype(
        np.float32
    )
    return out


LINEAR_SUFFIXES = (".pfm", ".npy")


def write_linear(path: Path, rgb: F32) -> None:
    """Write (H, W, 3) scene-linear colour, rows top first, by the name's suffix: `.npy`
    (float32 H x W x 3, rows top first) or `.pfm` (Portable Float Map: "PF", little-endian
    float32, rows bottom first as the format has them). ValueError for another suffix;
    OSError if it cannot be written."""
    data = np.ascontiguousarray(rgb, np.float32)
    if data.ndim != 3 or data.shape[2] != 3:
        raise ValueError(f"scene-linear picture must be H x W x 3, got {data.shape}")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        with path.open("wb") as f:
            np.save(f, data, allow_pickle=False)
    elif suffix == ".pfm":
        h, w = data.shape[:2]
        # A negative scale says little-endian; the rows go bottom first.
        header = f"PF\n{w} {h}\n-1.0\n".encode("ascii")
        body = np.ascontiguousarray(data[::-1]).astype("<f4").tobytes()
        with path.open("wb") as f:
            f.write(header + body)
    else:
        raise ValueError(f"{path}: give a name ending in .pfm or .npy")


def read_pfm(path: Path) -> F32:
    """(H, W, 3) float32, rows top first, from a colour PFM file (either byte order)."""
    raw = path.read_bytes()
    parts = raw.split(b"\n", 3)
    if len(parts) < 4 or parts[0].strip() != b"PF":
        raise ValueError(f"{path}: not a colour PFM file")
    w, h = (int(v) for v in parts[1].split())
    scale = float(parts[2])
    dtype = "<f4" if scale < 0 else ">f4"
    pixels = np.frombuffer(parts[3], dtype, count=w * h * 3).reshape(h, w, 3)
    out: F32 = pixels[::-1].astype(np.float32)
    return out
