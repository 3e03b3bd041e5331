"""`wxsky weather set`: an instructor's weather, set directly on a running daemon (the
control channel's `set_weather`): visibility, cloud layers (base, top, cover), wind,
temperature, dewpoint, QNH and present weather, held until `wxsky preset release`."""

from __future__ import annotations

import argparse
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
    put.add_argument("--now", action="store_true", help="switch the sky at once")
    add_control_option(put)
    put.set_defaults(func=_cmd_set)


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
    if not params:
        raise ValueError(
            "nothing to set: give --visibility-m, --layer, --no-layers, --temperature-c, "
            "--dewpoint-c, --qnh-hpa or --present-weather"
        )
    params["now"] = args.now
    return params


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
