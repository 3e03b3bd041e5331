"""The cloud texture sheet: the shipped PNGs hold the generator's output, pixel for pixel, on
any machine (not byte for byte: zlib builds differ); every mip level keeps its cells apart;
and each of Wang's categories measures like what it claims to be. Figures in comments are
what the shipped sheet measures.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import moderngl
import numpy as np
import numpy.typing as npt
import pytest
from png_helpers import recompressed
from tool_loader import load_tool

from wxsky.png import encode_png, read_png
from wxsky.render.renderer import Renderer
from wxsky.render.sheet_textures import build_levels
from wxsky.render.sprite_sheet import (
    CELL_PX,
    MARGIN_PX,
    MIP_LEVELS,
    SHEET_PX,
    level_filename,
    level_margin,
    load_sheet,
)
from wxsky.scene.texture_slots import SHEET_CELLS, TEX_FLAT_BOTTOM, TEX_FOG, TEX_PUFFY, TEX_WISPY

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "wxsky" / "render" / "data"
LUMA = np.array([0.2126, 0.7152, 0.0722])

F64 = npt.NDArray[np.float64]
U8 = npt.NDArray[np.uint8]


TOOL = load_tool("generate/build_sprite_sheet")


@pytest.fixture(scope="module")
def generated() -> list[U8]:
    return build_levels()


def _digest(levels: list[U8]) -> str:
    h = hashlib.sha256()
    for level in levels:
        h.update(level.tobytes())
    return h.hexdigest()


def _cell(slot: int, level: int = 0) -> F64:
    """One texture of the shipped sheet as straight RGBA floats 0..1."""
    img = load_sheet()[level]
    s = img.shape[0] // SHEET_CELLS
    r, c = divmod(slot, SHEET_CELLS)
    return img[r * s : (r + 1) * s, c * s : (c + 1) * s].astype(np.float64) / 255.0


def _alpha(slot: int) -> F64:
    return _cell(slot)[..., 3]


def _premultiplied(img: U8) -> F64:
    f = img.astype(np.float64) / 255.0
    out: F64 = np.concatenate([f[..., :3] * f[..., 3:], f[..., 3:]], axis=-1)
    return out


# -- the shipped files ------------------------------------------------------------------


def test_shipped_files_are_the_generators_output(generated: list[U8]) -> None:
    for i, img in enumerate(generated):
        path = DATA / level_filename(i)
        np.testing.assert_array_equal(
            read_png(path), img, err_msg=f"{path.name} is stale: rebuild the sheet"
        )
    for shipped, fresh in zip(load_sheet(), generated, strict=True):
        np.testing.assert_array_equal(shipped, fresh)


def test_check_flag_catches_drift(
    generated: list[U8], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(TOOL, "DATA", tmp_path)
    monkeypatch.setattr(TOOL, "build_levels", lambda seed: generated)
    for i, img in enumerate(generated):
        (tmp_path / level_filename(i)).write_bytes(encode_png(img))
    assert TOOL.main(["--check"]) == 0
    # The same pixels compressed otherwise (another machine's zlib) are up to date.
    shipped = (tmp_path / level_filename(1)).read_bytes()
    (tmp_path / level_filename(1)).write_bytes(recompressed(shipped))
    assert (tmp_path / level_filename(1)).read_bytes() != shipped
    assert TOOL.main(["--check"]) == 0
    changed = generated[2].copy()
    changed[64, 64, 0] ^= 1
    (tmp_path / level_filename(2)).write_bytes(encode_png(changed))
    assert TOOL.main(["--check"]) == 1
    (tmp_path / level_filename(2)).unlink()
    assert TOOL.main(["--check"]) == 1


def test_tool_writes_the_sheet_and_its_preview(
    generated: list[U8], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(TOOL, "DATA", tmp_path / "data")
    monkeypatch.setattr(TOOL, "PREVIEW", tmp_path / "texture-sheet.png")
    monkeypatch.setattr(TOOL, "build_levels", lambda seed: generated)
    assert TOOL.main([]) == 0
    for i, img in enumerate(generated):
        np.testing.assert_array_equal(read_png(tmp_path / "data" / level_filename(i)), img)
    assert read_png(tmp_path / "texture-sheet.png").shape[0] == SHEET_PX
    assert TOOL.main(["--check"]) == 0


def test_generation_is_the_same_in_another_process(generated: list[U8]) -> None:
    code = (
        "import hashlib\n"
        "from wxsky.render.sheet_textures import build_levels\n"
        "h = hashlib.sha256()\n"
        "for level in build_levels():\n"
        "    h.update(level.tobytes())\n"
        "print(h.hexdigest())\n"
    )
    env = {**os.environ, "PYTHONHASHSEED": "4242"}
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, env=env, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == _digest(generated)


def test_levels_run_from_512_to_32_px() -> None:
    levels = load_sheet()
    assert [lv.shape for lv in levels] == [(s, s, 4) for s in (512, 256, 128, 64, 32)]
    assert len(levels) == MIP_LEVELS and levels[0].shape[0] == SHEET_PX
    assert all(lv.dtype == np.uint8 and not lv.flags.writeable for lv in levels)
    assert load_sheet()[0] is levels[0]  # read once, shared


# -- cells stay apart -------------------------------------------------------------------


def test_alpha_is_zero_around_every_cell_on_every_level() -> None:
    assert level_margin(0) == MARGIN_PX == 8
    for level, img in enumerate(load_sheet()):
        s = img.shape[0] // SHEET_CELLS
        m = level_margin(level)
        alpha = img[..., 3].reshape(SHEET_CELLS, s, SHEET_CELLS, s)
        border = np.ones(s, bool)
        border[m:-m] = False
        assert not alpha[:, border].any(), f"level {level}: alpha in the {m}-texel border"
        assert not alpha[:, :, :, border].any(), f"level {level}: alpha in the {m}-texel border"
        # ... and every cell still holds a texture on the smallest level.
        assert (alpha.max(axis=(1, 3)) > 32).all(), f"level {level}: an empty cell"


def test_mip_levels_are_averages_of_premultiplied_colour() -> None:
    levels = load_sheet()
    for level in range(1, MIP_LEVELS):
        finer = _premultiplied(levels[level - 1])
        s = finer.shape[0] // 2
        expected = finer.reshape(s, 2, s, 2, 4).mean(axis=(1, 3))
        actual = _premultiplied(levels[level])
        # The 32 px level's outer texels straddle the 8 px margin and are cleared.
        keep = np.ones((s, s), bool)
        if level == MIP_LEVELS - 1:
            ring = np.arange(s) % (s // SHEET_CELLS)
            edge = (ring == 0) | (ring == s // SHEET_CELLS - 1)
            keep = ~(edge[:, None] | edge[None, :])
        # 8-bit rounding of straight colour and alpha on both levels: within 2.5 levels.
        assert np.abs(actual - expected)[keep].max() < 2.5 / 255.0, f"level {level}"


def test_edges_do_not_darken_down_the_chain() -> None:
    for slot in range(SHEET_CELLS * SHEET_CELLS):
        means = []
        for level in range(MIP_LEVELS):
            p = _premultiplied(np.round(_cell(slot, level) * 255.0).astype(np.uint8))
            means.append(float((p[..., :3] @ LUMA).sum() / p[..., 3].sum()))
        # Averaging straight colour would pull the fringes toward the black of the empty
        # texels; premultiplied, the cloud's colour holds (measured spread <= 0.0013).
        assert max(means) - min(means) < 0.01, (slot, means)


def test_transparent_texels_next_to_a_cloud_carry_its_colour() -> None:
    for level, img in enumerate(load_sheet()):
        a = img[..., 3] > 0
        near = np.zeros_like(a)
        near[1:] |= a[:-1]
        near[:-1] |= a[1:]
        near[:, 1:] |= a[:, :-1]
        near[:, :-1] |= a[:, 1:]
        fringe = near & ~a
        # Bilinear filtering mixes these with the cloud: black there would draw a dark rim.
        assert img[fringe][:, :3].min() > 150, f"level {level}"


# -- each category looks like what it claims ---------------------------------------------


def _anisotropy(alpha: F64) -> float:
    """Ratio of the structure tensor's eigenvalues: 1 for round shapes, large when edges all
    run one way (fibres)."""
    gy, gx = np.gradient(alpha)
    j = np.array([[np.sum(gx * gx), np.sum(gx * gy)], [np.sum(gx * gy), np.sum(gy * gy)]])
    lo, hi = np.linalg.eigvalsh(j)
    return float(hi / lo)


def _steepest_slope(alpha: F64) -> float:
    gy, gx = np.gradient(alpha)
    return float(np.hypot(gx, gy).max())


def _luma_spread(cell: F64) -> float:
    a = cell[..., 3]
    luma = cell[..., :3] @ LUMA
    mean = (luma * a).sum() / a.sum()
    return float(np.sqrt((((luma - mean) ** 2) * a).sum() / a.sum()))


def _largest_component_share(mask: npt.NDArray[np.bool_]) -> float:
    """Share of the mask's pixels in its largest 4-connected piece."""
    labels = np.where(mask, np.arange(1, mask.size + 1).reshape(mask.shape), 0)
    while True:
        grown = labels.copy()
        grown[1:] = np.maximum(grown[1:], labels[:-1])
        grown[:-1] = np.maximum(grown[:-1], labels[1:])
        grown[:, 1:] = np.maximum(grown[:, 1:], labels[:, :-1])
        grown[:, :-1] = np.maximum(grown[:, :-1], labels[:, 1:])
        grown = np.where(mask, grown, 0)
        if np.array_equal(grown, labels):
            break
        labels = grown
    return float(np.bincount(labels[mask]).max() / mask.sum())


def _gyration(mask: npt.NDArray[np.bool_]) -> float:
    """Mean squared distance from the centroid over the area: 1/(2 pi) = 0.16 for a disc,
    0.2 for a 2:1 ellipse, larger for strands and scattered pieces."""
    r, c = np.nonzero(mask)
    return float(((r - r.mean()) ** 2 + (c - c.mean()) ** 2).mean() / mask.sum())


def _bright(cell: F64) -> float:
    """90th percentile of premultiplied luminance over the sprite: how white it gets."""
    a = cell[..., 3]
    return float(np.percentile((cell[..., :3] @ LUMA * a)[a > 0.05], 90))


def test_fog_is_soft_even_and_broad() -> None:
    puffy_slope = min(_steepest_slope(_alpha(s)) for s in TEX_PUFFY)  # 0.20
    for slot in TEX_FOG:
        cell = _cell(slot)
        a = cell[..., 3]
        # Gentle edges: alpha changes at most 0.045-0.058 a texel (puffs: 0.20 and more).
        assert _steepest_slope(a) < 0.07 < puffy_slope
        # Nearly uniform: over the plateau (alpha >= 80 % of its peak) std 0.040-0.042 ...
        assert a[a >= 0.8 * a.max()].std() < 0.05
        # ... low contrast in colour too (std of luminance 0.012, puffy 0.07) ...
        assert _luma_spread(cell) < 0.03
        # ... dense enough to hide the sky (peak 0.86-0.87) and large (alpha > 0.25 on
        # 33-37 % of the cell; the margin leaves at most 60 %).
        assert a.max() > 0.8
        assert np.mean(a > 0.25) > 0.3
        # Neutral grey: the shading model colours a deck; a tint here would tint every one.
        dense = a > 0.25
        assert abs(cell[..., 2][dense].mean() - cell[..., 0][dense].mean()) < 0.005


def test_flat_bottom_has_a_sharp_level_base() -> None:
    cell = _cell(TEX_FLAT_BOTTOM[0])
    a = cell[..., 3]
    dense_cols = np.nonzero((a > 0.5).any(axis=0))[0]
    c0, c1 = dense_cols.min(), dense_cols.max()
    middle = a[:, c0 + (c1 - c0) // 4 : c1 - (c1 - c0) // 4]
    base_rows = {int(np.nonzero(col > 0.5)[0].max()) for col in middle.T}
    # One row: the base is level across the middle half of the cloud (row 82, below the
    # middle of the sprite, so the cloud stands on it).
    assert len(base_rows) == 1
    base = base_rows.pop()
    assert CELL_PX // 2 < base < CELL_PX * 0.68
    assert not a[base + 2 :].any()  # nothing hangs below it
    # Sharp below, soft above: alpha falls 0.94 within one texel at the base (every column
    # at least 0.92) but rises at most 0.20 per texel at the top.
    drop = np.array([np.max(col[:-1] - col[1:]) for col in middle.T])
    rise = np.array([np.max(col[1:] - col[:-1]) for col in middle.T])
    assert drop.min() > 0.8
    assert rise.max() < 0.3
    # The base is in shade, the top in sun (luminance 0.83 against 0.95).
    luma = cell[..., :3] @ LUMA
    dense = a > 0.5
    rows = np.nonzero(dense.any(axis=1))[0]
    assert luma[rows.min() : rows.min() + 12][dense[rows.min() : rows.min() + 12]].mean() > (
        luma[base - 11 : base + 1][dense[base - 11 : base + 1]].mean() + 0.04
    )


def test_wisps_run_one_way_and_puffs_do_not() -> None:
    # Wisps: anisotropy 3.2-4.6 (ragged), 7.8 (hooked), 23-46 (straight fibres).
    wispy = {slot: _anisotropy(_alpha(slot)) for slot in TEX_WISPY}
    # Puffs and fog: 1.0-1.6.
    round_ = {slot: _anisotropy(_alpha(slot)) for slot in TEX_PUFFY + TEX_FOG}
    assert min(wispy.values()) > 2.5, wispy
    assert max(round_.values()) < 2.0, round_
    # The straight fibres are the most one-way of all.
    assert min(wispy[s] for s in TEX_WISPY[:2]) > 15.0


def test_wisps_are_thin_and_translucent() -> None:
    for slot in TEX_WISPY:
        a = _alpha(slot)
        # Streaks and fringes let the sky through: peak alpha 0.67-0.87, and their whitest
        # tenth reaches 0.50-0.66 premultiplied (puffs: 0.87-0.90).
        assert a.max() < 0.9
        assert _bright(_cell(slot)) < 0.7


def test_puffs_are_compact_and_bright() -> None:
    others = max(_bright(_cell(s)) for s in TEX_FOG + TEX_WISPY)
    for slot in TEX_PUFFY:
        cell = _cell(slot)
        a = cell[..., 3]
        dense = a > 0.5
        # One solid body: the dense part is a single piece (99.6-100 %) that fills most of
        # what the sprite touches (76-83 %), about as compact as a disc to a 2.5:1
        # ellipse (0.17-0.27).
        assert _largest_component_share(dense) > 0.97
        assert np.mean(dense[a > 0.05]) > 0.65
        assert _gyration(dense) < 0.3
        # Bright: whiter than any fog or wisp (0.87-0.90 against 0.74 at most), with lit
        # lobe tops above shaded undersides (upper half's luminance 0.085-0.11 higher).
        assert _bright(cell) > max(0.8, others)
        rows = np.nonzero(dense.any(axis=1))[0]
        mid = (rows.min() + rows.max()) // 2
        luma = cell[..., :3] @ LUMA
        assert luma[:mid][dense[:mid]].mean() > luma[mid:][dense[mid:]].mean() + 0.04


@pytest.mark.parametrize(
    ("slots", "least"),
    # Mean |alpha difference| between any two variants measures 0.035-0.039 for fog (meant
    # to be much alike), 0.091-0.25 for puffs, 0.048-0.071 for wisps.
    [(TEX_FOG, 0.03), (TEX_PUFFY, 0.08), (TEX_WISPY, 0.04)],
    ids=["fog", "puffy", "wispy"],
)
def test_variants_differ(slots: tuple[int, ...], least: float) -> None:
    for i, s in enumerate(slots):
        for t in slots[i + 1 :]:
            diff = float(np.abs(_alpha(s) - _alpha(t)).mean())
            assert diff > least, f"textures {s} and {t} look alike ({diff:.3f})"


# -- the GPU gets exactly these levels ----------------------------------------------------


def test_renderer_uploads_every_shipped_level(renderer: Renderer) -> None:
    fresh = Renderer(ring_texture_px=64, ctx=renderer.ctx)
    try:
        assert renderer.ctx.error == "GL_NO_ERROR"
        sheet = fresh._sheet  # the texture itself: what the sprites sample
        assert sheet.filter == (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        for level, expected in enumerate(load_sheet()):
            data = sheet.read(level=level, alignment=1)
            size = expected.shape[0]
            got = np.frombuffer(data, np.uint8).reshape(size, size, 4)
            np.testing.assert_array_equal(got, expected, err_msg=f"level {level}")
        assert renderer.ctx.error == "GL_NO_ERROR"
    finally:
        fresh.close()


def test_cell_shades_are_each_slots_alpha_weighted_mean_luminance() -> None:
    from wxsky.render.sprite_sheet import cell_shades, load_sheet

    level = load_sheet()[0].astype(np.float64) / 255.0
    shades = cell_shades()
    assert shades.shape == (16,) and np.all((shades > 0.5) & (shades <= 1.0))
    # Slot 5 by hand: the luminance of its texels, weighted by how much of each a sprite shows.
    cell = level[128:256, 128:256]
    luma = cell[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    expected = (luma * cell[..., 3]).sum() / cell[..., 3].sum()
    assert shades[5] == pytest.approx(expected, rel=1e-5)
    # A sheet of flat white texels has nothing to divide out.
    white = [np.full((512, 512, 4), 255, np.uint8)]
    assert np.allclose(cell_shades(white), 1.0)
