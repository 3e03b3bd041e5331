"""Domain errors. Each carries a one-line message saying what was wrong and where."""


class WxskyError(Exception):
    """Base of every error wxsky reports to a user instead of a traceback: something the user
    gave was wrong (the command line exits 2), unless it is a RuntimeFailure."""


class RuntimeFailure(WxskyError):
    """The user's input was fine but something it needs failed while running: a daemon that
    does not answer, a feed that cannot be read, no GL context (the command line exits 1)."""


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


class RenderError(RuntimeFailure):
    """The GL context could not be created or a GL call failed."""


class FeedError(WxskyError):
    """A weather feed that is not a METAR feed at all (the message names the source)."""


class FeedUnavailable(FeedError, RuntimeFailure):
    """A feed that cannot be read now: no such file, an I/O, HTTP or network failure."""


class FeedTooLarge(FeedError):
    """Feed data over the size limit, as sent or unpacked (a gzip bomb): refused unread."""


class FeedChanging(FeedUnavailable):
    """A feed file caught while it is being written: not read now, read again shortly."""

    def __init__(self, message: str, retry_in_s: float) -> None:
        super().__init__(message)
        self.retry_in_s = retry_in_s


class GribError(WxskyError):
    """GRIB2 model data that cannot be used: not GRIB2, truncated, corrupt, or on a grid wxsky
    does not read (the message names the file or URL and the message)."""
