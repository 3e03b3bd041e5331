"""`wxsky cigi send`: a running daemon's applied weather, sent to a CIGI 3.3 image generator
as a host sends it (`protocols.cigi_source.host_message`), with the IG's answers read back.

The weather is the daemon's status `weather`, then each `weather` notification; the clock is
each `frame` notification's time, so the IG's clock follows the daemon's between changes of
weather. Every message is the whole weather (docs/cigi.md, "CIGI source").
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from wxsky.cli.common import (
    Checked,
    NumberArg,
    Subparsers,
    UsageError,
    add_control_option,
    control_address,
    show_help,
)
from wxsky.schema import Number

if TYPE_CHECKING:
    from wxsky.host.client import ControlClient
    from wxsky.inputs.cigi_link import Address, CigiHostSocket
    from wxsky.protocols.cigi import ByteOrder
    from wxsky.protocols.cigi_source import SourceFrame
    from wxsky.weather.state import WeatherState

# The ceiling is the config's [cigi] send_rate_hz's; there 0 means "every frame", here there
# are no frames of our own.
RATE_HZ = Number(0.1, 240.0, unit="Hz")
COUNT = Number(1, 2**32 - 1, integer=True)
SECONDS = Number(0.01, 31_536_000.0, unit="s")
REPORT_EVERY_S = 1.0
# One read of the control channel between messages waits this long for more notifications.
NOTIFICATION_WAIT_S = 0.001
MAX_NOTIFICATIONS_PER_MESSAGE = 1000  # a daemon flooding the channel still lets us send
TOPICS = ("weather", "frame")
# A daemon whose messages this command cannot read is most likely another wxsky's.
OTHER_VERSION_HINT = "is it another wxsky version? run the daemon's own `wxsky cigi send`"


def add_commands(sub: Subparsers) -> None:
    cigi = sub.add_parser("cigi", help="CIGI 3.3 tools")
    cigi.set_defaults(func=show_help(cigi))
    csub = cigi.add_subparsers(dest="cigi_command", metavar="COMMAND", title="commands")
    send = csub.add_parser(
        "send",
        help="send a running daemon's weather to a CIGI image generator",
        description="Send a running daemon's applied weather (layers, precipitation, time, "
        "atmosphere) to a CIGI 3.3 image generator as a host does, following its changes, "
        "and read the IG's Start of Frame and Weather Conditions Responses; prints a line a "
        "second. Runs until Ctrl-C (exit 130), --count or --seconds; exits 1 when no daemon "
        "answers at the address or it goes away.",
    )
    send.add_argument(
        "--to",
        required=True,
        type=Checked("--to", _udp("--to")),
        metavar="udp:HOST:PORT",
        help="the image generator's address, e.g. udp:127.0.0.1:8000 (CCL's example IG's port)",
    )
    send.add_argument(
        "--bind",
        type=Checked("--bind", _udp("--bind")),
        metavar="udp:HOST:PORT",
        help="send from, and read the IG's answers on, this address (default: any free port, "
        "on loopback for an IG on loopback, else on every interface; CCL's example IG "
        "answers to port 8001)",
    )
    send.add_argument(
        "--rate-hz",
        type=NumberArg("--rate-hz", RATE_HZ),
        default=30.0,
        metavar="N",
        help="messages a second",
    )
    send.add_argument(
        "--byte-order",
        choices=("big", "little"),
        default="big",
        help="the byte order of the messages (an IG reads either)",
    )
    add_control_option(send)
    stop = send.add_mutually_exclusive_group()
    stop.add_argument(
        "--count",
        type=NumberArg("--count", COUNT),
        metavar="N",
        help="stop after N messages (default: run until Ctrl-C)",
    )
    stop.add_argument(
        "--seconds",
        type=NumberArg("--seconds", SECONDS),
        metavar="S",
        help="stop after S seconds (default: run until Ctrl-C)",
    )
    send.add_argument(
        "--json", action="store_true", help="print one JSON object a second instead of a line"
    )
    send.set_defaults(func=_cmd_send)


def _udp(flag: str) -> Callable[[str], Address]:
    def parse(text: str) -> Address:
        from wxsky.inputs.cigi_link import parse_udp

        # Its ConfigError is a usage error, naming the option.
        address = parse_udp(text, flag)
        if flag == "--to" and address[1] == 0:
            raise UsageError(f"--to {text!r}: an IG listens on a port of 1..65535, not 0")
        return address

    return parse


def _cmd_send(args: argparse.Namespace) -> int:
    from wxsky.host.client import ControlClient
    from wxsky.inputs.cigi_link import CigiHostSocket

    address = control_address(args)
    with ControlClient.connect(address) as client:
        # Subscribed before the status is read: no change after it is missed.
        client.subscribe(TOPICS)
        status = client.call("status")
        weather = status.get("weather") if isinstance(status, dict) else None
        state = _state(weather, f"the daemon at {address}")
        # Without --bind the socket picks loopback for an IG on loopback, every interface else.
        with CigiHostSocket(args.to, args.bind) as sock:
            sender = _Sender(args, client, sock, state)
            if not args.json:
                host, port = sock.address
                print(
                    f"sending the weather of the daemon at {address} to the IG at "
                    f"udp:{args.to[0]}:{args.to[1]} from {host}:{port}, "
                    f"{args.rate_hz:g} messages a second, {args.byte_order}-endian",
                    flush=True,
                )
            sender.run()
    return 0


def _state(weather: Any, where: str) -> WeatherState:
    from wxsky.host.client import DaemonUnavailable
    from wxsky.weather.state import weather_from_dict

    if not isinstance(weather, dict):
        raise DaemonUnavailable(f"{where} sent no weather; {OTHER_VERSION_HINT}")
    try:
        return weather_from_dict(weather)
    except (KeyError, TypeError, ValueError) as exc:
        raise DaemonUnavailable(
            f"{where} sent weather wxsky cannot read: {exc!r}; {OTHER_VERSION_HINT}"
        ) from None


@dataclass
class _Counts:
    sent: int = 0
    send_errors: int = 0
    start_of_frame: int = 0
    responses: int = 0
    other: int = 0  # datagrams that are no IG→host CIGI message
    weather_updates: int = 0


class _Sender:
    """The send loop: a message every 1/rate s, the IG's answers read in between, the
    daemon's notifications taken before each message, a report every second."""

    def __init__(
        self,
        args: argparse.Namespace,
        client: ControlClient,
        sock: CigiHostSocket,
        state: WeatherState,
    ) -> None:
        from wxsky.protocols.cigi_source import SourceFrame

        self.client = client
        self.sock = sock
        self.state = state
        self.period_s = 1.0 / float(args.rate_hz)
        self.byte_order: ByteOrder = "little" if args.byte_order == "little" else "big"
        self.count: int | None = args.count
        self.seconds: float | None = args.seconds
        self.json: bool = args.json
        self.where = f"the daemon at {client.address}"
        self.frame: SourceFrame = SourceFrame()
        self.counts = _Counts()
        self.last_send_error = ""
        self.start = time.monotonic()

    def run(self) -> None:
        start = self.start
        next_send, next_report = start, start + REPORT_EVERY_S
        end = None if self.seconds is None else start + self.seconds
        try:
            while True:
                now = time.monotonic()
                if end is not None and now >= end:
                    break
                if self.count is not None and self.counts.sent >= self.count:
                    # The last message's answers have had a message period to come.
                    if now >= next_send:
                        break
                elif now >= next_send:
                    self._take_notifications()
                    self._send()
                    # Late: the next one at once, but no backlog caught up.
                    next_send = max(next_send + self.period_s, now)
                if now >= next_report:
                    self._report(now)
                    next_report = max(next_report + REPORT_EVERY_S, now)
                wake = min(next_send, next_report, end if end is not None else next_send)
                self._hear(wake - time.monotonic())
        except KeyboardInterrupt:
            self._report(time.monotonic())
            raise
        self._report(time.monotonic())

    def _take_notifications(self) -> None:
        for _ in range(MAX_NOTIFICATIONS_PER_MESSAGE):
            note = self.client.next_notification(timeout_s=NOTIFICATION_WAIT_S)
            if note is None:
                return
            if note.method == "weather":
                self.state = _state(note.params, self.where)
                self.counts.weather_updates += 1
            elif note.method == "frame":
                self.state = _at_frame_time(self.state, note.params, self.where)

    def _send(self) -> None:
        from wxsky.protocols.cigi_source import host_message

        self.frame = self.frame.next()
        try:
            self.sock.send(host_message(self.state, self.frame), self.byte_order)
        except OSError as exc:
            self.counts.send_errors += 1
            self.last_send_error = exc.strerror or str(exc)
        self.counts.sent += 1

    def _hear(self, timeout_s: float) -> None:
        """The IG's answers, until timeout_s has passed (at least those already there)."""
        deadline = time.monotonic() + max(0.0, timeout_s)
        while True:
            got = self.sock.receive(deadline - time.monotonic())
            if got is None:
                return
            decoded, _ = got
            if decoded.refused or decoded.direction != "ig_to_host":
                self.counts.other += 1
                continue
            for p in decoded.packets:
                if p.key == "start_of_frame":
                    self.counts.start_of_frame += 1
                elif p.key == "weather_conditions_response":
                    self.counts.responses += 1
            self.frame = self.frame.heard(decoded)
            if time.monotonic() >= deadline:  # an IG that never pauses still lets us send
                return

    def _report(self, now: float) -> None:
        from wxsky.weather.state import format_time_utc

        c, f = self.counts, self.frame
        if self.json:
            line = {
                "elapsed_s": round(now - self.start, 3),
                **dataclasses.asdict(c),
                "last_send_error": self.last_send_error or None,
                "last_ig_frame": f.last_ig_frame,
                "last_response": f.last_response,
                "time_utc": format_time_utc(self.state.time_utc),
            }
            print(json.dumps(line), flush=True)
            return
        ig_frame = "-" if f.last_ig_frame is None else str(f.last_ig_frame)
        text = (
            f"sent {c.sent}, Start of Frame {c.start_of_frame}, last IG frame {ig_frame}, "
            f"last response {_response_text(f.last_response)}"
        )
        if c.send_errors:
            text += f", {c.send_errors} send errors ({self.last_send_error})"
        if c.other:
            text += f", {c.other} datagrams that are no IG answer"
        print(text, flush=True)


def _at_frame_time(state: WeatherState, params: Any, where: str) -> WeatherState:
    from wxsky.host.client import DaemonUnavailable
    from wxsky.weather.state import parse_time_utc

    try:
        when = parse_time_utc(str(params["time_utc"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise DaemonUnavailable(
            f"{where} sent a frame without a time: {exc!r}; {OTHER_VERSION_HINT}"
        ) from None
    return dataclasses.replace(state, time_utc=when)


def _response_text(response: dict[str, Any] | None) -> str:
    if response is None:
        return "none"
    r = response
    return (
        f"#{r['request_id']}: {r['temperature_c']:.1f} °C, humidity {r['humidity_pct']} %, "
        f"visibility {r['visibility_m']:.0f} m, wind {r['wind_dir_deg']:03.0f}° "
        f"{r['wind_speed_mps']:.1f} m/s, {r['pressure_hpa']:.1f} hPa"
    )
