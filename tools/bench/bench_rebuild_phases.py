#!/usr/bin/env python3
"""Frame times along the default flight split by what the ring is doing (issue 19: p95 along
the flight path, rebuilds included): the steady frames, those while the worker process builds
a ring, those that draw an impostor slice, and the cross-fade's; and each stage's median in
each phase. One `wxsky bench` run per preset and repeat, in this process, its trace read back.

    .venv/bin/python tools/bench/bench_rebuild_phases.py --frames 400 --repeats 2 \\
        fair-cumulus scattered-cumulus

A phase is named by the ring events of the bench's trace: from `ring_rebuild_start` on the
frames are "building"; a frame that drew a slice (the impostor_slice stage took time) is a
"slice" frame; from `crossfade_start` to `crossfade_done` "fade". The lead-in (frames until the
first ring is shown) is not timed, as in `wxsky bench`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

PHASES = ("steady", "building", "slice", "fade")
STAGES = ("scene", "sort", "impostor_slice", "near_pass", "publish")
SLICE_DRAWN_S = 0.0005  # a slice frame's impostor_slice stage takes milliseconds, others µs


def p95(values: list[float]) -> float:
    ordered = sorted(values)
    return ordered[max(0, int(0.95 * len(ordered)) - 1)]


@dataclasses.dataclass
class Phase:
    frames: int
    median_ms: float
    p95_ms: float
    stage_ms: dict[str, float]  # each stage's median over the phase's frames


@dataclasses.dataclass
class Run:
    median_ms: float
    p95_ms: float
    phases: dict[str, Phase]


def run(preset: str, frames: int) -> Run:
    from wxsky.app.bench import run_bench
    from wxsky.app.camera_path import straight_and_level
    from wxsky.app.trace import TraceWriter
    from wxsky.settings.config import load_config
    from wxsky.settings.presets import load_preset
    from wxsky.weather.state import WeatherState

    config = load_config(None)
    scene = config.scene
    with tempfile.TemporaryDirectory() as tmp:
        trace_path = Path(tmp) / "trace.jsonl"
        trace = TraceWriter(trace_path)
        try:
            result = run_bench(
                WeatherState().apply(load_preset(preset)),
                scene.settings(),
                straight_and_level(alt_m=1500.0),
                frames,
                "ring",
                (1280, 720),
                preset=preset,
                ring_fade_s=scene.ring_fade_s,
                ring_slice_ms=scene.ring_slice_ms or None,
                ring_worker=scene.ring_worker,
                ring_worker_nice=scene.ring_worker_nice,
                trace=trace,
            )
        finally:
            trace.close()
        events = [json.loads(line) for line in trace_path.read_text().splitlines()]
    lead = result.lead_in_frames
    timed = [e for e in events if e["frame"] > lead]
    rebuild = [e["frame"] for e in timed if e["event"] == "ring_rebuild_start"]
    fade_on = [e["frame"] for e in timed if e["event"] == "crossfade_start"]
    fade_off = [e["frame"] for e in timed if e["event"] == "crossfade_done"]
    frame_ms = [s * 1000.0 for s in result.frame_s]
    phase = []
    for i in range(len(frame_ms)):
        number = lead + 1 + i  # the trace numbers every drawn frame, the lead-in's too
        name = "building" if rebuild and number >= rebuild[0] else "steady"
        if result.stage_s["impostor_slice"][i] > SLICE_DRAWN_S:
            name = "slice"
        if fade_on and number >= fade_on[0] and (not fade_off or number <= fade_off[0]):
            name = "fade"
        phase.append(name)
    phases = {}
    for name in PHASES:
        rows = [i for i, p in enumerate(phase) if p == name]
        if rows:
            times = [frame_ms[i] for i in rows]
            stage_ms = {
                stage: statistics.median(result.stage_s[stage][i] * 1000.0 for i in rows)
                for stage in STAGES
            }
            phases[name] = Phase(len(rows), statistics.median(times), p95(times), stage_ms)
    return Run(statistics.median(frame_ms), p95(frame_ms), phases)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("presets", nargs="+")
    parser.add_argument("--frames", type=int, default=400)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--json", type=Path, help="write every run there")
    args = parser.parse_args()
    runs: dict[str, list[Run]] = {}
    for _ in range(args.repeats):
        for preset in args.presets:  # presets alternate, so a slow minute falls on several
            runs.setdefault(preset, []).append(run(preset, args.frames))
    print(f"{'preset':24}{'phase':10}{'frames':>7}{'median':>8}{'p95':>7}  stage medians, ms")
    for preset, results in runs.items():
        for k, r in enumerate(results):
            ratio = r.p95_ms / r.median_ms
            print(
                f"{preset + ' #' + str(k + 1):24}{'all':10}{args.frames:7}"
                f"{r.median_ms:8.1f}{r.p95_ms:7.1f}  p95/median {ratio:.2f}"
            )
            for name, ph in r.phases.items():
                stages = " ".join(f"{s} {ph.stage_ms[s]:.2f}" for s in STAGES)
                print(f"{'':24}{name:10}{ph.frames:7}{ph.median_ms:8.1f}{ph.p95_ms:7.1f}  {stages}")
    if args.json:
        data = {p: [dataclasses.asdict(r) for r in rs] for p, rs in runs.items()}
        args.json.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
