"""tools/soak/attacks.py, the harness of issue 40's attacks: one cheap attack (control set_time
to the end of year 9999) against a real daemon, and the harness's report checked against what
the daemon's pid says; then the daemon SIGKILLed, and the harness must report it dead, not
raise. Whether the daemon survives the attacks is the fixes' tests' business; this one checks
that the tool tells the truth either way. The other cases cost a minute or more each:
`tools/fuzz/fuzz.py --attacks` runs them all."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from gl_probe import skip_without_gl
from tool_loader import load_tool

attacks = load_tool("soak/attacks")

ROOT = Path(__file__).resolve().parents[1]
NAMES = {
    "year9999_control",
    "year9999_cigi",
    "year9999_flightgear",
    "zenoh_tick",
    "zenoh_state",
    "health_flood",
    "conditions_requests",
    "regions_flood",
    "shm_truncate",
}


def test_every_attack_of_the_issue_is_a_case() -> None:
    assert set(attacks.ATTACKS) == NAMES
    out = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "fuzz" / "fuzz.py"), "--attacks", "--list"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr
    assert {line.split()[0] for line in out.stdout.splitlines()} == NAMES


def test_an_unknown_attack_is_a_usage_error() -> None:
    for tool, args in (
        ("fuzz/fuzz.py", ["--attacks", "nope"]),
        ("soak/soak.py", ["--attacks=nope"]),
    ):
        out = subprocess.run(
            [sys.executable, str(ROOT / "tools" / tool), *args],
            capture_output=True,
            text=True,
            timeout=60,
            cwd=ROOT,
        )
        assert out.returncode == 2, (tool, out.stdout, out.stderr)
        assert "nope" in out.stderr, tool


@pytest.mark.gl
def test_the_harness_reports_what_the_daemon_did(tmp_path: Path) -> None:
    skip_without_gl()
    with attacks.Dome(tmp_path, share=False, channel=False) as target:
        master = target.master
        r = attacks.run_attack("year9999_control", target)

        # The report is the pid's truth, whichever way the attack went.
        alive = master.proc.poll() is None
        assert r.name == "year9999_control" and r.aimed_at == "master"
        assert r.alive == alive, r.line()
        assert r.frames_before is not None and r.frames_before > 0
        if alive:
            assert r.status_ok and r.frames_after is not None
            assert r.advancing == (r.frames_after > r.frames_before)
        else:
            assert not r.survived and not r.status_ok and r.frames_after is None
            assert "exit status" in r.what or "killed by" in r.what, r.what
        assert r.survived == (r.alive and r.advancing and r.status_ok and all(r.checks.values()))
        line = r.line()
        assert line.startswith("year9999_control") and ("survived yes" in line) == r.survived
        assert r.as_dict()["survived"] == r.survived


@pytest.mark.gl
def test_the_harness_tells_a_live_daemon_from_a_killed_one(tmp_path: Path) -> None:
    """observe(), the part of every case that judges the daemon: a healthy one survives, one
    SIGKILLed under it is reported dead with its signal, and nothing raises."""
    skip_without_gl()
    with attacks.Dome(tmp_path, share=False, channel=False) as target:
        master = target.master
        live = attacks.AttackResult("nothing", "master", frames_before=master.frame())
        status = attacks.observe(live, master, master.frame(), after_s=1.0)
        assert status is not None and live.alive and live.status_ok and live.advancing
        assert live.frames_after is not None and live.frames_before is not None
        assert live.frames_after > live.frames_before and live.survived, live.line()

        os.killpg(master.proc.pid, signal.SIGKILL)
        master.proc.wait(timeout=60)
        dead = attacks.AttackResult("killed", "master", frames_before=live.frames_after)
        assert attacks.observe(dead, master, master.frame(), after_s=0.5) is None
        assert not dead.alive and not dead.status_ok and not dead.survived
        assert dead.frames_after is None
        assert "killed by SIGKILL" in dead.what, dead.what
        assert "survived no" in dead.line()


def test_a_stall_through_the_whole_watch_counts_as_a_gap() -> None:
    """The frame gap is measured from the watch's ends too: a daemon that stopped drawing
    for the whole watch is a gap of its length, not "no gap seen"."""
    watch = attacks.FrameWatch.__new__(attacks.FrameWatch)
    watch.samples = [(0.0, 5), (1.0, 5), (4.0, 5)]
    assert watch.largest_gap_s() == 4.0
    watch.samples = [(0.0, 5), (0.1, 6), (0.2, 7), (1.2, 8), (1.3, 9)]
    assert abs(watch.largest_gap_s() - 1.0) < 1e-9
    assert abs(watch.fps(0.0, 2.0) - 4 / 1.3) < 1e-9
    watch.samples = [(0.0, 5)]
    assert watch.largest_gap_s() is None and watch.fps(0.0, 1.0) is None


def test_a_failed_case_keeps_its_daemons_logs(tmp_path: Path) -> None:
    case = tmp_path / "run" / "zenoh_tick"
    for name, text in (("master", "m\n"), ("channel-ab12", "Fatal Python error: Aborted\n")):
        (case / name).mkdir(parents=True)
        (case / name / "daemon.log").write_text(text)
    kept = attacks.keep_logs(case, tmp_path / "keep" / "zenoh_tick")
    assert [k.name for k in kept] == ["channel-ab12.log", "master.log"]
    assert "Aborted" in kept[0].read_text()
