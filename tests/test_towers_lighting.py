"""Slice lighting of tower volumes (wxsky/towers/lighting.py, Domański's Algorithm 1): light
falls off from the lit side through a uniform volume, a dense blob shadows the cells its ray
reaches and not the ones beside, and an empty volume is lit everywhere."""

from __future__ import annotations

import numpy as np
import pytest

from wxsky.towers.lighting import slice_light

SHAPE = (24, 20, 22)  # z, y, x


def test_an_empty_volume_is_lit_everywhere() -> None:
    for light in ((0.0, 0.0, 1.0), (1.0, 0.3, 0.2), (-0.2, -1.0, 0.5)):
        assert np.allclose(slice_light(np.zeros(SHAPE, np.float32), light), 1.0)


@pytest.mark.parametrize(
    "light, axis, lit_end",
    [
        ((1.0, 0.0, 0.0), 2, -1),  # from +x: the high-x side is lit
        ((-1.0, 0.0, 0.0), 2, 0),
        ((0.0, 1.0, 0.0), 1, -1),
        ((0.0, 0.0, 1.0), 0, -1),  # sun overhead: the top is lit
        ((0.0, 0.0, -1.0), 0, 0),
    ],
)
def test_light_falls_from_the_lit_side_to_the_far_side(
    light: tuple[float, float, float], axis: int, lit_end: int
) -> None:
    lit = slice_light(np.ones(SHAPE, np.float32), light)
    line = np.moveaxis(lit, axis, 0)[:, 10, 10]
    if lit_end == -1:
        line = line[::-1]
    assert np.all(np.diff(line) < 0.0)  # strictly darker with every cell from the light
    # Beer-Lambert through a uniform volume: each cell keeps exp(-0.35) of the one before.
    assert line[1] / line[0] == pytest.approx(np.exp(-0.35), rel=1e-4)
    assert line[-1] < 0.01


def test_a_blob_shadows_along_the_oblique_ray_only() -> None:
    density = np.zeros(SHAPE, np.float32)
    density[13:16, 9:12, 13:16] = 4.0  # dense, centred at z 14, y 10, x 14
    lit = slice_light(density, (1.0, 0.0, 1.0))  # 45 degrees up toward +x
    # The ray from (z 8, x 8) toward the light runs through the blob; from straight below
    # the blob (z 8, x 14) and from beside it on the light's side it does not.
    assert lit[8, 10, 8] < 0.1
    assert lit[8, 10, 14] > 0.9 and lit[14, 10, 20] > 0.9
    assert lit[14, 10, 14] < lit[14, 10, 15] < 1.0  # deeper in the blob, darker


def test_a_light_with_no_direction_is_an_error() -> None:
    with pytest.raises(ValueError, match="no length"):
        slice_light(np.zeros(SHAPE, np.float32), (0.0, 0.0, 0.0))
