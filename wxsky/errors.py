"""Domain errors. Each carries a one-line message saying what was wrong and where."""


class WxskyError(Exception):
    """Base of every error wxsky reports to a user instead of a traceback."""


class ConfigError(WxskyError):
    """A config or preset file is malformed (the message names the file and key)."""


class PresetError(WxskyError):
    """An unknown or malformed weather preset."""


class MetarError(WxskyError):
    """A METAR report that cannot be decoded (the message names the group)."""


class ProtocolError(WxskyError):
    """A malformed control or stream message."""


class PluginError(WxskyError):
    """A plugin that cannot be found or imported (the message names it)."""


class RenderError(WxskyError):
    """The GL context could not be created or a GL call failed."""


class FeedError(WxskyError):
    """A weather feed that is not a METAR feed at all (the message names the source)."""
