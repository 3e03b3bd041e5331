"""The sky pass's shipped textures: the PNGs are the generator's output, byte for byte; the
tool's --check catches drift; the loaded arrays have their documented shapes and encodings;
and the star cells' channels mean what sky_textures says (R mean intensity, G flicker rate,
B variance, A phase).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from tool_loader import load_tool

from wxsky.png import encode_png
from wxsky.render.sky_textures import (
    DOME_FILE,
    DOME_NOISE_PX,
    GALAXY_FILE,
    GALAXY_SIZE_PX,
    SKY_FILES,
    STAR_FACE_PX,
    STAR_FILE,
    build_sky_textures,
    dome_noise_texture,
    galaxy_texture,
    star_texture,
)

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "wxsky" / "render" / "data"

U8 = npt.NDArray[np.uint8]


TOOL = load_tool("build_sky_textures")


@pytest.fixture(scope="module")
def generated() -> dict[str, U8]:
    return build_sky_textures()


# -- the shipped files ------------------------------------------------------------------


def test_shipped_files_are_the_generators_output(generated: dict[str, U8]) -> None:
    assert tuple(generated) == SKY_FILES == (STAR_FILE, GALAXY_FILE, DOME_FILE)
    for name, img in generated.items():
        assert name.startswith("sky_") and name.endswith(".png")
        assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 4
        path = DATA / name
        assert path.read_bytes() == encode_png(img), f"{name} is stale: run the tool"
    np.testing.assert_array_equal(star_texture(), generated[STAR_FILE])
    np.testing.assert_array_equal(galaxy_texture(), generated[GALAXY_FILE][..., 0])
    np.testing.assert_array_equal(dome_noise_texture(), generated[DOME_FILE])


def test_generation_is_deterministic(generated: dict[str, U8]) -> None:
    again = build_sky_textures()
    for name, img in generated.items():
        assert again[name].tobytes() == img.tobytes(), name


def test_check_flag_catches_drift(tmp_path: Path) -> None:
    for name in SKY_FILES:
        shutil.copyfile(DATA / name, tmp_path / name)
    assert TOOL.main(["--check"]) == 0  # the package's own files
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 0
    data = bytearray((tmp_path / GALAXY_FILE).read_bytes())
    data[-20] ^= 1  # inside the compressed pixels
    (tmp_path / GALAXY_FILE).write_bytes(bytes(data))
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 1
    shutil.copyfile(DATA / GALAXY_FILE, tmp_path / GALAXY_FILE)
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 0
    (tmp_path / STAR_FILE).unlink()
    assert TOOL.main(["--check", "--out", str(tmp_path)]) == 1


def test_tool_writes_the_files(tmp_path: Path) -> None:
    out = tmp_path / "data"
    assert TOOL.main(["--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(SKY_FILES)
    for name in SKY_FILES:
        assert (out / name).read_bytes() == (DATA / name).read_bytes(), name


# -- what the renderer loads ------------------------------------------------------------


def test_loaded_arrays_have_the_documented_shapes() -> None:
    n = STAR_FACE_PX
    w, h = GALAXY_SIZE_PX
    expected = {
        star_texture: (6 * n, n, 4),
        galaxy_texture: (h, w),
        dome_noise_texture: (DOME_NOISE_PX, DOME_NOISE_PX, 4),
    }
    for load, shape in expected.items():
        arr = load()
        assert arr.shape == shape and arr.dtype == np.uint8, load.__name__
        assert not arr.flags.writeable, load.__name__  # shared through the cache
        assert arr.flags.c_contiguous, load.__name__  # uploaded with tobytes()
        assert load() is arr, load.__name__  # read once


def test_galaxy_file_is_grey_and_opaque(generated: dict[str, U8]) -> None:
    img = generated[GALAXY_FILE]
    assert (img[..., 0] == img[..., 1]).all() and (img[..., 0] == img[..., 2]).all()
    assert (img[..., 3] == 255).all()
    glow = galaxy_texture()
    assert glow.max() == 255  # normalised to its peak
    h = GALAXY_SIZE_PX[1]
    # Brightest along the galactic plane (the middle rows), faint at the poles.
    assert glow[h // 2 - 8 : h // 2 + 8].mean() > 4 * glow[: h // 8].mean()


def test_star_channels_mean_what_they_say() -> None:
    tex = star_texture()
    mean = tex[..., 0]
    has_star = mean > 0
    # R, mean intensity 0..1: mostly dark background (no star in 88-96 % of the cells) ...
    assert 0.88 < 1.0 - has_star.mean() < 0.96
    stars = tex[has_star].astype(int)
    r, g, b, a = (stars[:, k] for k in range(4))
    # ... and some bright stars among many faint ones.
    assert (r >= 200).sum() >= 10
    assert np.median(r) < 32
    # An empty cell is all zero: no flicker, variance or phase without a star.
    assert not tex[~has_star].any()
    # G, flicker rate (0.15-1 of STAR_RATE_SCALE_HZ): spread over its range, never zero.
    assert 0.15 * 255 - 1 <= g.min() < 45 and g.max() > 250
    assert np.histogram(g, bins=8, range=(38, 256))[0].min() > 0.08 * len(g)
    # B, variance: 0.15-0.45 of the mean, so the brightness R + B·sin stays above zero.
    assert (b <= r).all()
    # A, phase 0..1: spread evenly over the whole cycle.
    assert a.min() < 3 and a.max() > 252
    assert np.histogram(a, bins=8, range=(0, 256))[0].min() > 0.1 * len(a)
