"""A decoded METAR as a `WeatherPatch`: cloud layers from a documented table, plus the wind,
visibility, temperatures and altimeter the report states.

Sources of the tables below:

* Cover in oktas: WMO code table 2700 (FEW 1-2, SCT 3-4, BKN 5-7, OVC 8). Each cover takes the
  top of its range, so thin cover still shows on screen; VV (sky obscured) is 8.
* Étages (altitude bands, by base above ground): WMO International Cloud Atlas, temperate
  regions: low clouds from the surface to 2 km, middle 2-7 km, high above. The band picks the
  genus (cumulus/stratocumulus/stratus low, altocumulus/altostratus middle, cirrus/cirrostratus
  high); a reported CB or TCU overrides it.
* Convective or stratiform low cloud: Espy's rule puts the base of surface-based convective
  cloud at about 125 m per °C of temperature-dewpoint spread. A low layer whose reported base
  lies near that estimate (within `CONVECTIVE_TOLERANCE_M` or `CONVECTIVE_TOLERANCE_FRACTION`)
  is convective; one much lower was not made by surface heating and is stratiform; without
  temperature and dewpoint, or with a base well above the estimate, the form is undetermined
  and the cover alone decides.
* Layer depths: typical vertical extents from the Cloud Atlas descriptions (stratus a few
  hundred metres, cumulus about a kilometre, towering cumulus several, cumulonimbus through
  the troposphere). Convective cumulus gets deeper with the instability proxy: its depth is
  scaled by the Espy base over `REFERENCE_CONVECTIVE_BASE_M`, clamped to `CONVECTIVE_DEPTH_SCALE`
  (a high base means a dry, strongly heated boundary layer and tall thermals).
* Clear-sky groups: CAVOK, NSC and NCD state no cloud below 5,000 ft (1,500 m) AGL (ICAO Annex 3);
  CLR is the US automatic stations' "none below 12,000 ft"; SKC is "no cloud at all". Groups
  reported above the limit are kept; with none, the layers are `()` (clear).

`docs/metar-clouds.md` holds `table_markdown()`'s output so the documentation cannot drift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from wxsky.schema import Number
from wxsky.units import FT_TO_M
from wxsky.weather.metar import Metar, MetarSkyGroup
from wxsky.weather.metar_fog import metar_fog
from wxsky.weather.state import MAX_LAYERS, CloudLayer, CloudType, Source, WeatherPatch, WindLayer

Band = Literal["low", "middle", "high", "any"]
Form = Literal["CB", "TCU", "convective", "stratiform", "undetermined", "-"]
Cover = Literal["FEW", "SCT", "BKN", "OVC"]

COVER_OKTAS: dict[str, int] = {"FEW": 2, "SCT": 4, "BKN": 6, "OVC": 8, "VV": 8}

# (band, lowest base AGL in metres): a base belongs to the last band whose floor it reaches.
BAND_FLOORS_M: tuple[tuple[Band, float], ...] = (("low", 0.0), ("middle", 2000.0), ("high", 7000.0))

ESPY_M_PER_C = 125.0
CONVECTIVE_TOLERANCE_M = 300.0
CONVECTIVE_TOLERANCE_FRACTION = 0.3
REFERENCE_CONVECTIVE_BASE_M = 1000.0  # fair-weather cumulus: spread about 8 °C
CONVECTIVE_DEPTH_SCALE = (0.5, 2.0)

WIND_HEIGHT_M = 10.0  # anemometer height above the field
VV_MIN_DEPTH_M = 30.0  # VV000 still gets a visible fog layer
MAX_CLOUD_TOP_M = 25_000.0  # CloudLayer's limit
# A report's field elevation: any airport on Earth (the control channel's and the command
# line's `field_elevation_m` are checked against this kind).
FIELD_ELEVATION_RANGE_M = (-500.0, 9000.0)
FIELD_ELEVATION_M = Number(*FIELD_ELEVATION_RANGE_M, unit="m")

# Lowest base (ft AGL) a layer may have and still be reported alongside each clear-sky group.
CLEAR_SKY_MIN_BASE_FT: dict[str, float] = {
    "CAVOK": 5000.0,
    "NSC": 5000.0,
    "NCD": 5000.0,
    "CLR": 12000.0,
    "SKC": math.inf,
}


@dataclass(frozen=True)
class CloudRow:
    """One row of the sky-group table: which layer a cover in a band and form becomes."""

    band: Band
    form: Form
    cover: Cover | Literal["any"]
    cloud_type: CloudType
    thickness_m: float
    scales_with_spread: bool = False  # depth grows with the Espy base (instability proxy)
    note: str = ""


CLOUD_TABLE: tuple[CloudRow, ...] = (
    CloudRow("any", "CB", "any", CloudType.CUMULONIMBUS, 9000.0, note="reported CB"),
    CloudRow("any", "TCU", "any", CloudType.CUMULUS, 4000.0, note="towering cumulus (congestus)"),
    CloudRow("low", "convective", "FEW", CloudType.CUMULUS, 1200.0, True),
    CloudRow("low", "convective", "SCT", CloudType.CUMULUS, 1200.0, True),
    CloudRow("low", "convective", "BKN", CloudType.CUMULUS, 1200.0, True),
    CloudRow("low", "convective", "OVC", CloudType.STRATOCUMULUS, 600.0, note="spread-out Cu"),
    CloudRow("low", "stratiform", "FEW", CloudType.STRATOCUMULUS, 400.0),
    CloudRow("low", "stratiform", "SCT", CloudType.STRATOCUMULUS, 500.0),
    CloudRow("low", "stratiform", "BKN", CloudType.STRATOCUMULUS, 600.0),
    CloudRow("low", "stratiform", "OVC", CloudType.STRATUS, 400.0),
    CloudRow("low", "undetermined", "FEW", CloudType.CUMULUS, 1200.0),
    CloudRow("low", "undetermined", "SCT", CloudType.CUMULUS, 1200.0),
    CloudRow("low", "undetermined", "BKN", CloudType.STRATOCUMULUS, 600.0),
    CloudRow("low", "undetermined", "OVC", CloudType.STRATUS, 400.0),
    CloudRow("middle", "-", "FEW", CloudType.ALTOCUMULUS, 500.0),
    CloudRow("middle", "-", "SCT", CloudType.ALTOCUMULUS, 500.0),
    CloudRow("middle", "-", "BKN", CloudType.ALTOCUMULUS, 500.0),
    CloudRow("middle", "-", "OVC", CloudType.ALTOSTRATUS, 1500.0),
    CloudRow("high", "-", "FEW", CloudType.CIRRUS, 1000.0),
    CloudRow("high", "-", "SCT", CloudType.CIRRUS, 1000.0),
    CloudRow("high", "-", "BKN", CloudType.CIRRUS, 1000.0),
    CloudRow("high", "-", "OVC", CloudType.CIRROSTRATUS, 800.0),
)
# VV: an obscured sky is fog or stratus from the ground up to the vertical visibility.
VV_CLOUD_TYPE = CloudType.STRATUS

_ROWS: dict[tuple[str, str, str], CloudRow] = {
    (row.band, row.form, row.cover): row for row in CLOUD_TABLE
}


def band_of(base_agl_m: float) -> Band:
    band: Band = "low"
    for name, floor_m in BAND_FLOORS_M:
        if base_agl_m >= floor_m:
            band = name
    return band


def espy_base_m(temperature_c: float | None, dewpoint_c: float | None) -> float | None:
    """Estimated base of surface-based convective cloud above ground, or None if unknown."""
    if temperature_c is None or dewpoint_c is None:
        return None
    return max(0.0, temperature_c - dewpoint_c) * ESPY_M_PER_C


def low_cloud_form(base_agl_m: float, espy_m: float | None) -> Form:
    """convective / stratiform / undetermined for a low layer without CB or TCU."""
    if espy_m is None:
        return "undetermined"
    tolerance_m = max(CONVECTIVE_TOLERANCE_M, CONVECTIVE_TOLERANCE_FRACTION * espy_m)
    if base_agl_m < espy_m - tolerance_m:
        return "stratiform"
    if base_agl_m <= espy_m + tolerance_m:
        return "convective"
    return "undetermined"


def cloud_row(group: MetarSkyGroup, espy_m: float | None) -> CloudRow | None:
    """The table row for a cloud group, None for VV, a `///` cover or a missing base."""
    if group.base_m is None or group.cover not in ("FEW", "SCT", "BKN", "OVC"):
        return None
    if group.cb:
        return _ROWS["any", "CB", "any"]
    if group.tcu:
        return _ROWS["any", "TCU", "any"]
    band = band_of(group.base_m)
    form: Form = low_cloud_form(group.base_m, espy_m) if band == "low" else "-"
    return _ROWS[band, form, group.cover]


def cover_of_oktas(cover_oktas: float) -> Cover:
    """The report cover a (possibly fractional) okta count falls in (WMO code table 2700)."""
    if cover_oktas <= 2.0:
        return "FEW"
    if cover_oktas <= 4.0:
        return "SCT"
    if cover_oktas < 8.0:
        return "BKN"
    return "OVC"


def derived_layer_row(cover_oktas: float, base_agl_m: float, espy_m: float | None) -> CloudRow:
    """The table row for a layer known only by cover and base (a cockpit knob, not a report):
    the same bands and Espy test as a reported group without CB or TCU."""
    band = band_of(base_agl_m)
    form: Form = low_cloud_form(base_agl_m, espy_m) if band == "low" else "-"
    return _ROWS[band, form, cover_of_oktas(cover_oktas)]


def cloud_layer(
    group: MetarSkyGroup, field_elevation_m: float, espy_m: float | None
) -> CloudLayer | None:
    """The layer one sky group stands for, or None when it cannot be placed."""
    if group.base_m is None:
        return None
    if group.cover == "VV":
        # VV999 (99,900 ft) would reach above the state's ceiling: the layer stops there.
        top_m = min(field_elevation_m + max(group.base_m, VV_MIN_DEPTH_M), MAX_CLOUD_TOP_M)
        return CloudLayer(COVER_OKTAS["VV"], field_elevation_m, top_m, VV_CLOUD_TYPE)
    row = cloud_row(group, espy_m)
    if row is None:
        return None
    thickness_m = row.thickness_m
    if row.scales_with_spread and espy_m is not None:
        lo, hi = CONVECTIVE_DEPTH_SCALE
        thickness_m *= min(hi, max(lo, espy_m / REFERENCE_CONVECTIVE_BASE_M))
    base_m = field_elevation_m + group.base_m
    top_m = min(base_m + thickness_m, MAX_CLOUD_TOP_M)
    if top_m <= base_m:
        return None  # a base at or above the state's ceiling
    return CloudLayer(COVER_OKTAS[group.cover], base_m, top_m, row.cloud_type)


def cloud_layers(metar: Metar, field_elevation_m: float) -> tuple[CloudLayer, ...] | None:
    """The report's layers, lowest MAX_LAYERS; () for a clear sky, None when it says nothing."""
    clear = "CAVOK" if metar.cavok else metar.sky_clear
    groups = metar.sky
    if clear is not None:
        min_base_m = CLEAR_SKY_MIN_BASE_FT[clear] * FT_TO_M
        groups = tuple(s for s in groups if s.base_m is not None and s.base_m >= min_base_m)
    elif not groups:
        return None  # no sky group at all: unknown, not clear
    espy_m = espy_base_m(metar.temperature_c, metar.dewpoint_c)
    layers = [
        layer
        for group in sorted(groups, key=lambda s: s.base_m or 0.0)
        if (layer := cloud_layer(group, field_elevation_m, espy_m)) is not None
    ]
    if not layers and clear is None:
        return None  # only groups without cover or base (BKN///): cloud, but nowhere known
    return tuple(layers[:MAX_LAYERS])


def metar_to_patch(metar: Metar, *, field_elevation_m: float) -> WeatherPatch:
    """The weather a report states, with cloud bases and wind moved to MSL.

    A NIL report says nothing. Wind: one layer 10 m above the field; VRB or an unreported
    direction gives dir 0, variable=True. A report without weather groups says "no weather"
    (an empty tuple). Temperatures outside what the weather state accepts are left out.
    """
    lo, hi = FIELD_ELEVATION_RANGE_M
    if not lo <= field_elevation_m <= hi:
        raise ValueError(f"field_elevation_m {field_elevation_m} outside {lo:g}..{hi:g}")
    if metar.nil:
        return WeatherPatch(source=Source.METAR)
    return WeatherPatch(
        source=Source.METAR,
        layers=cloud_layers(metar, field_elevation_m),
        wind=_wind_layers(metar, field_elevation_m),
        visibility_m=metar.visibility_m,
        temperature_c=_state_temperature(metar.temperature_c),
        dewpoint_c=_state_temperature(metar.dewpoint_c),
        qnh_hpa=metar.altimeter_hpa,
        present_weather=metar.weather,
        fog=metar_fog(metar),
    )


# The decoder accepts ±70 °C (the report range); the weather state stops at -90..60 °C.
_STATE_TEMPERATURE_RANGE_C = (-90.0, 60.0)


def _state_temperature(value_c: float | None) -> float | None:
    lo, hi = _STATE_TEMPERATURE_RANGE_C
    return value_c if value_c is not None and lo <= value_c <= hi else None


def _wind_layers(metar: Metar, field_elevation_m: float) -> tuple[WindLayer, ...] | None:
    w = metar.wind
    if w is None:
        return None
    return (
        WindLayer(
            alt_m=field_elevation_m + WIND_HEIGHT_M,
            dir_from_deg=0.0 if w.dir_from_deg is None else w.dir_from_deg,
            speed_mps=w.speed_mps,
            gust_mps=w.gust_mps or 0.0,
            variable=w.dir_from_deg is None,
        ),
    )


def table_markdown() -> str:
    """The tables above as markdown, for docs/metar-clouds.md."""
    lines = ["| Cover | Oktas |", "|---|---:|"]
    lines += [f"| {cover} | {oktas} |" for cover, oktas in COVER_OKTAS.items()]
    lines += ["", "| Band | Base AGL from |", "|---|---:|"]
    lines += [f"| {band} | {floor_m:.0f} m |" for band, floor_m in BAND_FLOORS_M]
    lines += [
        "",
        "| Band | Form | Cover | Cloud type | Depth | Depth scales with spread | Note |",
        "|---|---|---|---|---:|---|---|",
    ]
    lines += [
        f"| {r.band} | {r.form} | {r.cover} | {r.cloud_type.wire_name} | {r.thickness_m:.0f} m "
        f"| {'yes' if r.scales_with_spread else 'no'} | {r.note} |"
        for r in CLOUD_TABLE
    ]
    lines += [
        f"| ground | VV | VV | {VV_CLOUD_TYPE.wire_name} | to the VV height, "
        f"at least {VV_MIN_DEPTH_M:.0f} m | no | obscured sky |",
        "",
        "| Clear-sky group | Layers kept |",
        "|---|---|",
    ]
    lines += [
        f"| {code} | {'none' if math.isinf(ft) else f'base {ft:,.0f} ft AGL or higher'} |"
        for code, ft in CLEAR_SKY_MIN_BASE_FT.items()
    ]
    lines += [
        "",
        f"Espy's rule: convective base ≈ {ESPY_M_PER_C:.0f} m per °C of temperature-dewpoint "
        f"spread; convective when the reported base is within ±max({CONVECTIVE_TOLERANCE_M:.0f} "
        f"m, {CONVECTIVE_TOLERANCE_FRACTION:.0%} of the estimate), stratiform when lower. "
        f"Depth scale = Espy base / {REFERENCE_CONVECTIVE_BASE_M:.0f} m, clamped to "
        f"{CONVECTIVE_DEPTH_SCALE[0]:g}..{CONVECTIVE_DEPTH_SCALE[1]:g}.",
    ]
    return "\n".join(lines) + "\n"
