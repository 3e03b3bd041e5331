"""Every preset under a noon, a low and a twilight sun, facing the sun and away, before | after.

    .venv/bin/python tools/gallery/light_sheet.py [--before REF] [--preset NAME ...]
        [--size 320x180] [--eye ground,cruise] [--cruise-alt-m 10000] [--jobs 1]
        [--out-dir docs/gallery] [--cache-dir build/light-sheet]

Issue 41's before-and-after sheet (item 6). For each preset, rows are moments: noon (the
day's highest sun), the sun 20° and 5° up, and 4° and 10° down (twilight), each on the morning
of the preset's own date at its own site, found by bisection on the sun's elevation from
`wxsky.scene.ephemeris`; columns are the view toward the sun (heading = its azimuth) and away
from it, each as the `--before` revision | this checkout. The eye stands 2 m above the
observer ("ground", looking `--pitch-deg` up) and, with `--eye cruise`, at `--cruise-alt-m`
MSL (looking `--cruise-pitch-deg`).

Every cell is a `wxsky snapshot` run as its own process, so the "before" cells are drawn by
the other revision's own code: it is checked out into a temporary detached `git worktree`
(removed afterwards) and its `wxsky` imported from there (PYTHONPATH; the venv is shared).
Cells are cached under `--cache-dir` by the revision's `wxsky/` tree (plus any uncommitted
change to it) and the cell's arguments, so a rerun draws only what changed; when both sides
have the same `wxsky/` tree they share their cells and the sheet says so.

Writes `light-sheet-PRESET.png` per preset, `light-sheet.png` (every preset's low-sun row,
`--overview-moment`) and `light-sheet.md` (the index, with the times) into `--out-dir`.
`--palette` writes them as 256-colour, dithered PNGs, about a third the size: the committed
sheets are made so (`--size 320x180 --palette`); the cached cells are always full colour.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import dataclasses
import hashlib
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import numpy.typing as npt

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from wxsky.cli.common import parse_size  # noqa: E402
from wxsky.png import read_png, write_png  # noqa: E402
from wxsky.scene.ephemeris import sun_position  # noqa: E402
from wxsky.settings.presets import list_presets, load_preset  # noqa: E402
from wxsky.weather.state import WeatherState  # noqa: E402

U8 = npt.NDArray[np.uint8]

# The commit issue 41 started from (main on the day it was filed).
ISSUE_41_START = "b4dd2e9"
# (label, the sun's elevation or None for the day's highest), top row first.
MOMENTS: tuple[tuple[str, float | None], ...] = (
    ("noon", None),
    ("sun+20", 20.0),
    ("sun+5", 5.0),
    ("sun-4", -4.0),
    ("sun-10", -10.0),
)
FACINGS = ("toward the sun", "away from the sun")
GROUND_EYE_AGL_M = 2.0
GAP_PX = 4
PAIR_GAP_PX = 12
LABEL_W_PX = 150
HEADER_H_PX = 34
BACKGROUND = 255
INK = (20, 20, 20)


@dataclasses.dataclass(frozen=True)
class SunMoment:
    time_utc: datetime
    elevation_deg: float
    azimuth_deg: float


@dataclasses.dataclass(frozen=True)
class Cell:
    """One picture: a preset, a moment, a facing and an eye, as `wxsky snapshot` arguments."""

    preset: str
    moment: str
    facing: str
    eye: str
    time_utc: datetime
    heading_deg: float
    pitch_deg: float
    alt_m: float
    size: tuple[int, int]
    fov_deg: float | None = None  # `wxsky snapshot`'s default where None

    def args(self) -> list[str]:
        fov = [] if self.fov_deg is None else ["--fov-deg", f"{self.fov_deg:.3f}"]
        return [
            *fov,
            "--preset",
            self.preset,
            "--time",
            self.time_utc.strftime("%Y-%m-%dT%H:%M:%SZ"),
            "--heading-deg",
            f"{self.heading_deg % 360.0:.3f}",
            "--pitch-deg",
            f"{self.pitch_deg:.3f}",
            "--alt-m",
            f"{self.alt_m:.2f}",
            "--size",
            f"{self.size[0]}x{self.size[1]}",
        ]

    def key(self) -> str:
        digest = hashlib.sha256("\0".join(self.args()).encode()).hexdigest()[:16]
        return f"{self.preset}-{self.eye}-{digest}"


# --- the sun -------------------------------------------------------------------------------


def _elevation(when: datetime, lat_deg: float, lon_deg: float) -> float:
    return sun_position(when, lat_deg, lon_deg).elevation_deg


def solar_noon(day: datetime, lat_deg: float, lon_deg: float) -> datetime:
    """The time of the day's highest sun on `day`'s UTC date at the site: a 10-minute scan from
    the UTC midnight, then golden-section refinement to the second."""
    midnight = day.replace(hour=0, minute=0, second=0, microsecond=0)
    steps = [midnight + timedelta(minutes=10 * i) for i in range(24 * 6)]
    best = max(steps, key=lambda t: _elevation(t, lat_deg, lon_deg))
    lo, hi = best - timedelta(minutes=10), best + timedelta(minutes=10)
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    while (hi - lo).total_seconds() > 1.0:
        span = hi - lo
        a, b = hi - span * ratio, lo + span * ratio
        if _elevation(a, lat_deg, lon_deg) < _elevation(b, lat_deg, lon_deg):
            lo = a
        else:
            hi = b
    return lo + (hi - lo) / 2


def sun_time(
    day: datetime, lat_deg: float, lon_deg: float, elevation_deg: float | None
) -> SunMoment:
    """When the sun stands at `elevation_deg` (apparent, refracted, as wxsky's sky shows it) on
    the morning of `day`'s date at the site: bisection between the lowest sun of the 12 hours
    before the solar noon and the noon, where the sun only climbs. `None`: the noon itself.
    ValueError where the sun never reaches that elevation that morning."""
    noon = solar_noon(day, lat_deg, lon_deg)
    if elevation_deg is None:
        when = noon
    else:
        before = [noon - timedelta(minutes=10 * i) for i in range(72, -1, -1)]
        low = min(before, key=lambda t: _elevation(t, lat_deg, lon_deg))
        lo_el, hi_el = _elevation(low, lat_deg, lon_deg), _elevation(noon, lat_deg, lon_deg)
        if not lo_el <= elevation_deg <= hi_el:
            raise ValueError(
                f"the sun is between {lo_el:.1f} and {hi_el:.1f} deg that morning at "
                f"{lat_deg:.2f}, {lon_deg:.2f}, never {elevation_deg:g} deg"
            )
        lo, hi = low, noon
        while (hi - lo).total_seconds() > 0.5:
            mid = lo + (hi - lo) / 2
            if _elevation(mid, lat_deg, lon_deg) < elevation_deg:
                lo = mid
            else:
                hi = mid
        when = (lo + (hi - lo) / 2).replace(microsecond=0)
    sun = sun_position(when, lat_deg, lon_deg)
    return SunMoment(when, sun.elevation_deg, sun.azimuth_deg)


def preset_sun(name: str, elevation_deg: float | None) -> SunMoment:
    """`sun_time` at a preset's own site and date."""
    state = WeatherState().apply(load_preset(name, ()))
    obs = state.observer
    return sun_time(state.time_utc, obs.lat_deg, obs.lon_deg, elevation_deg)


# --- revisions and rendering ----------------------------------------------------------------


def _git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(
        ["git", *args], cwd=cwd, check=True, capture_output=True, text=True
    ).stdout.strip()


def checkout_key(checkout: Path) -> str:
    """What a checkout's pictures depend on: its committed `wxsky/` tree, and any uncommitted
    change to it (tracked or not), hashed."""
    tree = _git("rev-parse", "HEAD:wxsky", cwd=checkout)
    dirty = _git("status", "--porcelain", "--untracked-files=all", "--", "wxsky", cwd=checkout)
    if not dirty:
        return tree[:16]
    h = hashlib.sha256(_git("diff", "HEAD", "--", "wxsky", cwd=checkout).encode())
    for line in sorted(dirty.splitlines()):
        if line.startswith("??"):
            path = checkout / line[3:]
            h.update(line.encode())
            if path.is_file():
                h.update(path.read_bytes())
    return f"{tree[:12]}-dirty-{h.hexdigest()[:12]}"


def revision_key(ref: str) -> tuple[str, str]:
    """(full commit, key) of a revision: the key is its `wxsky/` tree."""
    commit = _git("rev-parse", "--verify", f"{ref}^{{commit}}")
    return commit, _git("rev-parse", f"{commit}:wxsky")[:16]


@contextlib.contextmanager
def temporary_worktree(commit: str) -> Iterator[Path]:
    """The commit checked out, detached, in a temporary worktree, removed afterwards."""
    parent = Path(tempfile.mkdtemp(prefix="light-sheet-"))
    path = parent / "wt"
    _git("worktree", "add", "--detach", str(path), commit)
    try:
        yield path
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(path)], cwd=ROOT, check=False)
        shutil.rmtree(parent, ignore_errors=True)


def render_cell(checkout: Path, cell: Cell, out: Path) -> str:
    """`wxsky snapshot` of one cell with the checkout's own wxsky, niced; '' or the error."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    tmp = out.with_name(out.stem + f".{os.getpid()}.tmp.png")
    cmd = ["nice", "-n", "19", sys.executable, "-m", "wxsky", "snapshot", *cell.args()]
    done = subprocess.run(
        [*cmd, "--out", str(tmp)], cwd=checkout, env=env, capture_output=True, text=True
    )
    if done.returncode != 0 or not tmp.is_file():
        tmp.unlink(missing_ok=True)
        return (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]
    tmp.replace(out)
    return ""


DRAWN: list[int] = []  # how many cells each `render_all` of this run drew (the rest: cached)


def render_all(
    checkout: Path, key: str, cells: Sequence[Cell], cache: Path, jobs: int
) -> dict[Cell, Path | str]:
    """Each cell's cached picture, drawing those missing; a failed cell maps to its error."""
    folder = cache / key
    folder.mkdir(parents=True, exist_ok=True)
    result: dict[Cell, Path | str] = {}
    todo = []
    for cell in cells:
        path = folder / f"{cell.key()}.png"
        result[cell] = path
        if not path.is_file():
            todo.append((cell, path))
    DRAWN.append(len(todo))
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = {pool.submit(render_cell, checkout, c, p): c for c, p in todo}
        for n, future in enumerate(concurrent.futures.as_completed(futures), 1):
            cell = futures[future]
            error = future.result()
            if error:
                result[cell] = error
            print(
                f"  [{key}] {n}/{len(todo)} {cell.preset} {cell.eye} {cell.moment} "
                f"{cell.facing}{': ' + error if error else ''}",
                flush=True,
            )
    return result


def render_sides(
    before_ref: str, cells: Sequence[Cell], cache: Path, jobs: int
) -> tuple[dict[Cell, Path | str], dict[Cell, Path | str], tuple[str, str]]:
    """Every cell drawn by `before_ref`'s code (in a temporary worktree, unless cached or the
    same `wxsky/` tree) and by this checkout's: (before, after, their titles)."""
    after_key = checkout_key(ROOT)
    # Labelled by the wxsky/ tree, not the commit: a commit that leaves wxsky/ alone (a
    # sheet's own, say) redraws nothing and changes no pixel of the sheets.
    after_title = f"after: this checkout (wxsky/ {after_key[:7]})"
    commit, before_key = revision_key(before_ref)
    before_title = f"before: {before_ref} (wxsky/ {before_key[:7]})"
    if before_key == after_key:
        after_title += ", the same"
    print(
        f"{len(cells)} cells a side; before {commit[:10]} (wxsky {before_key}), after {after_key}"
    )
    after = render_all(ROOT, after_key, cells, cache, jobs)
    if before_key == after_key:
        before = after
    elif all((cache / before_key / f"{c.key()}.png").is_file() for c in cells):
        before = render_all(ROOT, before_key, cells, cache, jobs)  # all cached
    else:
        with temporary_worktree(commit) as tree:
            before = render_all(tree, before_key, cells, cache, jobs)
    return before, after, (before_title, after_title)


# --- the sheet ------------------------------------------------------------------------------


def _font(size_px: int) -> object:
    from PIL import ImageFont  # matplotlib's dependency: a dev tool's, not wxsky's

    return ImageFont.load_default(size=size_px)


def _label(image: U8, lines: Sequence[str], x: int, y: int, size_px: int = 12) -> None:
    """Text onto an RGBA image in place, top-left at (x, y)."""
    from PIL import Image, ImageDraw

    pil = Image.fromarray(image)
    draw = ImageDraw.Draw(pil)
    font = _font(size_px)
    for i, line in enumerate(lines):
        draw.text((x, y + i * (size_px + 3)), line, fill=(*INK, 255), font=font)  # type: ignore[arg-type]
    image[...] = np.asarray(pil)


def _missing(size: tuple[int, int], why: str) -> U8:
    tile = np.full((size[1], size[0], 4), 200, np.uint8)
    tile[..., 3] = 255
    _label(tile, ["no picture:", why[:40], why[40:80]], 6, 6, 11)
    return tile


def _tile(found: Path | str, size: tuple[int, int]) -> U8:
    if isinstance(found, str):
        return _missing(size, found)
    return read_png(found)


def preset_sheet(
    preset: str,
    rows: Sequence[tuple[str, str, SunMoment]],
    before: dict[Cell, Path | str],
    after: dict[Cell, Path | str],
    cells: dict[tuple[str, str, str], Cell],
    size: tuple[int, int],
    titles: tuple[str, str],
) -> U8:
    """One preset: a row per (eye, moment), a column pair (before | after) per facing."""
    w, h = size
    pair_w = 2 * w + GAP_PX
    width = LABEL_W_PX + len(FACINGS) * pair_w + (len(FACINGS) - 1) * PAIR_GAP_PX
    height = HEADER_H_PX + len(rows) * (h + GAP_PX)
    sheet = np.full((height, width, 4), BACKGROUND, np.uint8)
    for f, facing in enumerate(FACINGS):
        x = LABEL_W_PX + f * (pair_w + PAIR_GAP_PX)
        _label(sheet, [facing], x, 2, 13)
        _label(sheet, [titles[0]], x, 18, 11)
        _label(sheet, [titles[1]], x + w + GAP_PX, 18, 11)
    for r, (eye, moment, sun) in enumerate(rows):
        y = HEADER_H_PX + r * (h + GAP_PX)
        _label(
            sheet,
            [
                preset,
                f"{moment}, {eye} eye",
                f"{sun.time_utc:%Y-%m-%d %H:%M}Z",
                f"sun el {sun.elevation_deg:+.1f} az {sun.azimuth_deg:.0f}",
            ],
            4,
            y + 4,
            11,
        )
        for f, facing in enumerate(FACINGS):
            cell = cells[(eye, moment, facing)]
            x = LABEL_W_PX + f * (pair_w + PAIR_GAP_PX)
            sheet[y : y + h, x : x + w] = _tile(before[cell], size)
            sheet[y : y + h, x + w + GAP_PX : x + pair_w] = _tile(after[cell], size)
    return sheet


def write_sheet(path: Path, image: U8, palette: bool) -> None:
    """The sheet as an opaque PNG: full colour by wxsky's own writer, or (`palette`) 256
    colours from a median cut, Floyd-Steinberg dithered so the skies' gradients do not band."""
    if not palette:
        write_png(path, image)
        return
    from PIL import Image

    rgb = Image.fromarray(np.ascontiguousarray(image[..., :3]))
    colours = rgb.quantize(256, method=Image.Quantize.MEDIANCUT)
    rgb.quantize(palette=colours, dither=Image.Dither.FLOYDSTEINBERG).save(
        path, "PNG", optimize=True
    )


def _index(
    out_dir: Path,
    names: Sequence[str],
    titles: tuple[str, str],
    command: str,
    suns: dict[tuple[str, str], SunMoment],
    eyes: Sequence[str],
    seconds: float,
    overview: str,
) -> str:
    lines = [
        "# Light sheet: every preset under noon, low and twilight suns, before | after",
        "",
        f"Made by `{command}` (tools/gallery/light_sheet.py, issue 41 item 6) in {seconds:.0f} s,",
        f"drawing {sum(DRAWN)} cells and taking the rest from its cache. From an empty cache",
        "each cell is one `wxsky snapshot` process: 2-8 s at 320x180 on one llvmpipe core.",
        f"Each cell pair is **{titles[0]}** (left) | **{titles[1]}** (right); the left pair of",
        "columns faces the sun (heading = its azimuth), the right pair faces away.",
        f"Eyes: {', '.join(eyes)}. Times are on the morning of each preset's own date at its",
        "site, found by bisection on the sun's apparent elevation (wxsky.scene.ephemeris).",
        "",
        f"Every preset at {overview}, on one sheet: [light-sheet.png](light-sheet.png)",
        "",
        # Notes written by whoever looked at a sheet (light-sheet-before.md, ...), kept.
        *(
            line
            for note in sorted(out_dir.glob("light-sheet-*.md"))
            for line in (f"What a pilot saw: [{note.name}]({note.name}).", "")
        ),
        "| preset | sheet | " + " | ".join(m for m, _ in MOMENTS) + " |",
        "|---|---|" + "---|" * len(MOMENTS),
    ]
    for name in names:
        times = [
            f"{suns[(name, m)].time_utc:%H:%M}Z" if (name, m) in suns else "-" for m, _ in MOMENTS
        ]
        lines.append(
            f"| {name} | [light-sheet-{name}.png](light-sheet-{name}.png) | "
            + " | ".join(times)
            + " |"
        )
    text = "\n".join(lines) + "\n"
    (out_dir / "light-sheet.md").write_text(text)
    return text


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--before",
        default=ISSUE_41_START,
        metavar="REF",
        help=f"the revision on the left of each pair (default {ISSUE_41_START}, "
        "where issue 41 started)",
    )
    p.add_argument("--preset", action="append", help="only these presets (repeatable)")
    p.add_argument(
        "--moment",
        action="append",
        choices=[m for m, _ in MOMENTS],
        help="only these moments (repeatable; default all)",
    )
    p.add_argument("--size", default="320x180", help="each cell, WxH (default 320x180)")
    p.add_argument(
        "--eye", default="ground", help="comma-separated: ground (2 m above the observer), cruise"
    )
    p.add_argument("--pitch-deg", type=float, default=8.0, help="ground eye's pitch (8)")
    p.add_argument("--cruise-alt-m", type=float, default=10000.0, help="MSL (10000)")
    p.add_argument("--cruise-pitch-deg", type=float, default=0.0, help="cruise pitch (0)")
    p.add_argument(
        "--overview-moment",
        default="sun+5",
        choices=[m for m, _ in MOMENTS],
        help="the row of each preset in light-sheet.png (default sun+5)",
    )
    p.add_argument("--palette", action="store_true", help="256-colour dithered PNGs (smaller)")
    p.add_argument("--jobs", type=int, default=1, help="snapshots at once (default 1)")
    p.add_argument("--out-dir", type=Path, default=ROOT / "docs" / "gallery")
    p.add_argument("--cache-dir", type=Path, default=ROOT / "build" / "light-sheet")
    args = p.parse_args(argv)
    size = parse_size(args.size)
    eyes = [e.strip() for e in args.eye.split(",") if e.strip()]
    if not eyes or any(e not in ("ground", "cruise") for e in eyes):
        p.error(f"--eye: ground and/or cruise, not {args.eye!r}")
    names = args.preset or [e.name for e in list_presets(()) if e.origin == "builtin"]
    started = time.monotonic()

    suns: dict[tuple[str, str], SunMoment] = {}
    cells: dict[str, dict[tuple[str, str, str], Cell]] = {}
    rows: dict[str, list[tuple[str, str, SunMoment]]] = {}
    for name in names:
        state = WeatherState().apply(load_preset(name, ()))
        obs = state.observer
        cells[name], rows[name] = {}, []
        for moment, elevation in MOMENTS:
            if args.moment and moment not in args.moment:
                continue
            try:
                sun = sun_time(state.time_utc, obs.lat_deg, obs.lon_deg, elevation)
            except ValueError as exc:
                print(f"{name} {moment}: skipped, {exc}")
                continue
            suns[(name, moment)] = sun
            for eye in eyes:
                rows[name].append((eye, moment, sun))
                ground = eye == "ground"
                for facing in FACINGS:
                    heading = sun.azimuth_deg + (0.0 if facing == FACINGS[0] else 180.0)
                    cells[name][(eye, moment, facing)] = Cell(
                        name,
                        moment,
                        facing,
                        eye,
                        sun.time_utc,
                        heading,
                        args.pitch_deg if ground else args.cruise_pitch_deg,
                        obs.alt_m + GROUND_EYE_AGL_M if ground else args.cruise_alt_m,
                        size,
                    )
    every = [c for per in cells.values() for c in per.values()]

    before, after, titles = render_sides(args.before, every, args.cache_dir, args.jobs)

    args.out_dir.mkdir(parents=True, exist_ok=True)
    low_sun: list[U8] = []
    for name in names:
        sheet = preset_sheet(name, rows[name], before, after, cells[name], size, titles)
        write_sheet(args.out_dir / f"light-sheet-{name}.png", sheet, args.palette)
        chosen = [r for r in rows[name] if r[1] == args.overview_moment]
        if chosen:
            row = preset_sheet(name, chosen, before, after, cells[name], size, titles)
            low_sun.append(row[HEADER_H_PX:] if low_sun else row)
    if low_sun:
        overview = np.full(
            (sum(s.shape[0] for s in low_sun), max(s.shape[1] for s in low_sun), 4),
            BACKGROUND,
            np.uint8,
        )
        y = 0
        for s in low_sun:
            overview[y : y + s.shape[0], : s.shape[1]] = s
            y += s.shape[0]
        write_sheet(args.out_dir / "light-sheet.png", overview, args.palette)
    seconds = time.monotonic() - started
    command = "tools/gallery/light_sheet.py " + " ".join(
        a for a in (argv if argv is not None else sys.argv[1:])
    )
    _index(args.out_dir, names, titles, command.strip(), suns, eyes, seconds, args.overview_moment)
    failed = [c for c in every if isinstance(after[c], str) or isinstance(before[c], str)]
    print(
        f"wrote {len(names)} sheets, light-sheet.png and light-sheet.md into {args.out_dir} "
        f"in {seconds:.0f} s; {len(failed)} cells without a picture"
    )
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
