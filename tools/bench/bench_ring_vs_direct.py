#!/usr/bin/env python3
"""Does the impostor ring pay? `wxsky bench` in ring and direct mode, side by side, as whole
processes, plus the image difference between the two modes and a check of the rebuild trace.

    .venv/bin/python tools/bench/bench_ring_vs_direct.py [--frames 120] [--size 1280x720] \\
        [--repeat 3] [--png docs/performance-ring-vs-direct.png] [--json out.json]

1. Speed: for each preset (overcast-stratus, broken-stratocumulus), `wxsky bench --json` in
   each mode, interleaved ring/direct, `--repeat` times; each process's wall time less the
   startup the bench reports (interpreter, imports, GL context, shaders, first scene), medians.
   Also the medians of the per-stage timings the runs print.
2. Pictures: `wxsky.app.snapshot.take_snapshot` in both modes at one static camera per preset;
   mean and largest absolute difference per channel of the composited images (/255).
3. Trace: one longer ring run along the default flight (120 m/s at 1500 m, 30 fps), checking
   that every rebuild starts on the first frame past 15 % of the radius horizontally (or 2 %
   vertically) from the previous ring's centre, renders its 8 impostors on 8 consecutive
   frames, is followed by a cross-fade, and that no frame renders two impostors.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.app.snapshot import take_snapshot  # noqa: E402
from wxsky.cli.common import parse_size  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.settings.config import DaemonConfig  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

PRESETS = ("overcast-stratus", "broken-stratocumulus")
STAGES = ("scene", "sort", "impostor_slice", "near_pass", "publish")
# Static cameras for the picture check: above the stratus deck looking down the deck, and
# from the ground looking up into the stratocumulus.
CAMERAS = {
    "overcast-stratus": {"alt_m": 1600.0, "heading_deg": 90.0, "pitch_deg": -8.0},
    "broken-stratocumulus": {"alt_m": None, "heading_deg": 90.0, "pitch_deg": 8.0},
}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=120)
    p.add_argument("--size", default="1280x720")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--trace-frames", type=int, default=1000)
    p.add_argument("--png", type=Path, help="bar chart of the per-stage medians")
    p.add_argument("--json", type=Path, help="write every figure there")
    args = p.parse_args()
    width, height = parse_size(args.size)
    wxsky = [sys.executable, "-m", "wxsky"]
    report: dict[str, Any] = {"size": [width, height], "frames": args.frames, "presets": {}}
    for preset in PRESETS:
        runs: dict[str, list[dict[str, Any]]] = {"ring": [], "direct": []}
        for _ in range(args.repeat):
            for mode in ("ring", "direct"):
                cmd = [*wxsky, "bench", "--preset", preset, "--frames", str(args.frames)]
                cmd += ["--mode", mode, "--size", args.size, "--json"]
                t0 = time.perf_counter()
                out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
                wall = time.perf_counter() - t0
                result = json.loads(out)
                result["process_s"] = wall
                result["process_less_startup_s"] = wall - result["startup_s"]
                runs[mode].append(result)
        summary = {mode: _summarise(r) for mode, r in runs.items()}
        ratio = (
            summary["ring"]["process_less_startup_s"] / summary["direct"]["process_less_startup_s"]
        )
        diff = picture_difference(preset, width, height)
        report["presets"][preset] = {"modes": summary, "ring_over_direct": ratio, "image": diff}
        print(_table(preset, summary, ratio, diff, args.frames), flush=True)
    report["trace"] = trace_check(wxsky, args.trace_frames)
    print(_trace_lines(report["trace"]))
    report["renderer"] = report["presets"][PRESETS[0]]["modes"]["ring"]["renderer"]
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    if args.png:
        chart(report, args.png)
        print(f"wrote {args.png}")
    return 0


def _summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "renderer": runs[0]["renderer"],
        "process_s": statistics.median(r["process_s"] for r in runs),
        "startup_s": statistics.median(r["startup_s"] for r in runs),
        "process_less_startup_s": statistics.median(r["process_less_startup_s"] for r in runs),
        "frames_s": statistics.median(r["frames_s"] for r in runs),
        "stages_ms": {
            name: {
                k: statistics.median(r["stages_ms"][name][k] for r in runs)
                for k in ("median", "p95")
            }
            for name in STAGES
        },
        "frame_ms": {
            k: statistics.median(r["frame_ms"][k] for r in runs) for k in ("median", "p95")
        },
        "near_sprites": statistics.median(r["near_sprites"]["median"] for r in runs),
        "runs": len(runs),
    }


def picture_difference(preset: str, width: int, height: int) -> dict[str, float]:
    state = WeatherState().apply(load_preset(preset, ()))
    cam = CAMERAS[preset]
    alt_m = cam["alt_m"] if cam["alt_m"] is not None else state.observer.alt_m + 2.0
    camera = Camera(
        position_m=(0.0, 0.0, alt_m),
        heading_deg=cam["heading_deg"],
        pitch_deg=cam["pitch_deg"],
        width_px=width,
        height_px=height,
    )
    settings = DaemonConfig().scene.settings()
    with Renderer(settings.ring_texture_px) as renderer:
        ring = take_snapshot(state, camera, settings, renderer, mode="ring").image
        direct = take_snapshot(state, camera, settings, renderer, mode="direct").image
    d = np.abs(ring[..., :3].astype(int) - direct[..., :3].astype(int))
    return {"mean": float(d.mean()), "p99": float(np.percentile(d, 99)), "max": int(d.max())}


def trace_check(wxsky: list[str], frames: int) -> dict[str, Any]:
    trace = Path("/tmp") / f"wxsky-ring-trace-{id(frames)}.jsonl"
    cmd = [*wxsky, "bench", "--preset", "broken-stratocumulus", "--frames", str(frames)]
    cmd += ["--size", "320x180", "--trace", str(trace), "--json"]
    subprocess.run(cmd, check=True, capture_output=True)
    lines = [json.loads(line) for line in trace.read_text().splitlines()]
    trace.unlink()
    starts = [e for e in lines if e["event"] == "ring_rebuild_start"]
    rendered = [e for e in lines if e["event"] == "impostor_rendered"]
    per_frame: dict[int, int] = {}
    for e in rendered:
        per_frame[e["frame"]] = per_frame.get(e["frame"], 0) + 1
    radius_m = DaemonConfig().scene.ring_radius_m
    # Frames and positions: the default path is 4 m per frame east from the origin.
    exact = []
    for prev, start in itertools.pairwise(starts):
        moved = math.dist(start["camera_m"][:2], prev["centre_m"][:2])
        before = math.dist((start["camera_m"][0] - 4.0, start["camera_m"][1]), prev["centre_m"][:2])
        exact.append(moved > 0.15 * radius_m >= before)
    spread = []
    slices: list[int] = []
    for k in range(len(starts)):
        idx = [e for e in rendered[8 * k : 8 * k + 8]]
        frames_k = [e["frame"] for e in idx]
        n_k = [int(e.get("slices", 1)) for e in idx]
        if k == 0:  # the first ring, replacing none on show, all in one frame
            consecutive = len(set(frames_k)) == 1
        else:  # one impostor after the other, each over its slices' consecutive frames
            consecutive = [b - a for a, b in itertools.pairwise(frames_k)] == n_k[1:]
            slices += n_k
        spread.append([e["index"] for e in idx] == list(range(8)) and consecutive)
    fades = sum(e["event"] == "crossfade_start" for e in lines)
    return {
        "frames": frames,
        "rebuilds": len(starts),
        "reasons": [s["reason"] for s in starts],
        "start_frames": [s["frame"] for s in starts],
        "starts_exactly_past_threshold": all(exact),
        "each_impostor_after_the_other": all(spread) and len(spread) == len(starts),
        "slices_per_impostor": slices,
        "crossfades": fades,
        "most_impostors_in_one_frame": max(per_frame.values(), default=0),
    }


def _table(
    preset: str, s: dict[str, Any], ratio: float, diff: dict[str, float], frames: int
) -> str:
    rows = [
        f"\n## {preset}: {frames} frames",
        "",
        "| stage | ring median ms | ring p95 ms | direct median ms | direct p95 ms |",
        "|---|---|---|---|---|",
    ]
    for name in (*STAGES, "frame"):
        r = s["ring"]["frame_ms"] if name == "frame" else s["ring"]["stages_ms"][name]
        d = s["direct"]["frame_ms"] if name == "frame" else s["direct"]["stages_ms"][name]
        rows.append(
            f"| {name} | {r['median']:.2f} | {r['p95']:.2f} | {d['median']:.2f} | {d['p95']:.2f} |"
        )
    rows += [
        "",
        f"Near sprites per frame (median): ring {s['ring']['near_sprites']:.0f}, direct "
        f"{s['direct']['near_sprites']:.0f}. Whole process less startup (median of "
        f"{s['ring']['runs']}): ring {s['ring']['process_less_startup_s']:.2f} s, direct "
        f"{s['direct']['process_less_startup_s']:.2f} s: **ring / direct = {ratio:.3f}**. "
        f"Composited pictures at one static camera: mean |ring - direct| "
        f"{diff['mean']:.3f}/255, p99 {diff['p99']:.0f}, max {diff['max']}.",
    ]
    return "\n".join(rows)


def _trace_lines(t: dict[str, Any]) -> str:
    return (
        f"\n## Rebuild trace: {t['frames']} frames along the default flight\n\n"
        f"{t['rebuilds']} rebuilds ({', '.join(t['reasons'])}) starting at frames "
        f"{t['start_frames']}; each started on the first frame past the threshold: "
        f"{t['starts_exactly_past_threshold']}; the first ring whole in one frame, then each "
        f"impostor after the other over its slices' frames: {t['each_impostor_after_the_other']}"
        f" (slices per impostor: {t['slices_per_impostor']}); cross-fades started: "
        f"{t['crossfades']}; most impostors rendered in one frame: "
        f"{t['most_impostors_in_one_frame']}."
    )


def chart(report: dict[str, Any], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    presets = list(report["presets"])
    fig, axes = plt.subplots(1, len(presets), figsize=(5.5 * len(presets), 4.2), dpi=100)
    colours = ("#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3")
    for ax, preset in zip(np.atleast_1d(axes), presets, strict=True):
        modes = report["presets"][preset]["modes"]
        bottom = np.zeros(2)
        for name, colour in zip(STAGES, colours, strict=True):
            values = np.array([modes[m]["stages_ms"][name]["median"] for m in ("ring", "direct")])
            ax.bar(("ring", "direct"), values, bottom=bottom, label=name, color=colour)
            bottom += values
        ratio = report["presets"][preset]["ring_over_direct"]
        ax.set_title(f"{preset}\nring / direct (whole process) = {ratio:.2f}", fontsize=10)
        ax.set_ylabel("median ms per frame, by stage")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    w, h = report["size"]
    fig.suptitle(
        f"wxsky bench, {report['frames']} frames at {w}x{h}, {report['renderer']}", fontsize=9
    )
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
