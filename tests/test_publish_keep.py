"""The ring's images kept in a shared-memory slot from frame to frame (`publish_plan` with
`FrameWriter.keep_layer`): a host reading the real segment must see, in every frame, exactly
the images of the texture sets on show, across ring rebuilds, cross-fades and the alternating
slots, while the images are read from the renderer only when a slot does not hold them. The
sky layer, which the renderer keeps while nothing it shows moves, is kept the same way."""

from __future__ import annotations

import dataclasses
import uuid
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from wxsky.app.camera_path import straight_and_level
from wxsky.app.frame_publish import draw_ring, frame_layer_specs, publish_layer, publish_plan
from wxsky.engine.stages import SkyEngine
from wxsky.output.shm import FrameReader, FrameWriter
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.layout import FrameScene, RingScene, SceneSettings, SpriteDraw
from wxsky.scene.ring import RING_SIZE, ring_target_name
from wxsky.scene.sky import sky_params
from wxsky.scene.sprites import SpriteBatch
from wxsky.settings.presets import load_preset
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

NO_SPRITES = SpriteDraw(SpriteBatch.empty(), np.zeros((0, 4), np.float32))
PX = 8  # ring images: small, each filled with one value per drawing
SIZE = (16, 8)


class FakeRenderer:
    """Texture contents as the renderer would hold them: each drawing of a ring image fills
    it with a value of its own, so a stale copy in a slot shows."""

    def __init__(self) -> None:
        self.images: dict[str, bytes] = {}
        self.drawings = 0
        self.reads: list[str] = []
        self.sky_version = 0  # the sky is kept for a few frames, then drawn again

    def draw_sky(self, frame: int) -> None:
        if frame % 7 == 0:
            self.sky_version += 1
            self.images["sky"] = (self.sky_version % 251 + 1).to_bytes(1, "little") * (
                SIZE[0] * SIZE[1] * 4
            )

    def layer_bands(self, name: str) -> tuple[tuple[int, int, int], ...] | None:
        return ((0, SIZE[1], self.sky_version),) if name == "sky" else None

    def _draw(self, name: str, px: int) -> None:
        self.drawings += 1
        self.images[name] = (self.drawings % 251 + 1).to_bytes(1, "little") * (px * px * 4)

    def render_ring(
        self,
        ring: RingScene,
        indices: range | list[int] | tuple[int, ...] | None = None,
        ring_set: int = 0,
    ) -> None:
        for i in indices if indices is not None else range(RING_SIZE):
            self._draw(ring_target_name(i, ring_set), PX)

    def render_impostor_slice(
        self, ring: RingScene, index: int, start: int, stop: int, ring_set: int
    ) -> None:
        self._draw(ring_target_name(index, ring_set), PX)

    def layer_size(self, name: str) -> tuple[int, int]:
        return SIZE

    def read_into(self, name: str, buffer: memoryview, rows: tuple[int, int] | None = None) -> None:
        assert rows in (None, (0, SIZE[1]))  # one band: read whole or kept
        self.reads.append(name)
        data = self.images.get(name, bytes(len(buffer)))
        buffer[:] = data[: len(buffer)]


@pytest.mark.parametrize(
    ("build", "fade_s"),
    # A fade seen by both slots, one seen by one slot only, and rebuilds drawn whole into
    # set 0 every time (snapshots' "immediate"): the set alone does not name the images.
    [("sync", 0.1), ("sync", 0.05), ("immediate", 0.0)],
)
def test_a_host_sees_the_sets_and_sky_on_show_in_every_frame_while_kept_ones_are_not_read(
    build: str, fade_s: float
) -> None:
    state = WeatherState(layers=(CloudLayer(3.0, 2500.0, 3000.0, CloudType.CUMULUS),), wind=())
    settings = SceneSettings(ring_texture_px=PX, shadow_map_px=0)
    path = straight_and_level(speed_mps=1500.0, alt_m=1500.0)
    renderer = FakeRenderer()
    name = f"wxsky-keep-{uuid.uuid4().hex[:10]}"
    specs = frame_layer_specs(*SIZE, PX, 0)
    frames = 0
    reads_when_steady = []
    fades = rebuilds = 0
    with (
        FrameWriter.create(name, specs) as writer,
        FrameReader.open(name) as reader,
        SkyEngine(
            state, Camera((0.0, 0.0, 1500.0)), settings, ring_build=build, ring_fade_s=fade_s
        ) as engine,
    ):
        for k in range(90):
            pose = path.at(k / 30.0)
            engine.set_camera(Camera(pose.position_m, pose.heading_deg, pose.pitch_deg))
            plan = engine.advance(1.0 / 30.0 if k else 0.0)
            draw_ring(renderer, plan)
            renderer.draw_sky(k)
            renderer.reads.clear()
            publish_plan(renderer, writer, plan, k + 1, PX)
            frame = reader.read()
            frames += 1
            assert frame.layers["sky"].tobytes() == renderer.images["sky"]
            # The sky is read into each slot once per drawing of it: in its first two frames.
            assert ("sky" in renderer.reads) == (k % 7 < 2)
            rings = plan.rings
            for i in range(RING_SIZE):
                want = renderer.images.get(ring_target_name(i, rings.current_set), b"")
                assert frame.layers[f"ring_{i}"].tobytes() == want.ljust(PX * PX * 4, b"\0")
            if rings.fade > 0.0:
                fades += 1
                for i in range(RING_SIZE):
                    want = renderer.images[ring_target_name(i, rings.incoming_set)]
                    assert frame.layers[f"ring_in_{i}"].tobytes() == want
            else:
                assert frame.layers["ring_in_0"].size == 0
            rebuilds += sum(e.event == "ring_rebuild_start" for e in plan.events)
            if rings.current is not None and rings.fade == 0.0 and not rings.render:
                reads_when_steady.append([r for r in renderer.reads if r.startswith("ring")])
    assert frames == 90 and rebuilds >= 3 and (fades > 0) == (build != "immediate")
    # Between rebuilds, after one frame in each slot, no ring image is read again.
    assert (
        reads_when_steady
        and sum(1 for r in reads_when_steady if not r) > len(reads_when_steady) // 2
    )


def test_a_layer_written_again_is_not_kept_and_each_slot_keeps_only_its_own() -> None:
    name = f"wxsky-keep-{uuid.uuid4().hex[:10]}"
    specs = frame_layer_specs(*SIZE, PX, 0)
    with FrameWriter.create(name, specs) as writer, FrameReader.open(name) as reader:
        assert not writer.keep_layer("ring_0", PX, PX, "a")
        np.frombuffer(writer.layer_buffer("ring_0", PX, PX, "a"), np.uint8)[:] = 1
        writer.publish(1)
        # The other slot does not hold it yet.
        assert not writer.keep_layer("ring_0", PX, PX, "a")
        np.frombuffer(writer.layer_buffer("ring_0", PX, PX, "a"), np.uint8)[:] = 1
        writer.publish(2)
        assert writer.keep_layer("ring_0", PX, PX, "a")
        writer.publish(3)
        assert reader.read().layers["ring_0"].min() == 1
        assert not writer.keep_layer("ring_0", PX, PX, "b")  # other content
        assert not writer.keep_layer("ring_0", PX // 2, PX // 2, "a")  # other size
        # Written under no name: the slot no longer holds "a".
        np.frombuffer(writer.layer_buffer("ring_0", PX, PX), np.uint8)[:] = 2
        writer.publish(4)
        assert reader.read().layers["ring_0"].min() == 2
        assert writer.keep_layer("ring_0", PX, PX, "a")  # slot of frame 3, untouched since
        writer.publish(5)
        assert not writer.keep_layer("ring_0", PX, PX, "a")
        # A layer not kept nor written is absent, as before.
        writer.publish(6)
        assert reader.read().layers["ring_0"].size == 0


class CountingReads:
    """The real renderer, counting the rows each read copies (publish_layer's reads)."""

    def __init__(self, renderer: Renderer) -> None:
        self.renderer = renderer
        self.rows = 0

    def layer_size(self, name: str) -> tuple[int, int]:
        return self.renderer.layer_size(name)

    def layer_bands(self, name: str) -> tuple[tuple[int, int, int], ...] | None:
        return self.renderer.layer_bands(name)

    def read_into(self, name: str, buffer: memoryview, rows: tuple[int, int] | None = None) -> None:
        first, stop = (0, self.layer_size(name)[1]) if rows is None else rows
        self.rows += stop - first
        self.renderer.read_into(name, buffer, rows)


@pytest.mark.parametrize("height_px", [360, 357])  # strips of whole rows, and not
def test_a_drifting_sky_is_published_exactly_while_only_its_redrawn_strips_are_read(
    renderer: Renderer, height_px: int
) -> None:
    """The dome's band above the horizon drifts with the wind and the sun moves, so the
    renderer draws a strip or so of the sky layer again every frame or two: every frame a
    host reads from either slot must be the layer to the byte, while a slot holding an
    earlier drawing reads only the strips drawn since (rows counted from the real reads)."""
    state = WeatherState().apply(load_preset("fair-cumulus"))
    state = dataclasses.replace(state, time_utc=datetime(2026, 6, 21, 13, 0, tzinfo=UTC))
    cam = Camera(
        position_m=(0.0, 0.0, 1500.0),
        heading_deg=90.0,
        pitch_deg=0.0,
        width_px=640,
        height_px=height_px,
    )
    counting = CountingReads(renderer)
    name = f"wxsky-keep-{uuid.uuid4().hex[:10]}"
    specs = frame_layer_specs(640, height_px, PX, 0)
    partial = 0
    with FrameWriter.create(name, specs) as writer, FrameReader.open(name) as reader:
        for k in range(60):
            moment = state.time_utc + timedelta(seconds=k / 30.0)
            sky = sky_params(dataclasses.replace(state, time_utc=moment))
            if k == 40:  # a turn: the layer is drawn whole, and read whole into each slot
                cam = dataclasses.replace(cam, heading_deg=cam.heading_deg + 1.0)
            renderer.render_frame(FrameScene(cam, sky, NO_SPRITES))
            before = counting.rows
            publish_layer(counting, writer, "sky")
            writer.publish(k + 1)
            read = counting.rows - before
            partial += 0 < read < height_px
            got = reader.read().layers["sky"]
            assert got.shape == (height_px, 640, 4)
            assert np.array_equal(got, renderer.read("sky")), f"frame {k}"
            if k in (40, 41):
                assert read == height_px
    # Most frames read a strip or two, not the layer (a frame with nothing drawn reads none).
    assert partial > 20
    assert counting.rows < 0.5 * 60 * height_px
