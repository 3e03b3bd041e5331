"""Whole-picture regression: fixed snapshots compared with the goldens in tests/golden/.

The goldens are written only by tools/generate/regen_goldens.py (see tests/golden/README.md). A
mismatch leaves tests/_failures/<case>_{actual,expected,diff}.png behind and names them.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import pytest
from tool_loader import load_tool

from wxsky.png import read_png, write_png

if TYPE_CHECKING:
    from wxsky.render.renderer import Renderer

ROOT = Path(__file__).resolve().parents[1]
GOLDEN_DIR = ROOT / "tests" / "golden"
FAILURE_DIR = ROOT / "tests" / "_failures"

# Tolerances, per 8-bit channel: renderers (llvmpipe versions, GPU drivers) differ in the last
# bits of filtering and blending, not in where the clouds are.
MAX_MEAN_ABS_DIFF = 1.0
FAR_OFF_LEVELS = 16
MAX_FAR_OFF_SHARE = 0.005
DIFF_GAIN = 8


TOOL = load_tool("generate/regen_goldens")
CASES = {case.name: case for case in TOOL.CASES}


def compare_images(
    name: str,
    actual: npt.NDArray[np.uint8],
    expected: npt.NDArray[np.uint8],
    failure_dir: Path,
) -> None:
    """Assert two RGBA8 pictures agree within the tolerances; on failure write the actual,
    expected and amplified-difference pictures and name them in the message."""
    if actual.shape != expected.shape:
        raise AssertionError(f"{name}: shape {actual.shape} != golden {expected.shape}")
    diff = np.abs(actual.astype(np.int16) - expected.astype(np.int16))
    mean = float(diff.mean())
    far_off = float((diff.max(axis=2) > FAR_OFF_LEVELS).mean())
    if mean <= MAX_MEAN_ABS_DIFF and far_off <= MAX_FAR_OFF_SHARE:
        return
    failure_dir.mkdir(parents=True, exist_ok=True)
    paths = {kind: failure_dir / f"{name}_{kind}.png" for kind in ("actual", "expected", "diff")}
    amplified = np.clip(diff * DIFF_GAIN, 0, 255).astype(np.uint8)
    amplified[..., 3] = 255
    write_png(paths["actual"], actual)
    write_png(paths["expected"], expected)
    write_png(paths["diff"], amplified)
    raise AssertionError(
        f"{name}: differs from its golden: mean |diff| {mean:.3f} (limit {MAX_MEAN_ABS_DIFF}), "
        f"{far_off:.2%} of pixels off by more than {FAR_OFF_LEVELS} "
        f"(limit {MAX_FAR_OFF_SHARE:.1%}). Wrote {paths['actual']}, {paths['expected']} and "
        f"{paths['diff']} (x{DIFF_GAIN}). If the change is intended, regenerate with "
        f"tools/generate/regen_goldens.py {name}"
    )


# -- the comparison itself (no GL) --------------------------------------------------------


def _picture(seed: int = 0) -> npt.NDArray[np.uint8]:
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, size=(20, 30, 4), dtype=np.uint8)
    img[..., 3] = 255
    return img


def test_compare_accepts_identical_and_slightly_different(tmp_path: Path) -> None:
    a = _picture()
    compare_images("same", a, a.copy(), tmp_path)
    b = a.astype(int)
    b[::2, :, 0] += np.where(b[::2, :, 0] < 255, 1, -1)  # last-bit noise on half the rows
    compare_images("noise", a, b.astype(np.uint8), tmp_path)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    "damage",
    [
        "block",  # a few pixels very wrong: trips the far-off share
        "shift",  # everything a little off: trips the mean
    ],
)
def test_compare_rejects_and_writes_failure_images(tmp_path: Path, damage: str) -> None:
    a = _picture()
    b = a.copy()
    if damage == "block":
        b[5:7, 5:8, :3] = 255 - b[5:7, 5:8, :3]  # 6 of 600 pixels = 1 %
    else:
        b[..., :3] = np.clip(b[..., :3].astype(int) + 3, 0, 255).astype(np.uint8)
    with pytest.raises(AssertionError) as info:
        compare_images("case", b, a, tmp_path)
    message = str(info.value)
    for kind in ("actual", "expected", "diff"):
        path = tmp_path / f"case_{kind}.png"
        assert str(path) in message
        assert path.exists()
    np.testing.assert_array_equal(read_png(tmp_path / "case_actual.png"), b)
    np.testing.assert_array_equal(read_png(tmp_path / "case_expected.png"), a)
    diff = read_png(tmp_path / "case_diff.png")
    assert np.all(diff[..., 3] == 255)
    if damage == "block":
        assert diff[5, 5, :3].max() > 0 and not diff[0, 0, :3].any()


def test_compare_rejects_a_size_change(tmp_path: Path) -> None:
    with pytest.raises(AssertionError, match="shape"):
        compare_images("size", _picture()[:10], _picture(), tmp_path)


# -- the goldens --------------------------------------------------------------------------


def test_every_case_has_a_golden_and_the_readme_names_the_renderer() -> None:
    readme = (GOLDEN_DIR / "README.md").read_text(encoding="utf-8")
    assert "Made on:" in readme and "tools/generate/regen_goldens.py" in readme
    for name in CASES:
        assert (GOLDEN_DIR / f"{name}.png").is_file(), f"run tools/generate/regen_goldens.py {name}"
        assert f"`{name}.png`" in readme


@pytest.mark.parametrize("name", list(CASES))
def test_golden(renderer: Renderer, name: str) -> None:
    path = GOLDEN_DIR / f"{name}.png"
    if not path.is_file():
        pytest.fail(f"missing golden {path}: create it with tools/generate/regen_goldens.py {name}")
    expected = read_png(path)
    actual = TOOL.render_case(CASES[name], renderer)
    assert actual.shape == (TOOL.HEIGHT, TOOL.WIDTH, 4)
    assert np.all(actual[..., 3] == 255)
    compare_images(name, actual, expected, FAILURE_DIR)


def test_goldens_show_sky_and_clouds() -> None:
    """A sanity check on the goldens themselves: blue sky above a dark ground band, cloudy
    cases greyer than the clear one (guards against regenerating garbage)."""
    images = {name: read_png(GOLDEN_DIR / f"{name}.png").astype(int) for name in CASES}
    for name, img in images.items():
        if CASES[name].eye_alt_m is not None or name.endswith(("-dawn", "-night")):
            continue  # see test_the_other_goldens_show_their_moment
        top, bottom = img[:10, :, :3].mean(axis=(0, 1)), img[-2:, :, :3].mean(axis=(0, 1))
        assert bottom.sum() < top.sum(), f"{name}: ground should be darker than the sky"
        assert img[..., :3].std() > 5.0, f"{name}: featureless"
    clear = images["clear"][:100, :, :3]
    assert np.all(clear[..., 2] > clear[..., 0])  # blue everywhere above the horizon

    def saturation(img: np.ndarray) -> float:
        rgb = img[:100, :, :3]
        return float((rgb.max(axis=2) - rgb.min(axis=2)).mean())

    assert saturation(images["overcast-stratus"]) < 0.4 * saturation(images["clear"])
    assert saturation(images["fair-cumulus"]) < saturation(images["clear"])


def test_the_other_goldens_show_their_moment() -> None:
    def rgb(name: str) -> np.ndarray:
        return read_png(GOLDEN_DIR / f"{name}.png")[..., :3].astype(float)

    # Night: a dark sky with stars, each a few bright pixels.
    night = rgb("clear-night")
    assert night.mean() < 30.0
    stars = night.max(axis=2) > np.median(night.max(axis=2)) + 60.0
    assert 30 < stars.sum() < 0.02 * stars.size
    # Under the deck at dawn: dim and grey, not orange (the deck's underside is lit through it).
    deck = rgb("overcast-stratus-dawn")[:60]
    assert deck.mean() < 90.0 and deck[..., 0].mean() < 1.15 * deck[..., 2].mean()
    # Above the deck: blue sky over a bright white top.
    above = rgb("overcast-stratus-above")
    sky, top = above[:6].mean(axis=(0, 1)), above[-40:].mean(axis=(0, 1))
    assert sky[2] > 1.3 * sky[0] and top.min() > 170.0 and top[2] < 1.15 * top[0]
    # Dusk: cumulus lit orange by the low sun.
    dusk = rgb("scattered-cumulus-dusk")
    assert dusk[..., 0].mean() > 1.2 * dusk[..., 2].mean()


@pytest.mark.parametrize("name", list(CASES))
def test_each_case_shows_the_moment_its_name_says(name: str) -> None:
    # Dawn and dusk: the sun 3-5° up, ahead of the camera; night: 20° and more down.
    from wxsky.scene.sky import sun_position

    case = CASES[name]
    obs = TOOL.case_state(case).observer
    sun = sun_position(case.time_utc, obs.lat_deg, obs.lon_deg)
    if name.endswith(("-dawn", "-dusk")):
        assert 3.0 <= sun.elevation_deg <= 5.0
        assert abs((sun.azimuth_deg - case.heading_deg + 180.0) % 360.0 - 180.0) < 30.0
        assert (sun.azimuth_deg < 180.0) == name.endswith("-dawn")
    elif name.endswith("-night"):
        assert sun.elevation_deg <= -20.0
    else:
        assert sun.elevation_deg > 30.0
