"""Display channels meet without seams (docs/channels.md): a sky master and channels turned
-30/+30 degrees with 60-degree views (meeting straight ahead), and a third 60-degree view
turned +20 degrees whose left 10 degrees overlap the -30 one, real daemons on loopback, each
frame read from its own shared memory and composited as a host would. The pixels where two
views meet must agree: the edge columns of adjacent views, and the overlap of overlapping
ones reprojected from one view into the other, mean difference at most 2/255."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from daemon_harness import HANG_S, DaemonSpec, RunningDaemon, running_daemon, running_daemons
from test_channels import channel_args, free_port, status, wait_for

from wxsky.host.reference import HostFrame, ReferenceHost
from wxsky.png import write_png
from wxsky.scene.camera import Camera

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed")

# Four daemons, each drawing every frame.
pytestmark = pytest.mark.gl

W, H = 240, 136
CONFIG = f"""
[camera]
width = {W}
height = {H}
pitch_deg = 0.0
[scene]
ring_texture_px = 128
ring_slice_ms = 0
ring_fade_s = 0
"""
# Four daemons share two cores here: at 10 frames a second instead of 30 they leave the ring
# workers time to build. Each new ring's impostors are drawn whole, one a frame, and it comes
# in without a cross-fade: the settled frame compared is the same (a sliced impostor is the
# one drawn whole, byte for byte: test_render.py), only sooner.
DAEMON = "tick_hz = 10.0"
LEVEL = 2.0 / 255.0
F = npt.NDArray[np.float64]


def _camera(d: RunningDaemon) -> Camera:
    c = status(d)["camera"]
    return Camera(
        tuple(c["position_m"]),
        c["heading_deg"],
        c["pitch_deg"],
        c["roll_deg"],
        c["fov_deg"],
        c["width"],
        c["height"],
    )


def _picture(d: RunningDaemon) -> F:
    """The channel's latest frame once its ring has settled, composited: (H, W, 3) in 0..1."""
    with ReferenceHost.connect(d.address) as host:
        frame: HostFrame = host.wait_settled_frame(timeout_s=HANG_S)
        rgb = frame.composite()
    return np.asarray(rgb[..., :3], np.float64) / 255.0


def _sample(img: F, col: F, row: F) -> F:
    """Bilinear samples of img at fractional pixel centres (col, row)."""
    h, w = img.shape[:2]
    c0 = np.clip(np.floor(col).astype(int), 0, w - 2)
    r0 = np.clip(np.floor(row).astype(int), 0, h - 2)
    fc = np.clip(col - c0, 0.0, 1.0)[..., None]
    fr = np.clip(row - r0, 0.0, 1.0)[..., None]
    top = img[r0, c0] * (1 - fc) + img[r0, c0 + 1] * fc
    bottom = img[r0 + 1, c0] * (1 - fc) + img[r0 + 1, c0 + 1] * fc
    out: F = top * (1 - fr) + bottom * fr
    return out


def overlap_difference(a: F, cam_a: Camera, b: F, cam_b: Camera) -> tuple[float, int]:
    """Mean absolute difference over the pixels of b whose rays land inside a's picture (a
    sampled bilinearly there), and how many pixels that is."""
    rays = cam_b.pixel_rays()
    right, up, fwd = cam_a.basis()
    depth = rays @ fwd
    x = (rays @ right) / depth / cam_a.tan_half_fov_x
    y = (rays @ up) / depth / cam_a.tan_half_fov_y
    col = (x + 1.0) / 2.0 * cam_a.width_px - 0.5
    row = (1.0 - y) / 2.0 * cam_a.height_px - 0.5
    inside = (depth > 0) & (col >= 0) & (col <= cam_a.width_px - 1)
    inside &= (row >= 0) & (row <= cam_a.height_px - 1)
    if not inside.any():
        return float("nan"), 0
    got = _sample(a, col[inside], row[inside])
    return float(np.abs(got - b[inside]).mean()), int(inside.sum())


@contextlib.contextmanager
def master(tmp_path: Path, endpoint: str) -> Iterator[RunningDaemon]:
    (tmp_path / "master").mkdir()
    args = ("--share", f"zenoh:{endpoint}", "--preset", "broken-stratocumulus")
    with running_daemon(tmp_path / "master", CONFIG, args, daemon_config=DAEMON) as m:
        with m.client() as c:
            c.call(
                "set_camera",
                {"position_m": [0.0, 0.0, 900.0], "heading_deg": 0.0, "pitch_deg": 0.0},
            )
            c.call("set_time", {"time_utc": "2026-06-21T11:00:00Z", "rate": 0.0})
        yield m


def _run_channels(
    stack: contextlib.ExitStack,
    tmp_path: Path,
    endpoint: str,
    views: dict[str, tuple[float, float]],
) -> dict[str, RunningDaemon]:
    """The channels, started together (their start-ups overlap)."""
    specs = []
    for name, (yaw, fov) in views.items():
        (tmp_path / name).mkdir()
        args = (*channel_args(f"zenoh:{endpoint}", name, yaw), "--fov-deg", str(fov))
        specs.append(DaemonSpec(tmp_path / name, CONFIG, args, daemon_config=DAEMON))
    return dict(zip(views, stack.enter_context(running_daemons(specs)), strict=True))


def _follow(m: RunningDaemon, chans: dict[str, RunningDaemon]) -> None:
    def joined() -> bool:
        sky = status(m)["sky_id"]
        return all(
            (s := status(c))["sky_id"] == sky and s["channel"]["master_alive"]
            for c in chans.values()
        )

    wait_for("channels following the master", joined)


def test_adjacent_and_overlapping_channels_agree_where_they_meet(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with master(tmp_path, endpoint) as m, contextlib.ExitStack() as stack:
        # "ov" (-10..50 degrees) overlaps "left" (-60..0) by 10 degrees, each view's edge
        # over the other's: the adjacent pair is one of the overlapping pair too, so three
        # channels (not four, two a check) do both checks.
        views = {
            "left": (-30.0, 60.0),
            "right": (30.0, 60.0),
            "ov": (20.0, 60.0),
        }
        everyone = _run_channels(stack, tmp_path, endpoint, views)
        _follow(m, everyone)
        pictures = {name: _picture(d) for name, d in everyone.items()}
        cams = {name: _camera(d) for name, d in everyone.items()}
        times = {status(d)["sim_clock"]["time_utc"][:19] for d in everyone.values()}
        assert times == {"2026-06-21T11:00:00"}  # one moment: the clock stands still
    # The pictures a person would look at: the two adjacent views side by side, then the two
    # overlapping ones.
    row1 = np.concatenate([pictures[n] for n in ("left", "right")], axis=1)
    row2 = np.concatenate([pictures["left"], pictures["ov"]], axis=1)
    sheet = (np.concatenate([row1, row2], axis=0) * 255.0 + 0.5).astype(np.uint8)
    sheet = np.concatenate([sheet, np.full((*sheet.shape[:2], 1), 255, np.uint8)], axis=2)
    write_png(tmp_path / "seams.png", sheet)
    # Adjacent: the last column of each view against the first of the next one (the rows of
    # both edges see the same rays; the columns are a pixel apart).
    seams = []
    for a, b in (("left", "right"),):
        diff = float(np.abs(pictures[a][:, -1] - pictures[b][:, 0]).mean())
        seams.append(diff)
        assert diff <= LEVEL, f"{a}|{b} edge columns differ by {255 * diff:.2f}/255 on average"
    # (The views are where the seams say.)
    assert abs(cams["left"].heading_deg - 330.0) < 1e-6
    assert abs(cams["right"].heading_deg - 30.0) < 1e-6
    assert abs(cams["ov"].heading_deg - 20.0) < 1e-6
    # Overlapping: 10 degrees of each 60-degree view are the other's.
    diff, pixels = overlap_difference(pictures["left"], cams["left"], pictures["ov"], cams["ov"])
    assert pixels > 0.1 * W * H, pixels
    assert diff <= LEVEL, f"the overlap differs by {255 * diff:.2f}/255 on average"
    print(
        "seam means /255:",
        [round(255 * s, 3) for s in seams],
        "overlap /255:",
        round(255 * diff, 3),
        "over",
        pixels,
        "pixels",
    )
