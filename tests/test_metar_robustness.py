"""The METAR decoder never raises on any text, and these tests would notice if it did.

Each input stream below (prefixes, suffixes and mutations of real reports, garbage, random
bytes, out-of-range values, impossible and rolled-over times, every token prefix of every corpus
report, every truncation of every corpus group) must decode to a sound result. That alone would
also pass if the decoder swallowed its own exceptions. It does not: a defect propagates as
MetarInternalError. `test_a_fault_in_any_decoder_step_fails_the_robustness_tests` injects a
RuntimeError into each group handler, each other step of the decoder and each value function in
turn, and shows that one of the streams stops on it.
"""

from __future__ import annotations

import inspect
import random
import re
from collections.abc import Callable, Iterable, Iterator
from datetime import UTC, datetime

import pytest
from metar_helpers import (
    COMPOSED_REPORTS,
    REAL_REPORTS,
    assert_consistent,
    assert_sound,
    corpus_reports,
)

from wxsky.errors import WxskyError
from wxsky.weather import metar as metar_module
from wxsky.weather import metar_groups
from wxsky.weather.metar import Metar, MetarInternalError, decode

# The streams date undated reports against a fixed "now", so that they are the same every run.
NOW = datetime(2026, 12, 1, 0, 10, tzinfo=UTC)
REPORTS = REAL_REPORTS + COMPOSED_REPORTS
Input = tuple[str, int | None, int | None]  # text, year, month (None: dated against NOW)


def dec(text: str, year: int | None = 2025, month: int | None = 7) -> Metar:
    return decode(text, year=year, month=month, now_utc=NOW)


def _july(texts: Iterable[str]) -> Iterator[Input]:
    for text in dict.fromkeys(texts):
        yield text, 2025, 7


# --- input streams ----------------------------------------------------------------------------


def real_report_prefixes() -> Iterator[Input]:
    return _july(r[:end] for r in REPORTS for end in range(len(r) + 1))


def real_report_suffixes() -> Iterator[Input]:
    return _july(r[start:] for r in REPORTS for start in range(len(r) + 1))


def undated_real_reports() -> Iterator[Input]:
    """Every token prefix, without a year and month: dated by the latest-not-after-now rule."""
    for r in REPORTS:
        words = r.split()
        for end in range(len(words) + 1):
            yield " ".join(words[:end]), None, None


GARBAGE = [
    "",
    "   \n\t ",
    "=",
    "METAR",
    "SPECI COR AUTO",
    "\x00" * 50,
    "KXYZ 261550Z 27010KT 10SM CLR 20°/10",
    "ＫＸＹＺ ２６１５５０Ｚ",  # full-width letters and digits
    "KXYZ ٢٦١٥٥٠Z 27010KT",  # Arabic-Indic digits: not a time group
    "KXYZ 261550Z \x0127010KT",
    "KXYZ 261550Z " + "9" * 10_000,
    "KXYZ 261550Z " + "FEW030 " * 5_000,
    "\ud800 lone surrogate",
    "KXYZ 261550Z 1 ",
    "KXYZ 261550Z 1/0SM 0/0SM 1 1/0SM QFE",
    "KXYZ 261550Z WS",
    "KXYZ 261550Z 27010KT WS ALL",
    "KXYZ 261550Z CB TCU ///CB CB",
    "KXYZ 261550Z 9999 9999 9999 0000 P9999 M0000",
    "KXYZ 261550Z Q1013 A2992 Q1013 A3100 Q////",
    "KXYZ 261550Z RMK",
    "KXYZ 261550Z RMK T",
    "KXYZ 261550Z 20/10 RMK T1999 T01990999 T9999",
    "KXYZ 999999Z 99999KT",
    "KXYZ KXYZ KXYZ 261550Z",
    "METAR METAR SPECI KXYZ 261550Z METAR KXYZ 261550Z",
]


def garbage() -> Iterator[Input]:
    return _july(GARBAGE)


OUT_OF_RANGE_GROUPS = [
    "270300KT",
    "090140MPS",
    "27010G260KT",
    "37010KT",
    "99999G999KT",
    "370V010",
    "75/10",
    "M95/M05",
    "10/M75",
    "99/99",
    "Q0800",
    "Q1200",
    "Q0000",
    "A3500",
    "A0000",
    "FEW-10",
    "BKN-999",
    "999SM",
    "99/1SM",
    "999KM",
    "270250KT",
    "70/M70",
    "Q1100",
    "Q0850",
]


def out_of_range_values() -> Iterator[Input]:
    for group in OUT_OF_RANGE_GROUPS:
        yield f"KXYZ 261550Z {group}", 2025, 7
        yield f"KXYZ 261550Z 27010KT 9999 {group} FEW030 20/10 Q1015", 2025, 7


TIME_DAYS = (0, 1, 28, 29, 30, 31, 32, 99)
TIME_HOURS = (0, 23, 24, 25, 99)
TIME_MINUTES = (0, 59, 60, 61, 99)
TIME_MONTHS = (
    (2025, 7),
    (2025, 6),
    (2025, 2),
    (2024, 2),
    (2025, 12),
    (9999, 12),
    (1, 1),
    (2025, 13),
    (None, None),
    (2026, None),
    (2030, None),
    (None, 2),
    (None, 4),
)
# The usual header (one regex), a time group without Z and flags around the station (the
# token-by-token path), and a report without a station.
TIME_FORMS = (
    "KXYZ {}Z 27010KT 9999 FEW030 20/10 Q1015",
    "KXYZ {} 27010KT",
    "METAR COR KXYZ AUTO {}Z NIL",
    "{}Z 9999",
)


def time_groups() -> Iterator[Input]:
    """Every kind of impossible and rolled-over time, in every kind of month."""
    for day in TIME_DAYS:
        for hour in TIME_HOURS:
            for minute in TIME_MINUTES:
                for form in TIME_FORMS:
                    text = form.format(f"{day:02d}{hour:02d}{minute:02d}")
                    for year, month in TIME_MONTHS:
                        yield text, year, month


def random_bytes() -> Iterator[Input]:
    rng = random.Random(1234)
    return _july(rng.randbytes(rng.randint(0, 80)).decode("latin-1") for _ in range(500))


def token_soup() -> Iterator[Input]:
    rng = random.Random(99)
    alphabet = "0123456789/ MPSKTVRBGCLROFEWSNQAXZ+-=."
    words = "METAR SPECI KXYZ 261550Z AUTO COR RMK NOSIG TEMPO CAVOK 9999 SM KT VV NIL QFE WS"
    tokens = words.split(" ")
    for _ in range(3000):
        parts = [
            rng.choice(tokens)
            if rng.random() < 0.3
            else "".join(rng.choice(alphabet) for _ in range(rng.randint(1, 9)))
            for _ in range(rng.randint(0, 12))
        ]
        if rng.random() < 0.5:
            parts[:0] = ["KXYZ", "261550Z"]
        yield " ".join(parts), 2025, 7


def mutated_real_reports() -> Iterator[Input]:
    rng = random.Random(7)
    alphabet = "0123456789/ MPSKTVRBGCLROFEWSNQA"
    for _ in range(3000):
        chars = list(rng.choice(REPORTS))
        for _ in range(rng.randint(1, 4)):
            pos = rng.randrange(len(chars))
            action = rng.random()
            if action < 0.4:
                chars[pos] = rng.choice(alphabet)
            elif action < 0.7:
                del chars[pos]
            else:
                chars.insert(pos, rng.choice(alphabet))
        yield "".join(chars), 2025, 7


def corpus_token_prefixes() -> Iterator[Input]:
    """Every token prefix of every distinct report of every corpus (about 160,000)."""
    for raw, (year, month) in corpus_reports().items():
        words = raw.split()
        for end in range(1, len(words) + 1):
            yield " ".join(words[:end]), year, month


def corpus_truncated_groups() -> Iterator[Input]:
    """Every character prefix of every distinct corpus token, as a body group and in the time
    group's place: truncation inside a group (the prefix streams cut only between groups, or
    inside the last group of a few reports)."""
    cuts = sorted(
        {t[:end] for raw in corpus_reports() for t in raw.split() for end in range(len(t))}
    )
    for cut in cuts:
        yield f"KXYZ 261550Z 27010KT {cut}", 2025, 7
        yield f"KXYZ {cut} 9999", 2025, 7


def corpus_character_prefixes() -> Iterator[Input]:
    """Every character prefix of one corpus report in 80."""
    for raw, (year, month) in sorted(corpus_reports().items())[::80]:
        for end in range(len(raw) + 1):
            yield raw[:end], year, month


# Cheap streams first: the fault test below stops at the first one that notices.
STREAMS: dict[str, tuple[Callable[[], Iterable[Input]], Callable[[Metar], None]]] = {
    "garbage": (garbage, assert_sound),
    "out-of-range values": (out_of_range_values, assert_sound),
    "real report prefixes": (real_report_prefixes, assert_sound),
    "real report suffixes": (real_report_suffixes, assert_sound),
    "undated real reports": (undated_real_reports, assert_sound),
    "time groups": (time_groups, assert_sound),
    "random bytes": (random_bytes, assert_sound),
    "token soup": (token_soup, assert_sound),
    "mutated real reports": (mutated_real_reports, assert_sound),
    "corpus character prefixes": (corpus_character_prefixes, assert_sound),
    "corpus truncated groups": (corpus_truncated_groups, assert_consistent),
    "corpus token prefixes": (corpus_token_prefixes, assert_consistent),
}


def run_stream(name: str) -> int:
    """Decodes every input of a stream and checks each result; the number of inputs."""
    make, check = STREAMS[name]
    count = 0
    for text, year, month in make():
        r = dec(text, year, month)
        try:
            check(r)
            if year is None and month is None:
                assert r.time_utc is None or r.time_utc <= NOW  # never in the future
        except AssertionError as exc:
            exc.add_note(f"{name}: {text[:200]!r} (year {year}, month {month})")
            raise
        count += 1
    return count


@pytest.mark.parametrize("stream", STREAMS)
def test_never_raises_and_every_result_is_sound(stream: str) -> None:
    assert run_stream(stream) > 0


def test_huge_garbage_lists_a_bounded_number_of_errors() -> None:
    r = dec("KXYZ 261550Z " + " ".join(["X?"] * 5000))
    assert len(r.errors) <= 41 and r.errors[-1] == "more errors not listed"


def test_text_that_is_no_string_is_an_error_line() -> None:
    r = decode(b"KXYZ 261550Z 27010KT", year=2025, month=7)  # type: ignore[arg-type]
    assert r.errors == ("report is a bytes, not text",) and r.partial


def test_a_year_or_month_that_is_no_int_is_the_callers_bug() -> None:
    with pytest.raises(TypeError, match="year and month"):
        decode("KXYZ 261550Z 27010KT", year="2025", month=7)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="year and month"):
        decode("KXYZ 261550Z 27010KT", year=2025, month=7.0)  # type: ignore[arg-type]


# --- the robustness tests can fail ------------------------------------------------------------

HANDLER_TABLES: dict[str, dict[str, Callable[..., int]]] = {
    "fixed": metar_module._FIXED_HANDLERS,
    "match": metar_module._MATCH_HANDLERS,
}
_HANDLER_FUNCTIONS = {f for table in HANDLER_TABLES.values() for f in table.values()}
# Every other method of the decoder that decoding calls.
DECODER_STEPS = sorted(
    name
    for name, member in vars(metar_module._Decoder).items()
    if inspect.isfunction(member)
    and member not in _HANDLER_FUNCTIONS
    and name not in ("__init__", "run")
)
# Every value function of metar_groups that the decoder calls, read from its source, so a new
# one is covered without being listed here.
VALUE_FUNCTIONS = sorted(set(re.findall(r"\bg\.([a-z_]+)\(", inspect.getsource(metar_module))))
MODULE_HELPERS = ["_group_message", "_year_month"]

FAULT_TARGETS = [
    *(f"handler {table}:{kind}" for table, handlers in HANDLER_TABLES.items() for kind in handlers),
    *(f"decoder {name}" for name in DECODER_STEPS),
    *(f"groups {name}" for name in VALUE_FUNCTIONS),
    *(f"metar {name}" for name in MODULE_HELPERS),
]


def inject_fault(monkeypatch: pytest.MonkeyPatch, target: str) -> None:
    """Makes one step of the decoder raise RuntimeError, as a bug in it would."""

    def fault(*args: object, **kwargs: object) -> int:
        raise RuntimeError(f"injected fault in {target}")

    what, name = target.split(" ")
    if what == "handler":
        table, kind = name.split(":")
        monkeypatch.setitem(HANDLER_TABLES[table], kind, fault)
    elif what == "decoder":
        monkeypatch.setattr(metar_module._Decoder, name, fault)
    elif what == "groups":
        monkeypatch.setattr(metar_groups, name, fault)
    else:
        monkeypatch.setattr(metar_module, name, fault)


def test_the_fault_targets_cover_the_decoder() -> None:
    kinds = {kind for table in HANDLER_TABLES.values() for kind in table}
    assert kinds >= {"sky", "wind", "temperatures", "qnh", "cavok", "nil", "trend", "remarks"}
    assert len(FAULT_TARGETS) == len(set(FAULT_TARGETS)) > 60
    assert {"_common_header", "_header", "_time", "_refine_temperatures"} <= set(DECODER_STEPS)
    assert {"wind", "sky_group", "celsius", "parse_time", "latest_time"} <= set(VALUE_FUNCTIONS)


@pytest.mark.parametrize("target", FAULT_TARGETS)
def test_a_fault_in_any_decoder_step_fails_the_robustness_tests(
    monkeypatch: pytest.MonkeyPatch, target: str
) -> None:
    inject_fault(monkeypatch, target)
    for stream in STREAMS:
        try:
            run_stream(stream)
        except MetarInternalError as exc:
            # The stream stopped on the injected fault itself, reported as a defect.
            assert str(exc.__cause__) == f"injected fault in {target}", exc
            assert "METAR decoder defect" in str(exc) and "\n" not in str(exc)
            return
    pytest.fail(f"no robustness stream noticed a fault in {target}")


def test_a_decoder_defect_is_no_user_error() -> None:
    # The command line and the feed input treat WxskyError and ValueError as bad input.
    assert not issubclass(MetarInternalError, WxskyError | ValueError)


def test_a_defect_names_the_group_and_the_report(monkeypatch: pytest.MonkeyPatch) -> None:
    inject_fault(monkeypatch, "handler match:sky")
    with pytest.raises(MetarInternalError) as err:
        dec("KXYZ 261550Z 27010KT 9999 FEW030 20/10 Q1015")
    assert str(err.value) == (
        "METAR decoder defect: the sky handler failed on group 5 'FEW030' (RuntimeError: "
        "injected fault in handler match:sky) of 'KXYZ 261550Z 27010KT 9999 FEW030 20/10 Q1015'"
    )
    assert dec("KXYZ 261550Z 27010KT 9999 20/10 Q1015").errors == ()  # no cloud group


def test_a_deliberate_rejection_stays_an_error_line(monkeypatch: pytest.MonkeyPatch) -> None:
    def reject(*args: object) -> None:
        raise metar_groups.GroupValueError("rejected on purpose")

    monkeypatch.setattr(metar_groups, "wind", reject)
    r = dec("KXYZ 261550Z 27010KT 9999")
    assert r.errors == ("group 3 '27010KT': rejected on purpose; group skipped",)
    assert r.wind is None and r.visibility_m == 10_000.0


def test_a_plain_value_error_is_a_defect_not_a_rejection(monkeypatch: pytest.MonkeyPatch) -> None:
    # GroupValueError is a ValueError; any other ValueError (int("x") in a handler) is a bug.
    def buggy(*args: object) -> None:
        int("x")

    monkeypatch.setattr(metar_groups, "wind", buggy)
    with pytest.raises(MetarInternalError, match="the wind handler failed") as err:
        dec("KXYZ 261550Z 27010KT 9999")
    assert type(err.value.__cause__) is ValueError
