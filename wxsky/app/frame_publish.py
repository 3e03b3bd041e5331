"""Drawing a frame plan and handing it to hosts: the steps the daemon runs per frame, shared
with `wxsky bench` so the benchmark times exactly what the daemon does.

    draw_ring (one impostor of a rebuild, a slice of one, or none)
    -> renderer.render_frame (sky + near)
    -> publish_plan (read the layers into the shared-memory slot, the frame record, publish)
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Hashable, Sequence
from datetime import UTC
from typing import Protocol

import numpy as np

from wxsky.app.radar_layer import RadarShow
from wxsky.engine.stages import FramePlan
from wxsky.output.frame_meta import FrameMeta, ShadowPlacement
from wxsky.output.shm import RGBA8, LayerSpec
from wxsky.scene.cloud_shadow import SHADOW_MAP_PX
from wxsky.scene.layout import RingScene
from wxsky.scene.ring import RING_SIZE, ring_target_name


class RingRenderer(Protocol):
    def render_ring(
        self,
        ring: RingScene,
        indices: range | list[int] | tuple[int, ...] | None = None,
        ring_set: int = 0,
    ) -> None: ...

    def render_impostor_slice(
        self, ring: RingScene, index: int, start: int, stop: int, ring_set: int
    ) -> None: ...

    def read_into(
        self, name: str, buffer: memoryview, rows: tuple[int, int] | None = None
    ) -> None: ...

    def layer_size(self, name: str) -> tuple[int, int]: ...

    def layer_bands(self, name: str) -> tuple[tuple[int, int, int], ...] | None: ...


class LayerExport(Protocol):
    """The zero-copy textures of the slot being filled (render/texture_export.SlotTextures,
    bound to a slot): a GPU copy of each published layer, then a finish before the publish."""

    def copy(self, layer: str, source: str) -> None: ...

    def write(self, layer: str, pixels: bytes, width: int, height: int, version: int) -> None: ...

    def finish(self) -> None: ...


class LayerSink(Protocol):
    def layer_buffer(
        self,
        layer: str,
        width: int,
        height: int,
        content: Hashable | None = None,
        rows: Sequence[tuple[int, int]] | None = None,
    ) -> memoryview: ...

    def keep_layer(self, layer: str, width: int, height: int, content: Hashable) -> bool: ...

    def held_layer(self, layer: str, width: int, height: int) -> Hashable | None: ...

    def publish(self, frame_number: int, meta: bytes = b"") -> None: ...


def frame_layer_specs(
    width: int,
    height: int,
    ring_px: int,
    shadow_px: int = SHADOW_MAP_PX,
    layer_format: str = RGBA8,
    radar_px: int = 0,
    near_depth: bool = False,
) -> list[LayerSpec]:
    """The segment's layers: sky and near at most width x height, the current ring's 8
    images, the incoming ring's 8 while it fades in (absent otherwise), and the cloud-shadow
    map of the ring on show (`shadow_px` square; none with 0). The pictures are in
    `layer_format` (the renderer's: "rgba8" display values or "rgba16f" scene-linear); the
    shadow map, a map of transmittance rather than a picture, is RGBA8 in either; so is the
    weather radar's picture (`radar_px` square; none with 0: `[radar] layer` off), and the
    near layer's depth (`near_depth`: `[output] near_depth`; render/renderer.py
    near_depth_size, at most half the picture each way)."""
    shadow = [LayerSpec("shadow", shadow_px, shadow_px)] if shadow_px > 0 else []
    radar = [LayerSpec("radar", radar_px, radar_px)] if radar_px > 0 else []
    depth = [LayerSpec("near_depth", (width + 1) // 2, (height + 1) // 2)] if near_depth else []
    fmt = layer_format
    return [
        LayerSpec("sky", width, height, fmt),
        LayerSpec("near", width, height, fmt),
        # The near sprites in front of the host's aircraft, while it is set (absent otherwise).
        LayerSpec("near_front", width, height, fmt),
        *(LayerSpec(f"ring_{i}", ring_px, ring_px, fmt) for i in range(RING_SIZE)),
        *(LayerSpec(f"ring_in_{i}", ring_px, ring_px, fmt) for i in range(RING_SIZE)),
        *shadow,
        *depth,
        *radar,
    ]


def draw_ring(renderer: RingRenderer, plan: FramePlan) -> None:
    """The ring work of this frame: the impostor(s) the schedule asks for, into their set."""
    rings = plan.rings
    if rings.current is None:
        # Nothing built yet: the set on show is the empty ring (transparent images).
        renderer.render_ring(plan.ring, ring_set=rings.current_set)
    if rings.render and rings.render_ring is not None:
        piece = rings.render_slice
        if piece is None:
            renderer.render_ring(rings.render_ring, rings.render, rings.render_set)
        else:
            renderer.render_impostor_slice(
                rings.render_ring, piece.index, piece.start, piece.stop, rings.render_set
            )


def publish_plan(
    renderer: RingRenderer,
    sink: LayerSink,
    plan: FramePlan,
    frame_number: int,
    ring_px: int,
    export: LayerExport | None = None,
    radar: RadarShow | None = None,
    near_depth: bool = False,
) -> FrameMeta:
    """Copy the drawn layers into the slot being filled (the current ring as ring_i, the
    incoming one as ring_in_i while it fades in; `radar`, the radar picture on show, as the
    `radar` layer), write the frame record and publish. With
    `export` (a host takes zero-copy textures), each layer also goes to the slot's texture,
    finished before the publish so the seqlock covers it too."""
    rings = plan.rings
    cam = plan.frame.camera
    names: tuple[str, ...] = ("sky", "near")
    if plan.frame.near_front is not None:
        names += ("near_front",)
    if near_depth:  # the renderer draws it with `near` ([output] near_depth)
        names += ("near_depth",)
    copies: list[tuple[str, str]] = [(name, name) for name in names]
    for name in names:
        publish_layer(renderer, sink, name)
    # A complete ring's images never change while it is on show or fading in (a new ring
    # draws into the other set), so a slot that holds them from an earlier frame keeps them:
    # they are read twice per ring, once into each slot, not 2 MB every frame.
    _publish_ring(renderer, sink, copies, "ring", rings.current, rings.current_set, ring_px)
    incoming = rings.incoming if rings.fade > 0.0 else None
    if incoming is not None:
        _publish_ring(renderer, sink, copies, "ring_in", incoming, rings.incoming_set, ring_px)
    # The ring on show's shadow map, changing with it: written into each slot once per map.
    shadow = plan.ring.shadow
    placement = None
    if shadow is not None:
        map_name = ("shadow", shadow.serial)
        if not sink.keep_layer("shadow", shadow.px, shadow.px, map_name):
            buffer = sink.layer_buffer("shadow", shadow.px, shadow.px, map_name)
            np.frombuffer(buffer, np.uint8)[:] = shadow.rgba.reshape(-1)
        placement = ShadowPlacement(
            version=shadow.serial,
            # Moved on with the clouds since the map was made, so shadows stay under them.
            centre_m=shadow.centre_at(plan.state.time_utc),
            size_m=shadow.size_m,
            sun_direction_enu=shadow.sun_direction_enu,
        )
    # The radar's newest picture, made on its own thread: into each slot once per picture.
    if radar is not None:
        picture_name = ("radar", radar.version)
        if not sink.keep_layer("radar", radar.px, radar.px, picture_name):
            buffer = sink.layer_buffer("radar", radar.px, radar.px, picture_name)
            np.frombuffer(buffer, np.uint8)[:] = radar.rgba.reshape(-1)
    if export is not None:
        # After the first layer_buffer (the slot's seq is odd) and before the publish.
        for layer, source in copies:
            export.copy(layer, source)
        if shadow is not None:  # made on the CPU: uploaded, once per map and slot
            export.write("shadow", shadow.rgba.tobytes(), shadow.px, shadow.px, shadow.serial)
        if radar is not None:
            export.write("radar", radar.rgba.tobytes(), radar.px, radar.px, radar.version)
        export.finish()
    geo = plan.ring.geometry
    meta = FrameMeta(
        frame_number=frame_number,
        ring_version=plan.ring_version,
        time_utc_unix_s=plan.state.time_utc.astimezone(UTC).timestamp(),
        camera=cam,
        sun_direction_enu=plan.frame.sky.sun.direction_enu,
        ring_centre_m=geo.centre_m,
        ring_radius_m=geo.radius_m,
        ring_quads_m=geo.corners_m(),
        ring_set=rings.current_set,
        ring_fade=rings.fade if incoming is not None else 0.0,
        incoming_centre_m=incoming.geometry.centre_m if incoming else None,
        incoming_radius_m=incoming.geometry.radius_m if incoming else 0.0,
        incoming_quads_m=incoming.geometry.corners_m() if incoming else None,
        shadow=placement,
        radar=radar.placement if radar is not None else None,
    )
    sink.publish(frame_number, meta.pack())
    return meta


_ROWS = operator.itemgetter(0, 1)  # a band's rows (first, stop), without its serial


def publish_layer(renderer: RingRenderer, sink: LayerSink, name: str) -> None:
    """Layer `name` (sky, near, near_front) of the renderer into the slot being filled: read
    whole where it is drawn every frame, kept or read in part where the renderer keeps it."""
    # The near layers are smaller than the picture (Renderer.near_scale): hosts stretch.
    width, height = renderer.layer_size(name)
    bands = renderer.layer_bands(name)
    if bands is None:
        renderer.read_into(name, sink.layer_buffer(name, width, height))
        return
    # A layer the renderer kept from an earlier frame (the sky of a steady view) is kept by a
    # slot that already holds it too (3.7 MB not read at 1280x720), and of one drawn again in
    # bands (a drifting sky: a strip a frame or so), a slot that holds an earlier drawing
    # takes only the bands drawn since (0.3 of 0.7 ms of publishing a frame here).
    content = ("layer", name, bands)
    if sink.keep_layer(name, width, height, content):
        return
    held = sink.held_layer(name, width, height)
    old = held[2] if isinstance(held, tuple) and held[:2] == ("layer", name) else None
    if old is None or len(old) != len(bands) or list(map(_ROWS, old)) != list(map(_ROWS, bands)):
        renderer.read_into(name, sink.layer_buffer(name, width, height, content))
        return
    runs: list[list[int]] = []  # the bands drawn since, touching ones as one read
    for band, was in zip(bands, old, strict=True):
        if band == was:
            continue
        if runs and band[0] <= runs[-1][1]:
            runs[-1][1] = max(runs[-1][1], band[1])
        else:
            runs.append([band[0], band[1]])
    # Only those rows go on to the segment's file too (`FrameWriter.layer_buffer`'s rows).
    rows = [(first, stop) for first, stop in runs]
    buffer = sink.layer_buffer(name, width, height, content, rows)
    for first, stop in rows:
        renderer.read_into(name, buffer, (first, stop))


def _publish_ring(
    renderer: RingRenderer,
    sink: LayerSink,
    copies: list[tuple[str, str]],
    prefix: str,
    ring: RingScene | None,
    ring_set: int,
    ring_px: int,
) -> None:
    """The 8 images of `ring` (None: the empty ring drawn before the first, read every
    frame) from texture set `ring_set` into layers prefix_0..7 of the slot being filled."""
    pairs = _ring_layers(prefix, ring_set)
    copies.extend(pairs)
    for i, (layer, source) in enumerate(pairs):
        content = None if ring is None else ("ring", ring.serial, ring_set, i)
        if content is not None and sink.keep_layer(layer, ring_px, ring_px, content):
            continue
        renderer.read_into(source, sink.layer_buffer(layer, ring_px, ring_px, content))


@functools.lru_cache(maxsize=8)
def _ring_layers(prefix: str, ring_set: int) -> tuple[tuple[str, str], ...]:
    """(slot layer, renderer target) of each impostor of a ring set: named every frame."""
    return tuple((f"{prefix}_{i}", ring_target_name(i, ring_set)) for i in range(RING_SIZE))
