"""Measure the daemon as the issue's acceptance asks: frames per second at the default
settings (as `wxsky status --json` reports them) and time to stop after SIGTERM.

    .venv/bin/python tools/bench/measure_daemon.py [--seconds 20] [--preset NAME] [--change-to NAME]

Prints the median and range of the fps samples and the stop time; exits 0. It starts its own
daemon on a private socket and shared-memory name so it never disturbs a running one.
`--change-to` applies a second preset once the daemon runs, so the samples are taken while the
weather moves toward it (the ring is rebuilt for it, cycle after cycle).
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
import uuid
from pathlib import Path


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--preset", default=None)
    p.add_argument("--change-to", default=None, metavar="PRESET")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        sock = Path(tmp) / "wx.sock"
        cfg = Path(tmp) / "wxsky.toml"
        cfg.write_text(f'[output]\nshm_name = "wxsky-measure-{uuid.uuid4().hex[:8]}"\n')
        cmd = [
            sys.executable,
            "-m",
            "wxsky",
            "run",
            "--config",
            str(cfg),
            "--control",
            f"unix:{sock}",
        ]
        if args.preset:
            cmd += ["--preset", args.preset]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            while not sock.exists():
                if proc.poll() is not None:
                    print("daemon exited early", file=sys.stderr)
                    return 1
                time.sleep(0.1)
            time.sleep(3.0)  # past start-up and the first ring build
            if args.change_to:
                apply = [sys.executable, "-m", "wxsky", "preset", "apply", args.change_to]
                subprocess.run(
                    [*apply, "--control", f"unix:{sock}"], check=True, capture_output=True
                )
                time.sleep(2.0)  # the fps window holds only frames drawn during the change
            samples = []
            end = time.monotonic() + args.seconds
            while time.monotonic() < end:
                out = subprocess.run(
                    [
                        sys.executable,
                        "-m",
                        "wxsky",
                        "status",
                        "--control",
                        f"unix:{sock}",
                        "--json",
                    ],
                    capture_output=True,
                    text=True,
                    check=True,
                ).stdout
                status = json.loads(out)
                samples.append(status["fps"])
                time.sleep(1.0)
            start = time.monotonic()
            proc.send_signal(signal.SIGTERM)
            code = proc.wait(timeout=30)
            stop_s = time.monotonic() - start
        finally:
            if proc.poll() is None:
                proc.kill()
        change = f" -> {args.change_to} (changing)" if args.change_to else ""
        print(
            f"cpu: {os.cpu_count()} cores; preset: {args.preset or 'default'}{change}; "
            f"viewport {status['camera']['width']}x{status['camera']['height']}"
        )
        print(
            f"fps over {len(samples)} samples: median {statistics.median(samples):.1f}, "
            f"min {min(samples):.1f}, max {max(samples):.1f}; frames {status['frames_published']}"
        )
        print(f"SIGTERM -> exit {code} in {stop_s:.2f} s; socket left: {sock.exists()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
