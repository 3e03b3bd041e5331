#!/usr/bin/env python3
"""What model data adds to a METAR (issue 45): one PNG, docs/gallery/weather-aloft.png.

    .venv/bin/python tools/gallery/weather_aloft.py [--out docs/gallery/weather-aloft.png]
        [--grib FILE] [--size 640x360]

Left, Zurich's sky from a METAR alone (`wxsky snapshot --metar`); middle, the same METAR laid
over the real GFS file (`--grib`): the model's cirrus above what the station sees, and the
reported layer's top from the model; right, the model's column there (wind speed and
direction, temperature by height, the model's own cloud layers as bands, the freezing level
dotted), as `wxsky grib show` prints it. The clouds stand apart in the two pictures because
each drifted ten minutes (11:50 to 12:00) with its own wind: the METAR's one surface wind,
or the model's at the layer's height.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run as a script from a checkout
    sys.path.insert(0, str(ROOT))

GFS = ROOT / "tests" / "data" / "grib" / "gfs.t12z.pgrbf120.2p5deg.grib2"
METAR = "LSZH 151150Z 24008KT 9999 FEW045 07/02 Q1020"
TIME = "2011-01-15T12:00:00Z"  # the GFS file's valid time
SITE = ("47.4647", "8.5492")  # the default site, where a --metar snapshot stands
VIEW = ["--heading-deg", "300", "--pitch-deg", "30", "--fov-deg", "80"]


def _wxsky(*args: str) -> str:
    proc = subprocess.run(
        [sys.executable, "-m", "wxsky", *args], capture_output=True, text=True, cwd=ROOT
    )
    if proc.returncode != 0:
        raise SystemExit(f"wxsky {' '.join(args)}: {proc.stderr.strip()}")
    return proc.stdout


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "gallery" / "weather-aloft.png")
    p.add_argument("--grib", type=Path, default=GFS, help="the GRIB2 file (the GFS fixture)")
    p.add_argument("--size", default="640x360", help="each sky picture, WIDTHxHEIGHT")
    args = p.parse_args(argv)
    if not args.grib.exists():
        print(f"no GRIB file at {args.grib}", file=sys.stderr)
        return 2

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wxsky.png import read_png

    with tempfile.TemporaryDirectory() as tmp:
        alone, over = Path(tmp) / "alone.png", Path(tmp) / "over.png"
        common = ["snapshot", "--metar", METAR, "--time", TIME, "--size", args.size, *VIEW]
        said_alone = _wxsky(*common, "--out", str(alone)).strip()
        said_over = _wxsky(*common, "--grib", str(args.grib), "--out", str(over)).strip()
        pictures = [read_png(alone), read_png(over)]
    column = json.loads(
        _wxsky("grib", "show", str(args.grib), "--lat", SITE[0], "--lon", SITE[1], "--time",
               TIME, "--json")
    )  # fmt: skip
    levels = [lev for lev in column["levels"] if lev["height_m"] <= 14_000]

    fig = plt.figure(figsize=(16, 4.6), dpi=100)
    grid = fig.add_gridspec(1, 3, width_ratios=[1.0, 1.0, 0.55], wspace=0.08)
    titles = (
        f"METAR alone: {METAR}",
        "the same METAR over GFS (+120 h, 2.5°): the model's cirrus above it",
    )
    for i, (image, title, said) in enumerate(
        zip(pictures, titles, (said_alone, said_over), strict=True)
    ):
        ax = fig.add_subplot(grid[0, i])
        ax.imshow(image[..., :3])
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(said.split(": ", 1)[-1], fontsize=7)
        ax.set_xticks([])
        ax.set_yticks([])
    ax = fig.add_subplot(grid[0, 2])
    heights_km = [lev["height_m"] / 1000 for lev in levels]
    ax.plot([lev["speed_mps"] for lev in levels], heights_km, "-o", ms=3, label="wind m/s")
    ax.plot([lev["t_c"] for lev in levels], heights_km, "-", color="tab:red", label="temp °C")
    for lev in levels[::2]:
        ax.annotate(
            f"{lev['dir_deg']:03.0f}°",
            (lev["speed_mps"], lev["height_m"] / 1000),
            xytext=(4, -3),
            textcoords="offset points",
            fontsize=6,
        )
    for cloud in column["clouds"]:
        ax.axhspan(cloud["base_m"] / 1000, cloud["top_m"] / 1000, color="0.85", zorder=0)
        ax.text(
            -58, cloud["base_m"] / 1000 + 0.1, f"{cloud['type']} {cloud['cover_oktas']:.1f}/8",
            fontsize=6,
        )  # fmt: skip
    if column["freezing_level_m"] is not None:
        ax.axhline(column["freezing_level_m"] / 1000, color="tab:blue", lw=0.8, ls=":")
    ax.set_xlim(-60, 60)
    ax.set_ylabel("height MSL, km")
    ax.set_title("the model's column over Zurich", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(alpha=0.3)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, bbox_inches="tight")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
