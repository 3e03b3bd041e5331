"""Which source each weather field is taken from, highest first:

    cockpit (while held) > control channel / preset applied at run time
        > CIGI host (while it keeps sending) > METAR feed > model (GRIB) > base

The base is the config's defaults with the preset the daemon started on. Every slot keeps the
fields its source last gave; a field falls through to the next slot down when a slot has no
value for it. Cockpit values are held only while they keep coming: a field the cockpit has not
updated for `cockpit_hold_s` expires, so a knob left alone hands the field back. Control-channel
overrides stay until released. A CIGI host's weather stands while the host keeps sending: each
new picture of the host's weather replaces the whole slot, which is handed back when the host
has been silent for `cigi_hold_s` (docs/cigi.md says why CIGI ranks there). The simulation
clock is not a weather field here: `time_utc` in a patch sets the clock directly (see
`SkyEngine`).

The cockpit slot also holds finely keyed values (`wind.speed_mps`, `layer2.base_m`; see
`wxsky.weather.cockpit`): hardware sets one knob at a time, and each knob expires on its own.
They are laid over the weather of the sources below by `cockpit.overlay`.

The METAR does not simply hide the model's layers and wind: a report speaks for the surface
and the sky it sees near its station, the model for the rest, and `model_blend` lays one over
the other by `metar_weight` (the nearest station's distance and its report's age).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from wxsky.weather.cockpit import overlay
from wxsky.weather.model_blend import blend
from wxsky.weather.state import Provenance, Source, WeatherPatch, WeatherState

# Fields that can be overridden; time_utc belongs to the clock.
FIELDS: tuple[str, ...] = tuple(
    f.name for f in dataclasses.fields(Provenance) if f.name != "time_utc"
)
DEFAULT_COCKPIT_HOLD_S = 30.0
DEFAULT_CIGI_HOLD_S = 10.0

Slot = Mapping[str, "Held"]
_EMPTY: Slot = MappingProxyType({})


@dataclass(frozen=True)
class Held:
    """One field's value as a source last gave it, with the wall time it arrived."""

    value: Any
    updated_s: float


@dataclass(frozen=True)
class SourceStack:
    base: WeatherState
    grib: Slot = field(default_factory=lambda: _EMPTY)
    metar: Slot = field(default_factory=lambda: _EMPTY)
    cigi: Slot = field(default_factory=lambda: _EMPTY)
    control: Slot = field(default_factory=lambda: _EMPTY)
    cockpit: Slot = field(default_factory=lambda: _EMPTY)
    cockpit_hold_s: float = DEFAULT_COCKPIT_HOLD_S
    cigi_hold_s: float = DEFAULT_CIGI_HOLD_S
    cigi_heard_s: float = 0.0  # when the CIGI host was last heard from
    # How much the METAR counts against the model's layers and wind (model_blend)
    metar_weight: float = 1.0

    def with_patch(self, patch: WeatherPatch, now_s: float) -> SourceStack:
        """The stack with a source's new values. METAR and CIGI replace the whole slot (the
        newest report, the host's whole weather, stands alone); control and cockpit patches
        update only the fields they give."""
        values = {
            name: Held(getattr(patch, name), now_s)
            for name in FIELDS
            if getattr(patch, name) is not None
        }
        match patch.source:
            case Source.DEFAULT | Source.PRESET:
                return dataclasses.replace(self, base=self.base.apply(_without_time(patch)))
            case Source.METAR:
                return dataclasses.replace(self, metar=MappingProxyType(values))
            case Source.GRIB:
                return dataclasses.replace(self, grib=MappingProxyType(values))
            case Source.CIGI:
                return dataclasses.replace(self, cigi=MappingProxyType(values), cigi_heard_s=now_s)
            case Source.CONTROL:
                return dataclasses.replace(self, control=_merged(self.control, values))
            case Source.COCKPIT:
                return dataclasses.replace(self, cockpit=_merged(self.cockpit, values))
        raise ValueError(f"unknown weather source {patch.source!r}")

    def with_cockpit_values(self, values: Mapping[str, Any], now_s: float) -> SourceStack:
        """The stack with a cockpit link's finely keyed values (already range-checked)."""
        if not values:
            return self
        held = {key: Held(value, now_s) for key, value in values.items()}
        return dataclasses.replace(self, cockpit=_merged(self.cockpit, held))

    def heard_cigi(self, now_s: float) -> SourceStack:
        """The CIGI host is still there (it sent a message): its weather stands on."""
        return dataclasses.replace(self, cigi_heard_s=now_s) if self.cigi else self

    def released(self, source: Source) -> tuple[SourceStack, tuple[str, ...]]:
        """Drop every value a control, cockpit, CIGI or METAR source holds; returns the fields
        it held."""
        if source is Source.CONTROL:
            return dataclasses.replace(self, control=_EMPTY), tuple(sorted(self.control))
        if source is Source.COCKPIT:
            return dataclasses.replace(self, cockpit=_EMPTY), tuple(sorted(self.cockpit))
        if source is Source.METAR:
            return dataclasses.replace(self, metar=_EMPTY), tuple(sorted(self.metar))
        if source is Source.CIGI:
            return dataclasses.replace(self, cigi=_EMPTY), tuple(sorted(self.cigi))
        if source is Source.GRIB:
            return dataclasses.replace(self, grib=_EMPTY), tuple(sorted(self.grib))
        raise ValueError(
            f"only control, cockpit, cigi, metar and grib values can be released, not {source}"
        )

    def with_metar_weight(self, weight: float) -> SourceStack:
        w = min(1.0, max(0.0, weight))
        return self if w == self.metar_weight else dataclasses.replace(self, metar_weight=w)

    def expired(self, now_s: float) -> tuple[SourceStack, tuple[str, ...]]:
        """Drop cockpit fields not updated within the hold time, and the CIGI host's weather
        when the host has been silent for its hold time; returns the dropped fields."""
        if not self.cigi and not self.cockpit:  # every frame, mostly: nothing to hold
            return self, ()
        stack = self
        dropped: list[str] = []
        if self.cigi and self.cigi_heard_s < now_s - self.cigi_hold_s:
            stack, gone_cigi = stack.released(Source.CIGI)
            dropped += gone_cigi
        limit = now_s - self.cockpit_hold_s
        gone = tuple(sorted(n for n, h in self.cockpit.items() if h.updated_s < limit))
        if gone:
            kept = {n: h for n, h in self.cockpit.items() if n not in gone}
            stack = dataclasses.replace(stack, cockpit=MappingProxyType(kept))
            dropped += gone
        return stack, tuple(dropped)

    def target(self) -> WeatherState:
        """The weather every field's highest-ranked source asks for, with its provenance."""
        state = self.base
        if self.grib:
            state = state.apply(WeatherPatch(source=Source.GRIB, **_whole(self.grib)))
        if self.metar:
            metar = _whole(self.metar)
            if self.grib:
                metar = self._over_model(metar, state)
            state = state.apply(WeatherPatch(source=Source.METAR, **metar))
        for source, slot in (
            (Source.CIGI, self.cigi),
            (Source.CONTROL, self.control),
            (Source.COCKPIT, self.cockpit),
        ):
            if slot:
                state = state.apply(WeatherPatch(source=source, **_whole(slot)))
        fine = {n: h.value for n, h in self.cockpit.items() if n not in FIELDS}
        return overlay(state, fine)

    def _over_model(self, metar: dict[str, Any], model: WeatherState) -> dict[str, Any]:
        """The METAR's values with its layers and wind laid over the model's by weight; at
        weight 0 the model's stand (and are shown as the model's)."""
        out = dict(metar)
        w = self.metar_weight
        if w <= 0.0:
            out.pop("layers", None)
            out.pop("wind", None)
            return out
        got = blend(
            metar.get("layers"),
            metar.get("wind"),
            model.layers if "layers" in self.grib else None,
            model.wind if "wind" in self.grib else None,
            w,
            model.observer.alt_m,
        )
        for name, value in (("layers", got.layers), ("wind", got.wind)):
            if value is not None:
                out[name] = value
        return out

    def holds(self, now_s: float) -> dict[str, dict[str, Any]]:
        """CIGI, control and cockpit overrides for status: field -> source and age (the
        highest source holding a field wins, as in `target`)."""
        out: dict[str, dict[str, Any]] = {}
        for source, slot in (
            (Source.CIGI, self.cigi),
            (Source.CONTROL, self.control),
            (Source.COCKPIT, self.cockpit),
        ):
            for name, held in slot.items():
                entry: dict[str, Any] = {"source": source.value, "age_s": now_s - held.updated_s}
                if source is Source.COCKPIT:
                    entry["expires_in_s"] = held.updated_s + self.cockpit_hold_s - now_s
                elif source is Source.CIGI:
                    entry["expires_in_s"] = self.cigi_heard_s + self.cigi_hold_s - now_s
                out[name] = entry
        return out


def _whole(slot: Slot) -> dict[str, Any]:
    return {n: h.value for n, h in slot.items() if n in FIELDS}


def _merged(slot: Slot, values: dict[str, Held]) -> Slot:
    return MappingProxyType({**slot, **values})


def _without_time(patch: WeatherPatch) -> WeatherPatch:
    return dataclasses.replace(patch, time_utc=None)
