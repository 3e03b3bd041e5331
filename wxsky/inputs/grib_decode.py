"""GRIB2 messages into model fields: the **only** eccodes user (issue 45, docs/weather-aloft.md).

ECMWF's eccodes decodes; its wheels carry the C library, so no system package is needed.
Two things it must be told:

* NCEP packs each u/v pair in ONE message (two fields sharing the grid): multi-field support
  must be on, or every `v` is silently missing;
* the messages are read from a file descriptor (an anonymous memory file here), since only
  its file reader walks the fields inside a message.

Only the fields wxsky uses are decoded (`wanted`); each is cut to a window around a point,
so a 0.25 degree global file costs kilobytes, not gigabytes, once decoded. Regular
latitude/longitude grids (template 0: GFS 0.25/0.5/1/2.5 degree, ECMWF open data, ICON's
regular-grid products) are read; a wanted field on any other grid is refused with a one-line
error naming the template. The C decoder runs wherever the caller puts it: the daemon runs it
in a child process (`wxsky.app.grib_part`), so a corrupt file that trips it costs that file,
not the daemon.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import numpy as np

from wxsky.errors import GribError
from wxsky.weather.model_fields import Grid, ModelField

G0_MPS2 = 9.80665  # standard gravity: geopotential (m2/s2) over this is geopotential metres
# Pressure levels above this (lower pressure) are left out: 100 hPa is about 16 km (FL530),
# above every cloud and every civil aircraft's ceiling, and a fifth of a model's levels.
MIN_LEVEL_HPA = 100.0

# (eccodes shortName, typeOfLevel) -> (wxsky name, level type, scale). The level number is
# kept only for isobaric levels (in hPa); `scale` turns the centre's unit into wxsky's.
_ISOBARIC = {"u": "u", "v": "v", "t": "t", "gh": "gh", "r": "r", "clwmr": "clwmr", "clwc": "clwmr"}
_TABLE: dict[tuple[str, str], tuple[str, str, float]] = {
    ("orog", "surface"): ("orog", "surface", 1.0),
    ("h", "surface"): ("orog", "surface", 1.0),
    ("z", "surface"): ("orog", "surface", 1.0 / G0_MPS2),
    ("sp", "surface"): ("sp", "surface", 1.0),
    ("cape", "surface"): ("cape", "surface", 1.0),
    ("prate", "surface"): ("prate", "surface", 1.0),
    ("avg_prate", "surface"): ("prate", "surface", 1.0),
    ("2t", "heightAboveGround"): ("t2m", "surface", 1.0),
    ("10u", "heightAboveGround"): ("u10", "surface", 1.0),
    ("10v", "heightAboveGround"): ("v10", "surface", 1.0),
    ("gh", "isothermZero"): ("gh", "freezing", 1.0),
    ("deg0l", "surface"): ("gh", "freezing", 1.0),
    ("gh", "tropopause"): ("gh", "tropopause", 1.0),
    ("trpp", "tropopause"): ("pres", "tropopause", 1.0),
    ("pres", "tropopause"): ("pres", "tropopause", 1.0),
    # ECMWF and ICON give the decks' cover as a fraction, NCEP in per cent
    ("lcc", "surface"): ("tcc", "low_cloud", 100.0),
    ("mcc", "surface"): ("tcc", "middle_cloud", 100.0),
    ("hcc", "surface"): ("tcc", "high_cloud", 100.0),
}
for _deck in ("low", "middle", "high", "convective"):
    for _cover in ("tcc", "avg_tcc"):
        _TABLE[(_cover, f"{_deck}CloudLayer")] = ("tcc", f"{_deck}_cloud", 1.0)
    for _end in ("Top", "Bottom"):
        for _pres in ("pres", "avg_pres"):
            _TABLE[(_pres, f"{_deck}Cloud{_end}")] = ("pres", f"{_deck}_cloud_{_end.lower()}", 1.0)


_ECCODES: Any = None


def _eccodes() -> Any:
    """eccodes, imported on first use: its bindings take a few tenths of a second to load
    (cffi parses the library's declarations), and every daemon imports this module while
    most never decode a GRIB message."""
    global _ECCODES
    if _ECCODES is None:
        import eccodes

        _ECCODES = eccodes
    return _ECCODES


def wanted(short_name: str, type_of_level: str) -> tuple[str, str, float] | None:
    """What wxsky makes of a field, or None when it does not use it."""
    if type_of_level in ("isobaricInhPa", "isobaricInPa"):
        if short_name == "z":
            return ("gh", "isobaric", 1.0 / G0_MPS2)
        name = _ISOBARIC.get(short_name)
        return (name, "isobaric", 1.0) if name else None
    return _TABLE.get((short_name, type_of_level))


@dataclass(frozen=True)
class Window:
    """Cut each field to this many degrees either side of a point (None: the whole grid)."""

    lat_deg: float
    lon_deg: float
    half_deg: float = 6.0


_LOG: Any = None


def _quiet() -> None:
    """The C library writes its complaints to stderr, several lines for one bad message: they
    go to a memory file instead, and the last is added to the one-line error."""
    global _LOG
    if _LOG is None:
        _LOG = os.fdopen(os.memfd_create("wxsky-eccodes-log", os.MFD_CLOEXEC), "w+b")
        _eccodes().codes_context_set_logging(_LOG)
    _LOG.seek(0)
    _LOG.truncate()


def _last_complaint() -> str:
    if _LOG is None:
        return ""
    _LOG.flush()
    _LOG.seek(0)
    lines = [ln.strip() for ln in _LOG.read().decode("utf-8", "replace").splitlines() if ln.strip()]
    return f" (eccodes: {lines[-1][:160]})" if lines else ""


def decode(
    data: bytes, name: str, window: Window | None = None, problems: list[str] | None = None
) -> list[ModelField]:
    """The wanted fields of every message in `data` (GRIB edition 2; edition 1 is refused).
    Each problem is one line naming `name`, the message and the field: without `problems`,
    the first raises GribError; with it, each is added there and what can be used is used (a
    field out of its range is left out, a truncated file gives the messages before the cut).
    Data with no GRIB message at all raises either way."""
    if not data:
        raise GribError(f"{name}: empty, no GRIB messages")
    _quiet()
    try:
        return _decode(data, name, window, problems)
    except GribError as e:
        raise GribError(f"{e}{_last_complaint()}") from None


def _decode(
    data: bytes, name: str, window: Window | None, problems: list[str] | None
) -> list[ModelField]:
    out: list[ModelField] = []
    _eccodes().codes_grib_multi_support_on()
    with _memory_file(data) as f:
        n = 0
        while True:
            where = f"{name}: message {n + 1}"
            try:
                h = _eccodes().codes_grib_new_from_file(f)
            except Exception as e:  # eccodes raises its own errors for a truncated message
                if problems is None or n == 0:
                    raise GribError(f"{where}: {_said(e)}") from None
                # nothing after a broken message can be found again
                problems.append(f"{where}: {_said(e)}; the file's rest left out")
                break
            if h is None:
                break
            n += 1
            try:
                field = _field(h, f"{where} at byte {_get(h, 'offset', -1):.0f}", window)
            except GribError as e:
                if problems is None:
                    raise
                problems.append(f"{e}{_last_complaint()}")
                continue
            finally:
                _eccodes().codes_release(h)
            if field is not None:
                out.append(field)
    if n == 0:
        raise GribError(f"{name}: no GRIB messages found ({len(data)} bytes)")
    return out


# What each field may hold, in wxsky's units (NaN, where the model has no value, is allowed):
# beyond it a field is refused, not clipped (a file that says 400 m/s says nothing).
_LIMITS: dict[tuple[str, str], tuple[float, float, str]] = {
    ("u", "isobaric"): (-150.0, 150.0, "m/s"),
    ("v", "isobaric"): (-150.0, 150.0, "m/s"),
    ("t", "isobaric"): (150.0, 350.0, "K"),
    ("gh", "isobaric"): (-1000.0, 60_000.0, "m"),
    ("r", "isobaric"): (-1.0, 110.0, "%"),
    ("clwmr", "isobaric"): (0.0, 0.1, "kg/kg"),
    ("u10", "surface"): (-150.0, 150.0, "m/s"),
    ("v10", "surface"): (-150.0, 150.0, "m/s"),
    ("t2m", "surface"): (150.0, 350.0, "K"),
    ("sp", "surface"): (20_000.0, 115_000.0, "Pa"),
    ("orog", "surface"): (-1000.0, 9000.0, "m"),
    ("cape", "surface"): (0.0, 20_000.0, "J/kg"),
    ("prate", "surface"): (0.0, 0.2, "kg m-2 s-1"),
    ("gh", "freezing"): (-1000.0, 10_000.0, "m"),
    ("gh", "tropopause"): (2000.0, 30_000.0, "m"),
}


def _check_range(where: str, name: str, level_type: str, level: float, values: np.ndarray) -> None:
    limits = _LIMITS.get((name, level_type))
    if limits is None and level_type.endswith("_cloud"):
        limits = (0.0, 100.5, "%")  # a deck's cover
    if limits is None:
        return
    lo, hi, unit = limits
    finite = values[np.isfinite(values)]
    bad = finite[(finite < lo) | (finite > hi)]
    if bad.size:
        at = f" at {level:g} hPa" if level_type == "isobaric" else f" ({level_type})"
        worst = float(bad[np.argmax(np.abs(bad))])
        raise GribError(
            f"{where}: {name}{at}: {bad.size} values outside {lo:g}..{hi:g} {unit} "
            f"(e.g. {worst:.6g}); the field left out"
        )


@contextlib.contextmanager
def _memory_file(data: bytes) -> Iterator[Any]:
    fd = os.memfd_create("wxsky-grib", os.MFD_CLOEXEC)
    with os.fdopen(fd, "w+b") as f:
        f.write(data)
        f.seek(0)
        try:
            yield f
        finally:
            # With multi-field support on, eccodes keeps the rest of a message whose first
            # field was read (NCEP's v after its u) for the next read of *any* file: left
            # there by a file given up half-way, it came out of the next file's first read.
            _eccodes().codes_grib_multi_support_reset_file(f)


def _said(e: BaseException) -> str:
    text = " ".join(str(e).split()) or type(e).__name__
    return text[:200]


def _get(h: Any, key: str, default: Any = None) -> Any:
    try:
        return _eccodes().codes_get(h, key)
    except Exception:  # a key a message does not have
        return default


def _field(h: Any, where: str, window: Window | None) -> ModelField | None:
    edition = _get(h, "edition", 0)
    if edition != 2:
        raise GribError(f"{where}: GRIB edition {edition}; wxsky reads GRIB2")
    # Any message on another grid refuses the file: a model's files put every field on one.
    template = _get(h, "gridDefinitionTemplateNumber", -1)
    grid_type = _get(h, "gridType", "?")
    if template != 0 or grid_type != "regular_ll":
        raise GribError(
            f"{where}: grid template {template} ({grid_type}) is not supported; wxsky reads "
            "regular latitude/longitude grids (template 0)"
        )
    short, level_kind = str(_get(h, "shortName", "")), str(_get(h, "typeOfLevel", ""))
    if level_kind == "hybrid" and short in _ISOBARIC:
        raise GribError(
            f"{where}: {short} on native model levels (hybrid) is not supported; wxsky reads "
            "pressure levels"
        )
    what = wanted(short, level_kind)
    if what is None:
        return None
    name, level_type, scale = what
    level = 0.0
    if level_type == "isobaric":
        level = float(_get(h, "level", 0))
        if _get(h, "typeOfLevel") == "isobaricInPa":
            level /= 100.0
        if level < MIN_LEVEL_HPA:
            return None
    try:
        grid, values = _grid_values(h, window)
    except GribError as e:
        raise GribError(f"{where}: {e}") from None
    except Exception as e:
        raise GribError(f"{where}: {_said(e)}") from None
    valid = _valid_utc(h, where)
    scaled = (values * scale).astype(np.float32)
    _check_range(where, name, level_type, level, scaled)
    return ModelField(name, level_type, level, valid, grid, scaled)


def _valid_utc(h: Any, where: str) -> datetime:
    date = int(_get(h, "validityDate", 0))
    hhmm = int(_get(h, "validityTime", 0))
    try:
        return datetime(
            date // 10000, date // 100 % 100, date % 100, hhmm // 100, hhmm % 100, tzinfo=UTC
        )
    except ValueError:
        raise GribError(f"{where}: impossible valid time {date} {hhmm:04d}") from None


def _grid_values(h: Any, window: Window | None) -> tuple[Grid, np.ndarray]:
    ec = _eccodes()
    ni = int(ec.codes_get(h, "Ni"))
    nj = int(ec.codes_get(h, "Nj"))
    if ni < 1 or nj < 1 or ni * nj > 50_000_000:
        raise GribError(f"grid of {ni} x {nj} points")
    lat0 = float(ec.codes_get(h, "latitudeOfFirstGridPointInDegrees"))
    lon0 = float(ec.codes_get(h, "longitudeOfFirstGridPointInDegrees"))
    di = float(ec.codes_get(h, "iDirectionIncrementInDegrees"))
    dj = float(ec.codes_get(h, "jDirectionIncrementInDegrees"))
    if not (0.0 < di <= 90.0 and 0.0 < dj <= 90.0):
        raise GribError(f"grid increments {di} x {dj} degrees")
    if int(_get(h, "jPointsAreConsecutive", 0)):
        raise GribError("columns stored first (jPointsAreConsecutive) is not supported")
    values = np.asarray(ec.codes_get_values(h), dtype=np.float64)
    if values.size != ni * nj:
        raise GribError(f"{values.size} values for a grid of {ni} x {nj}")
    if int(_get(h, "bitmapPresent", 0)):
        missing = float(_get(h, "missingValue", 9999.0))
        values = np.where(values == missing, np.nan, values)
    grid = values.reshape(nj, ni)
    j_step = dj if int(_get(h, "jScansPositively", 0)) else -dj
    i_step = -di if int(_get(h, "iScansNegatively", 0)) else di
    lats = lat0 + j_step * np.arange(nj)
    lons = lon0 + i_step * np.arange(ni)
    if j_step < 0:
        lats, grid = lats[::-1], grid[::-1]
    if i_step < 0:
        lons, grid = lons[::-1], grid[:, ::-1]
    wraps = abs(ni * di - 360.0) < 0.5 * di
    return _cut(Grid(lats, lons, wraps), grid, window)


def _cut(grid: Grid, values: np.ndarray, window: Window | None) -> tuple[Grid, np.ndarray]:
    if window is None:
        return grid, values
    lats, lons = grid.lats_deg, grid.lons_deg
    rows = np.nonzero(np.abs(lats - window.lat_deg) <= window.half_deg + 1e-9)[0]
    if rows.size == 0:
        raise GribError(f"the grid has no rows near latitude {window.lat_deg:.2f}")
    r0, r1 = max(int(rows[0]) - 1, 0), min(int(rows[-1]) + 2, len(lats))
    if grid.wraps:
        step = float(lons[1] - lons[0]) if len(lons) > 1 else 360.0
        centre = grid.local_lon(window.lon_deg)
        k0 = int(np.floor((centre - window.half_deg - lons[0]) / step)) - 1
        k1 = int(np.ceil((centre + window.half_deg - lons[0]) / step)) + 2
        if k1 - k0 >= len(lons):  # the window goes round the earth: the whole row
            cols = np.arange(len(lons))
            cut_lons = lons.copy()
        else:
            cols = np.arange(k0, k1)
            cut_lons = lons[0] + step * cols
            cols = cols % len(lons)
        cut = values[r0:r1][:, cols]
        return Grid(lats[r0:r1].copy(), cut_lons, grid.wraps), np.ascontiguousarray(cut)
    near = np.nonzero(np.abs(lons - window.lon_deg) <= window.half_deg + 1e-9)[0]
    if near.size == 0:
        raise GribError(f"the grid has no columns near longitude {window.lon_deg:.2f}")
    c0, c1 = max(int(near[0]) - 1, 0), min(int(near[-1]) + 2, len(lons))
    cut = np.ascontiguousarray(values[r0:r1, c0:c1])
    return Grid(lats[r0:r1].copy(), lons[c0:c1].copy(), False), cut


# --- inventories (.idx), as NOAA's servers publish beside each file --------------------------

# (eccodes shortName, typeOfLevel) -> wgrib2's variable name, for the inventories wxsky writes
# and the byte ranges it asks for.
_WGRIB2_VAR = {
    "u": "UGRD", "v": "VGRD", "t": "TMP", "gh": "HGT", "r": "RH", "clwmr": "CLWMR",
    "tcc": "TCDC", "avg_tcc": "TCDC", "pres": "PRES", "avg_pres": "PRES", "orog": "HGT",
    "sp": "PRES", "cape": "CAPE", "prate": "PRATE", "avg_prate": "PRATE", "2t": "TMP",
    "10u": "UGRD", "10v": "VGRD", "trpp": "PRES", "z": "HGT",
}  # fmt: skip
_WGRIB2_LEVEL = {
    "surface": "surface", "tropopause": "tropopause", "isothermZero": "0C isotherm",
    "lowCloudLayer": "low cloud layer", "middleCloudLayer": "middle cloud layer",
    "highCloudLayer": "high cloud layer", "convectiveCloudLayer": "convective cloud layer",
    "lowCloudTop": "low cloud top level", "lowCloudBottom": "low cloud bottom level",
    "middleCloudTop": "middle cloud top level", "middleCloudBottom": "middle cloud bottom level",
    "highCloudTop": "high cloud top level", "highCloudBottom": "high cloud bottom level",
    "convectiveCloudTop": "convective cloud top level",
    "convectiveCloudBottom": "convective cloud bottom level",
}  # fmt: skip


def inventory(data: bytes) -> str:
    """A wgrib2-style `.idx` inventory of `data` (one line per field: `N:OFFSET:d=YYYYMMDDHH:
    VAR:LEVEL:FORECAST:`, fields sharing a message numbered N.1, N.2 as wgrib2 does): what a
    test's HTTP server publishes beside the real file, and what `wxsky grib idx` prints.
    Fields wxsky does not read are listed with eccodes' names."""
    lines: list[str] = []
    _quiet()
    _eccodes().codes_grib_multi_support_on()
    with _memory_file(data) as f:
        n = 0
        last_offset = -1
        parts: list[tuple[int, str]] = []
        while True:
            try:
                h = _eccodes().codes_grib_new_from_file(f)
            except Exception as e:  # a truncated or corrupt message
                raise GribError(f"message {n + 1}: {_said(e)}") from None
            if h is None:
                break
            try:
                offset = int(_get(h, "offset", 0))
                if offset != last_offset:
                    n += 1
                    last_offset = offset
                parts.append((n, _idx_text(h, offset)))
            finally:
                _eccodes().codes_release(h)
    if n == 0:
        raise GribError(f"no GRIB messages found ({len(data)} bytes)")
    counts: dict[int, int] = {}
    for k, _ in parts:
        counts[k] = counts.get(k, 0) + 1
    seen: dict[int, int] = {}
    for k, text in parts:
        seen[k] = seen.get(k, 0) + 1
        number = f"{k}.{seen[k]}" if counts[k] > 1 else str(k)
        lines.append(f"{number}:{text}")
    return "".join(line + "\n" for line in lines)


def _idx_text(h: Any, offset: int) -> str:
    short = str(_get(h, "shortName", "unknown"))
    tol = str(_get(h, "typeOfLevel", "unknown"))
    level = _get(h, "level", 0)
    if tol == "isobaricInhPa":
        level_text = f"{level} mb"
    elif tol == "isobaricInPa":
        level_text = f"{level / 100:g} mb"
    elif tol == "heightAboveGround":
        level_text = f"{level} m above ground"
    elif tol == "heightAboveSea":
        level_text = f"{level} m above mean sea level"
    else:
        level_text = _WGRIB2_LEVEL.get(tol, tol)
    var = _WGRIB2_VAR.get(short, short.upper())
    date = int(_get(h, "dataDate", 0))
    time_ = int(_get(h, "dataTime", 0))
    step = str(_get(h, "stepRange", "0"))
    forecast = "anl" if step == "0" else f"{step} hour fcst"
    if _get(h, "stepType", "instant") == "avg" and "-" in step:
        forecast = f"{step} hour ave fcst"
    return f"{offset}:d={date:08d}{time_ // 100:02d}:{var}:{level_text}:{forecast}:"


# The inventory lines whose messages the daemon fetches by byte range (`[grib] fields`): wgrib2's
# names for `wanted`'s fields, "mb" standing for every pressure level down to MIN_LEVEL_HPA.
# "wind": the wind and temperature profile alone, under a fifth of a GFS file; heights are
# reckoned from the temperatures up from the lowest level's standard height (model_profile).
IDX_WIND: tuple[tuple[str, str], ...] = (("UGRD", "mb"), ("VGRD", "mb"), ("TMP", "mb"))
# "all": everything wxsky reads (heights, humidity, cloud water, the cloud decks, the surface).
IDX_WANTED: tuple[tuple[str, str], ...] = (
    ("UGRD", "mb"), ("VGRD", "mb"), ("TMP", "mb"), ("HGT", "mb"), ("RH", "mb"),
    ("CLWMR", "mb"), ("HGT", "surface"), ("PRES", "surface"), ("CAPE", "surface"),
    ("PRATE", "surface"), ("TMP", "2 m above ground"), ("UGRD", "10 m above ground"),
    ("VGRD", "10 m above ground"), ("HGT", "0C isotherm"), ("HGT", "tropopause"),
    ("PRES", "tropopause"), ("TCDC", "low cloud layer"), ("TCDC", "middle cloud layer"),
    ("TCDC", "high cloud layer"), ("TCDC", "convective cloud layer"),
    ("PRES", "low cloud top level"), ("PRES", "low cloud bottom level"),
    ("PRES", "middle cloud top level"), ("PRES", "middle cloud bottom level"),
    ("PRES", "high cloud top level"), ("PRES", "high cloud bottom level"),
    ("PRES", "convective cloud top level"), ("PRES", "convective cloud bottom level"),
)  # fmt: skip
