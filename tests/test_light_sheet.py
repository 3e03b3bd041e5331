"""tools/gallery/light_sheet.py (issue 41's before | after sheet): the times it finds put the
sun where asked, and a run draws each side with its own revision's wxsky, caches the cells and
leaves no worktree behind."""

from __future__ import annotations

import subprocess
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from tool_loader import load_tool

from wxsky.png import read_png
from wxsky.scene.ephemeris import sun_position

sheet = load_tool("gallery/light_sheet")
ROOT = Path(__file__).resolve().parents[1]
ZURICH = (47.37, 8.54)


@pytest.mark.parametrize(
    "day", [datetime(2026, 6, 21, tzinfo=UTC), datetime(2026, 11, 18, tzinfo=UTC)]
)
@pytest.mark.parametrize("elevation_deg", [20.0, 5.0, -4.0, -10.0])
def test_the_sun_stands_where_asked_on_the_morning(day: datetime, elevation_deg: float) -> None:
    sun = sheet.sun_time(day, *ZURICH, elevation_deg)
    assert sun.time_utc.date() == day.date()
    assert abs(sun.elevation_deg - elevation_deg) < 0.02
    assert abs(sun_position(sun.time_utc, *ZURICH).elevation_deg - elevation_deg) < 0.02
    assert 0.0 < sun.azimuth_deg < 180.0  # morning: the sun in the east
    later = sun_position(sun.time_utc + timedelta(minutes=10), *ZURICH).elevation_deg
    assert later > elevation_deg  # and climbing


def test_noon_is_the_highest_sun_and_out_of_reach_is_an_error() -> None:
    day = datetime(2026, 11, 18, tzinfo=UTC)
    noon = sheet.sun_time(day, *ZURICH, None)
    for minutes in (-6, 6):
        beside = sun_position(noon.time_utc + timedelta(minutes=minutes), *ZURICH)
        assert beside.elevation_deg < noon.elevation_deg
    assert 160.0 < noon.azimuth_deg < 200.0
    with pytest.raises(ValueError, match="never 40 deg"):
        sheet.sun_time(day, *ZURICH, 40.0)  # a November noon at Zurich is 23° high


def _worktrees() -> set[str]:
    """The tool's temporary worktrees (other worktrees of this repository come and go with
    other people's work meanwhile)."""
    listed = subprocess.run(
        ["git", "worktree", "list", "--porcelain"], cwd=ROOT, capture_output=True, text=True
    ).stdout
    return {
        line
        for line in listed.splitlines()
        if line.startswith("worktree ") and "light-sheet-" in line
    }


@pytest.mark.gl
def test_before_and_after_are_drawn_by_their_own_revisions(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A revision whose wxsky/ differs from this checkout's: main two commits before issue 41.
    old = "a87ac5c"
    probe = subprocess.run(
        ["git", "rev-parse", "--verify", f"{old}^{{commit}}"], cwd=ROOT, capture_output=True
    )
    if probe.returncode != 0:
        pytest.skip(f"this clone lacks {old}")
    before_trees = _worktrees()
    argv = [
        "--preset", "clear", "--moment", "sun+5", "--size", "64x36", "--before", old,
        "--out-dir", str(tmp_path / "out"), "--cache-dir", str(tmp_path / "cache"), "--jobs", "2",
    ]  # fmt: skip
    assert sheet.main(argv) == 0
    first = capsys.readouterr().out
    assert _worktrees() == before_trees  # the temporary worktree is gone
    _, old_key = sheet.revision_key(old)
    new_key = sheet.checkout_key(ROOT)
    assert old_key != new_key
    for key in (old_key, new_key):
        assert len(list((tmp_path / "cache" / key).glob("*.png"))) == 2  # toward and away
    assert f"[{old_key}] 2/2" in first and f"[{new_key}] 2/2" in first
    out = read_png(tmp_path / "out" / "light-sheet-clear.png")
    assert out.shape == (
        sheet.HEADER_H_PX + 36 + sheet.GAP_PX,
        sheet.LABEL_W_PX + 4 * 64 + 2 * sheet.GAP_PX + sheet.PAIR_GAP_PX,
        4,
    )
    index = (tmp_path / "out" / "light-sheet.md").read_text()
    assert "light-sheet-clear.png" in index and old in index
    # A rerun draws nothing: every cell comes from the cache.
    assert sheet.main(argv) == 0
    assert "/2 " not in capsys.readouterr().out
