"""The `wxsky` command line. Errors a user can fix print one line and exit with status 2.

Each command group lives in its own module and adds its subparsers through `add_commands`:
`daemon_cmd` (run, status, snapshot), `metar_cmd` (metar ...), `preset_cmd` (preset ...),
`sun_cmd` (sun), `bench_cmd` (bench).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from wxsky import __version__
from wxsky.cli import bench_cmd, daemon_cmd, metar_cmd, preset_cmd, sun_cmd
from wxsky.cli.common import EXIT_USAGE, parse_size
from wxsky.errors import WxskyError

__all__ = ["EXIT_USAGE", "main", "parse_size"]


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        result: int = args.func(args)
        return result
    except (WxskyError, ValueError) as exc:
        print(f"wxsky: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:
        return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="wxsky", description="Flight-simulator weather and cloud daemon"
    )
    p.add_argument("--version", action="version", version=f"wxsky {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    daemon_cmd.add_commands(sub)
    preset_cmd.add_commands(sub)
    metar_cmd.add_commands(sub)
    sun_cmd.add_commands(sub)
    bench_cmd.add_commands(sub)
    return p
