"""Show a weather change as the daemon applies it: one PNG with a row of snapshots taken at
equal intervals while the applied weather moves from one METAR to the next at the default
[transition] rates (docs/transition.png).

    .venv/bin/python tools/gallery/transition_strip.py [--out docs/transition.png] [--size 240x135]

The two reports are real-shaped METARs for Zurich: fair cumulus, then a low overcast moving
in. The caption row of numbers is printed, not drawn: minutes and the applied cover per layer.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wxsky.app.snapshot import take_snapshot
from wxsky.cli.common import parse_size
from wxsky.png import write_png
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.scene.layout import SceneSettings
from wxsky.settings.config import TransitionSection
from wxsky.settings.presets import load_preset
from wxsky.weather.metar import decode
from wxsky.weather.metar_clouds import metar_to_patch
from wxsky.weather.state import WeatherState
from wxsky.weather.transition import step_toward

BEFORE = "LSZH 081150Z 24008KT 9999 FEW045 SCT060 24/12 Q1016"
AFTER = "LSZH 081250Z 26012KT 6000 -RA BKN012 OVC025 17/14 Q1011"
FIELD_ELEVATION_M = 432.0
FRAMES = 8
MINUTES_PER_FRAME = 0.75


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("docs/transition.png"))
    p.add_argument("--size", default="240x135")
    args = p.parse_args()
    w, h = parse_size(args.size)
    base = WeatherState().apply(load_preset("fair-cumulus"))
    applied = base.apply(_patch(BEFORE))
    target = base.apply(_patch(AFTER))
    rates = TransitionSection().rates()
    sheet = np.full((h, FRAMES * w, 4), 255, np.uint8)
    settings = SceneSettings()
    with Renderer(settings.ring_texture_px) as renderer:
        for n in range(FRAMES):
            cam = Camera((0.0, 0.0, applied.observer.alt_m + 2.0), 200.0, 14.0, 0.0, 70.0, w, h)
            sheet[:, n * w : (n + 1) * w] = take_snapshot(applied, cam, settings, renderer).image
            covers = ", ".join(
                f"{lay.type.wire_name} {lay.cover_oktas:.1f}/8" for lay in applied.layers
            )
            print(f"t = {n * MINUTES_PER_FRAME:4.2f} min: {covers}")
            for _ in range(round(MINUTES_PER_FRAME * 60)):  # one-second steps, as the daemon
                applied = step_toward(applied, target, 1.0, rates)
    write_png(args.out, sheet)
    print(f"wrote {args.out}: {FRAMES} frames, {MINUTES_PER_FRAME} min apart")
    return 0


def _patch(report: str):  # type: ignore[no-untyped-def]
    metar = decode(report, year=2026, month=7).require_usable()
    return metar_to_patch(metar, field_elevation_m=FIELD_ELEVATION_M)


if __name__ == "__main__":
    raise SystemExit(main())
