"""Helpers shared by the CLI's command modules."""

from __future__ import annotations

import argparse
import logging
import re
from typing import Any

EXIT_USAGE = 2

# The type of `ArgumentParser.add_subparsers()`'s result, for the modules' add_commands.
Subparsers = Any


def parse_size(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d{1,5})\s*[xX]\s*(\d{1,5})\s*", text)
    if not m:
        raise ValueError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 960x540")
    w, h = int(m.group(1)), int(m.group(2))
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise ValueError(f"--size {text!r}: width and height must be in 16..8192")
    return w, h


def setup_logging(level: str) -> None:
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s %(levelname)-7s %(name)s: %(message)s",
        datefmt="%H:%M:%S",
    )


def control_address(args: argparse.Namespace) -> Any:
    """The daemon address from `--control`, else the user's default socket."""
    from wxsky.output.transport import default_address, parse_address

    return parse_address(args.control) if args.control else default_address()
