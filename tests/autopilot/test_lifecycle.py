"""Flight lifecycle, boot→GPS time and packet loss: the pure cores of the autopilot link."""

from __future__ import annotations

import datetime as dt

from onboard.autopilot.lifecycle import (
    LANDED_IN_AIR,
    LANDED_LANDING,
    LANDED_ON_GROUND,
    LANDED_TAKEOFF,
    LANDED_UNDEFINED,
    BootTimeMap,
    FlightLifecycle,
    SequenceLoss,
    is_autopilot_heartbeat,
)
from onboard.gnsstime import GpsTime

ARMED = 128 | 1
DISARMED = 1
S = 1_000_000_000


def names(events: list) -> list[str]:
    return [e.event for e in events]


def test_only_flight_controllers_count() -> None:
    assert is_autopilot_heartbeat(2, 3)  # quadrotor, ArduPilot
    assert is_autopilot_heartbeat(1, 12)  # fixed wing, PX4
    assert not is_autopilot_heartbeat(6, 8)  # a ground station
    assert not is_autopilot_heartbeat(18, 8)  # a companion (us)
    assert not is_autopilot_heartbeat(2, 8)  # autopilot INVALID
    assert not is_autopilot_heartbeat(26, 3)  # a gimbal


def test_arm_takeoff_land_disarm() -> None:
    lc = FlightLifecycle()
    seen = []
    seen += lc.on_heartbeat(DISARMED, 1 * S)
    seen += lc.on_landed_state(LANDED_ON_GROUND, 1 * S)
    seen += lc.on_heartbeat(ARMED, 2 * S)
    seen += lc.on_heartbeat(ARMED, 3 * S)
    seen += lc.on_landed_state(LANDED_TAKEOFF, 4 * S)
    assert names(seen) == ["armed"] and not lc.flown
    seen += lc.on_landed_state(LANDED_IN_AIR, 5 * S)
    seen += lc.on_landed_state(LANDED_IN_AIR, 6 * S)
    seen += lc.on_landed_state(LANDED_LANDING, 7 * S)
    seen += lc.on_landed_state(LANDED_IN_AIR, 8 * S)  # a go-around is still the same flight
    seen += lc.on_landed_state(LANDED_ON_GROUND, 9 * S)
    seen += lc.on_heartbeat(DISARMED, 10 * S)
    assert names(seen) == ["armed", "takeoff", "landed", "disarmed"]
    assert [e.monotonic_ns for e in seen] == [2 * S, 5 * S, 9 * S, 10 * S]
    assert lc.flown and not lc.flying and lc.armed is False


def test_first_heartbeat_armed_is_an_event_disarmed_is_not() -> None:
    assert names(FlightLifecycle().on_heartbeat(ARMED, 0)) == ["armed"]
    assert FlightLifecycle().on_heartbeat(DISARMED, 0) == []


def test_undefined_landed_state_does_not_land() -> None:
    lc = FlightLifecycle()
    lc.on_landed_state(LANDED_IN_AIR, 0)
    assert lc.on_landed_state(LANDED_UNDEFINED, S) == [] and lc.flying


def test_reboot_from_boot_time_going_back() -> None:
    lc = FlightLifecycle()
    lc.times.update(1_700_000_000_000_000, 50_000, 50 * S)
    assert lc.on_boot_ms(120_000, 60 * S) == []
    assert lc.on_boot_ms(119_500, 61 * S) == []  # a late packet, not a reboot
    ev = lc.on_boot_ms(800, 62 * S)
    assert names(ev) == ["reboot"] and ev[0].detail == {"previous_boot_ms": 120_000, "time_boot_ms": 800}
    assert lc.reboots == 1 and lc.times.boot_gpst is None  # the old boot clock mapping is gone
    assert lc.on_boot_ms(1800, 63 * S) == []


def test_system_time_maps_boot_time_to_gps_time() -> None:
    utc = dt.datetime(2026, 12, 2, 15, 0, 0, 250_000, tzinfo=dt.UTC)
    usec = (utc - dt.datetime(1970, 1, 1, tzinfo=dt.UTC)) // dt.timedelta(microseconds=1)
    m = BootTimeMap()
    assert m.update(0, 1000, 0) is None and m.boot_gpst is None  # no GPS time on the autopilot yet
    got = m.update(usec, 600_000, 7 * S)
    assert got == GpsTime.from_utc(utc)
    assert got.diff_s(GpsTime.from_utc(utc.replace(microsecond=0))) == 0.25
    # GPS time is 18 s ahead of UTC since 2017
    naive_gps = utc - dt.datetime(1980, 1, 6, tzinfo=dt.UTC)
    assert got.total_ns - (naive_gps // dt.timedelta(microseconds=1)) * 1000 == 18 * S
    assert m.gpst_at_boot_ms(600_000) == got
    assert m.gpst_at_boot_ms(0) == got.add_s(-600)
    assert m.gpst_at_monotonic(9 * S) == got.add_s(2)


def test_events_carry_gps_time_once_known() -> None:
    lc = FlightLifecycle()
    assert lc.on_heartbeat(ARMED, S)[0].gpst is None
    utc = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    lc.times.update(round((utc - dt.datetime(1970, 1, 1, tzinfo=dt.UTC)).total_seconds() * 1e6), 10, 2 * S)
    rec = lc.on_landed_state(LANDED_IN_AIR, 3 * S)[0].to_record()
    gpst = GpsTime.from_utc(utc).add_s(1)
    assert rec["event"] == "takeoff" and rec["type"] == "autopilot"
    assert (rec["gps_week"], rec["gps_tow_ns"]) == (gpst.week, gpst.tow_ns)


def test_sequence_loss() -> None:
    loss = SequenceLoss()
    for seq in [250, 251, 253, 254, 255, 0, 3]:  # 252, 1, 2 lost across the wrap
        loss.update(seq)
    assert (loss.received, loss.lost) == (7, 3)
    assert abs(loss.loss_ratio - 0.3) < 1e-12
    loss.update(100)  # a jump of 96: counted
    loss.update(10)  # a jump back (sender restarted): not 165 losses
    assert loss.lost == 3 + 96


def test_events_are_timed_on_the_autopilots_clock() -> None:
    """An event is timed from the autopilot's latest time_boot_ms plus the host time since that message, not
    from the SYSTEM_TIME's arrival: a slow SYSTEM_TIME (1 Hz) and host latency do not shift it."""
    lc = FlightLifecycle()
    utc = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)
    usec = (utc - dt.datetime(1970, 1, 1, tzinfo=dt.UTC)) // dt.timedelta(microseconds=1)
    lc.on_boot_ms(10_000, 100 * S)
    lc.times.update(usec, 10_000, 100 * S + 300_000_000)  # this SYSTEM_TIME waited 0.3 s on the host
    lc.on_boot_ms(12_000, 101 * S)  # an ATTITUDE: the autopilot's clock ran 2 s while the host's ran 1 s
    (ev,) = lc.on_heartbeat(ARMED, 101 * S + 100_000_000)
    assert ev.gpst == GpsTime.from_utc(utc).add_s(2.1)
