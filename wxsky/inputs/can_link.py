"""A CAN bus speaking CANaerospace, through any interface python-can supports (`socketcan`,
`slcan` for USB-serial adapters, `pcan`, `virtual`, `udp_multicast`, ...)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import can

from wxsky.inputs.cockpit_link import CockpitLink
from wxsky.protocols.canaerospace import CanasDecoder
from wxsky.protocols.result import Decoded
from wxsky.weather.cockpit import ALL_GROUPS

if TYPE_CHECKING:
    from wxsky.settings.config import CanInputSection

MAX_BATCH = 256  # frames merged into one update when a bus delivers faster than we read


class CanLink(CockpitLink):
    kind: ClassVar[str] = "can"

    def __init__(
        self,
        interface: str,
        channel: str,
        *,
        bitrate: int = 0,
        node_ids: Sequence[int] = (),
        name: str = "",
        fields: Sequence[str] = ALL_GROUPS,
    ) -> None:
        super().__init__(name or f"can:{interface}:{channel}", f"{interface}:{channel}", fields)
        self.interface = interface
        self.channel = channel
        self.bitrate = bitrate
        self._decoder = CanasDecoder(frozenset(node_ids))
        self._bus: Any = None

    @classmethod
    def from_section(cls, section: CanInputSection) -> CanLink:
        return cls(
            section.interface,
            section.channel,
            bitrate=section.bitrate,
            node_ids=section.node_ids,
            name=section.input_name,
            fields=section.fields,
        )

    def _open(self) -> None:
        kwargs: dict[str, Any] = {"interface": self.interface}
        if self.channel:
            kwargs["channel"] = self.channel
        if self.bitrate:
            kwargs["bitrate"] = self.bitrate
        self._bus = can.Bus(**kwargs)

    def _receive(self) -> list[can.Message]:
        bus = self._bus
        first = bus.recv(timeout=self.POLL_S)
        if first is None:
            return []
        frames = [first]
        while len(frames) < MAX_BATCH:
            more = bus.recv(timeout=0.0)
            if more is None:
                break
            frames.append(more)
        return frames

    def _decode(self, received: list[can.Message]) -> list[Decoded]:
        return [
            self._decoder.decode(
                msg.arbitration_id,
                bytes(msg.data),
                is_extended=msg.is_extended_id,
                is_remote=msg.is_remote_frame,
                is_error=msg.is_error_frame,
            )
            for msg in received
        ]

    def _close_device(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            bus.shutdown()
