"""The cloud cover a pilot on the ground sees 5-15 deg above the horizon, preset by preset.

    .venv/bin/python tools/bench/cover_seen.py [--preset NAME ...] [--heading-deg DEG ...]
        [--json FILE]

Issue 42's "cover seen" check. Each case is the daemon's picture (`take_snapshot`, ring mode)
at 1280x720, the eye 2 m above the preset's observer looking 10 deg up with a 60 deg field of
view, at the preset's own time, at every heading asked for (default: the four quarters). The
clouds' opacity at each pixel is exact, not guessed from colours: the picture is composited
twice, over a black sky and over a white one, and a pixel's clouds let through the
difference (premultiplied layers: out = clouds + (1 - alpha) x sky). Over the pixels whose ray
is 5-15 deg above level, the figure is the share at least half opaque ("cloud" to a pilot),
with the mean opacity beside it. The issue's bar: scattered-cumulus (4/8) at most 0.75.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tools.bench.banding import ray_elevation_deg  # noqa: E402
from wxsky.app.snapshot import take_snapshot  # noqa: E402
from wxsky.host.compositor import clouds_alpha  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

F64 = npt.NDArray[np.float64]

PRESETS = ("fair-cumulus", "scattered-cumulus", "towering-cumulus", "broken-stratocumulus")
HEADINGS_DEG = (0.0, 90.0, 180.0, 270.0)
SIZE = (1280, 720)
FOV_DEG = 60.0
PITCH_DEG = 10.0
EYE_AGL_M = 2.0
BAND_DEG = (5.0, 15.0)
CLOUD_ALPHA = 0.5
BARS = {"scattered-cumulus": 0.75}


def cloud_alpha(renderer: Renderer, state: WeatherState, heading_deg: float) -> F64:
    """(H, W) the opacity of every cloud layer together at each pixel of the picture."""
    camera = Camera(
        position_m=(0.0, 0.0, state.observer.alt_m + EYE_AGL_M),
        heading_deg=heading_deg,
        pitch_deg=PITCH_DEG,
        fov_deg=FOV_DEG,
        width_px=SIZE[0],
        height_px=SIZE[1],
    )
    shot = take_snapshot(state, camera, SceneSettings(), renderer=renderer)
    alpha: F64 = np.clip(clouds_alpha(shot.layers, shot.ring_quads_m, camera), 0.0, 1.0)
    return alpha


def band_cover(alpha: F64) -> tuple[float, float]:
    """(share of the band's pixels at least CLOUD_ALPHA opaque, their mean opacity)."""
    elevation = ray_elevation_deg(SIZE, PITCH_DEG, FOV_DEG)
    inside = (elevation >= BAND_DEG[0]) & (elevation <= BAND_DEG[1])
    return float(np.mean(alpha[inside] >= CLOUD_ALPHA)), float(np.mean(alpha[inside]))


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", action="append", help=f"only these (default {', '.join(PRESETS)})")
    p.add_argument("--heading-deg", type=float, action="append", help="default: 0, 90, 180, 270")
    p.add_argument("--json", type=Path, help="write every case's figures there")
    args = p.parse_args(argv)
    headings = args.heading_deg or HEADINGS_DEG
    rows = []
    ok = True
    print(
        f"cover seen {BAND_DEG[0]:.0f}-{BAND_DEG[1]:.0f} deg up: share of pixels at least "
        f"{CLOUD_ALPHA:.0%} opaque (mean opacity), eye {EYE_AGL_M:.0f} m, headings "
        + ", ".join(f"{h:.0f}" for h in headings)
    )
    print(f"{'preset':<22}{'oktas':>6}{'share':>8}{'mean':>8}{'min-max':>13}{'bar':>7}")
    with Renderer(SceneSettings().ring_texture_px) as renderer:
        for name in args.preset or PRESETS:
            state = WeatherState().apply(load_preset(name, ()))
            figures = [band_cover(cloud_alpha(renderer, state, h)) for h in headings]
            shares = [f[0] for f in figures]
            share, mean = float(np.mean(shares)), float(np.mean([f[1] for f in figures]))
            oktas = max((layer.cover_oktas for layer in state.layers), default=0)
            bar = BARS.get(name)
            ok &= bar is None or share <= bar
            print(
                f"{name:<22}{oktas:>6}{share:>8.2f}{mean:>8.2f}"
                f"{f'{min(shares):.2f}-{max(shares):.2f}':>13}"
                f"{'' if bar is None else f'{bar:.2f}':>7}"
            )
            rows.append(
                {
                    "preset": name,
                    "oktas": oktas,
                    "share": share,
                    "mean_alpha": mean,
                    "by_heading": dict(zip([str(h) for h in headings], shares, strict=True)),
                }
            )
    if args.json is not None:
        args.json.write_text(json.dumps({"band_deg": list(BAND_DEG), "cases": rows}, indent=1))
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
