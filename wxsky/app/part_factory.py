"""Which parts a daemon runs (`parts.py`), made from its config and `wxsky run`'s options, and
the checks across them. The one place a new integration is wired in: made here, the daemon
starts, walks, reports and closes it with the rest.

A part with nothing to do (no feed, no link, no CIGI address, no FlightGear address) is left
out; the channel bus is always there, since `status` carries its keys on every daemon.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from wxsky.app.cigi_part import CigiPart
from wxsky.app.cockpit_part import CockpitPart
from wxsky.app.flightgear_part import FlightGearPart
from wxsky.app.grib_part import GribPart
from wxsky.app.metar_part import MetarFeedsPart
from wxsky.app.parts import Part
from wxsky.app.share_part import SharePart
from wxsky.errors import ConfigError
from wxsky.inputs.drivers import open_link
from wxsky.settings.config import CanInputSection, DaemonConfig, SerialInputSection


@dataclass(frozen=True)
class PartOptions:
    """What `wxsky run`'s command line adds to the config's parts: each list adds to the
    config's own, each address replaces it."""

    metar_feeds: Sequence[str] = ()
    grib: Sequence[str] = ()
    replay: bool = False  # the METAR feeds are an archive, replayed by the sim clock
    serial: Sequence[SerialInputSection] = ()
    can: Sequence[CanInputSection] = ()
    cigi: Sequence[str] = ()
    cigi_send: Sequence[str] = ()
    flightgear: str | None = None
    flightgear_pose: str | None = None
    web: str | None = None  # HOST:PORT for the web station, over [web] listen


def parts_from_config(config: DaemonConfig, options: PartOptions | None = None) -> list[Part]:
    """The daemon's parts in the order it walks them: the METAR feeds, the model data, the
    cockpit links, CIGI, FlightGear, the web station, the channel bus. ConfigError (one line) for a
    combination refused."""
    opt = options or PartOptions()
    feeds = MetarFeedsPart(config.metar, (*config.metar.feeds, *opt.metar_feeds), replay=opt.replay)
    grib = GribPart(config.grib, (*config.grib.sources, *opt.grib), nearest=feeds.nearest)
    cockpit = CockpitPart(
        [
            *(open_link("serial", section) for section in (*config.serial, *opt.serial)),
            *(open_link("can", section) for section in (*config.can, *opt.can)),
        ]
    )
    blend = config.metar.blend_stations
    cigi = CigiPart(
        config.cigi,
        clock_rate=config.clock.rate,
        listen=opt.cigi,
        send_to=opt.cigi_send,
        blended=feeds.blended,
        region_slots=blend if blend > 1 else 0,
        tick_hz=config.daemon.tick_hz,
    )
    flightgear = FlightGearPart(config.flightgear, props=opt.flightgear, pose=opt.flightgear_pose)
    share = SharePart(config)
    if share.role == "channel":
        given = [
            name
            for name, present in (
                ("METAR feeds", bool(feeds.feeds)),
                ("model data", grib.enabled),
                ("cockpit links", bool(cockpit.links)),
                ("CIGI", cigi.listens),
            )
            if present
        ]
        if given:
            raise ConfigError(
                f"channel {config.channel.name!r} takes its weather from the sky master; "
                f"it cannot also read {', '.join(given)} (give them to the master)"
            )
    used: list[Part] = []
    if feeds.feeds:
        used.append(feeds)
    if grib.enabled:
        used.append(grib)
    if cockpit.links:
        used.append(cockpit)
    if cigi.inputs():  # a listener or a sender
        used.append(cigi)
    if flightgear.enabled:
        used.append(flightgear)
    listen = opt.web or config.web.listen
    if listen:
        # Imported only here: the web library (aiohttp, and the TLS it loads) takes a few
        # tenths of a second to import, which a daemon without the station need not pay.
        from wxsky.app.web_part import WebPart

        used.append(WebPart(config, listen, stations=feeds.stations))
    return [*used, share]
