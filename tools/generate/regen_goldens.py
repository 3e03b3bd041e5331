#!/usr/bin/env python3
"""Regenerate the golden images that tests/test_golden.py compares renders against.

    .venv/bin/python tools/generate/regen_goldens.py            # all cases
    .venv/bin/python tools/generate/regen_goldens.py clear      # just the named ones

Each case is a shipped weather preset rendered by `wxsky.app.snapshot.take_snapshot` (the same
engine, renderer passes and compositor as daemon + host) at a fixed time, camera and size.
The PNGs go to tests/golden/<case>.png, and tests/golden/README.md records the GL renderer
they were made on. Only this tool writes goldens; the test never does. Regenerate them when
a change to the picture is intended, look at every PNG before committing, and say why in the
commit message.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

from wxsky.app.snapshot import take_snapshot  # noqa: E402
from wxsky.png import write_png  # noqa: E402
from wxsky.render.context import describe  # noqa: E402
from wxsky.render.renderer import NEAR_SCALE, Renderer  # noqa: E402
from wxsky.scene.camera import Camera  # noqa: E402
from wxsky.scene.layout import SceneSettings  # noqa: E402
from wxsky.settings.presets import load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

GOLDEN_DIR = ROOT / "tests" / "golden"
TIME_UTC = datetime(2026, 6, 21, 14, 0, 0, tzinfo=UTC)
WIDTH, HEIGHT = 240, 135
FOV_DEG = 60.0
EYE_ABOVE_GROUND_M = 2.0
RING_PX = 128
# The goldens hold Roden & Parberry's sky, as drawn before issue 41 made the physical
# atmosphere the default; a physical set is for whoever regenerates them to decide.
SETTINGS = SceneSettings(ring_texture_px=RING_PX, sky="roden-parberry")


@dataclasses.dataclass(frozen=True)
class Case:
    name: str
    preset: str
    heading_deg: float = 200.0
    pitch_deg: float = 15.0
    time_utc: datetime = TIME_UTC
    eye_alt_m: float | None = None  # MSL; None: EYE_ABOVE_GROUND_M over the observer


# Every preset is at Zurich; the twilight cases face the sun 3-5° up, the night one has the
# sun 20° and more down (tests/test_golden.py checks both).
CASES = (
    Case("fair-cumulus", "fair-cumulus"),
    Case("overcast-stratus", "overcast-stratus"),
    Case("clear", "clear"),
    Case("broken-stratocumulus", "broken-stratocumulus"),
    Case(
        "overcast-stratus-dawn",
        "overcast-stratus",
        heading_deg=60.0,
        time_utc=datetime(2026, 6, 21, 4, 5, tzinfo=UTC),
    ),
    Case(
        "overcast-stratus-above",
        "overcast-stratus",
        pitch_deg=-15.0,
        eye_alt_m=2600.0,
    ),
    Case(
        "scattered-cumulus-dusk",
        "scattered-cumulus",
        heading_deg=300.0,
        pitch_deg=10.0,
        time_utc=datetime(2026, 6, 21, 18, 50, tzinfo=UTC),
    ),
    Case(
        "clear-night",
        "clear",
        heading_deg=180.0,
        pitch_deg=40.0,
        time_utc=datetime(2026, 11, 18, 20, 0, tzinfo=UTC),
    ),
)


def case_state(case: Case) -> WeatherState:
    """The preset's weather at the case's time."""
    state = WeatherState().apply(load_preset(case.preset))
    return dataclasses.replace(state, time_utc=case.time_utc)


def case_camera(case: Case, state: WeatherState) -> Camera:
    eye_m = state.observer.alt_m + EYE_ABOVE_GROUND_M if case.eye_alt_m is None else case.eye_alt_m
    return Camera(
        position_m=(0.0, 0.0, eye_m),
        heading_deg=case.heading_deg,
        pitch_deg=case.pitch_deg,
        fov_deg=FOV_DEG,
        width_px=WIDTH,
        height_px=HEIGHT,
    )


def render_case(case: Case, renderer: Renderer) -> npt.NDArray[np.uint8]:
    """The composited (H, W, 4) picture of one case."""
    if renderer.ring_px != RING_PX or renderer.near_scale != NEAR_SCALE:
        raise ValueError(
            f"golden renders need ring_px={RING_PX} and near_scale={NEAR_SCALE}, got "
            f"{renderer.ring_px} and {renderer.near_scale}"
        )
    state = case_state(case)
    return take_snapshot(state, case_camera(case, state), SETTINGS, renderer).image


def golden_path(case: Case) -> Path:
    return GOLDEN_DIR / f"{case.name}.png"


def _readme(renderer_name: str) -> str:
    rows = "\n".join(
        f"| `{c.name}.png` | `{c.preset}` | {c.time_utc:%Y-%m-%dT%H:%MZ} | "
        f"{'ground' if c.eye_alt_m is None else f'{c.eye_alt_m:g} m'} | {c.heading_deg:g}° | "
        f"{c.pitch_deg:g}° |"
        for c in CASES
    )
    return f"""# Golden images

Reference pictures for `tests/test_golden.py`: each is a shipped preset rendered through
`wxsky.app.snapshot.take_snapshot` (engine, renderer and the reference compositor, as daemon +
host) and compared with a tolerance (mean absolute difference and share of pixels far off).

Made on: **{renderer_name}** (headless EGL), ring textures {RING_PX} px, near layer at
{NEAR_SCALE:g} scale, {WIDTH}x{HEIGHT} px, horizontal fov {FOV_DEG:g}°, preset seeds; the eye
{EYE_ABOVE_GROUND_M:g} m above the observer ("ground") or at the altitude given.

| file | preset | time | eye | heading | pitch |
|---|---|---|---|---|---|
{rows}

## Regenerating

Only when a change to the picture is intended:

```sh
.venv/bin/python tools/generate/regen_goldens.py          # all cases, or name some
```

then look at every PNG and say in the commit why they changed. The test never writes here;
on a mismatch it writes `tests/_failures/<case>_{{actual,expected,diff}}.png` (diff amplified
8x) and names them in the assertion message.
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("cases", nargs="*", help="case names (default: all)")
    args = parser.parse_args(argv)
    known = {c.name: c for c in CASES}
    unknown = [n for n in args.cases if n not in known]
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)} (known: {', '.join(known)})")
    chosen = [known[n] for n in args.cases] if args.cases else list(CASES)
    with Renderer(ring_texture_px=RING_PX) as renderer:
        renderer_name = describe(renderer.ctx)
        for case in chosen:
            image = render_case(case, renderer)
            write_png(golden_path(case), image)
            print(f"wrote {golden_path(case).relative_to(ROOT)}")
    (GOLDEN_DIR / "README.md").write_text(_readme(renderer_name), encoding="utf-8")
    print(f"renderer: {renderer_name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
