"""Issue 41, "Horizon under a deck": under overcast-stratus and broken-stratocumulus, at noon
and with the sun 5° up, facing the sun and away, from 2 m above the ground, the band from 1°
below the horizon to 1° above it is never bluer (B/R, by more than 5 %) nor brighter (by more
than 15 %) than the deck 5° above the horizon. In nature a layer carries on into the horizon
haze; today the layers stop 1-2° short of it and leave a strip of clear sky under the deck
(issue 41 item 5)."""

from __future__ import annotations

import pytest
from sky_measure import eye_camera, horizon_band_vs_deck, preset_state, preset_sun, snapshot_linear

from wxsky.render.renderer import Renderer

pytestmark = pytest.mark.gl

EYE_AGL_M = 2.0
# Looking 2° up with a 60° by 34° view: the horizon band and the deck 5° above it are both in
# the picture with room to spare, at about 5 rows a degree.
PITCH_DEG = 2.0
SIZE = (320, 180)
MOST_BLUER = 1.05
MOST_BRIGHTER = 1.15

CASES = [
    pytest.param(preset, moment, facing, id=f"{preset}-{moment}-{facing}")
    for preset in ("overcast-stratus", "broken-stratocumulus")
    for moment in ("noon", "sun+5")
    for facing in ("toward", "away")
]


@pytest.mark.parametrize(("preset", "moment", "facing"), CASES)
def test_the_band_at_the_horizon_is_the_deck_in_haze(
    renderer: Renderer, preset: str, moment: str, facing: str
) -> None:
    sun = preset_sun(preset, None if moment == "noon" else 5.0)
    state = preset_state(preset, sun.time_utc)
    heading = sun.azimuth_deg + (0.0 if facing == "toward" else 180.0)
    camera = eye_camera(state, heading, PITCH_DEG, SIZE, eye_agl_m=EYE_AGL_M)
    m = horizon_band_vs_deck(snapshot_linear(renderer, state, camera), camera, EYE_AGL_M)
    assert m.bluer <= MOST_BLUER and m.brighter <= MOST_BRIGHTER, str(m)
