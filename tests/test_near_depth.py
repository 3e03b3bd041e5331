"""The distance inside which a frame's near layer holds nothing (scene/near_depth.py), which a
host with its own geometry composites the layer at (plugins/osg, `wxsky_gl_draw_near_at`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from wxsky.engine.stages import SkyEngine
from wxsky.render.renderer import NEAR_DEPTH_LOG2_RANGE, Renderer, near_depth_size
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.scene.near_depth import near_distance_m
from wxsky.weather.state import CloudLayer, CloudType, WeatherState


def _frame(state: WeatherState, alt_m: float):  # type: ignore[no-untyped-def]
    cam = Camera((0.0, 0.0, alt_m), pitch_deg=10.0, width_px=320, height_px=180)
    with SkyEngine(state, cam, SceneSettings(), clock_rate=0.0) as engine:
        return engine.advance(0.0).frame


def _cumulus(base_m: float) -> WeatherState:
    layer = CloudLayer(4, base_m, base_m + 1500.0, CloudType.CUMULUS)
    return dataclasses.replace(WeatherState(), layers=(layer,))


def test_below_a_cumulus_layer_it_is_a_bound_on_the_nearest_sprite() -> None:
    frame = _frame(_cumulus(1500.0), 300.0)
    d = near_distance_m(frame)
    assert d is not None
    batch = frame.near.sprites
    eye = np.array(frame.camera.position_m)
    reach = np.linalg.norm(batch.centre_m - eye, axis=1)
    half = batch.size_m.astype(np.float64) * math.sqrt(0.5)
    # never farther than any sprite's nearest point, and no looser than the largest sprite
    assert d <= float((reach - half).min()) + 1e-6
    assert d >= float((reach - half.max()).min()) - 1e-6
    # the clouds are above the eye: nothing of them within the gap to the base, less a sprite
    assert d > 0.0 and d > 1200.0 - float(half.max())


def test_inside_cloud_it_is_zero_and_in_clear_air_there_is_nothing() -> None:
    overcast = dataclasses.replace(
        WeatherState(), layers=(CloudLayer(8, 800.0, 1600.0, CloudType.STRATUS),)
    )
    inside = _frame(overcast, 1200.0)
    assert inside.in_cloud.inside
    assert near_distance_m(inside) == 0.0
    clear = _frame(dataclasses.replace(WeatherState(), layers=()), 1000.0)
    assert len(clear.near) == 0
    assert near_distance_m(clear) is None


def test_the_near_depth_layer_holds_each_pixels_nearest_cloud() -> None:
    """The renderer's `near_depth` layer (near_depth.glsl's encoding): where the near layer
    shows a cloud the layer holds a distance, between the frame's near_distance_m and the
    farthest sprite's reach; where it shows nothing, nothing; nearer rows (higher, under an
    overcast) nearer clouds."""
    state = dataclasses.replace(
        WeatherState(), layers=(CloudLayer(8, 830.0, 1500.0, CloudType.STRATUS),)
    )
    frame = _frame(state, 300.0)
    with Renderer(256, near_depth=True) as r:
        r.render_frame(frame)
        near = r.read("near")
        w, h = r.layer_size("near_depth")
        assert (w, h) == near_depth_size(r.layer_size("near"))
        buf = bytearray(w * h * 4)
        r.read_into("near_depth", memoryview(buf))
    px = np.frombuffer(bytes(buf), np.uint8).reshape(h, w, 4).astype(np.int64)
    held = px[..., 3] == 255
    assert set(np.unique(px[..., 3])) <= {0, 255}
    q = ((px[..., 0] << 16) | (px[..., 1] << 8) | px[..., 2]) / 16777215.0
    d = np.exp2(q * NEAR_DEPTH_LOG2_RANGE) - 1.0
    # the near layer at the depth layer's texel centres
    ys = ((np.arange(h) + 0.5) * near.shape[0] / h).astype(int)
    xs = ((np.arange(w) + 0.5) * near.shape[1] / w).astype(int)
    shown = near[ys][:, xs, 3] >= 8
    assert shown.any() and held.any()
    assert float((held == shown)[shown | held].mean()) > 0.9
    floor = near_distance_m(frame)
    assert floor is not None
    batch = frame.near.sprites
    reach = np.linalg.norm(batch.centre_m - np.array(frame.camera.position_m), axis=1)
    top = float((reach + batch.size_m).max())
    assert float(d[held].min()) >= floor - 1.0
    assert float(d[held].max()) <= top
    # under the deck, looking out: the rows toward the horizon hold farther cloud
    rows = [float(np.median(d[y][held[y]])) for y in range(h) if held[y].sum() > w // 2]
    assert len(rows) >= 3 and rows[-1] > rows[0]
