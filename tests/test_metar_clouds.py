"""METAR -> WeatherPatch: the cloud table row by row, the clear-sky rules, and the other fields."""

from __future__ import annotations

from pathlib import Path

import pytest

from wxsky.units import FT_TO_M, KT_TO_MPS, STATUTE_MILE_TO_M
from wxsky.weather import metar_clouds as mc
from wxsky.weather.metar import Metar, decode
from wxsky.weather.metar_clouds import CLOUD_TABLE, CloudRow, metar_to_patch, table_markdown
from wxsky.weather.state import MAX_LAYERS, CloudLayer, CloudType, Source, WeatherState

DOC = Path(__file__).resolve().parents[1] / "docs" / "metar-clouds.md"
FIELD_M = 500.0


def dec(text: str) -> Metar:
    return decode(text, year=2025, month=7)


def layers_of(groups: str, field_elevation_m: float = FIELD_M) -> tuple[CloudLayer, ...] | None:
    return metar_to_patch(dec(f"KXYZ 261550Z {groups}"), field_elevation_m=field_elevation_m).layers


# For each band and form: a base (hundreds of ft AGL) and a temperature group that put a layer
# there. Convective: spread 8 °C -> Espy base 1000 m, reported base 1006 m. Stratiform: spread
# 12 °C -> Espy 1500 m, reported 152 m. Undetermined: no dewpoint.
EXAMPLES: dict[tuple[str, str], tuple[str, str]] = {
    ("any", "CB"): ("030", "20/10"),
    ("any", "TCU"): ("030", "20/10"),
    ("low", "convective"): ("033", "20/12"),
    ("low", "stratiform"): ("005", "20/08"),
    ("low", "undetermined"): ("030", "20/"),
    ("middle", "-"): ("100", "10/05"),
    ("high", "-"): ("250", "10/05"),
}


def _row_id(row: CloudRow) -> str:
    return f"{row.band}-{row.form}-{row.cover}"


@pytest.mark.parametrize("row", CLOUD_TABLE, ids=_row_id)
def test_cloud_table_row(row: CloudRow) -> None:
    height, temps = EXAMPLES[row.band, row.form]
    cover = "BKN" if row.cover == "any" else row.cover
    suffix = row.form if row.form in ("CB", "TCU") else ""
    layers = layers_of(f"{cover}{height}{suffix} {temps}")
    assert layers is not None and len(layers) == 1
    layer = layers[0]
    assert layer.type is row.cloud_type
    assert layer.cover_oktas == mc.COVER_OKTAS[cover]
    assert layer.base_m == pytest.approx(FIELD_M + int(height) * 100 * FT_TO_M)
    # The examples put convective bases at the reference Espy base: scale 1.
    assert layer.thickness_m == pytest.approx(row.thickness_m)


def test_cloud_table_is_complete_and_unambiguous() -> None:
    keys = [(r.band, r.form, r.cover) for r in CLOUD_TABLE]
    assert len(keys) == len(set(keys))
    covers = ("FEW", "SCT", "BKN", "OVC")
    expected = {("any", "CB", "any"), ("any", "TCU", "any")}
    expected |= {
        ("low", f, c) for f in ("convective", "stratiform", "undetermined") for c in covers
    }
    expected |= {(b, "-", c) for b in ("middle", "high") for c in covers}
    assert set(keys) == expected
    assert all(r.thickness_m > 0 for r in CLOUD_TABLE)


@pytest.mark.parametrize(
    ("cover", "oktas"), [("FEW", 2), ("SCT", 4), ("BKN", 6), ("OVC", 8), ("VV", 8)]
)
def test_oktas_per_cover(cover: str, oktas: int) -> None:
    # WMO code 2700: FEW 1-2, SCT 3-4, BKN 5-7, OVC 8; each takes the top of its range.
    assert mc.COVER_OKTAS[cover] == oktas


@pytest.mark.parametrize(
    ("height", "band"),
    [("000", "low"), ("065", "low"), ("066", "middle"), ("229", "middle"), ("230", "high")],
)
def test_band_boundaries(height: str, band: str) -> None:
    # 6500 ft = 1981 m, 6600 ft = 2012 m; 22900 ft = 6980 m, 23000 ft = 7010 m.
    assert mc.band_of(int(height) * 100 * FT_TO_M) == band


@pytest.mark.parametrize(
    ("base_m", "espy_m", "form"),
    [
        (1000.0, None, "undetermined"),
        (1000.0, 1000.0, "convective"),
        (700.0, 1000.0, "convective"),  # within 300 m
        (690.0, 1000.0, "stratiform"),
        (1300.0, 1000.0, "convective"),
        (1310.0, 1000.0, "undetermined"),  # well above the convective level
        (1400.0, 2000.0, "convective"),  # 30 % of 2000 m = 600 m
        (1390.0, 2000.0, "stratiform"),
        (0.0, 0.0, "convective"),  # saturated at the ground: fog lifting into cloud
    ],
)
def test_low_cloud_form_from_espy(base_m: float, espy_m: float | None, form: str) -> None:
    assert mc.low_cloud_form(base_m, espy_m) == form


def test_espy_base() -> None:
    assert mc.espy_base_m(20.0, 12.0) == 1000.0
    assert mc.espy_base_m(10.0, 12.0) == 0.0  # dewpoint above temperature: saturated
    assert mc.espy_base_m(None, 12.0) is None and mc.espy_base_m(20.0, None) is None


@pytest.mark.parametrize(
    ("groups", "depth_m"),
    [
        ("SCT003 20/18", 600.0),  # spread 2: Espy 250 m, scale clamped to 0.5
        ("SCT016 20/16", 600.0),  # spread 4: Espy 500 m, scale 0.5
        ("SCT040 20/10", 1500.0),  # spread 10: Espy 1250 m, scale 1.25
        ("SCT060 30/15", 2250.0),  # spread 15: Espy 1875 m, scale 1.875
    ],
)
def test_convective_cumulus_deepens_with_the_spread(groups: str, depth_m: float) -> None:
    layers = layers_of(groups)
    assert layers is not None and layers[0].type is CloudType.CUMULUS
    assert layers[0].thickness_m == pytest.approx(depth_m)


def test_same_base_is_cumulus_or_stratocumulus_by_spread() -> None:
    convective = layers_of("SCT010 20/19")  # Espy 125 m, base 305 m: near
    stratiform = layers_of("SCT010 25/05")  # Espy 2500 m, base 305 m: far below
    assert convective is not None and convective[0].type is CloudType.CUMULUS
    assert stratiform is not None and stratiform[0].type is CloudType.STRATOCUMULUS


# --- VV and the clear-sky groups ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("group", "top_agl_m"), [("VV005", 152.4), ("VV001", 30.48), ("VV000", 30)]
)
def test_vertical_visibility_is_fog_from_the_ground(group: str, top_agl_m: float) -> None:
    layers = layers_of(f"0100 FG {group}")
    assert layers is not None and len(layers) == 1
    fog = layers[0]
    assert (fog.cover_oktas, fog.type) == (8, CloudType.STRATUS)
    assert fog.base_m == FIELD_M
    assert fog.top_m == pytest.approx(FIELD_M + top_agl_m)


def test_vertical_visibility_without_height_says_nothing() -> None:
    assert layers_of("0100 FG VV///") is None


@pytest.mark.parametrize(
    ("groups", "layer_bases_ft"),
    [
        ("CAVOK", []),
        ("9999 NSC", []),
        ("9999 NCD", []),
        ("10SM CLR", []),
        ("10SM SKC", []),
        ("9999 NSC FEW030 SCT060", [6000]),  # only cloud at or above 5,000 ft survives
        ("9999 NCD BKN050", [5000]),
        ("10SM CLR FEW050 SCT130", [13000]),  # CLR: none below 12,000 ft
        ("10SM SKC FEW250", []),
    ],
)
def test_clear_sky_groups(groups: str, layer_bases_ft: list[int]) -> None:
    layers = layers_of(groups, field_elevation_m=0.0)
    assert layers is not None
    assert [round(lay.base_m / FT_TO_M) for lay in layers] == layer_bases_ft


def test_no_sky_group_says_nothing_about_clouds() -> None:
    assert layers_of("27010KT 9999 20/10 Q1015") is None


@pytest.mark.parametrize("groups", ["BKN///", "///030", "//////CB", "///CB", "SCT///TCU"])
def test_groups_without_cover_or_base_are_dropped(groups: str) -> None:
    assert layers_of(groups) is None  # there is cloud, but nothing says where
    kept = layers_of(f"FEW040 {groups}")
    assert kept is not None and len(kept) == 1


def test_max_layers_keeps_the_lowest() -> None:
    layers = layers_of("OVC250 FEW020 SCT040 BKN060 OVC090 FEW100 SCT120 BKN220", 0.0)
    assert layers is not None and len(layers) == MAX_LAYERS
    assert [round(lay.base_m / FT_TO_M) for lay in layers] == [
        2000,
        4000,
        6000,
        9000,
        10000,
        12000,
    ]


def test_tops_stay_within_the_state_limit() -> None:
    capped = layers_of("FEW700CB")
    assert capped is not None and capped[0].top_m == mc.MAX_CLOUD_TOP_M
    assert layers_of("OVC850") is None  # above the state's ceiling: nowhere to draw it


# --- the other fields ---------------------------------------------------------------------------


def test_patch_wind_layer() -> None:
    patch = metar_to_patch(dec("KXYZ 261550Z 24012G25KT 9999"), field_elevation_m=432.0)
    assert patch.wind is not None and len(patch.wind) == 1
    w = patch.wind[0]
    assert (w.alt_m, w.dir_from_deg, w.variable) == (442.0, 240.0, False)
    assert w.speed_mps == pytest.approx(12 * KT_TO_MPS)
    assert w.gust_mps == pytest.approx(25 * KT_TO_MPS)
    vrb = metar_to_patch(dec("KXYZ 261550Z VRB03KT 9999"), field_elevation_m=0.0).wind
    assert vrb is not None
    assert (vrb[0].dir_from_deg, vrb[0].variable, vrb[0].gust_mps) == (0.0, True, 0.0)


def test_patch_passes_values_through_and_leaves_unknowns_none() -> None:
    r = dec("SPECI CYBW 201519Z AUTO 15006KT 1SM -RA BR VV002 00/00 A2978")
    patch = metar_to_patch(r, field_elevation_m=1197.0)
    assert patch.source is Source.METAR
    assert patch.visibility_m == pytest.approx(STATUTE_MILE_TO_M)
    assert (patch.temperature_c, patch.dewpoint_c) == (0.0, 0.0)
    assert patch.qnh_hpa == pytest.approx(r.altimeter_hpa)
    assert patch.present_weather == ("-RA", "BR")
    assert patch.layers is not None and patch.layers[0].base_m == 1197.0
    assert patch.time_utc is None and patch.observer is None and patch.seed is None
    sparse = metar_to_patch(
        dec("KXYZ 261550Z AUTO /////KT //// ////// ///// Q////"), field_elevation_m=0.0
    )
    assert (sparse.wind, sparse.visibility_m, sparse.layers, sparse.temperature_c) == (None,) * 4
    assert sparse.qnh_hpa is None and sparse.present_weather == ()


def test_nil_report_says_nothing() -> None:
    patch = metar_to_patch(dec("KXYZ 261550Z NIL"), field_elevation_m=0.0)
    assert patch == type(patch)(source=Source.METAR)


def test_temperature_the_state_cannot_hold_is_left_out() -> None:
    r = dec("OIAW 261550Z 27010KT 9999 65/10 Q1005")
    assert r.temperature_c == 65.0  # within the decoder's ±70 °C
    patch = metar_to_patch(r, field_elevation_m=20.0)
    assert (patch.temperature_c, patch.dewpoint_c) == (None, 10.0)
    WeatherState().apply(patch)


def test_patch_applies_to_the_weather_state() -> None:
    r = dec("EGLL 261550Z 24010KT 200V280 9999 -RA FEW012 BKN025CB 18/14 Q1009 NOSIG")
    state = WeatherState().apply(metar_to_patch(r, field_elevation_m=25.0))
    assert state.sources.layers is Source.METAR and state.sources.qnh_hpa is Source.METAR
    assert state.qnh_hpa == 1009.0
    # Spread 4 °C: Espy base 500 m; FEW012 at 366 m is near it, so convective cumulus.
    assert [lay.type for lay in state.layers] == [CloudType.CUMULUS, CloudType.CUMULONIMBUS]


def test_patch_rejects_an_impossible_field_elevation() -> None:
    with pytest.raises(ValueError, match="field_elevation_m"):
        metar_to_patch(dec("KXYZ 261550Z 27010KT"), field_elevation_m=20_000.0)


# --- documentation ------------------------------------------------------------------------------


def test_doc_holds_the_generated_table() -> None:
    assert table_markdown() in DOC.read_text(encoding="utf-8")


def test_table_markdown_lists_every_row() -> None:
    text = table_markdown()
    for row in CLOUD_TABLE:
        assert f"| {row.band} | {row.form} | {row.cover} | {row.cloud_type.wire_name} |" in text
