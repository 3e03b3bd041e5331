"""Flat cumulus bases in profile: where each cloud's lowest visible pixel lies against its base.

    .venv/bin/python tools/bench/flat_bases.py [--preset NAME ...] [--heading-deg DEG ...]
        [--below-m 500] [--json FILE] [--png FILE]

Issue 42's "flat bases" check. For each cumulus preset the eye stands `--below-m` under the
layer's base, looking 4 deg up (1280x720, 60 deg wide) at every heading asked for; every cloud
whose centre is 10-20 km away and in the picture is drawn alone (direct mode: its own sprites,
with the daemon's shading, through the real renderer), and its lowest pixel at least 10 %
opaque is found. Its elevation is compared with the elevation at which the layer's base
altitude is seen at the cloud's distance: a cloud passes when the two are within 0.1 deg.
Rounded bases hang below the line, a base eaten away by soft sprites sits above it. The bar:
at least 80 % of the clouds of every preset pass. `--png` writes the picture of the first
case with each cloud's lowest pixel marked (green: within, red: outside) over the base line.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tools.bench.banding import ray_elevation_deg  # noqa: E402
from wxsky.engine.stages import SkyEngine  # noqa: E402
from wxsky.render.renderer import Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import CloudType, WeatherState  # noqa: E402

F64 = npt.NDArray[np.float64]

PRESETS = ("fair-cumulus", "scattered-cumulus", "towering-cumulus")
HEADINGS_DEG = (0.0, 90.0, 180.0, 270.0)
SIZE = (1280, 720)
FOV_DEG = 60.0
PITCH_DEG = 4.0
RANGE_M = (10_000.0, 20_000.0)
VISIBLE_ALPHA = 0.1
TOLERANCE_DEG = 0.1
BAR = 0.8


@dataclasses.dataclass(frozen=True)
class CloudBase:
    cloud_id: int
    distance_m: float  # horizontal, eye to the cloud's axis
    column: int  # where its lowest pixel is
    row: int
    lowest_deg: float  # that pixel's elevation
    base_deg: float  # the base altitude's elevation at the cloud's distance

    @property
    def error_deg(self) -> float:
        return self.lowest_deg - self.base_deg

    @property
    def flat(self) -> bool:
        return abs(self.error_deg) <= TOLERANCE_DEG


def cumulus_base_m(state: WeatherState) -> float:
    for layer in state.layers:
        if layer.type == CloudType.CUMULUS:
            return float(layer.base_m)
    raise ValueError("the weather has no cumulus layer")


def measure_case(
    renderer: Renderer,
    state: WeatherState,
    heading_deg: float,
    below_m: float,
    settings: SceneSettings,
    cut: bool = True,
) -> tuple[list[CloudBase], npt.NDArray[np.uint8]]:
    """Every cloud 10-20 km away in the picture, drawn alone; and the whole picture.
    `cut=False` draws the sprites without their flat base's cut (what the test compares)."""
    base_m = cumulus_base_m(state)
    camera = Camera(
        position_m=(0.0, 0.0, base_m - below_m),
        heading_deg=heading_deg,
        pitch_deg=PITCH_DEG,
        fov_deg=FOV_DEG,
        width_px=SIZE[0],
        height_px=SIZE[1],
    )
    engine = SkyEngine(state, camera, settings, clock_rate=0.0, render_mode="direct")
    plan = engine.advance(0.0)
    frame = dataclasses.replace(plan.frame, towers=(), near_far_count=0, near_front=None)
    if not cut:
        uncut = dataclasses.replace(
            frame.near.sprites, base_m=np.full(len(frame.near), np.nan, np.float32)
        )
        frame = dataclasses.replace(frame, near=dataclasses.replace(frame.near, sprites=uncut))
    renderer.render_frame(frame)
    whole = renderer.read("near")
    elevation = ray_elevation_deg(SIZE, PITCH_DEG, FOV_DEG)
    right, _, fwd = camera.basis()
    tan_x = camera.tan_half_fov_x
    near = frame.near
    s = near.sprites
    ids, inverse = np.unique(s.cloud_id, return_inverse=True)
    found: list[CloudBase] = []
    for k, cloud_id in enumerate(ids):
        index = np.flatnonzero(inverse == k)
        centre = s.centre_m[index].mean(axis=0) - np.asarray(camera.position_m)
        distance = float(math.hypot(centre[0], centre[1]))
        ahead = float(centre @ fwd)
        if not RANGE_M[0] <= distance <= RANGE_M[1] or ahead <= 0.0:
            continue
        column = (float(centre @ right) / ahead / tan_x + 1.0) / 2.0 * SIZE[0]
        if not 0.1 * SIZE[0] <= column <= 0.9 * SIZE[0]:
            continue
        renderer.render_frame(dataclasses.replace(frame, near=near.take(index)))
        alpha = renderer.read("near")[..., 3].astype(np.float64) / 255.0
        rows, cols = np.nonzero(alpha >= VISIBLE_ALPHA)
        if len(rows) == 0:
            continue  # still forming: nothing to see
        low = int(np.argmax(rows))
        row, col = int(rows[low]), int(cols[low])
        found.append(
            CloudBase(
                cloud_id=int(cloud_id),
                distance_m=distance,
                column=col,
                row=row,
                lowest_deg=float(elevation[row, col]),
                base_deg=math.degrees(math.atan2(below_m, distance)),
            )
        )
    return found, whole


def marked(picture: npt.NDArray[np.uint8], bases: Sequence[CloudBase]) -> npt.NDArray[np.uint8]:
    """The near layer over black, each cloud's lowest pixel crossed in green (flat) or red."""
    rgb = picture[..., :3].astype(np.float64)
    out = np.clip(rgb, 0, 255).astype(np.uint8)
    for b in bases:
        colour = (40, 220, 40) if b.flat else (230, 40, 40)
        r0, r1 = max(0, b.row - 1), min(SIZE[1], b.row + 2)
        c0, c1 = max(0, b.column - 6), min(SIZE[0], b.column + 7)
        out[r0:r1, c0:c1] = colour
        out[max(0, b.row - 6) : min(SIZE[1], b.row + 7), b.column] = colour
    alpha = np.full((*out.shape[:2], 1), 255, np.uint8)
    return np.concatenate([out, alpha], axis=2)


def run(
    presets: Sequence[str], headings: Sequence[float], below_m: float
) -> tuple[dict[str, list[CloudBase]], npt.NDArray[np.uint8] | None]:
    settings = SceneSettings()
    first: npt.NDArray[np.uint8] | None = None
    out: dict[str, list[CloudBase]] = {}
    with Renderer(settings.ring_texture_px, near_scale=1.0) as renderer:
        for name in presets:
            state = WeatherState().apply(load_preset(name, ()))
            out[name] = []
            for heading in headings:
                bases, whole = measure_case(renderer, state, heading, below_m, settings)
                if first is None:
                    first = marked(whole, bases)
                out[name].extend(bases)
    return out, first


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", action="append", help=f"only these (default {', '.join(PRESETS)})")
    p.add_argument("--heading-deg", type=float, action="append", help="default: 0, 90, 180, 270")
    p.add_argument("--below-m", type=float, default=500.0, help="eye under the base (500)")
    p.add_argument("--json", type=Path, help="write every cloud's figures there")
    p.add_argument("--png", type=Path, help="the first case, lowest pixels marked")
    args = p.parse_args(argv)
    found, first = run(args.preset or PRESETS, args.heading_deg or HEADINGS_DEG, args.below_m)
    print(
        f"flat bases: lowest pixel within {TOLERANCE_DEG} deg of the base line, clouds "
        f"{RANGE_M[0] / 1000:.0f}-{RANGE_M[1] / 1000:.0f} km, eye {args.below_m:.0f} m below "
        f"(bar {BAR:.0%})"
    )
    print(f"{'preset':<20}{'clouds':>8}{'flat':>8}{'median err deg':>16}{'p90 |err|':>11}")
    ok = True
    for name, bases in found.items():
        errors = np.array([b.error_deg for b in bases])
        share = float(np.mean([b.flat for b in bases])) if bases else math.nan
        ok &= share >= BAR
        print(
            f"{name:<20}{len(bases):>8}{share:>8.0%}"
            f"{float(np.median(errors)) if len(errors) else math.nan:>16.3f}"
            f"{float(np.percentile(np.abs(errors), 90)) if len(errors) else math.nan:>11.3f}"
        )
    if args.json is not None:
        args.json.write_text(
            json.dumps(
                {name: [dataclasses.asdict(b) for b in bases] for name, bases in found.items()},
                indent=1,
            )
            + "\n"
        )
    if args.png is not None and first is not None:
        from wxsky.png import write_png

        write_png(args.png, first)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
