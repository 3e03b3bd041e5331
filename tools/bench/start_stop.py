#!/usr/bin/env python3
"""A daemon's start-up (spawned to its first published frame, as `status` reports it) and its
shutdown (SIGTERM to exit), this checkout against another, side by side in one run.

    .venv/bin/python tools/bench/start_stop.py [--base /tmp/base] [--preset NAME] \\
        [--repeats 5] [--json FILE]

Each round starts a daemon from the base checkout, then one from this one (base, new, base,
new ...), so both see the same minute of this shared machine; "pair ratio" is the median of
each new run over the base run just before it (min-max after it). The base is any other
checkout of the source (`git worktree add /tmp/base REV`), run with this venv's Python and
that checkout first on the path. Without `--base` it times this checkout alone.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
HANG_S = 120.0  # a start or stop past this is a hang, not a figure


def _status(sock: Path) -> dict[str, Any] | None:
    from wxsky.errors import WxskyError
    from wxsky.host.client import ControlClient

    try:
        with ControlClient.connect(f"unix:{sock}") as client:
            reply: dict[str, Any] = client.call("status")
            return reply
    except (OSError, WxskyError):
        return None


def one_run(source: Path, preset: str) -> tuple[float, float]:
    """(start_s, stop_s) of one daemon run from the checkout at `source`."""
    with tempfile.TemporaryDirectory(prefix="wxsky-start-stop-") as tmp:
        sock = Path(tmp) / "wx.sock"
        env = dict(os.environ, PYTHONPATH=str(source))
        cmd = [sys.executable, "-m", "wxsky", "run", "--preset", preset]
        cmd += ["--control", f"unix:{sock}", "--shm-name", f"wxsky-start-stop-{os.getpid()}"]
        t0 = time.monotonic()
        with open(Path(tmp) / "daemon.log", "wb") as log_file:
            proc = subprocess.Popen(
                cmd, cwd=source, env=env, stdout=subprocess.DEVNULL, stderr=log_file
            )
        try:
            while True:
                if proc.poll() is not None:
                    why = (Path(tmp) / "daemon.log").read_text()[-400:]
                    raise SystemExit(f"the daemon from {source} exited at its start: {why}")
                if time.monotonic() - t0 > HANG_S:
                    raise SystemExit(f"the daemon from {source} never published a frame")
                st = _status(sock)
                if st is not None and st.get("frames_published", 0) > 0:
                    break
                time.sleep(0.02)
            t1 = time.monotonic()
            proc.send_signal(signal.SIGTERM)
            proc.wait(HANG_S)
            return t1 - t0, time.monotonic() - t1
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", type=Path, help="another checkout to time against (its root)")
    ap.add_argument("--preset", default="scattered-cumulus", help="the preset the daemons run")
    ap.add_argument("--repeats", type=int, default=5, help="rounds (one run per build each)")
    ap.add_argument("--json", type=Path, help="write the runs and their medians here")
    args = ap.parse_args()
    builds = {"new": ROOT} if args.base is None else {"base": args.base.resolve(), "new": ROOT}
    runs: dict[str, list[tuple[float, float]]] = {name: [] for name in builds}
    for _ in range(args.repeats):
        for name, source in builds.items():
            runs[name].append(one_run(source, args.preset))
    result: dict[str, Any] = {"preset": args.preset, "repeats": args.repeats}
    for name, times in runs.items():
        result[name] = {
            "start_s": [round(s, 3) for s, _ in times],
            "stop_s": [round(s, 3) for _, s in times],
            "start_median_s": round(statistics.median(s for s, _ in times), 3),
            "stop_median_s": round(statistics.median(s for _, s in times), 3),
        }
        print(
            f"{name:4}  start median {result[name]['start_median_s']:.2f} s "
            f"(min-max {min(s for s, _ in times):.2f}-{max(s for s, _ in times):.2f})  "
            f"stop median {result[name]['stop_median_s']:.2f} s"
        )
    if "base" in runs:
        for i, what in enumerate(("start", "stop")):
            ratios = [n[i] / b[i] for b, n in zip(runs["base"], runs["new"], strict=True)]
            result[f"{what}_pair_ratio"] = round(statistics.median(ratios), 3)
            print(
                f"{what} pair ratio new/base {statistics.median(ratios):.2f} "
                f"(min-max {min(ratios):.2f}-{max(ratios):.2f})"
            )
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
