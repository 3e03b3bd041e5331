"""A daemon's credentials on the channel bus, apart from the module that imports Zenoh (the
daemon reads them from its config without loading Zenoh)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Credentials:
    """PEM files: the dome's CA, and this daemon's certificate and private key
    (tools/generate/dome_certs.py makes them; docs/channels.md)."""

    ca_certificate: str
    certificate: str
    private_key: str

    @classmethod
    def of(cls, ca_certificate: str, certificate: str, private_key: str) -> Credentials | None:
        """The credentials a config section names; None when it names none (the checker
        makes sure it names all three or none)."""
        if not (ca_certificate or certificate or private_key):
            return None
        return cls(ca_certificate, certificate, private_key)
