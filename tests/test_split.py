"""Impostor splitting (Harris 3.2): with the host's aircraft set, the near layer is split at
its distance into sprites behind it and in front of it; drawn one over the other the two
layers are the unsplit picture, so a host that draws nothing between loses nothing."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
from daemon_harness import HANG_S, running_daemon

from wxsky.app.snapshot import LAYER_NAMES
from wxsky.host.client import RemoteError
from wxsky.host.compositor import composite, layers_from_images
from wxsky.host.reference import ReferenceHost
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.clouds import BLOCK_SIZE_M
from wxsky.scene.gather import NearRing, zero_drift
from wxsky.scene.layout import SceneSettings, build_frame, empty_ring, split_at_distance
from wxsky.scene.sky import sky_params
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

STATE = WeatherState().apply(load_preset("scattered-cumulus", ()))
EYE = (0.0, 0.0, STATE.observer.alt_m + 2.0)
CAMERA = Camera(position_m=EYE, heading_deg=200.0, pitch_deg=20.0, width_px=160, height_px=90)


def _frame(split_at: tuple[float, float, float] | None) -> object:
    drift = zero_drift(STATE)
    return build_frame(
        STATE,
        drift,
        CAMERA,
        (NearRing(EYE, drift, 1.0),),
        sky_params(STATE),
        SceneSettings(),
        split_at_m=split_at,
    )


def test_the_split_puts_each_sprite_on_its_side_and_loses_none() -> None:
    whole = _frame(None).near  # type: ignore[attr-defined]
    behind, front = split_at_distance(whole, EYE, 4000.0)
    d_behind = np.linalg.norm(behind.sprites.centre_m - np.asarray(EYE), axis=1)
    d_front = np.linalg.norm(front.sprites.centre_m - np.asarray(EYE), axis=1)
    assert len(behind) and len(front) and len(behind) + len(front) == len(whole)
    assert d_behind.min() >= 4000.0 > d_front.max()
    np.testing.assert_array_equal(np.concatenate([behind.rgba, front.rgba]), whole.rgba)


def test_build_frame_splits_at_the_aircraft_distance() -> None:
    aircraft = (3000.0, -4000.0, EYE[2] + 800.0)
    frame = _frame(aircraft)
    assert frame.split_distance_m == pytest.approx(math.dist(aircraft, EYE))  # type: ignore[attr-defined]
    assert frame.near_front is not None and len(frame.near_front)  # type: ignore[attr-defined]
    assert _frame(None).near_front is None  # type: ignore[attr-defined]


@pytest.mark.gl
def test_the_two_layers_composite_to_the_unsplit_picture(renderer: Renderer) -> None:
    def picture(split_at: tuple[float, float, float] | None) -> tuple[np.ndarray, dict]:
        frame = _frame(split_at)
        renderer.render_frame(frame)  # type: ignore[arg-type]
        names = [n for n in ("sky", "near", "near_front") if n != "near_front" or split_at]
        images = {n: renderer.read(n) for n in names}
        empty = np.zeros((renderer.ring_px, renderer.ring_px, 4), np.uint8)
        images.update({n: empty for n in LAYER_NAMES if n.startswith("ring_")})
        quads = empty_ring(EYE, 8000.0, zero_drift(STATE)).geometry.corners_m()
        return composite(layers_from_images(images, quads), CAMERA), images

    aircraft = (0.0, -5000.0, EYE[2] + 1200.0)
    old_scale = renderer.near_scale
    try:
        # At full size the split is exact but for rounding each layer to 8 bits ...
        renderer.near_scale = 1.0
        whole, _ = picture(None)
        split, images = picture(aircraft)
        assert images["near_front"][..., 3].any() and images["near"][..., 3].any()
        diff = np.abs(whole.astype(int) - split.astype(int))
        assert diff.max() <= 3, f"max diff {diff.max()}"  # three roundings to 8 bits
    finally:
        renderer.near_scale = old_scale
    # ... and at the daemon's reduced size, upsampled layer by layer, nearly so.
    diff = np.abs(picture(None)[0].astype(int) - picture(aircraft)[0].astype(int))
    assert diff.mean() < 0.2 and diff.max() <= 10, (diff.mean(), diff.max())


@pytest.mark.gl
def test_a_host_gets_the_front_layer_after_set_aircraft(tmp_path: Path) -> None:
    with running_daemon(tmp_path) as d, ReferenceHost.connect(d.address) as host:
        with pytest.raises(RemoteError, match=r"set_aircraft: position_m: must be \[east_m"):
            host.call("set_aircraft", {"position_m": [1.0, 2.0]})
        with pytest.raises(
            RemoteError, match=r"position_m\[2\]: must be a number in -1000..100000, got 10000000.0"
        ):
            host.call("set_aircraft", {"position_m": [1.0, 2.0, 1e7]})
        with pytest.raises(RemoteError, match="set_aircraft: speed: unknown key"):
            host.call("set_aircraft", {"position_m": None, "speed": 3})
        cam = host.call("status")["camera"]
        ahead = [cam["position_m"][0], cam["position_m"][1] - 3000.0, cam["position_m"][2] + 500]
        assert host.call("set_aircraft", {"position_m": ahead})["position_m"] == ahead
        frame = host.wait_frame(host.reader.frame_number + 2, timeout_s=HANG_S)
        assert frame.layers.near_front is not None
        assert frame.layers.near_front.shape == frame.layers.near.shape
        host.call("set_aircraft", {"position_m": None})
        frame = host.wait_frame(host.reader.frame_number + 2, timeout_s=HANG_S)
        assert frame.layers.near_front is None


@pytest.mark.gl
def test_run_trace_records_the_daemons_ring_cycle(tmp_path: Path) -> None:
    trace = tmp_path / "ring.jsonl"
    extra = "[scene]\nring_fade_s = 0.2\n"
    with running_daemon(tmp_path, extra_config=extra, args=("--trace", str(trace))) as d:
        deadline = time.monotonic() + HANG_S
        while time.monotonic() < deadline:
            text = trace.read_text() if trace.exists() else ""
            if "crossfade_done" in text:
                break
            time.sleep(0.1)
        with d.client() as c:
            scene = c.call("scene")
        assert scene["ring"] is not None  # the first ring is on show
        assert scene["block_size_m"] == BLOCK_SIZE_M
        assert -90.0 <= scene["sky"]["sun_elevation_deg"] <= 90.0
    lines = [json.loads(line) for line in trace.read_text().splitlines()]
    events = [line["event"] for line in lines]
    assert events[0] == "ring_rebuild_start" and lines[0]["reason"] == "initial"
    rendered = [line for line in lines if line["event"] == "impostor_rendered"]
    assert [line["index"] for line in rendered[:8]] == list(range(8))
    # Sliced like every rebuild: each impostor completes in a later frame than the last.
    frames = [line["frame"] for line in rendered[:8]]
    assert frames == sorted(set(frames))
    assert events.index("ring_rebuild_done") < events.index("crossfade_start")
    assert events.index("crossfade_start") < events.index("crossfade_done")
    assert all(len(line["camera_m"]) == 3 for line in lines)
