"""`wxsky metar ...`: decode reports and files, and try a feed the way the daemon reads it."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Iterable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from wxsky.cli.common import (
    EXIT_FAILURE,
    EXIT_OK,
    KindRef,
    NumberArg,
    Subparsers,
    UsageError,
    show_help,
)
from wxsky.schema import Number

# "auto" and wxsky.weather.feeds.FORMATS (a test keeps them equal; importing feeds here would
# slow every command's start).
FORMAT_CHOICES = ("auto", "awc-csv", "awc-xml", "tgftp", "lines")
MONTH = Number(1, 12, integer=True)


def add_commands(sub: Subparsers) -> None:
    metar = sub.add_parser("metar", help="METAR tools")
    metar.set_defaults(func=show_help(metar))
    msub = metar.add_subparsers(dest="metar_command", metavar="COMMAND", title="commands")
    dec = msub.add_parser("decode", help="decode one report, or every report of a feed file")
    dec.add_argument("report", nargs="?", help="the report text (or use --file)")
    dec.add_argument("--file", type=Path, help="a feed file; prints one JSON object per report")
    dec.add_argument("--format", choices=FORMAT_CHOICES, default="auto", help="with --file")
    # A report names only its day; one typed on the command line is most likely recent.
    dec.add_argument(
        "--year",
        type=NumberArg("--year", Number(integer=True)),
        metavar="Y",
        help="for REPORT (default: the latest that puts the report at or before now, UTC)",
    )
    dec.add_argument(
        "--month",
        type=NumberArg("--month", MONTH),
        metavar="M",
        help="for REPORT (default: the latest that puts the report at or before now, UTC)",
    )
    dec.add_argument("--json", action="store_true", help="print the decoded fields as JSON")
    dec.set_defaults(func=_cmd_decode)

    fetch = msub.add_parser(
        "fetch", help="read a feed once and show what the daemon would take from it"
    )
    fetch.add_argument("source", help="a file, '-' for stdin, or an http(s) URL")
    fetch.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="daemon config: its [metar] settings and [daemon] preset (default: built-in)",
    )
    fetch.add_argument(
        "--format", choices=FORMAT_CHOICES, help="the feed's format (default: the config's)"
    )
    fetch.add_argument(
        "--lat",
        type=NumberArg("--lat", KindRef("wxsky.weather.state:LAT_DEG")),
        metavar="DEG",
        help="observer latitude, with --lon (default: the config's preset's)",
    )
    fetch.add_argument(
        "--lon",
        type=NumberArg("--lon", KindRef("wxsky.weather.state:LON_DEG")),
        metavar="DEG",
        help="observer longitude, with --lat (default: the config's preset's)",
    )
    fetch.add_argument(
        "--station", metavar="ICAO", help="use this station only (default: the config's)"
    )
    fetch.add_argument(
        "--blend",
        type=NumberArg("--blend", KindRef("wxsky.settings.config:BLEND_STATIONS")),
        metavar="N",
        help="blend the nearest N stations (default: the config's [metar] blend_stations)",
    )
    fetch.add_argument(
        "--age-reference",
        choices=("clock", "feed"),
        help="measure report age against the clock or the feed's newest report (default: the "
        "config's)",
    )
    fetch.add_argument("--json", action="store_true", help="print one JSON object")
    fetch.set_defaults(func=_cmd_fetch)


def add_field_elevation_option(p: argparse.ArgumentParser, report_flag: str) -> None:
    """`--field-elevation-m`, for a command that takes a METAR report as `report_flag`."""
    p.add_argument(
        "--field-elevation-m",
        type=NumberArg(
            "--field-elevation-m", KindRef("wxsky.weather.metar_clouds:FIELD_ELEVATION_M")
        ),
        metavar="M",
        help=f"with {report_flag}: the field elevation (MSL) the report's cloud bases are "
        "above (default: its station's, from wxsky's station table, as a METAR feed's report "
        "of that station is read)",
    )


def check_field_elevation(
    args: argparse.Namespace, report: str | None, report_flag: str
) -> float | None:
    """The --field-elevation-m given, which goes with a report only."""
    given: float | None = args.field_elevation_m
    if given is not None and not report:
        raise UsageError(f"--field-elevation-m goes with {report_flag}")
    return given


def _cmd_decode(args: argparse.Namespace) -> int:
    if (args.report is None) == (args.file is None):
        raise UsageError("give a REPORT or --file PATH (one of them)")
    if args.file is not None:
        return _decode_file(args.file, args.format)
    from wxsky.weather.metar import decode

    # Without --year/--month: the latest date not after now (decode's rule, never the future).
    report = decode(args.report, year=args.year, month=args.month)
    if report.station is None or report.time_group is None:
        # Nothing a user could mean as a report; a partial body, an impossible time (day 32) or
        # a NIL report still prints.
        report.require_usable()
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
    else:
        print(report.describe())
    return 0


def _decode_file(path: Path, fmt: str) -> int:
    """JSON Lines: every report of the feed, in feed order; feed problems go to stderr."""
    from wxsky.weather.feeds import read_feed
    from wxsky.weather.metar import decode

    feed = read_feed(path, format=fmt)
    for problem in feed.problems:
        print(f"wxsky: {problem.where}: {problem.reason}", file=sys.stderr)
    out = sys.stdout
    for report in feed.reports:
        data = decode(report.raw, year=report.year, month=report.month).to_dict()
        data["where"] = report.where
        out.write(json.dumps(data) + "\n")
    return 0


def _cmd_fetch(args: argparse.Namespace) -> int:
    from wxsky.errors import FeedTooLarge
    from wxsky.inputs.feed_sources import MAX_FEED_BYTES, Fetched, gunzip_if_needed, open_source
    from wxsky.inputs.metar_input import MetarSettings, ingest, select
    from wxsky.settings.config import load_config
    from wxsky.settings.presets import load_preset
    from wxsky.weather.feeds import parse_feed
    from wxsky.weather.state import WeatherState, weather_to_dict

    config = load_config(args.config)
    m = config.metar
    settings = dataclasses.replace(
        MetarSettings.from_section(m),
        format=args.format or m.format,
        age_reference=args.age_reference or m.age_reference,
        station=(args.station or m.station).upper(),
        blend_stations=args.blend or m.blend_stations,
    )
    if (args.lat is None) != (args.lon is None):
        raise UsageError("--lat and --lon go together")
    observer = WeatherState().apply(load_preset(config.daemon.preset, config.presets.dirs))
    lat = observer.observer.lat_deg if args.lat is None else args.lat
    lon = observer.observer.lon_deg if args.lon is None else args.lon
    if args.source == "-":
        args.progress("reading stdin")
        data = sys.stdin.buffer.read(MAX_FEED_BYTES + 1)
        if len(data) > MAX_FEED_BYTES:
            raise FeedTooLarge(f"stdin: over the {MAX_FEED_BYTES}-byte limit for a METAR feed")
        fetched: Fetched | None = Fetched(gunzip_if_needed(data, "stdin"), datetime.now(UTC))
    else:
        import asyncio

        # A one-shot read: the file is read as it is now, however recently it was written.
        source = open_source(args.source, timeout_s=m.http_timeout_s, settle_s=0.0)
        args.progress(f"reading {args.source}")
        # Read on this thread: Ctrl-C then stops the command at once, where the
        # daemon's way (a worker thread) would wait out the HTTP timeout first.
        fetch_now = getattr(source, "fetch_now", None)
        fetched = fetch_now() if fetch_now is not None else asyncio.run(source.fetch())
    assert fetched is not None  # a first fetch always returns data or raises
    args.progress(f"decoding {len(fetched.data):,} bytes of reports")
    feed = parse_feed(
        fetched.data,
        format=settings.format,
        name=args.source,
        reference_utc=fetched.reference_utc,
    )
    result = ingest(feed)
    args.progress.done()
    # A decoder defect on any report is a wxsky bug: the rest is shown, and the status says so.
    status = EXIT_FAILURE if result.internal_errors else EXIT_OK
    for defect in result.internal_errors:
        # A wxsky bug, not the feed's problem: on stderr, whatever the output format.
        print(f"wxsky: internal error: {defect}", file=sys.stderr)
    choice = select(result.stations, lat, lon, settings)
    weather = None
    if choice.patch is not None:
        weather = _patch_fields(weather_to_dict(observer.apply(choice.patch)), choice.patch)
    hint = _archive_hint(result.stations.values(), choice.fresh, settings.age_reference)
    summary: dict[str, Any] = {
        "source": args.source,
        "format": feed.format,
        "reports": result.reports,
        "duplicates": result.duplicates,
        "stations": len(result.stations),
        "partial": result.partial,
        "nil": result.nil,
        "problems": list(result.problems),
        "internal_errors": list(result.internal_errors),
        "observer": {"lat_deg": lat, "lon_deg": lon},
        "using": [{"station": s, "distance_km": round(d / 1000, 1)} for s, d in choice.used],
        "fresh": choice.fresh,
        "stale": choice.stale_count,
        "reason": choice.reason or None,
        "hint": hint,
        "weather": weather,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return status
    print(
        f"{args.source}: {feed.format}, {result.reports} reports, {result.duplicates} duplicates, "
        f"{len(result.stations)} stations ({result.partial} partial, {result.nil} NIL), "
        f"{len(result.problems)} problems"
    )
    for problem in result.problems[:10]:
        print(f"  problem: {problem}")
    if len(result.problems) > 10:
        print(f"  ... and {len(result.problems) - 10} more")
    print(
        f"observer {lat:.4f} {lon:.4f}: {choice.fresh} fresh and {choice.stale_count} stale "
        f"stations (age limit {m.max_age_min:.0f} min against the {settings.age_reference})"
    )
    if hint:
        print(f"note: {hint}")
    if weather is None:
        print(f"the daemon would keep its weather: {choice.reason}")
        return status
    using = ", ".join(f"{s} at {d / 1000:.1f} km" for s, d in choice.used)
    print(f"the daemon would take (source metar) from {using}:")
    print(json.dumps(weather, indent=2))
    return status


def _archive_hint(stations: Iterable[Any], fresh: int, age_reference: str) -> str | None:
    """How to see a feed whose reports are all too old against the clock (an archived file)
    as of its own time; None where that is not the case."""
    if fresh or age_reference != "clock":
        return None
    times = [s.observed_utc for s in stations if s.observed_utc is not None]
    if not times:
        return None
    newest = max(times)
    return (
        f"the feed's newest report is from {newest:%Y-%m-%d %H:%M}Z: to see the feed as of "
        "its own time, age its reports against that one with --age-reference feed "
        '([metar] age_reference = "feed" for the daemon)'
    )


def _patch_fields(weather: dict[str, Any], patch: Any) -> dict[str, Any]:
    """Only the fields the METAR patch sets, in the status shape."""
    return {k: v for k, v in weather.items() if getattr(patch, k, None) is not None}
