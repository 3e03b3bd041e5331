"""One-shot render: the daemon's stages and the reference host's compositing, in one process.

`wxsky snapshot` and the daemon share everything from the weather state to the composited
picture: the same engine plan, the same renderer passes, the same compositor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.engine import SkyEngine
from wxsky.host.compositor import composite, layers_from_images
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.scene.ring import RING_SIZE
from wxsky.weather.state import WeatherState

LAYER_NAMES: tuple[str, ...] = ("sky", "near", *(f"ring_{i}" for i in range(RING_SIZE)))

U8 = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class Snapshot:
    image: U8  # (H, W, 4) composited, opaque
    layers: dict[str, U8]  # raw premultiplied layers by name (LAYER_NAMES)
    ring_quads_m: npt.NDArray[np.float64]  # (8, 4, 3)


def take_snapshot(
    state: WeatherState,
    camera: Camera,
    settings: SceneSettings,
    renderer: Renderer | None = None,
) -> Snapshot:
    plan = SkyEngine(state, camera, settings, clock_rate=0.0).advance(0.0)
    own = renderer is None
    r = renderer if renderer is not None else Renderer(settings.ring_texture_px)
    try:
        r.render_ring(plan.ring)
        r.render_frame(plan.frame)
        images = {name: r.read(name) for name in LAYER_NAMES}
    finally:
        if own:
            r.close()
    quads = plan.ring.geometry.corners_m()
    return Snapshot(
        image=composite(layers_from_images(images, quads), camera),
        layers=images,
        ring_quads_m=quads,
    )
