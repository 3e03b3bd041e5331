#!/usr/bin/env python3
"""What model data costs (issue 45): decoding the real GFS file and working out a column,
the decoder's memory, and whether the daemon's frames stay on time while it reads GRIB.

    .venv/bin/python tools/bench/bench_grib.py [--repeats 5] [--phase-s 20]
        [--json docs/performance-grib.json]

1. Times, median of `--repeats` in this process: decoding the 2.5 degree file whole and cut
   to the daemon's window, the column at a place (`profile_at`) and its clouds.
2. Memory: the peak resident size of a child process that imports the decoder, against one
   that decodes the file (the daemon decodes in such a child), and one that decodes a file
   of GFS's 0.25 degree size made from it (`quarter_degree`: the fixture's values spread onto
   the finer grid; for memory and time only, never for checking values).
3. Frames: a private daemon at 30 Hz, without model data and then with the file in a
   directory the tool rewrites every 2 s with other bytes (each rewrite fetched and decoded
   again, the column applied every 0.5 s); the largest gap between published frames and the
   99th percentile, from the daemon's own publish times.
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

GFS = ROOT / "tests" / "data" / "grib" / "gfs.t12z.pgrbf120.2p5deg.grib2"
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
import resource, sys, time
sys.path.insert(0, {root!r})
from wxsky.inputs.grib_decode import Window, decode
seconds = kib = 0.0
if {decode!r}:
    data = open({path!r}, "rb").read()
    t0 = time.perf_counter()
    fields = decode(data, "gfs", Window(47.46, 8.55))
    seconds = time.perf_counter() - t0
    kib = sum(f.values.nbytes for f in fields) / 1024
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, seconds, kib)
"""


def _child(path: Path, do: bool) -> tuple[float, float, float]:
    code = _CHILD.format(root=str(ROOT), decode=do, path=str(path))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    rss, seconds, kib = proc.stdout.split()
    return int(rss) / 1024.0, float(seconds), float(kib)


def quarter_degree(out: Path) -> int:
    """The fixture's fields wxsky reads, spread onto GFS's 0.25 degree grid (1440 x 721,
    each value repeated): a file the size and shape of a real 0.25 degree step's, to measure
    memory and time with. Its values are the 2.5 degree file's, not a forecast's."""
    import eccodes
    import numpy as np

    from wxsky.inputs.grib_decode import wanted

    data = GFS.read_bytes()
    written = 0
    eccodes.codes_grib_multi_support_on()
    with open(GFS, "rb") as f, open(out, "wb") as dst:
        while (h := eccodes.codes_grib_new_from_file(f)) is not None:
            try:
                short = eccodes.codes_get(h, "shortName")
                level_type = eccodes.codes_get(h, "typeOfLevel")
                if wanted(short, level_type) is None:
                    continue
                values = eccodes.codes_get_values(h).reshape(73, 144)
                fine = np.repeat(np.repeat(values, 10, axis=0)[:721], 10, axis=1)
                clone = eccodes.codes_clone(h)
                try:
                    eccodes.codes_set(clone, "Ni", 1440)
                    eccodes.codes_set(clone, "Nj", 721)
                    eccodes.codes_set(clone, "iDirectionIncrementInDegrees", 0.25)
                    eccodes.codes_set(clone, "jDirectionIncrementInDegrees", 0.25)
                    eccodes.codes_set(clone, "longitudeOfLastGridPointInDegrees", 359.75)
                    eccodes.codes_set_values(clone, fine.ravel())
                    eccodes.codes_write(clone, dst)
                    written += 1
                finally:
                    eccodes.codes_release(clone)
            finally:
                eccodes.codes_release(h)
    del data
    return written


def memory(work: Path) -> dict[str, float]:
    base, _, _ = _child(GFS, False)
    coarse, coarse_s, coarse_kib = _child(GFS, True)
    fine_path = work / "gfs-0p25.grib2"
    messages = quarter_degree(fine_path)
    fine, fine_s, fine_kib = _child(fine_path, True)
    return {
        "child_import_mib": base,
        "child_decode_2p5deg_mib": coarse,
        "decode_2p5deg_s": coarse_s,
        "quarter_degree_messages": messages,
        "quarter_degree_mib": fine_path.stat().st_size / 2**20,
        "child_decode_0p25deg_mib": fine,
        "decode_0p25deg_s": fine_s,
        "window_0p25deg_kib": fine_kib,
        "window_2p5deg_kib": coarse_kib,
    }


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
    config.write_text(f'[output]\nshm_name = "wxsky-bench-{tag}"\n' + CONFIG)
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
        client = _connect(f"unix:{sock}", proc, work / f"daemon-{tag}.log")
        with client:
            client.subscribe(["frame"])
            end = time.monotonic() + phase_s
            next_rewrite = time.monotonic() + 2.0
            rewrites = 0
            while time.monotonic() < end:
                note = client.next_notification(timeout_s=5.0)
                if note is not None and note.method == "frame":
                    published.append(float(note.params["published_s"]))
                if with_grib and time.monotonic() >= next_rewrite:
                    next_rewrite += 2.0
                    rewrites += 1
                    tmp = steps / "gfs.tmp"
                    # other bytes each time (padding after the last message, which readers
                    # skip): not the same content, so fetched and decoded again
                    tmp.write_bytes(GFS.read_bytes() + b"\0" * rewrites)
                    os.replace(tmp, steps / "gfs")
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


def _connect(address: str, proc: subprocess.Popen[bytes], log: Path) -> ControlClient:
    deadline = time.monotonic() + 60.0
    while True:
        if proc.poll() is not None:
            raise SystemExit(f"the daemon stopped: {log.read_text()[-2000:]}")
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
    with tempfile.TemporaryDirectory() as tmp:
        result["memory"] = memory(Path(tmp))
        result["frames_without"] = frame_gaps(args.phase_s, False, Path(tmp))
        result["frames_with"] = frame_gaps(args.phase_s, True, Path(tmp))
    print(json.dumps(result, indent=2))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
