"""Fuzz wxsky's parsers and keep every crashing input as a regression test.

    .venv/bin/python tools/fuzz/fuzz.py TARGET|all [--runs N | --minutes M] [--engine ENGINE]
    .venv/bin/python tools/fuzz/fuzz.py --list
    .venv/bin/python tools/fuzz/fuzz.py TARGET --replay FILE...
    .venv/bin/python tools/fuzz/fuzz.py --attacks [NAME ...] [--json]

The targets are in `tools/fuzz/fuzz_targets.py` (METAR, each feed format and detection, NMEA,
CANaerospace, CIGI 3.3 datagrams, the control channel against a real daemon, config, preset
and cloud-model TOML, and where OpenSceneGraph is installed the OSG plugin's `.wxsky` file,
parsed by its sanitizer build in a process of its own: `wxsky-file`).
Each runs for `--runs` inputs (default 1,000,000) or `--minutes`, whichever ends first when
both are given.

Engines: `atheris` (coverage-guided libFuzzer; wxsky instrumented) runs each target in a child
process, since `atheris.Fuzz()` never returns, with a persistent corpus in
`--work-dir/<target>/corpus` seeded from the real corpora and the regression inputs, and the
target's words as a libFuzzer dictionary. `hypothesis` runs in this process: mutations of the
seeds (bit flips, cuts, repeats, dictionary words, splices of two seeds, numbers swapped) and
random bytes, many examples, no shrinking. `auto` (the default) is atheris where it imports,
hypothesis otherwise; a target whose code runs in another process (`control`) always uses
hypothesis, in this process, which owns its daemon.

Every failing input is saved as `--crash-dir/<target>/crash-<hash>` (default
`tests/data/fuzz/`, the regression corpus `tests/test_fuzz.py` replays), at most two per
distinct cause; libFuzzer's own crash, timeout and out-of-memory artifacts are saved the same
way. Prints inputs run, inputs/s and failures per target; exits 1 when anything failed.

`--attacks` runs the seven attacks of issue 40 instead (tools/soak/attacks.py), each once as a
scripted case against fresh daemons of its own on loopback (NAME ...: only those; `--list`
with it names them): one line per attack with whether the daemon survived, its frames before
and after, its own checks and the counters it read from `status`. A daemon an attack kills is
a failed case, not the end of the run; the daemons' logs of a failed case are kept in
`--work-dir/attacks/<name>/`. Exits 1 when a case failed.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import random
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the child imports wxsky only under atheris' instrumentation
    from hypothesis.strategies import SearchStrategy

    from tools.fuzz.fuzz_targets import FuzzFailure, Target

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run as a script: the checkout, for `tools.*`

DEFAULT_RUNS = 1_000_000
MAX_PER_SIGNATURE = 2  # crash files kept per distinct cause
MAX_SIGNATURES = 25  # distinct causes saved per run (a bug that fires everywhere stops here)
MAX_RESTARTS = 20  # atheris children restarted after a hard crash, timeout or OOM
HANG_S = 60  # libFuzzer -timeout: one input this long is a hang, not a slow decode
RSS_LIMIT_MB = 4096
MALLOC_LIMIT_MB = 2048  # one allocation this large is the input's doing, whatever the RSS
# libFuzzer's and atheris's own tables grow with the inputs run (a config run passed 900 MB
# in 280,000 inputs while the same inputs replayed in this process stay at 42 MB): a fresh
# child every this many inputs keeps the RSS limit about the target. The corpus is on disk.
CHILD_RUNS = 200_000
PROGRESS_S = 15.0
INPUTS_PER_EXAMPLE = 32  # inputs one hypothesis example makes in a fuzz run (1 in the smoke)
_ARTIFACT_KINDS = ("crash-", "timeout-", "oom-", "leak-", "slow-unit-")


# --- what a run saw -----------------------------------------------------------------------------


@dataclass
class RunStats:
    target: str
    engine: str
    inputs: int = 0
    seconds: float = 0.0
    failures: int = 0  # failing inputs, saved or not
    saved: list[str] = field(default_factory=list)  # crash files written
    causes: dict[str, int] = field(default_factory=dict)  # signature -> failing inputs
    stopped: str = ""  # why the run ended early (the target died), else ""

    @property
    def per_s(self) -> float:
        return self.inputs / self.seconds if self.seconds > 0 else 0.0

    def add(self, other: dict[str, Any]) -> None:
        self.inputs += other["inputs"]
        self.seconds += other["seconds"]
        self.failures += other["failures"]
        self.saved += other["saved"]
        for cause, n in other["causes"].items():
            self.causes[cause] = self.causes.get(cause, 0) + n
        self.stopped = self.stopped or other["stopped"]


class CrashRecorder:
    """Saves failing inputs as `crash-<hash>`, at most MAX_PER_SIGNATURE per cause."""

    def __init__(self, crash_dir: Path, stats: RunStats, log: Callable[[str], None]) -> None:
        self.crash_dir = crash_dir
        self.stats = stats
        self.log = log

    def record(self, data: bytes, failure: FuzzFailure) -> None:
        self.stats.failures += 1
        causes = self.stats.causes
        seen = causes.get(failure.signature, 0)
        causes[failure.signature] = seen + 1
        if seen >= MAX_PER_SIGNATURE or (seen == 0 and len(causes) > MAX_SIGNATURES):
            return
        path = self.save(data)
        shown = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
        self.log(f"{self.stats.target}: FAILURE saved as {shown}\n  {failure}")

    def save(self, data: bytes) -> Path:
        self.crash_dir.mkdir(parents=True, exist_ok=True)
        path = self.crash_dir / f"crash-{hashlib.sha256(data).hexdigest()[:16]}"
        if not path.exists():
            path.write_bytes(data)
        if str(path) not in self.stats.saved:
            self.stats.saved.append(str(path))
        return path


@dataclass
class Budget:
    runs: int | None
    seconds: float | None
    started: float = field(default_factory=time.monotonic)

    def done(self, inputs: int) -> bool:
        if self.runs is not None and inputs >= self.runs:
            return True
        return self.seconds is not None and time.monotonic() - self.started >= self.seconds

    def left(self, inputs: int) -> tuple[int | None, float | None]:
        runs = None if self.runs is None else max(0, self.runs - inputs)
        secs = None if self.seconds is None else self.seconds - (time.monotonic() - self.started)
        return runs, secs


class _Stop(Exception):
    """Ends a hypothesis run from inside the test body when the budget is spent."""


class Runner:
    """Runs inputs through a target's check, with its batch check every `batch_every`."""

    def __init__(self, t: Target, stats: RunStats, recorder: CrashRecorder, budget: Budget) -> None:
        self.t = t
        self.stats = stats
        self.recorder = recorder
        self.budget = budget
        self.last_progress = time.monotonic()
        self.started = time.monotonic()
        self.on_progress: Callable[[], None] | None = None

    def one(self, data: bytes) -> None:
        from tools.fuzz.fuzz_targets import FatalFailure, FuzzFailure, run_check

        t, stats = self.t, self.stats
        try:
            run_check(t, data)
        except FuzzFailure as failure:
            self.recorder.record(data, failure)
            if isinstance(failure, FatalFailure):
                stats.stopped = str(failure).splitlines()[0]
        stats.inputs += 1
        if (
            not stats.stopped
            and t.batch_check
            and t.batch_every
            and stats.inputs % t.batch_every == 0
        ):
            self.batch(data)
        now = time.monotonic()
        stats.seconds = now - self.started
        if now - self.last_progress >= PROGRESS_S:
            self.last_progress = now
            rate = f"{stats.inputs:,} inputs, {stats.per_s:,.0f}/s"
            print(f"  {t.name}: {rate}, {stats.failures} failing", flush=True)
            if self.on_progress is not None:
                self.on_progress()

    def batch(self, last: bytes) -> None:
        from tools.fuzz.fuzz_targets import FatalFailure, FuzzFailure, checked_batch

        try:
            checked_batch(self.t)
        except FuzzFailure as failure:
            # Saved with the last input before it: the batch check cannot say which one did it.
            self.recorder.record(last, failure)
            if isinstance(failure, FatalFailure):
                self.stats.stopped = str(failure).splitlines()[0]

    def finished(self) -> bool:
        return bool(self.stats.stopped) or self.budget.done(self.stats.inputs)


# --- mutations (the hypothesis engine) -----------------------------------------------------------

_INTERESTING_BYTES = b"\x00\x01\x7f\x80\xff\n\r\t ,=/$*\"'[]#"
_INTERESTING_NUMBERS = (
    b"0",
    b"-0",
    b"1",
    b"-1",
    b"00",
    b"999",
    b"9999",
    b"99999",
    b"65535",
    b"4294967296",
    b"9223372036854775807",
    b"1e308",
    b"-1e308",
    b"1e-308",
    b"nan",
    b"inf",
    b"-inf",
    b"0.5",
    b"360",
    b"361",
    b"-180",
    b"25",
    b"60",
    b"32",
    b"13",
)


def mutate(
    data: bytes, rng: random.Random, tokens: Sequence[bytes], others: Sequence[bytes], max_len: int
) -> bytes:
    """`data` after a few random edits, at most `max_len` bytes."""
    buf = bytearray(data)
    for _ in range(rng.choice((1, 1, 1, 2, 2, 3, 4, 8))):
        op = rng.randrange(11)
        pos = rng.randrange(len(buf) + 1)
        if op == 0 and buf:  # flip a bit
            i = min(pos, len(buf) - 1)
            buf[i] ^= 1 << rng.randrange(8)
        elif op == 1 and buf:  # a random byte
            buf[min(pos, len(buf) - 1)] = rng.randrange(256)
        elif op == 2:  # insert random bytes
            buf[pos:pos] = rng.randbytes(rng.randint(1, 8))
        elif op == 3 and buf:  # cut a piece
            del buf[pos : pos + rng.randint(1, 16)]
        elif op == 4 and buf:  # repeat a piece
            start = rng.randrange(len(buf))
            piece = buf[start : start + rng.randint(1, 32)]
            buf[pos:pos] = piece * rng.choice((1, 1, 2, 8, 64))
        elif op == 5 and tokens:  # insert a dictionary word
            buf[pos:pos] = rng.choice(tokens)
        elif op == 6 and tokens:  # overwrite with a dictionary word
            word = rng.choice(tokens)
            buf[pos : pos + len(word)] = word
        elif op == 7 and others:  # splice in a piece of another seed
            other = rng.choice(others)
            start = rng.randrange(len(other) + 1)
            buf[pos:pos] = other[start : start + rng.randint(1, 64)]
        elif op == 8:  # swap a run of digits for another number
            digits = [i for i, b in enumerate(buf) if 0x30 <= b <= 0x39]
            if digits:
                i = rng.choice(digits)
                j = i
                while j < len(buf) and 0x30 <= buf[j] <= 0x39:
                    j += 1
                buf[i:j] = rng.choice(_INTERESTING_NUMBERS)
        elif op == 9:  # an interesting byte
            buf[pos:pos] = bytes([rng.choice(_INTERESTING_BYTES)])
        elif op == 10 and buf:  # cut short
            del buf[pos:]
    return bytes(buf[:max_len])


def fuzz_inputs(
    t: Target, seeds: Sequence[bytes], per_example: int = 1
) -> SearchStrategy[list[bytes]]:
    """Hypothesis' inputs for a target, `per_example` at a time: random bytes (1 in 16), or
    a seed mutated, then each next input a mutation of the last one or of another seed.

    Hypothesis chooses the seed and the random stream; the mutations draw from that stream,
    so one example costs one hypothesis draw however many inputs it makes (hypothesis spends
    about a millisecond an example, more than most of the parsers take).
    """
    from hypothesis import strategies as st

    seeds = list(seeds) or [b""]
    tokens = t.tokens
    random_len = min(t.max_len, 512)

    @st.composite
    def inputs(draw: Callable[[SearchStrategy[Any]], Any]) -> list[bytes]:
        if draw(st.integers(0, 15)) == 0:
            first: bytes = draw(st.binary(max_size=random_len))
        else:
            # An index, not sampled_from: that one rechecks its whole list on every draw.
            first = seeds[draw(st.integers(0, len(seeds) - 1))]
        rng = random.Random(draw(st.integers(0, 2**32 - 1)))
        out = [mutate(first, rng, tokens, seeds, t.max_len)]
        while len(out) < per_example:
            base = out[-1] if rng.random() < 0.5 else rng.choice(seeds)
            out.append(mutate(base, rng, tokens, seeds, t.max_len))
        return _Batch(out)

    return inputs()


class _Batch(list[bytes]):
    """The inputs of one example, with a short repr: hypothesis formats every example's
    arguments, and the repr of 32 inputs of up to 16 kB is slow (and warns)."""

    def __repr__(self) -> str:
        sizes = ", ".join(str(len(b)) for b in self[:8])
        return f"<{len(self)} inputs of {sizes}{', ...' if len(self) > 8 else ''} bytes>"


def run_hypothesis(runner: Runner, seed: int, seeds: Sequence[bytes]) -> None:
    """Chunks of hypothesis examples, each chunk its own seed, until the budget is spent."""
    from hypothesis import HealthCheck, Phase, Verbosity, given, settings
    from hypothesis import seed as hypothesis_seed

    strategy = fuzz_inputs(runner.t, seeds, INPUTS_PER_EXAMPLE)
    for s in seeds:  # the seeds themselves first, as libFuzzer does with its corpus
        if runner.finished():
            return
        runner.one(s)
    chunk, i = 200, 0
    while not runner.finished():
        runs_left, _ = runner.budget.left(runner.stats.inputs)
        n = chunk if runs_left is None else max(1, min(chunk, runs_left // INPUTS_PER_EXAMPLE))
        started, before = time.monotonic(), runner.stats.inputs

        @hypothesis_seed(seed * 1_000_003 + i)
        @settings(
            max_examples=n,
            database=None,
            phases=[Phase.generate],
            deadline=None,
            suppress_health_check=list(HealthCheck),
            verbosity=Verbosity.quiet,
            print_blob=False,
        )
        @given(strategy)
        def body(batch: list[bytes]) -> None:
            for data in batch:
                if runner.finished():
                    raise _Stop
                runner.one(data)

        try:
            body()
        except _Stop:
            return
        i += 1
        rate = (runner.stats.inputs - before) / max(1e-3, time.monotonic() - started)
        chunk = int(min(20_000, max(20, rate * 10 / INPUTS_PER_EXAMPLE)))  # about 10 s a chunk


def smoke(t: Target, examples: int, seed: int = 0, max_seeds: int = 300) -> int:
    """A short deterministic run for tests: `max_seeds` of the seeds (spread over them), then
    `examples` mutated inputs; the first failure raises (FuzzFailure). Returns the inputs
    run."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hypothesis_seed

    from tools.fuzz.fuzz_targets import checked_batch, run_check, sample, session

    seeds = t.seeds()
    count = 0
    with session(t):
        for s in sample(seeds, max_seeds):
            run_check(t, s)
            count += 1

        @hypothesis_seed(seed)
        @settings(
            max_examples=examples,
            database=None,
            phases=[Phase.explicit, Phase.generate],
            deadline=None,
            suppress_health_check=list(HealthCheck),
            derandomize=True,
        )
        @given(fuzz_inputs(t, seeds))
        def body(batch: list[bytes]) -> None:
            nonlocal count
            for data in batch:
                run_check(t, data)
                count += 1
                if t.batch_check and t.batch_every and count % t.batch_every == 0:
                    checked_batch(t)

        body()
        if t.batch_check:
            checked_batch(t)
    return count


# --- atheris -------------------------------------------------------------------------------------


def atheris_available() -> bool:
    try:
        import atheris  # noqa: F401
    except ImportError:
        return False
    return True


def _dict_line(word: bytes) -> str:
    text = "".join(chr(b) if 0x20 <= b < 0x7F and b not in b'"\\' else f"\\x{b:02x}" for b in word)
    return f'"{text}"'


def _paths(t: Target, work: Path) -> dict[str, Path]:
    """Where a target's atheris files live under the work directory."""
    tdir = work / t.name
    return {
        "corpus": tdir / "corpus",  # libFuzzer's, kept between runs
        "seeds": tdir / "seeds",  # rewritten from the target's seeds every run
        "artifacts": tdir / "artifacts",
        "dict": tdir / "words.dict",
        "stats": tdir / "child-stats.json",
        "log": tdir / "libfuzzer.log",
    }


def _prepare_atheris(t: Target, work: Path) -> dict[str, Path]:
    paths = _paths(t, work)
    for key in ("corpus", "seeds", "artifacts"):
        paths[key].mkdir(parents=True, exist_ok=True)
    for old in paths["seeds"].iterdir():
        old.unlink()
    for s in t.seeds():
        (paths["seeds"] / hashlib.sha256(s).hexdigest()[:16]).write_bytes(s)
    paths["dict"].write_text("".join(_dict_line(w) + "\n" for w in t.tokens))
    return paths


def run_atheris(t: Target, budget: Budget, stats: RunStats, args: argparse.Namespace) -> None:
    paths = _prepare_atheris(t, args.work_dir)
    crash_dir = args.crash_dir / t.name
    recorder = CrashRecorder(crash_dir, stats, print)
    restarts = children = 0
    while not stats.stopped and not budget.done(stats.inputs):
        runs, secs = budget.left(stats.inputs)
        before = stats.inputs
        cmd = [sys.executable, str(Path(__file__).resolve()), t.name, "--child"]
        cmd += ["--work-dir", str(args.work_dir), "--crash-dir", str(args.crash_dir)]
        cmd += ["--seed", str(args.seed + children)]
        children += 1
        cmd += ["--runs", str(CHILD_RUNS if runs is None else min(runs, CHILD_RUNS))]
        if secs is not None:
            cmd += ["--minutes", str(max(secs, 1.0) / 60.0)]
        paths["stats"].unlink(missing_ok=True)
        with open(paths["log"], "ab") as log:
            proc = subprocess.run(cmd, stderr=log, check=False)
        if paths["stats"].exists():
            stats.add(json.loads(paths["stats"].read_text()))
        for artifact in sorted(paths["artifacts"].iterdir()):
            if artifact.name.startswith(_ARTIFACT_KINDS):
                kind = artifact.name.split("-", 1)[0]
                saved = recorder.save(artifact.read_bytes())
                stats.failures += 1
                stats.causes[f"{t.name}: libFuzzer {kind}"] = (
                    stats.causes.get(f"{t.name}: libFuzzer {kind}", 0) + 1
                )
                print(f"{t.name}: libFuzzer {kind} saved as {saved}; see {paths['log']}")
            artifact.unlink()
        if proc.returncode == 0:
            if stats.inputs == before:
                stats.stopped = "an atheris child ran no input"
            continue  # its share of the inputs is done; the budget says whether more follow
        restarts += 1
        tail = paths["log"].read_text(errors="replace")[-1500:]
        print(f"{t.name}: the atheris child exited {proc.returncode}; log tail:\n{tail}")
        if restarts > MAX_RESTARTS:
            stats.stopped = f"atheris child failed {restarts} times"


def child_main(args: argparse.Namespace) -> int:
    """One target under atheris: the inputs counted here, the budget kept here (the child
    exits itself when it is spent), stats written to a file for the parent."""
    import atheris

    with atheris.instrument_imports(include=["wxsky"]):
        from tools.fuzz import fuzz_targets
    t = fuzz_targets.TARGETS[args.target]
    paths = _paths(t, args.work_dir)
    stats = RunStats(t.name, "atheris")
    recorder = CrashRecorder(args.crash_dir / t.name, stats, lambda m: print(m, flush=True))
    budget = Budget(args.runs, None if args.minutes is None else args.minutes * 60.0)
    runner = Runner(t, stats, recorder, budget)

    def write_stats() -> None:
        tmp = paths["stats"].with_suffix(".tmp")
        tmp.write_text(json.dumps(dataclasses.asdict(stats)))
        tmp.replace(paths["stats"])

    runner.on_progress = write_stats

    def one(data: bytes) -> None:
        runner.one(data)
        if runner.finished():
            write_stats()
            fuzz_targets.cleanup()
            sys.stdout.flush()
            os._exit(0)

    argv = [sys.argv[0], str(paths["corpus"]), str(paths["seeds"])]
    if (args.crash_dir / t.name).is_dir():
        argv.append(str(args.crash_dir / t.name))
    argv += [
        f"-max_len={t.max_len}",
        f"-timeout={HANG_S}",
        f"-rss_limit_mb={RSS_LIMIT_MB}",
        f"-malloc_limit_mb={MALLOC_LIMIT_MB}",
        f"-seed={args.seed}",
        f"-artifact_prefix={paths['artifacts']}/",
        "-print_final_stats=1",
    ]
    if t.tokens:
        argv.append(f"-dict={paths['dict']}")
    write_stats()
    atheris.Setup(argv, one)
    atheris.Fuzz()
    return 0  # not reached: Fuzz() exits the process


# --- the command ---------------------------------------------------------------------------------


def run_target(t: Target, args: argparse.Namespace) -> RunStats:
    from tools.fuzz.fuzz_targets import session

    engine = args.engine
    if engine == "auto":
        engine = "atheris" if atheris_available() else "hypothesis"
    if engine == "atheris" and not t.coverage:
        print(f"{t.name}: its code runs in another process; hypothesis, in this one")
        engine = "hypothesis"
    if engine == "atheris" and not atheris_available():
        raise SystemExit(
            "fuzz: atheris is not installed (pip install atheris); use --engine hypothesis"
        )
    budget = Budget(args.runs, None if args.minutes is None else args.minutes * 60.0)
    stats = RunStats(t.name, engine)
    print(f"{t.name}: {engine}, {_budget_text(args)}", flush=True)
    if engine == "atheris":
        run_atheris(t, budget, stats, args)
    else:
        recorder = CrashRecorder(args.crash_dir / t.name, stats, print)
        runner = Runner(t, stats, recorder, budget)
        with session(t):
            run_hypothesis(runner, args.seed, t.seeds())
            if t.batch_check and not stats.stopped:
                runner.batch(b"")
        stats.seconds = time.monotonic() - runner.started
    return stats


def _budget_text(args: argparse.Namespace) -> str:
    parts = []
    if args.runs is not None:
        parts.append(f"{args.runs:,} inputs")
    if args.minutes is not None:
        parts.append(f"{args.minutes:g} min")
    return " or ".join(parts)


def replay(t: Target, files: Sequence[Path]) -> int:
    from tools.fuzz.fuzz_targets import FuzzFailure, run_check, session

    failed = 0
    with session(t):
        for path in files:
            try:
                run_check(t, path.read_bytes())
                print(f"ok      {path}")
            except FuzzFailure as failure:
                failed += 1
                print(f"FAILED  {path}\n  {failure}")
    return 1 if failed else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("target", nargs="?", help="a target name, or 'all'")
    p.add_argument(
        "--runs", type=int, help=f"inputs per target (default {DEFAULT_RUNS:,} without --minutes)"
    )
    p.add_argument("--minutes", type=float, help="minutes per target")
    p.add_argument("--engine", choices=("auto", "atheris", "hypothesis"), default="auto")
    p.add_argument("--work-dir", type=Path, default=ROOT / ".fuzz", help="atheris corpora and logs")
    p.add_argument("--crash-dir", type=Path, default=ROOT / "tests" / "data" / "fuzz")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--list", action="store_true", help="list the targets")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("--replay", type=Path, nargs="+", metavar="FILE", help="run these inputs once")
    p.add_argument(
        "--attacks",
        action="store_true",
        help="run issue 40's attacks against real daemons, each once (target: their names)",
    )
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args, extra = p.parse_known_args()
    if args.attacks:
        return attacks_main(p, args, extra)
    if extra:
        p.error(f"unrecognized arguments: {' '.join(extra)}")
    if args.runs is None and args.minutes is None:
        args.runs = DEFAULT_RUNS
    args.work_dir, args.crash_dir = args.work_dir.resolve(), args.crash_dir.resolve()
    if args.child:
        return child_main(args)

    from tools.fuzz.fuzz_targets import TARGETS

    if args.list:
        for name, t in TARGETS.items():
            doc = (t.check.__doc__ or "").strip().splitlines() or [""]
            print(f"{name:16s} {doc[0]}")
        return 0
    if args.target is None:
        p.error("give a target (or 'all'); --list lists them")
    if args.target != "all" and args.target not in TARGETS:
        p.error(f"unknown target {args.target!r} (known: {', '.join(TARGETS)}, all)")
    if args.replay:
        if args.target == "all":
            p.error("--replay takes one target")
        return replay(TARGETS[args.target], args.replay)
    names = list(TARGETS) if args.target == "all" else [args.target]
    results = [run_target(TARGETS[name], args) for name in names]
    if args.json:
        print(json.dumps([dataclasses.asdict(r) | {"per_s": r.per_s} for r in results], indent=2))
    else:
        head = f"{'target':16s} {'engine':10s} {'inputs':>12s} {'inputs/s':>10s} {'failing':>8s}"
        print(f"\n{head}  saved")
        for r in results:
            print(
                f"{r.target:16s} {r.engine:10s} {r.inputs:12,d} {r.per_s:10,.0f} {r.failures:8d}  "
                f"{len(r.saved)}{'  stopped: ' + r.stopped if r.stopped else ''}"
            )
            for cause, n in sorted(r.causes.items(), key=lambda kv: -kv[1]):
                print(f"    {n:8d} x {cause}")
    return 1 if any(r.failures for r in results) else 0


def attacks_main(p: argparse.ArgumentParser, args: argparse.Namespace, extra: list[str]) -> int:
    """`--attacks [NAME ...]`: each attack once against its own daemons."""
    import logging
    import tempfile

    from tools.soak.attacks import ATTACKS, run_all, summary

    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(name)s: %(message)s")
    if args.list:
        for name, (fn, _, _) in ATTACKS.items():
            print(f"{name:22s} {(fn.__doc__ or '').strip().splitlines()[0]}")
        return 0
    names = [n for n in [args.target, *extra] if n not in (None, "all")] or list(ATTACKS)
    unknown = [n for n in names if n not in ATTACKS]
    if unknown:
        p.error(f"unknown attack {', '.join(unknown)} (known: {', '.join(ATTACKS)})")
    keep = args.work_dir / "attacks"  # the daemons' logs of the failed cases
    with tempfile.TemporaryDirectory(prefix="wxsky-attacks-") as tmp:
        results = run_all(names, Path(tmp), lambda line: print(line, flush=True), keep)
    s = summary(results)
    failed = ", ".join(s["failed"]) or "none"
    print(f"attacks: {s['survived']} of {s['ran']} survived; failed: {failed}")
    if args.json:
        print(json.dumps([r.as_dict() for r in results], indent=1, default=str))
    return 1 if s["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
