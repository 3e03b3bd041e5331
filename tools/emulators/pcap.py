#!/usr/bin/env python3
"""UDP datagrams written as a classic pcap file (LINKTYPE_RAW: IPv4 packets, no link layer),
for Wireshark/tshark to decode what wxsky's CIGI encoder and the host emulator sent.

    from tools.emulators.pcap import Datagram, write_pcap
    write_pcap(path, [Datagram(0.0, ("127.0.0.1", 8001), ("127.0.0.1", 8000), payload)])

The IPv4 header carries a correct checksum; the UDP checksum is 0 ("none", allowed over IPv4),
so a reader never flags a datagram for it. Only what tshark needs: no IPv6, no fragments.

As a command, it writes every example message of wxsky's CIGI 3.3 encoder
(`cigi_examples.messages()`), big-endian first, then little-endian, for a look in Wireshark:

    .venv/bin/python tools/emulators/pcap.py cigi-examples cigi.pcap && tshark -r cigi.pcap -V

tests/test_cigi_tshark.py decodes the same datagrams with tshark and compares every field.
"""

from __future__ import annotations

import argparse
import ipaddress
import struct
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from wxsky.protocols.cigi import ByteOrder, Packet

LINKTYPE_RAW = 101  # each record is an IP packet
SNAPLEN = 65_535
IPV4_HEADER = struct.Struct(">BBHHHBBH4s4s")
UDP_HEADER = struct.Struct(">HHHH")
MAX_PAYLOAD = SNAPLEN - IPV4_HEADER.size - UDP_HEADER.size
# CIGI ends: a simulation host and an image generator (TEST-NET-1 addresses), each on the
# port it receives on in CCL's example programs: the IG on 8000, the host on 8001.
CIGI_HOST = ("192.0.2.1", 8001)
CIGI_IG = ("192.0.2.2", 8000)


@dataclass(frozen=True)
class Datagram:
    time_s: float  # seconds since the epoch (or since any start: tshark shows it as given)
    src: tuple[str, int]  # IPv4 address, UDP port
    dst: tuple[str, int]
    payload: bytes

    def __post_init__(self) -> None:
        if not 0 <= self.time_s < 2**32:
            raise ValueError(f"time {self.time_s} s does not fit a pcap record (0..2**32)")
        for address, port in (self.src, self.dst):
            ipaddress.IPv4Address(address)  # raises ValueError for anything but IPv4
            if not 0 <= port <= 0xFFFF:
                raise ValueError(f"UDP port {port} is outside 0..65535")
        if len(self.payload) > MAX_PAYLOAD:
            raise ValueError(f"UDP payload of {len(self.payload)} bytes: at most {MAX_PAYLOAD}")


def _checksum(header: bytes) -> int:
    """The Internet checksum (RFC 1071) of an even number of bytes."""
    total = sum(int.from_bytes(header[i : i + 2], "big") for i in range(0, len(header), 2))
    while total >> 16:
        total = (total & 0xFFFF) + (total >> 16)
    return ~total & 0xFFFF


def ip_packet(d: Datagram, ident: int = 0) -> bytes:
    """The IPv4 + UDP packet carrying `d.payload`."""
    src = ipaddress.IPv4Address(d.src[0]).packed
    dst = ipaddress.IPv4Address(d.dst[0]).packed
    udp = UDP_HEADER.pack(d.src[1], d.dst[1], UDP_HEADER.size + len(d.payload), 0)
    length = IPV4_HEADER.size + len(udp) + len(d.payload)
    fields = (0x45, 0, length, ident & 0xFFFF, 0x4000, 64, 17)  # v4, DF, TTL 64, UDP
    header = IPV4_HEADER.pack(*fields, 0, src, dst)
    header = IPV4_HEADER.pack(*fields, _checksum(header), src, dst)
    return header + udp + d.payload


def write_pcap(path: Path, datagrams: Iterable[Datagram]) -> int:
    """Write the datagrams in order (little-endian pcap 2.4, microsecond times); returns how
    many."""
    count = 0
    with open(path, "wb") as f:
        f.write(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, SNAPLEN, LINKTYPE_RAW))
        for count, d in enumerate(datagrams, 1):
            packet = ip_packet(d, count)
            seconds, micros = divmod(round(d.time_s * 1_000_000), 1_000_000)
            f.write(struct.pack("<IIII", seconds, micros, len(packet), len(packet)))
            f.write(packet)
    return count


def cigi_example_datagrams(
    start_s: float = 0.0,
) -> list[tuple[ByteOrder, list[Packet], Datagram]]:
    """Every example message of the CIGI encoder in both byte orders, one a millisecond:
    host → IG messages from CIGI_HOST to CIGI_IG, IG → host ones back."""
    from wxsky.protocols.cigi import encode_datagram
    from wxsky.protocols.cigi_examples import messages

    out: list[tuple[ByteOrder, list[Packet], Datagram]] = []
    orders: tuple[ByteOrder, ...] = ("big", "little")
    for order in orders:
        for message in messages():
            to_ig = message[0].spec.direction == "host_to_ig"
            src, dst = (CIGI_HOST, CIGI_IG) if to_ig else (CIGI_IG, CIGI_HOST)
            time_s = start_s + len(out) / 1000
            out.append(
                (order, message, Datagram(time_s, src, dst, encode_datagram(message, order)))
            )
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    cigi = sub.add_parser("cigi-examples", help="every example message of the CIGI encoder")
    cigi.add_argument("out", type=Path, help="the pcap file to write")
    args = p.parse_args(argv)
    count = write_pcap(args.out, (d for _, _, d in cigi_example_datagrams()))
    print(f"{args.out}: {count} datagrams")
    return 0


if __name__ == "__main__":
    sys.exit(main())
