"""The CIGI host emulator (tools/emulators/cigi_host.py, its flight in
tools/emulators/cigi_script.py) against a real daemon: the whole script played in a few seconds
gets a Start of Frame for its messages and an answer to each request, and leaves the daemon with
the layers, clock and camera it sent."""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime
from pathlib import Path

import pytest
from daemon_harness import running_daemon
from tool_loader import load_tool

from wxsky.protocols.cigi_session import Region
from wxsky.protocols.cigi_weather import region_weight

# Before the tool that imports it, so both share one module.
script = load_tool("emulators/cigi_script")
host = load_tool("emulators/cigi_host")

SECONDS = 3.0


def test_the_storm_is_half_blended_in_when_the_script_ends() -> None:
    end = script.moment(script.LENGTH_S)
    lat, lon = script.on_runway_line(script.STORM_ALONG_M)
    size = script.STORM_SIZE_M
    storm = Region(1, True, lat, lon, size, size, 1000.0, 154.0, script.STORM_PERIMETER_M)
    assert end.phase is script.SCRIPT[-1]
    assert region_weight(storm, end.lat_deg, end.lon_deg) == pytest.approx(0.5, abs=0.01)
    assert region_weight(storm, *script.on_runway_line(0.0)) == 0.0


@pytest.mark.gl
def test_emulated_flight_against_the_daemon(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    small = "[camera]\nwidth = 640\nheight = 360\n"  # llvmpipe keeps up at this size
    with (
        running_daemon(tmp_path, small, ("--cigi", "udp:127.0.0.1:0")) as daemon,
        daemon.client() as client,
    ):
        ig = next(i for i in client.call("status")["inputs"] if i["kind"] == "cigi")
        pcap = tmp_path / "flight.pcap"
        args = ["--to", f"udp:{ig['listen']}", "--seconds", str(SECONDS), "--json"]
        assert host.main([*args, "--byte-order", "little", "--pcap", str(pcap)]) == 0
        status = client.call("status")
    s = json.loads(capsys.readouterr().out)

    assert [p["name"] for p in s["phases"]] == [p.name for p in script.SCRIPT]
    assert s["messages_sent"] >= 0.5 * 60 * SECONDS  # a loaded machine drops late ticks
    sof = s["start_of_frame"]
    assert sof["received"] >= 5
    assert sof["ig_frames_without_sof"] == 0
    # The SOFs after the last message say the daemon applied it.
    assert sof["last_host_frame_applied"] == s["messages_sent"]
    assert sof["lag_host_frames"]["median"] >= 0
    assert s["requests"]["sent"] in (SECONDS, SECONDS + 1)  # one a second, from the start
    assert s["requests"]["answered"] == s["requests"]["sent"]
    assert s["responses"]["weather_conditions_response"] == s["requests"]["sent"]
    assert s["responses"]["aerosol_concentration_response"] >= s["requests"]["sent"]
    assert s["problems"] == {}  # nothing refused, dropped or in the other byte order
    assert s["pcap"]["datagrams"] >= s["messages_sent"] + sof["received"]
    assert pcap.stat().st_size > 0

    ig = next(i for i in status["inputs"] if i["kind"] == "cigi")
    assert (ig["datagrams"], ig["dropped"], ig["byte_order"]) == (s["messages_sent"], {}, "little")
    assert (ig["layers"], ig["regions"]) == (2, 1)  # the deck, and the storm's cumulonimbus
    target = status["target"]
    assert target["sources"]["layers"] == target["sources"]["time_utc"] == "cigi"
    deck = next(lay for lay in target["layers"] if lay["type"] == "stratocumulus")
    assert (deck["cover_oktas"], deck["base_m"], deck["top_m"]) == pytest.approx((7.2, 900, 1600))
    storm = next(lay for lay in target["layers"] if lay["type"] == "cumulonimbus")
    assert (storm["base_m"], storm["top_m"]) == pytest.approx((900, 9900))
    assert storm["cover_oktas"] == pytest.approx(0.5 * 80 * 0.08, abs=0.2)  # half blended in
    # Dusk, 19:45, and the daemon's clock running on from there.
    clock = datetime.fromisoformat(status["weather"]["time_utc"].replace("Z", "+00:00"))
    assert (
        datetime(2026, 6, 21, 19, 45, tzinfo=UTC)
        <= clock
        < datetime(2026, 6, 21, 19, 46, tzinfo=UTC)
    )

    camera = status["camera"]
    along, heading = script.SCRIPT[-1].along_m[1], math.radians(script.RUNWAY_DEG)
    expected = (along * math.sin(heading), along * math.cos(heading), 2400.0)
    assert camera["position_m"] == pytest.approx(expected, abs=1.0)
    assert (camera["heading_deg"], camera["pitch_deg"], camera["fov_deg"]) == pytest.approx(
        (154.0, 0.0, 60.0), abs=1e-3
    )
