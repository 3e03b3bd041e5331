"""`wxsky preset ...`: list, show, check, compare and save weather presets, and apply them to
(or release them from) a running daemon."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from wxsky.cli.common import (
    EXIT_DIFFERENT,
    EXIT_USAGE,
    Subparsers,
    add_control_option,
    control_address,
    show_help,
)
from wxsky.cli.metar_cmd import add_field_elevation_option, check_field_elevation


def add_commands(sub: Subparsers) -> None:
    preset = sub.add_parser("preset", help="weather presets")
    preset.set_defaults(func=show_help(preset))
    psub = preset.add_subparsers(dest="preset_command", metavar="COMMAND", title="commands")

    lst = psub.add_parser("list", help="list presets: name, origin, description")
    _config_option(lst)
    lst.set_defaults(func=_cmd_list)

    show = psub.add_parser("show", help="show one preset as the weather it makes")
    show.add_argument("name", help="preset name")
    _config_option(show)
    show.set_defaults(func=_cmd_show)

    apply = psub.add_parser(
        "apply",
        help="apply a preset to the running daemon (held until 'preset release')",
        description="Apply a preset's weather to the running daemon, held until 'wxsky preset "
        "release'. The daemon keeps its clock and site, and its sky moves toward the preset's "
        "weather at the [transition] rates.",
    )
    apply.add_argument("name", help="preset name (looked up by the daemon)")
    apply.add_argument("--now", action="store_true", help="switch the sky to the preset at once")
    apply.add_argument(
        "--site",
        action="store_true",
        help="take the preset's place, date and time and cloud seed as well: another sky, "
        "switched to at once",
    )
    add_control_option(apply)
    apply.set_defaults(func=_cmd_apply)

    release = psub.add_parser(
        "release",
        help="hand the fields a preset or control client holds back to METAR/config",
        description="Hand the fields a preset or control client holds back to the METAR feed "
        "and the config; the sky moves back at the [transition] rates.",
    )
    release.add_argument("--now", action="store_true", help="switch the sky back at once")
    add_control_option(release)
    release.set_defaults(func=_cmd_release)

    save = psub.add_parser("save", help="save the current or a METAR's weather as a user preset")
    save.add_argument("name", help="preset name: lowercase letters, digits and '-'")
    src = save.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--from-running", action="store_true", help="the weather of the running daemon"
    )
    src.add_argument("--from-metar", metavar="REPORT", help="the weather a METAR report states")
    add_field_elevation_option(save, "--from-metar")
    save.add_argument(
        "--description", metavar="TEXT", help="the preset's description (default: its source)"
    )
    save.add_argument("--force", action="store_true", help="replace an existing user preset")
    add_control_option(save)
    save.set_defaults(func=_cmd_save)

    validate = psub.add_parser(
        "validate",
        help="check preset files, reporting every problem",
        description="Check preset files, reporting every problem as FILE:LINE: key: problem; "
        "exits 2 when a file has one.",
    )
    validate.add_argument("files", nargs="+", type=Path, metavar="FILE", help="preset files")
    validate.set_defaults(func=_cmd_validate)

    diff = psub.add_parser(
        "diff",
        help="compare what two presets set, field by field",
        description="Compare what two presets set, field by field; like diff(1), exits 0 when "
        "they are the same and 1 when they differ.",
    )
    diff.add_argument("a", help="preset name or file")
    diff.add_argument("b", help="preset name or file")
    diff.add_argument("--json", action="store_true", help="print one JSON object")
    _config_option(diff)
    diff.set_defaults(func=_cmd_diff)


def _config_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="daemon config whose [presets] dirs are searched first",
    )


def _preset_dirs(args: argparse.Namespace) -> tuple[Path, ...]:
    from wxsky.settings.config import load_config

    return load_config(args.config).presets.dirs if args.config else ()


def _cmd_list(args: argparse.Namespace) -> int:
    from wxsky.settings.presets import list_presets

    infos = list_presets(_preset_dirs(args))
    origins = [
        info.origin + (f" (overrides {', '.join(info.overrides)})" if info.overrides else "")
        for info in infos
    ]
    name_w = max((len(i.name) for i in infos), default=0)
    origin_w = max((len(o) for o in origins), default=0)
    for info, origin in zip(infos, origins, strict=True):
        print(f"{info.name:{name_w}}  {origin:{origin_w}}  {info.description}")
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from wxsky.settings.presets import find_preset, load_preset_file
    from wxsky.weather.state import WeatherState, weather_to_dict

    path, origin = find_preset(args.name, _preset_dirs(args))
    info, patch = load_preset_file(path)
    state = WeatherState().apply(patch)
    print(f"# {info.name}: {info.description}\n# {path} ({origin})")
    print(json.dumps(weather_to_dict(state), indent=2))
    return 0


def _cmd_apply(args: argparse.Namespace) -> int:
    from wxsky.host.client import ControlClient

    address = control_address(args)
    params = {"name": args.name, "keep_site": not args.site, "now": args.now}
    with ControlClient.connect(address) as client:
        result = client.call("apply_preset", params)
    name = result if isinstance(result, str) else args.name
    if args.site:
        how = "switched to it, at its own site, date and time"
    elif args.now:
        how = "switched to it at once"
    else:
        how = "the sky moves toward it at the [transition] rates"
    print(
        f"applied preset {name!r} on the daemon at {address}: {how}; its fields override "
        "METAR until 'wxsky preset release'"
    )
    return 0


def _cmd_release(args: argparse.Namespace) -> int:
    from wxsky.host.client import ControlClient, DaemonUnavailable

    address = control_address(args)
    with ControlClient.connect(address) as client:
        result = client.call("release", {"now": args.now})
    released = result.get("released") if isinstance(result, dict) else None
    if not isinstance(released, list):
        raise DaemonUnavailable(
            f"unexpected answer to release from the daemon at {address}: {result!r}"
        )
    if not released:
        print(f"nothing to release: the daemon at {address} held no overrides")
    else:
        fields = ", ".join(str(f) for f in released)
        # A preset applied with its own site and seed was another sky: so is the way back.
        jump = args.now or {"observer", "seed"} & set(released)
        how = "at once" if jump else "at the [transition] rates"
        print(f"released {len(released)} fields ({fields}): back to METAR/config sources, {how}")
    return 0


def _cmd_save(args: argparse.Namespace) -> int:
    from datetime import UTC, datetime

    from wxsky.errors import PresetError
    from wxsky.settings.presets import find_preset, preset_to_toml, write_user_preset

    elevation_m = check_field_elevation(args, args.from_metar, "--from-metar")
    stamp = f"{datetime.now(UTC):%Y-%m-%d %H:%MZ}"
    notes: list[str] = []
    if args.from_running:
        patch, source, notes = _running_weather(args)
    else:
        patch = _metar_weather(args.from_metar, elevation_m)
        source = f"METAR {' '.join(args.from_metar.split())}"
    description = args.description or f"Saved from {source}"
    text = preset_to_toml(patch, description, comment=f"Written by 'wxsky preset save' {stamp}")
    try:
        existing = find_preset(args.name)
    except PresetError:
        existing = None
    path = write_user_preset(args.name, text, force=args.force)
    for note in notes:
        print(f"note: {note}")
    hides = " (overrides the builtin preset)" if existing and existing[1] == "builtin" else ""
    print(f"saved preset {args.name!r} to {path}{hides}")
    return 0


def _metar_weather(report: str, field_elevation_m: float | None) -> Any:
    """The weather a METAR report states, its clouds over its station's field as a feed
    reads the report (or over the field elevation given)."""
    from wxsky.inputs.station_table import report_patch
    from wxsky.weather.metar import decode

    # A preset keeps no date, so any month with 31 days lets every report's day decode.
    metar = decode(report, year=2000, month=1).require_usable()
    return report_patch(metar, field_elevation_m)


def _running_weather(args: argparse.Namespace) -> tuple[Any, str, list[str]]:
    from wxsky.host.client import ControlClient, DaemonUnavailable
    from wxsky.settings.presets import patch_from_weather_dict

    address = control_address(args)
    with ControlClient.connect(address) as client:
        status = client.call("status")
    weather = status.get("weather") if isinstance(status, dict) else None
    if not isinstance(weather, dict):
        raise DaemonUnavailable(f"the daemon at {address} sent no weather in its status")
    notes = [
        f"layers[{i}].cover_oktas {layer['cover_oktas']} rounded to whole oktas "
        "(the weather is changing)"
        for i, layer in enumerate(weather.get("layers") or [])
        if isinstance(layer, dict)
        and isinstance(layer.get("cover_oktas"), float)
        and not float(layer["cover_oktas"]).is_integer()
    ]
    return patch_from_weather_dict(weather), f"the daemon at {address}", notes


def _cmd_validate(args: argparse.Namespace) -> int:
    from wxsky.settings.presets import check_preset_file

    bad = False
    for path in args.files:
        check = check_preset_file(path)
        if check.problems:
            bad = True
            for line in check.lines():
                print(line)
        else:
            print(f"{path}: ok")
    return EXIT_USAGE if bad else 0


def _cmd_diff(args: argparse.Namespace) -> int:
    from wxsky.settings.preset_write import format_value
    from wxsky.settings.presets import preset_diff, resolve_preset

    dirs = _preset_dirs(args)
    info_a, patch_a = resolve_preset(args.a, dirs)
    info_b, patch_b = resolve_preset(args.b, dirs)
    diffs = preset_diff(patch_a, patch_b)
    if args.json:
        body = {
            "a": str(info_a.path),
            "b": str(info_b.path),
            "differences": [{"key": d.key, "a": d.a, "b": d.b} for d in diffs],
        }
        print(json.dumps(body, indent=2))
    elif not diffs:
        print(f"no differences between {args.a} and {args.b}")
    else:
        print(f"--- {args.a} ({info_a.path})\n+++ {args.b} ({info_b.path})")
        for d in diffs:
            print(f"{d.key}: {format_value(d.a)} -> {format_value(d.b)}")
    return EXIT_DIFFERENT if diffs else 0
