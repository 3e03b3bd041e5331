#!/usr/bin/env python3
"""Benchmark the OpenSceneGraph plugin (plugins/osg) against a real daemon: what the sky costs
an OSG application per frame, uploading the newest frame and drawing sky, ring and near
layers at their depth over the example terrain, at 1280x720 and 1920x1080.

    .venv/bin/python tools/bench/bench_osg.py [--frames 60] [--sizes 1280x720,1920x1080]
        [--json FILE] [--live]

For each size it starts its own daemon as tools/bench/bench_host_c.py does (preset
`scattered-cumulus`, the size as [output] max_width/max_height, [output] near_depth on), runs
`plugins/osg/build/wxsky-osg-snapshot --bench N` (built with make when missing): after its
picture, N pairs of OSG frames, one with the sky node and one without (its mask 0), each
finished with glFinish, the node uploading the newest frame in every frame it draws. The
sky's cost is the difference within each pair. The daemon is paused (SIGSTOP) once the
picture is taken, so that its rendering does not share the two cores (`--live` leaves it
running). Prints a table of medians and p95; --json writes every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

from tools.bench.bench_host_c import daemon, parse_size  # noqa: E402

KIT = ROOT / "plugins" / "osg"
TOOL = KIT / "build" / "wxsky-osg-snapshot"
TERRAIN = KIT / "examples" / "terrain.osg"
ROWS = ("frame_without_sky", "frame_with_sky", "sky_upload_and_draw")


def build() -> None:
    proc = subprocess.run(["make", "-s", "-C", str(KIT)], capture_output=True, text=True)
    if proc.returncode != 0 or not TOOL.exists():
        raise SystemExit(f"make -C plugins/osg failed:\n{proc.stdout}{proc.stderr}")


def measure(width: int, height: int, frames: int, live: bool) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="wxsky-bench-osg-") as tmp:
        folder = Path(tmp)
        with daemon(folder, width, height, "scattered-cumulus", near_depth=True) as (
            proc,
            _,
            address,
        ):
            cmd = [str(TOOL), "--control", address, "--alt-m", "300", "--pitch-deg", "6"]
            cmd += ["--fov-deg", "70", "--size", f"{width}x{height}", "--scene", str(TERRAIN)]
            cmd += ["--out", str(folder / "picture.png"), "--bench", str(frames)]
            tool = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            assert tool.stdout is not None
            figures: dict[str, Any] = {"size": f"{width}x{height}", "live": live}
            paused = False
            for line in tool.stdout:
                if line.startswith("wrote ") and not live:
                    os.kill(proc.pid, signal.SIGSTOP)  # (the tool's 10 warm-up pairs cover it)
                    paused = True
                if line.startswith("{"):
                    row = json.loads(line)
                    figures[row.pop("what")] = row
            err = tool.stderr.read() if tool.stderr else ""
            if paused:
                os.kill(proc.pid, signal.SIGCONT)
            if tool.wait() != 0:
                raise SystemExit(f"wxsky-osg-snapshot failed: {err}")
            return figures


def table(results: list[dict[str, Any]]) -> str:
    head = "| what | " + " | ".join(f"{r['size']} median ms | {r['size']} p95 ms" for r in results)
    lines = [head + " |", "|---" * (1 + 2 * len(results)) + "|"]
    for row in ROWS:
        cells = [f"{r[row]['median_ms']:.2f} | {r[row]['p95_ms']:.2f}" for r in results]
        lines.append(f"| {row} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=60, help="timed pairs per size")
    parser.add_argument("--sizes", default="1280x720,1920x1080", help="WxH,WxH,...")
    parser.add_argument("--json", type=Path, help="write every figure here")
    parser.add_argument("--live", action="store_true", help="leave the daemon running")
    args = parser.parse_args()
    build()
    results = [measure(*parse_size(s), args.frames, args.live) for s in args.sizes.split(",") if s]
    print(table(results))
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
