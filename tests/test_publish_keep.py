"""The ring's images kept in a shared-memory slot from frame to frame (`publish_plan` with
`FrameWriter.keep_layer`): a host reading the real segment must see, in every frame, exactly
the images of the texture sets on show, across ring rebuilds, cross-fades and the alternating
slots, while the images are read from the renderer only when a slot does not hold them. The
sky layer, which the renderer keeps while nothing it shows moves, is kept the same way."""

from __future__ import annotations

import uuid

import numpy as np
import pytest

from wxsky.app.camera_path import straight_and_level
from wxsky.app.frame_publish import draw_ring, frame_layer_specs, publish_plan
from wxsky.engine.stages import SkyEngine
from wxsky.output.shm import FrameReader, FrameWriter
from wxsky.scene.camera import Camera
from wxsky.scene.layout import RingScene, SceneSettings
from wxsky.scene.ring import RING_SIZE, ring_target_name
from wxsky.weather.state import CloudLayer, CloudType, WeatherState

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

    def layer_version(self, name: str) -> int | None:
        return self.sky_version if name == "sky" else None

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

    def read_into(self, name: str, buffer: memoryview) -> None:
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
