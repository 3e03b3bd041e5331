#!/usr/bin/env python3
"""Render the same views with two builds of wxsky and say how much the pictures differ.

    .venv/bin/python tools/gallery/compare_frames.py --base /work/base19/.venv/bin/wxsky \\
        --out /tmp/compare [--size 1280x720] [--preset NAME ...]

For every preset and view (from the ground looking up, level at 1,500 m, looking down from
above the clouds) it runs `wxsky snapshot` with the base build and with this checkout's, and
prints the mean, 99th percentile and largest difference per channel (0..255). It writes both
pictures and an amplified difference (x8) side by side per view to --out, to look at: a
change to what a pilot sees must be seen, not only counted.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from wxsky.png import read_png, write_png  # noqa: E402

PRESETS = (
    "clear",
    "fair-cumulus",
    "scattered-cumulus",
    "broken-stratocumulus",
    "overcast-stratus",
    "high-cirrus",
    "thunderstorm",
)
# (name, snapshot options): the views a pilot sees most.
VIEWS = (
    ("ground-up", ["--heading-deg", "200", "--pitch-deg", "15"]),
    ("level-1500", ["--alt-m", "1900", "--heading-deg", "90", "--pitch-deg", "0"]),
    ("above", ["--alt-m", "4000", "--heading-deg", "250", "--pitch-deg", "-12"]),
    ("dusk", ["--heading-deg", "300", "--pitch-deg", "5", "--time", "2026-06-21T19:10:00Z"]),
)


def snapshot(wxsky: str, preset: str, view: list[str], size: str, out: Path) -> np.ndarray:
    cmd = [wxsky, "snapshot", "--preset", preset, "--size", size, "--out", str(out), *view]
    subprocess.run(cmd, check=True, capture_output=True)
    return read_png(out)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="the base build's wxsky executable")
    parser.add_argument("--new", default=str(ROOT / ".venv" / "bin" / "wxsky"))
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--preset", action="append", help="only these presets")
    parser.add_argument("--view", action="append", help="only these views")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{'preset':<22}{'view':<12}{'mean':>7}{'p99':>6}{'max':>6}")
    worst = 0.0
    for preset in args.preset or PRESETS:
        for name, view in VIEWS:
            if args.view and name not in args.view:
                continue
            stem = f"{preset}-{name}"
            base = snapshot(args.base, preset, view, args.size, args.out / f"{stem}-base.png")
            new = snapshot(args.new, preset, view, args.size, args.out / f"{stem}-new.png")
            diff = np.abs(base[..., :3].astype(np.int16) - new[..., :3].astype(np.int16))
            mean = float(diff.mean())
            worst = max(worst, mean)
            print(
                f"{preset:<22}{name:<12}{mean:>7.3f}{int(np.percentile(diff, 99)):>6}"
                f"{int(diff.max()):>6}"
            )
            amplified = np.clip(diff * 8, 0, 255).astype(np.uint8)
            alpha = np.full((*diff.shape[:2], 1), 255, np.uint8)
            strip = np.concatenate([base[..., :3], new[..., :3], amplified], axis=1)
            write_png(
                args.out / f"{stem}-compare.png",
                np.concatenate([strip, np.tile(alpha, (1, 3, 1))], axis=2),
            )
    print(f"largest mean difference: {worst:.3f}/255")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
