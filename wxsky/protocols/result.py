"""What one sentence or frame from a cockpit link came to."""

from __future__ import annotations

from dataclasses import dataclass

from wxsky.weather.cockpit import CockpitUpdate


@dataclass(frozen=True)
class Decoded:
    """Exactly one of: an update, a reason it was ignored, a reason it was rejected.

    Ignored means well-formed but of no use to wxsky (an unknown sentence or CAN id, another
    node's frame, apparent wind when not configured for it); it is counted, not an error.
    Rejected means malformed or out of range; the value never reaches the weather."""

    update: CockpitUpdate | None = None
    ignored: str = ""
    error: str = ""

    @classmethod
    def ignore(cls, reason: str) -> Decoded:
        return cls(ignored=reason)

    @classmethod
    def reject(cls, reason: str) -> Decoded:
        return cls(error=reason)
