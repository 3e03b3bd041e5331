"""Benchmark the C host kit (plugins/host-c) against a real daemon: the host side's cost per
frame (copy-out read, upload plain and through PBOs, composite) and the end-to-end latency
from `set_camera` to a composited frame for that camera, at 1280x720 and 1920x1080.

    .venv/bin/python tools/bench/bench_host_c.py [--frames 60] [--latency 20] [--sizes 1280x720,...]
        [--json FILE] [--png FILE] [--live]

For each size it starts its own daemon (a private shared-memory name and unix socket in a
temporary folder, [output] max_width/max_height and [camera] width/height set to the size),
waits for its first frames, runs `plugins/host-c/build/wxsky_gl_bench` (built with make when
missing or older than its sources), then stops the daemon with SIGTERM. By default the daemon
is paused (SIGSTOP) while the stages are timed, so its own rendering does not share the CPU
with the host's (on llvmpipe both are CPU work); the segment stays valid and the frames read
are the last one it published. `--live` leaves it running. The latency runs with the daemon
running, of course. Prints a table; --json writes every figure, --png a bar chart.

`--zero-copy` measures instead, per size, the host's upload of a frame from the segment
(wxsky_frame_begin, wxsky_gl_upload_view of every layer, glFinish) against its zero-copy
import of the daemon's exported textures (wxsky_gl_import_view: GPU copies and a fence,
docs/protocol.md §6), with `plugins/host-c/build/wxsky_gl_zero_copy --bench`; where the
daemon exports nothing (llvmpipe: no EGL_MESA_image_dma_buf_export) it says so, with the
daemon's reason, and gives the segment's figures alone.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
KIT = ROOT / "plugins" / "host-c"
BENCH = KIT / "build" / "wxsky_gl_bench"
ZERO_COPY = KIT / "build" / "wxsky_gl_zero_copy"
STAGES = (
    "read",
    "upload_plain",
    "composite_plain",
    "host_plain",
    "upload_pbo",
    "composite_pbo",
    "host_pbo",
    "upload_rings_plain",
    "background_plain",
)
LATENCY = {"latency": "set_camera → composited", "latency_wait": "set_camera → frame seen"}


def build_kit() -> Path:
    """`make -C plugins/host-c` (a no-op when up to date); the benchmark program's path."""
    proc = subprocess.run(
        ["make", "-s", "-C", str(KIT), f"-j{os.cpu_count() or 2}"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    if proc.returncode != 0:
        raise SystemExit(f"make -C {KIT} failed:\n{proc.stdout}{proc.stderr}")
    if not BENCH.exists():
        raise SystemExit(f"{BENCH} was not built (pkg-config finds no egl and gl?)")
    return BENCH


def write_config(
    path: Path, shm_name: str, width: int, height: int, preset: str, near_depth: bool = False
) -> None:
    path.write_text(
        f"""
[daemon]
preset = "{preset}"
status_interval_s = 5.0
[camera]
width = {width}
height = {height}
[output]
shm_name = "{shm_name}"
max_width = {width}
max_height = {height}
near_depth = {str(near_depth).lower()}
"""
    )


@contextlib.contextmanager
def daemon(
    folder: Path,
    width: int,
    height: int,
    preset: str,
    timeout_s: float = 120.0,
    near_depth: bool = False,
) -> Iterator[tuple[subprocess.Popen[bytes], str, str]]:
    """A running `wxsky run` at width x height: (process, shm name, control address);
    `near_depth`: with the near layer's depth ([output] near_depth)."""
    shm_name = f"wxsky-benchc-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    config = folder / f"wxsky-{width}x{height}.toml"
    write_config(config, shm_name, width, height, preset, near_depth)
    sock = folder / f"wx-{width}x{height}.sock"
    address = f"unix:{sock}"
    log_path = folder / f"daemon-{width}x{height}.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "wxsky", "run", "--config", str(config), "--control", address],
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    try:
        deadline = time.monotonic() + timeout_s
        while not frames_published(address):
            if proc.poll() is not None:
                raise SystemExit(f"daemon exited early:\n{log_path.read_text(errors='replace')}")
            if time.monotonic() > deadline:
                raise SystemExit(f"daemon published no frame in {timeout_s:.0f} s")
            time.sleep(0.2)
        yield proc, shm_name, address
    finally:
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(proc.pid, signal.SIGCONT)
                proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(f"/dev/shm/{shm_name}")


def frames_published(address: str) -> bool:
    from wxsky.host.client import ControlClient

    try:
        with ControlClient.connect(address) as c:
            return int(c.call("status")["frames_published"]) >= 3
    except Exception:
        return False


def run_bench(exe: Path, args: list[str], timeout_s: float) -> dict[str, Any]:
    proc = subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=timeout_s)
    line = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else ""
    if proc.returncode != 0 or not line.startswith("{"):
        raise SystemExit(f"{exe.name} {' '.join(args)} failed ({proc.returncode}): {proc.stdout}")
    result: dict[str, Any] = json.loads(line)
    return result


def measure(
    exe: Path, folder: Path, width: int, height: int, args: argparse.Namespace
) -> dict[str, Any]:
    with daemon(folder, width, height, args.preset) as (proc, shm_name, address):
        paused = not args.live
        if paused:
            os.kill(proc.pid, signal.SIGSTOP)
        try:
            stages = run_bench(exe, [shm_name, "--frames", str(args.frames)], timeout_s=300)
        finally:
            if paused:
                os.kill(proc.pid, signal.SIGCONT)
        latency_args = ["--frames", "1", "--warmup", "1", "--latency", str(args.latency)]
        latency = run_bench(exe, [shm_name, *latency_args, "--control", address], timeout_s=300)
    return {
        "size": f"{width}x{height}",
        "renderer": stages["renderer"],
        "daemon_paused_for_stages": paused,
        "frames": stages["frames"],
        "ring_uploads": stages["ring_uploads"],
        "stages": stages["stages"],
        "latency": latency["latency"],
        "latency_wait": latency["latency_wait"],
        "latency_camera_matched": latency["latency_camera_matched"],
        "latency_frames_waited_mean": latency["latency_frames_waited_mean"],
    }


def measure_zero_copy(folder: Path, width: int, height: int, args: argparse.Namespace) -> str:
    """One size's segment upload vs zero-copy import, as a line of text."""
    with daemon(folder, width, height, args.preset) as (_proc, shm_name, address):
        result = run_bench(
            ZERO_COPY, [address, shm_name, "--bench", str(args.frames)], timeout_s=300
        )
    stages = result["stages"]
    shm = stages["shm_view_upload"]
    line = (
        f"{width}x{height} ({result['renderer']}): segment upload median "
        f"{shm['median_ms']:.3f} ms, p95 {shm['p95_ms']:.3f} ms"
    )
    if result["mode"] != "zero-copy":
        return f"{line}; zero-copy unavailable: {result['reason']}"
    zc = stages["zero_copy_import"]
    return f"{line}; zero-copy import median {zc['median_ms']:.3f} ms, p95 {zc['p95_ms']:.3f} ms"


def figures(result: dict[str, Any], stage: str) -> dict[str, Any]:
    found: dict[str, Any] = result[stage] if stage in LATENCY else result["stages"][stage]
    return found


def table(results: list[dict[str, Any]]) -> str:
    sizes = [r["size"] for r in results]
    head = "| stage | " + " | ".join(f"{s} median ms | {s} p95 ms" for s in sizes) + " |"
    rule = "|---|" + "---|---|" * len(sizes)
    rows = [head, rule]
    for stage in (*STAGES, *LATENCY):
        cells = []
        for r in results:
            st = figures(r, stage)
            cells.append(f"{st['median_ms']:.2f} | {st['p95_ms']:.2f}")
        rows.append(f"| {LATENCY.get(stage, stage)} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def chart(results: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = (*STAGES, *LATENCY)
    fig, axes = plt.subplots(1, len(results), figsize=(6.0 * len(results), 4.2), squeeze=False)
    for ax, r in zip(axes[0], results, strict=True):
        med = [figures(r, n)["median_ms"] for n in names]
        p95 = [figures(r, n)["p95_ms"] for n in names]
        xs = range(len(names))
        ax.bar([x - 0.2 for x in xs], med, 0.4, label="median")
        ax.bar([x + 0.2 for x in xs], p95, 0.4, label="p95")
        ax.set_xticks(list(xs))
        ax.set_xticklabels(names, rotation=35, ha="right", fontsize=8)
        ax.set_yscale("log")  # from the 1 ms copies to the 100 ms composites
        ax.set_ylabel("ms (log scale)")
        ax.set_title(f"{r['size']} ({r['renderer'].split(' (')[0]})", fontsize=10)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("C host kit per frame, and set_camera → composited frame", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def parse_size(text: str) -> tuple[int, int]:
    w, _, h = text.partition("x")
    return int(w), int(h)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=60, help="timed frames per size")
    p.add_argument("--latency", type=int, default=20, help="set_camera round trips per size")
    p.add_argument("--sizes", default="1280x720,1920x1080")
    p.add_argument("--preset", default="scattered-cumulus")
    p.add_argument("--live", action="store_true", help="do not pause the daemon for the stages")
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--png", type=Path, default=None)
    p.add_argument(
        "--zero-copy",
        action="store_true",
        help="time the segment upload against the zero-copy import (docs/protocol.md §6)",
    )
    args = p.parse_args()
    exe = build_kit()
    if args.zero_copy:
        if not ZERO_COPY.exists():
            raise SystemExit(f"{ZERO_COPY} was not built (pkg-config finds no egl and gl?)")
        with tempfile.TemporaryDirectory(prefix="wxsky-benchzc-") as tmp:
            for size in args.sizes.split(","):
                w, h = parse_size(size)
                print(measure_zero_copy(Path(tmp), w, h, args), flush=True)
        return 0
    results = []
    with tempfile.TemporaryDirectory(prefix="wxsky-benchc-") as tmp:
        for size in args.sizes.split(","):
            w, h = parse_size(size)
            print(f"{w}x{h} ...", file=sys.stderr, flush=True)
            results.append(measure(exe, Path(tmp), w, h, args))
    print(f"renderer: {results[0]['renderer']}")
    print(table(results))
    for r in results:
        print(
            f"{r['size']}: ring uploads in {r['ring_uploads']} of {r['frames']} timed frames; "
            f"latency camera matched: {r['latency_camera_matched']}, "
            f"frames published meanwhile (mean): {r['latency_frames_waited_mean']:.2f}"
        )
    if args.json:
        args.json.write_text(json.dumps({"results": results}, indent=2) + "\n")
    if args.png:
        chart(results, args.png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
