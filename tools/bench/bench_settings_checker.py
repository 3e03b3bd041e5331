"""Start-up cost of the settings checker against pydantic v2: the `[daemon]` and `[camera]`
tables of configs/wxsky.toml imported, declared and checked in a fresh process, median of N.

    .venv/bin/python tools/bench/bench_settings_checker.py [--pydantic-python PATH] [--runs 15]

pydantic is not a wxsky dependency: point --pydantic-python at an interpreter that has it
(e.g. a scratch venv with `pip install pydantic`); without one only wxsky.schema is timed.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "wxsky.toml"

OURS = f"""
import time
t = time.perf_counter()
import tomllib
from pathlib import Path
from wxsky.schema import Field, Number, Table, Text
n, i = Number, lambda lo, hi: Number(lo, hi, integer=True)
cam = Table({{"heading_deg": Field(n(0, 360)), "pitch_deg": Field(n(-90, 90)),
    "roll_deg": Field(n(-180, 180)), "fov_deg": Field(n(1, 170)), "width": Field(i(16, 8192)),
    "height": Field(i(16, 8192)), "alt_agl_m": Field(n(0, 20000))}})
dae = Table({{"tick_hz": Field(n(1, 240)), "status_interval_s": Field(n(0.1, 3600)),
    "preset": Field(Text(pattern=r"[a-z0-9-]+")), "log_level": Field(Text()),
    "shutdown_timeout_s": Field(n(0, 60))}})
data = tomllib.loads(Path({str(CONFIG)!r}).read_text())
Table({{"daemon": Field(dae), "camera": Field(cam)}}).values(
    {{"daemon": data["daemon"], "camera": data["camera"]}})
print(time.perf_counter() - t)
"""

PYDANTIC = f"""
import time
t = time.perf_counter()
import tomllib
from pathlib import Path
from pydantic import BaseModel, ConfigDict, Field
class S(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
class Camera(S):
    heading_deg: float = Field(0.0, ge=0, le=360)
    pitch_deg: float = Field(12.0, ge=-90, le=90)
    roll_deg: float = Field(0.0, ge=-180, le=180)
    fov_deg: float = Field(60.0, ge=1, le=170)
    width: int = Field(960, ge=16, le=8192)
    height: int = Field(540, ge=16, le=8192)
    alt_agl_m: float = Field(2.0, ge=0, le=20000)
class Daemon(S):
    tick_hz: float = Field(30.0, ge=1, le=240)
    status_interval_s: float = Field(5.0, ge=0.1, le=3600)
    preset: str = Field("fair-cumulus", pattern=r"^[a-z0-9-]+$")
    log_level: str = "INFO"
    shutdown_timeout_s: float = Field(1.5, ge=0, le=60)
class Config(S):
    daemon: Daemon = Daemon()
    camera: Camera = Camera()
data = tomllib.loads(Path({str(CONFIG)!r}).read_text())
Config(daemon=data["daemon"], camera=data["camera"])
print(time.perf_counter() - t)
"""

BASE = "import time; t = time.perf_counter(); import tomllib; print(time.perf_counter() - t)"


def median_s(python: str, code: str, runs: int) -> float:
    times = []
    for _ in range(runs):
        out = subprocess.run([python, "-c", code], capture_output=True, text=True, check=True)
        times.append(float(out.stdout))
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pydantic-python", help="an interpreter with pydantic installed")
    parser.add_argument("--runs", type=int, default=15)
    args = parser.parse_args()
    rows = [("tomllib alone", median_s(sys.executable, BASE, args.runs))]
    # Interleaved would be fairer still; separate fresh processes already dominate the noise.
    ours = median_s(sys.executable, OURS, args.runs)
    rows.append(("wxsky.schema", ours))
    if args.pydantic_python:
        theirs = median_s(args.pydantic_python, PYDANTIC, args.runs)
        rows.append(("pydantic v2", theirs))
    for name, t in rows:
        print(f"{name:14s} {t * 1000:7.1f} ms (median of {args.runs})")
    if args.pydantic_python:
        print(f"pydantic / wxsky.schema: {theirs / ours:.1f}")


if __name__ == "__main__":
    main()
