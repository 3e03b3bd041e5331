"""`wxsky bench`: frames along a camera path, timed per stage (see `wxsky.app.bench`)."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from wxsky.cli.common import KindRef, NumberArg, OutputFile, Subparsers, UsageError, size_arg
from wxsky.schema import Number

STARTED_S = time.perf_counter()  # the command's start, for the startup figure

FRAMES = Number(1, 100_000, integer=True)
FPS = Number(1.0, 1000.0, unit="Hz")  # the simulated clock; the frames render as fast as they can


def add_commands(sub: Subparsers) -> None:
    bench = sub.add_parser(
        "bench",
        help="render frames along a camera path as the daemon would and time each stage",
    )
    bench.add_argument(
        "--preset", default="broken-stratocumulus", metavar="NAME", help="weather preset"
    )
    bench.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help=(
            "daemon config: its [presets] dirs, [scene], [render] exposure and [output] "
            "near_depth (default: built-in)"
        ),
    )
    bench.add_argument(
        "--frames",
        type=NumberArg("--frames", FRAMES),
        default=120,
        metavar="N",
        help="frames to render",
    )
    bench.add_argument(
        "--mode",
        choices=("ring", "direct"),
        default="ring",
        help="ring: the daemon's pipeline; direct: every cloud as sprites every frame",
    )
    bench.add_argument(
        "--size", type=size_arg(), default="1280x720", metavar="WxH", help="frame size in pixels"
    )
    bench.add_argument(
        "--fov-deg",
        type=NumberArg("--fov-deg", KindRef("wxsky.scene.camera:FOV_DEG")),
        default=60.0,
        metavar="DEG",
        help="horizontal field of view",
    )
    bench.add_argument(
        "--camera-path",
        type=Path,
        metavar="FILE",
        help="timestamped poses (t_s, x_m, y_m, z_m, heading_deg, pitch_deg[, roll_deg] per "
        "line) (default: straight and level at 120 m/s and 1500 m, heading 090)",
    )
    bench.add_argument(
        "--fps",
        type=NumberArg("--fps", FPS),
        default=30.0,
        help="simulated frames per second (how far the camera moves between frames)",
    )
    bench.add_argument(
        "--turn",
        action="store_true",
        help="instead of a path: a full turn on the spot in 2 s at 1500 m (sort stability)",
    )
    bench.add_argument(
        "--check-order",
        action="store_true",
        help="also measure how much each change in the near sprites' order changes a pixel",
    )
    bench.add_argument(
        "--profile",
        action="store_true",
        help="also time every renderer pass, count the pixels it writes and compare its fill "
        "rate with this machine's limits (the passes then wait for the GPU one by one)",
    )
    bench.add_argument(
        "--from-start",
        action="store_true",
        help="time the frames from the daemon's start, while its first ring is built (default: "
        "untimed frames until the first ring is shown, then the timed ones)",
    )
    bench.add_argument("--json", action="store_true", help="print one JSON object")
    bench.add_argument(
        "--trace", type=OutputFile("--trace"), metavar="FILE", help="write ring events there"
    )
    bench.set_defaults(func=_cmd_bench)


def _cmd_bench(args: argparse.Namespace) -> int:
    from wxsky.app.bench import run_bench
    from wxsky.app.camera_path import parse_camera_path, straight_and_level, turn_in_place
    from wxsky.app.trace import TraceWriter
    from wxsky.errors import ConfigError
    from wxsky.settings.config import load_config
    from wxsky.settings.presets import load_preset
    from wxsky.weather.state import WeatherState

    if args.turn and args.camera_path is not None:
        raise UsageError("--turn and --camera-path are two paths: give one")
    config = load_config(args.config)
    size = args.size
    state = WeatherState().apply(load_preset(args.preset, config.presets.dirs))
    if args.camera_path is not None:
        try:
            text = args.camera_path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError(f"--camera-path {args.camera_path}: {exc.strerror}") from None
        except UnicodeDecodeError:
            raise ConfigError(f"--camera-path {args.camera_path}: not UTF-8 text") from None
        path = parse_camera_path(text, str(args.camera_path))
    elif args.turn:
        path = turn_in_place(seconds=2.0, alt_m=1500.0)
    else:
        path = straight_and_level(alt_m=1500.0)
    trace = TraceWriter(args.trace) if args.trace is not None else None
    try:
        result = run_bench(
            state,
            config.scene.settings(),
            path,
            args.frames,
            args.mode,
            size,
            preset=args.preset,
            fov_deg=args.fov_deg,
            fps=args.fps,
            ring_fade_s=config.scene.ring_fade_s,
            ring_slice_ms=config.scene.ring_slice_ms or None,
            ring_worker=config.scene.ring_worker,
            ring_worker_nice=config.scene.ring_worker_nice,
            trace=trace,
            started_s=STARTED_S,
            check_order=args.check_order,
            profile=args.profile,
            lead_in=not args.from_start,
            progress=args.progress,
            exposure_setting=config.render.exposure,
            near_depth=config.output.near_depth,
        )
    finally:
        if trace is not None:
            trace.close()
    args.progress.done()
    print(json.dumps(result.to_dict(), indent=2) if args.json else result.table())
    return 0
