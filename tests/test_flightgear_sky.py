"""wxsky's clouds in FlightGear's own view (issue 44): Debian's FlightGear 2020.3 started by
`fgfs-with-wxsky --sky` draws them through the osgdb_wxsky plugin, FlightGear's clouds off.
Frozen over Honolulu in the chase view, FlightGear's picture (Xvfb's frame buffer: exactly what
it drew) must hold wxsky-host-snapshot's sky and clouds for the camera the plugin sent, where
nothing of FlightGear's stands before them, and must not where its aircraft and terrain do.
Skips where FlightGear is not installed (tools/setup does not install it: about 3 GB)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from host_kit import gl_program, host_kit  # noqa: F401
from osg_kit import osg_kit  # noqa: F401

from tools.gallery import flightgear_sky as fgsky
from wxsky.host.client import ControlClient

# One FlightGear at a time: the two FlightGear tests share a worker (--dist loadgroup).
pytestmark = [pytest.mark.gl, pytest.mark.xdist_group("flightgear")]


def test_flightgears_view_shows_wxskys_clouds_behind_its_aircraft_and_terrain(
    osg_kit: Path,  # noqa: F811
    host_kit: Path,  # noqa: F811
    tmp_path: Path,
) -> None:
    why = fgsky.missing()
    if why is not None:
        pytest.skip(why)
    gl_program(host_kit, "wxsky-host-snapshot")
    with (
        fgsky.daemon(tmp_path, "scattered-cumulus") as control,
        ControlClient.connect(control) as client,
        fgsky.flightgear_with_sky(tmp_path / "fg", control) as fg,
    ):
        gmt = fg.props.get("/sim/time/gmt")
        client.call("set_time", {"time_utc": gmt + "Z", "rate": 0.0})
        number, heading, pitch = fgsky.VIEWS["chase"]
        fg.view(number, heading, pitch)
        camera = fgsky.settle(client)
        # the camera the plugin sends is FlightGear's view: over Honolulu (the daemon's site
        # moved there), at the view's height, its size
        assert (camera["width"], camera["height"]) == fgsky.SIZE
        assert 300.0 < float(camera["position_m"][2]) < 700.0  # type: ignore[index]
        seen = fg.screen().astype(int)
        host = fgsky.host_snapshot(control, tmp_path / "host.png").astype(int)
    near = np.abs(seen - host).max(axis=-1)
    h = near.shape[0]
    sky = near[: int(0.35 * h)]  # above the aircraft and the mountains
    ground = near[int(0.7 * h) :]  # Honolulu and the airport below the aircraft
    assert float(sky.mean()) <= 2.0, f"the sky differs by {sky.mean():.2f}/255"
    assert float((ground <= 3).mean()) <= 0.05, "wxsky's picture over FlightGear's terrain"
