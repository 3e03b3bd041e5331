"""Measure wxsky's METAR decoder against AWC's own decoded columns, beside python-metar.

    .venv/bin/python tools/bench/metar_agreement.py [--json] [--disagreements N] [FILE ...]

FILE defaults to every `tests/data/metar/awc_cache_*.csv.gz` (docs/metar-agreement.md has the
measured table). Each distinct report text (the first copy wins) is decoded with
`wxsky.weather.metar.decode` and with python-metar `Metar(raw, month=, year=, strict=False)`
(every exception caught: a crash disagrees on every field), and each field is compared with
AWC's column wherever AWC gives a value:

* wind speed and gust: the same whole knot (AWC converts MPS/KMH groups to knots);
* wind direction: the same degrees; VRB winds (AWC writes 0, or `VRB` in 2025) and calm winds
  (AWC speed 0: there is no direction) are not compared;
* visibility: `6+`/`10+` (2025 on) mean "at least that many SM" and the legacy `6.21` is 9999
  or CAVOK, so anything from 10 km up agrees with it; other values must give the same SM to
  AWC's hundredths;
* temperature: within 0.05 °C, or the same whole degree (within 0.5 °C) when AWC's value is
  whole and the report has a `Tsttt` remark;
* altimeter: within 0.01 inHg. Reports with both a Q and an A group are counted apart from the
  headline (reference §3.3: which group AWC took is ambiguous; it is the Q group);
* cloud layers: cover and base of the first four layers, in report order, CB/TCU ignored.
  Layers with a `///` height are left out on both sides (AWC drops them, and writes `VV///` as
  `OVX,0` with no vert_vis_ft); AWC `OVX` is our `VV`, its height from `cloud_base_ft_agl`
  (2026) or `vert_vis_ft` (legacy `OVX,0`). A lone `CLR`/`SKC` matches any clear token (CLR,
  SKC, NSC, NCD: AWC maps NSC/NCD to CLR from 2020 on); `CAVOK` matches CAVOK. An empty sky is
  no value (2014: NSC/NCD; 2026: CLR and CAVOK as well) and is not compared.

A disagreement is put down to AWC when one of AWC_RULES explains AWC's value from the report
text alone: an AWC error (its value contradicts the report: 0 °C for `09/08`, an altimeter of
24.97 inHg, trend layers folded in, a suffixed layer dropped) or an AWC guess (it decodes text
that is no valid group or no report at all, where wxsky by design decodes nothing). The bar
(exit status 0): every field but clouds agrees on at least 99.9 % of the compared reports, and
cloud layers agree at least as often as python-metar's.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from wxsky.units import INHG_TO_HPA, STATUTE_MILE_TO_M  # noqa: E402 - after the path is set
from wxsky.weather.feeds import Report, read_reports  # noqa: E402
from wxsky.weather.metar import decode  # noqa: E402

DATA_DIR = ROOT / "tests" / "data" / "metar"
CORPUS_GLOB = "awc_cache_*.csv.gz"

FIELDS = ("wind_speed", "wind_gust", "wind_dir", "visibility", "temperature", "altimeter", "clouds")
LABELS = {
    "wind_speed": "wind speed",
    "wind_gust": "gust",
    "wind_dir": "wind direction",
    "visibility": "visibility",
    "temperature": "temperature",
    "altimeter": "altimeter",
    "clouds": "cloud layers",
}
# Every field but clouds must agree on this share of comparable reports.
BAR = 0.999
CLOUD_LAYERS = 4  # AWC has four sky column pairs

TEN_KM_M = 9999.0
ALTIMETER_TOLERANCE_INHG = 0.01
TEMPERATURE_TOLERANCE_C = 0.05
WHOLE_DEGREE_TOLERANCE_C = 0.5  # AWC whole, the report in tenths: the same whole degree
VISIBILITY_TOLERANCE_SM = 0.005 + 1e-6  # AWC rounds to hundredths
LEGACY_TEN_KM_SM = "6.21"  # 2014-2022: 9999 and CAVOK
# No sea-level pressure outside this has ever been measured (870 and 1084 hPa are the records).
PLAUSIBLE_ALTIMETER_HPA = (850.0, 1100.0)

COVERS = frozenset({"FEW", "SCT", "BKN", "OVC", "VV"})
CLEAR_TOKENS = frozenset({"CLR", "SKC", "NSC", "NCD"})
PLAIN_SUFFIXES = frozenset({"", "CB", "TCU"})

# Report text, read independently of either decoder (for exclusions and the AWC rules).
_TREND_WORDS = frozenset({"NOSIG", "BECMG", "TEMPO", "INTER"})
_TREND_START = re.compile(r"(?:FM|TL|AT)\d{4}|PROB\d0")
_TIME_GROUP = re.compile(r"\d{6}Z")
_VRB_WIND = re.compile(r"VRB(?:\d\d\d?|//)(?:GP?\d\d\d?)?(?:KTS?|MPS|KMH)?")
# Well-formed wind groups, the known variants included (KTS; no unit; `/////KT`).
_WIND_GROUP = re.compile(r"(?:\d{3}|VRB|///)(?:P?\d{2,3}|//)(?:GP?\d{2,3})?(?:KTS?|MPS|KMH)?")
_VISIBILITY_GROUP = re.compile(
    r"CAVOK|\d{4}(?:[NSEW]{1,2}|NDV|M)?|////(?:SM)?|[MP]?\d+(?:/\d+)?SM|\d+KM"
)
_Q_GROUP = re.compile(r"Q\d{4}")
_A_GROUP = re.compile(r"A\d{4}")
_T_GROUP = re.compile(r"T[01]\d{3}(?:[01]\d{3}|////)?")
_TEMP_GROUP = re.compile(r"(M?\d\d)/(M?\d\d)?")
_CLOUD_TOKEN = re.compile(r"(FEW|SCT|BKN|OVC|VV)(\d{3}|///)(\S*)")
_CLOUD_GROUP = re.compile(r"(?:FEW|SCT|BKN|OVC|VV|///)(?:\d{3}|///)(?:CB|TCU|///)?|CLR|SKC|NSC|NCD")
_CLOUD_SEARCH = re.compile(r"(?P<cover>FEW|SCT|BKN|OVC|VV)(?P<height>\d{3}|///)|CLR|SKC|NSC|NCD")


# --- one report, as each decoder and AWC give it --------------------------------------------


@dataclass(frozen=True)
class Sky:
    """Cloud layers normalised for comparison: kind "layers", "clear", "cavok" or "none"."""

    kind: str
    layers: tuple[tuple[str, int], ...] = ()

    def __str__(self) -> str:
        if self.kind == "layers":
            return " ".join(f"{cover}{base}" for cover, base in self.layers)
        return {"clear": "clear", "cavok": "CAVOK"}.get(self.kind, "no sky group")


@dataclass(frozen=True)
class Values:
    """The compared fields of one decode, in AWC's units (kt, °, m, °C, inHg, ft)."""

    speed_kt: float | None = None
    gust_kt: float | None = None
    dir_deg: float | None = None
    vis_m: float | None = None
    temp_c: float | None = None
    altim_inhg: float | None = None
    sky: Sky = Sky("none")
    failure: str | None = None  # the decoder raised: every field is None


@dataclass(frozen=True)
class Text:
    """The report text cut into body, trend and remark tokens (decoder-independent)."""

    body: tuple[str, ...]
    trend: tuple[str, ...]
    remarks: tuple[str, ...]

    @classmethod
    def of(cls, raw: str) -> Text:
        tokens = raw.split()
        rmk = tokens.index("RMK") if "RMK" in tokens else len(tokens)
        before = tokens[:rmk]
        trend_at = next(
            (
                i
                for i, tok in enumerate(before)
                if i > 1 and (tok in _TREND_WORDS or _TREND_START.fullmatch(tok))
            ),
            len(before),
        )
        return cls(tuple(before[:trend_at]), tuple(before[trend_at:]), tuple(tokens[rmk + 1 :]))


def _sky_from_layers(layers: Iterable[tuple[str, int | None]], clear: bool, cavok: bool) -> Sky:
    known = tuple((c, b) for c, b in layers if c in COVERS and b is not None)[:CLOUD_LAYERS]
    if known:
        return Sky("layers", known)
    if cavok:
        return Sky("cavok")
    return Sky("clear") if clear else Sky("none")


def ours(report: Report) -> Values:
    """wxsky's decode, through `Metar.to_dict()`."""
    d = decode(report.raw, year=report.year, month=report.month).to_dict()
    wind = d["wind"] or {}
    hpa = d["altimeter_hpa"]
    clouds = [(c["cover"], c["base_ft_agl"]) for c in d["clouds"]]
    return Values(
        speed_kt=wind.get("speed_kt"),
        gust_kt=wind.get("gust_kt"),
        dir_deg=wind.get("dir_deg"),
        vis_m=d["visibility_m"],
        temp_c=d["temperature_c"],
        altim_inhg=None if hpa is None else hpa / INHG_TO_HPA,
        sky=_sky_from_layers(clouds, d["sky_clear"] is not None, d["cavok"]),
    )


def python_metar_available() -> bool:
    try:
        import metar.Metar  # noqa: F401
    except ImportError:
        return False
    return True


def python_metar(report: Report) -> Values:
    """python-metar in lenient mode; any exception is a failed decode (all fields None)."""
    from metar.Metar import Metar

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # one RuntimeWarning per unparsed group
            obs = Metar(report.raw, month=report.month, year=report.year, strict=False)
        layers = [
            (cover, None if height is None else round(height.value("FT")))
            for cover, height, _ in obs.sky
        ]
        clear = any(cover in CLEAR_TOKENS for cover, _, _ in obs.sky)
        # python-metar keeps no CAVOK flag (it sets 10 km and no layers): take it from the text.
        cavok = "CAVOK" in Text.of(report.raw).body
        return Values(
            speed_kt=None if obs.wind_speed is None else obs.wind_speed.value("KT"),
            gust_kt=None if obs.wind_gust is None else obs.wind_gust.value("KT"),
            dir_deg=None if obs.wind_dir is None else obs.wind_dir.value(),
            vis_m=None if obs.vis is None else obs.vis.value("M"),
            temp_c=None if obs.temp is None else obs.temp.value("C"),
            altim_inhg=None if obs.press is None else obs.press.value("IN"),
            sky=_sky_from_layers(layers, clear, cavok),
        )
    except Exception as exc:  # the library's crashes are part of the comparison
        return Values(failure=f"{type(exc).__name__}: {exc}")


# --- AWC's columns --------------------------------------------------------------------------


def _number(text: str | None) -> float | None:
    if text is None:
        return None
    try:
        value = float(text.rstrip("+"))
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _whole_kt(value: float) -> int:
    return math.floor(value + 0.5)


def awc_sky(awc: Mapping[str, Any]) -> Sky | None:
    """AWC's sky columns as a Sky, None where they say nothing (empty: see the module doc)."""
    pairs: list[tuple[str | None, str | None]] = list(awc.get("sky") or [])
    covers = [cover for cover, _ in pairs]
    if not pairs:
        return None
    if "CAVOK" in covers:
        return Sky("cavok")
    layers: list[tuple[str, int | None]] = []
    for cover, base_text in pairs:
        base = _number(base_text)
        if cover == "OVX":
            cover = "VV"
            vv = _number(awc.get("vert_vis_ft"))
            # Legacy: `OVX,0` with the height in vert_vis_ft, which is empty for `VV///` (height
            # unknown, left out like every `///` height); 2026: `OVX,200` and vert_vis_ft 2.
            if not base:
                base = vv
        if cover in COVERS:
            layers.append((cover, None if base is None else round(base)))
    if not layers and all(cover in ("CLR", "SKC") for cover in covers):
        return Sky("clear")
    return _sky_from_layers(layers, False, False)


# --- per field: AWC's reference value and the test of a decode against it ------------------


@dataclass(frozen=True)
class Reference:
    """AWC's value for one field of one report, and how a decoded value is judged."""

    awc: str  # AWC's column(s) as given
    agrees: Callable[[Values], bool]
    show: Callable[[Values], str]
    # Compared, but counted apart from the headline rate (an ambiguous reference, §3.3).
    apart: str | None = None


# What a reference function returns: a Reference; a string saying why AWC's value is not
# compared; or None where AWC gives no value.
Outcome = Reference | str | None


def _fmt(value: float | None, digits: int) -> str:
    return "None" if value is None else f"{value:.{digits}f}"


def _ref_speed(report: Report, column: str, name: str) -> Outcome:
    text = (report.awc or {}).get(column)
    value = _number(text)
    if text is None or value is None:
        return None
    expected = _whole_kt(value)

    def agrees(v: Values) -> bool:
        got: float | None = getattr(v, name)
        return got is not None and _whole_kt(got) == expected

    return Reference(text, agrees, lambda v: _fmt(getattr(v, name), 2))


def ref_wind_speed(report: Report, text: Text) -> Outcome:
    return _ref_speed(report, "wind_speed_kt", "speed_kt")


def ref_wind_gust(report: Report, text: Text) -> Outcome:
    return _ref_speed(report, "wind_gust_kt", "gust_kt")


def ref_wind_dir(report: Report, text: Text) -> Outcome:
    awc = report.awc or {}
    column = awc.get("wind_dir_degrees")
    value = _number(column)
    if column is None:
        return None
    if column == "VRB" or any(_VRB_WIND.fullmatch(tok) for tok in text.body):
        return "VRB wind (AWC writes 0 or VRB)"
    if value is None:
        return None
    if _number(awc.get("wind_speed_kt")) == 0:
        return "calm (AWC speed 0: no direction)"

    def agrees(v: Values) -> bool:
        return v.dir_deg is not None and v.dir_deg % 360 == value % 360

    return Reference(column, agrees, lambda v: _fmt(v.dir_deg, 0))


def ref_visibility(report: Report, text: Text) -> Outcome:
    column = (report.awc or {}).get("visibility_statute_mi")
    value = _number(column)
    if column is None or value is None:
        return None
    agrees: Callable[[Values], bool]
    if column.endswith("+"):  # 2025 on: "at least"
        at_least = value * STATUTE_MILE_TO_M - 1.0

        def agrees(v: Values) -> bool:
            return v.vis_m is not None and v.vis_m >= at_least

    elif column == LEGACY_TEN_KM_SM:  # 2014-2022: 9999 or CAVOK

        def agrees(v: Values) -> bool:
            return v.vis_m is not None and v.vis_m >= TEN_KM_M

    else:

        def agrees(v: Values) -> bool:
            if v.vis_m is None:
                return False
            return abs(v.vis_m / STATUTE_MILE_TO_M - value) <= VISIBILITY_TOLERANCE_SM

    def show(v: Values) -> str:
        if v.vis_m is None:
            return "None"
        return f"{v.vis_m:.0f} m = {v.vis_m / STATUTE_MILE_TO_M:.2f} SM"

    return Reference(column, agrees, show)


def ref_temperature(report: Report, text: Text) -> Outcome:
    column = (report.awc or {}).get("temp_c")
    value = _number(column)
    if column is None or value is None:
        return None
    whole = value.is_integer() and any(_T_GROUP.fullmatch(tok) for tok in text.remarks)
    tolerance = (WHOLE_DEGREE_TOLERANCE_C if whole else TEMPERATURE_TOLERANCE_C) + 1e-9

    def agrees(v: Values) -> bool:
        return v.temp_c is not None and abs(v.temp_c - value) <= tolerance

    return Reference(column, agrees, lambda v: _fmt(v.temp_c, 1))


def ref_altimeter(report: Report, text: Text) -> Outcome:
    column = (report.awc or {}).get("altim_in_hg")
    value = _number(column)
    if column is None or value is None:
        return None
    both = any(_Q_GROUP.fullmatch(t) for t in text.body) and any(
        _A_GROUP.fullmatch(t) for t in text.body
    )

    def agrees(v: Values) -> bool:
        if v.altim_inhg is None:
            return False
        return abs(v.altim_inhg - value) <= ALTIMETER_TOLERANCE_INHG + 1e-9

    return Reference(
        column,
        agrees,
        lambda v: _fmt(v.altim_inhg, 3),
        apart="both Q and A groups" if both else None,
    )


def ref_clouds(report: Report, text: Text) -> Outcome:
    awc = report.awc or {}
    expected = awc_sky(awc)
    if expected is None:
        layers = _cloud_layers(text.body)
        if any(suffix not in PLAIN_SUFFIXES for _, _, suffix in layers):
            return "AWC sky empty, the report has layers with a type suffix (2014 drops them)"
        return None
    if expected.kind == "none":
        return "AWC's only layers have an unknown height (VV/// is OVX,0 in 2014-2022)"
    pairs = awc.get("sky") or []
    shown = " ".join(c if b is None else f"{c},{b}" for c, b in pairs)
    if any(c == "OVX" for c, _ in pairs) and awc.get("vert_vis_ft") is not None:
        shown += f" vert_vis_ft {awc.get('vert_vis_ft')}"

    def agrees(v: Values) -> bool:
        return v.sky == expected

    return Reference(f"{shown} -> {expected}", agrees, lambda v: str(v.sky))


REFERENCES: dict[str, Callable[[Report, Text], Outcome]] = {
    "wind_speed": ref_wind_speed,
    "wind_gust": ref_wind_gust,
    "wind_dir": ref_wind_dir,
    "visibility": ref_visibility,
    "temperature": ref_temperature,
    "altimeter": ref_altimeter,
    "clouds": ref_clouds,
}


# --- disagreements that are AWC's, not the decoders' ------------------------------------------

AWC_ERROR = "AWC error"  # AWC's value contradicts the report
AWC_GUESS = "AWC guess"  # AWC decodes text that is no valid group (or no report) at all


@dataclass(frozen=True)
class Rule:
    """A known way AWC's column goes wrong, recognised from the report text alone."""

    name: str
    verdict: str  # AWC_ERROR or AWC_GUESS
    fields: frozenset[str]
    test: Callable[[Report, Text], bool]


def _cloud_layers(tokens: Iterable[str]) -> list[tuple[str, int, str]]:
    """(cover, base ft, suffix) of the cloud groups among tokens; `///` heights left out."""
    found = []
    for tok in tokens:
        m = _CLOUD_TOKEN.fullmatch(tok)
        if m and m[2] != "///":
            found.append((m[1], int(m[2]) * 100, m[3]))
    return found


def _awc_layers(report: Report) -> tuple[tuple[str, int], ...]:
    sky = awc_sky(report.awc or {})
    return () if sky is None else sky.layers


def _no_time_group(report: Report, text: Text) -> bool:
    return not any(_TIME_GROUP.fullmatch(tok) for tok in report.raw.split()[:4])


def _malformed_wind_as_calm(report: Report, text: Text) -> bool:
    awc = report.awc or {}
    return _number(awc.get("wind_speed_kt")) == 0 and not any(
        _WIND_GROUP.fullmatch(tok) for tok in text.body
    )


def _malformed_visibility(report: Report, text: Text) -> bool:
    return not any(_VISIBILITY_GROUP.fullmatch(tok) for tok in text.body)


def _garbled_cloud_group(report: Report, text: Text) -> bool:
    garbled = [
        tok for tok in text.body if _CLOUD_SEARCH.search(tok) and not _CLOUD_GROUP.fullmatch(tok)
    ]
    if not garbled:
        return False
    # AWC's sky is what a search inside the garbled tokens finds.
    layers: list[tuple[str, int | None]] = []
    clear = False
    for tok in text.body:
        for m in _CLOUD_SEARCH.finditer(tok):
            if m["height"]:
                layers.append(
                    (m["cover"], None if m["height"] == "///" else int(m["height"]) * 100)
                )
            else:
                clear = True
    return awc_sky(report.awc or {}) == _sky_from_layers(layers, clear, False)


def _implausible_altimeter(report: Report, text: Text) -> bool:
    inhg = _number((report.awc or {}).get("altim_in_hg"))
    if inhg is None:
        return False
    lo, hi = PLAUSIBLE_ALTIMETER_HPA
    return not lo <= inhg * INHG_TO_HPA <= hi


def _zero_temperature(report: Report, text: Text) -> bool:
    if _number((report.awc or {}).get("temp_c")) != 0:
        return False
    groups = [m for tok in text.body if (m := _TEMP_GROUP.fullmatch(tok))]
    return bool(groups) and groups[0][1] not in ("00", "M00")


def _trend_layers_folded(report: Report, text: Text) -> bool:
    body = [(c, b) for c, b, _ in _cloud_layers(text.body)]
    trend = [(c, b) for c, b, _ in _cloud_layers(text.trend)]
    folded = tuple((body + trend)[:CLOUD_LAYERS])
    return bool(trend) and folded != tuple(body[:CLOUD_LAYERS]) and _awc_layers(report) == folded


def _suffixed_layer_dropped(report: Report, text: Text) -> bool:
    layers = _cloud_layers(text.body)
    if all(suffix in PLAIN_SUFFIXES for _, _, suffix in layers):
        return False
    kept = tuple((c, b) for c, b, s in layers if s in PLAIN_SUFFIXES)[:CLOUD_LAYERS]
    return _awc_layers(report) == kept


_WIND_FIELDS = frozenset({"wind_speed", "wind_gust", "wind_dir"})
AWC_RULES = (
    Rule(
        "temperature decoded as 0 °C although the body group says otherwise",
        AWC_ERROR,
        frozenset({"temperature"}),
        _zero_temperature,
    ),
    Rule(
        "altimeter outside 850-1100 hPa taken as given",
        AWC_ERROR,
        frozenset({"altimeter"}),
        _implausible_altimeter,
    ),
    Rule(
        "trend (TEMPO/BECMG/FM) layers folded into the observed layers",
        AWC_ERROR,
        frozenset({"clouds"}),
        _trend_layers_folded,
    ),
    Rule(
        "layer with a type suffix other than CB/TCU (FEW030SC, BKN040///) dropped",
        AWC_ERROR,
        frozenset({"clouds"}),
        _suffixed_layer_dropped,
    ),
    Rule(
        "row with no ddhhmmZ time group decoded (junk, or a report cut short)",
        AWC_GUESS,
        frozenset(FIELDS),
        _no_time_group,
    ),
    Rule(
        "malformed wind group (E00000KT, 4.62500005KT) decoded as calm",
        AWC_GUESS,
        _WIND_FIELDS,
        _malformed_wind_as_calm,
    ),
    Rule(
        "no valid visibility group (99999) but a visibility given",
        AWC_GUESS,
        frozenset({"visibility"}),
        _malformed_visibility,
    ),
    Rule(
        "garbled cloud group (/OVC014, /CLR) read as if it were valid",
        AWC_GUESS,
        frozenset({"clouds"}),
        _garbled_cloud_group,
    ),
)


def awc_rule(report: Report, text: Text, name: str) -> Rule | None:
    """The first rule that explains AWC's value of field `name` as AWC's own doing, or None."""
    for rule in AWC_RULES:
        if name in rule.fields and rule.test(report, text):
            return rule
    return None


# --- the comparison ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """One field of one report where ours or python-metar disagrees with AWC."""

    field: str
    raw: str
    source: str
    awc: str
    ours: str
    python_metar: str | None
    ours_agrees: bool
    python_metar_agrees: bool | None
    rule: str | None  # the AWC rule that explains AWC's value, if any
    verdict: str | None  # that rule's verdict (AWC_ERROR, AWC_GUESS)
    apart: str | None  # compared apart from the headline (an ambiguous reference)

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class Tally:
    compared: int = 0
    ours: int = 0  # reports where ours agrees
    python_metar: int = 0
    # Where ours disagrees, by the verdict of the AWC rule that explains it ("" for none).
    ours_differs: dict[str, int] = field(default_factory=dict)

    def rate(self, agreed: int) -> float:
        return agreed / self.compared if self.compared else 1.0

    def as_dict(self, with_python_metar: bool) -> dict[str, Any]:
        return {
            "compared": self.compared,
            "ours_agree": self.ours,
            "ours_agree_rate": self.rate(self.ours),
            "python_metar_agree": self.python_metar if with_python_metar else None,
            "python_metar_agree_rate": self.rate(self.python_metar) if with_python_metar else None,
            "ours_differs_awc_error": self.ours_differs.get(AWC_ERROR, 0),
            "ours_differs_awc_guess": self.ours_differs.get(AWC_GUESS, 0),
            "ours_differs_unexplained": self.ours_differs.get("", 0),
        }


@dataclass
class FieldResult:
    headline: Tally = field(default_factory=Tally)
    apart: dict[str, Tally] = field(default_factory=dict)  # compared apart, by reason
    not_compared: dict[str, int] = field(default_factory=dict)  # AWC value left out, by reason


@dataclass
class Result:
    reports: int
    sources: dict[str, int]
    with_python_metar: bool
    fields: dict[str, FieldResult]
    cases: list[Case]

    def meets_bar(self) -> dict[str, bool]:
        """Per field: does our decoder meet the issue's bar (on the headline comparison)?"""
        out = {}
        for name, f in self.fields.items():
            t = f.headline
            if name == "clouds":
                out[name] = not self.with_python_metar or t.ours >= t.python_metar
            else:
                out[name] = t.rate(t.ours) >= BAR
        return out

    def as_dict(self) -> dict[str, Any]:
        return {
            "reports": self.reports,
            "sources": self.sources,
            "python_metar": self.with_python_metar,
            "bar": {"fields_except_clouds": BAR, "clouds": "ours >= python-metar"},
            "meets_bar": self.meets_bar(),
            "fields": {
                name: {
                    **f.headline.as_dict(self.with_python_metar),
                    "apart": {why: t.as_dict(self.with_python_metar) for why, t in f.apart.items()},
                    "not_compared": f.not_compared,
                }
                for name, f in self.fields.items()
            },
            "rules": [{"name": r.name, "verdict": r.verdict} for r in AWC_RULES],
            "disagreements": [c.as_dict() for c in self.cases],
        }


def distinct_reports(paths: Iterable[Path]) -> list[tuple[str, Report]]:
    """(file name, report) for each distinct report text with AWC columns, first copy kept."""
    seen: dict[str, tuple[str, Report]] = {}
    for path in paths:
        for report in read_reports(path):
            if report.awc is not None:
                seen.setdefault(report.raw, (Path(path).name, report))
    return list(seen.values())


def compare(
    reports: Iterable[tuple[str, Report]], *, with_python_metar: bool | None = None
) -> Result:
    """Compare every (source, report) with AWC's columns, field by field (module doc)."""
    if with_python_metar is None:
        with_python_metar = python_metar_available()
    fields = {name: FieldResult() for name in FIELDS}
    cases: list[Case] = []
    sources: dict[str, int] = {}
    for source, report in reports:
        sources[source] = sources.get(source, 0) + 1
        text = Text.of(report.raw)
        mine = ours(report)
        theirs = python_metar(report) if with_python_metar else None
        for name in FIELDS:
            ref = REFERENCES[name](report, text)
            f = fields[name]
            if ref is None:
                continue
            if isinstance(ref, str):
                f.not_compared[ref] = f.not_compared.get(ref, 0) + 1
                continue
            tally = f.headline if ref.apart is None else f.apart.setdefault(ref.apart, Tally())
            tally.compared += 1
            ours_ok = ref.agrees(mine)
            theirs_ok = None if theirs is None else ref.agrees(theirs)
            tally.ours += ours_ok
            tally.python_metar += bool(theirs_ok)
            if ours_ok and theirs_ok is not False:
                continue
            rule = awc_rule(report, text, name)
            if not ours_ok:
                verdict = "" if rule is None else rule.verdict
                tally.ours_differs[verdict] = tally.ours_differs.get(verdict, 0) + 1
            cases.append(
                Case(
                    field=name,
                    raw=report.raw,
                    source=source,
                    awc=ref.awc,
                    ours=ref.show(mine),
                    python_metar=None if theirs is None else theirs.failure or ref.show(theirs),
                    ours_agrees=ours_ok,
                    python_metar_agrees=theirs_ok,
                    rule=None if rule is None else rule.name,
                    verdict=None if rule is None else rule.verdict,
                    apart=ref.apart,
                )
            )
    return Result(sum(sources.values()), sources, with_python_metar, fields, cases)


# --- output -----------------------------------------------------------------------------------


def _pct(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.2f} %"


def _row(label: str, t: Tally, with_python_metar: bool, bar: str) -> str:
    theirs = _pct(t.rate(t.python_metar)) if with_python_metar else "n/a"
    differs = (
        f"{t.ours_differs.get(AWC_ERROR, 0)}/{t.ours_differs.get(AWC_GUESS, 0)}"
        f"/{t.ours_differs.get('', 0)}"
    )
    return (
        f"{label:34s} {t.compared:8d} {_pct(t.rate(t.ours)):>10s} {theirs:>13s}"
        f" {differs:>14s}  {bar}"
    )


def table(result: Result) -> list[str]:
    header = (
        f"{'field':34s} {'compared':>8s} {'ours':>10s} {'python-metar':>13s}"
        f" {'ours differs':>14s}  bar"
    )
    lines = [header, "-" * len(header)]
    bar = result.meets_bar()
    for name, f in result.fields.items():
        lines.append(
            _row(
                LABELS[name], f.headline, result.with_python_metar, "ok" if bar[name] else "MISSED"
            )
        )
    for name, f in result.fields.items():
        for why, t in f.apart.items():
            lines.append(_row(f"  {LABELS[name]}: {why}", t, result.with_python_metar, "apart"))
    lines.append(
        "ours, python-metar: share of compared reports agreeing with AWC. ours differs: "
        "AWC error / AWC guess / unexplained."
    )
    return lines


def _case_lines(case: Case) -> list[str]:
    theirs = "" if case.python_metar is None else f" | python-metar {case.python_metar}"
    return [
        f"  [{case.source[:25]}] {case.raw}",
        f"      AWC {case.awc} | ours {case.ours}{theirs}",
    ]


def report_lines(result: Result, disagreements: int) -> list[str]:
    lines = [
        f"{result.reports} distinct reports with AWC columns: "
        + ", ".join(f"{name} {n}" for name, n in result.sources.items()),
        "",
        *table(result),
        "",
        "AWC values not compared:",
    ]
    for name, f in result.fields.items():
        for why, n in f.not_compared.items():
            lines.append(f"  {LABELS[name]}: {why}: {n}")
    for verdict, heading in (
        (AWC_ERROR, "Disagreements judged to be AWC's own errors"),
        (AWC_GUESS, "Disagreements where AWC decodes text that is no valid group or report"),
    ):
        lines += ["", f"{heading} (rule: reports where ours / python-metar differ):"]
        for rule in (r for r in AWC_RULES if r.verdict == verdict):
            mine = [c for c in result.cases if c.rule == rule.name and not c.ours_agrees]
            theirs = [
                c for c in result.cases if c.rule == rule.name and c.python_metar_agrees is False
            ]
            lines.append(f"  {rule.name}: {len(mine)} / {len(theirs)}")
            for case in (mine or theirs)[: max(0, disagreements)]:
                lines += ["  " + line for line in _case_lines(case)]
    lines += ["", "Disagreements of ours that no AWC rule explains:"]
    unexplained = [
        c for c in result.cases if c.rule is None and c.apart is None and not c.ours_agrees
    ]
    for name in FIELDS:
        mine = [c for c in unexplained if c.field == name]
        if mine:
            lines.append(f"  {LABELS[name]}: {len(mine)}")
            for case in mine[: max(0, disagreements)]:
                lines += ["  " + line for line in _case_lines(case)]
    if not unexplained:
        lines.append("  none")
    apart = [c for c in result.cases if c.apart is not None]
    if apart and disagreements > 0:
        lines += ["", "Compared apart (an ambiguous reference), disagreements:"]
        for name in FIELDS:
            for why in result.fields[name].apart:
                some = [c for c in apart if c.field == name and c.apart == why]
                lines.append(f"  {LABELS[name]}, {why}: {len(some)}")
                for case in some[:disagreements]:
                    lines += ["  " + line for line in _case_lines(case)]
    if disagreements > 0 and result.with_python_metar:
        lines += ["", "Where only python-metar disagrees:"]
        for name in FIELDS:
            theirs = [
                c
                for c in result.cases
                if c.field == name
                and c.apart is None
                and c.ours_agrees
                and c.python_metar_agrees is False
            ]
            if theirs:
                lines.append(f"  {LABELS[name]}: {len(theirs)}")
                for case in theirs[:disagreements]:
                    lines += ["  " + line for line in _case_lines(case)]
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("files", nargs="*", type=Path, help=f"AWC caches (default {CORPUS_GLOB})")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument(
        "--disagreements",
        type=int,
        default=0,
        metavar="N",
        help="print up to N disagreeing reports per field and per rule, with both values",
    )
    args = p.parse_args(argv)
    paths = list(args.files) or sorted(DATA_DIR.glob(CORPUS_GLOB))
    if not paths:
        print(f"metar_agreement: no {CORPUS_GLOB} under {DATA_DIR}", file=sys.stderr)
        return 2
    if not python_metar_available():
        print(
            "metar_agreement: python-metar is missing (pip install metar==2.0.2); "
            "its column is n/a",
            file=sys.stderr,
        )
    result = compare(distinct_reports(paths))
    if args.json:
        print(json.dumps(result.as_dict(), indent=2, ensure_ascii=False))
    else:
        print("\n".join(report_lines(result, args.disagreements)))
    return 0 if all(result.meets_bar().values()) else 1


if __name__ == "__main__":
    sys.exit(main())
