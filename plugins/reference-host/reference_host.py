"""Reference host: composite what a running wxsky daemon publishes into PNG files.

    python plugins/reference-host/reference_host.py --out sky.png [--control ADDR]
        [--frames N] [--heading-deg D --pitch-deg D --fov-deg D --size WxH]

It reads only what a simulator reads (the msgpack stream and the shared-memory segment), so
it doubles as the worked example for a host written in another language: see
docs/protocol.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from wxsky.cli.common import parse_size
from wxsky.errors import WxskyError
from wxsky.host.reference import ReferenceHost
from wxsky.output.transport import default_address, parse_address
from wxsky.png import write_png


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--control", help="daemon address (default: the user's unix socket)")
    p.add_argument("--out", type=Path, required=True, help="PNG to write (frame N adds _N)")
    p.add_argument("--frames", type=int, default=1, help="how many consecutive frames")
    p.add_argument("--heading-deg", type=float)
    p.add_argument("--pitch-deg", type=float)
    p.add_argument("--fov-deg", type=float)
    p.add_argument("--size", help="WIDTHxHEIGHT")
    args = p.parse_args(argv)
    try:
        address = parse_address(args.control) if args.control else default_address()
        with ReferenceHost.connect(address) as host:
            camera = {
                k: v
                for k, v in (
                    ("heading_deg", args.heading_deg),
                    ("pitch_deg", args.pitch_deg),
                    ("fov_deg", args.fov_deg),
                )
                if v is not None
            }
            if args.size:
                camera["width"], camera["height"] = parse_size(args.size)
            after = host.reader.frame_number
            if camera:
                host.call("set_camera", camera)
                # Frames already in flight were drawn for the old camera.
                after = host.reader.frame_number + 2
            for n in range(args.frames):
                frame = host.wait_frame(after)
                after = frame.meta.frame_number
                out = args.out if args.frames == 1 else args.out.with_stem(f"{args.out.stem}_{n}")
                write_png(out, frame.composite())
                print(f"frame {frame.meta.frame_number} -> {out}")
    except (WxskyError, ValueError) as exc:
        print(f"reference-host: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
