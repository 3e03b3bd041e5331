"""Which parts of the sky layer a frame draws, so that a slowly changing sky costs little and
the same every frame.

The sky is drawn in parts (sky.glsl): the plain sky over the whole picture, then the dome's
variant over its band and the moon's over its disc, each part's colour a function of the
pixel and the uniforms only, so any part may be drawn over any sub-rectangle and agree with
the rest to the bit. The layer is kept in horizontal strips (`strip_edges`: about
`SKY_STRIPS`, with edges on those of the dome's band where it spans the picture's width, so
that the dearest part redraws whole strips of its own, one a frame or so at an even cost),
and each part remembers, strip by strip, the numbers it was drawn there with:

- what the layer shows changed in kind (another texture, another feature or rectangle):
  everything is drawn;
- a part some number of which moved by more than `SKY_CATCH_UP` tolerances in a strip (a
  turn, a clock set, the stars' twinkle) is drawn again over all of its strips;
- otherwise, once one of a part's strips has drifted past its tolerance, its stalest strips
  are drawn again, as many a frame as keep them all within SKY_CATCH_UP at the rate things
  drift (the mean over the last few frames: the sun moves on the sky's eighth-of-a-second
  step, every third or fourth frame). The sun moves a little, and the dome every frame: a
  steady view pays a thin strip of its plain sky and a piece of the dome's band every frame,
  instead of the whole sky every few frames, and its frame time stays even.

Drawing a part over a strip again means drawing the parts after it there too (each part
overwrites its rectangle), not the ones before it: a drifting dome does not redraw the plain
sky under it. A part is never drawn in a strip a later part covers whole: the plain sky under
the dome's band would be drawn only to be drawn over (before, a plain-sky strip redrawn for
the sun's motion redrew the dome in it as well, and a frame's dome cost 20 to 110 rows).

Tolerances are in the uniforms' own units: `SKY_REUSE_TOLERANCE` for directions (radians),
colours and the like, and that share of a number's size past 1 (radiances in kcd/m^2, heights in
metres); for the dome's texture offsets, what moves the nearest dome the eye can
see by `DOME_REUSE_PX` of a pixel (`dome_offset_tolerance`).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt

from wxsky.render import sky_textures
from wxsky.render.sky_textures import Rect, SkyFeatures
from wxsky.scene.sky import SkyParams

F64 = npt.NDArray[np.float64]

# A number the sky is drawn from may move this much before the pixels it makes are drawn
# again: by day the sun moves 2.4e-6 rad a frame at 30 fps, on the sky's eighth-of-a-second
# step 9e-6 rad at a time (scene.sky.SKY_STEP_US), so a strip is drawn again every twenty
# frames or so, by steps a twentieth of a pixel and a fortieth of a colour level wide. A step
# is a fifth of a tolerance, and the plain sky's 32 strips then come one every frame, evenly
# (at 1e-4 one in most frames and none in the rest: clear's median fell, its p95 did not; at
# 2e-5 a step was half a tolerance, and the pace wavered between two strips and three).
SKY_REUSE_TOLERANCE = 5e-5
# Thin strips (22 rows at 720): a drifting part redraws a strip or two of them every frame,
# where 8 strips of 90 rows came one frame in two or three, and a frame with one cost a
# millisecond or more than a frame without (clear: p95 / median 1.4-1.6 -> 1.2-1.3).
SKY_STRIPS = 32
# Strips at least in the dome's band (`strip_edges`): as it drifts, a strip of it a frame.
DOME_STRIPS = 3
# Beyond this many tolerances a change is a jump, not a drift: drawn whole at once.
SKY_CATCH_UP = 3.0
# The dome drifts with the wind aloft: redrawn once it has moved this share of a pixel where
# it is nearest the eye (a soft texture; the band at the horizon is 30 to 100 km off and
# hardly moves, high cover overhead a few pixels a second).
DOME_REUSE_PX = 0.25
# The share of the drift rate a frame keeps from the frames before (an exponential mean over
# some eight frames: two sky steps at 30 fps).
RATE_KEEP = 0.875
_NO_RATE = -1.0  # no frame since the layer was drawn whole
# Uniforms a change of which always redraws the whole layer (the stars twinkle every frame).
_ALWAYS = frozenset({"u_star_clock_s"})
_NOT_COMPARED = frozenset({"u_rect"})  # where a part is drawn, compared as the layout
# The physical sky's sun azimuth (a unit vector in the level plane) turns its baked table
# (scene.sky.display_sky_view) about the zenith. Away from the sun part's rectangle, where the
# sky is drawn per pixel, neighbouring columns of that table (0.94 deg apart) differ by at most
# 4.2 display levels (sun 5 deg up, the steepest; 1.7 at 60 deg): a turn of 1e-3 rad changes a
# pixel by at most a quarter of a level. At the colour tolerance the plain sky was drawn again
# a strip every frame for turns of a fortieth of a level (clear: 22 rows a frame, a third of its
# frame); `tests/test_sky_strips.py` holds the bound.
FLAT_SUN_TOLERANCE_RAD = 1e-3
# The ground's light (`sky_textures.physical_ground_tint`), a factor on its colour at most about
# 1: 1e-3 moves the ground by a quarter of a level at most; it steps with the sun's 0.01 deg.
GROUND_TINT_TOLERANCE = 1e-3
_TOLERANCES = {"u_flat_sun": FLAT_SUN_TOLERANCE_RAD, "u_ground_tint": GROUND_TINT_TOLERANCE}
# Texture offsets repeat: 0.9999 and 0.0001 are a step of 0.0002.
_PERIODS = {"u_dome_off0": 1.0, "u_dome_off1": 1.0, "u_dome_off2": 1.0}

_serials = itertools.count(1)


@dataclasses.dataclass(frozen=True)
class SkyPart:
    """One sky pass: its name, shader variant, rectangle (NDC), uniforms (less `u_rect`),
    and the numbers it is drawn from with their tolerances, flattened alike."""

    pass_name: str
    feats: SkyFeatures
    rect: Rect
    uniforms: dict[str, object]
    values: F64
    tolerance: F64
    period: F64  # of each number that wraps (the dome's texture offsets), else 0

    def drift_from(self, drawn: F64) -> float:
        """The largest change of any number since `drawn`, in its tolerances (any change of
        one with none is a jump), the short way round for the periodic ones."""
        return float(self.drifts_from(drawn[None, :])[0])

    def drifts_from(self, drawn: F64) -> F64:
        """`drift_from` for each row of `drawn` (S, K) at once: (S,)."""
        if self.values.size == 0:
            return np.zeros(len(drawn))
        change = np.abs(self.values - drawn)
        wraps, period, tolerated, tolerance = self._masks
        if wraps is not None:
            wrapped = np.mod(change, period)
            change = np.where(wraps, np.minimum(wrapped, self.period - wrapped), change)
        ratio = change / tolerance
        if tolerated is not None:
            ratio = np.where(tolerated, ratio, np.where(change > 0.0, np.inf, 0.0))
        out: F64 = ratio.max(axis=1)
        return out

    @functools.cached_property
    def _masks(self) -> tuple[npt.NDArray[np.bool_] | None, F64, npt.NDArray[np.bool_] | None, F64]:
        """(which numbers wrap, or None; their periods, inf for the rest; which have a
        tolerance, or None when all do; the tolerances, 1 for those without): made once a
        part, for the strips' drifts."""
        wraps = self.period > 0.0
        tolerated = self.tolerance > 0.0
        return (
            wraps if wraps.any() else None,
            np.where(wraps, self.period, np.inf),
            None if tolerated.all() else tolerated,
            np.where(tolerated, self.tolerance, 1.0),
        )

    @staticmethod
    def of(
        pass_name: str,
        feats: SkyFeatures,
        rect: Rect,
        uniforms: Mapping[str, object],
        tolerances: Mapping[str, float] | None = None,
    ) -> SkyPart:
        """`tolerances`: by uniform name, where not SKY_REUSE_TOLERANCE."""
        tolerances = {**_TOLERANCES, **(tolerances or {})}
        values: list[float] = []
        # Per number: its own tolerance, or -1 for the default (relative past 1: worked out
        # on the whole array below, one numpy call a part rather than one a number).
        tolerance: list[float] = []
        period: list[float] = []
        for name, value in uniforms.items():
            if name in _NOT_COMPARED:
                continue
            numbers = _numbers(value)
            k = len(numbers)
            values += numbers
            if name in _ALWAYS:
                tolerance += [0.0] * k
            else:
                tolerance += [tolerances.get(name, -1.0)] * k
            period += [_PERIODS.get(name, 0.0)] * k
        array = np.asarray(values, np.float64)
        tol = np.asarray(tolerance, np.float64)
        # Relative past 1: the physical sky's radiances are kcd/m^2 (the sun's disc about
        # 1e6), and an absolute 5e-5 of them redrew the whole sky whenever the sun moved at
        # all (clear: a full sky every frame or two, not a strip).
        default = tol < 0.0
        tol[default] = SKY_REUSE_TOLERANCE * np.maximum(np.abs(array[default]), 1.0)
        drawn = {k: v for k, v in uniforms.items() if k not in _NOT_COMPARED}
        return SkyPart(
            pass_name,
            feats,
            rect,
            drawn,
            array,
            tol,
            np.asarray(period, np.float64),
        )


@dataclasses.dataclass(frozen=True)
class SkyLayerState:
    """What a sky layer holds: the texture drawn into, its parts' layout, the numbers each
    part was drawn from in each strip, the numbers of the latest frame (drawn or not: how
    fast things drift), and per strip a serial that changes with every drawing into it (a
    publisher copies only the strips drawn since its copy: `strip_rows`)."""

    texture: int
    layout: tuple[tuple[str, SkyFeatures, Rect], ...]
    strips: tuple[tuple[F64, ...], ...]  # by part, by strip
    latest: tuple[F64, ...]  # by part
    strip_serials: tuple[int, ...]
    # NDC y of the strips' edges, top to bottom (`strip_edges`): strips + 1 of them.
    edges: tuple[float, ...]
    # By part, how far its numbers drift a frame, in tolerances, averaged over the last few
    # frames (RATE_KEEP): the sky moves on its step (scene.sky.SKY_STEP_US), every third or
    # fourth frame, and strips are drawn again at the mean rate, not in bursts.
    rates: tuple[float, ...] = ()

    def strip_rows(self, height_px: int) -> tuple[tuple[int, int], ...]:
        """Each strip's rows at a picture height_px tall (`strip_rows`)."""
        return _strips_rows(self.edges, height_px)


def plan_sky(
    kept: SkyLayerState | None, texture: int, parts: Sequence[SkyPart]
) -> tuple[list[tuple[SkyPart, Rect]], SkyLayerState]:
    """The draws (each part with the rectangle to draw it over, in order) that bring a sky
    layer holding `kept` (None: nothing known) to `parts`, and what the layer then holds.

    Part by part, in drawing order: of the strips a part covers, the stalest are drawn
    again, as many as keep them all within SKY_CATCH_UP at the recent frames' mean drift
    (all of them past it), and with them every strip an earlier part was drawn again in (a part
    overwrites what lies under its rectangle, not what lies over it)."""
    layout = tuple((p.pass_name, p.feats, p.rect) for p in parts)
    edges = strip_edges(parts)
    count = len(edges) - 1
    if (
        kept is None
        or kept.texture != texture
        or kept.layout != layout
        or kept.edges != edges
        or any(s[0].shape != p.values.shape for s, p in zip(kept.strips, parts, strict=True))
    ):
        serial = next(_serials)
        return [(p, p.rect) for p in parts], SkyLayerState(
            texture,
            layout,
            tuple((p.values,) * count for p in parts),
            tuple(p.values for p in parts),
            (serial,) * count,
            edges,
            (_NO_RATE,) * len(parts),
        )
    draws: list[tuple[SkyPart, Rect]] = []
    redrawn: set[int] = set()  # strips an earlier part was drawn in again
    strips: list[tuple[F64, ...]] = []
    rates: list[float] = []
    was = kept.rates if len(kept.rates) == len(parts) else (_NO_RATE,) * len(parts)
    for k, (part, held, latest) in enumerate(zip(parts, kept.strips, kept.latest, strict=True)):
        now = part.drift_from(latest)
        # The first frame after a whole drawing has no mean yet: its own drift starts it.
        rate = now if was[k] < 0.0 else RATE_KEEP * was[k] + (1.0 - RATE_KEEP) * now
        rates.append(rate)
        # Strips a later part covers whole (the dome's band, full width) show none of this
        # part: it is not drawn there, and its numbers there are not kept up.
        bands = [(p.rect[1], p.rect[3]) for p in parts[k + 1 :] if _spans_width(p.rect)]
        x0, y0, x1, y1 = part.rect
        mine = [
            i
            for i in range(count)
            if x0 < x1
            and y0 < edges[i + 1]
            and edges[i] < y1
            and not any(lo <= edges[i] and edges[i + 1] <= hi for lo, hi in bands)
        ]
        drifts = part.drifts_from(np.stack([held[i] for i in mine])) if mine else np.zeros(0)
        drift = dict(zip(mine, drifts.tolist(), strict=True))
        stale = [i for i in sorted(mine, key=lambda i: -drift[i]) if drift[i] > 1.0]
        if stale and drift[stale[0]] > SKY_CATCH_UP:
            chosen = set(mine)
        elif stale:
            many = max(1, math.ceil(len(mine) * rate / (SKY_CATCH_UP - 1.0)))
            chosen = set(stale[:many])
        else:
            chosen = set()
        redo = sorted(chosen | (redrawn & set(mine)))
        for first, last in _runs(redo):
            band = (-1.0, edges[first], 1.0, edges[last + 1])
            clipped = _intersect(part.rect, band)
            if clipped is not None:
                draws.append((part, clipped))
        again = set(redo)
        redrawn |= again
        strips.append(tuple(part.values if i in again else v for i, v in enumerate(held)))
    latest_values = tuple(p.values for p in parts)
    if not draws:
        return [], dataclasses.replace(kept, latest=latest_values, rates=tuple(rates))
    serial = next(_serials)
    strip_serials = tuple(
        serial if i in redrawn else held for i, held in enumerate(kept.strip_serials)
    )
    return draws, SkyLayerState(
        texture, layout, tuple(strips), latest_values, strip_serials, edges, tuple(rates)
    )


def _numbers(value: object) -> list[float]:
    """A uniform's value as a flat list of floats. Most are a number or a short tuple of
    numbers, taken as they are: numpy's conversion of each of a frame's hundred-odd values was
    half of the sky pass's own CPU time."""
    if isinstance(value, (int, float)):
        return [float(value)]
    if isinstance(value, tuple):
        try:
            return [float(v) for v in value]  # numbers (a nested tuple raises: numpy's)
        except TypeError:
            pass
    out: list[float] = np.asarray(value, np.float64).ravel().tolist()
    return out


def strip_edges(parts: Sequence[SkyPart]) -> tuple[float, ...]:
    """The strips' edges (NDC y, top -1 to bottom 1) for these parts: SKY_STRIPS even strips,
    or, where a later part spans the picture's width over a band (the dome's, the dearest
    part), strips that meet that band's edges: at least DOME_STRIPS in the band, and the rest
    of the picture in strips about as tall as even ones. A band's strips are drawn whole by
    its part, at an even cost a frame, and the parts under it are not drawn there at all."""
    band = next(
        (r for r in (p.rect for p in parts[1:]) if _spans_width(r) and (r[1] > -1.0 or r[3] < 1.0)),
        None,
    )
    if band is None:
        return tuple(-1.0 + 2.0 * i / SKY_STRIPS for i in range(SKY_STRIPS + 1))
    edges: list[float] = [-1.0]
    for lo, hi, least in ((-1.0, band[1], 1), (band[1], band[3], DOME_STRIPS), (band[3], 1.0, 1)):
        if hi <= lo:
            continue
        n = max(least, round(SKY_STRIPS * (hi - lo) / 2.0))
        edges.extend(lo + (hi - lo) * j / n for j in range(1, n))
        edges.append(hi)
    return tuple(edges)


def _runs(indices: Sequence[int]) -> list[tuple[int, int]]:
    """Sorted indices as runs of consecutive ones, (first, last) each."""
    runs: list[tuple[int, int]] = []
    for i in indices:
        if runs and runs[-1][1] == i - 1:
            runs[-1] = (runs[-1][0], i)
        else:
            runs.append((i, i))
    return runs


@functools.lru_cache(maxsize=8)
def strip_columns(rows: tuple[tuple[int, int], ...]) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """`strip_rows`' first rows and stop rows, apart (a publisher's bands, every frame)."""
    if not rows:
        return (), ()
    firsts, stops = zip(*rows, strict=True)
    return firsts, stops


@functools.lru_cache(maxsize=8)
def _strips_rows(edges: tuple[float, ...], height_px: int) -> tuple[tuple[int, int], ...]:
    # Asked for every frame by the publisher; the edges change only with the layout.
    return tuple(strip_rows(edges[i], edges[i + 1], height_px) for i in range(len(edges) - 1))


def strip_rows(top_ndc: float, bottom_ndc: float, height_px: int) -> tuple[int, int]:
    """The rows (first, stop; 0 the top of the picture, as the layer is read) that a strip
    from top_ndc to bottom_ndc draws into at a picture height_px tall, with a row more at
    either end where an edge is not on a row boundary: every row its rectangle rasterises to."""
    top, bottom = (top_ndc + 1.0) * 0.5 * height_px, (bottom_ndc + 1.0) * 0.5 * height_px
    first, stop = math.floor(top), math.ceil(bottom)
    if first != top:
        first -= 1
    if stop != bottom:
        stop += 1
    return max(0, first), min(height_px, stop)


def dome_offset_tolerance(
    pixel_rad: float, sky: SkyParams, eye_alt_m: float, view_top_sin: float = 1.0
) -> float:
    """How far the dome's texture offsets (tile units) may move before the dome nearest the
    eye that the picture shows has moved DOME_REUSE_PX of a pixel: 0 where no dome is drawn.
    `view_top_sin`: the sine of the highest elevation in the picture (`sky_textures`
    `view_top_sin`; 1: the zenith)."""
    frame = sky_textures.dome_frame(sky, eye_alt_m)
    if frame.height_m <= 0.0:
        return 0.0
    # The nearest visible dome: overhead under high cover, else the top of the distant band;
    # no higher than the picture's top. A level view's top is 18 deg up at 60 deg across
    # 16:9: the dome there is 3.2 times as far as overhead and moves a third as many pixels
    # (high cirrus at 120 m/s: the whole band was drawn again every frame for the zenith's
    # motion, which that view does not show).
    top_z = 1.0 if sky.dome.high_cover > 0.0 else sky_textures.dome_band(sky)[1]
    top_z = min(top_z, view_top_sin)
    nearest_m = frame.height_m / max(top_z, 1e-3)
    # A texture offset of 1 moves the dome by at most a (stretched) tile.
    tile_m = max(1.0 / min(math.hypot(m[0], m[2]), math.hypot(m[1], m[3])) for m in frame.matrices)
    return DOME_REUSE_PX * pixel_rad * nearest_m / tile_m


def _spans_width(rect: Rect) -> bool:
    return rect[0] <= -1.0 and rect[2] >= 1.0


def _intersect(a: Rect, b: Rect) -> Rect | None:
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[2], b[2]), min(a[3], b[3])
    if x0 >= x1 or y0 >= y1:
        return None
    return (x0, y0, x1, y1)
