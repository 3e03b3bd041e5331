"""Cockpit link drivers, found by entry point (group `wxsky.inputs`) and imported only when a
link of that kind is configured: a daemon without CAN inputs never imports python-can.

Built-ins are registered the same way as third-party drivers (see pyproject.toml), so there is
one mechanism for both. A driver is a `CockpitLink` subclass with a `from_section` classmethod.
"""

from __future__ import annotations

import functools
from importlib import metadata
from typing import Any

from wxsky.errors import PluginError
from wxsky.inputs.cockpit_link import CockpitLink

GROUP = "wxsky.inputs"


def driver_names() -> tuple[str, ...]:
    return tuple(sorted(ep.name for ep in metadata.entry_points(group=GROUP)))


@functools.cache
def load_driver(kind: str) -> type[CockpitLink]:
    """The driver class for a link kind; a missing or broken driver is a PluginError naming it."""
    found = [ep for ep in metadata.entry_points(group=GROUP) if ep.name == kind]
    if not found:
        known = ", ".join(driver_names()) or "none installed"
        raise PluginError(f"no cockpit input driver {kind!r} (known: {known})")
    try:
        cls = found[0].load()
    except Exception as exc:  # an ImportError deep inside a driver's dependencies, typically
        raise PluginError(
            f"cockpit input driver {kind!r} ({found[0].value}) failed to import: {exc}"
        ) from exc
    if not (isinstance(cls, type) and issubclass(cls, CockpitLink)):
        raise PluginError(f"cockpit input driver {kind!r} ({found[0].value}) is not a CockpitLink")
    return cls


def open_link(kind: str, section: Any) -> CockpitLink:
    """A (not yet started) link of `kind` configured by its config section."""
    link: CockpitLink = load_driver(kind).from_section(section)
    return link
