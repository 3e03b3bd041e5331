"""The channel bus's error, apart from the module that imports Zenoh (the daemon names it
without loading Zenoh)."""

from __future__ import annotations

from wxsky.errors import WxskyError


class BusError(WxskyError):
    """The bus could not be opened, or a second master tried to claim a site."""
