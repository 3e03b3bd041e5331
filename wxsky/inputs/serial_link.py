"""A cockpit serial line speaking NMEA 0183, opened with pyserial's `serial_for_url`, so a
device path, `loop://`, `socket://host:port` and `rfc2217://host:port` all work."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import serial

from wxsky.inputs.cockpit_link import CockpitLink
from wxsky.protocols.nmea import NmeaDecoder, NmeaSettings
from wxsky.protocols.result import Decoded
from wxsky.weather.cockpit import ALL_GROUPS

if TYPE_CHECKING:
    from wxsky.settings.config import SerialInputSection

DEFAULT_BAUD = 4800  # NMEA 0183's own rate
READ_CHUNK_BYTES = 4096


class SerialLink(CockpitLink):
    kind: ClassVar[str] = "serial"

    def __init__(
        self,
        url: str,
        *,
        baud: int = DEFAULT_BAUD,
        settings: NmeaSettings | None = None,
        name: str = "",
        fields: Sequence[str] = ALL_GROUPS,
    ) -> None:
        super().__init__(name or f"serial:{url}", url, fields)
        self.url = url
        self.baud = baud
        self.settings = settings or NmeaSettings()
        self._port: Any = None
        self._decoder = NmeaDecoder(self.settings)

    @classmethod
    def from_section(cls, section: SerialInputSection) -> SerialLink:
        settings = NmeaSettings(
            sensor_heading_deg=section.sensor_heading_deg,
            heading_source=section.heading_source,
            accept_relative_wind=section.accept_relative_wind,
            allow_missing_checksum=section.allow_missing_checksum,
            max_line_bytes=section.max_line_bytes,
        )
        return cls(
            section.url,
            baud=section.baud,
            settings=settings,
            name=section.input_name,
            fields=section.fields,
        )

    def _open(self) -> None:
        # A fresh decoder per opening: half a line from before the device went away must not
        # be glued to the first line after it came back.
        self._decoder = NmeaDecoder(self.settings)
        self._port = serial.serial_for_url(
            self.url, baudrate=self.baud, timeout=self.POLL_S, write_timeout=self.POLL_S
        )

    def _receive(self) -> bytes:
        port = self._port
        # One blocking byte (up to the timeout), then whatever else is already waiting: a
        # sentence is read as soon as it arrives, not when a large buffer fills.
        first: bytes = port.read(1)
        if not first:
            return b""
        waiting = port.in_waiting
        rest: bytes = port.read(min(waiting, READ_CHUNK_BYTES)) if waiting else b""
        return first + rest

    def _decode(self, received: bytes) -> list[Decoded]:
        return self._decoder.feed(received, time.monotonic())

    def _close_device(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            port.close()
