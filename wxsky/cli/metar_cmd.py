"""`wxsky metar ...`: decode reports and try feeds."""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime

from wxsky.cli.common import Subparsers


def add_commands(sub: Subparsers) -> None:
    metar = sub.add_parser("metar", help="METAR tools")
    msub = metar.add_subparsers(dest="metar_command", required=True)
    dec = msub.add_parser("decode", help="decode one report")
    dec.add_argument("report")
    # A report names only its day; one typed on the command line is most likely current.
    now = datetime.now(UTC)
    dec.add_argument("--year", type=int, default=now.year, help="default: the current UTC year")
    dec.add_argument("--month", type=int, default=now.month, help="default: the current UTC month")
    dec.add_argument("--json", action="store_true", help="print the decoded fields as JSON")
    dec.set_defaults(func=_cmd_decode)


def _cmd_decode(args: argparse.Namespace) -> int:
    from wxsky.weather.metar import decode

    if not 1 <= args.month <= 12:
        raise ValueError(f"--month {args.month} is not a month (1..12)")
    report = decode(args.report, year=args.year, month=args.month)
    if report.station is None or report.time_utc is None:
        # Nothing a user could mean as a report; a partial body or a NIL report still prints.
        report.require_usable()
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
    else:
        print(report.describe())
    return 0
