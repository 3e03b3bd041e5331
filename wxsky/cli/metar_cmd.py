"""`wxsky metar ...`: decode reports and try feeds."""

from __future__ import annotations

import argparse
import json

from wxsky.cli.common import Subparsers


def add_commands(sub: Subparsers) -> None:
    metar = sub.add_parser("metar", help="METAR tools")
    msub = metar.add_subparsers(dest="metar_command", required=True)
    dec = msub.add_parser("decode", help="decode one report")
    dec.add_argument("report")
    dec.add_argument("--json", action="store_true")
    dec.set_defaults(func=_cmd_decode)


def _cmd_decode(args: argparse.Namespace) -> int:
    from wxsky.weather.metar import decode_metar

    report = decode_metar(args.report)
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
    else:
        print(report.describe())
    return 0
