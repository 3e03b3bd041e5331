"""The C demo host's pictures for docs/gallery/: its terrain, runway and ridge flown along
its camera path against a real daemon, the clouds composited with the terrain's depth and
their shadows on the ground.

    .venv/bin/python tools/gallery/host_demo_gallery.py [--preset scattered-cumulus]
        [--time 2026-07-08T14:30:00Z] [--size 480x270] [--frames 6] [--out FILE]

Starts its own daemon (tools/bench/bench_host_c.py's), runs plugins/host-c/build/wxsky-host-demo
(built with make when missing or out of date) and writes docs/gallery/host-demo.png.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`
from tools.bench.bench_host_c import KIT, build_kit, daemon, parse_size

ROOT = Path(__file__).resolve().parents[2]
DEMO = KIT / "build" / "wxsky-host-demo"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", default="scattered-cumulus")
    p.add_argument("--time", default="2026-07-08T14:30:00Z")
    p.add_argument("--size", type=parse_size, default=(480, 270))
    p.add_argument("--frames", type=int, default=6)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "gallery" / "host-demo.png")
    args = p.parse_args()
    build_kit()
    if not DEMO.exists():
        raise SystemExit(f"{DEMO} was not built (pkg-config finds no egl, gl or zlib?)")
    width, height = args.size
    with (
        tempfile.TemporaryDirectory() as tmp,
        daemon(Path(tmp), width, height, args.preset) as (_, shm_name, address),
    ):
        proc = subprocess.run(
            [
                str(DEMO),
                "--control",
                address,
                "--shm",
                shm_name,
                "--time",
                args.time,
                "--size",
                f"{width}x{height}",
                "--frames",
                str(args.frames),
                "--out",
                str(args.out),
            ],
            capture_output=True,
            text=True,
            timeout=600,
        )
    sys.stdout.write(proc.stdout)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
