"""Structure in an overcast deck's base: the local spread of its luminance, seen from below.

    .venv/bin/python tools/bench/deck_structure.py [--preset NAME ...] [--json FILE]
        [--png FILE]

Issue 42's "decks" check. Each case is the daemon's picture (`take_snapshot`) at 640x360 of
the preset's sky from 2 m above its observer, looking 30 deg up with a 60 deg field of view,
at the day's noon and with the sun 5 deg up on the preset's own morning, facing the sun and
facing away. The picture's luma (Rec. 709 weights on its display values, 0-255) is blurred
by a 9x9 box and by a 61x61 box; the figure is the standard deviation of their difference
over the pixels whose 61x61 box lies wholly in the picture: the patches and undulations a
few to a few tens of pixels across that a grey sheet lacks (an even gradient, or noise finer
than 9 pixels, leaves it near 0). The issue's bar: at least 1.5 for overcast-stratus.
`--png` writes the first case's picture beside its band-passed luma (x 8, mid-grey 0).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tools.bench.banding import LUMA  # noqa: E402
from tools.gallery import light_sheet as sheet  # noqa: E402
from wxsky.app.snapshot import take_snapshot  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

F64 = npt.NDArray[np.float64]

PRESETS = ("overcast-stratus",)
SIZE = (640, 360)
PITCH_DEG = 30.0
FOV_DEG = 60.0
EYE_AGL_M = 2.0
SMALL_PX, LARGE_PX = 9, 61
BAR = 1.5
MOMENTS: tuple[tuple[str, float | None], ...] = (("noon", None), ("sun+5", 5.0))


def box_blur(image: F64, size: int) -> F64:
    """(H - size + 1, W - size + 1) the mean of every size x size box wholly in the image."""
    c = np.cumsum(np.cumsum(np.pad(image, ((1, 0), (1, 0))), axis=0), axis=1)
    out: F64 = (c[size:, size:] - c[:-size, size:] - c[size:, :-size] + c[:-size, :-size]) / (
        size * size
    )
    return out


def band_pass(luma: F64) -> F64:
    """The 9x9 box blur less the 61x61 one, over the pixels where the larger fits."""
    small = box_blur(luma, SMALL_PX)
    large = box_blur(luma, LARGE_PX)
    m = (LARGE_PX - SMALL_PX) // 2
    out: F64 = small[m : m + large.shape[0], m : m + large.shape[1]] - large
    return out


def structure(rgb: npt.NDArray[np.uint8]) -> tuple[float, F64]:
    luma = rgb[..., :3].astype(np.float64) @ LUMA
    passed = band_pass(luma)
    return float(np.std(passed)), passed


def picture(renderer: Renderer, state: WeatherState, heading_deg: float) -> npt.NDArray[np.uint8]:
    camera = Camera(
        position_m=(0.0, 0.0, state.observer.alt_m + EYE_AGL_M),
        heading_deg=heading_deg,
        pitch_deg=PITCH_DEG,
        fov_deg=FOV_DEG,
        width_px=SIZE[0],
        height_px=SIZE[1],
    )
    image: npt.NDArray[np.uint8] = take_snapshot(state, camera, SceneSettings(), renderer).image
    return image


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", action="append", help=f"only these (default {', '.join(PRESETS)})")
    p.add_argument("--json", type=Path, help="write every case's figure there")
    p.add_argument("--png", type=Path, help="the first case and its band-passed luma")
    args = p.parse_args(argv)
    rows = []
    ok = True
    first: npt.NDArray[np.uint8] | None = None
    print(
        f"deck structure: std of the {SMALL_PX}x{SMALL_PX} less the {LARGE_PX}x{LARGE_PX} box "
        f"blur of the luma (0-255), {SIZE[0]}x{SIZE[1]}, {PITCH_DEG:.0f} deg up (bar {BAR})"
    )
    print(f"{'preset':<20}{'moment':<8}{'facing':<20}{'structure':>10}")
    with Renderer(SceneSettings().ring_texture_px) as renderer:
        for name in args.preset or PRESETS:
            base = WeatherState().apply(load_preset(name, ()))
            obs = base.observer
            for moment, elevation in MOMENTS:
                sun = sheet.sun_time(base.time_utc, obs.lat_deg, obs.lon_deg, elevation)
                state = dataclasses.replace(base, time_utc=sun.time_utc)
                for facing, turn in (("toward the sun", 0.0), ("away from the sun", 180.0)):
                    image = picture(renderer, state, sun.azimuth_deg + turn)
                    figure, passed = structure(image)
                    if first is None:
                        first = _sheet(image, passed)
                    ok &= figure >= BAR
                    print(f"{name:<20}{moment:<8}{facing:<20}{figure:>10.2f}")
                    rows.append(
                        {
                            "preset": name,
                            "moment": moment,
                            "facing": facing,
                            "time_utc": sun.time_utc.isoformat(),
                            "structure": figure,
                        }
                    )
    if args.json is not None:
        args.json.write_text(json.dumps({"bar": BAR, "cases": rows}, indent=1) + "\n")
    if args.png is not None and first is not None:
        from wxsky.png import write_png

        write_png(args.png, first)
    return 0 if ok else 1


def _sheet(image: npt.NDArray[np.uint8], passed: F64) -> npt.NDArray[np.uint8]:
    h, w = image.shape[:2]
    grey = np.clip(128.0 + 8.0 * passed, 0.0, 255.0).astype(np.uint8)
    pad = np.full((h, w, 4), 255, np.uint8)
    pad[..., :3] = 0
    m = (LARGE_PX - 1) // 2
    pad[m : m + grey.shape[0], m : m + grey.shape[1], :3] = grey[..., None]
    return np.concatenate([image, pad], axis=1)


if __name__ == "__main__":
    raise SystemExit(main())
