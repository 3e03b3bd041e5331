"""A channel's sim clock following the master's (wxsky/share/clock.py), the view a channel
turns from the shared camera (scene.camera.turned), and an engine that follows another's sky
(SkyEngine.follow): the same cloud field, to the bit, for the same sim time."""

from __future__ import annotations

import dataclasses
import math
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from wxsky.engine.stages import SkyEngine
from wxsky.scene.camera import Camera, turned
from wxsky.scene.layout import SceneSettings
from wxsky.settings.presets import load_preset
from wxsky.share.clock import (
    FAST_PINGS,
    GOOD_RTT_S,
    MAX_OFFSET_STEP_S,
    MAX_TICK_AHEAD_S,
    OFFSET_OUTVOTE,
    PING_EVERY_S,
    PING_FAST_S,
    ClockFollower,
)
from wxsky.share.messages import ClockTick
from wxsky.weather.state import EARLIEST_UTC, LATEST_UTC, Source, WeatherPatch, WeatherState
from wxsky.weather.transition import TransitionRates

T0 = datetime(2026, 6, 21, 13, 0, tzinfo=UTC)
MASTER = "0123456789abcdef"


def _tick(master_s: float, sim: datetime, rate: float = 1.0, master: str = MASTER) -> ClockTick:
    return ClockTick("default", master, master_s, sim, rate, 1, None, None)


def test_the_best_round_trip_sets_the_offset_and_time_follows_the_rate() -> None:
    clock = ClockFollower()
    assert clock.time_at(10.0) is None  # nothing heard yet
    # The master's monotonic clock is 100 s ahead of ours; one-way delays of 1 and 4 ms.
    clock.ping(sent_s=10.000, master_s=110.001, received_s=10.002, master_id=MASTER)
    clock.ping(sent_s=11.000, master_s=111.006, received_s=11.008, master_id=MASTER)
    assert clock.offset_s == pytest.approx(100.0, abs=1e-9)  # the 2 ms round trip wins
    assert clock.rtt_s == pytest.approx(0.002)
    clock.tick(_tick(112.0, T0, rate=2.0), received_s=12.003)
    # At our 12.5 s the master reads 112.5: half a second after its tick, twice as fast.
    assert clock.time_at(12.5) == T0 + timedelta(seconds=1.0)
    # An older tick arriving late changes nothing.
    clock.tick(_tick(111.0, T0 - timedelta(seconds=9)), received_s=12.6)
    assert clock.time_at(12.5) == T0 + timedelta(seconds=1.0)


def test_a_tick_far_from_the_masters_clock_is_dropped_and_cannot_hold_back_the_next() -> None:
    """Issue 40: a copy of the master's tick with `master_mono_s = 1e12` ended a channel
    (OverflowError); one a day ahead would have held back every real tick for a day."""
    clock = ClockFollower()
    clock.ping(sent_s=10.000, master_s=110.001, received_s=10.002, master_id=MASTER)
    assert clock.tick(_tick(110.5, T0), received_s=10.51) is None
    for forged in (1e12, 110.6 + 86_400.0, 110.6 + MAX_TICK_AHEAD_S + 0.1, 0.0):
        reason = clock.tick(_tick(forged, T0 + timedelta(days=3)), received_s=10.6)
        assert reason is not None and "master's clock" in reason, forged
    assert clock.latest is not None and clock.latest.master_mono_s == 110.5
    assert clock.tick(_tick(110.7, T0 + timedelta(seconds=0.2)), received_s=10.71) is None
    assert clock.time_at(10.7) == T0 + timedelta(seconds=0.2)


def test_a_forged_first_tick_gives_way_to_the_masters_own() -> None:
    clock = ClockFollower()
    clock.tick(_tick(1e9, T0 + timedelta(days=300)), received_s=10.0)  # nothing to judge by
    assert clock.tick(_tick(110.0, T0), received_s=10.01) is None  # the first ping decides
    clock.ping(sent_s=10.02, master_s=110.021, received_s=10.022, master_id=MASTER)
    assert clock.tick(_tick(1e9, T0 + timedelta(days=300)), received_s=10.03) is not None
    assert clock.time_at(10.0) == T0


def test_one_pong_cannot_move_the_offset_but_several_that_agree_do() -> None:
    clock = ClockFollower()
    clock.ping(10.0, 110.001, 10.002, MASTER)
    far = 100.0 + 50 * MAX_OFFSET_STEP_S
    assert clock.ping(11.0, 11.0005 + far, 11.001, MASTER) is not None
    assert clock.offset_s == pytest.approx(100.0)
    # The estimate was the odd one out (a forged first pong): the master's own outvote it.
    for i in range(1, OFFSET_OUTVOTE):
        assert clock.offset_s == pytest.approx(100.0)
        clock.ping(11.0 + i, 11.0005 + i + far, 11.001 + i, MASTER)
    assert clock.offset_s == pytest.approx(far)


def test_no_tick_rate_or_offset_carries_the_time_out_of_the_clocks_range() -> None:
    clock = ClockFollower()
    clock.tick(_tick(0.0, LATEST_UTC - timedelta(seconds=1), rate=10_000.0), received_s=0.0)
    assert clock.time_at(3.0e9) == LATEST_UTC - timedelta(microseconds=1)
    clock.tick(_tick(3.0e9, EARLIEST_UTC, rate=10_000.0, master="1" * 16), received_s=3.0e9)
    assert clock.time_at(0.0) == EARLIEST_UTC


def test_before_a_ping_a_ticks_arrival_stands_in_and_a_new_master_starts_afresh() -> None:
    clock = ClockFollower()
    clock.tick(_tick(50.0, T0), received_s=20.0)
    assert clock.offset_s == pytest.approx(30.0)
    assert clock.time_at(21.0) == T0 + timedelta(seconds=1.0)
    clock.ping(20.0, 50.0005, 20.001, MASTER)
    assert clock.offset_s == pytest.approx(30.0)
    # A restarted master: another id, another monotonic clock; what was learnt is dropped.
    clock.tick(_tick(5.0, T0 + timedelta(hours=1), master="fedcba9876543210"), received_s=30.0)
    assert clock.rtt_s is None and clock.offset_s == pytest.approx(-25.0)
    assert clock.time_at(30.5) == T0 + timedelta(hours=1, seconds=0.5)
    clock.ping(31.0, 6.0, 30.9, "fedcba9876543210")  # received before sent: ignored
    assert clock.rtt_s is None


@pytest.mark.parametrize("heading", [0.0, 90.0, 271.0])
def test_a_level_view_offset_turns_the_heading_alone(heading: float) -> None:
    cam = Camera((1.0, 2.0, 3.0), heading, 0.0, 0.0, 60.0, 320, 180)
    for yaw in (-60.0, 0.0, 60.0, 179.0):
        view = turned(cam, yaw, 0.0, 0.0)
        assert view.heading_deg == pytest.approx((heading + yaw) % 360.0, abs=1e-9)
        assert view.pitch_deg == pytest.approx(0.0, abs=1e-9)
        assert view.roll_deg == pytest.approx(0.0, abs=1e-9)
        assert view.position_m == cam.position_m and view.width_px == 320


def test_a_view_offset_is_turned_in_the_cameras_own_axes() -> None:
    """Each view's forward ray is the camera's basis applied to the offset's, whatever the
    camera's attitude: channels either side of a climbing, banking ownship stay side by side."""
    rng = np.random.default_rng(5)
    for _ in range(50):
        h, p, r = rng.uniform(0, 360), rng.uniform(-60, 60), rng.uniform(-90, 90)
        yaw, pitch, roll = rng.uniform(-120, 120), rng.uniform(-30, 30), rng.uniform(-20, 20)
        cam = Camera((0.0, 0.0, 0.0), h, p, r)
        right, up, fwd = cam.basis()
        view = turned(cam, yaw, pitch, roll)
        v_right, v_up, v_fwd = Camera((0.0, 0.0, 0.0), yaw, pitch, roll).basis()
        body = np.stack([right, fwd, up], axis=1)
        got_right, got_up, got_fwd = view.basis()
        np.testing.assert_allclose(got_fwd, body @ v_fwd, atol=1e-9)
        np.testing.assert_allclose(got_right, body @ v_right, atol=1e-9)
        np.testing.assert_allclose(got_up, body @ v_up, atol=1e-9)
    assert math.isclose(turned(Camera((0, 0, 0)), 0.0, 90.0, 0.0).pitch_deg, 90.0)


def test_a_following_engine_builds_the_masters_cloud_field_for_the_same_time() -> None:
    """The master runs a transition; a channel given its shared sky and its clock has the
    same applied weather and drift (to the bit) and the same near sprites at every frame, and
    never steps the weather itself."""
    settings = SceneSettings(max_range_m=16_000.0)
    start = dataclasses.replace(WeatherState().apply(load_preset("fair-cumulus")), time_utc=T0)
    cam = Camera((0.0, 0.0, 1500.0), 90.0, 0.0, 0.0, 60.0, 160, 90)
    slow = TransitionRates(cover_oktas_per_min=3.0)
    with (
        SkyEngine(start, cam, settings, rates=slow, ring_build="immediate") as master,
        SkyEngine(WeatherState(), cam, settings, ring_build="immediate") as channel,
    ):
        master.drift_for(600.0)  # clouds blown on 10 minutes: a non-zero anchor
        master.apply(
            WeatherPatch(source=Source.CONTROL, layers=load_preset("overcast-stratus").layers)
        )
        for frame in range(6):
            plan = master.advance(0.5 if frame else 0.0)
            channel.follow(master.shared())
            channel.follow_time(plan.state.time_utc)
            mine = channel.advance(0.5 if frame else 0.0)
            assert mine.state.layers == plan.state.layers
            assert channel.drift == master.drift
            assert mine.frame.near.sprites.centre_m.tobytes() == (
                plan.frame.near.sprites.centre_m.tobytes()
            )
        assert not master.settled  # the transition is under way, in steps
        # On its own the channel moves neither the clock nor the weather.
        before = channel.state
        channel.advance(5.0)
        assert channel.state == before and channel.following


def test_a_channel_refuses_the_masters_commands_and_the_camera_only_while_it_is_shared() -> None:
    from wxsky.app.share_part import SharePart
    from wxsky.output.wire import pack_data
    from wxsky.settings.config import ChannelSection, DaemonConfig
    from wxsky.share.messages import encode_tick

    config = DaemonConfig(channel=ChannelSection(join="tcp/127.0.0.1:7447", name="left"))
    cam = Camera((0.0, 0.0, 1500.0))
    part = SharePart(config)
    assert part.role == "channel" and not part.master_alive
    for command in ("apply_preset", "apply_metar", "release", "set_time"):
        refused = part.refusal(command)
        assert refused is not None and "sky master at zenoh:tcp/127.0.0.1:7447" in refused
    assert part.refusal("set_camera") is None  # nothing shared yet
    assert part.refusal("status") is None
    part._master_seen(MASTER, True, 0.0)  # ticks count only from the run whose token is alive
    part._got_tick(pack_data(encode_tick(_tick(1.0, T0))), 1.0)  # a master sharing none
    assert part.refusal("set_camera") is None
    shared = dataclasses.replace(_tick(2.0, T0), camera=cam)
    part._got_tick(pack_data(encode_tick(shared)), 2.0)
    assert "shared camera" in (part.refusal("set_camera") or "")
    part._got_tick(b"\xc1 not msgpack", 3.0)
    assert part.status()["channel"]["dropped"] == {"clock": 1}
    standalone = SharePart(DaemonConfig())
    assert standalone.role == "standalone" and standalone.refusal("apply_preset") is None


def test_a_channel_pings_quickly_until_a_short_round_trip_then_settles() -> None:
    clock = ClockFollower()
    # Nothing heard: quick pings, but not for ever (no master to answer them).
    waits = [clock.wait_before_ping_s() for _ in range(FAST_PINGS + 3)]
    assert waits[:FAST_PINGS] == [PING_FAST_S] * FAST_PINGS
    assert waits[FAST_PINGS:] == [PING_EVERY_S] * 3
    # A master: quick again while its round trips are slow (a busy machine just after a
    # join), and settled once one comes back within GOOD_RTT_S.
    clock.ping(sent_s=1.0, master_s=101.0, received_s=1.02, master_id=MASTER)
    assert clock.wait_before_ping_s() == PING_FAST_S
    clock.ping(sent_s=1.1, master_s=101.1, received_s=1.1 + GOOD_RTT_S / 2, master_id=MASTER)
    assert clock.wait_before_ping_s() == PING_EVERY_S
    assert clock.offset_s == pytest.approx(100.0 - GOOD_RTT_S / 4)
