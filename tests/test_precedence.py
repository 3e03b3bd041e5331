"""Each field takes the highest-ranked source that holds it; cockpit holds expire."""

from __future__ import annotations

import dataclasses

import pytest

from wxsky.weather.precedence import SourceStack
from wxsky.weather.state import CloudLayer, CloudType, Source, WeatherPatch, WeatherState

OVC = (CloudLayer(8, 300.0, 700.0, CloudType.STRATUS),)
SCT = (CloudLayer(4, 1500.0, 2500.0, CloudType.CUMULUS),)
FEW = (CloudLayer(2, 2000.0, 2600.0, CloudType.CUMULUS),)


def _stack() -> SourceStack:
    base = WeatherState().apply(WeatherPatch(source=Source.PRESET, layers=(), visibility_m=9000.0))
    return SourceStack(base=base, cockpit_hold_s=30.0)


def test_metar_beats_the_base_and_control_beats_metar() -> None:
    stack = _stack().with_patch(
        WeatherPatch(source=Source.METAR, layers=SCT, visibility_m=5000.0), 0.0
    )
    target = stack.target()
    assert target.layers == SCT and target.sources.layers is Source.METAR
    stack = stack.with_patch(WeatherPatch(source=Source.CONTROL, layers=OVC), 1.0)
    # A later METAR changes what lies under the override, not the override.
    stack = stack.with_patch(
        WeatherPatch(source=Source.METAR, layers=FEW, visibility_m=7000.0), 2.0
    )
    target = stack.target()
    assert target.layers == OVC and target.sources.layers is Source.CONTROL
    assert target.visibility_m == 7000.0 and target.sources.visibility_m is Source.METAR
    stack, released = stack.released(Source.CONTROL)
    assert released == ("layers",)
    assert stack.target().layers == FEW


def test_a_new_metar_replaces_the_old_one_whole() -> None:
    stack = _stack().with_patch(
        WeatherPatch(source=Source.METAR, layers=SCT, visibility_m=5000.0), 0.0
    )
    stack = stack.with_patch(WeatherPatch(source=Source.METAR, visibility_m=6000.0), 1.0)
    target = stack.target()
    # The new report has no sky group: the clouds fall back to the base, not to the old report.
    assert target.layers == () and target.sources.layers is Source.PRESET
    assert target.visibility_m == 6000.0


def test_cockpit_wins_while_held_then_expires() -> None:
    stack = _stack().with_patch(WeatherPatch(source=Source.CONTROL, layers=OVC), 0.0)
    stack = stack.with_patch(WeatherPatch(source=Source.COCKPIT, layers=FEW), 10.0)
    assert stack.target().layers == FEW
    stack, gone = stack.expired(39.0)
    assert gone == () and stack.target().sources.layers is Source.COCKPIT
    # An update renews the hold.
    stack = stack.with_patch(WeatherPatch(source=Source.COCKPIT, layers=SCT), 35.0)
    stack, gone = stack.expired(60.0)
    assert gone == () and stack.target().layers == SCT
    stack, gone = stack.expired(65.5)
    assert gone == ("layers",)
    assert stack.target().layers == OVC and stack.target().sources.layers is Source.CONTROL


def test_cockpit_fields_expire_one_by_one() -> None:
    stack = _stack().with_patch(
        WeatherPatch(source=Source.COCKPIT, layers=FEW, visibility_m=1000.0), 0.0
    )
    stack = stack.with_patch(WeatherPatch(source=Source.COCKPIT, visibility_m=1500.0), 20.0)
    stack, gone = stack.expired(40.0)
    assert gone == ("layers",)
    assert stack.target().visibility_m == 1500.0
    holds = stack.holds(40.0)
    assert holds == {"visibility_m": {"source": "cockpit", "age_s": 20.0, "expires_in_s": 10.0}}


def test_base_patches_change_the_base_but_not_the_clock() -> None:
    stack = _stack()
    new = stack.with_patch(WeatherPatch(source=Source.PRESET, layers=OVC, seed=5), 0.0)
    assert new.target().layers == OVC and new.target().seed == 5
    assert new.target().time_utc == stack.base.time_utc


def test_only_overrides_can_be_released() -> None:
    with pytest.raises(ValueError, match="default"):
        _stack().released(Source.DEFAULT)


def test_a_cigi_host_ranks_between_control_and_metar_while_it_keeps_sending() -> None:
    stack = _stack().with_patch(
        WeatherPatch(source=Source.METAR, layers=SCT, visibility_m=5000.0), 0.0
    )
    stack = dataclasses.replace(stack, cigi_hold_s=10.0)
    stack = stack.with_patch(WeatherPatch(source=Source.CIGI, layers=OVC), 1.0)
    target = stack.target()
    assert target.layers == OVC and target.sources.layers is Source.CIGI
    # The host's picture stands alone, as a METAR's: visibility it did not give is METAR's.
    assert target.visibility_m == 5000.0 and target.sources.visibility_m is Source.METAR
    stack = stack.with_patch(WeatherPatch(source=Source.CONTROL, layers=FEW), 2.0)
    assert stack.target().sources.layers is Source.CONTROL
    stack, _ = stack.released(Source.CONTROL)
    assert stack.target().layers == OVC
    # Any message from the host keeps its weather; silence for the hold time hands it back.
    stack = stack.heard_cigi(9.0)
    stack, gone = stack.expired(18.5)
    assert gone == () and stack.target().sources.layers is Source.CIGI
    assert stack.holds(18.5)["layers"]["source"] == "cigi"
    stack, gone = stack.expired(19.5)
    assert gone == ("layers",)
    assert stack.target().layers == SCT and stack.target().sources.layers is Source.METAR
