#!/usr/bin/env python3
"""Frame time of every preset, this checkout against a base build, side by side in one run.

    .venv/bin/python tools/bench/bench_frame_time.py --base /work/base19/.venv/bin/wxsky \\
        [--size 1280x720] [--frames 90] [--repeats 2] [--json out.json] [--png out.png]

For each preset it runs `wxsky bench --json` with the base build and with this checkout's,
alternating (base, new, base, new ...) so that both see the same machine, and reports per
build the median over the runs of: the frame median and p95, and the CPU stages (scene +
sort + publish) median, and, from this checkout, the frame thread's own CPU in those stages
(`cpu_stages_ms.thread_cpu`). "pair ratio" is the median, over the runs, of each new run's
frame median over the base run just before it (min-max after it): on this shared 2-core
machine the speed drifts over minutes, by more than the ratio of the medians shows (two
calls of two runs each gave fair-cumulus 1.05 and 1.32); a pair sees the same minute, and
more `--repeats` narrow the spread. The base build is any other checkout's `wxsky` (issue 19
compares against the code at its start: `git worktree add /tmp/base issue19-start`, a venv
there, `pip install -e /tmp/base`).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

from wxsky.app.bench import CPU_STAGES  # the stages `wxsky bench` sums as CPU

ROOT = Path(__file__).resolve().parents[2]
PRESETS = (
    "clear",
    "fair-cumulus",
    "scattered-cumulus",
    "broken-stratocumulus",
    "overcast-stratus",
    "high-cirrus",
    "thunderstorm",
    "towering-cumulus",
)


def bench(wxsky: str, preset: str, size: str, frames: int) -> dict[str, Any]:
    cmd = [wxsky, "bench", "--preset", preset, "--size", size, "--frames", str(frames), "--json"]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    result: dict[str, Any] = json.loads(out)
    return result


def summary(runs: list[dict[str, Any]]) -> dict[str, float]:
    def med(values: list[float]) -> float:
        return float(statistics.median(values))

    return {
        "frame_median_ms": med([r["frame_ms"]["median"] for r in runs]),
        "frame_p95_ms": med([r["frame_ms"]["p95"] for r in runs]),
        "cpu_median_ms": med([sum(r["stages_ms"][s]["median"] for s in CPU_STAGES) for r in runs]),
        # The frame thread's own CPU in those stages, where the build reports it (since
        # 2026-12-04; the base does not): nan otherwise.
        "cpu_thread_median_ms": med(
            [r.get("cpu_stages_ms", {}).get("thread_cpu", {}).get("median", math.nan) for r in runs]
        ),
        **{
            f"{stage}_median_ms": med([r["stages_ms"][stage]["median"] for r in runs])
            for stage in ("scene", "sort", "impostor_slice", "near_pass", "publish")
        },
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="the base build's wxsky executable")
    parser.add_argument("--new", default=str(ROOT / ".venv" / "bin" / "wxsky"))
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--preset", action="append", help="only these presets")
    parser.add_argument("--json", type=Path, help="write the figures there")
    parser.add_argument("--png", type=Path, help="draw the medians there")
    parser.add_argument(
        "--label", default="base", help="what the base is, in the chart's title (a commit)"
    )
    args = parser.parse_args()
    report: dict[str, Any] = {
        "size": args.size,
        "frames": args.frames,
        "base_label": args.label,
        "presets": {},
    }
    header = (
        f"{'preset':<22}{'base ms':>9}{'new ms':>8}{'ratio':>7}{'base p95':>10}{'new p95':>9}"
        f"{'p95/med':>9}{'base cpu':>10}{'new cpu':>9}{'new thread cpu':>16}"
        f"{'pair ratio (min-max)':>24}"
    )
    print(f"wxsky bench --size {args.size} --frames {args.frames}, {args.repeats} runs each")
    print(header)
    for preset in args.preset or PRESETS:
        runs: dict[str, list[dict[str, Any]]] = {"base": [], "new": []}
        for _ in range(args.repeats):
            runs["base"].append(bench(args.base, preset, args.size, args.frames))
            runs["new"].append(bench(args.new, preset, args.size, args.frames))
        b, n = summary(runs["base"]), summary(runs["new"])
        ratio = n["frame_median_ms"] / b["frame_median_ms"]
        pairs = [
            nr["frame_ms"]["median"] / br["frame_ms"]["median"]
            for br, nr in zip(runs["base"], runs["new"], strict=True)
        ]
        pair = float(statistics.median(pairs))
        report["presets"][preset] = {
            "base": b,
            "new": n,
            "ratio": ratio,
            "pair_ratios": pairs,
            "pair_ratio_median": pair,
        }
        print(
            f"{preset:<22}{b['frame_median_ms']:>9.1f}{n['frame_median_ms']:>8.1f}"
            f"{ratio:>7.2f}{b['frame_p95_ms']:>10.1f}{n['frame_p95_ms']:>9.1f}"
            f"{n['frame_p95_ms'] / n['frame_median_ms']:>9.2f}{b['cpu_median_ms']:>10.1f}"
            f"{n['cpu_median_ms']:>9.1f}{n['cpu_thread_median_ms']:>16.2f}"
            f"{pair:>11.2f} ({min(pairs):.2f}-{max(pairs):.2f})"
        )
        sys.stdout.flush()
    report["renderer"] = runs["new"][0]["renderer"]
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    if args.png is not None:
        chart(report, args.png)
    return 0


def chart(report: dict[str, Any], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    presets = list(report["presets"])
    fig, (ax, cpu) = plt.subplots(
        1, 2, figsize=(14, 4.8), dpi=110, gridspec_kw={"width_ratios": [3, 2]}
    )
    x = range(len(presets))
    width = 0.38
    for k, (build, colour) in enumerate((("base", "#b0b0b0"), ("new", "#3b7dd8"))):
        med = [report["presets"][p][build]["frame_median_ms"] for p in presets]
        p95 = [report["presets"][p][build]["frame_p95_ms"] for p in presets]
        pos = [i + (k - 0.5) * width for i in x]
        ax.bar(pos, med, width, color=colour, label=f"{build} median")
        ax.scatter(pos, p95, color="black", marker="_", s=200, zorder=3)
    ax.axhline(33.3, color="#d04040", linewidth=1, linestyle="--", label="33 ms (30 fps)")
    ax.set_xticks(list(x), presets, rotation=20, ha="right")
    ax.set_ylabel("frame ms (bars: median, ticks: p95)")
    ax.set_title(
        f"wxsky bench {report['size']}, {report['frames']} frames: "
        f"{report.get('base_label', 'base')} vs now "
        f"({report['renderer'].split(' / ')[0]})",
        fontsize=9,
    )
    ax.legend(fontsize=8)
    # The new build's CPU stages, stacked (the base's are 3-120 ms: off this scale).
    bottom = [0.0] * len(presets)
    for stage, colour in zip(CPU_STAGES, ("#3b7dd8", "#8fb8ee", "#f0a040"), strict=True):
        part = [report["presets"][p]["new"][f"{stage}_median_ms"] for p in presets]
        cpu.bar(list(x), part, 0.6, bottom=bottom, color=colour, label=stage)
        bottom = [b + v for b, v in zip(bottom, part, strict=True)]
    cpu.axhline(2.0, color="#d04040", linewidth=1, linestyle="--", label="2 ms")
    cpu.set_xticks(list(x), presets, rotation=20, ha="right")
    cpu.set_ylabel("ms (medians)")
    cpu.set_title("new build's CPU stages per frame", fontsize=9)
    cpu.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out)


if __name__ == "__main__":
    raise SystemExit(main())
