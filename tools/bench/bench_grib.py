#!/usr/bin/env python3
"""What model data costs (issue 45): decoding the real GFS file and working out a column,
the decoder's memory, and whether the daemon's frames stay on time while it reads GRIB.

    .venv/bin/python tools/bench/bench_grib.py [--repeats 5] [--phase-s 20]
        [--json docs/performance-grib.json]

1. Times, median of `--repeats` in this process: decoding the 2.5 degree file whole and cut
   to the daemon's window, the column at a place (`profile_at`) and its clouds.
2. Memory: the peak resident size of a child process that imports the decoder, against one
   that decodes the file (the daemon decodes in such a child).
3. Frames: a private daemon at 30 Hz, without model data and then with the file in a
   directory the tool rewrites every 2 s (each rewrite fetched and decoded again, the column
   applied every 0.5 s); the largest gap between published frames and the 99th percentile,
   from the daemon's own publish times.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run as a script from a checkout
    sys.path.insert(0, str(ROOT))

from wxsky.host.client import ControlClient, DaemonUnavailable  # noqa: E402
from wxsky.inputs.grib_decode import Window, decode  # noqa: E402
from wxsky.weather.model_clouds import model_layers  # noqa: E402
from wxsky.weather.model_fields import merge_steps  # noqa: E402
from wxsky.weather.model_profile import profile_at  # noqa: E402

GFS = ROOT.parent / "shared" / "data" / "grib" / "gfs.t12z.pgrbf120.2p5deg.grib2"
VALID = datetime(2011, 1, 15, 12, tzinfo=UTC)
SITE = (47.46, 8.55)


def _median_ms(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1000.0)
    return statistics.median(times)


def timings(repeats: int) -> dict[str, float]:
    data = GFS.read_bytes()
    window = Window(*SITE)
    fields = decode(data, "gfs", window)
    steps = merge_steps(fields, ("gfs",))
    column = profile_at(steps, *SITE, VALID)
    assert column is not None
    return {
        "decode_whole_ms": _median_ms(lambda: decode(data, "gfs"), repeats),
        "decode_window_ms": _median_ms(lambda: decode(data, "gfs", window), repeats),
        "profile_ms": _median_ms(lambda: profile_at(steps, *SITE, VALID), repeats),
        "clouds_ms": _median_ms(lambda: model_layers(column), repeats),
        "window_fields": len(fields),
        "window_kib": sum(f.values.nbytes for f in fields) / 1024.0,
    }


_CHILD = """
import resource, sys
sys.path.insert(0, {root!r})
from wxsky.inputs.grib_decode import Window, decode
if {decode!r}:
    data = open({path!r}, "rb").read()
    fields = decode(data, "gfs", Window(47.46, 8.55))
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def memory() -> dict[str, float]:
    out = {}
    for key, do in (("child_import_mib", False), ("child_decode_mib", True)):
        code = _CHILD.format(root=str(ROOT), decode=do, path=str(GFS))
        proc = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        )
        out[key] = int(proc.stdout.strip()) / 1024.0
    return out


CONFIG = """
[camera]
width = 320
height = 180
[scene]
ring_texture_px = 128
[grib]
poll_interval_s = 1.0
update_s = 0.5
"""


def frame_gaps(phase_s: float, with_grib: bool, work: Path) -> dict[str, float]:
    """The daemon's publish times over `phase_s`: the largest gap and the 99th percentile."""
    tag = uuid.uuid4().hex[:8]
    sock = work / f"wx-{tag}.sock"
    config = work / f"wxsky-{tag}.toml"
    config.write_text(f'[output]\nshm_name = "/wxsky-bench-{tag}"\n' + CONFIG)
    steps = work / f"steps-{tag}"
    steps.mkdir()
    args = [sys.executable, "-m", "wxsky", "run", "--config", str(config)]
    args += ["--control", f"unix:{sock}", "--preset", "clear"]
    args += ["--replay", "2011-01-15T11:00:00Z"]
    if with_grib:
        shutil.copy(GFS, steps / "gfs")
        args += ["--grib", str(steps)]
    log = open(work / f"daemon-{tag}.log", "w")  # noqa: SIM115 (closed below)
    proc = subprocess.Popen(args, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    published: list[float] = []
    try:
        client = _connect(f"unix:{sock}")
        with client:
            client.subscribe(["frame"])
            end = time.monotonic() + phase_s
            next_rewrite = time.monotonic() + 2.0
            while time.monotonic() < end:
                note = client.next_notification(timeout_s=5.0)
                if note is not None and note.method == "frame":
                    published.append(float(note.params["published_s"]))
                if with_grib and time.monotonic() >= next_rewrite:
                    next_rewrite += 2.0
                    tmp = steps / "gfs.tmp"
                    shutil.copy(GFS, tmp)
                    os.replace(tmp, steps / "gfs")  # a new file: fetched and decoded again
            status = client.call("status")
    finally:
        proc.terminate()
        proc.wait(timeout=30)
        log.close()
    gaps = sorted(b - a for a, b in itertools.pairwise(published))
    grib = status.get("grib") or {}
    return {
        "frames": len(published),
        "largest_gap_ms": gaps[-1] * 1000.0,
        "p99_gap_ms": gaps[int(0.99 * (len(gaps) - 1))] * 1000.0,
        "median_gap_ms": statistics.median(gaps) * 1000.0,
        "decodes": sum(i.get("messages", 0) for i in status["inputs"] if i["kind"] == "grib"),
        "profile_levels": len((grib.get("profile") or {}).get("levels", [])),
    }


def _connect(address: str) -> ControlClient:
    deadline = time.monotonic() + 60.0
    while True:
        try:
            client = ControlClient.connect(address)
            client.call("status")
            return client
        except (DaemonUnavailable, OSError):
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="timings: runs of each step")
    parser.add_argument("--phase-s", type=float, default=20.0, help="seconds of frames each")
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args(argv)
    if not GFS.exists():
        print(f"the GFS fixture is absent: {GFS}", file=sys.stderr)
        return 2
    result: dict[str, Any] = {"file": GFS.name, "bytes": GFS.stat().st_size}
    result["timings"] = timings(args.repeats)
    result["memory"] = memory()
    with tempfile.TemporaryDirectory() as tmp:
        result["frames_without"] = frame_gaps(args.phase_s, False, Path(tmp))
        result["frames_with"] = frame_gaps(args.phase_s, True, Path(tmp))
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
