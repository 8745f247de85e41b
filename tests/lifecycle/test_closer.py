"""The flight-over rule (pure): disarmed, on the ground and the link up for the settle time, after a flight."""

from __future__ import annotations

from onboard.autopilot.lifecycle import LANDED_IN_AIR, LANDED_ON_GROUND, LANDED_UNDEFINED, FlightCloser

S = 1_000_000_000
SETTLE = 20 * S


def fly(c: FlightCloser, t0: int = 0) -> int:
    """Arm on the ground, fly, land, disarm; returns the time of the disarm."""
    assert not c.update(False, LANDED_ON_GROUND, True, t0)
    assert not c.update(True, LANDED_ON_GROUND, True, t0 + 1 * S)
    assert not c.update(True, LANDED_IN_AIR, True, t0 + 5 * S)
    assert not c.update(True, LANDED_ON_GROUND, True, t0 + 60 * S)
    assert not c.update(False, LANDED_ON_GROUND, True, t0 + 63 * S)
    return t0 + 63 * S


def test_closes_after_the_settle_time_once() -> None:
    c = FlightCloser(SETTLE)
    t = fly(c)
    assert not c.update(False, LANDED_ON_GROUND, True, t + SETTLE - 1)
    assert c.update(False, LANDED_ON_GROUND, True, t + SETTLE)
    c.closed()
    assert not c.update(False, LANDED_ON_GROUND, True, t + 10 * SETTLE)  # the next flight is not flown yet


def test_rearming_during_the_settle_time_cancels() -> None:
    c = FlightCloser(SETTLE)
    t = fly(c)
    assert not c.update(True, LANDED_ON_GROUND, True, t + SETTLE // 2)  # re-armed
    assert not c.update(False, LANDED_ON_GROUND, True, t + SETTLE // 2 + S)
    assert not c.update(False, LANDED_ON_GROUND, True, t + SETTLE + S)  # counted from the second disarm
    assert c.update(False, LANDED_ON_GROUND, True, t + SETTLE // 2 + S + SETTLE)


def test_a_silent_link_restarts_the_wait() -> None:
    c = FlightCloser(SETTLE)
    t = fly(c)
    assert not c.update(False, LANDED_ON_GROUND, False, t + SETTLE)  # link down: nothing known
    assert not c.update(False, LANDED_ON_GROUND, True, t + SETTLE + S)
    assert not c.update(False, LANDED_ON_GROUND, True, t + 2 * SETTLE)
    assert c.update(False, LANDED_ON_GROUND, True, t + 2 * SETTLE + S)


def test_arming_on_the_ground_is_no_flight() -> None:
    c = FlightCloser(SETTLE)
    c.update(True, LANDED_ON_GROUND, True, 0)
    c.update(False, LANDED_ON_GROUND, True, S)
    assert not c.update(False, LANDED_ON_GROUND, True, 100 * SETTLE)


def test_without_landed_state_an_arm_counts() -> None:
    c = FlightCloser(SETTLE)
    c.update(True, LANDED_UNDEFINED, True, 0)
    c.update(False, LANDED_UNDEFINED, True, S)
    assert c.update(False, LANDED_UNDEFINED, True, S + SETTLE)


def test_a_resumed_flight_counts_as_flown() -> None:
    c = FlightCloser(SETTLE, resumed=True)
    assert not c.update(False, LANDED_ON_GROUND, True, 0)
    assert c.update(False, LANDED_ON_GROUND, True, SETTLE)
    unknown = FlightCloser(SETTLE, resumed=True)
    assert not unknown.update(None, LANDED_ON_GROUND, True, 0)  # no heartbeat yet: armed unknown
    assert not unknown.update(None, LANDED_ON_GROUND, True, 2 * SETTLE)
