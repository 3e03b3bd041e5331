"""Camera paths for `wxsky bench`: timestamped poses, read from a text file or made up.

File format: one pose per line, comma-separated,

    t_s, x_m, y_m, z_m, heading_deg, pitch_deg[, roll_deg]

t_s in seconds from the start, strictly increasing; x, y, z in metres east, north and up (MSL)
around the observer; heading 0 = north, clockwise; pitch positive up. Blank lines and lines
starting with `#` are skipped, and so is a first line of column names. Between poses the camera
moves linearly (heading the short way round); after the last it holds.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from wxsky.errors import ConfigError
from wxsky.scene.camera import PITCH_DEG, ROLL_DEG
from wxsky.weather.state import ALT_M

MAX_OFFSET_M = 500_000.0


@dataclass(frozen=True)
class Pose:
    t_s: float
    position_m: tuple[float, float, float]
    heading_deg: float
    pitch_deg: float
    roll_deg: float = 0.0


@dataclass(frozen=True)
class CameraPath:
    poses: tuple[Pose, ...]  # by time, at least one
    name: str = "path"

    def at(self, t_s: float) -> Pose:
        """The pose at t_s, interpolated (held before the first and after the last)."""
        poses = self.poses
        if t_s <= poses[0].t_s:
            return poses[0]
        for a, b in itertools.pairwise(poses):
            if t_s <= b.t_s:
                u = (t_s - a.t_s) / (b.t_s - a.t_s)
                turn = (b.heading_deg - a.heading_deg + 180.0) % 360.0 - 180.0
                pa, pb = a.position_m, b.position_m
                return Pose(
                    t_s,
                    (
                        pa[0] + (pb[0] - pa[0]) * u,
                        pa[1] + (pb[1] - pa[1]) * u,
                        pa[2] + (pb[2] - pa[2]) * u,
                    ),
                    (a.heading_deg + turn * u) % 360.0,
                    a.pitch_deg + (b.pitch_deg - a.pitch_deg) * u,
                    a.roll_deg + (b.roll_deg - a.roll_deg) * u,
                )
        return poses[-1]


def straight_and_level(
    speed_mps: float = 120.0,
    alt_m: float = 1500.0,
    heading_deg: float = 90.0,
    seconds: float = 60.0,
) -> CameraPath:
    """The default benchmark flight: level at alt_m, speed_mps along heading_deg, from the
    observer, looking ahead and a little up."""
    h = math.radians(heading_deg)
    end = (speed_mps * seconds * math.sin(h), speed_mps * seconds * math.cos(h), alt_m)
    return CameraPath(
        (
            Pose(0.0, (0.0, 0.0, alt_m), heading_deg, 5.0),
            Pose(seconds, end, heading_deg, 5.0),
        ),
        name=f"straight and level, {speed_mps:g} m/s at {alt_m:g} m",
    )


def turn_in_place(
    seconds: float = 2.0, alt_m: float = 1500.0, pitch_deg: float = 10.0, steps: int = 8
) -> CameraPath:
    """A full turn on the spot in `seconds` (to watch the near sprites' order as the view
    swings round)."""
    poses = tuple(
        Pose(seconds * k / steps, (0.0, 0.0, alt_m), 360.0 * k / steps % 360.0, pitch_deg)
        for k in range(steps + 1)
    )
    # The last pose is heading 0 again: the interpolation's short way round would turn back.
    poses = (*poses[:-1], Pose(seconds, (0.0, 0.0, alt_m), 359.999, pitch_deg))
    return CameraPath(poses, name=f"360° turn in {seconds:g} s")


def parse_camera_path(text: str, where: str) -> CameraPath:
    """Poses from the file format above; a bad line raises ConfigError naming `where`, the
    line and what is wrong."""
    poses: list[Pose] = []
    first_content = True
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = [f.strip() for f in line.split(",")]
        if first_content and fields and fields[0].lower() in ("t_s", "t", "time_s"):
            first_content = False
            continue
        first_content = False
        at = f"{where} line {number}"
        if len(fields) not in (6, 7):
            raise ConfigError(
                f"{at}: expected t_s, x_m, y_m, z_m, heading_deg, pitch_deg[, roll_deg], "
                f"got {len(fields)} fields"
            )
        try:
            values = [float(f) for f in fields]
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            raise ConfigError(f"{at}: {bad!r} is not a number") from None
        if not all(math.isfinite(v) for v in values):
            raise ConfigError(f"{at}: values must be finite")
        t_s, x, y, z, heading, pitch = values[:6]
        roll = values[6] if len(values) == 7 else 0.0
        if t_s < 0.0 or (poses and t_s <= poses[-1].t_s):
            raise ConfigError(f"{at}: t_s {t_s:g} must be >= 0 and after the previous pose's")
        if max(abs(x), abs(y)) > MAX_OFFSET_M:
            raise ConfigError(f"{at}: x/y more than {MAX_OFFSET_M / 1000:g} km from the observer")
        for name, kind, value in (
            ("z_m", ALT_M, z),
            ("pitch_deg", PITCH_DEG, pitch),
            ("roll_deg", ROLL_DEG, roll),
        ):
            if not kind.contains(value):
                raise ConfigError(f"{at}: {name} {value:g} outside {kind.range_text()}")
        poses.append(Pose(t_s, (x, y, z), heading % 360.0, pitch, roll))
    if not poses:
        raise ConfigError(f"{where}: no poses")
    return CameraPath(tuple(poses), name=where)


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
