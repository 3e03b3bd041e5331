"""`wxsky bench` end to end on the real renderer and a real shared-memory segment: stage
timings per frame, the ring's events and trace, direct mode drawing every cloud."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from wxsky.app.bench import CPU_STAGES, STAGES, run_bench
from wxsky.app.camera_path import straight_and_level
from wxsky.app.trace import TraceWriter
from wxsky.cli import main
from wxsky.scene.layout import SceneSettings
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

STATE = WeatherState().apply(load_preset("scattered-cumulus", ()))
SETTINGS = SceneSettings(ring_texture_px=64, max_range_m=20_000.0)


# Frames enough for the first ring's 8 impostors, sliced by a budget of wall time a frame:
# beside stress-ng and the other worker's tests, 80 frames held only 6 of them.
FRAMES = 240


@pytest.mark.gl
def test_ring_mode_times_every_stage_and_traces_the_ring(tmp_path: Path) -> None:
    trace_path = tmp_path / "trace.jsonl"
    with TraceWriter(trace_path) as trace:
        result = run_bench(
            STATE,
            SETTINGS,
            straight_and_level(),
            FRAMES,
            "ring",
            (96, 54),
            preset="scattered-cumulus",
            ring_fade_s=0.1,
            trace=trace,
            # Built in the frame that needs it, so the frames surely hold the whole ring
            # (in a worker process below the frames' priority, it may not be ready in them).
            ring_build="sync",
            lead_in=False,  # the first ring's events are what this test reads
        )
    assert result.frames == FRAMES
    for name in STAGES:
        assert len(result.stage_s[name]) == FRAMES and min(result.stage_s[name]) >= 0.0
    assert all(f > 0.0 for f in result.frame_s)
    # The first ring: started at frame 1, its 8 impostors one after the other.
    lines = [json.loads(line) for line in trace_path.read_text().splitlines()]
    assert lines[0]["event"] == "ring_rebuild_start" and lines[0]["reason"] == "initial"
    assert all({"frame", "event", "camera_m"} <= set(line) for line in lines)
    rendered = [line for line in lines if line["event"] == "impostor_rendered"]
    assert [line["index"] for line in rendered] == list(range(8))
    # Sliced like every rebuild (tests/test_ring_schedule.py): each impostor completes in
    # a frame of its own, after its slices.
    frames = [line["frame"] for line in rendered]
    assert frames == sorted(set(frames))
    assert all(line["slices"] >= 1 for line in rendered)
    assert result.events["ring_rebuild_start"] == 1 and result.build_s
    d = result.to_dict()
    assert set(d["stages_ms"]) == set(STAGES) and d["frames"] == FRAMES
    assert "impostor_slice" in result.table()
    # The CPU stages' own CPU: some in every frame, never more than the wall time they took
    # (one thread), give or take the clocks' grain.
    walls = [sum(f) for f in zip(*(result.stage_s[n] for n in CPU_STAGES), strict=True)]
    assert len(result.cpu_stages_s) == FRAMES and all(c > 0.0 for c in result.cpu_stages_s)
    assert all(c <= w + 1e-3 for c, w in zip(result.cpu_stages_s, walls, strict=True))
    assert d["cpu_stages_ms"]["thread_cpu"]["median"] > 0.0
    assert "frame thread's CPU" in result.table()


@pytest.mark.gl
def test_direct_mode_draws_every_cloud_as_a_sprite() -> None:
    args = (STATE, SETTINGS, straight_and_level(), 3)
    direct = run_bench(*args, "direct", (96, 54))
    ring = run_bench(*args, "ring", (96, 54))
    # Direct mode has no lead-in: its first frame may be drawn before every cloud's block is
    # gathered off the frame path (beside `stress-ng --cpu 2`: 4377 sprites, then 4919), so
    # its fullest frame is the one that shows every cloud. The ring's near layer is the
    # clouds within its 8 km of 20 (a sixth of the area: idle 971 sprites against 5109);
    # beside `stress-ng --cpu 2` the lead-in takes 96 s, the camera flies 11 km on from the
    # first ring's centre and the near layer reaches farther until the next ring is in
    # (1759), so the margin is twice, which leaving the far clouds out would never reach.
    assert max(direct.sprites) > 2 * max(ring.sprites)
    assert not direct.events and direct.lead_in_frames == 0  # no ring at all
    # The ring's timed frames came after its lead-in, which built, drew and faded in the
    # first ring: none of its events is in them.
    assert ring.lead_in_frames > 1 and "ring_rebuild_start" not in ring.events


@pytest.mark.gl
def test_the_command_prints_json(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = tmp_path / "path.csv"
    path.write_text("0, 0, 0, 1500, 45, 5\n1, 100, 100, 1500, 45, 5\n")
    code = main(
        ["bench", "--preset", "clear", "--frames", "3", "--size", "64x36", "--json",
         "--camera-path", str(path)]
    )  # fmt: skip
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frames"] == 3 and out["size"] == [64, 36] and out["path"] == str(path)
    assert out["lead_in_frames"] > 1 and out["ring_events"].get("crossfade_done", 0) == 0


@pytest.mark.gl
def test_profile_counts_every_pass_and_its_pixels(capsys: pytest.CaptureFixture[str]) -> None:
    result = run_bench(
        STATE,
        SETTINGS,
        straight_and_level(),
        20,
        "ring",
        (96, 54),
        profile=True,
        ring_fade_s=0.1,
        ring_slice_ms=None,  # one whole impostor a frame
        ring_build="sync",  # from the first frame on, however busy the machine
        lead_in=False,  # the first ring's impostors are the passes counted
        # Half a second a frame: the sun's azimuth (1.5e-4 rad/s at this noon) turns by the
        # kept physical sky's tolerance (sky_layer.FLAT_SUN_TOLERANCE_RAD) in 13 frames, so
        # these 20 frames draw some of its strips again.
        fps=2.0,
    )
    rows = {r["pass"]: r for r in result.passes}
    # The sky writes every pixel when it is drawn, which a steady view does only when the
    # sun has moved enough; the near layer is the host's to stretch.
    # (The first frame's whole sky is drawn at startup: `Renderer.warm_up`.) The layer is
    # kept in strips (SKY_STRIPS, under two rows each at this height), and a call draws a run
    # of them: a row at least, and less than the layer.
    assert 0.0 < rows["sky"]["calls_per_frame"] < 1.0
    assert 96 / 1e6 <= rows["sky"]["mpix_per_call"] < 96 * 54 / 1e6
    assert "upsample near" not in rows
    # Eight impostors in twenty frames (one with no cloud in it would draw nothing); the layer
    # seen edge-on is drawn with fewer rows and stretched to its 64 x 64 texels.
    assert rows["impostor"]["calls_per_frame"] == pytest.approx(0.4)
    assert rows["impostor"]["mpix_per_call"] > 0.0
    stretch = rows["upsample impostor"]
    assert stretch["calls_per_frame"] == rows["impostor"]["calls_per_frame"]
    assert stretch["mpix_per_call"] == pytest.approx(64 * 64 / 1e6)
    assert set(result.fill_limits) == {
        "untextured",
        "bilinear",
        "bilinear_blend",
        "trilinear_blend",
    }
    assert min(result.fill_limits.values()) > 0.0
    for row in result.passes:
        assert row["limit_mpix_per_s"] == result.fill_limits[str(row["limit"])]
        assert float(row["ratio"]) == pytest.approx(
            float(row["mpix_per_s"]) / float(row["limit_mpix_per_s"])
        )
    table = result.table()
    assert "upsample impostor" in table and "ratio" in table
    assert result.to_dict()["passes"] == result.passes


# No GL: the path is read before anything is drawn.
def test_a_bad_camera_path_is_a_one_line_error(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("0, 0, 0, 1500, 45\n")
    assert main(["bench", "--frames", "2", "--camera-path", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("wxsky: error:") and "bad.csv line 1" in err and "\n" not in err
