"""Benchmark wxsky's METAR decoder against python-metar (strict) on the real corpora.

    .venv/bin/python tools/bench/bench_metar.py [--rounds 7] [--json] [--data-dir tests/data/metar]

Loads every report from the gzip fixtures (AWC cache CSVs and the NOAA cycle file), keeps one
copy of each distinct text with the year and month its own feed timestamp gives, and decodes
all of them with `wxsky.weather.metar.decode` and with python-metar
`Metar(code, month=, year=, strict=True)` in the same process, round after round, the order of
the two alternating so neither always runs on a warm cache. Prints reports/s (median and range
over the rounds) for each, their ratio, and the failure rates: ours partial, python-metar's
`ParserError`s and any other exception either raises; then the same rates file by file.
Needs `pip install metar==2.0.2` (the `dev` extra).
"""

from __future__ import annotations

import argparse
import csv
import gc
import gzip
import json
import platform
import re
import statistics
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.weather.metar import decode  # noqa: E402 - after the checkout is on the path

Report = tuple[str, int, int]  # text, year, month
_CYCLE_TIMESTAMP = re.compile(r"(\d{4})/(\d\d)/\d\d \d\d:\d\d")
# The legacy CSV's raw_text is unquoted; the 43 decoded columns are counted from the right.
_CSV_COLUMNS = 44


def load_corpus(data_dir: Path) -> dict[str, list[Report]]:
    """The distinct reports of each *.gz file, in file order."""
    corpus: dict[str, list[Report]] = {}
    for path in sorted(data_dir.glob("*.gz")):
        text = gzip.decompress(path.read_bytes()).decode("latin-1").replace("\r", "")
        seen: dict[str, Report] = {}
        for report, year, month in _reports(text):
            report = report.strip()
            if report and report not in seen:
                seen[report] = (report, year, month)
        corpus[path.name] = list(seen.values())
    return corpus


def distinct(corpus: dict[str, list[Report]]) -> list[Report]:
    """Every distinct report text once, with the year and month of its first appearance."""
    seen: dict[str, Report] = {}
    for reports in corpus.values():
        for report in reports:
            seen.setdefault(report[0], report)
    return list(seen.values())


def _reports(text: str) -> list[Report]:
    lines = text.split("\n")
    if not any(line.startswith("raw_text,") for line in lines):
        # NOAA cycle file: a timestamp line, then the report it dates.
        return [
            (lines[i + 1], int(m[1]), int(m[2]))
            for i, line in enumerate(lines[:-1])
            if (m := _CYCLE_TIMESTAMP.fullmatch(line))
        ]
    lines = [line for line in lines if line]
    header = next(i for i, line in enumerate(lines) if line.startswith("raw_text,"))
    out = []
    for row in csv.reader(lines[header + 1 :]):
        if len(row) > _CSV_COLUMNS:
            row = [",".join(row[: len(row) - 43]), *row[len(row) - 43 :]]
        observed = row[2]  # observation_time, ISO
        out.append((row[0], int(observed[:4]), int(observed[5:7])))
    return out


def _run_ours(reports: list[Report]) -> dict[str, int]:
    partial = 0
    for text, year, month in reports:
        partial += decode(text, year=year, month=month).partial
    return {"partial": partial}


def _python_metar_runner() -> Callable[[list[Report]], dict[str, int]]:
    from metar.Metar import Metar, ParserError

    def run(reports: list[Report]) -> dict[str, int]:
        parser_errors = other = 0
        for text, year, month in reports:
            try:
                Metar(text, month=month, year=year, strict=True)
            except ParserError:
                parser_errors += 1
            except Exception:  # the library's own crashes are part of the comparison
                other += 1
        return {"parser_error": parser_errors, "other_exception": other}

    return run


def _timed(
    run: Callable[[list[Report]], dict[str, int]], reports: list[Report]
) -> tuple[float, dict[str, int]]:
    gc.collect()
    start = time.perf_counter()
    counts = run(reports)
    return len(reports) / (time.perf_counter() - start), counts


def bench(reports: list[Report], rounds: int) -> dict[str, Any]:
    runners = {"wxsky": _run_ours, "python-metar strict": _python_metar_runner()}
    rates: dict[str, list[float]] = {name: [] for name in runners}
    counts: dict[str, dict[str, int]] = {}
    names = list(runners)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # python-metar warns per unparsed group
        for r in range(rounds):
            for name in names if r % 2 == 0 else reversed(names):
                rate, counts[name] = _timed(runners[name], reports)
                rates[name].append(rate)
    result: dict[str, Any] = {"reports": len(reports), "rounds": rounds, "decoders": {}}
    for name in names:
        result["decoders"][name] = {
            "reports_per_s_median": statistics.median(rates[name]),
            "reports_per_s_min": min(rates[name]),
            "reports_per_s_max": max(rates[name]),
            **{k: v for k, v in counts[name].items()},
            **{f"{k}_rate": v / len(reports) for k, v in counts[name].items()},
        }
    ours, theirs = (result["decoders"][n]["reports_per_s_median"] for n in names)
    result["ratio_wxsky_over_python_metar"] = ours / theirs
    result["python"] = platform.python_version()
    result["machine"] = platform.machine()
    return result


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--data-dir", type=Path, default=ROOT / "tests" / "data" / "metar")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    args = p.parse_args()
    try:
        _python_metar_runner()
    except ImportError:
        print("bench_metar: python-metar is missing: pip install metar==2.0.2", file=sys.stderr)
        return 2
    corpus = load_corpus(args.data_dir)
    reports = distinct(corpus)
    if not reports:
        print(f"bench_metar: no *.gz reports under {args.data_dir}", file=sys.stderr)
        return 2
    result = bench(reports, max(1, args.rounds))
    ours, theirs = _run_ours, _python_metar_runner()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result["per_file"] = {
            name: {"reports": len(file_reports), **ours(file_reports), **theirs(file_reports)}
            for name, file_reports in corpus.items()
        }
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"{result['reports']} distinct reports, {result['rounds']} rounds, ", end="")
    print(f"Python {result['python']}")
    for name, d in result["decoders"].items():
        failures = ", ".join(
            f"{k} {v} ({d[k + '_rate']:.2%})" for k, v in d.items() if isinstance(v, int)
        )
        print(
            f"  {name:20s} {d['reports_per_s_median']:9,.0f} reports/s median "
            f"({d['reports_per_s_min']:,.0f}..{d['reports_per_s_max']:,.0f}); {failures}"
        )
    print(f"  ratio wxsky / python-metar: {result['ratio_wxsky_over_python_metar']:.2f}")
    print("per file (distinct reports in the file): wxsky partial / python-metar ParserError")
    for name, f in result["per_file"].items():
        n = f["reports"]
        print(
            f"  {name:50s} {n:5d}  {f['partial']:4d} ({f['partial'] / n:6.2%})"
            f"  {f['parser_error']:4d} ({f['parser_error'] / n:6.2%})"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
