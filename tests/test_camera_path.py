"""Camera path files for `wxsky bench`: parsing (garbage, truncation, out-of-range values) and
interpolation between poses."""

from __future__ import annotations

import math

import pytest

from wxsky.app.camera_path import parse_camera_path, straight_and_level, turn_in_place
from wxsky.errors import ConfigError

GOOD = """# a climbing turn
t_s, x_m, y_m, z_m, heading_deg, pitch_deg, roll_deg
0.0, 0, 0, 1500, 350, 0
2.0, 100, 200, 1600, 10, 4, -20

4.0, 100, 200, 1600, 10, 4
"""


def test_a_good_file_reads_with_header_comments_and_blank_lines() -> None:
    path = parse_camera_path(GOOD, "flight.csv")
    assert len(path.poses) == 3 and path.name == "flight.csv"
    assert path.poses[1].roll_deg == -20.0 and path.poses[2].roll_deg == 0.0


def test_poses_are_interpolated_and_headings_turn_the_short_way() -> None:
    path = parse_camera_path(GOOD, "f")
    mid = path.at(1.0)
    assert mid.position_m == pytest.approx((50.0, 100.0, 1550.0))
    assert mid.heading_deg == pytest.approx(0.0, abs=1e-9) or mid.heading_deg == pytest.approx(
        360.0
    )
    assert mid.pitch_deg == pytest.approx(2.0) and mid.roll_deg == pytest.approx(-10.0)
    assert path.at(-5.0) == path.poses[0]
    assert path.at(99.0) == path.poses[-1]


def test_the_default_flight_is_level_at_120_mps() -> None:
    path = straight_and_level()
    a, b = path.at(0.0), path.at(10.0)
    assert a.position_m[2] == b.position_m[2] == 1500.0
    assert math.dist(a.position_m, b.position_m) == pytest.approx(1200.0)
    assert b.position_m[0] == pytest.approx(1200.0)  # heading 090: east


def test_the_turn_goes_all_the_way_round() -> None:
    path = turn_in_place(seconds=2.0)
    headings = [path.at(t).heading_deg for t in (0.0, 0.5, 1.0, 1.5, 1.99)]
    assert headings[:4] == pytest.approx([0.0, 90.0, 180.0, 270.0])
    assert headings[4] > 355.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "no poses"),
        ("# only a comment\n", "no poses"),
        ("0, 0, 0, 1500, 90\n", "line 1: expected t_s, x_m"),  # truncated
        ("0, 0, 0, 1500, 90, 0, 0, 9\n", "got 8 fields"),
        ("0, 0, zero, 1500, 90, 0\n", "'zero' is not a number"),
        ("\x00\xff garbage,,,,,\n", "is not a number"),
        ("0, 0, 0, nan, 90, 0\n", "finite"),
        ("0, 0, 0, 1500, 90, 0\n0, 1, 0, 1500, 90, 0\n", "line 2: t_s 0 must be"),
        ("-1, 0, 0, 1500, 90, 0\n", "t_s -1 must be >= 0"),
        ("0, 0, 0, 40000, 90, 0\n", "z_m 40000 outside"),
        ("0, 900000, 0, 1500, 90, 0\n", "more than 500 km"),
        ("0, 0, 0, 1500, 90, 95\n", "pitch_deg 95 outside"),
        ("0, 0, 0, 1500, 90, 0, 200\n", "roll_deg 200 outside"),
    ],
)
def test_bad_files_are_one_line_errors_naming_file_and_line(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message) as info:
        parse_camera_path(text, "path.csv")
    assert str(info.value).startswith("path.csv") and "\n" not in str(info.value)
