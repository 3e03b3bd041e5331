"""The `wxsky` command line.

Exit status: 0 on success; 2 for a usage error (a bad option or value, an unknown preset, a
file that is wrong), one line on stderr; 1 for a runtime failure (no daemon at the address, a
feed that cannot be read, no GL context), one line too, and for an internal error (a bug: any
exception that is not a WxskyError), one line or with -v its traceback; 130 when Ctrl-C
interrupts a command, as a shell reports a process killed by SIGINT. `wxsky run` is the
exception: the daemon catches SIGINT and SIGTERM, shuts down cleanly and exits 0, as an
operator stopping a service expects; a second Ctrl-C forces it out with 130.

A command that may take a while (snapshot, bench, metar fetch) shows what it is doing on a
line of stderr when stderr is a terminal (`common.Progress`), and nothing otherwise.

Each command group lives in its own module and adds its subparsers through `add_commands`:
`daemon_cmd` (run, status, snapshot), `metar_cmd` (metar ...), `preset_cmd` (preset ...),
`sun_cmd` (sun), `bench_cmd` (bench), `cigi_cmd` (cigi ...), `grib_cmd` (grib ...).
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from collections.abc import Sequence

from wxsky import __version__
from wxsky.cli import (
    bench_cmd,
    cigi_cmd,
    daemon_cmd,
    grib_cmd,
    metar_cmd,
    preset_cmd,
    sun_cmd,
    weather_cmd,
)
from wxsky.cli.common import (
    DEFAULT_LOG_LEVEL,
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    LOGGING_DEFAULTS,
    Parser,
    Progress,
    log_level,
    logging_to_stderr,
    parse_size,
    show_help,
)
from wxsky.errors import RuntimeFailure, WxskyError

__all__ = ["EXIT_FAILURE", "EXIT_USAGE", "build_parser", "exit_status", "main", "parse_size"]


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except WxskyError as exc:  # Parser.error and the option types raise UsageError
        _print_error(exc)
        return EXIT_USAGE
    except SystemExit as exc:  # --help and --version: printed, and argparse wants out
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    for name, default in LOGGING_DEFAULTS.items():
        if not hasattr(args, name):
            setattr(args, name, default)
    with logging_to_stderr(log_level(args, DEFAULT_LOG_LEVEL)):
        return _run(args)


def _print_error(exc: WxskyError) -> None:
    # A file with several problems reports each on its own line, each a whole error.
    for line in str(exc).splitlines() or [""]:
        print(f"wxsky: error: {line}", file=sys.stderr)


def _run(args: argparse.Namespace) -> int:
    # Every command may report what it is doing (`args.progress(...)`); the line is erased
    # before anything else is printed, a result or an error.
    args.progress = Progress(_command_name(args))
    try:
        try:
            result: int = args.func(args)
        finally:
            args.progress.done()
        return result
    except WxskyError as exc:
        if args.debug:
            traceback.print_exc()
        _print_error(exc)
        return exit_status(exc)
    except KeyboardInterrupt:
        print("wxsky: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader of our output went away (`| head`): not a failure. Later writes, and the
        # interpreter's flush at exit, must not fail again on the closed pipe.
        _silence_stdout()
        return EXIT_OK
    except Exception as exc:
        if args.verbose or args.debug:
            traceback.print_exc()
            print(f"wxsky: internal error: {_describe(exc)}", file=sys.stderr)
        else:
            print(
                f"wxsky: internal error: {_describe(exc)} (a bug in wxsky; rerun with -v for "
                "the traceback)",
                file=sys.stderr,
            )
        return EXIT_FAILURE


def _command_name(args: argparse.Namespace) -> str:
    words = [args.command] if getattr(args, "command", None) else []
    for group in (
        "metar_command",
        "preset_command",
        "cigi_command",
        "weather_command",
        "grib_command",
    ):
        word = getattr(args, group, None)
        if word:
            words.append(word)
    return " ".join(words) or "wxsky"


def exit_status(exc: WxskyError) -> int:
    """1 for a runtime failure, 2 for a user error."""
    from wxsky.host.client import RemoteError

    if isinstance(exc, RuntimeFailure):
        return EXIT_FAILURE
    # A daemon reports its own bugs this way (docs/protocol.md §2.5); its other refusals are
    # about the request: an unknown preset, a bad value.
    if isinstance(exc, RemoteError) and str(exc).startswith("internal error"):
        return EXIT_FAILURE
    return EXIT_USAGE


def _describe(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _silence_stdout() -> None:
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass  # not a real file (a test's capture): nothing will flush it at exit


def build_parser() -> argparse.ArgumentParser:
    p = Parser(
        prog="wxsky",
        description="Flight-simulator weather and cloud daemon. Run 'wxsky COMMAND --help' for "
        "a command's options.",
        epilog="Exit status: 0 success, 1 runtime failure (no daemon, unreadable feed) or "
        "internal error, 2 usage error (bad option, unknown preset, bad file), 130 interrupted "
        "by Ctrl-C ('wxsky run' shuts down cleanly on Ctrl-C or SIGTERM and exits 0).",
    )
    p.add_argument("--version", action="version", version=f"wxsky {__version__}")
    p.set_defaults(func=show_help(p))
    sub = p.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    daemon_cmd.add_commands(sub)
    preset_cmd.add_commands(sub)
    metar_cmd.add_commands(sub)
    grib_cmd.add_commands(sub)
    sun_cmd.add_commands(sub)
    bench_cmd.add_commands(sub)
    cigi_cmd.add_commands(sub)
    weather_cmd.add_commands(sub)
    return p
