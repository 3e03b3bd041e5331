"""Reference host: composite what a running wxsky daemon publishes into PNG files.

    python plugins/reference-host/reference_host.py --out sky.png [--control ADDR]
        [--frames N] [--heading-deg D --pitch-deg D --fov-deg D --size WxH]
        [--exposure EV] [--linear-out FILE.pfm|FILE.npy]
        [--radar-out radar.png [--radar-range-nm N --radar-tilt-deg D]]

With --radar-out it also asks the daemon for its weather radar picture (the `radar` command,
docs/radar.md) and writes it as a cockpit display shows it: heading-up on the camera's
heading, the usual colours, range rings at each quarter of the range.

A daemon with `[output] layer_format = "rgba16f"` publishes scene-linear half-float layers:
this host composites them in linear, writes that composite with --linear-out, and exposes
(--exposure, EV; 0 the legacy look) and tone-maps it once for the PNG. With 8-bit layers the
PNG is their composite as published (--exposure does not apply; --linear-out is an error).

It reads only what a simulator reads (the msgpack stream and the shared-memory segment), so
it doubles as the worked example for a host written in another language: see
docs/protocol.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from wxsky.app.snapshot import LINEAR_SUFFIXES, write_linear
from wxsky.cli.common import parse_size
from wxsky.errors import WxskyError
from wxsky.host.reference import ReferenceHost, radar_display
from wxsky.output.transport import default_address, parse_address
from wxsky.png import write_png
from wxsky.scene.exposure import scale_of_ev


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--control", help="daemon address (default: the user's unix socket)")
    p.add_argument("--out", type=Path, required=True, help="PNG to write (frame N adds _N)")
    p.add_argument("--frames", type=int, default=1, help="how many consecutive frames")
    p.add_argument("--heading-deg", type=float)
    p.add_argument("--pitch-deg", type=float)
    p.add_argument("--fov-deg", type=float)
    p.add_argument("--size", help="WIDTHxHEIGHT")
    p.add_argument("--exposure", type=float, default=0.0, help="EV for rgba16f layers")
    p.add_argument("--linear-out", type=Path, help="scene-linear composite (.pfm or .npy)")
    p.add_argument("--radar-out", type=Path, help="the weather radar's display (PNG)")
    p.add_argument("--radar-range-nm", type=float, default=40.0, help="radar range, 10..320")
    p.add_argument("--radar-tilt-deg", type=float, default=0.0, help="antenna tilt, -15..15")
    args = p.parse_args(argv)
    try:
        exposure = scale_of_ev(args.exposure)  # ValueError outside -20..20 EV
        if args.linear_out is not None and args.linear_out.suffix.lower() not in LINEAR_SUFFIXES:
            raise ValueError(f"--linear-out {args.linear_out}: give a name ending in .pfm or .npy")
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
                # First, so 8-bit layers refuse --linear-out before anything is written.
                linear = None if args.linear_out is None else frame.composite_linear()
                write_png(out, frame.composite(exposure=exposure))
                print(f"frame {frame.meta.frame_number} -> {out}")
                if linear is not None:
                    lin = args.linear_out
                    lin = lin if args.frames == 1 else lin.with_stem(f"{lin.stem}_{n}")
                    write_linear(lin, linear.astype(np.float32))
                    print(f"frame {frame.meta.frame_number} -> {lin} (scene-linear)")
            if args.radar_out is not None:
                dbz = host.radar(args.radar_range_nm, args.radar_tilt_deg)
                heading = float(host.call("scene")["camera"]["heading_deg"])
                write_png(args.radar_out, radar_display(dbz, heading))
                print(
                    f"radar {args.radar_range_nm:g} NM, max {dbz.max():.0f} dBZ -> {args.radar_out}"
                )
    except (WxskyError, ValueError) as exc:
        print(f"reference-host: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
