#!/usr/bin/env python3
"""What a convective tower's volume costs (wxsky/towers): one automaton step, the growth rules
alone, the smoothing, the ellipsoid odds and the slice lighting, medians of repeated runs.

    .venv/bin/python tools/bench/bench_towers.py [--grid 64 --grid 128] [--repeats 15]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

from wxsky.towers.automaton import (
    Cells,
    Odds,
    cell_rng,
    ellipsoid_weight,
    grow,
    smoothed,
    step,
    tower_ellipsoids,
    tower_odds,
)
from wxsky.towers.lighting import slice_light


def median_ms(f: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return 1000.0 * statistics.median(times)


def odds_for(shape: tuple[int, int, int], maturity: float) -> Odds:
    weight = ellipsoid_weight(shape, tower_ellipsoids(shape, maturity))
    return tower_odds(weight, hum=0.1, act=0.01, ext_inside=0.001, ext_outside=0.3)


def measure(grid: int, repeats: int) -> list[float]:
    shape = (grid, grid, grid)
    rng = cell_rng(1, (0, 0), 0)
    odds = odds_for(shape, 1.0)
    cells = Cells.empty(shape)
    for _ in range(30):  # a grown tower, not an empty grid
        cells = step(cells, odds, rng)
    density = smoothed(cells.cld)
    return [
        median_ms(lambda: step(cells, odds, rng), repeats),
        median_ms(lambda: grow(cells), repeats),
        median_ms(lambda: smoothed(cells.cld), repeats),
        median_ms(lambda: odds_for(shape, 0.7), repeats),
        median_ms(lambda: slice_light(density, (0.8, 0.2, 0.6)), repeats),
        median_ms(lambda: slice_light(density, (0.0, 0.0, 1.0)), repeats),
    ]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--grid", type=int, action="append")
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print(
        "| grid | step | of which the rules | smoothing | odds (ellipsoids) | light, oblique "
        "| light, overhead |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for grid in args.grid or [64, 128]:
        row = measure(grid, args.repeats)
        print(f"| {grid}³ | " + " | ".join(f"{v:.1f} ms" for v in row) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
