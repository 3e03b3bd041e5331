"""The fuzz targets: one per parser, each a `check(data: bytes)` that feeds the bytes to the
parser and raises AssertionError for anything the parser must never do, plus seed inputs.

    from tools.fuzz.fuzz_targets import TARGETS, run_check
    run_check(TARGETS["metar"], b"KXYZ 261550Z 27010KT 10SM CLR 20/10 A3000")

A check lets through what the parser documents as bad input (a `WxskyError` such as
`FeedError`/`ConfigError`, a decoder's error lines, a `Decoded.reject`) and fails on:

* an escaped exception (anything else, `MetarInternalError` included: a decoder defect);
* a value outside the weather state's ranges (`weather/state.py`'s kinds, the cockpit's
  `RANGES`): every patch must make a `WeatherState`, and that state must be in range;
* a broken documented property (a decode that is not one line per error, a feed read in
  chunks that differs from one read whole, a preset or config that does not load back equal);
* a decode slower than the target's `time_limit_s` (measured twice before it counts, so a
  scheduler hiccup is not a failure): pathological backtracking shows as seconds.

Adding a target is one function and its decorator line:

    @target("cigi", seeds=cigi_seeds, tokens=_cigi_tokens(), max_len=2048)
    def check_cigi(data: bytes) -> None:
        d = decode_cigi(data)  # never raises: problems are counted in `d.counts`
        for p in d.packets:
            _assert_cigi_packet(p, p.spec.name)

Seeds come from the real corpora: `../shared/data/` (absent in a fresh clone: skipped) and
`tests/data/`, the shipped presets, cloud models and configs. `tools/fuzz/fuzz.py` runs the targets;
`tests/test_fuzz.py` replays the regression corpus `tests/data/fuzz/<target>/` and smokes each.
"""

from __future__ import annotations

import atexit
import contextlib
import gzip
import json
import math
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import traceback
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass
from datetime import MAXYEAR, MINYEAR, UTC, datetime
from functools import cache
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape as xml_escape

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from wxsky.errors import ConfigError, FeedError, MetarError  # noqa: E402 - after the path
from wxsky.protocols.canaerospace import CanasDecoder  # noqa: E402
from wxsky.protocols.cigi import REASONS as CIGI_REASONS  # noqa: E402
from wxsky.protocols.cigi import CigiDatagram  # noqa: E402
from wxsky.protocols.cigi import Packet as CigiPacket  # noqa: E402
from wxsky.protocols.cigi import decode_datagram as decode_cigi  # noqa: E402
from wxsky.protocols.cigi import encode_datagram as encode_cigi  # noqa: E402
from wxsky.protocols.cigi import make as make_cigi  # noqa: E402
from wxsky.protocols.cigi_examples import messages as cigi_messages  # noqa: E402
from wxsky.protocols.cigi_eye import eye as cigi_eye  # noqa: E402
from wxsky.protocols.cigi_packets import PACKETS as CIGI_PACKETS  # noqa: E402
from wxsky.protocols.cigi_packets import START_PACKETS as CIGI_START_PACKETS  # noqa: E402
from wxsky.protocols.cigi_session import HostState as CigiHostState  # noqa: E402
from wxsky.protocols.cigi_session import absorb as cigi_absorb  # noqa: E402
from wxsky.protocols.cigi_weather import weather_patch as cigi_weather_patch  # noqa: E402
from wxsky.protocols.nmea import NmeaDecoder, NmeaSettings  # noqa: E402
from wxsky.protocols.result import Decoded  # noqa: E402
from wxsky.scene.cloud_model_files import MODEL_TABLE, model_from_values  # noqa: E402
from wxsky.scene.clouds import UNDER_BASE_MAX_M, generate_block_clouds  # noqa: E402
from wxsky.scene.lightning import RATE_PER_MIN, storm_rate_per_min  # noqa: E402
from wxsky.schema import Kind, Number, Table, Tables  # noqa: E402
from wxsky.schema.toml_file import check_toml_bytes  # noqa: E402
from wxsky.settings.config import (  # noqa: E402
    CONFIG_TABLE,
    DaemonConfig,
    config_to_toml_dict,
    load_config,
)
from wxsky.settings.preset_check import PRESET_TABLE, check_preset_bytes  # noqa: E402
from wxsky.settings.preset_write import preset_to_toml, toml_string, toml_value  # noqa: E402
from wxsky.weather.cockpit import (  # noqa: E402
    LAYER_TYPE,
    RANGES,
    WEATHER_KEYS,
    CockpitUpdate,
    overlay,
)
from wxsky.weather.feed_formats import MAX_PROBLEMS, awc_csv_records  # noqa: E402
from wxsky.weather.feeds import FORMATS, parse_feed, read_feed  # noqa: E402
from wxsky.weather.metar import MAX_ERRORS, Metar, decode  # noqa: E402
from wxsky.weather.metar_clouds import FIELD_ELEVATION_RANGE_M, metar_to_patch  # noqa: E402
from wxsky.weather.state import (  # noqa: E402
    ALT_M,
    COVER_OKTAS,
    GUST_MPS,
    LAT_DEG,
    LAYER_HEIGHT_M,
    LON_DEG,
    MAX_LAYERS,
    QNH_HPA,
    SEED,
    TEMPERATURE_C,
    VISIBILITY_M,
    WIND_DIR_DEG,
    WIND_SPEED_MPS,
    CloudType,
    WeatherPatch,
    WeatherState,
    parse_time_utc,
)

SHARED_DATA = ROOT.parent / "shared" / "data"
TEST_DATA = ROOT / "tests" / "data"
REGRESSION_DIR = TEST_DATA / "fuzz"
MAX_SEEDS = 3000  # per target: a deterministic sample of a large corpus

Check = Callable[[bytes], None]


@dataclass(frozen=True)
class Target:
    name: str
    check: Check
    seeds: Callable[[], list[bytes]]
    tokens: tuple[bytes, ...] = ()  # dictionary words the mutators splice in (atheris -dict=)
    max_len: int = 4096  # longest input the engines make
    time_limit_s: float = 1.0  # per input, measured twice before it counts
    # Entered around a whole run (the control target's daemon); None for pure parsers.
    session: Callable[[], AbstractContextManager[object]] | None = None
    # Called every `batch_every` inputs and at the end of a run, inside the session.
    batch_check: Callable[[], None] | None = None
    batch_every: int = 0
    # False where the code under test runs in another process: coverage guidance sees none
    # of it, and an atheris child killed on a hang would leave its daemon behind.
    coverage: bool = True


TARGETS: dict[str, Target] = {}


def target(
    name: str, *, seeds: Callable[[], list[bytes]], **options: Any
) -> Callable[[Check], Check]:
    """Register `check` as the target `name` (see the module docstring)."""

    def register(check: Check) -> Check:
        TARGETS[name] = Target(name, check, seeds, **options)
        return check

    return register


class FuzzFailure(AssertionError):
    """What a target found: `signature` groups failures with one cause (for deduplication)."""

    def __init__(self, message: str, signature: str) -> None:
        super().__init__(message)
        self.signature = signature


class FatalFailure(FuzzFailure):
    """The code under test is gone (the control daemon died or stopped answering): the run
    cannot go on."""


def session(t: Target) -> AbstractContextManager[object]:
    """What a run of `t` happens inside: the control target's daemon, nothing for the rest."""
    return t.session() if t.session is not None else contextlib.nullcontext()


def cleanup() -> None:
    """Remove what the targets made on disk (also done at exit)."""
    _Scratch.remove()


def checked_batch(t: Target) -> None:
    """`t.batch_check`, its failures as FuzzFailure (see run_check)."""
    if t.batch_check is not None:
        _guarded(t, t.batch_check, ", between inputs", "")


def run_check(t: Target, data: bytes) -> None:
    """Run `t.check` on `data`; raises FuzzFailure for anything the parser must not do."""
    start = time.perf_counter()
    _checked(t, data)
    elapsed = time.perf_counter() - start
    if elapsed > t.time_limit_s:
        start = time.perf_counter()
        _checked(t, data)
        again = time.perf_counter() - start
        if again > t.time_limit_s:
            raise FuzzFailure(
                f"{t.name}: took {min(elapsed, again):.3f} s, limit {t.time_limit_s:g} s, "
                f"on {_show(data)}",
                f"{t.name}: slow",
            )


def _checked(t: Target, data: bytes) -> None:
    _guarded(t, lambda: t.check(data), "", f" on {_show(data)}")


def _guarded(t: Target, call: Callable[[], None], where: str, on: str) -> None:
    """`call()`, whatever it raises but FuzzFailure turned into one: `where` follows the
    target's name and `on` (the input) ends the message; the signature names the cause."""
    try:
        call()
    except FuzzFailure:
        raise
    except AssertionError as exc:
        message = str(exc).splitlines()[0] if str(exc) else "assertion failed"
        raise FuzzFailure(
            f"{t.name}{where}: {message}{on}", f"{t.name}: {_signature_text(message)}"
        ) from exc
    except Exception as exc:
        raise FuzzFailure(
            f"{t.name}{where}: {type(exc).__name__} escaped: {_one_line(exc)}{on}",
            f"{t.name}: {type(exc).__name__} at {_where(exc)}",
        ) from exc


def _show(data: bytes, limit: int = 160) -> str:
    more = f"... ({len(data)} bytes)" if len(data) > limit else ""
    return f"{data[:limit]!r}{more}"


def _one_line(exc: BaseException) -> str:
    text = str(exc).replace("\n", " | ")
    return text if len(text) <= 300 else text[:300] + "..."


def _signature_text(message: str) -> str:
    """A message with its numbers and quoted values blanked, so one cause is one signature."""
    text = re.sub(r"'[^']*'|\"[^\"]*\"", "'…'", message)
    return re.sub(r"[-+]?\d[\d.e+-]*", "#", text)[:120]


def _where(exc: BaseException) -> str:
    """The innermost wxsky frame of the exception (or of its cause: MetarInternalError)."""
    frames = traceback.extract_tb(exc.__traceback__)
    if exc.__cause__ is not None:
        frames += traceback.extract_tb(exc.__cause__.__traceback__)
    ours = [f for f in frames if "/wxsky/" in f.filename] or frames
    if not ours:
        return "?"
    f = ours[-1]
    name = f.filename.split("/wxsky/")[-1] if "/wxsky/" in f.filename else Path(f.filename).name
    return f"{name}:{f.lineno}"


# --- range checks shared by the targets ----------------------------------------------------------


def _number_in(kind: Number, value: object, what: str) -> None:
    ok = (
        isinstance(value, int | float)
        and not isinstance(value, bool)
        and math.isfinite(value)
        and kind.contains(value)
    )
    if not ok:
        raise AssertionError(f"{what} = {value!r} is outside {kind.range_text() or 'finite'}")


_CLOUD_NAMES = frozenset(t.wire_name for t in CloudType)


def assert_weather_dict(w: Mapping[str, Any], what: str = "weather") -> None:
    """A `weather_to_dict` map (the daemon's status) within the weather state's ranges."""
    parse_time_utc(w["time_utc"])
    obs = w["observer"]
    _number_in(LAT_DEG, obs["lat_deg"], f"{what}.observer.lat_deg")
    _number_in(LON_DEG, obs["lon_deg"], f"{what}.observer.lon_deg")
    _number_in(ALT_M, obs["alt_m"], f"{what}.observer.alt_m")
    layers = w["layers"]
    assert len(layers) <= MAX_LAYERS, f"{what}: {len(layers)} cloud layers"
    for i, lay in enumerate(layers):
        _number_in(COVER_OKTAS, lay["cover_oktas"], f"{what}.layers[{i}].cover_oktas")
        _number_in(LAYER_HEIGHT_M, lay["base_m"], f"{what}.layers[{i}].base_m")
        _number_in(LAYER_HEIGHT_M, lay["top_m"], f"{what}.layers[{i}].top_m")
        assert lay["top_m"] > lay["base_m"], f"{what}.layers[{i}]: top not above base"
        assert lay["type"] in _CLOUD_NAMES, f"{what}.layers[{i}].type = {lay['type']!r}"
    for i, wind in enumerate(w["wind"]):
        _number_in(ALT_M, wind["alt_m"], f"{what}.wind[{i}].alt_m")
        _number_in(WIND_DIR_DEG, wind["dir_deg"], f"{what}.wind[{i}].dir_deg")
        _number_in(WIND_SPEED_MPS, wind["speed_mps"], f"{what}.wind[{i}].speed_mps")
        _number_in(GUST_MPS, wind["gust_mps"], f"{what}.wind[{i}].gust_mps")
        assert isinstance(wind["variable"], bool), f"{what}.wind[{i}].variable"
    _number_in(VISIBILITY_M, w["visibility_m"], f"{what}.visibility_m")
    for key in ("temperature_c", "dewpoint_c"):
        if w[key] is not None:
            _number_in(TEMPERATURE_C, w[key], f"{what}.{key}")
    _number_in(QNH_HPA, w["qnh_hpa"], f"{what}.qnh_hpa")
    _number_in(SEED, w["seed"], f"{what}.seed")
    assert all(isinstance(g, str) for g in w["present_weather"]), f"{what}.present_weather"


def assert_state_in_range(state: WeatherState, what: str = "weather") -> None:
    """Every field of a state within the weather state's ranges (the state checks some of
    them itself; this says so for all, and would notice a check that went missing)."""
    obs = state.observer
    _number_in(LAT_DEG, obs.lat_deg, f"{what}.observer.lat_deg")
    _number_in(LON_DEG, obs.lon_deg, f"{what}.observer.lon_deg")
    _number_in(ALT_M, obs.alt_m, f"{what}.observer.alt_m")
    assert state.time_utc.utcoffset() is not None, f"{what}.time_utc without a zone"
    assert len(state.layers) <= MAX_LAYERS, f"{what}: {len(state.layers)} cloud layers"
    for i, lay in enumerate(state.layers):
        _number_in(COVER_OKTAS, lay.cover_oktas, f"{what}.layers[{i}].cover_oktas")
        _number_in(LAYER_HEIGHT_M, lay.base_m, f"{what}.layers[{i}].base_m")
        _number_in(LAYER_HEIGHT_M, lay.top_m, f"{what}.layers[{i}].top_m")
        assert lay.top_m > lay.base_m, f"{what}.layers[{i}]: top not above base"
        assert isinstance(lay.type, CloudType), f"{what}.layers[{i}].type = {lay.type!r}"
    for i, w in enumerate(state.wind):
        _number_in(ALT_M, w.alt_m, f"{what}.wind[{i}].alt_m")
        _number_in(WIND_DIR_DEG, w.dir_from_deg, f"{what}.wind[{i}].dir_deg")
        _number_in(WIND_SPEED_MPS, w.speed_mps, f"{what}.wind[{i}].speed_mps")
        _number_in(GUST_MPS, w.gust_mps, f"{what}.wind[{i}].gust_mps")
    _number_in(VISIBILITY_M, state.visibility_m, f"{what}.visibility_m")
    if state.temperature_c is not None:
        _number_in(TEMPERATURE_C, state.temperature_c, f"{what}.temperature_c")
    if state.dewpoint_c is not None:
        _number_in(TEMPERATURE_C, state.dewpoint_c, f"{what}.dewpoint_c")
    _number_in(QNH_HPA, state.qnh_hpa, f"{what}.qnh_hpa")
    _number_in(SEED, state.seed, f"{what}.seed")
    assert all(isinstance(g, str) for g in state.present_weather), f"{what}.present_weather"


def assert_patch_in_range(patch: WeatherPatch) -> WeatherState:
    """The state `patch` makes over the defaults; it must exist and be within range."""
    if patch.layers is not None:
        assert len(patch.layers) <= MAX_LAYERS, f"patch with {len(patch.layers)} cloud layers"
    try:
        state = WeatherState().apply(patch)
    except ValueError as exc:
        raise AssertionError(f"the weather state refuses the patch: {_one_line(exc)}") from exc
    assert_state_in_range(state, "patched weather")
    return state


def assert_cockpit_update(update: CockpitUpdate, *, weather: bool = True) -> None:
    """Every value of a decoded cockpit update in the cockpit's ranges, and (`weather`) the
    weather it lays over the defaults a valid state."""
    for key, value in update.values.items():
        assert key in WEATHER_KEYS, f"cockpit update with unknown key {key!r}"
        if key.endswith("." + LAYER_TYPE):
            assert isinstance(value, CloudType), f"{key} = {value!r} is not a cloud type"
        else:
            _number_in(RANGES[key], value, f"cockpit {key}")
    if update.position_deg is not None:
        lat, lon = update.position_deg
        _number_in(LAT_DEG, lat, "cockpit position lat")
        _number_in(LON_DEG, lon, "cockpit position lon")
    if update.time_utc is not None:
        assert update.time_utc.utcoffset() is not None, "cockpit time without a zone"
    if update.time_of_day_s is not None:
        _number_in(Number(0.0, 86_400.0), update.time_of_day_s, "cockpit time_of_day_s")
    if not weather:
        return
    try:
        state = overlay(WeatherState(), update.values)
    except ValueError as exc:
        raise AssertionError(f"overlay refuses the cockpit values: {_one_line(exc)}") from exc
    assert_state_in_range(state, "cockpit weather")


def _assert_decoded(d: Decoded) -> None:
    given = [d.update is not None, bool(d.ignored), bool(d.error)]
    assert sum(given) <= 1, f"Decoded with more than one outcome: {d!r}"
    for reason in (d.ignored, d.error):
        assert "\n" not in reason and "\r" not in reason, f"a reason of two lines: {reason!r}"
    if d.update is not None:
        assert_cockpit_update(d.update, weather=False)  # the merged updates make the weather


# --- METAR -----------------------------------------------------------------------------------

_NOW = datetime(2026, 12, 1, 0, 10, tzinfo=UTC)  # "now" for undated reports: deterministic
METAR_TOKENS = tuple(
    t.encode()
    for t in (
        "METAR ",
        "SPECI ",
        " AUTO",
        " COR",
        " CCA",
        " NIL",
        " CAVOK",
        " NOSIG",
        " RMK ",
        " BECMG",
        " TEMPO",
        " INTER",
        " FM1200",
        " PROB30",
        " BLU",
        " YLO",
        "KXYZ 261550Z ",
        "27010KT",
        "VRB03KT",
        "27010G25KT",
        "04014",
        "05MPS",
        "00000KT",
        "280V350",
        "P49MPS",
        "9999",
        "0000",
        "10SM",
        "1/2SM",
        "1 1/4SM",
        "M1/4SM",
        "P6SM",
        "4000SE",
        "9999NDV",
        "10KM",
        "R24/0900VP2000U",
        "-RA",
        "+TSRA",
        "BR",
        "FG",
        "VCSH",
        "FEW030",
        "SCT025CB",
        "BKN///",
        "OVC010TCU",
        "VV005",
        "///",
        "CLR",
        "SKC",
        "NSC",
        "NCD",
        "20/10",
        "M05/M07",
        "Q1013",
        "A2992",
        "Q////",
        "QFE986",
        "T02560244",
        "WS R24",
        "RERA",
        "W16/H11",
        "=",
        " 262400Z",
        " 261560Z",
        " 320000Z",
        "999999",
        "M",
        "P",
        "/",
        "G",
        # Fog and runway visual range (issue 43 item 3): every FM-15 form of an RVR group.
        " BCFG",
        " PRFG",
        " MIFG",
        " FZFG",
        " VCFG",
        " R14/0600N",
        " R32L/P1500",
        " R06/0400V0800U",
        " R14/M0050",
        " R28L/2400FT",
        " R28R/1000V1600FT/D",
        " R88/0600",
        " R36C/0000",
    )
)


def _assert_metar(m: Metar, field_elevation_m: float) -> None:
    assert m.partial == bool(m.errors), "partial does not match the error lines"
    assert len(m.errors) <= MAX_ERRORS + 1, f"{len(m.errors)} error lines"
    for e in m.errors:
        assert e and "\n" not in e and "\r" not in e, f"error line {e!r}"
    assert m.time_utc is None or m.time_group is not None, "a time without its group"
    assert m.time_utc is None or m.time_utc.utcoffset() is not None, "a time without a zone"
    json.dumps(m.to_dict())
    m.describe()
    with contextlib.suppress(MetarError):
        m.require_usable()
    state = assert_patch_in_range(metar_to_patch(m, field_elevation_m=field_elevation_m))
    _assert_fog(state)


def _assert_fog(state: WeatherState) -> None:
    """The fog a report makes: a field whose visibility and RVR are finite and positive at the
    field, its runways' touchdown zones and beside it."""
    from wxsky.scene.fog import fog_field

    field = fog_field(state)
    if field is None:
        return
    for name in ("14", "32L", *(r.runway for r in state.fog.rvr if state.fog is not None)):
        rvr = field.runway_rvr_m(name)
        assert math.isfinite(rvr) and rvr > 0.0, f"RVR {rvr!r} at runway {name}"
    for east, north, height in ((0.0, 0.0, 2.5), (3000.0, -2000.0, 30.0)):
        seen = float(field.visibility_m(east, north, height))
        assert math.isfinite(seen) and seen > 0.0, f"visibility {seen!r}"


@cache
def corpus_reports() -> tuple[tuple[str, int, int], ...]:
    """Every distinct report of the METAR corpora (shared data where present, tests/data),
    with its feed's year and month."""
    found: dict[str, tuple[int, int]] = {}
    for path in _corpus_files():
        for report in read_feed(path).reports:
            found.setdefault(report.raw, (report.year, report.month))
    return tuple((raw, year, month) for raw, (year, month) in found.items())


def _corpus_files() -> list[Path]:
    files = sorted((TEST_DATA / "metar").glob("*.gz"))
    if (SHARED_DATA / "metar").is_dir():  # absent in a fresh clone
        files += sorted(p for p in (SHARED_DATA / "metar").iterdir() if p.suffix != ".md")
    return files


def sample(items: list[bytes], limit: int = MAX_SEEDS) -> list[bytes]:
    """At most `limit` of the distinct items, spread evenly over them, in order."""
    unique = list(dict.fromkeys(items))
    if len(unique) <= limit:
        return unique
    step = len(unique) / limit
    return [unique[int(i * step)] for i in range(limit)]


# Fog and RVR reports (issue 43 item 3), whatever the corpora hold of them.
FOG_SEEDS = (
    b"LSZH 061020Z 24004KT 0300 R14/0600N R32L/P1500 R06/0400V0800U FG VV001 08/08 Q1020",
    b"EGLL 061020Z 00000KT 4000 BCFG R09L/0350 R27R/M0050 SCT002 04/04 Q1025",
    b"LFPG 061030Z 18003KT 2500 PRFG BR R26L/0900U R08R/1200D FEW001 05/05 Q1030",
    b"KSFO 061056Z 00000KT 1/4SM R28L/2400FT R28R/1000V1600FT/D FG VV002 11/11 A3002",
    b"EDDF 061020Z VRB01KT 6000 MIFG R25C/P2000 NSC 02/02 Q1031",
)


@cache
def metar_seeds() -> list[bytes]:
    return sample([raw.encode() for raw, _, _ in corpus_reports()]) + list(FOG_SEEDS)


@target("metar", seeds=metar_seeds, tokens=METAR_TOKENS, max_len=1024, time_limit_s=0.5)
def check_metar(data: bytes) -> None:
    """The decoder on the text, dated by the feed and undated, then the patch it makes."""
    text = data.decode("utf-8", "replace")
    # Dated and undated; at the lowest and the highest field elevation (cloud near the
    # state's ceiling).
    lo, hi = FIELD_ELEVATION_RANGE_M
    _assert_metar(decode(text, year=2025, month=7), hi)
    _assert_metar(decode(text, now_utc=_NOW), lo)


# --- METAR feeds -----------------------------------------------------------------------------

_REFERENCE = datetime(2026, 3, 20, 16, 0, tzinfo=UTC)
FEED_LINES = 24  # lines per seed: a window of a real file
FEED_REPORTS_DECODED = 10  # reports of one input decoded (the rest only parsed)
FEED_TOKENS = (
    b"raw_text,",
    b"<?xml version='1.0'?>",
    b"<response>",
    b"<METAR>",
    b"</METAR>",
    b"<raw_text>",
    b"</raw_text>",
    b"<observation_time>",
    b"<elevation_m>",
    b"<latitude>",
    b"<sky_condition sky_cover='BKN' cloud_base_ft_agl='1200'/>",
    b"<error>",
    b"<![CDATA[",
    b"&amp;",
    b"2025/07/26 15:55\n",
    b"2026-03-20T15:20:00.000Z",
    b"\x1f\x8b",
    b"\r\n",
    b'"',
    b",,,,,,,,,,",
    b"\xef\xbb\xbf",
    b"1e308",
    b"nan",
    *METAR_TOKENS[:20],
)


def _feed_check(fmt: str) -> Check:
    def check(data: bytes) -> None:
        """parse_feed: FeedError, or reports with sane dates; the first ones decoded.

        The first FEED_REPORTS_DECODED reports go through the decoder and into a patch at
        the feed's field elevation, as the daemon's METAR input does."""
        try:
            feed = parse_feed(data, format=fmt, name="fuzz", reference_utc=_REFERENCE)
        except FeedError:
            return
        assert feed.format in FORMATS and fmt in ("auto", feed.format), f"format {feed.format}"
        assert len(feed.problems) <= MAX_PROBLEMS + 1, f"{len(feed.problems)} problems"
        for r in feed.reports:
            assert r.raw and r.raw == " ".join(r.raw.split()), f"report text {r.raw[:60]!r}"
            assert 1 <= r.month <= 12 and MINYEAR <= r.year <= MAXYEAR, f"{r.year}-{r.month}"
            assert r.observed_utc is None or r.observed_utc.utcoffset() is not None
        for r in feed.reports[:FEED_REPORTS_DECODED]:
            # As the daemon's METAR input does: decode, then the patch at the feed's elevation
            # where the feed gives a plausible one.
            metar = decode(r.raw, year=r.year, month=r.month)
            lo, hi = FIELD_ELEVATION_RANGE_M
            elevation = (
                r.elevation_m if r.elevation_m is not None and lo <= r.elevation_m <= hi else 0.0
            )
            assert_patch_in_range(metar_to_patch(metar, field_elevation_m=elevation))

    check.__name__ = f"check_feed_{fmt.replace('-', '_')}"
    return check


def _file_lines(path: Path) -> list[bytes]:
    data = path.read_bytes()
    if data[:2] == b"\x1f\x8b":
        data = gzip.decompress(data)
    return data.splitlines(keepends=True)


def _windows(lines: list[bytes], head: list[bytes], count: int = 12) -> list[bytes]:
    """`count` windows of FEED_LINES lines spread over a file, each after `head`."""
    if not lines:
        return []
    step = max(1, (len(lines) - FEED_LINES) // count)
    return [b"".join(head + lines[i : i + FEED_LINES]) for i in range(0, len(lines), step)][:count]


def _xml_document(csv_window: bytes) -> bytes:
    """An AWC XML document with the rows of a CSV window (no XML corpus is stored)."""
    records = awc_csv_records(csv_window.decode("utf-8", "replace").splitlines(), _NoProblems())
    out = ['<?xml version="1.0" encoding="UTF-8"?>', '<response version="1.2">']
    out.append(f'  <data num_results="{len(records)}">')
    for r in records:
        out.append("    <METAR>")
        out.append(f"      <raw_text>{xml_escape(r.raw)}</raw_text>")
        for tag in ("station_id", "observation_time", "latitude", "longitude", "elevation_m"):
            value = getattr(r, tag)
            if value is not None:
                out.append(f"      <{tag}>{xml_escape(value)}</{tag}>")
        for cover, base in r.hints.get("sky", ()):
            attrs = f' sky_cover="{xml_escape(cover or "")}"'
            if base is not None:
                attrs += f' cloud_base_ft_agl="{xml_escape(base)}"'
            out.append(f"      <sky_condition{attrs} />")
        out.append("    </METAR>")
    out += ["  </data>", "</response>", ""]
    return "\n".join(out).encode()


class _NoProblems:
    def add(self, line: int, reason: str) -> None:
        pass


@cache
def feed_seed_files() -> dict[str, list[bytes]]:
    """Windows of the real feed files by format, and XML made from the CSV windows."""
    out: dict[str, list[bytes]] = {f: [] for f in FORMATS}
    for path in _corpus_files():
        lines = _file_lines(path)
        if any(line.startswith(b"raw_text,") for line in lines[:10]):
            header = next(i for i, line in enumerate(lines) if line.startswith(b"raw_text,"))
            windows = _windows(lines[header + 1 :], lines[: header + 1])
            out["awc-csv"] += windows
            out["awc-xml"] += [_xml_document(w) for w in windows[:4]]
            out["lines"] += [
                b"\n".join(r.raw.encode() for r in parse_feed(w, format="awc-csv").reports)
                for w in windows[:4]
            ]
        else:
            # tgftp: keep timestamp lines paired with their reports
            start = len(lines) % 2
            pairs = [b"".join(lines[i : i + 2]) for i in range(start, len(lines) - 1, 2)]
            out["tgftp"] += _windows(pairs, [], 8)
            out["lines"] += [b"".join(lines[i + 1 : i + 2 * FEED_LINES : 2]) for i in (0, 400)]
    for fmt in FORMATS:
        if out[fmt]:
            out[fmt].append(gzip.compress(out[fmt][0], mtime=0))
    return out


def _feed_seeds(fmt: str) -> Callable[[], list[bytes]]:
    def seeds() -> list[bytes]:
        files = feed_seed_files()
        if fmt == "auto":
            return sample([s for f in FORMATS for s in files[f][:4]])
        return sample(files[fmt])

    return seeds


for _fmt in (*FORMATS, "auto"):
    target(
        f"feed-{_fmt}",
        seeds=_feed_seeds(_fmt),
        tokens=FEED_TOKENS,
        max_len=16_384,
        time_limit_s=2.0,
    )(_feed_check(_fmt))


# --- NMEA 0183 -------------------------------------------------------------------------------

_PERMISSIVE_NMEA = NmeaSettings(
    heading_source="hdt", accept_relative_wind=True, allow_missing_checksum=True, max_line_bytes=82
)
NMEA_CHUNK = 7  # bytes per read in the chunked decode
NMEA_TOKENS = tuple(
    t.encode()
    for t in (
        "$",
        "!",
        "*",
        "\r\n",
        "\n",
        "\r",
        ",",
        "WIMWV",
        "WIMWD",
        "WIMDA",
        "HEHDT",
        "HCHDG",
        "GPZDA",
        "GPRMC",
        "PWXCL",
        "AIVDM",
        ",T,",
        ",R,",
        ",M,",
        ",N,",
        ",K,",
        ",A",
        ",V",
        "*00",
        "*FF",
        "360.0",
        "-0.0",
        "1e9",
        "nan",
        "99.99",
        "235960.00",
        "311299",
    )
)


def _nmea_decode(decoder: NmeaDecoder, chunks: Iterable[bytes]) -> list[Decoded]:
    out: list[Decoded] = []
    for chunk in chunks:
        out += decoder.feed(chunk, 1.0)
    return out + decoder.flush()


@cache
def nmea_seeds() -> list[bytes]:
    lines = _file_lines(TEST_DATA / "cockpit" / "instructor-panel.nmea")
    bare = [line.split(b" ", 1)[-1] for line in lines]  # without the logger's timestamp
    seeds = [b"".join(lines), b"".join(bare)]
    seeds += [b"".join(bare[i : i + 6]) for i in range(0, len(bare), 6)]
    seeds += [line for line in bare if line.strip()]
    return sample(seeds)


@target("nmea", seeds=nmea_seeds, tokens=NMEA_TOKENS, max_len=1024)
def check_nmea(data: bytes) -> None:
    """NMEA decoder on a byte stream: whole = in pieces; permissive too; values in range.

    Fed whole and in 7-byte reads (the results must be the same), and with permissive
    settings; every update in the cockpit's ranges and the weather they make valid."""
    whole = NmeaDecoder(reference_year=2026)
    whole_out = _nmea_decode(whole, [data])
    chunked = NmeaDecoder(reference_year=2026)
    pieces = [data[i : i + NMEA_CHUNK] for i in range(0, len(data), NMEA_CHUNK)]
    chunked_out = _nmea_decode(chunked, pieces)
    assert whole_out == chunked_out, "the stream decodes differently when read in pieces"
    permissive = NmeaDecoder(_PERMISSIVE_NMEA, reference_year=2026)
    permissive_out = _nmea_decode(permissive, [data])
    for decoder, results in ((whole, whole_out), (permissive, permissive_out)):
        s = decoder.stats
        assert s.lines == len(results) == s.updates + s.consumed + s.ignored + s.errors, s
        merged = CockpitUpdate()
        for d in results:
            _assert_decoded(d)
            if d.update is not None:
                merged = merged.merged(d.update)
        assert_cockpit_update(merged)


# --- CANaerospace ----------------------------------------------------------------------------

# An input is frames back to back: 2 bytes CAN id (big-endian; above 0x7FF is not an 11-bit
# id), 1 byte flags (low nibble: data length 0-15; 0x10 extended, 0x20 remote, 0x40 error
# frame), then the data.
_CAN_EXTENDED, _CAN_REMOTE, _CAN_ERROR = 0x10, 0x20, 0x40
_CAN_LOG = re.compile(r"\s([0-9A-Fa-f]{3,8})#([0-9A-Fa-f]*)")
_CAN_ASC = re.compile(
    r"^\s*[\d.]+\s+\d+\s+([0-9A-Fa-f]+)\s+Rx\s+d\s+(\d+)\s+((?:[0-9A-Fa-f]{2}\s*)*)$"
)


def can_frames(data: bytes) -> Iterator[tuple[int, int, bytes]]:
    """(can_id, flags, payload) of each frame in a fuzz input."""
    i = 0
    while i + 3 <= len(data):
        can_id, flags = (data[i] << 8) | data[i + 1], data[i + 2]
        n = flags & 0x0F
        yield can_id, flags, data[i + 3 : i + 3 + n]
        i += 3 + n


def can_frame(can_id: int, payload: bytes, flags: int = 0) -> bytes:
    """One frame of a fuzz input (the inverse of `can_frames`)."""
    return bytes([(can_id >> 8) & 0xFF, can_id & 0xFF, (flags & 0xF0) | len(payload)]) + payload


@cache
def can_seeds() -> list[bytes]:
    frames: list[bytes] = []
    for line in (TEST_DATA / "cockpit" / "canaerospace.log").read_text().splitlines():
        if m := _CAN_LOG.search(line):
            frames.append(can_frame(int(m[1], 16), bytes.fromhex(m[2])))
    for line in (TEST_DATA / "cockpit" / "canaerospace.asc").read_text().splitlines():
        if m := _CAN_ASC.match(line):
            frames.append(can_frame(int(m[1], 16), bytes.fromhex(m[3])[: int(m[2])]))
    seeds = [b"".join(frames[i : i + 8]) for i in range(0, len(frames), 8)]
    return sample(seeds + frames)


_CAN_DECODERS = (CanasDecoder(), CanasDecoder(frozenset({10})))


@target("canaerospace", seeds=can_seeds, max_len=512)
def check_canaerospace(data: bytes) -> None:
    """CANaerospace frames through a decoder for every node and one for node 10 only."""
    merged = CockpitUpdate()
    for can_id, flags, payload in can_frames(data):
        for decoder in _CAN_DECODERS:
            d = decoder.decode(
                can_id << 13 | can_id if flags & _CAN_EXTENDED else can_id,
                bytearray(payload),
                is_extended=bool(flags & _CAN_EXTENDED),
                is_remote=bool(flags & _CAN_REMOTE),
                is_error=bool(flags & _CAN_ERROR),
            )
            _assert_decoded(d)
            if d.update is not None:
                merged = merged.merged(d.update)
    assert_cockpit_update(merged)


# --- CIGI 3.3 datagrams ------------------------------------------------------------------------


@cache
def cigi_seeds() -> list[bytes]:
    """Every example message (each packet type behind its first packet, each direction whole,
    repeats) in both byte orders, and two datagrams run together (what a receive buffer read
    twice looks like)."""
    seeds = [encode_cigi(m, order) for m in cigi_messages() for order in ("big", "little")]
    seeds += [encode_cigi(m, order) for m in _storm_messages() for order in ("big", "little")]
    return [*seeds, seeds[0] + seeds[-1], seeds[1] + seeds[2]]


def _storm_messages() -> list[list[CigiPacket]]:
    """A host's storm (issue 43): a cumulonimbus layer with random lightning at each severity,
    and the precipitation layers (4 rain .. 7 hail), global and in a region, so that the
    mutations start from the fields the lightning and the shafts read."""
    host = make_cigi("ig_control", ig_mode=1)
    storm = [
        make_cigi(
            "weather_control",
            layer_id=layer,
            weather_enable=1,
            random_lightning_enable=lightning,
            cloud_type=1 if layer <= 3 else 0,  # cumulonimbus
            scope=scope,
            entity_or_region_id=7 if scope == 1 else 0,
            severity=severity,
            visibility_m=2500.0,
            coverage_pct=40.0 + 10.0 * severity,
            base_elevation_m=900.0,
            thickness_m=9000.0 if layer <= 3 else 800.0,
        )
        for layer, lightning, scope, severity in (
            (1, 1, 0, 0),
            (2, 1, 0, 3),
            (3, 1, 1, 5),
            (1, 0, 0, 2),
            (4, 0, 0, 4),
            (5, 0, 1, 1),
            (6, 0, 0, 3),
            (7, 0, 0, 5),
        )
    ]
    region = make_cigi(
        "environmental_region_control",
        region_id=7,
        region_state=1,
        merge_weather=1,
        lat_deg=47.5,
        lon_deg=8.5,
        size_x_m=20_000.0,
        size_y_m=20_000.0,
    )
    return [[host, *storm[:4]], [host, region, *storm[4:]], [host, region, *storm]]


def _cigi_tokens() -> tuple[bytes, ...]:
    headers = tuple(bytes([s.opcode, s.size]) for s in CIGI_PACKETS)
    floats = tuple(
        struct.pack(order + "f", x)
        for order in "<>"
        for x in (math.nan, math.inf, -math.inf, -0.0, 360.0, -180.0, 100.0, 3.4e38)
    )
    return (
        headers
        + floats
        + (b"\x80\x00", b"\x00\x80", b"\x03", b"\x00\x00", b"\xff\xff", b"\x00\x18")
    )


def _assert_cigi_packet(p: CigiPacket, where: str) -> None:
    """A decoded packet's values against the table's numbers, read here, not by the decoder."""
    for f in p.spec.value_fields:
        v = p[f.name]
        assert isinstance(v, float if f.is_float else int), f"{where}: {f.name} is {v!r}"
        assert math.isfinite(v), f"{where}: {f.name} is {v}"
        if f.when is not None and p[f.when[0]] != f.when[1]:
            continue
        assert f.lo is None or v >= f.lo, f"{where}: {f.name} {v} below {f.lo}"
        assert f.hi is None or (v < f.hi if f.wrap else v <= f.hi), f"{where}: {f.name} {v}"


@target("cigi", seeds=cigi_seeds, tokens=_cigi_tokens(), max_len=2048)
def check_cigi(data: bytes) -> None:
    """A CIGI 3.3 datagram: never an exception, decoded values finite and in range, problems
    one line each and counted, and the decoded packets encode back to themselves."""
    d = decode_cigi(data)
    assert set(d.counts) <= set(CIGI_REASONS), f"undocumented reasons {set(d.counts)}"
    assert sum(d.counts.values()) >= len(d.problems), "a problem was not counted"
    for problem in d.problems:
        assert problem.message and "\n" not in problem.message, f"message {problem.message!r}"
        assert 0 <= problem.offset < max(len(data), 1), f"offset {problem.offset} outside"
    if d.refused:
        assert not d.packets and d.direction is None, "a refused datagram with packets"
        return
    assert d.byte_order is not None and d.direction is not None
    for i, p in enumerate(d.packets):
        _assert_cigi_packet(p, f"packet {i} ({p.spec.name})")
    message = list(d.packets)
    if not message or not message[0].spec.starts_message:
        # The first packet was dropped (a value out of range): a default one stands in.
        message.insert(0, make_cigi(CIGI_START_PACKETS[d.direction].key))
    again = decode_cigi(encode_cigi(message, d.byte_order))
    assert again.packets == tuple(message), "decoded packets do not encode back to themselves"
    assert not again.counts, f"a re-encoded datagram has problems: {dict(again.counts)}"
    _assert_cigi_session(d)


def _assert_cigi_session(d: CigiDatagram) -> None:
    """What the IG makes of a host's datagram, twice over (the second time every packet
    meets the state the first left): the weather a valid state, the eye finite and a camera."""
    state = CigiHostState()
    for _ in range(2):
        got = cigi_absorb(state, d)
        state = got.state
        for reason, message in got.dropped:
            assert reason in CIGI_REASONS and "\n" not in message, f"drop {reason}: {message!r}"
        eye = cigi_eye(state)
        own = state.ownship
        place = (own.lat_deg, own.lon_deg, own.alt_m) if own else (47.0, 8.0, 500.0)
        weather = assert_patch_in_range(cigi_weather_patch(state, *place))
        # Random lightning's storm, as the frames flash it (scene/lightning.py).
        rate = storm_rate_per_min(weather)
        assert rate in (0.0, *RATE_PER_MIN.values()), f"lightning at {rate} a minute"
        if eye is not None:
            values = (eye.lat_deg, eye.lon_deg, eye.alt_m, eye.heading_deg, eye.pitch_deg)
            assert all(math.isfinite(v) for v in values), f"eye {eye}"
            assert -90.0 <= eye.pitch_deg <= 90.0 and 0.0 <= eye.heading_deg < 360.0, f"{eye}"
            assert eye.fov_deg is None or 1.0 <= eye.fov_deg <= 170.0, f"eye {eye}"


# --- settings files: config, presets, cloud models --------------------------------------------


def table_keys(kind: Kind) -> set[str]:
    """Every key name of a settings table, nested tables included (dictionary words)."""
    keys: set[str] = set()
    if isinstance(kind, Tables):
        return table_keys(kind.item)
    if isinstance(kind, Table):
        for name, f in kind.fields.items():
            keys.add(name)
            keys |= table_keys(f.kind)
    return keys


_TOML_WORDS = (
    b" = ",
    b"\n",
    b"[",
    b"]",
    b"[[",
    b"]]",
    b'"',
    b"'",
    b"'''",
    b'"""',
    b"true",
    b"false",
    b"0",
    b"-1",
    b"1e308",
    b"-1e308",
    b"inf",
    b"nan",
    b"-0.0",
    b"9223372036854775807",
    b"0x7fffffffffffffff",
    b"1979-05-27T07:32:00Z",
    b"1979-05-27",
    b"{ }",
    b"[ ]",
    b"#",
    b".",
    b"\\u0000",
    b"\\n",
)


def _toml_tokens(kind: Kind) -> tuple[bytes, ...]:
    return _TOML_WORDS + tuple(sorted(k.encode() for k in table_keys(kind)))


def toml_text(data: Mapping[str, Any]) -> str:
    """Plain data (`config_to_toml_dict`'s shape: tables of scalars and lists, arrays of such
    tables) as TOML: the stdlib reads TOML but writes none."""
    top = [f"{k} = {toml_value(v)}" for k, v in data.items() if not isinstance(v, dict | list)]
    top += [
        f"{k} = {toml_value(v)}"
        for k, v in data.items()
        if isinstance(v, list) and not (v and isinstance(v[0], dict))
    ]
    out = top
    for key, value in data.items():
        if isinstance(value, dict):
            out += [
                "",
                f"[{_toml_key(key)}]",
                *(f"{_toml_key(k)} = {toml_value(v)}" for k, v in value.items()),
            ]
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            for table in value:
                out += ["", f"[[{_toml_key(key)}]]"]
                out += [f"{_toml_key(k)} = {toml_value(v)}" for k, v in table.items()]
    return "\n".join(out) + "\n"


def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else toml_string(key)


class _Scratch:
    """A private directory for the file the config loader reads (it takes a path)."""

    path: Path | None = None

    @classmethod
    def file(cls, name: str) -> Path:
        if cls.path is None or not cls.path.is_dir():
            # In memory where there is /dev/shm: a file per input on a disk is slow.
            shm = Path("/dev/shm")
            where = str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None
            cls.path = Path(tempfile.mkdtemp(prefix="wxsky-fuzz-", dir=where))
        return cls.path / name

    @classmethod
    def remove(cls) -> None:
        if cls.path is not None:
            shutil.rmtree(cls.path, ignore_errors=True)
            cls.path = None


atexit.register(_Scratch.remove)


@cache
def config_seeds() -> list[bytes]:
    seeds = [p.read_bytes() for p in sorted((ROOT / "configs").glob("*.toml"))]
    full = config_to_toml_dict(DaemonConfig())
    seeds.append(toml_text(full).encode())
    full["serial"] = [{"url": "/dev/ttyUSB0", "baud": 4800, "fields": ["wind", "clouds"]}]
    full["can"] = [{"interface": "socketcan", "channel": "can0", "node_ids": [10, 11]}]
    seeds.append(toml_text(full).encode())
    seeds.append(b'[output]\nshm_name = "wxsky-a"\nmax_width = 960\nmax_height = 540\n')
    seeds.append(b"[lightning]\nflashes_per_min = 30\n[radar]\nlayer = true\nrange_nm = 320\n")
    seeds.append(b"[radar]\nlayer = true\ntilt_deg = -15.0\nsize_px = 1024\nevery_s = 0.1\n")
    return seeds


@target("config", seeds=config_seeds, tokens=_toml_tokens(CONFIG_TABLE), max_len=16_384)
def check_config(data: bytes) -> None:
    """load_config: ConfigError, or a config that builds and loads back equal.

    Its derived settings must build and `config_to_toml_dict` must give it back (the
    documented round trip)."""
    path = _Scratch.file("wxsky.toml")
    path.write_bytes(data)
    try:
        config = load_config(path)
    except ConfigError as exc:
        assert str(exc).strip(), "an empty ConfigError"
        return
    config.scene.settings()
    config.transition.rates()
    path.write_text(toml_text(config_to_toml_dict(config)), encoding="utf-8")
    again = load_config(path)
    assert again == config, "the config does not load back equal from config_to_toml_dict"


@cache
def preset_seeds() -> list[bytes]:
    return [
        p.read_bytes() for p in sorted((ROOT / "wxsky" / "settings" / "presets").glob("*.toml"))
    ]


_PRESET_PATH = Path("fuzz.toml")


@target("preset", seeds=preset_seeds, tokens=_toml_tokens(PRESET_TABLE), max_len=8192)
def check_preset(data: bytes) -> None:
    """The preset checker: problems, or a patch in range that writes back to itself.

    `preset_to_toml` of the patch must load back to the same patch (its documented round
    trip)."""
    check = check_preset_bytes(_PRESET_PATH, data)
    if check.patch is None:
        assert check.problems, "no patch and no problem"
        check.lines()
        assert check.error_message().strip()
        return
    assert not check.problems, "a patch despite problems"
    assert_patch_in_range(check.patch)
    text = preset_to_toml(check.patch, check.description or "fuzz")
    back = check_preset_bytes(_PRESET_PATH, text.encode())
    assert back.patch == check.patch, f"the preset does not load back equal: {back.problems}"


@cache
def cloud_model_seeds() -> list[bytes]:
    return [p.read_bytes() for p in sorted((ROOT / "wxsky" / "scene" / "clouds").glob("*.toml"))]


# The thickest layer a model may serve, for the one block an accepted model generates.
_MODEL_LAYER_THICKNESS_M = 1500.0


@target(
    "cloud-model",
    seeds=cloud_model_seeds,
    tokens=_toml_tokens(MODEL_TABLE),
    max_len=8192,
    time_limit_s=2.0,
)
def check_cloud_model(data: bytes) -> None:
    """The cloud-model checker: problems, or a model whose block of clouds is bounded.

    The block is generated (what the daemon does with the model next), within the time
    limit and the process' memory."""
    checked = check_toml_bytes(Path("fuzz.toml"), data, MODEL_TABLE)
    if not checked.ok:
        assert checked.error_message().strip()
        return
    try:
        model = model_from_values(checked.value, "fuzz")
    except ConfigError:
        return
    thickness_m = max(model.min_thickness_m, _MODEL_LAYER_THICKNESS_M)
    # Uncached: no fuzz model may stay in the process-wide block cache.
    clouds = generate_block_clouds(0, 0, 0, model, thickness_m, 1)
    pos = clouds.sprites.centre_m
    # Scud boxes (`under_base`) may hang under the base, no farther than the model allows.
    floor_m = -UNDER_BASE_MAX_M if any(box.under_base for box in model.boxes) else 0.0
    assert pos.size == 0 or bool(((pos[:, 2] >= floor_m) & (pos[:, 2] <= thickness_m)).all()), (
        "sprites outside the layer"
    )


# --- the control channel: a real daemon ---------------------------------------------------------

CONTROL_REPLY_S = 10.0  # a daemon that has not answered and hung up by then is stuck
CONTROL_BATCH = 50  # inputs between status checks
_LOG_TROUBLE = re.compile(r"^\S+ (ERROR|CRITICAL)\b|Traceback \(most recent call last\)", re.M)


@dataclass
class FuzzDaemon:
    proc: subprocess.Popen[bytes]
    socket_path: Path
    log_path: Path
    log_offset: int = 0
    frames_seen: int = 0
    frames_checked_at: float = 0.0

    def log_tail(self, chars: int = 3000) -> str:
        return self.log_path.read_text(errors="replace")[-chars:]

    def new_log(self) -> str:
        with open(self.log_path, "rb") as f:
            f.seek(self.log_offset)
            data = f.read()
        self.log_offset += len(data)
        return data.decode("utf-8", "replace")

    def assert_alive(self) -> None:
        code = self.proc.poll()
        if code is not None:
            raise FatalFailure(
                f"control: the daemon died (exit {code}); its log ends:\n{self.log_tail()}",
                "control: the daemon died",
            )


_DAEMON: list[FuzzDaemon] = []  # the running session's daemon, while one runs

FUZZ_DAEMON_CONFIG = """
[daemon]
tick_hz = 10.0
status_interval_s = 60.0
[camera]
width = 320
height = 180
[scene]
ring_texture_px = 64
shadow_map_px = 64
[output]
shm_name = "{shm_name}"
max_width = 320
max_height = 180
[radar]
layer = true
range_nm = 10.0
size_px = 64
"""


@contextlib.contextmanager
def daemon_session() -> Iterator[FuzzDaemon]:
    """A private `wxsky run` (small frames, 10 Hz) for the control target; killed on the way
    out, whatever happened."""
    with tempfile.TemporaryDirectory(prefix="wxsky-fuzz-") as tmp:
        shm_name = f"wxsky-fuzz-{uuid.uuid4().hex[:10]}"
        config = Path(tmp) / "wxsky.toml"
        config.write_text(FUZZ_DAEMON_CONFIG.format(shm_name=shm_name))
        sock, log_path = Path(tmp) / "wx.sock", Path(tmp) / "daemon.log"
        cmd = [sys.executable, "-m", "wxsky", "run", "--config", str(config)]
        cmd += ["--control", f"unix:{sock}"]
        with open(log_path, "wb") as log:
            proc = subprocess.Popen(
                cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
            )
        daemon = FuzzDaemon(proc, sock, log_path)
        try:
            _wait_started(daemon)
            _DAEMON.append(daemon)
            yield daemon
        finally:
            if daemon in _DAEMON:
                _DAEMON.remove(daemon)
            _stop(proc)
            with contextlib.suppress(FileNotFoundError):
                os.unlink(f"/dev/shm/{shm_name}")


def _wait_started(daemon: FuzzDaemon) -> None:
    from wxsky.host.client import DaemonUnavailable

    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:
        daemon.assert_alive()
        if daemon.socket_path.exists():
            # The socket's file is there from its bind, a moment before it listens: a refused
            # connection then is the daemon still starting (on a busy machine, a while).
            with contextlib.suppress(OSError, ValueError, KeyError, DaemonUnavailable):
                if _status(daemon)["frames_published"] > 0:
                    daemon.new_log()  # start-up lines are not the fuzzer's doing
                    return
        time.sleep(0.1)
    raise RuntimeError(f"the fuzz daemon did not start; its log:\n{daemon.log_tail()}")


def _stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)


def _status(daemon: FuzzDaemon) -> dict[str, Any]:
    from wxsky.host.client import ControlClient

    with ControlClient.connect(f"unix:{daemon.socket_path}", timeout_s=CONTROL_REPLY_S) as c:
        result: dict[str, Any] = c.call("status", timeout_s=CONTROL_REPLY_S)
        return result


def _session_daemon() -> FuzzDaemon:
    assert _DAEMON, "the control target runs only inside its session (daemon_session)"
    return _DAEMON[-1]


def _exchange(path: Path, data: bytes) -> tuple[bytes, bool]:
    """Send `data` on a fresh connection, half-close, read until the daemon hangs up.
    Returns (what came back, whether the daemon reset the connection)."""
    replies = bytearray()
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(CONTROL_REPLY_S)
        s.connect(str(path))
        try:
            s.sendall(data)
            s.shutdown(socket.SHUT_WR)
            while chunk := s.recv(1 << 16):
                replies += chunk
        except (BrokenPipeError, ConnectionResetError):
            return bytes(replies), True
        except TimeoutError:
            raise AssertionError(
                f"the daemon neither answered nor hung up within {CONTROL_REPLY_S:g} s"
            ) from None
    return bytes(replies), False


@cache
def control_seeds() -> list[bytes]:
    from wxsky.output.wire import Notification, Request, Response, encode

    reports = [raw for raw, _, _ in corpus_reports()[:: max(1, len(corpus_reports()) // 24)]]
    presets = [p.stem for p in sorted((ROOT / "wxsky" / "settings" / "presets").glob("*.toml"))]
    calls: list[tuple[str, dict[str, Any]]] = [
        ("status", {}),
        ("scene", {}),
        ("set_camera", {"position_m": [0.0, 0.0, 1500.0], "heading_deg": 90.0, "pitch_deg": 5.0}),
        ("set_camera", {"lat_deg": 47.5, "lon_deg": 8.6, "alt_m": 900.0, "fov_deg": 70.0}),
        ("set_camera", {"alt_m": 3000.0, "roll_deg": 10.0, "width": 320, "height": 180}),
        ("set_aircraft", {"position_m": [100.0, 200.0, 1500.0]}),
        ("set_aircraft", {"position_m": None}),
        ("set_time", {"time_utc": "2026-06-21T18:30:00Z", "rate": 60.0}),
        ("set_time", {"rate": 1.0}),
        ("release", {}),
        ("release", {"source": "cockpit"}),
        ("export_textures", {}),
        ("subscribe", {"topics": ["weather", "target", "scene", "frame"]}),
        ("unsubscribe", {"topics": ["frame"]}),
        ("no_such_command", {"x": 1}),
        ("set_weather", {"visibility_m": 1500.0, "present_weather": ["+TSRA"], "now": True}),
        (
            "set_weather",
            {
                "layers": [
                    {"type": "stratus", "cover_oktas": 6, "base_m": 650.0, "top_m": 900.0},
                    {"type": "cumulus", "cover_oktas": 3, "base_m": 1400.0, "top_m": 2600.0},
                ],
                "wind": [{"alt_m": 10.0, "dir_deg": 240.0, "speed_mps": 8.0, "gust_mps": 15.0}],
            },
        ),
        ("set_weather", {"layers": [], "temperature_c": 3.0, "dewpoint_c": 2.5, "qnh_hpa": 990.0}),
        ("visibility", {}),
        ("visibility", {"runway": "14"}),
        ("visibility", {"east_m": 1500.0, "north_m": -300.0, "height_m": 30.0}),
        (
            "set_weather",
            {
                "fog": {
                    "visibility_m": 150.0,
                    "depth_m": 80.0,
                    "patchy": True,
                    "rvr": [{"runway": "32L", "rvr_m": 550.0}],
                },
                "now": True,
            },
        ),
        ("set_weather", {"fog": {}}),
        ("radar", {}),
        ("radar", {"range_nm": 10.0, "tilt_deg": -15.0, "size_px": 64}),
        ("radar", {"range_nm": 320.0, "tilt_deg": 15.0, "size_px": 1024}),
        *(("apply_preset", {"name": name}) for name in presets),
        *(("apply_metar", {"report": r}) for r in reports[:16]),
        *(
            ("apply_metar", {"report": r, "field_elevation_m": 1200.0, "year": 2025, "month": 7})
            for r in reports[16:]
        ),
    ]
    seeds = [encode(Request(i + 1, method, params)) for i, (method, params) in enumerate(calls)]
    seeds += [
        encode(Notification("set_time", {"rate": 2.0})),
        encode(Response(7, None, {"ok": True})),
        b"".join(seeds[:6]),
        b"".join(seeds[6:12]),
        b"\x94\x00\x01\xa6status\x80" * 3,
    ]
    return seeds


def _control_tokens() -> tuple[bytes, ...]:
    import msgpack

    words: list[Any] = [
        "status",
        "scene",
        "set_camera",
        "set_aircraft",
        "set_time",
        "apply_preset",
        "apply_metar",
        "release",
        "export_textures",
        "set_weather",
        "radar",
        "visibility",
        "fog",
        "rvr",
        "runway",
        "rvr_m",
        "depth_m",
        "patchy",
        "visibility_m",
        "east_m",
        "north_m",
        "height_m",
        "32L",
        "subscribe",
        "unsubscribe",
        "topics",
        "position_m",
        "lat_deg",
        "lon_deg",
        "alt_m",
        "heading_deg",
        "pitch_deg",
        "roll_deg",
        "fov_deg",
        "width",
        "height",
        "time_utc",
        "rate",
        "name",
        "report",
        "field_elevation_m",
        "year",
        "month",
        "source",
        "control",
        "cockpit",
        "weather",
        "target",
        "frame",
        "lightning",
        "radar",
        "range_nm",
        "tilt_deg",
        "size_px",
        "set_weather",
        "visibility_m",
        "layers",
        "wind",
        "present_weather",
        "now",
        "type",
        "cover_oktas",
        "base_m",
        "top_m",
        "cumulonimbus",
        "+TSRA",
        "-TS",
        "VCTS",
        320.0,
        -15.0,
        1024,
        float("nan"),
        float("inf"),
        -1e308,
        2**64 - 1,
        -(2**63),
        0,
        None,
        True,
        [0.0, 0.0, 0.0],
    ]
    tokens = [msgpack.packb(w) for w in words]
    # Message and container headers: request, notification, maps, huge declared lengths.
    tokens += [b"\x94\x00", b"\x93\x02", b"\x94\x01", b"\x80", b"\x81", b"\xde\xff\xff"]
    tokens += [b"\xdd\xff\xff\xff\xff", b"\xdb\x7f\xff\xff\xff", b"\xc4\x10", b"\xd4\x01\x00"]
    return tuple(tokens)


# --- the control channel's framing ------------------------------------------------------------

WIRE_PIECE = 5  # bytes per read in the chunked decode


def _wire_decode(chunks: Iterable[bytes]) -> list[object]:
    """What one connection's decoder makes of a stream read in `chunks`: messages and, for
    each WireError, ("error", recoverable, msgid), continuing as the server does."""
    from wxsky.output.wire import MessageDecoder, WireError

    decoder = MessageDecoder()
    out: list[object] = []
    for chunk in chunks:
        data = chunk
        while True:
            try:
                out += decoder.feed(data)
                break
            except WireError as exc:
                out += exc.decoded
                out.append(("error", exc.recoverable, exc.msgid))
                if not exc.recoverable:
                    return out
                data = b""  # the rest of the stream is still in step
    return out


@target("wire", seeds=control_seeds, tokens=_control_tokens(), max_len=4096)
def check_wire(data: bytes) -> None:
    """The msgpack-RPC decoder: WireError or typed messages; whole = in pieces; re-encodes.

    The same read whole or in 5-byte pieces, each message encoding back to itself."""
    from wxsky.errors import ProtocolError
    from wxsky.output.wire import MSGID_MAX, Notification, Request, Response, encode

    whole = _wire_decode([data])
    pieces = _wire_decode(data[i : i + WIRE_PIECE] for i in range(0, len(data), WIRE_PIECE))
    # repr, not ==: a NaN in params is not equal to itself.
    assert repr(whole) == repr(pieces), "the stream decodes differently when read in pieces"
    for m in whole:
        if isinstance(m, tuple):
            continue
        if isinstance(m, Request | Notification):
            assert isinstance(m.method, str) and isinstance(m.params, dict), repr(m)[:200]
        if isinstance(m, Request):
            assert isinstance(m.msgid, int) and 0 <= m.msgid <= MSGID_MAX, repr(m)[:200]
        if isinstance(m, Response):
            assert m.msgid is None or (isinstance(m.msgid, int) and 0 <= m.msgid <= MSGID_MAX)
            assert m.error is None or isinstance(m.error, str), repr(m)[:200]
        assert isinstance(m, Request | Notification | Response), repr(m)[:200]
        try:
            again = _wire_decode([encode(m)])
        except ProtocolError as exc:
            raise AssertionError(f"a decoded message does not encode: {exc}") from None
        assert repr(again) == repr([m]), "a decoded message does not encode back to itself"


def _control_batch_check() -> None:
    """The daemon still answers status, its weather and target in range, still drawing."""
    daemon = _session_daemon()
    daemon.assert_alive()
    try:
        status = _status(daemon)
    except Exception as exc:
        raise FatalFailure(
            f"control: the daemon does not answer status: {_one_line(exc)}",
            "control: no status",
        ) from exc
    assert_weather_dict(status["weather"], "daemon weather")
    assert_weather_dict(status["target"], "daemon target")
    now = time.monotonic()
    frames = status["frames_published"]
    if daemon.frames_checked_at and now - daemon.frames_checked_at > 5.0:
        # What the daemon was doing, for telling a stall from a starved machine.
        cam = status["camera"]
        assert frames > daemon.frames_seen, (
            f"no frame published in {now - daemon.frames_checked_at:.0f} s "
            f"(fps {status['fps']:.1f}, camera at {cam['position_m']} {cam['width']}x"
            f"{cam['height']}, clock rate {status['clock_rate']}, load "
            f"{os.getloadavg()[0]:.1f})"
        )
    if frames > daemon.frames_seen or not daemon.frames_checked_at:
        daemon.frames_seen, daemon.frames_checked_at = frames, now


@target(
    "control",
    seeds=control_seeds,
    tokens=_control_tokens(),
    max_len=4096,
    time_limit_s=5.0,
    session=daemon_session,
    batch_check=_control_batch_check,
    batch_every=CONTROL_BATCH,
    coverage=False,
)
def check_control(data: bytes) -> None:
    """One connection's whole stream to a real daemon: answered, logged clean, alive.

    The daemon must answer and hang up, with no `internal error` answer and no ERROR or
    traceback in its log, and live on; between batches its weather must stay in range."""
    from wxsky.errors import ProtocolError
    from wxsky.output.wire import MessageDecoder, Response

    daemon = _session_daemon()
    daemon.assert_alive()
    replies, reset = _exchange(daemon.socket_path, data)
    try:
        messages = MessageDecoder().feed(replies)
    except ProtocolError as exc:
        if not reset:  # a reset may cut the last answer short; anything else is the daemon's
            raise AssertionError(f"the daemon's answer is not valid: {exc}") from None
        messages = []
    for m in messages:
        if isinstance(m, Response) and m.error is not None:
            assert not m.error.startswith("internal error"), f"the daemon answered {m.error!r}"
            assert "\n" not in m.error, f"an error answer of two lines: {m.error[:200]!r}"
    trouble = [line for line in daemon.new_log().splitlines() if _LOG_TROUBLE.search(line)]
    assert not trouble, f"the daemon logged: {trouble[0].split(' ', 1)[-1][:300]}"
    daemon.assert_alive()


# --- the channel bus (wxsky/share/messages.py): what a channel decodes from the network ------


def share_seeds() -> list[bytes]:
    """A master's state, tick, pong and health as they go on the bus, for two presets."""
    from wxsky.output.wire import pack_data
    from wxsky.scene.camera import Camera
    from wxsky.settings.presets import load_preset
    from wxsky.share.messages import (
        ClockTick,
        Health,
        SkyState,
        encode_health,
        encode_pong,
        encode_state,
        encode_tick,
    )
    from wxsky.weather.state import WeatherState

    out: list[bytes] = []
    for name in ("fair-cumulus", "thunderstorm"):
        state = WeatherState().apply(load_preset(name))
        drift = tuple((1.5 * i, -2.0) for i in range(len(state.layers)))
        sky = SkyState(
            "default", "0123456789abcdef", 7, 3, state, state, state.time_utc, drift, 1.0
        )
        out.append(pack_data(encode_state(sky)))
    cam = Camera((10.0, -20.0, 1500.0), 90.0, 5.0, -3.0, 60.0, 320, 180)
    tick = ClockTick(
        "default",
        "0123456789abcdef",
        1234.5,
        datetime(2026, 6, 21, tzinfo=UTC),
        1.0,
        7,
        cam,
        (1.0, 2.0, 3.0),
    )
    out.append(pack_data(encode_tick(tick)))
    out.append(pack_data(encode_pong("default", "0123456789abcdef", 99.25)))
    out.append(pack_data(encode_health(Health("default", "left", "channel", 29.5, 12.0, 100))))
    return out


@target("share", seeds=share_seeds, max_len=8192)
def check_share(data: bytes) -> None:
    """A channel's decoders: WireError/ShareError or a message whose values are in range,
    and which encodes and decodes back to itself."""
    from wxsky.output.wire import WireError, pack_data, unpack_data
    from wxsky.share.messages import (
        ShareError,
        decode_health,
        decode_pong,
        decode_state,
        decode_tick,
        encode_health,
        encode_state,
        encode_tick,
        sky_id,
    )

    try:
        value = unpack_data(data)
    except WireError:
        return
    for decoder, encoder in (
        (decode_state, encode_state),
        (decode_tick, encode_tick),
        (decode_health, encode_health),
        (decode_pong, None),
    ):
        try:
            message = decoder(value, "default")  # type: ignore[operator]
        except ShareError as exc:
            assert "\n" not in str(exc), "a share error is not one line"
            continue
        if encoder is None:
            continue
        again = decoder(unpack_data(pack_data(encoder(message))), "default")  # type: ignore[operator]
        assert again == message, "a decoded message does not encode back to itself"
        if decoder is decode_state:
            assert_state_in_range(message.applied, "shared applied weather")
            assert_state_in_range(message.target, "shared target weather")
            assert len(sky_id(message)) == 16


# --- GRIB2 inventories (wxsky/weather/grib_idx.py): the .idx a server publishes ------------

# With the module, not in the check: atheris instruments what is imported while this module is.
from wxsky.errors import GribError  # noqa: E402
from wxsky.weather.grib_idx import MAX_OFFSET_B, parse_idx, wanted_ranges  # noqa: E402

GRIB_FIXTURE = ROOT / "tests" / "data" / "grib" / "gfs.t12z.pgrbf120.2p5deg.grib2"
GRIB_IDX_LINES = 24  # lines per seed: a window of the real inventory
GRIB_IDX_TOKENS = tuple(
    t.encode()
    for t in (
        ":",
        "\n",
        "\r\n",
        ".1:",
        ".2:",
        ":d=2011011012:",
        "UGRD",
        "VGRD",
        "TMP",
        "HGT",
        "PRES",
        "TCDC",
        ":10 mb:",
        ":1000 mb:",
        " mb",
        ":surface:",
        ":2 m above ground:",
        ":low cloud layer:",
        ":120 hour fcst:",
        ":anl:",
        "9007199254740992",
        "99999999999999999",
        "-1",
    )
)


def grib_idx_seeds() -> list[bytes]:
    """Windows of an inventory of the real GFS file (`grib_decode.inventory`, as a server's
    .idx), and a few hand-written lines where the file is absent (a fresh clone)."""
    seeds = [
        b"1:0:d=2011011012:HGT:10 mb:120 hour fcst:\n"
        b"2.1:16299:d=2011011012:UGRD:10 mb:120 hour fcst:\n"
        b"2.2:16299:d=2011011012:VGRD:10 mb:120 hour fcst:\n"
        b"3:30000:d=2011011012:ABSV:10 mb:120 hour fcst:\n",
        b"1:0:d=2024010100:PRES:surface:anl:ENS=hi res ctl\r\n2:9:d=2024010100:TMP:2 m above "
        b"ground:anl:\r\n",
    ]
    if not GRIB_FIXTURE.exists():
        return seeds
    from wxsky.inputs.grib_decode import inventory

    lines = inventory(GRIB_FIXTURE.read_bytes()).encode().splitlines(keepends=True)
    step = max(1, (len(lines) - GRIB_IDX_LINES) // 16)
    seeds += [b"".join(lines[i : i + GRIB_IDX_LINES]) for i in range(0, len(lines), step)]
    return sample(seeds)


def _assert_names_a_line(message: str, name: str, text: str) -> None:
    """An index's error: one line, naming the index and a line it has."""
    assert len(message.splitlines()) == 1, f"not one line: {message[:200]!r}"
    m = re.match(re.escape(name) + r": line (\d+): ", message)
    assert m is not None, f"names no line: {message[:200]!r}"
    assert 1 <= int(m.group(1)) <= text.count("\n") + 1, f"no such line: {message[:200]!r}"


@target("grib-idx", seeds=grib_idx_seeds, tokens=GRIB_IDX_TOKENS, max_len=4096)
def check_grib_idx(data: bytes) -> None:
    """parse_idx: GribError, one line naming the inventory and a line it has; or entries in
    file order, whose wanted_ranges are sorted, apart (neighbours merged), each from a
    message's start, and hold exactly the messages with a wanted field."""
    from wxsky.inputs.grib_decode import IDX_WANTED  # eccodes: only where this target runs

    text = data.decode("utf-8", "replace")
    try:
        entries = parse_idx(text, "fuzz.idx")
    except GribError as exc:
        _assert_names_a_line(str(exc), "fuzz.idx", text)
        return
    offsets = [e.offset_b for e in entries]
    assert offsets == sorted(offsets), "entries out of file order"
    assert all(0 <= o <= MAX_OFFSET_B for o in offsets), "an offset out of range"
    ranges = wanted_ranges(entries, IDX_WANTED)
    for k, (first, last) in enumerate(ranges):
        assert last is not None or k == len(ranges) - 1, f"an open range before the last: {ranges}"
        assert last is None or first <= last, f"an empty range {first}-{last}"
        if k > 0:
            before = ranges[k - 1][1]
            assert before is not None and before + 1 < first, f"ranges not apart: {ranges}"
    pairs = set(IDX_WANTED)
    wanted_at = {
        e.offset_b
        for e in entries
        if (e.var, e.level) in pairs or (e.level.endswith(" mb") and (e.var, "mb") in pairs)
    }
    starts = {first for first, _ in ranges}
    assert starts <= set(offsets), "a range that starts inside a message"
    for offset in set(offsets):
        inside = any(a <= offset and (b is None or offset <= b) for a, b in ranges)
        assert inside == (offset in wanted_at), f"message at {offset}: fetched {inside}"


def grib_ecmwf_index_seeds() -> list[bytes]:
    """Lines of ECMWF open data's index, as its files have them."""
    return [
        b'{"domain": "g", "date": "20240301", "time": "0000", "expver": "0001", "class": "od", '
        b'"type": "fc", "stream": "oper", "step": "6", "levelist": "500", "levtype": "pl", '
        b'"param": "u", "_offset": 0, "_length": 609069}\n'
        b'{"date": "20240301", "time": "0000", "step": "6", "levtype": "sfc", "param": "2t", '
        b'"_offset": 609069, "_length": 500000}\n',
        b'{"levtype": "pl", "levelist": "850", "param": "t", "_offset": 10, "_length": 5}\n',
    ]


@target(
    "grib-ecmwf-index",
    seeds=grib_ecmwf_index_seeds,
    tokens=(b'"_offset": ', b'"_length": ', b'"param": "u"', b'"levtype": "pl"', b"{", b"}"),
    max_len=4096,
)
def check_grib_ecmwf_index(data: bytes) -> None:
    """parse_ecmwf_index: GribError in one line naming a line the index has; or entries in
    file order whose wanted ranges are sorted, apart, and each within a listed message."""
    from wxsky.inputs.grib_decode import IDX_WANTED  # eccodes: only where this target runs
    from wxsky.weather.grib_idx import parse_ecmwf_index

    text = data.decode("utf-8", "replace")
    try:
        entries = parse_ecmwf_index(text, "fuzz.index")
    except GribError as exc:
        _assert_names_a_line(str(exc), "fuzz.index", text)
        return
    offsets = [e.offset_b for e in entries]
    assert offsets == sorted(offsets), "entries out of file order"
    ranges = wanted_ranges(entries, IDX_WANTED)
    for k, (first, last) in enumerate(ranges):
        assert last is not None and first <= last, f"a bad range {first}-{last}"
        if k:
            before = ranges[k - 1][1]
            assert before is not None and before + 1 < first, f"ranges not apart: {ranges}"
        assert any(e.offset_b <= first <= e.offset_b + (e.length_b or 0) - 1 for e in entries), (
            f"range {first}-{last} starts in no message"
        )


# --- GRIB2 messages (wxsky/inputs/grib_decode.py): what eccodes makes of a file -----------


def grib_seeds() -> list[bytes]:
    """The real GFS file's messages one by one (each GRIB2 message says its length in octets
    9-16), as many kinds as it has; nothing where the file is absent (a fresh clone)."""
    if not GRIB_FIXTURE.exists():
        return [b"GRIB\x00\x00\x00\x02" + (16).to_bytes(8, "big")]
    data = GRIB_FIXTURE.read_bytes()
    seeds, at = [], 0
    while at + 16 <= len(data) and data[at : at + 4] == b"GRIB":
        length = int.from_bytes(data[at + 8 : at + 16], "big")
        seeds.append(data[at : at + length])
        at += length
    return sample(seeds)


@target(
    "grib",
    seeds=grib_seeds,
    tokens=(b"GRIB", b"7777", b"\x00\x00\x00\x15\x01", b"\x00\x00\x00\x48\x03"),
    max_len=40_000,
    time_limit_s=2.0,
)
def check_grib(data: bytes) -> None:
    """decode: GribError in one line naming the file; or fields whose grids are ascending,
    finite and the size of their values, at valid times in the clock's range."""
    import numpy as np

    from wxsky.inputs.grib_decode import Window, decode
    from wxsky.weather.state import time_in_range

    for window in (None, Window(21.3, -157.9, 6.0)):
        try:
            fields = decode(data, "fuzz.grib2", window)
        except GribError as exc:
            message = str(exc)
            assert len(message.splitlines()) == 1, f"not one line: {message[:200]!r}"
            assert message.startswith("fuzz.grib2: "), f"names no file: {message[:200]!r}"
            return
        for f in fields:
            g = f.grid
            assert f.values.shape == (len(g.lats_deg), len(g.lons_deg)), "values not the grid"
            for axis in (g.lats_deg, g.lons_deg):
                assert np.all(np.isfinite(axis)) and np.all(np.diff(axis) > 0), "bad axis"
            assert time_in_range(f.valid_utc), f"valid time {f.valid_utc}"


# --- the OSG plugin's .wxsky file (plugins/osg/src/settings.cpp), in its own process ---------

OSG_KIT = ROOT / "plugins" / "osg"
# The parser's keys and values, for the mutators.
_WXSKY_TOKENS = tuple(
    t.encode()
    for t in (
        "control = ",
        "shm = ",
        "frame = ",
        "up_m = ",
        "camera = ",
        "background_bin = ",
        "near_bin = ",
        "near_depth = ",
        "node_mask = ",
        "unix:/tmp/x.sock",
        "tcp:127.0.0.1:4000",
        "geocentric",
        "enu",
        "0x800",
        "true",
        "false",
        "#",
        "\n",
        "=",
        "-1e308",
        "nan",
    )
)


def wxsky_file_seeds() -> list[bytes]:
    """The files plugins/osg/README.md and fgfs-with-wxsky write, and some bad ones."""
    return [
        b"# wxsky over the example terrain\ncontrol = unix:/run/wx.sock\nframe = enu\n",
        b"frame = geocentric\nnode_mask = 0x800\nbackground_bin = 6\nnear_bin = 7\n"
        b"control = tcp:127.0.0.1:7777\nshm = wxsky\n",
        b"up_m = 120.5\ncamera = main\nnear_depth = false\n",
        b"frame = enu\ncolour = blue\n",
        b"control = http://127.0.0.1/\n",
        b"node_mask = -1\n",
        b"",
    ]


class _WxskyFileChecker:
    """plugins/osg's wxsky_osg_settings_check (its sanitizer build where there is one), fed
    the inputs one after another: one answer line each."""

    def __init__(self) -> None:
        build = subprocess.run(
            ["make", "-s", "-C", str(OSG_KIT), "SANITIZE=1"], capture_output=True, text=True
        )
        program = OSG_KIT / "build" / "sanitize" / "wxsky_osg_settings_check"
        if build.returncode != 0 or not program.exists():
            raise FatalFailure(
                f"wxsky-file: the check program did not build: {build.stderr[-500:]}",
                "wxsky-file: no build",
            )
        env = {**os.environ, "ASAN_OPTIONS": "detect_leaks=0:abort_on_error=0:exitcode=99"}
        self.proc = subprocess.Popen(
            [str(program)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env
        )

    def ask(self, data: bytes) -> str:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        try:
            self.proc.stdin.write(len(data).to_bytes(4, "little") + data)
            self.proc.stdin.flush()
        except BrokenPipeError:
            pass
        line = self.proc.stdout.readline()
        if not line:
            code = self.proc.wait()
            raise FatalFailure(
                f"wxsky-file: the parser's process ended (exit {code}) on this input",
                f"wxsky-file: exit {code}",
            )
        return line.decode("ascii", errors="replace").rstrip("\n")

    def close(self) -> None:
        if self.proc.stdin is not None:
            with contextlib.suppress(BrokenPipeError):
                self.proc.stdin.close()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


_WXSKY_CHECKER: list[_WxskyFileChecker] = []


@contextlib.contextmanager
def wxsky_file_session() -> Iterator[None]:
    checker = _WxskyFileChecker()
    _WXSKY_CHECKER.append(checker)
    try:
        yield None
    finally:
        _WXSKY_CHECKER.remove(checker)
        checker.close()


_WXSKY_ERROR = re.compile(r"err (\d+) fuzz\.wxsky:(\d+): [ -~]*")


WEB_TOKENS = (
    b'"id"',
    b'"cmd"',
    b'"params"',
    b'"apply_preset"',
    b'"set_weather"',
    b'"set_time"',
    b'"freeze"',
    b'"view"',
    b'"presets"',
    b'"release"',
    b'"save_preset"',
    b'"layers"',
    b'"visibility_m"',
    b'"width_px"',
    b"NaN",
    b"1e999",
    b"-0",
    b"9007199254740992",
    b"[[[[[[[[[",
    b"\\ud800",
    b"true",
    b"null",
)


def web_message_seeds() -> list[bytes]:
    """The messages the page sends (docs/web.md), one of each command."""
    layer = {"type": "stratus", "cover_oktas": 8, "base_m": 600.0, "top_m": 900.0}
    wind = {"alt_m": 432.0, "dir_deg": 250.0, "speed_mps": 5.0, "gust_mps": 0.0}
    messages = [
        {"id": 1, "cmd": "view", "params": {"width_px": 960}},
        {"id": 2, "cmd": "presets"},
        {"id": 3, "cmd": "apply_preset", "params": {"name": "thunderstorm", "now": True}},
        {"id": 4, "cmd": "release", "params": {"now": False}},
        {"id": 5, "cmd": "save_preset", "params": {"name": "my-sky", "description": "x"}},
        {"id": 6, "cmd": "set_weather", "params": {"layers": [layer], "wind": [wind]}},
        {
            "id": 7,
            "cmd": "set_weather",
            "params": {"visibility_m": 800, "present_weather": ["+RA"]},
        },
        {
            "id": 8,
            "cmd": "set_weather",
            "params": {"fog": {"rvr": [{"runway": "14", "rvr_m": 550}]}},
        },
        {"id": 9, "cmd": "set_time", "params": {"time_utc": "2026-07-01T18:00:00Z", "rate": 2}},
        {"id": 10, "cmd": "freeze", "params": {"frozen": True}},
    ]
    return [json.dumps(m).encode() for m in messages]


@target("web-message", seeds=web_message_seeds, tokens=WEB_TOKENS, max_len=8192)
def check_web_message(data: bytes) -> None:
    """decode_message: a message whose id, command and params are what the page may send
    (nested no deeper than MAX_DEPTH), or MessageError in one line; the answer to either
    is strict JSON."""
    from wxsky.web.messages import (
        COMMANDS,
        MAX_DEPTH,
        MAX_ID,
        MessageError,
        decode_message,
        reply,
        reply_error,
    )

    try:
        msg = decode_message(data)
    except MessageError as exc:
        text = str(exc)
        assert text and len(text.splitlines()) == 1, f"not one line: {text[:200]!r}"
        assert exc.id is None or 0 <= exc.id <= MAX_ID, f"a bad id {exc.id!r}"
        json.loads(reply_error(exc.id, text))
        return
    assert 0 <= msg.id <= MAX_ID and not isinstance(msg.id, bool), f"id {msg.id!r}"
    assert msg.cmd in COMMANDS, f"command {msg.cmd!r}"
    assert isinstance(msg.params, dict), f"params {msg.params!r}"
    depth, stack = 0, [(msg.params, 2)]
    while stack:
        item, d = stack.pop()
        if isinstance(item, dict | list):
            depth = max(depth, d)
            stack.extend((v, d + 1) for v in (item.values() if isinstance(item, dict) else item))
    assert depth <= MAX_DEPTH, f"nested {depth} deep"
    json.loads(reply(msg.id, msg.params), parse_constant=_no_constant)


def _no_constant(name: str) -> None:
    raise AssertionError(f"{name} in an answer: the page's JSON.parse refuses it")


def _osg_available() -> bool:
    probe = subprocess.run(["pkg-config", "--exists", "openscenegraph"], capture_output=True)
    return probe.returncode == 0


if _osg_available():  # the kit builds only where OpenSceneGraph is installed

    @target(
        "wxsky-file",
        seeds=wxsky_file_seeds,
        tokens=_WXSKY_TOKENS,
        max_len=4096,
        session=wxsky_file_session,
        coverage=False,
    )
    def check_wxsky_file(data: bytes) -> None:
        """osgwxsky::parseSettings: settings in range, or one printable line naming the file
        and a line of it that exists; never a crash (under ASan and UBSan)."""
        assert _WXSKY_CHECKER, "the wxsky-file target runs only inside its session"
        answer = _WXSKY_CHECKER[-1].ask(data)
        if answer.startswith("ok "):
            fields = dict(kv.split("=", 1) for kv in answer[3:].split(" "))
            assert fields["frame"] in ("enu", "geocentric"), answer
            assert -1000.0 <= float(fields["up_m"]) <= 100000.0, answer
            bins = [int(b) for b in fields["bins"].split(",")]
            assert all(-1000 <= b <= 1000 for b in bins), answer
            return
        m = _WXSKY_ERROR.fullmatch(answer)
        assert m is not None, f"not one printable error line: {answer[:200]!r}"
        lines = data.count(b"\n") + 1
        assert 1 <= int(m.group(2)) <= lines, f"the error names line {m.group(2)} of {lines}"
