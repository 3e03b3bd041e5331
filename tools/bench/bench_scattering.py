#!/usr/bin/env python3
"""How fast Harris's scattering precompute runs on one CPU core: particles per second per light,
for the sun alone and for the sun with the skylights, side by side.

    .venv/bin/python tools/bench/bench_scattering.py                     # ~1 M particles per preset
    .venv/bin/python tools/bench/bench_scattering.py --particles 200000 --repeats 3 thunderstorm

The particles are a preset's far ring sprites (8-40 km) at noon, copied with new cloud ids
until there are enough, with the optical depths and shadow radii the shading uses. numpy is
held to one thread (the variables below are set before numpy loads) and the process to one
core, so the figure is per core. Each time is a median over the repeats.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

from wxsky.scene.gather import gather_blocks, zero_drift  # noqa: E402
from wxsky.scene.scattering import incident_light  # noqa: E402
from wxsky.scene.shading_harris import SHADOW_REACH, scene_lights, tau_of  # noqa: E402
from wxsky.scene.sky import sky_params  # noqa: E402
from wxsky.scene.sprites import SpriteBatch  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

PRESETS = ("fair-cumulus", "scattered-cumulus", "broken-stratocumulus", "thunderstorm")


def particles(preset: str, count: int) -> tuple[SpriteBatch, WeatherState]:
    """At least `count` far sprites of the preset's sky: copies get fresh cloud ids."""
    state = WeatherState().apply(load_preset(preset))
    centre = (0.0, 0.0, state.observer.alt_m)
    far = gather_blocks(state, zero_drift(state), centre, 8000.0, 40_000.0)
    _, cloud = np.unique(far.cloud_id, return_inverse=True)
    n_clouds = int(cloud.max()) + 1 if len(far) else 0
    copies = [
        dataclasses.replace(far, cloud_id=(cloud + k * n_clouds).astype(np.int64))
        for k in range(max(1, -(-count // max(len(far), 1))))
    ]
    return SpriteBatch.concat(copies), state


def timed(batch: SpriteBatch, dirs: np.ndarray, repeats: int) -> float:
    """Median seconds of one precompute of the batch for these light directions."""
    tau, radius = tau_of(batch), SHADOW_REACH * batch.size_m
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        incident_light(batch.centre_m, radius, tau, batch.cloud_id, dirs)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("presets", nargs="*", default=list(PRESETS))
    parser.add_argument("--particles", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    print(f"os.cpu_count() = {os.cpu_count()}; numpy {np.__version__}, one thread, one core")
    print(f"medians of {args.repeats} runs; M = million particles per second per light")
    header = f"{'preset':<22}{'particles':>10}{'clouds':>8}{'n/cloud':>9}"
    print(f"{header}{'sun alone':>14}{'sun + 4 sky':>14}")
    for name in args.presets:
        batch, state = particles(name, args.particles)
        dirs = scene_lights(sky_params(state)).directions  # (5, 3): sun, then skylights
        n_clouds = len(np.unique(batch.cloud_id))
        alone = len(batch) / timed(batch, dirs[:1], args.repeats) / 1e6
        every = len(batch) * len(dirs) / timed(batch, dirs, args.repeats) / 1e6
        row = f"{name:<22}{len(batch):>10}{n_clouds:>8}{len(batch) / n_clouds:>9.1f}"
        print(f"{row}{alone:>12.2f} M{every:>12.2f} M")
    return 0


if __name__ == "__main__":
    sys.exit(main())
