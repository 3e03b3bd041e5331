"""The fuzz harnesses (tools/fuzz/fuzz_targets.py, tools/fuzz/fuzz.py): every input a fuzz run saved
(tests/data/fuzz/<target>/) replays clean, every target survives a short deterministic smoke,
and the harness itself fails on a broken parser, so it cannot pass everything by accident.

The long runs are `tools/fuzz/fuzz.py all` (see its docstring); these are the CI smoke.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from tool_loader import load_tool

from wxsky.weather.cockpit import CockpitUpdate
from wxsky.weather.state import Source, WeatherPatch

targets = load_tool("fuzz/fuzz_targets")
fuzz = load_tool("fuzz/fuzz")

ROOT = Path(__file__).resolve().parents[1]
TARGETS = targets.TARGETS
REGRESSION = sorted(p for p in targets.REGRESSION_DIR.glob("*/*") if p.is_file())
PURE = [name for name, t in TARGETS.items() if t.session is None]
WITH_SESSION = [name for name, t in TARGETS.items() if t.session is not None]
SMOKE_EXAMPLES = 200
SESSION_SMOKE_EXAMPLES = 60  # each a connection to a real daemon


def _rel(path: Path) -> str:
    return str(path.relative_to(targets.REGRESSION_DIR))


def test_every_regression_folder_is_a_target() -> None:
    folders = {p.name for p in targets.REGRESSION_DIR.iterdir() if p.is_dir()}
    assert folders <= set(TARGETS), folders - set(TARGETS)


@pytest.mark.parametrize("path", [p for p in REGRESSION if p.parent.name in PURE], ids=_rel)
def test_a_saved_input_replays_clean(path: Path) -> None:
    targets.run_check(TARGETS[path.parent.name], path.read_bytes())


@pytest.mark.gl
@pytest.mark.parametrize("name", WITH_SESSION)
def test_the_saved_inputs_of_a_daemon_target_replay_clean(name: str) -> None:
    t = TARGETS[name]
    paths = [p for p in REGRESSION if p.parent.name == name]
    with targets.session(t):
        for path in paths:
            targets.run_check(t, path.read_bytes())
        targets.checked_batch(t)


@pytest.mark.parametrize("name", PURE)
def test_smoke(name: str) -> None:
    t = TARGETS[name]
    assert fuzz.smoke(t, SMOKE_EXAMPLES) >= SMOKE_EXAMPLES
    assert t.seeds(), f"{name} has no seeds"


@pytest.mark.gl
@pytest.mark.parametrize("name", WITH_SESSION)
def test_smoke_against_a_daemon(name: str) -> None:
    assert fuzz.smoke(TARGETS[name], SESSION_SMOKE_EXAMPLES) >= SESSION_SMOKE_EXAMPLES


def test_the_targets_cover_every_parser() -> None:
    from wxsky.weather.feeds import FORMATS

    expected = {"metar", "nmea", "canaerospace", "cigi", "control", "wire", "config", "preset"}
    expected |= {"share"}
    expected |= {"cloud-model", "feed-auto", *(f"feed-{f}" for f in FORMATS)}
    probe = subprocess.run(["pkg-config", "--exists", "openscenegraph"], capture_output=True)
    if probe.returncode == 0:  # the OSG plugin's parser, where its kit builds
        expected |= {"wxsky-file"}
    assert expected <= set(TARGETS)


# --- the harness catches what it must --------------------------------------------------------


def _broken(check: targets.Check, **options: object) -> targets.Target:
    return targets.Target("broken", check, lambda: [b"12345", b"678"], **options)


def test_the_smoke_finds_an_exception_a_mutation_provokes() -> None:
    def parse_int(data: bytes) -> None:
        int(data)  # ValueError on anything but digits: not a documented domain error

    with pytest.raises(targets.FuzzFailure, match="ValueError escaped"):
        fuzz.smoke(_broken(parse_int), SMOKE_EXAMPLES)


def test_a_documented_error_passes_and_anything_else_fails() -> None:
    def strict(data: bytes) -> None:
        raise KeyError(data)

    with pytest.raises(targets.FuzzFailure, match="KeyError escaped") as caught:
        targets.run_check(_broken(strict), b"x")
    assert caught.value.signature.startswith("broken: KeyError at ")


def test_a_value_out_of_range_fails() -> None:
    with pytest.raises(AssertionError, match="visibility_m"):
        targets.assert_patch_in_range(WeatherPatch(Source.METAR, visibility_m=-1.0))
    with pytest.raises(AssertionError, match=r"wind\.speed_mps"):
        targets.assert_cockpit_update(CockpitUpdate(values={"wind.speed_mps": 999.0}))


def test_the_metar_target_checks_the_patch_it_makes(monkeypatch: pytest.MonkeyPatch) -> None:
    def bad_patch(metar: object, *, field_elevation_m: float) -> WeatherPatch:
        return WeatherPatch(Source.METAR, qnh_hpa=5000.0)

    monkeypatch.setattr(targets, "metar_to_patch", bad_patch)
    with pytest.raises(targets.FuzzFailure, match="qnh_hpa"):
        targets.run_check(TARGETS["metar"], b"KXYZ 261550Z 27010KT 10SM CLR 20/10 A3000")


def test_a_slow_decode_fails() -> None:
    def slow(data: bytes) -> None:
        time.sleep(0.03)

    with pytest.raises(targets.FuzzFailure, match="took"):
        targets.run_check(_broken(slow, time_limit_s=0.01), b"x")


def test_a_run_saves_failing_inputs_a_few_per_cause(tmp_path: Path) -> None:
    def parse_int(data: bytes) -> None:
        int(data)

    t = _broken(parse_int)
    stats = fuzz.RunStats(t.name, "hypothesis")
    runner = fuzz.Runner(
        t, stats, fuzz.CrashRecorder(tmp_path, stats, lambda m: None), fuzz.Budget(400, None)
    )
    fuzz.run_hypothesis(runner, 1, t.seeds())
    assert stats.inputs >= 400 and stats.failures > 0
    saved = sorted(tmp_path.iterdir())
    assert saved and all(p.name.startswith("crash-") for p in saved)
    assert len(saved) <= fuzz.MAX_PER_SIGNATURE * len(stats.causes)
    for p in saved:
        with pytest.raises(targets.FuzzFailure):
            targets.run_check(t, p.read_bytes())


def test_mutations_are_deterministic_and_bounded() -> None:
    import random

    seeds = [b"KXYZ 261550Z 27010KT", b"$WIMWV,270.0,T,12.5,M,A*15\r\n"]
    runs = [
        [fuzz.mutate(s, random.Random(7), (b"TOKEN",), seeds, 16) for s in seeds] for _ in range(2)
    ]
    assert runs[0] == runs[1]
    assert all(len(m) <= 16 for m in runs[0])


def _fuzz_command(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "tools/fuzz/fuzz.py", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_the_command_runs_a_target(tmp_path: Path) -> None:
    crashes = str(tmp_path / "crashes")
    proc = _fuzz_command(
        "canaerospace", "--engine", "hypothesis", "--runs", "500", "--crash-dir", crashes
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "canaerospace" in proc.stdout and "inputs/s" in proc.stdout


def test_the_command_runs_a_target_under_atheris(tmp_path: Path) -> None:
    pytest.importorskip("atheris")
    crashes, work = str(tmp_path / "crashes"), str(tmp_path / "work")
    proc = _fuzz_command(
        "canaerospace",
        "--engine",
        "atheris",
        "--runs",
        "2000",
        "--crash-dir",
        crashes,
        "--work-dir",
        work,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert any((tmp_path / "work" / "canaerospace" / "corpus").iterdir()), "atheris kept no corpus"
