"""How long rendering keeps other Python threads waiting for the GIL, with and without the
renderer's GIL-free glFinish (`wxsky.render.context.gil_free_finish`), side by side.

    .venv/bin/python tools/bench/bench_gil_stall.py [--frames 6] [--rounds 3]

A probe thread sleeps 1 ms in a loop and records how long each wake-up really took while the
render thread draws the ring and a frame and reads every layer back, as the daemon does. The
longest gap is how long the event loop (and a cockpit reader) could be held up. Prints the
median over rounds of the max and p99 gap and of the render time, for both variants.
"""

from __future__ import annotations

import argparse
import statistics
import threading
import time

from wxsky.app.daemon import initial_patches
from wxsky.engine.stages import SkyEngine
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.ring import RING_SIZE
from wxsky.settings.config import DaemonConfig
from wxsky.weather.state import WeatherState


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=6)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    cfg = DaemonConfig()
    state = WeatherState().apply(initial_patches(cfg)[0])
    camera = Camera(position_m=(0.0, 0.0, state.observer.alt_m + 2.0), width_px=960, height_px=540)
    plan = SkyEngine(state, camera, cfg.scene.settings()).advance(0.033)
    renderer = Renderer(cfg.scene.ring_texture_px)
    gil_free = renderer._finish
    results: dict[str, list[tuple[float, float, float]]] = {"GIL-free finish": [], "plain": []}
    try:
        for _ in range(args.rounds):
            for name, finish in (("plain", lambda: None), ("GIL-free finish", gil_free)):
                renderer._finish = finish
                results[name].append(_round(renderer, plan, args.frames))
    finally:
        renderer._finish = gil_free
        renderer.close()
    print(
        f"{args.frames} frames per round (ring, frame, every layer read back), {args.rounds} rounds"
    )
    print(f"{'variant':<16} {'max gap ms':>11} {'p99 gap ms':>11} {'render ms':>10}")
    for name, rounds in results.items():
        print(
            f"{name:<16} {statistics.median(r[0] for r in rounds):>11.1f} "
            f"{statistics.median(r[1] for r in rounds):>11.1f} "
            f"{statistics.median(r[2] for r in rounds):>10.0f}"
        )
    return 0


def _round(renderer: Renderer, plan: object, frames: int) -> tuple[float, float, float]:
    gaps: list[float] = []
    stop = threading.Event()

    def probe() -> None:
        last = time.perf_counter()
        while not stop.is_set():
            time.sleep(0.001)
            now = time.perf_counter()
            gaps.append(now - last)
            last = now

    screen = memoryview(bytearray(960 * 540 * 4))
    ring_px = renderer.ring_px
    ring = memoryview(bytearray(ring_px * ring_px * 4))
    thread = threading.Thread(target=probe)
    thread.start()
    start = time.perf_counter()
    for _ in range(frames):
        renderer.render_ring(plan.ring)  # type: ignore[attr-defined]
        renderer.render_frame(plan.frame)  # type: ignore[attr-defined]
        renderer.read_into("sky", screen)
        renderer.read_into("near", screen)
        for i in range(RING_SIZE):
            renderer.read_into(f"ring_{i}", ring)
    render_ms = (time.perf_counter() - start) * 1000.0
    stop.set()
    thread.join()
    ordered = sorted(gaps)
    return ordered[-1] * 1000.0, ordered[int(0.99 * (len(ordered) - 1))] * 1000.0, render_ms


if __name__ == "__main__":
    raise SystemExit(main())
