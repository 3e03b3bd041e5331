"""The sky a CIGI host makes, as a picture: docs/gallery/cigi-session.png.

    .venv/bin/python tools/gallery/cigi_gallery.py [--out docs/gallery/cigi-session.png]

Starts a private daemon listening for a CIGI host (`--cigi udp:127.0.0.1:0`), plays moments of
the host emulator's flight (tools/emulators/cigi_script.py: taxi at Zurich, inside the stratocumulus
deck on the climb, above it with the regional thunderstorm ahead, the jump to dusk, the deck
thickened) as a host sends them, waits for the frame that shows each (the ownship's camera,
the rings settled) and composites it from shared memory as a host does; one panel a moment,
titled with the phase and what the daemon's stream says of it (in cloud, visibility).
Transitions are instant here so each panel shows the host's weather, not the way to it.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`

from tools.emulators import cigi_script
from tools.emulators.cockpit_daemon import private_daemon
from wxsky.host.client import ControlClient
from wxsky.host.reference import host_frame
from wxsky.inputs.cigi_link import CigiHostSocket, parse_udp
from wxsky.output.shm import FrameReader
from wxsky.protocols.cigi import make

ROOT = Path(__file__).resolve().parents[2]
CONFIG = """
[output]
max_width = 480
max_height = 270
[camera]
width = 480
height = 270
[transition]
cover_oktas_per_min = 0.0
base_m_per_min = 0.0
wind_mps_per_s = 0.0
visibility_m_per_s = 0.0
temperature_c_per_min = 0.0
qnh_hpa_per_min = 0.0
"""
# Seconds into the script, one panel each: taxiing, just under the deck, in it, above it,
# at dusk with the storm region's cumulonimbus blending in, the deck thickened and lowered.
MOMENTS = (5.0, 55.0, 62.0, 95.0, 128.0, 139.0)
COLUMNS = 3
SETTLE_TIMEOUT_S = 60.0
SETTLE_FRAMES = 4


def _settled(
    client: ControlClient, frames: ControlClient, alt_m: float, after_frame: int
) -> dict[str, Any]:
    """A frame notification, a few frames after `after_frame` (a ring rebuild the move calls
    for has then begun), with the camera at the ownship's height, the weather at its target
    and the ring idle."""
    deadline = time.monotonic() + SETTLE_TIMEOUT_S
    while time.monotonic() < deadline:
        note = frames.next_notification(timeout_s=1.0)
        if note is None or note.method != "frame":
            continue
        params: dict[str, Any] = note.params
        if params["frame_number"] < after_frame + SETTLE_FRAMES:
            continue
        if abs(params["camera"]["position_m"][2] - alt_m) > 1.0:
            continue
        if client.call("status")["settled"] and not client.call("scene")["ring_busy"]:
            return params
    raise SystemExit("the daemon did not settle on the host's view in time")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "gallery" / "cigi-session.png")
    args = p.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = []
    with (
        private_daemon(CONFIG, ["--cigi", "udp:127.0.0.1:0"]) as (_, client),
        ControlClient.connect(client.address) as frames,
    ):
        status = client.call("status")
        shm = status["shm_name"]
        listen = next(i["listen"] for i in status["inputs"] if i["kind"] == "cigi")
        frames.subscribe(["frame"])
        with CigiHostSocket(parse_udp(f"udp:{listen}")) as host:
            for number, t in enumerate(MOMENTS, 1):
                m = cigi_script.moment(t)
                sent_at = client.call("status")["frames_published"]
                host.send(
                    [
                        make("ig_control", ig_mode=1, host_frame_number=number),
                        cigi_script.ownship(m),
                        cigi_script.view_definition(),
                        *cigi_script.world(m.phase, set_clock=True),
                    ]
                )
                params = _settled(client, frames, m.alt_m, sent_at)
                with FrameReader.open(shm) as reader:
                    image = host_frame(reader.read(timeout_s=2.0)).composite()
                seen = (
                    f"in cloud, {params['in_cloud_visibility_m']:.0f} m"
                    if params["in_cloud"]
                    else "clear of cloud"
                )
                hour, minute = m.phase.clock_utc
                title = f"{m.phase.name}\n{m.alt_m:.0f} m, {hour:02d}:{minute:02d} UTC, {seen}"
                panels.append((image, title))
                print(f"{t:5.0f} s: {title.replace(chr(10), ', ')}", file=sys.stderr)
    rows = -(-len(panels) // COLUMNS)
    fig, axes = plt.subplots(rows, COLUMNS, figsize=(4.2 * COLUMNS, 2.9 * rows), dpi=110)
    for ax, (image, title) in zip(axes.flat, panels, strict=True):
        ax.imshow(image)
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.suptitle(
        "A CIGI 3.3 host drives wxsky (the flight of tools/emulators/cigi_host.py): ownship, "
        "clock, stratocumulus deck, regional thunderstorm",
        fontsize=10,
    )
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out)
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
