"""Cloud layers from a model column (issue 45, docs/weather-aloft.md): what the sky holds where no
METAR speaks (above what a station reports, and far from stations), and the tops of the
layers a METAR reports.

Two ways, the first the model allows:

1. **Decks.** Where the model gives each deck's cover with its bottom and top pressures (NCEP
   GFS: low, middle and high cloud, and convective cloud), each deck with cover is a layer
   from its bottom to its top (pressures to heights through the profile). GFS's decks are
   averages over the forecast period; a deck under `MIN_COVER_PCT` is left out.
2. **Humidity.** Otherwise (ECMWF's open data and ICON give cover but no heights), cloud is
   where the relative humidity passes a critical value that falls with height (`RH_CRIT`:
   Sundqvist's scheme, as the models themselves diagnose cloud): a run of levels over it is a
   layer from half-way below its lowest level to half-way above its highest, with cover
   8 * (1 - sqrt((1 - RH) / (1 - RHc))) oktas at the run's wettest level.

The type follows the height and the stability: low cloud is cumulus where the air is
unstable (CAPE over `CUMULUS_CAPE_JKG`, the lapse rate from the ground to 700 hPa over
`UNSTABLE_LAPSE_K_PER_KM`, or the convective deck has cover), cumulonimbus
where it is strongly so and the cloud reaches well above the freezing level; stratus or
stratocumulus otherwise, nimbostratus where it is thick and rains; middle cloud altostratus
when nearly overcast, else altocumulus; high cloud cirrostratus when nearly overcast, else
cirrus.
"""

from __future__ import annotations

import math

from wxsky.weather.model_profile import ModelProfile, ProfileLevel
from wxsky.weather.state import MAX_LAYERS, CloudLayer, CloudType

MIN_COVER_PCT = 6.25  # half an okta: less is no layer
MIN_THICKNESS_M = 150.0
MAX_TOP_M = 25_000.0  # CloudLayer's limit
CUMULUS_CAPE_JKG = 250.0
CUMULONIMBUS_CAPE_JKG = 1000.0
# Between the moist (about 6) and the dry (9.8) adiabatic lapse rates the air is
# conditionally unstable: a lifted cloudy parcel keeps rising, and low cloud heaps up.
UNSTABLE_LAPSE_K_PER_KM = 7.5
RAIN_MMPH = 0.5
LOW_TOP_HPA = 680.0  # the bottom of the middle deck, as NCEP divides them
HIGH_BASE_HPA = 440.0


def rh_crit_pct(pressure_hpa: float, surface_hpa: float = 1013.25) -> float:
    """The relative humidity over which the model air is taken to hold cloud: high near the
    ground, lower aloft (where the same RH over water is a higher one over ice)."""
    sigma = pressure_hpa / surface_hpa
    return 100.0 * (0.70 + 0.20 * max(0.0, min(1.0, (sigma - 0.4) / 0.6)))


def cover_from_rh(rh_pct: float, rh_crit: float) -> float:
    """Sundqvist's cloud fraction (0..1) for a relative humidity over the critical one."""
    if rh_pct <= rh_crit:
        return 0.0
    excess = min(1.0, (100.0 - min(rh_pct, 100.0)) / (100.0 - rh_crit))
    return 1.0 - math.sqrt(excess)


def model_layers(profile: ModelProfile) -> tuple[CloudLayer, ...]:
    """The column's cloud layers, lowest first, at most MAX_LAYERS (the most cover kept)."""
    have_heights = any(d.base_hpa and d.top_hpa for d in profile.decks if d.name != "convective")
    layers = _from_decks(profile) if have_heights else _from_humidity(profile)
    layers.sort(key=lambda lay: -lay.cover_oktas)
    return tuple(sorted(layers[:MAX_LAYERS], key=lambda lay: lay.base_m))


def _from_decks(p: ModelProfile) -> list[CloudLayer]:
    out: list[CloudLayer] = []
    for deck in p.decks:
        if deck.cover_pct < MIN_COVER_PCT or deck.base_hpa is None or deck.top_hpa is None:
            continue
        base = p.height_of_pressure(deck.base_hpa)
        top = p.height_of_pressure(deck.top_hpa)
        if base is None or top is None:
            continue
        if p.surface_m is not None:
            base = max(base, p.surface_m + 50.0)
        top = min(max(top, base + MIN_THICKNESS_M), MAX_TOP_M)
        if base >= MAX_TOP_M - MIN_THICKNESS_M:
            continue
        cover = 8.0 * deck.cover_pct / 100.0
        kind = _type(p, deck.name, deck.base_hpa, base, top, cover)
        out.append(CloudLayer(cover, base, top, kind))
    return _without_duplicate_convection(out)


def _without_duplicate_convection(layers: list[CloudLayer]) -> list[CloudLayer]:
    """The convective deck and the low deck are often the same cloud: a cumulus layer that
    overlaps another low layer takes the larger cover and the deeper extent."""
    conv = [lay for lay in layers if lay.type in (CloudType.CUMULUS, CloudType.CUMULONIMBUS)]
    rest = [lay for lay in layers if lay not in conv]
    for c in conv:
        for i, other in enumerate(rest):
            if other.base_m < c.top_m and c.base_m < other.top_m and other.base_m < 3000.0:
                rest[i] = CloudLayer(
                    max(c.cover_oktas, other.cover_oktas),
                    min(c.base_m, other.base_m),
                    max(c.top_m, other.top_m),
                    c.type,
                )
                break
        else:
            rest.append(c)
    return rest


def _from_humidity(p: ModelProfile) -> list[CloudLayer]:
    out: list[CloudLayer] = []
    run: list[ProfileLevel] = []
    levels = [lev for lev in p.levels if lev.rh_pct is not None]
    surface = p.surface_hpa or 1013.25
    for lev in [*levels, None]:
        wet = (
            lev is not None
            and lev.rh_pct is not None
            and lev.rh_pct > rh_crit_pct(lev.pressure_hpa, surface)
        )
        if wet and lev is not None:
            run.append(lev)
            continue
        if run:
            layer = _run_layer(p, levels, run, surface)
            if layer is not None:
                out.append(layer)
            run = []
    return out


def _run_layer(
    p: ModelProfile, levels: list[ProfileLevel], run: list[ProfileLevel], surface: float
) -> CloudLayer | None:
    i0, i1 = levels.index(run[0]), levels.index(run[-1])
    below = levels[i0 - 1].height_m if i0 > 0 else run[0].height_m - 300.0
    above = levels[i1 + 1].height_m if i1 + 1 < len(levels) else run[-1].height_m + 300.0
    base = 0.5 * (below + run[0].height_m)
    top = 0.5 * (run[-1].height_m + above)
    if p.surface_m is not None:
        base = max(base, p.surface_m + 50.0)
    top = min(max(top, base + MIN_THICKNESS_M), MAX_TOP_M)
    if base >= MAX_TOP_M - MIN_THICKNESS_M:
        return None
    fraction = max(
        cover_from_rh(lev.rh_pct or 0.0, rh_crit_pct(lev.pressure_hpa, surface)) for lev in run
    )
    cover = 8.0 * fraction
    if cover < 8.0 * MIN_COVER_PCT / 100.0:
        return None
    base_hpa = run[0].pressure_hpa
    deck = "low" if base_hpa > LOW_TOP_HPA else "middle" if base_hpa > HIGH_BASE_HPA else "high"
    return CloudLayer(cover, base, top, _type(p, deck, base_hpa, base, top, cover))


def lapse_k_per_km(p: ModelProfile) -> float:
    """How fast the temperature falls with height from the lowest level to 700 hPa (K/km;
    0 where the column does not reach that high)."""
    if not p.levels:
        return 0.0
    low = p.levels[0]
    top = next((lev for lev in p.levels if lev.pressure_hpa <= 700.0), None)
    if top is None or top.height_m - low.height_m < 500.0:
        return 0.0
    return (low.t_k - top.t_k) / ((top.height_m - low.height_m) / 1000.0)


def _type(
    p: ModelProfile, deck: str, base_hpa: float, base_m: float, top_m: float, cover: float
) -> CloudType:
    cape = p.cape_jkg or 0.0
    rain = (p.precip_mmph or 0.0) >= RAIN_MMPH
    conv_deck = any(d.name == "convective" and d.cover_pct >= MIN_COVER_PCT for d in p.decks)
    unstable = cape >= CUMULUS_CAPE_JKG or conv_deck or lapse_k_per_km(p) >= UNSTABLE_LAPSE_K_PER_KM
    if deck == "convective" or (deck == "low" and unstable):
        deep = p.freezing_m is not None and top_m > p.freezing_m + 2000.0
        if cape >= CUMULONIMBUS_CAPE_JKG and deep:
            return CloudType.CUMULONIMBUS
        return CloudType.CUMULUS
    if deck == "low" or base_hpa > LOW_TOP_HPA:
        if rain and top_m - base_m > 1500.0:
            return CloudType.NIMBOSTRATUS
        return (
            CloudType.STRATUS
            if cover >= 7.0 and top_m - base_m < 600.0
            else CloudType.STRATOCUMULUS
        )
    if deck == "middle":
        if rain and top_m - base_m > 2000.0:
            return CloudType.NIMBOSTRATUS
        return CloudType.ALTOSTRATUS if cover >= 6.0 else CloudType.ALTOCUMULUS
    return CloudType.CIRROSTRATUS if cover >= 6.0 else CloudType.CIRRUS
