"""tools/soak/soak.py end to end, for a few seconds: it runs a real daemon through every kind of
fault, writes a report with every metric at a plausible value, a chart and the daemon's log,
and leaves no process, segment or temporary folder behind. Whether the daemon meets the
targets is the hour-long run's business (docs/reliability.md), not this test's: the exit
status may be 1 (a target missed), never 2 (the tool failed)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOAK = ROOT / "tools" / "soak" / "soak.py"

TARGETS = (
    "crashes",
    "torn_frames",
    "valid_applied",
    "invalid_reaching",
    "fps_ratio",
    "rss_growth",
    "fd_growth",
    "thread_growth",
    "log_volume",
)


def _processes_naming(text: str) -> list[str]:
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if text in cmdline:
            found.append(f"{pid}: {cmdline}")
    return found


@pytest.mark.gl
def test_a_short_soak_reports_every_metric(tmp_path: Path) -> None:
    out = tmp_path / "out"
    # 4 s of baseline (two 1 s frame-rate samples after its first 2 s), 6 s of soak in 3 s
    # cycles: each fault at least once; a control action every 0.5 s, so that all four kinds
    # come round with room to spare (at 1 s the 7 s soak before this ran just the four).
    cmd = [sys.executable, str(SOAK), "--seconds", "10", "--baseline-s", "4", "--cycle-s", "3"]
    cmd += ["--control-period-s", "0.5", "--bomb-mib", "2"]
    proc = subprocess.run(
        [*cmd, "--out", str(out)], capture_output=True, text=True, timeout=120, cwd=ROOT
    )
    assert proc.returncode in (0, 1), proc.stdout + proc.stderr
    r = json.loads((out / "report.json").read_text())

    assert set(r["targets"]) == set(TARGETS)
    for name, target in r["targets"].items():
        assert isinstance(target["ok"], bool), name
        assert target["target"], name
    verdict = "PASS" if all(t["ok"] for t in r["targets"].values()) else "FAIL"
    assert proc.stdout.strip().endswith(f"verdict: {verdict}")
    assert (proc.returncode == 0) == (verdict == "PASS")

    # Each fault ran, and each check saw what it checks.
    assert r["crashes"]["count"] == 0, r["crashes"]
    assert r["frames"]["read"] > 10 and r["frames"]["double_reads"] > 0
    assert r["frames"]["torn"] == 0 and r["frames"]["order_errors"] == 0
    for kind in ("serial", "can", "metar", "presets"):
        assert r["valid"][kind]["sent"] > 0, kind
        assert 0 <= r["valid"][kind]["applied"] <= r["valid"][kind]["sent"], kind
    assert isinstance(r["invalid"]["count"], int)
    assert r["links"]["serial"]["unplugs"] >= 1 and r["links"]["can"]["unplugs"] >= 1
    assert r["links"]["serial"]["reopened"] >= 1
    assert len(r["feed_writes"]) >= 2
    assert r["reader_kills"]["killed"] >= 3
    actions = r["control"]["actions"]
    assert {"connect-drop", "flood", "slow-reader", "bad-bytes"} <= set(actions)

    # The figures are measurements, not placeholders.
    assert r["fps"]["baseline"] > 0 and r["fps"]["soak"] > 0
    assert 0.0 < r["fps"]["ratio"] < 10.0
    assert 50_000 < r["rss_kib"]["warm"] <= r["rss_kib"]["peak"] < 8_000_000
    assert 0 < r["rss_kib"]["block_cache_end"] < r["rss_kib"]["peak"]
    assert 3 < r["fds"]["start"] <= r["fds"]["max"] and r["fds"]["end"] > 3
    assert r["threads"]["start"] > 1
    assert r["log"]["bytes"] > 0 and r["log"]["lines"] > 0
    assert r["log"]["lines_per_min"] is not None
    assert len(r["samples"]) >= 10
    # How long the stop took is the report's to say (a busy machine makes it longer).
    assert r["exit"]["code"] == 0 and r["exit"]["stop_s"] >= 0.0

    assert (out / "soak.png").read_bytes().startswith(b"\x89PNG")
    assert "serving on unix:" in (out / "daemon.log").read_text()

    # Nothing left behind.
    assert not _processes_naming(r["plan"]["shm_name"])
    assert not Path(f"/dev/shm/{r['plan']['shm_name']}").exists()
    assert not Path(r["plan"]["tmp"]).exists()
