#!/usr/bin/env python3
"""Every preset, ring and direct mode, on the machine at hand: frame median and p95, the CPU
stages and the per-pass profile, as a table and a JSON file.

    python tools/bench/bench_presets.py [--size 1920x1080] [--frames 90] [--repeats 2]
        [--json out.json] [--no-profile]

Made for a machine with a GPU (issue 19 asks for these figures at 1920x1080), where it needs
no installed `wxsky`: it runs `python -m wxsky bench` from this checkout (run it with this
checkout on PYTHONPATH). Every shipped preset unless --preset names some. The runs of one
preset alternate ring, direct, ring, direct ... and each figure is the median over its runs.
After them, one `--profile` run per preset (ring mode) times every renderer pass to an idle
GPU and compares its fill rate with the limits measured on the same machine: that is where
the frame's time goes, and what limits it there.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from wxsky.app.bench import CPU_STAGES
from wxsky.settings.presets import list_presets

ROOT = Path(__file__).resolve().parents[2]
MODES = ("ring", "direct")
GPU_STAGES = ("impostor_slice", "near_pass")


def bench(preset: str, mode: str, size: str, frames: int, *extra: str) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "wxsky", "bench", "--preset", preset, "--mode", mode]
    cmd += ["--size", size, "--frames", str(frames), "--json", *extra]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
    }
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env).stdout
    result: dict[str, Any] = json.loads(out)
    return result


def summary(runs: list[dict[str, Any]]) -> dict[str, float]:
    def med(values: list[float]) -> float:
        return float(statistics.median(values))

    row = {
        "frame_median_ms": med([r["frame_ms"]["median"] for r in runs]),
        "frame_p95_ms": med([r["frame_ms"]["p95"] for r in runs]),
        "frame_max_ms": med([r["frame_ms"]["max"] for r in runs]),
        "cpu_median_ms": med([sum(r["stages_ms"][s]["median"] for s in CPU_STAGES) for r in runs]),
        "near_sprites": med([r["near_sprites"]["median"] for r in runs]),
        "startup_s": med([r["startup_s"] for r in runs]),
        "lead_in_s": med([r.get("lead_in_s", 0.0) for r in runs]),
    }
    for stage in (*CPU_STAGES, *GPU_STAGES):
        row[f"{stage}_median_ms"] = med([r["stages_ms"][stage]["median"] for r in runs])
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--preset", action="append", help="only these presets")
    parser.add_argument("--no-profile", action="store_true", help="skip the per-pass runs")
    parser.add_argument("--json", type=Path, help="write the figures there")
    args = parser.parse_args()
    presets = args.preset or [p.name for p in list_presets() if p.origin == "builtin"]
    report: dict[str, Any] = {"size": args.size, "frames": args.frames, "presets": {}}
    print(f"wxsky bench --size {args.size} --frames {args.frames}, {args.repeats} runs each")
    print(
        f"{'preset':<22}{'mode':<8}{'median':>8}{'p95':>8}{'p95/med':>8}{'cpu':>7}{'scene':>7}"
        f"{'sort':>6}{'publish':>8}{'slice':>7}{'draw':>7}{'sprites':>9}{'lead s':>8}"
    )
    t0 = time.perf_counter()
    renderer = ""
    for preset in presets:
        runs: dict[str, list[dict[str, Any]]] = {m: [] for m in MODES}
        for _ in range(args.repeats):
            for mode in MODES:
                runs[mode].append(bench(preset, mode, args.size, args.frames))
        renderer = runs["ring"][0]["renderer"]
        entry: dict[str, Any] = {}
        for mode in MODES:
            s = summary(runs[mode])
            entry[mode] = s
            print(
                f"{preset:<22}{mode:<8}{s['frame_median_ms']:>8.2f}{s['frame_p95_ms']:>8.2f}"
                f"{s['frame_p95_ms'] / s['frame_median_ms']:>8.2f}{s['cpu_median_ms']:>7.2f}"
                f"{s['scene_median_ms']:>7.2f}{s['sort_median_ms']:>6.2f}"
                f"{s['publish_median_ms']:>8.2f}{s['impostor_slice_median_ms']:>7.2f}"
                f"{s['near_pass_median_ms']:>7.2f}{s['near_sprites']:>9.0f}{s['lead_in_s']:>8.2f}"
            )
        report["presets"][preset] = entry
        sys.stdout.flush()
    if not args.no_profile:
        print("\nper pass (ring mode, --profile: each pass timed to an idle GPU)")
        for preset in presets:
            prof = bench(preset, "ring", args.size, args.frames, "--profile")
            report["presets"][preset]["profile"] = {
                "passes": prof.get("passes", []),
                "fill_limits_mpix_per_s": prof.get("fill_limits_mpix_per_s", {}),
            }
            limits = ", ".join(
                f"{k} {v:.0f}" for k, v in prof.get("fill_limits_mpix_per_s", {}).items()
            )
            print(f"{preset}: fill limits Mpix/s: {limits}")
            for r in prof.get("passes", []):
                print(
                    f"  {r['pass']:<20}{r['calls_per_frame']:>6.2f} calls/frame "
                    f"{r['median_ms']:>8.3f} ms/call {r['total_ms_per_frame']:>8.3f} ms/frame "
                    f"{r['mpix_per_s']:>8.0f} Mpix/s  {r['ratio']:>5.2f} of {r['limit']}"
                )
            sys.stdout.flush()
    report["renderer"] = renderer
    report["wall_s"] = time.perf_counter() - t0
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\n{renderer}; {report['wall_s']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
