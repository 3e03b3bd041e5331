#!/usr/bin/env python3
"""The physical atmosphere against the CIE standard clear sky (CIE S 011 type 12), and what
its tables cost to build: the table docs/atmosphere.md quotes.

    nice -n 19 .venv/bin/python tools/bench/cie_sky.py --png /tmp/cie_sky.png

For each visibility and sun elevation: the median and 90th percentile of the relative error of
the model's luminance relative to its zenith against CIE's, over 360 directions 5-80 deg up all
round (tests/test_atmosphere.py holds them to 25 % and 50 %), and the time to build the tables
(the medium's three once per visibility, then the sky view per sun). The PNG shows, per sun
elevation (rows), the model's relative luminance beside CIE's and their ratio, each as a
panorama (azimuth across, the sun in the middle; elevation 0-90 deg up), grey on a log scale
(L / L_zenith of 1/4 black, 16 white; the ratio: 1/2 black, 2 white).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

from wxsky.png import write_png  # noqa: E402
from wxsky.scene import atmosphere as atm  # noqa: E402
from wxsky.scene import cie_sky  # noqa: E402

SUN_ELEVATIONS_DEG = (10.0, 30.0, 60.0)
VISIBILITIES_M = (30_000.0, 45_000.0, 60_000.0)
PANORAMA_PX = (90, 360)  # elevation rows, azimuth columns


def _sun(elevation_deg: float) -> np.ndarray:
    e = math.radians(elevation_deg)
    return np.array([0.0, math.cos(e), math.sin(e)])  # due north


def _panorama(luts: atm.AtmosphereLuts, sun: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = PANORAMA_PX
    el = np.radians(90.0 - (np.arange(rows) + 0.5) * 90.0 / rows)  # top row near the zenith
    az = np.radians((np.arange(cols) + 0.5) * 360.0 / cols - 180.0)  # the sun in the middle
    e, a = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1)
    zenith = float(luts.radiance(np.array([0.0, 0.0, 1.0]), sun) @ cie_sky.LUMA)
    model = (luts.radiance(d.reshape(-1, 3), sun) @ cie_sky.LUMA).reshape(rows, cols) / zenith
    ref = cie_sky.relative_luminance(cie_sky.CLEAR_LOW_TURBIDITY, d, sun)
    return model, ref


def _grey(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    t = (np.log(np.maximum(values, 1e-9)) - math.log(lo)) / (math.log(hi) - math.log(lo))
    g = (np.clip(t, 0.0, 1.0) * 255.0).astype(np.uint8)
    return np.stack([g, g, g, np.full_like(g, 255)], axis=-1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--png", type=Path, help="write the model-against-CIE picture here")
    parser.add_argument("--png-visibility-m", type=float, default=30_000.0)
    args = parser.parse_args()
    dirs = cie_sky.hemisphere_directions()
    print(f"CIE S 011 type 12 against the model: {len(dirs)} directions, elevation 5-80 deg")
    print("visibility_m  sun_deg  median  p90    build_ms (medium + sky view)")
    panels = []
    for vis in VISIBILITIES_M:
        atm._medium_tables = None  # time the medium's tables once per visibility
        for sun_deg in SUN_ELEVATIONS_DEG:
            key = atm.atmosphere_key(sun_deg, vis, 50.0, 2.0)
            start = time.perf_counter()
            luts = atm.build_luts(key)
            build_ms = (time.perf_counter() - start) * 1000.0
            sun = _sun(sun_deg)
            zenith = float(luts.radiance(np.array([0.0, 0.0, 1.0]), sun) @ cie_sky.LUMA)
            lum = luts.radiance(dirs, sun) @ cie_sky.LUMA
            result = cie_sky.compare(lum, zenith, dirs, sun)
            print(
                f"{vis:12.0f}  {sun_deg:7.0f}  {result.median:6.3f}  {result.p90:5.3f}  "
                f"{build_ms:8.0f}"
            )
            if args.png is not None and vis == args.png_visibility_m:
                model, ref = _panorama(luts, sun)
                gap = np.full((PANORAMA_PX[0], 4, 4), 255, np.uint8)
                panels.append(
                    np.concatenate(
                        [
                            _grey(model, 0.25, 16.0),
                            gap,
                            _grey(ref, 0.25, 16.0),
                            gap,
                            _grey(model / ref, 0.5, 2.0),
                        ],
                        axis=1,
                    )
                )
    if args.png is not None and panels:
        bar = np.full((4, panels[0].shape[1], 4), 255, np.uint8)
        sheet = np.concatenate([p for panel in panels for p in (panel, bar)][:-1], axis=0)
        write_png(args.png, np.ascontiguousarray(sheet))
        print(f"wrote {args.png}: per sun (10, 30, 60 deg, top down): model | CIE | ratio")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
