"""`wxsky preset ...`: list, show and manage weather presets."""

from __future__ import annotations

import argparse
import json

from wxsky.cli.common import Subparsers


def add_commands(sub: Subparsers) -> None:
    preset = sub.add_parser("preset", help="weather presets")
    psub = preset.add_subparsers(dest="preset_command", required=True)
    psub.add_parser("list", help="list presets").set_defaults(func=_cmd_list)
    show = psub.add_parser("show", help="show one preset as the weather it makes")
    show.add_argument("name")
    show.set_defaults(func=_cmd_show)


def _cmd_list(args: argparse.Namespace) -> int:
    from wxsky.presets import list_presets

    for info in list_presets():
        print(f"{info.name:24} {info.description}")
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from wxsky.presets import list_presets, load_preset
    from wxsky.weather.state import WeatherState, weather_to_dict

    patch = load_preset(args.name)
    info = next(i for i in list_presets() if i.name == args.name)
    state = WeatherState().apply(patch)
    print(f"# {info.name}: {info.description}\n# {info.path}")
    print(json.dumps(weather_to_dict(state), indent=2))
    return 0
