"""Cockpit link drivers, looked up by kind and imported only when a link of that kind is
configured: a daemon without CAN inputs never imports python-can.

The built-ins are a static table of import paths, so `python -m wxsky run --serial ...` works
from a bare checkout with no installed metadata; third-party drivers register under the
entry-point group `wxsky.inputs` (a built-in name wins over an entry point of the same name).
A driver is a `CockpitLink` subclass with a `from_section` classmethod.
"""

from __future__ import annotations

import functools
import importlib
from importlib import metadata
from typing import Any

from wxsky.errors import PluginError
from wxsky.inputs.cockpit_link import CockpitLink

GROUP = "wxsky.inputs"

BUILTIN_DRIVERS: dict[str, str] = {
    "serial": "wxsky.inputs.serial_link:SerialLink",
    "can": "wxsky.inputs.can_link:CanLink",
}


def driver_names() -> tuple[str, ...]:
    """Every driver kind: the built-ins and those installed as entry points."""
    plugins = {ep.name for ep in metadata.entry_points(group=GROUP)}
    return tuple(sorted(set(BUILTIN_DRIVERS) | plugins))


def _target(kind: str) -> tuple[str, metadata.EntryPoint | None]:
    if kind in BUILTIN_DRIVERS:
        return BUILTIN_DRIVERS[kind], None
    for ep in metadata.entry_points(group=GROUP):
        if ep.name == kind:
            return ep.value, ep
    known = ", ".join(driver_names())
    raise PluginError(f"no cockpit input driver {kind!r} (known: {known})")


@functools.cache
def load_driver(kind: str) -> type[CockpitLink]:
    """The driver class for a link kind; a missing or broken driver is a PluginError naming it."""
    value, ep = _target(kind)
    try:
        if ep is not None:
            cls = ep.load()
        else:
            module, _, attr = value.partition(":")
            cls = getattr(importlib.import_module(module), attr)
    except Exception as exc:  # an ImportError deep inside a driver's dependencies, typically
        raise PluginError(
            f"cockpit input driver {kind!r} ({value}) failed to import: {exc}"
        ) from exc
    if not (isinstance(cls, type) and issubclass(cls, CockpitLink)):
        raise PluginError(f"cockpit input driver {kind!r} ({value}) is not a CockpitLink")
    return cls


def open_link(kind: str, section: Any) -> CockpitLink:
    """A (not yet started) link of `kind` configured by its config section."""
    link: CockpitLink = load_driver(kind).from_section(section)
    return link
