"""The weather radar as a segment layer (issue 43, item 5; `[radar] layer = true`): the
pictures a host reads from the segment and the stream, made off the frame path, holding the
storm's cells where its towers stand."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from wxsky.app.frame_publish import frame_layer_specs
from wxsky.output.frame_meta import FrameMeta
from wxsky.scene.clouds import BLOCK_SIZE_M, layer_keys
from wxsky.scene.convection import tower_specs
from wxsky.scene.formation import layer_block
from wxsky.scene.radar import radar_picture
from wxsky.scene.rain import rain_of
from wxsky.settings.presets import load_preset
from wxsky.weather.state import CloudType, WeatherState

RADAR_CONFIG = """
[clock]
rate = 0.0
[radar]
layer = true
range_nm = 20.0
size_px = 128
every_s = 0.5
"""


def test_the_layer_is_in_the_segment_only_when_asked_for() -> None:
    names = [s.name for s in frame_layer_specs(960, 540, 512)]
    assert "radar" not in names
    specs = {s.name: s for s in frame_layer_specs(960, 540, 512, radar_px=256)}
    assert (specs["radar"].max_width, specs["radar"].max_height) == (256, 256)
    assert specs["radar"].format == "rgba8"  # a map of bytes, as the shadow's, in either format


def _storm_towers(state: WeatherState, reach_m: float) -> np.ndarray:
    """Where the cumulonimbus layer's towers stand (no drift: the clock stands still)."""
    index = next(i for i, lay in enumerate(state.layers) if lay.type == CloudType.CUMULONIMBUS)
    layer, key = state.layers[index], layer_keys(state.layers)[index]
    n = math.ceil(reach_m / BLOCK_SIZE_M)
    out = []
    for bx in range(-n - 1, n + 1):
        for by in range(-n - 1, n + 1):
            sprites = layer_block(bx, by, key, layer, state.seed, (0.0, 0.0), rain=rain_of(state))
            if len(sprites):
                out += [s.axis_m for s in tower_specs(state, layer, (bx, by), sprites, 45.0)]
    return np.asarray(out)


@pytest.mark.gl
def test_the_daemon_publishes_radar_pictures_in_the_segment_and_the_stream(
    tmp_path: Path,
) -> None:
    """With `[radar] layer = true`: a `radar` notification with the first frame whose slot
    holds the picture, the layer's R channel the notification's bytes, the record's placement
    the camera's; its cells of 30 dBZ or more lie within 2 km of the thunderstorm's towers;
    frames go on being published while pictures are made."""
    from daemon_harness import HANG_S, running_daemon

    from wxsky.output.shm import FrameReader

    with (
        running_daemon(tmp_path, RADAR_CONFIG, args=("--preset", "thunderstorm")) as d,
        d.client() as c,
    ):
        assert "radar" in c.call("scene")["layers"]
        c.subscribe(["radar"])
        notes: dict[int, dict] = {}
        deadline = time.monotonic() + HANG_S
        with FrameReader.open(d.shm_name) as reader:
            while True:
                assert time.monotonic() < deadline, "no radar picture in the segment"
                note = c.next_notification(timeout_s=0.05)
                if note is not None and note.method == "radar":
                    notes[note.params["version"]] = note.params
                frame = reader.read(timeout_s=HANG_S)
                meta = FrameMeta.unpack(frame.meta)
                if meta.radar is not None and meta.radar.version in notes:
                    break
            first = notes[meta.radar.version]
            assert frame.frame_number >= first["frame_number"]
            layer = frame.layers["radar"]
            assert layer.shape == (128, 128, 4)
            codes = np.frombuffer(first["pixels"], np.uint8).reshape(128, 128)
            assert np.array_equal(layer[..., 0], codes)
            assert np.array_equal(layer[..., 1], codes) and (layer[..., 3] == 255).all()
            assert (first["range_nm"], first["tilt_deg"], first["size_px"]) == (20.0, 0.0, 128)
            assert (meta.radar.range_nm, meta.radar.tilt_deg) == (20.0, 0.0)
            assert meta.radar.centre_m == tuple(first["centre_m"]) == meta.camera.position_m
            before = c.call("status")["frames_published"]
            while c.call("status")["frames_published"] <= before + 5:
                assert time.monotonic() < deadline, "no frames published while the radar worked"
                time.sleep(0.05)
    # The very picture `scene.radar` makes of the daemon's sky (the clock stands still: no
    # drift), whose cells lie on the towers (test_radar.test_the_radar_cells_lie_on_the_towers).
    state = WeatherState().apply(load_preset("thunderstorm"))
    drift = [(0.0, 0.0)] * len(state.layers)
    pic = radar_picture(state, drift, meta.radar.centre_m, 20.0, 0.0, 128)
    assert np.array_equal(codes, np.frombuffer(pic.to_bytes(), np.uint8).reshape(128, 128))
    dbz = codes * first["dbz_step"] + first["dbz_offset"]
    assert float(dbz.max()) >= 40.0 and float(dbz.min()) < 5.0  # the storm's cores, clear air
    # Its cells of 30 dBZ or more peak within 2 km of a cumulonimbus tower's centre.
    range_m = 20.0 * 1852.0
    towers = _storm_towers(state, range_m + 8000.0)
    n, centre = 128, meta.radar.centre_m
    pixel_m = 2.0 * range_m / n
    xs = centre[0] - range_m + (np.arange(n) + 0.5) * pixel_m
    ys = centre[1] + range_m - (np.arange(n) + 0.5) * pixel_m
    gx, gy = np.meshgrid(xs, ys)
    to_tower = np.min(np.hypot(gx[..., None] - towers[:, 0], gy[..., None] - towers[:, 1]), axis=-1)
    pad = np.pad(dbz, 1, constant_values=-32.0)
    peak = (dbz >= 30.0) & np.all(
        [
            dbz >= pad[1 + dy : 1 + dy + n, 1 + dx : 1 + dx + n]
            for dy in (-1, 0, 1)
            for dx in (-1, 0, 1)
        ],
        axis=0,
    )
    assert peak.any()
    # Within 2 km, and the half diagonal of a pixel (410 m) the picture's grid adds.
    assert float(to_tower[peak].max()) <= 2000.0 + pixel_m / math.sqrt(2.0)
