"""`wxsky weather set`: an instructor's weather, set directly on a running daemon (the
control channel's `set_weather`): visibility, cloud layers (base, top, cover), wind,
temperature, dewpoint, QNH, present weather, fog and RVR, held until `wxsky preset release`.
`wxsky weather visibility` and `wxsky weather rvr`: how far one sees at a point or a runway,
from the fog the daemon draws (the control channel's `visibility`, docs/fog.md)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from wxsky.cli.common import (
    EXIT_USAGE,
    Subparsers,
    add_control_option,
    control_address,
    show_help,
)

LAYER_HELP = "TYPE:OKTAS:BASE_M:TOP_M, e.g. cumulus:4:900:2400 (repeat for several layers)"
RVR_HELP = "RUNWAY:METRES, e.g. 14:600 or 32L:1200: the RVR at that runway's touchdown zone"


def add_commands(sub: Subparsers) -> None:
    weather = sub.add_parser("weather", help="set the running daemon's weather directly")
    weather.set_defaults(func=show_help(weather))
    wsub = weather.add_subparsers(dest="weather_command", metavar="COMMAND", title="commands")
    put = wsub.add_parser(
        "set",
        help="set visibility, cloud layers, wind ... (held until 'preset release')",
        description="Set weather fields on the running daemon as an instructor does, in a "
        "preset's units: what is given overrides the METAR feed and the config until 'wxsky "
        "preset release'; the rest is left as it is. --layer replaces the whole list of cloud "
        "layers. The sky moves there at the [transition] rates, or at once with --now.",
    )
    put.add_argument("--visibility-m", type=float, metavar="M", help="visibility, metres")
    put.add_argument("--layer", action="append", metavar="LAYER", help=LAYER_HELP)
    put.add_argument(
        "--no-layers", action="store_true", help="clear the sky of cloud (an empty list)"
    )
    put.add_argument("--temperature-c", type=float, metavar="C", help="surface temperature")
    put.add_argument("--dewpoint-c", type=float, metavar="C", help="surface dewpoint")
    put.add_argument("--qnh-hpa", type=float, metavar="HPA", help="QNH, hectopascals")
    put.add_argument(
        "--present-weather",
        action="append",
        metavar="CODE",
        help="a METAR present-weather group, e.g. +TSRA (repeat for several)",
    )
    put.add_argument(
        "--fog-visibility-m",
        type=float,
        metavar="M",
        help="fog over the ground: the visibility inside it, metres (docs/fog.md)",
    )
    put.add_argument(
        "--fog-depth-m",
        type=float,
        metavar="M",
        help="how high the fog's top stands over the ground, metres (default 100)",
    )
    put.add_argument(
        "--patchy-fog", action="store_true", help="the fog in banks with clear air between"
    )
    put.add_argument("--rvr", action="append", metavar="RVR", help=RVR_HELP)
    put.add_argument("--no-fog", action="store_true", help="clear the fog (and its RVRs)")
    put.add_argument("--now", action="store_true", help="switch the sky at once")
    add_control_option(put)
    put.set_defaults(func=_cmd_set)
    seen = wsub.add_parser(
        "visibility",
        help="how far one sees at a point, in the fog the daemon draws",
        description="The visibility and the runway visual range at a point of the running "
        "daemon's scene (metres east and north of its observer, height over the ground), or at "
        "a runway's touchdown zone, from the same fog it draws (docs/fog.md).",
    )
    seen.add_argument("--east-m", type=float, default=0.0, help="metres east of the observer")
    seen.add_argument("--north-m", type=float, default=0.0, help="metres north of the observer")
    seen.add_argument(
        "--height-m", type=float, default=2.5, help="metres over the ground (default 2.5)"
    )
    seen.add_argument("--runway", help="a runway designator (14, 32L): its touchdown zone")
    seen.add_argument("--json", action="store_true", help="the answer as one JSON object")
    add_control_option(seen)
    seen.set_defaults(func=_cmd_visibility)
    rvr = wsub.add_parser(
        "rvr",
        help="the runway visual range at a runway's touchdown zone",
        description="The runway visual range at each runway's touchdown zone, from the fog "
        "the running daemon draws (docs/fog.md: a runway of 3 km on the field along its "
        "designator's heading).",
    )
    rvr.add_argument("runway", nargs="+", help="runway designators, e.g. 14 32L")
    rvr.add_argument("--json", action="store_true", help="the answers as JSON, one a line")
    add_control_option(rvr)
    rvr.set_defaults(func=_cmd_rvr)


def parse_layer(text: str) -> dict[str, Any]:
    """A --layer value as a preset's layer table; ValueError with what is wrong."""
    parts = text.split(":")
    if len(parts) != 4:
        raise ValueError(f"--layer {text!r}: give {LAYER_HELP}")
    kind, oktas, base, top = parts
    try:
        return {
            "type": kind.strip().lower(),
            "cover_oktas": int(oktas),
            "base_m": float(base),
            "top_m": float(top),
        }
    except ValueError:
        raise ValueError(
            f"--layer {text!r}: OKTAS is a whole number, BASE_M and TOP_M numbers"
        ) from None


def request_params(args: argparse.Namespace) -> dict[str, Any]:
    """The `set_weather` request the options ask for; ValueError when they ask for nothing
    or for two contrary things."""
    params: dict[str, Any] = {}
    if args.layer and args.no_layers:
        raise ValueError("--layer and --no-layers: give one of them")
    if args.layer:
        params["layers"] = [parse_layer(text) for text in args.layer]
    elif args.no_layers:
        params["layers"] = []
    for option, key in (
        ("visibility_m", "visibility_m"),
        ("temperature_c", "temperature_c"),
        ("dewpoint_c", "dewpoint_c"),
        ("qnh_hpa", "qnh_hpa"),
        ("present_weather", "present_weather"),
    ):
        value = getattr(args, option)
        if value is not None:
            params[key] = value
    fog = fog_params(args)
    if fog is not None:
        params["fog"] = fog
    if not params:
        raise ValueError(
            "nothing to set: give --visibility-m, --layer, --no-layers, --temperature-c, "
            "--dewpoint-c, --qnh-hpa, --present-weather, --fog-visibility-m, --rvr or --no-fog"
        )
    params["now"] = args.now
    return params


def parse_rvr(text: str) -> dict[str, Any]:
    """An --rvr value as a fog's rvr table; ValueError with what is wrong (the daemon's
    checker judges the runway and the range)."""
    runway, sep, metres = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return {"runway": runway.strip().upper(), "rvr_m": float(metres)}
    except ValueError:
        raise ValueError(f"--rvr {text!r}: give {RVR_HELP}") from None


def fog_params(args: argparse.Namespace) -> dict[str, Any] | None:
    """The `fog` table the fog options ask for, None when they ask for none."""
    asked = (
        args.fog_visibility_m is not None
        or args.fog_depth_m is not None
        or args.patchy_fog
        or args.rvr
    )
    if args.no_fog:
        if asked:
            raise ValueError("--no-fog and a fog option: give one of them")
        return {}
    if not asked:
        return None
    fog: dict[str, Any] = {"patchy": bool(args.patchy_fog)}
    if args.fog_visibility_m is not None:
        fog["visibility_m"] = args.fog_visibility_m
    if args.fog_depth_m is not None:
        fog["depth_m"] = args.fog_depth_m
    if args.rvr:
        fog["rvr"] = [parse_rvr(text) for text in args.rvr]
    return fog


def _cmd_visibility(args: argparse.Namespace) -> int:
    from wxsky.host.client import ControlClient

    params: dict[str, Any] = {"height_m": args.height_m}
    if args.runway is not None:
        params["runway"] = args.runway.strip().upper()
    else:
        params |= {"east_m": args.east_m, "north_m": args.north_m}
    with ControlClient.connect(control_address(args)) as client:
        answer = client.call("visibility", params)
    _show(answer, args.json)
    return 0


def _cmd_rvr(args: argparse.Namespace) -> int:
    from wxsky.host.client import ControlClient

    with ControlClient.connect(control_address(args)) as client:
        for name in args.runway:
            _show(client.call("visibility", {"runway": name.strip().upper()}), args.json)
    return 0


def _show(answer: Any, as_json: bool) -> None:
    if as_json:
        print(json.dumps(answer))
        return
    where = (
        f"runway {answer['runway']} touchdown zone"
        if "runway" in answer
        else f"{answer['east_m']:.0f} m east, {answer['north_m']:.0f} m north"
    )
    print(
        f"{where}: visibility {answer['visibility_m']:.0f} m at {answer['height_m']:.1f} m, "
        f"RVR {answer['rvr_m']:.0f} m{' (in fog)' if answer['in_fog'] else ''}"
    )


def _cmd_set(args: argparse.Namespace) -> int:
    from wxsky.host.client import ControlClient

    try:
        params = request_params(args)
    except ValueError as exc:
        print(f"wxsky weather set: {exc}", file=sys.stderr)
        return EXIT_USAGE
    address = control_address(args)
    with ControlClient.connect(address) as client:
        fields = client.call("set_weather", params)
    how = "at once" if args.now else "at the [transition] rates"
    shown = ", ".join(str(f) for f in fields) if isinstance(fields, list) else str(fields)
    print(f"set {shown} on the daemon at {address} (held until 'wxsky preset release'), {how}")
    return 0
