"""Helpers shared by the CLI's command modules: exit statuses, the parser every command is
built from (with the logging and verbosity options), option types whose limits come from the
settings' own kinds, and logging to stderr."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import math
import os
import re
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn, TextIO

from wxsky.errors import WxskyError
from wxsky.schema import Number, fmt_number

# The exit statuses (the package docstring says which is which). Scripts tell a mistake in the
# command from a failure while running by them, so every command uses these and no others.
EXIT_OK = 0
EXIT_FAILURE = 1  # the command was fine but failed while running (no daemon, unreadable feed)
EXIT_USAGE = 2  # something the user gave is wrong: an option, a preset name, a file's content
EXIT_DIFFERENT = 1  # `preset diff`: the presets differ, as diff(1) says it
EXIT_INTERRUPTED = 130  # Ctrl-C, as a shell reports a process killed by SIGINT

# Until a command sets its own (`run`: the config's [daemon] log_level).
DEFAULT_LOG_LEVEL = "WARNING"

# The type of `ArgumentParser.add_subparsers()`'s result, for the modules' add_commands.
Subparsers = Any


# What argparse takes for a negative number rather than an option (see Parser.__init__).
NEGATIVE_NUMBER = re.compile(r"-\.?\d")


class UsageError(WxskyError):
    """A bad command line: an option's value, a missing or conflicting option."""


# -- the parser ---------------------------------------------------------------------------------


class HelpFormatter(argparse.HelpFormatter):
    """Shows an option's limits and its default after its help, but no `default: None` or
    `default: False` noise: an option that defaults to nothing says in its help what happens."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if text == argparse.SUPPRESS:
            return text
        limits = action.type.describe() if isinstance(action.type, OptionType) else ""
        if limits:
            # Before an explicit "(default: ...)", so that the default stays last.
            at = text.rfind(" (default: ")
            if at >= 0 and text.endswith(")"):
                text = f"{text[:at]}, {limits}{text[at:]}"
            else:
                text = f"{text}, {limits}" if text else limits
        default = action.default
        # By identity: a default of 0 or 0.0 is worth showing, and it equals False.
        nothing = default is None or default is False or default is argparse.SUPPRESS
        shown = not nothing and default != [] and "default" not in text
        if shown and (action.option_strings or action.nargs in ("?", "*")):
            if isinstance(default, float):
                default = fmt_number(default)
            # The text is %-formatted by argparse next: a literal % must survive that.
            text += " (default: " + str(default).replace("%", "%%") + ")"
        return text or None


class Parser(argparse.ArgumentParser):
    """Every wxsky parser: the help shows defaults, a usage error is one line (the caller
    prints it and exits 2) instead of a usage dump and sys.exit, and every command takes
    --log-level, -v/--verbose and --debug, before or after its name."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        # A value that starts with '-' and a digit is a value, not an option: `--view-offset
        # -60,0,0`, `--lon -1e-3`, `--pitch-deg -5.` (argparse before Python 3.13 takes only
        # `-5` and `-5.0` so, and calls the rest an unknown option; 3.13 matches this). No
        # wxsky option is spelled like a negative number.
        self._negative_number_matcher = NEGATIVE_NUMBER
        add_logging_options(self)

    def error(self, message: str) -> NoReturn:
        raise UsageError(f"{message} (see '{self.prog} --help')")


def add_logging_options(p: argparse.ArgumentParser) -> None:
    # SUPPRESS: a subcommand's copy of an option must not overwrite what was given before the
    # subcommand's name (`wxsky -v status`); main fills in the defaults after parsing.
    g = p.add_argument_group("output and diagnostics")
    g.add_argument(
        "--log-level",
        type=LogLevel(),
        metavar="LEVEL",
        default=argparse.SUPPRESS,
        help="log this level and above to stderr (default: "
        f"{DEFAULT_LOG_LEVEL}; for 'run' the config's [daemon] log_level)",
    )
    g.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=argparse.SUPPRESS,
        help="log at DEBUG (unless --log-level says otherwise) and print the traceback of an "
        "internal error instead of one line",
    )
    g.add_argument(
        "--debug",
        action="store_true",
        default=argparse.SUPPRESS,
        help="as -v, and print the traceback of every error, a user error's too",
    )


LOGGING_DEFAULTS: dict[str, Any] = {"log_level": None, "verbose": 0, "debug": False}


def show_help(parser: argparse.ArgumentParser) -> Callable[[argparse.Namespace], int]:
    """The action of a bare command group (`wxsky`, `wxsky metar`): its help, on stdout."""

    def run(args: argparse.Namespace) -> int:
        parser.print_help()
        return EXIT_OK

    return run


# -- option types -------------------------------------------------------------------------------


class OptionType:
    """An argparse `type` that names its option in its errors and raises UsageError, which
    argparse lets through to main, so the message is ours and one line. `describe` is the
    values it takes, for the help."""

    flag: str

    def describe(self) -> str:
        return ""

    def fail(self, text: str, problem: str) -> UsageError:
        return UsageError(f"{self.flag} {text}{problem}")


@dataclass(frozen=True)
class KindRef:
    """Where a limit's kind lives, `module:NAME`; imported only when an option of that kind
    is given or the help shows it, so that `wxsky status` need not load numpy and the config."""

    spec: str

    def get(self) -> Number:
        module, _, name = self.spec.partition(":")
        kind = getattr(importlib.import_module(module), name)
        if not isinstance(kind, Number):
            raise TypeError(f"{self.spec} is a {type(kind).__name__}, not a schema Number")
        return kind


def _resolve(kind: Number | KindRef) -> Number:
    return kind.get() if isinstance(kind, KindRef) else kind


def limits_text(kind: Number) -> str:
    if kind.lo is not None and kind.hi is not None:
        return f"{fmt_number(kind.lo)}..{fmt_number(kind.hi)}"
    if kind.lo is not None:
        return f"at least {fmt_number(kind.lo)}"
    if kind.hi is not None:
        return f"at most {fmt_number(kind.hi)}"
    return ""


class NumberArg(OptionType):
    """A number within a `wxsky.schema.Number` kind, the same the config or the camera checks
    against, so that an option cannot accept what the setting refuses or the other way round."""

    def __init__(self, flag: str, kind: Number | KindRef) -> None:
        self.flag = flag
        self._kind = kind

    @property
    def kind(self) -> Number:
        return _resolve(self._kind)

    def describe(self) -> str:
        return limits_text(self.kind)

    def __call__(self, text: str) -> float | int:
        kind = self.kind
        try:
            value: float | int = int(text) if kind.integer else float(text)
        except ValueError:
            what = "an integer" if kind.integer else "a number"
            raise self.fail(text, f" is not {what}") from None
        if not math.isfinite(value):
            raise self.fail(text, " is not a finite number")
        if not kind.contains(value):
            raise self.fail(text, f" is outside {limits_text(kind)}")
        return value


class Checked(OptionType):
    """A value parsed by `convert`, whose ValueError says what is wrong with it."""

    def __init__(self, flag: str, convert: Callable[[str], Any]) -> None:
        self.flag = flag
        self._convert = convert

    def __call__(self, text: str) -> Any:
        try:
            return self._convert(text)
        except ValueError as exc:
            message = str(exc)
            # Converters shared with the tools name the option themselves (parse_size).
            if message.startswith(self.flag):
                raise UsageError(message) from None
            if text in message:
                raise UsageError(f"{self.flag}: {message}") from None
            raise self.fail(repr(text), f": {message}") from None


class LogLevel(OptionType):
    flag = "--log-level"

    def describe(self) -> str:
        return "one of " + ", ".join(_log_levels())

    def __call__(self, text: str) -> str:
        level = text.strip().upper()
        if level not in _log_levels():
            raise self.fail(text, f" is not a log level ({', '.join(_log_levels())})")
        return level


def _log_levels() -> tuple[str, ...]:
    from wxsky.settings.config import LOG_LEVELS

    return tuple(LOG_LEVELS)


class SizeArg(Checked):
    def __init__(self, flag: str = "--size") -> None:
        super().__init__(flag, parse_size)

    def describe(self) -> str:
        from wxsky.scene.camera import VIEWPORT_PX

        return f"width and height {limits_text(VIEWPORT_PX)}"


def size_arg(flag: str = "--size") -> SizeArg:
    return SizeArg(flag)


def parse_size(text: str) -> tuple[int, int]:
    """`WIDTHxHEIGHT` in pixels, each within the camera's VIEWPORT_PX (ValueError otherwise:
    the tools use this too)."""
    from wxsky.scene.camera import VIEWPORT_PX

    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise ValueError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 960x540")
    w, h = int(m.group(1)), int(m.group(2))
    for name, value in (("width", w), ("height", h)):
        if not VIEWPORT_PX.contains(value):
            raise ValueError(
                f"--size {text.strip()}: {name} must be {limits_text(VIEWPORT_PX)} px, got {value}"
            )
    return w, h


def time_arg(flag: str = "--time") -> Checked:
    return Checked(flag, _parse_time)


def _parse_time(text: str) -> Any:
    from wxsky.weather.state import parse_time_utc

    return parse_time_utc(text)


class OutputFile(OptionType):
    """A file to write, in a directory that exists (a typo in the path is an error before any
    work is done, not a tree of new folders), with `suffix` when one is given (a name that
    promises another format must not get PNG data); `suffix` may be several, one a format
    the command writes by the name's suffix."""

    def __init__(self, flag: str, suffix: str | tuple[str, ...] | None = None) -> None:
        self.flag = flag
        self.suffix = suffix
        self._suffixes = (suffix,) if isinstance(suffix, str) else (suffix or ())

    def describe(self) -> str:
        kind = f"a {' or '.join(self._suffixes)} file" if self._suffixes else "a file"
        return f"{kind} in an existing directory"

    def __call__(self, text: str) -> Path:
        path = Path(text)
        if self._suffixes and path.suffix.lower() not in self._suffixes:
            if len(self._suffixes) == 1:
                fmt = self._suffixes[0].lstrip(".").upper()
                raise self.fail(
                    text, f": {fmt} is written: give a name ending in {self._suffixes[0]}"
                )
            raise self.fail(text, f": give a name ending in {' or '.join(self._suffixes)}")
        if path.is_dir():
            raise self.fail(text, ": is a directory: give a file name")
        _check_directory(self, text, path.parent)
        return path


class OutputDir(OptionType):
    """A directory to write files into: one that exists, or a new one inside a directory that
    exists (made when the command writes; as mkdir, not mkdir -p)."""

    def __init__(self, flag: str) -> None:
        self.flag = flag

    def describe(self) -> str:
        return "made if missing, in an existing directory"

    def __call__(self, text: str) -> Path:
        path = Path(text)
        if path.is_dir():
            _check_directory(self, text, path)
        elif path.exists():
            raise self.fail(text, ": is not a directory")
        else:
            _check_directory(self, text, path.parent)
        return path


def _check_directory(option: OptionType, text: str, directory: Path) -> None:
    shown = str(directory)
    if not directory.exists():
        raise option.fail(text, f": directory {shown} does not exist (create it first)")
    if not directory.is_dir():
        raise option.fail(text, f": {shown} is not a directory")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise option.fail(text, f": directory {shown} is not writable")


# -- progress -----------------------------------------------------------------------------------

PROGRESS_INTERVAL_S = 0.25  # how often the line is redrawn (the seconds shown change each 1 s)
_TERMINAL_LOCK = threading.Lock()  # the progress line and log records share stderr
_showing: Progress | None = None  # the progress whose line is on the terminal now


class Progress:
    """What a long command is doing, on one line of stderr rewritten in place while it works:
    `wxsky: snapshot: drawing the far clouds (14 s)`, erased when it is done. Only on a
    terminal: a pipe or a file gets nothing, so scripts and logs see only the command's own
    output. Call it with what is being done now (from any thread); `done()` erases the line
    (a command calls it before printing its result; `main` calls it at the end whatever
    happens). Nothing runs until the first call."""

    def __init__(self, command: str, stream: TextIO | None = None) -> None:
        self.command = command
        self._stream = stream if stream is not None else sys.stderr
        self._enabled = _is_terminal(self._stream)
        self._what = ""
        self._start_s = 0.0
        self._shown = ""  # the text on the terminal now
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def enabled(self) -> bool:
        return self._enabled

    def __call__(self, what: str) -> None:
        if not self._enabled or self._stop.is_set():
            return
        # Only noted: the thread shows it at its next tick, so a caller may say something
        # every frame at no cost.
        self._what = what
        if self._thread is None:
            self._start_s = time.monotonic()
            self._draw()  # at once; the thread keeps the line up to date from here
            self._thread = threading.Thread(target=self._run, name="wxsky-progress", daemon=True)
            self._thread.start()

    def done(self) -> None:
        """Erase the line and stop. Idempotent; later calls show nothing."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        with _TERMINAL_LOCK:
            self._erase_locked()

    def _run(self) -> None:
        while not self._stop.wait(PROGRESS_INTERVAL_S):
            self._draw()

    def _draw(self) -> None:
        global _showing
        seconds = int(time.monotonic() - self._start_s)
        text = f"wxsky: {self.command}: {self._what} ({seconds} s)"
        width = _terminal_width(self._stream)
        if len(text) >= width:  # a line that wraps cannot be rewritten in place
            text = text[: max(width - 2, 1)] + "…"
        with _TERMINAL_LOCK:
            if self._stop.is_set() or text == self._shown:
                return
            try:
                self._stream.write("\r\x1b[K" + text)
                self._stream.flush()
            except (OSError, ValueError):
                self._enabled = False  # the terminal went away: nothing more to show
                return
            self._shown = text
            _showing = self

    def _erase_locked(self) -> None:
        global _showing
        if _showing is self:
            _showing = None
        if not self._shown:
            return
        self._shown = ""
        with contextlib.suppress(OSError, ValueError):
            self._stream.write("\r\x1b[K")
            self._stream.flush()


def _is_terminal(stream: TextIO) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # a closed stream, or no stream at all
        return False


def _terminal_width(stream: TextIO) -> int:
    try:
        return os.get_terminal_size(stream.fileno()).columns or 80
    except (AttributeError, OSError, ValueError):
        return 80


class _StderrHandler(logging.StreamHandler):  # type: ignore[type-arg]
    """Log records to stderr, on a line of their own: a progress line there is erased first
    (and drawn again by its next tick)."""

    def emit(self, record: logging.LogRecord) -> None:
        with _TERMINAL_LOCK:
            if _showing is not None:
                _showing._erase_locked()
            super().emit(record)


# -- logging ------------------------------------------------------------------------------------


def log_level(args: argparse.Namespace, default: str) -> str:
    """The level the options ask for: --log-level, else DEBUG with -v/--debug, else `default`."""
    if args.log_level:
        return str(args.log_level)
    return "DEBUG" if args.verbose or args.debug else default


def setup_logging(level: str) -> None:
    logging.getLogger().setLevel(getattr(logging, level.upper(), logging.INFO))


@contextlib.contextmanager
def logging_to_stderr(level: str) -> Iterator[None]:
    """Log records to stderr for the length of a command, then leave logging as it was (the
    tests call main in-process, many times)."""
    root = logging.getLogger()
    handler = _StderrHandler(sys.stderr)
    handler.setFormatter(
        logging.Formatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s", "%H:%M:%S")
    )
    before = root.level
    root.addHandler(handler)
    setup_logging(level)
    try:
        yield
    finally:
        root.removeHandler(handler)
        root.setLevel(before)


# -- the daemon ---------------------------------------------------------------------------------


def control_address(args: argparse.Namespace) -> Any:
    """The daemon address from `--control`, else the user's default socket."""
    from wxsky.output.transport import default_address, parse_address

    return parse_address(args.control) if args.control else default_address()


def add_control_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--control",
        metavar="ADDR",
        help="the daemon's address, unix:PATH or tcp:127.0.0.1:PORT (default: "
        "$XDG_RUNTIME_DIR/wxsky/wxsky.sock)",
    )
