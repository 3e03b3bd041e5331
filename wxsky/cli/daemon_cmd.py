"""`wxsky run`, `wxsky status` and `wxsky snapshot`: the daemon and one-off pictures."""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from wxsky.cli.common import (
    Checked,
    KindRef,
    NumberArg,
    OutputDir,
    OutputFile,
    Subparsers,
    UsageError,
    add_control_option,
    control_address,
    log_level,
    setup_logging,
    size_arg,
    time_arg,
)
from wxsky.cli.metar_cmd import add_field_elevation_option, check_field_elevation
from wxsky.schema import Number

# How far into a change of weather a snapshot may look: a day is more than any transition.
ELAPSED_S = Number(0.0, 86_400.0, unit="s")


def add_commands(sub: Subparsers) -> None:
    run = sub.add_parser(
        "run",
        help="run the daemon in the foreground",
        description="Run the daemon in the foreground; SIGINT/SIGTERM stop it cleanly, a "
        "second Ctrl-C forces exit.",
    )
    run.add_argument(
        "--config", type=Path, metavar="FILE", help="daemon config (TOML) (default: built-in)"
    )
    run.add_argument(
        "--preset",
        metavar="NAME",
        help="weather preset to start with, the base weather (default: the config's "
        "[daemon] preset)",
    )
    run.add_argument(
        "--metar", metavar="REPORT", help="METAR report to start with (beats the preset's fields)"
    )
    add_field_elevation_option(run, "--metar")
    run.add_argument(
        "--metar-feed",
        action="append",
        default=[],
        metavar="SOURCE",
        help="follow a METAR feed: a file, '-' for stdin, or an http(s) URL (repeatable; "
        "adds to [metar] feeds in the config)",
    )
    run.add_argument(
        "--grib",
        action="append",
        default=[],
        metavar="SOURCE",
        help="read model data (GRIB2): a file, a directory of forecast steps, or an http(s) "
        "URL (repeatable; adds to [grib] sources in the config; docs/weather-aloft.md)",
    )
    run.add_argument(
        "--replay",
        type=time_arg(),
        metavar="TIME",
        help="replay a past day: start the clock at TIME (ISO 8601, UTC unless it says) and "
        "take the METAR feeds as an archive, each station's latest report not after the "
        "clock (docs/weather-aloft.md says where to get archives); [clock] rate runs it faster",
    )
    run.add_argument(
        "--serial",
        action="append",
        default=[],
        type=Checked("--serial", _serial_spec),
        metavar="URL[@BAUD]",
        help="read NMEA 0183 from a serial device or pyserial URL, e.g. /dev/ttyUSB0@4800, "
        "socket://host:4001 (repeatable; adds to [[serial]] in the config)",
    )
    run.add_argument(
        "--can",
        action="append",
        default=[],
        type=Checked("--can", _can_spec),
        metavar="INTERFACE:CHANNEL",
        help="read CANaerospace from a python-can bus, e.g. socketcan:can0, "
        "udp_multicast:239.74.163.2 (repeatable; adds to [[can]] in the config)",
    )
    run.add_argument(
        "--cigi",
        action="append",
        default=[],
        type=Checked("--cigi", _udp_spec),
        metavar="udp:HOST:PORT",
        help="listen there for a CIGI 3.3 host, e.g. udp:127.0.0.1:8001 (repeatable; adds to "
        "[cigi] listen in the config)",
    )
    run.add_argument(
        "--cigi-send",
        action="append",
        default=[],
        type=Checked("--cigi-send", _udp_spec),
        metavar="udp:HOST:PORT",
        help="send the applied weather to a CIGI image generator there each frame "
        "(repeatable; adds to [cigi] send_to in the config)",
    )
    run.add_argument(
        "--flightgear",
        type=Checked("--flightgear", _tcp_spec),
        metavar="tcp:HOST:PORT",
        help="write the applied weather to a FlightGear's telnet/props server there, e.g. "
        "tcp:127.0.0.1:5501 (plugins/flightgear/README.md; over [flightgear] props)",
    )
    run.add_argument(
        "--flightgear-pose",
        type=Checked("--flightgear-pose", _udp_spec),
        metavar="udp:HOST:PORT",
        help="take the camera from a FlightGear's pose stream arriving there, e.g. "
        "udp:127.0.0.1:5505 (over [flightgear] pose)",
    )
    run.add_argument(
        "--web",
        type=Checked("--web", _web_spec),
        metavar="HOST:PORT",
        help="serve the instructor station in the browser there, e.g. 127.0.0.1:8080 "
        "(over [web] listen; off loopback every browser needs the token of [web] token_file; "
        "docs/web.md)",
    )
    share = run.add_argument_group(
        "one sky on several daemons (docs/channels.md)",
    )
    share.add_argument(
        "--share",
        type=Checked("--share", _zenoh_spec),
        metavar="zenoh:ENDPOINT",
        help="be the site's sky master, serving on a Zenoh endpoint, e.g. "
        "zenoh:tcp/127.0.0.1:7447 (sets [share] endpoint)",
    )
    share.add_argument(
        "--join",
        type=Checked("--join", _zenoh_spec),
        metavar="zenoh:ENDPOINT",
        help="be a display channel of the sky master there (sets [channel] join)",
    )
    share.add_argument("--channel", metavar="NAME", help="this channel's name ([channel] name)")
    share.add_argument(
        "--view-offset",
        type=Checked("--view-offset", _view_offset),
        metavar="YAW,PITCH,ROLL",
        help="this channel's view turned from the shared camera, degrees "
        "([channel] view_offset_deg)",
    )
    share.add_argument(
        "--fov-deg",
        type=float,
        metavar="DEG",
        help="this channel's horizontal field of view ([channel] fov_deg)",
    )
    share.add_argument(
        "--site", metavar="NAME", help="the shared sky's site ([share] and [channel] site)"
    )
    add_control_option(run)
    run.add_argument(
        "--shm-name",
        type=Checked("--shm-name", _shm_name),
        metavar="NAME",
        help="the shared-memory segment the frames go to (over [output] shm_name; another "
        "name lets a second daemon run beside the first)",
    )
    run.add_argument(
        "--preview",
        type=OutputDir("--preview"),
        metavar="DIR",
        help="write a composited preview.png there every few seconds",
    )
    run.add_argument(
        "--trace",
        type=OutputFile("--trace"),
        metavar="FILE",
        help="write the ring's rebuild events there, one JSON object per line",
    )
    run.set_defaults(func=_cmd_run)

    status = sub.add_parser(
        "status",
        help="ask a running daemon",
        description="Ask a running daemon for its frame rate, weather and inputs; exits 1 when "
        "no daemon answers at the address.",
    )
    add_control_option(status)
    status.add_argument("--json", action="store_true", help="print one JSON object")
    status.set_defaults(func=_cmd_status)

    snap = sub.add_parser(
        "snapshot",
        help="render one picture to a PNG",
        description="Render one picture, composited exactly as the daemon and a host do.",
    )
    src = snap.add_mutually_exclusive_group(required=True)
    src.add_argument("--preset", metavar="NAME", help="the weather of this preset")
    src.add_argument(
        "--metar",
        metavar="REPORT",
        help="the weather this METAR report states, over its station's field, where the "
        "camera stands",
    )
    add_field_elevation_option(snap, "--metar")
    snap.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="daemon config: its [presets] dirs, [scene], [render] exposure, [camera] alt_agl_m "
        "and [transition] rates (default: built-in)",
    )
    snap.add_argument(
        "--time",
        type=time_arg(),
        help="ISO 8601 time, UTC unless it says, e.g. 2026-06-21T14:00:00Z (default: the "
        "weather's own)",
    )
    snap.add_argument(
        "--lat",
        type=NumberArg("--lat", KindRef("wxsky.weather.state:LAT_DEG")),
        metavar="DEG",
        help="camera latitude, with --lon (default: the weather's site); as the daemon's "
        "set_camera: within 100 km of the site the camera flies there under the same sky, "
        "farther that place becomes the site",
    )
    snap.add_argument(
        "--lon",
        type=NumberArg("--lon", KindRef("wxsky.weather.state:LON_DEG")),
        metavar="DEG",
        help="camera longitude, east, with --lat (default: the weather's site)",
    )
    snap.add_argument(
        "--alt-m",
        type=NumberArg("--alt-m", KindRef("wxsky.weather.state:ALT_M")),
        metavar="M",
        help="camera altitude MSL (default: the observer's plus the config's [camera] alt_agl_m)",
    )
    snap.add_argument(
        "--heading-deg",
        type=NumberArg("--heading-deg", Number()),
        default=0.0,
        metavar="DEG",
        help="0 = north, clockwise",
    )
    snap.add_argument(
        "--pitch-deg",
        type=NumberArg("--pitch-deg", KindRef("wxsky.scene.camera:PITCH_DEG")),
        default=10.0,
        metavar="DEG",
        help="positive = up",
    )
    snap.add_argument(
        "--fov-deg",
        type=NumberArg("--fov-deg", KindRef("wxsky.scene.camera:FOV_DEG")),
        default=60.0,
        metavar="DEG",
        help="horizontal field of view",
    )
    snap.add_argument(
        "--size", type=size_arg(), default="960x540", metavar="WxH", help="picture size in pixels"
    )
    snap.add_argument(
        "--seed",
        type=NumberArg("--seed", KindRef("wxsky.weather.state:SEED")),
        metavar="N",
        help="cloud seed (default: the weather's)",
    )
    snap.add_argument(
        "--grib",
        action="append",
        default=[],
        metavar="SOURCE",
        help="lay the weather over model data (GRIB2: a file, a directory of steps, a URL) "
        "at its site and the picture's time, as the daemon does: the upper layers, tops and "
        "winds aloft (repeatable; docs/weather-aloft.md)",
    )
    snap.add_argument(
        "--transition-to",
        metavar="PRESET",
        help="picture the sky --elapsed-s after the weather target changed to this preset, "
        "moving toward it at the config's [transition] rates",
    )
    snap.add_argument(
        "--elapsed-s",
        type=NumberArg("--elapsed-s", ELAPSED_S),
        default=0.0,
        metavar="S",
        help="seconds since the change, with --transition-to",
    )
    snap.add_argument(
        "--mode",
        choices=("ring", "direct"),
        default="ring",
        help="far clouds as ring impostors (what the daemon does), or every cloud drawn as "
        "sprites, to compare the two",
    )
    snap.add_argument(
        "--out",
        type=OutputFile("--out", ".png"),
        required=True,
        metavar="FILE.png",
        help="output PNG",
    )
    snap.add_argument(
        "--layers-out",
        type=OutputDir("--layers-out"),
        metavar="DIR",
        help="also write the raw layers there, a LAYER.png each",
    )
    snap.add_argument(
        "--exposure",
        type=Checked("--exposure", _exposure_arg),
        metavar="EV|auto",
        help="exposure: a number of EV, -20..20 (the scale on scene-linear colour is 2^EV; 0 "
        'is the look of before), or "auto" (default: the config\'s [render] exposure)',
    )
    snap.add_argument(
        "--linear-out",
        type=OutputFile("--linear-out", (".pfm", ".npy")),
        metavar="FILE",
        help="also write the picture's scene-linear RGB (before exposure and tone map, the same "
        "camera): FILE.pfm a Portable Float Map, FILE.npy float32 HxWx3 rows top first",
    )
    snap.set_defaults(func=_cmd_snapshot)


def _serial_spec(spec: str) -> Any:
    from wxsky.settings.config import SerialInputSection

    return SerialInputSection.from_spec(spec)


def _udp_spec(spec: str) -> str:
    from wxsky.inputs.cigi_link import parse_udp

    parse_udp(spec)
    return spec


def _web_spec(spec: str) -> str:
    from wxsky.settings.config import parse_web_listen

    parse_web_listen(spec)
    return spec


def _tcp_spec(spec: str) -> str:
    from wxsky.app.flightgear_part import parse_tcp

    parse_tcp(spec, "--flightgear")
    return spec


def _can_spec(spec: str) -> Any:
    from wxsky.settings.config import CanInputSection

    return CanInputSection.from_spec(spec)


def _zenoh_spec(spec: str) -> str:
    if not spec.startswith("zenoh:") or len(spec) <= len("zenoh:"):
        raise ValueError("give zenoh:ENDPOINT, e.g. zenoh:tcp/127.0.0.1:7447")
    return spec.removeprefix("zenoh:")


def _shm_name(name: str) -> str:
    from wxsky.schema import Invalid
    from wxsky.settings.config import OutputSection

    try:
        OutputSection(shm_name=name)  # the config's own check of the name
    except Invalid as exc:
        raise ValueError(str(exc).removeprefix("output.shm_name: ")) from None
    return name


def _view_offset(spec: str) -> tuple[float, float, float]:
    parts = spec.split(",")
    if len(parts) != 3:
        raise ValueError("give YAW,PITCH,ROLL in degrees, e.g. -60,0,0")
    return (float(parts[0]), float(parts[1]), float(parts[2]))


def _shared_config(config: Any, args: argparse.Namespace) -> Any:
    """The config with `run`'s sharing options laid over [share] and [channel], and
    --shm-name over [output]."""
    import dataclasses

    from wxsky.errors import ConfigError
    from wxsky.schema import Invalid

    share, channel = config.share, config.channel
    try:
        if args.share is not None:
            share = dataclasses.replace(share, endpoint=args.share)
        if args.join is not None:
            channel = dataclasses.replace(channel, join=args.join)
        if args.channel is not None:
            channel = dataclasses.replace(channel, name=args.channel)
        if args.view_offset is not None:
            channel = dataclasses.replace(channel, view_offset_deg=args.view_offset)
        if args.fov_deg is not None:
            channel = dataclasses.replace(channel, fov_deg=args.fov_deg)
        if args.site is not None:
            share = dataclasses.replace(share, site=args.site)
            channel = dataclasses.replace(channel, site=args.site)
        output = config.output
        if args.shm_name is not None:
            output = dataclasses.replace(output, shm_name=args.shm_name)
        return dataclasses.replace(config, share=share, channel=channel, output=output)
    except Invalid as exc:
        raise ConfigError(f"wxsky run: {exc}") from None


def _cmd_run(args: argparse.Namespace) -> int:
    import asyncio

    from wxsky.app.memory import limit_arenas

    limit_arenas()  # first: before any thread that allocates starts (app/memory.py)

    from wxsky.app.daemon import Daemon, initial_patches
    from wxsky.app.part_factory import PartOptions, parts_from_config
    from wxsky.output.transport import parse_address
    from wxsky.settings.config import load_config
    from wxsky.weather.state import Source, WeatherPatch

    elevation_m = check_field_elevation(args, args.metar, "--metar")
    config = _shared_config(load_config(args.config), args)
    setup_logging(log_level(args, config.daemon.log_level))
    patches = initial_patches(
        config, preset=args.preset, metar=args.metar, field_elevation_m=elevation_m
    )
    if args.replay is not None:
        patches.append(WeatherPatch(source=Source.PRESET, time_utc=args.replay))
    address = parse_address(args.control) if args.control else None
    options = PartOptions(
        metar_feeds=args.metar_feed,
        grib=args.grib,
        replay=args.replay is not None,
        serial=args.serial,
        can=args.can,
        cigi=args.cigi,
        cigi_send=args.cigi_send,
        flightgear=args.flightgear,
        flightgear_pose=args.flightgear_pose,
        web=args.web,
    )
    daemon = Daemon(
        config,
        patches,
        parts_from_config(config, options),
        address=address,
        preview_dir=args.preview,
        trace_path=args.trace,
    )
    return asyncio.run(daemon.run())


def _cmd_status(args: argparse.Namespace) -> int:
    from wxsky.host.client import ControlClient

    with ControlClient.connect(control_address(args)) as client:
        status = client.call("status")
    if args.json:
        print(json.dumps(status, indent=2, sort_keys=True))
        return 0
    w = status["weather"]
    print(
        f"wxsky {status['version']} up {status['uptime_s']:.0f} s, "
        f"{status['frames_published']} frames, {status['fps']:.1f} fps"
    )
    print(
        f"time {w['time_utc']}  observer {w['observer']['lat_deg']:.4f} "
        f"{w['observer']['lon_deg']:.4f} {w['observer']['alt_m']:.0f} m"
    )
    src = w["sources"]
    for wind in w["wind"]:
        print(
            f"wind {wind['alt_m']:.0f} m: {wind['dir_deg']:03.0f}° {wind['speed_mps']:.1f} m/s"
            + (f" gusts {wind['gust_mps']:.1f}" if wind["gust_mps"] else "")
            + f"  [{src['wind']}]"
        )
    for lay in w["layers"]:
        print(
            f"cloud {lay['type']} {lay['cover_oktas']:.3g}/8 "
            f"{lay['base_m']:.0f}-{lay['top_m']:.0f} m  [{src['layers']}]"
        )
    print(f"visibility {w['visibility_m']:.0f} m, QNH {w['qnh_hpa']:.1f} hPa")
    if not status.get("settled", True):
        target = ", ".join(
            f"{lay['type']} {lay['cover_oktas']:.3g}/8 at {lay['base_m']:.0f} m"
            for lay in status["target"]["layers"]
        )
        print(f"changing toward: clouds {target or 'none'}")
    for name, hold in sorted(status.get("overrides", {}).items()):
        print(f"override {name}: {hold['source']}")
    _print_model(status.get("grib"))
    if status.get("frozen"):
        print("frozen: the weather stands still (freeze)")
    web = status.get("web")
    if isinstance(web, dict) and web.get("url"):
        guard = "token needed" if web.get("token") else "this machine only"
        print(f"web station {web['url']} ({guard}): {web['clients']} pages connected")
    ch = status.get("channel") or {}
    if ch.get("role") in ("master", "channel"):
        line = f"sky {ch['role']} {ch['name']!r} of site {ch['site']!r} on zenoh:{ch['endpoint']}"
        line += f", sky_id {status.get('sky_id')}"
        if ch["role"] == "channel":
            alive = "alive" if ch["master_alive"] else "GONE (keeping the last sky)"
            line += f", master {alive}"
            if ch.get("lag_ms") is not None:
                line += f", lag {ch['lag_ms']:.0f} ms"
        peers = ch.get("peers") or {}
        if peers:
            line += ", peers " + ", ".join(
                f"{n} ({p['role']}, {p['fps']:.0f} fps)" for n, p in sorted(peers.items())
            )
        dropped = sum((ch.get("dropped") or {}).values())
        if dropped or ch.get("refused_peers"):
            line += f", dropped {dropped} messages, refused {ch.get('refused_peers', 0)} peers"
        print(line)
    for inp in status["inputs"]:
        state = "ok" if inp["ok"] else "FAILING"
        line = (
            f"input {inp['name']} ({inp['kind']}): {state}, {inp['messages']} messages, "
            f"{inp['errors']} errors"
        )
        if inp.get("using"):
            line += ", using " + ", ".join(u["station"] for u in inp["using"])
        if inp.get("stale"):
            line += f", STALE ({inp.get('reason', '')})"
        if inp["kind"] == "cigi":
            line += (
                f", host {inp['host_address'] or 'not heard yet'}"
                f" ({inp['byte_order'] or '-'}), host frame {inp['last_host_frame']}, "
                f"{inp['start_of_frame_sent']} Start of Frame sent"
            )
            if inp["dropped"]:
                line += ", dropped " + _counts(inp["dropped"])
        if isinstance(inp.get("ignored"), dict):
            if inp["ignored"]:
                line += ", ignored " + _counts(inp["ignored"])
        elif inp.get("ignored"):
            line += f", {inp['ignored']} ignored"
        if not inp["ok"] and inp.get("state"):
            line += f" ({inp['state']})"
        print(line)
        if not inp["ok"] and inp.get("last_error"):
            print(f"  last error: {inp['last_error']}")
    return 0


def _print_model(grib: dict[str, Any] | None) -> None:
    """The model data's line (docs/weather-aloft.md): its steps, the freezing level and the
    tropopause at the site, the METAR's weight against it; or why it is not used."""
    if not grib:
        return
    p = grib.get("profile")
    if p is None:
        print(f"model data: not used: {grib.get('reason')}")
        return

    def metres(x: float | None) -> str:
        return "-" if x is None else f"{x:.0f} m"

    line = (
        f"model data: steps {', '.join(grib['steps_utc'])}; freezing level "
        f"{metres(p['freezing_level_m'])}, tropopause {metres(p['tropopause_m'])}"
    )
    if grib.get("metar_weight") is not None:
        line += f"; METAR weight {grib['metar_weight']:.2f}"
    print(line)
    for gap in grib.get("gaps", []):
        print(f"model data gap: {gap}")


def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{n} {reason}" for reason, n in sorted(counts.items()))


def _cmd_snapshot(args: argparse.Namespace) -> int:
    from wxsky.app.snapshot import take_snapshot
    from wxsky.scene.camera import Camera
    from wxsky.settings.config import load_config
    from wxsky.weather.state import Source, WeatherPatch, WeatherState

    if (args.lat is None) != (args.lon is None):
        raise UsageError("--lat and --lon go together")
    if args.elapsed_s and not args.transition_to:
        raise UsageError("--elapsed-s goes with --transition-to")
    check_field_elevation(args, args.metar, "--metar")
    args.progress("reading the weather")
    config = load_config(args.config)
    width, height = args.size
    patch = _weather_patch(args, config.presets.dirs)
    state = WeatherState().apply(patch)
    if args.grib:
        state = _under_model(args, patch, state)
    weather_time = state.time_utc
    state = state.apply(WeatherPatch(source=Source.CONTROL, time_utc=args.time, seed=args.seed))
    # Where the daemon puts its camera: the config's height above the observer.
    alt_m = state.observer.alt_m + config.camera.alt_agl_m if args.alt_m is None else args.alt_m
    camera = Camera(
        position_m=(0.0, 0.0, alt_m),
        heading_deg=args.heading_deg % 360.0,
        pitch_deg=args.pitch_deg,
        fov_deg=args.fov_deg,
        width_px=width,
        height_px=height,
    )
    settings = config.scene_settings()
    transition = None
    if args.transition_to:
        from wxsky.app.snapshot import Transition
        from wxsky.settings.presets import load_preset

        transition = Transition(
            to=load_preset(args.transition_to, config.presets.dirs),
            elapsed_s=args.elapsed_s,
            rates=config.transition.rates(),
            step_s=config.transition.step_s,
        )
    # The weather was set at its own time (a preset's time_utc): a later --time sees the
    # clouds blown on by the wind since then.
    drift_s = (state.time_utc - weather_time).total_seconds()
    shot = take_snapshot(
        state,
        camera,
        settings,
        transition=transition,
        drift_s=drift_s,
        mode=args.mode,
        position_deg=None if args.lat is None else (args.lat, args.lon),
        progress=args.progress,
        linear=args.linear_out is not None,
        exposure_setting=config.render.exposure if args.exposure is None else args.exposure,
    )
    args.progress(f"writing {args.out}")
    _write_png("--out", args.out, shot.image)
    if args.layers_out:
        for name, image in shot.layers.items():
            _write_png("--layers-out", args.layers_out / f"{name}.png", image)
    if args.linear_out is not None and shot.linear is not None:
        from wxsky.app.snapshot import write_linear

        try:
            write_linear(args.linear_out, shot.linear)
        except OSError as exc:
            raise UsageError(
                f"--linear-out {args.linear_out}: cannot write it ({exc.strerror or exc})"
            ) from None
    args.progress.done()
    print(f"wrote {args.out} ({width}x{height}): {shot.state.summary()}")
    return 0


def _exposure_arg(text: str) -> float | str:
    """--exposure: "auto" or EV, by the config's own kind (`[render] exposure`)."""
    from wxsky.scene.exposure import EXPOSURE

    try:
        value: object = float(text)
    except ValueError:
        value = text.strip()
    checked: float | str = EXPOSURE.validate("--exposure", value)
    return checked


def _under_model(args: argparse.Namespace, patch: Any, state: Any) -> Any:
    """The weather with the model's column at its site and the snapshot's time below it, as
    the daemon lays it: a preset is the base (the model above it), a METAR is laid over the
    model as at its station and time (docs/weather-aloft.md)."""
    from wxsky.cli.grib_cmd import column_at
    from wxsky.weather.model_clouds import model_layers
    from wxsky.weather.model_profile import KELVIN
    from wxsky.weather.precedence import SourceStack
    from wxsky.weather.state import Source, WeatherPatch, WeatherState

    obs = state.observer
    when = args.time or state.time_utc
    column = column_at(args.grib, obs.lat_deg, obs.lon_deg, when, args.progress)
    model = WeatherPatch(
        source=Source.GRIB,
        layers=model_layers(column),
        wind=column.winds() or None,
        temperature_c=None if column.t2m_k is None else column.t2m_k - KELVIN,
    )
    if patch.source is Source.METAR:
        site = WeatherState().apply(WeatherPatch(source=Source.PRESET, observer=obs))
        stack = SourceStack(base=site).with_patch(model, 0.0).with_patch(patch, 0.0)
    else:
        stack = SourceStack(base=state).with_patch(model, 0.0)
    return stack.target()


def _weather_patch(args: argparse.Namespace, preset_dirs: Sequence[Path]) -> Any:
    import dataclasses

    from wxsky.inputs.station_table import field_elevation_m, report_patch
    from wxsky.settings.presets import load_preset
    from wxsky.weather.metar import decode
    from wxsky.weather.state import WeatherState

    if args.metar:
        # The report names only its day: the latest such day not after the snapshot's time.
        site = WeatherState()
        report = decode(args.metar, now_utc=args.time or site.time_utc).require_usable()
        # Its clouds over its station's field, as a feed reads the report; the camera stands
        # on that field, so they are as high above it as the report says. The site's place
        # (and so the sun) stays the default one's.
        elevation_m = field_elevation_m(report.station, args.field_elevation_m)
        observer = dataclasses.replace(site.observer, alt_m=elevation_m)
        return dataclasses.replace(report_patch(report, elevation_m), observer=observer)
    return load_preset(args.preset, preset_dirs)


def _write_png(flag: str, path: Path, image: Any) -> None:
    from wxsky.png import write_png

    try:
        write_png(path, image)
    except OSError as exc:
        # A path the user gave that cannot be written is theirs to fix, like a bad --trace.
        raise UsageError(f"{flag} {path}: cannot write it ({exc.strerror or exc})") from None
