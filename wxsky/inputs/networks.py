"""Which source addresses a UDP input takes datagrams from (`allow_from`), shared by the CIGI
and FlightGear sockets: a list of addresses or networks, IPv4 or IPv6, and the test of a
datagram's source against it."""

from __future__ import annotations

import ipaddress
from collections.abc import Sequence

from wxsky.errors import ConfigError

Network = ipaddress.IPv4Network | ipaddress.IPv6Network


def parse_networks(items: Sequence[str], what: str = "cigi.allow_from") -> tuple[Network, ...]:
    """The networks `items` name (a bare address is a network of one); ConfigError naming
    `what` and the item for one that is neither."""
    out = []
    for item in items:
        try:
            out.append(ipaddress.ip_network(item, strict=False))
        except ValueError:
            raise ConfigError(f"{what}: {item!r} is not an address or network") from None
    return tuple(out)


def address_allowed(host: str, networks: Sequence[Network]) -> bool:
    """Whether a datagram from `host` (as recvfrom gives it) is taken: any address when
    `networks` is empty, else one inside them; an IPv4 host reaching an IPv6 socket
    (::ffff:a.b.c.d) is judged by its IPv4 address, and a scope (%eth0) is ignored."""
    if not networks:
        return True
    try:
        ip = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return False
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    return any(ip in net for net in networks)
