"""Folders of settings shipped inside the package (presets, cloud models), found through
`importlib.resources` so that a wheel, a `--user` install and an editable checkout all find
them from any working directory."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from wxsky.errors import ConfigError


def package_data_dir(name: str) -> Path:
    """The folder `name` of `wxsky.settings` as a real path (presets and models are read with
    ordinary file APIs, and listed with their paths in messages)."""
    folder = resources.files("wxsky.settings") / name
    if not isinstance(folder, Path):
        # Only a zip import gives something else; wxsky is never installed that way.
        raise ConfigError(f"wxsky.settings/{name}: package data is not on a file system")
    return folder
