#!/usr/bin/env python3
"""The CPU the frames' scene stages take (issue 19): `SkyEngine.advance` (sources, transition,
ring schedule, near set, shading, sort) along a level flight at 120 m/s, timed by the calling
thread's CPU clock so that other work on a shared machine counts for less than in wall time.
With `--base DIR` (a checkout of another commit), the same runs alternate between that tree
and this one in one call, and the medians are printed side by side.

    .venv/bin/python tools/bench/bench_scene_cpu.py --base /tmp/base --repeats 3 \\
        thunderstorm overcast-stratus fair-cumulus broken-stratocumulus

The ring is built in the calling thread at once (`ring_build = immediate`), so the frames that
build one are in the samples; the median leaves them out. Publishing (reading the layers back)
and drawing are not timed: `wxsky bench` has them.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LEAD_IN = 30  # frames before timing: the first near set and its light are made there


def run_here(presets: list[str], frames: int) -> dict[str, float]:
    """Median CPU ms a frame per preset, in this process (the tree on sys.path)."""
    import dataclasses
    import time

    from wxsky.engine.stages import SkyEngine
    from wxsky.scene.camera import Camera
    from wxsky.settings.config import load_config
    from wxsky.settings.presets import load_preset
    from wxsky.weather.state import WeatherState

    out = {}
    settings = load_config(None).scene.settings()
    for preset in presets:
        state = WeatherState().apply(load_preset(preset))
        camera = Camera(
            position_m=(0.0, 0.0, 1500.0),
            heading_deg=90.0,
            pitch_deg=0.0,
            fov_deg=60.0,
            width_px=1280,
            height_px=720,
        )
        with SkyEngine(state, camera, settings, ring_build="immediate") as engine:
            engine.settle()
            engine.warm_up()
            samples = []
            for i in range(LEAD_IN + frames):
                engine.set_camera(dataclasses.replace(camera, position_m=(4.0 * i, 0.0, 1500.0)))
                t0 = time.thread_time()
                engine.advance(1.0 / 30.0)
                samples.append((time.thread_time() - t0) * 1000.0)
        out[preset] = statistics.median(samples[LEAD_IN:])
    return out


def run_in(tree: Path, presets: list[str], frames: int) -> dict[str, float]:
    """The same in a fresh interpreter importing `tree`'s wxsky."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", "--frames", str(frames)]
    done = subprocess.run([*cmd, *presets], env=env, cwd=tree, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"bench_scene_cpu: {tree}: {done.stderr.strip().splitlines()[-1:]}")
    result: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("presets", nargs="+")
    parser.add_argument("--base", type=Path, help="a checkout to compare with")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(run_here(args.presets, args.frames)))
        return 0
    trees = [("new", ROOT)] + ([("base", args.base.resolve())] if args.base else [])
    runs: dict[str, list[dict[str, float]]] = {name: [] for name, _ in trees}
    for _ in range(args.repeats):
        for name, tree in trees:  # alternating, so a slow minute falls on both
            runs[name].append(run_in(tree, args.presets, args.frames))
    print(f"{'preset':24}" + "".join(f"{name + ' ms':>12}" for name, _ in trees), end="")
    print(f"{'new/base':>10}" if args.base else "")
    for preset in args.presets:
        medians = [statistics.median(r[preset] for r in runs[name]) for name, _ in trees]
        line = f"{preset:24}" + "".join(f"{m:12.2f}" for m in medians)
        print(line + (f"{medians[0] / medians[1]:10.2f}" if args.base else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
