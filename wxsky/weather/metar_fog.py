"""A METAR's fog (issue 43 item 3, docs/fog.md): its fog groups (`FG`, `FZFG`, `BCFG`,
`PRFG`, `MIFG`) and its runway visual range groups (WMO FM-15 15.7: `R14/0600N`,
`R32L/P1500`, `R06/0400V0800U`, `R14/M0050`, `R28L/2400FT`) as the weather state's `Fog`.

Mist (`BR`) is not fog: the report's visibility already is the mist's, and the air's haze
draws it; with RVR groups the fog is only what they ask for at their runways.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from wxsky.units import FT_TO_M
from wxsky.weather.metar import Metar
from wxsky.weather.state import MAX_RVR, NO_FOG, RVR_M, Fog, RunwayRvr

RVR_GROUP = re.compile(
    r"R(?P<runway>[0-9]{2}[LCR]?)/(?P<lo_sign>[PM])?(?P<lo>[0-9]{4})"
    r"(?:V(?P<hi_sign>[PM])?(?P<hi>[0-9]{4}))?(?P<feet>FT)?(?:/?(?P<trend>[UDN]))?/?"
)

# Inside a bank of fog or a shallow fog the report gives no figure (its visibility is the
# prevailing one, mostly outside them): 200 m, well inside fog's "under 1 km".
BANK_VISIBILITY_M = 200.0
# A fog sheet with no usable visibility in the report (`//// FG`).
SHEET_VISIBILITY_M = 500.0
# Tops: a fog sheet is typically 100-300 m deep (radiation fog), banks shallower; WMO's
# shallow fog (MI) reaches less than 2 m over land.
SHEET_DEPTH_M = 150.0
BANK_DEPTH_M = 60.0
SHALLOW_DEPTH_M = 2.0


@dataclass(frozen=True)
class RvrGroup:
    """One RVR group decoded: the runway, the range (the mean of a `V` group's extremes) in
    metres, whether it is beyond the system's limits (`P`: more than, `M`: less than), the
    tendency (`U`, `D`, `N` or None)."""

    runway: str
    rvr_m: float
    more_than: bool
    less_than: bool
    tendency: str | None


def rvr_group(text: str) -> RvrGroup | None:
    """An RVR group decoded, or None when it is not one (or names runway 88 or 99, all
    runways or a repeat, which place nothing; or runway 00 or one beyond 36)."""
    m = RVR_GROUP.fullmatch(text)
    if m is None:
        return None
    runway = m["runway"]
    number = int(runway[:2])
    if not 1 <= number <= 36:
        return None
    scale = FT_TO_M if m["feet"] else 1.0
    lo = float(m["lo"]) * scale
    hi = float(m["hi"]) * scale if m["hi"] else lo
    return RvrGroup(
        runway=runway,
        rvr_m=0.5 * (lo + hi),
        more_than=(m["hi_sign"] or m["lo_sign"]) == "P",
        less_than=m["lo_sign"] == "M",
        tendency=m["trend"],
    )


def metar_fog(metar: Metar) -> Fog:
    """The fog a report states: NO_FOG when it reports neither fog at the station nor RVR.
    Runway ranges are clamped into what the state holds (a `R14/0000` as RVR_M's least)."""
    rvr: list[RunwayRvr] = []
    lo, hi = RVR_M.bounds
    for text in metar.rvr:
        group = rvr_group(text)
        if group is None or any(r.runway == group.runway for r in rvr) or len(rvr) >= MAX_RVR:
            continue
        rvr.append(RunwayRvr(group.runway, min(max(group.rvr_m, lo), hi)))
    kind = _fog_kind(metar.weather)
    if kind is None:
        if not rvr:
            return NO_FOG
        return Fog(None, BANK_DEPTH_M, False, tuple(rvr))
    if kind == "patchy":
        return Fog(BANK_VISIBILITY_M, BANK_DEPTH_M, True, tuple(rvr))
    if kind == "shallow":
        return Fog(BANK_VISIBILITY_M, SHALLOW_DEPTH_M, False, tuple(rvr))
    vis = metar.visibility_m
    sheet_m = vis if vis is not None and 10.0 <= vis <= 1000.0 else SHEET_VISIBILITY_M
    return Fog(sheet_m, SHEET_DEPTH_M, False, tuple(rvr))


def _fog_kind(groups: tuple[str, ...]) -> str | None:
    """ "sheet" (FG, FZFG), "patchy" (BCFG, PRFG), "shallow" (MIFG) or None: the densest the
    report names at the station (a sheet over banks over shallow fog). VCFG is fog in the
    vicinity, not at the station, and BR is mist, not fog."""
    found: set[str] = set()
    for group in groups:
        g = group.lstrip("+-")
        if g.startswith("VC") or "FG" not in g:
            continue
        if g.startswith(("BC", "PR")):
            found.add("patchy")
        elif g.startswith("MI"):
            found.add("shallow")
        else:
            found.add("sheet")
    for kind in ("sheet", "patchy", "shallow"):
        if kind in found:
            return kind
    return None
