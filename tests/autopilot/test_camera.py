"""The camera cross-check (pure core): autopilot shots vs TIM-TM2 flash marks, attitude at each exposure."""

from __future__ import annotations

import datetime as dt

import pytest

from onboard.autopilot.camera import (
    CAMERA_CHECK_KIND,
    FLASH_WITHOUT_SHOT,
    MATCHED,
    SHOT_WITHOUT_FLASH,
    Attitude,
    CameraCrossCheck,
    CameraShot,
    camera_time_gpst,
)
from onboard.autopilot.lifecycle import BootTimeMap
from onboard.gnsstime import GpsTime

T0 = GpsTime.from_week_tow_s(2300, 345600.0)


def _t(s: float) -> GpsTime:
    return T0.add_ns(round(s * 1e9))


def test_pairs_within_tolerance_and_names_each_orphan() -> None:
    """Shots every 2.5 s, flashes 80 ms later; shot 2 lost its flash, one flash has no shot (a test shot)."""
    cc = CameraCrossCheck()
    for k in range(5):
        cc.add_shot(CameraShot("CAMERA_FEEDBACK", k + 1, _t(10 + 2.5 * k)))
        if k != 2:
            cc.add_flash(_t(10 + 2.5 * k + 0.080), 100 + k)
    cc.add_flash(_t(3.0), 99)  # on the ground, before the mission: no autopilot trigger
    for s in range(40):
        cc.add_attitude(Attitude(_t(s * 0.25 + 2.0), 1.0, -2.0, 359.0 + s * 0.1))
    recs = cc.poll(_t(30.0))
    assert [r["result"] for r in recs] == [FLASH_WITHOUT_SHOT, MATCHED, MATCHED, SHOT_WITHOUT_FLASH, MATCHED,
                                           MATCHED]
    assert all(r["kind"] == CAMERA_CHECK_KIND and r["v"] == 1 for r in recs)
    m = recs[1]
    assert m["delay_ns"] == 80_000_000 and m["shot_index"] == 1 and m["flash_count"] == 100
    assert (m["exposure_week"], m["exposure_tow_ns"]) == (m["flash_week"], m["flash_tow_ns"])
    # attitude interpolated at the flash (10.08 s): yaw 359 + (10.08-2)/0.25·0.1 = 362.232 → 2.232, across 360
    assert m["roll_deg"] == pytest.approx(1.0) and m["yaw_deg"] == pytest.approx(2.232, abs=1e-3)
    assert recs[3]["flash_week"] is None and recs[3]["exposure_tow_ns"] == recs[3]["shot_tow_ns"]
    c = cc.counts
    assert (c.shots, c.flashes, c.matched, c.shots_without_flash, c.flashes_without_shot) == (5, 5, 4, 1, 1)
    assert c.last_delay_ms == 80.0


def test_outside_tolerance_is_two_orphans_and_undecided_waits() -> None:
    cc = CameraCrossCheck()
    cc.add_shot(CameraShot("CAMERA_TRIGGER", 7, _t(10.0)))
    cc.add_flash(_t(10.6))  # 0.6 s > 0.5 s tolerance
    assert cc.poll(_t(11.0)) == []  # the partner could still come: nothing decided
    recs = cc.poll(_t(13.0))
    assert [r["result"] for r in recs] == [SHOT_WITHOUT_FLASH, FLASH_WITHOUT_SHOT]
    assert recs[0]["roll_deg"] is None  # no ATTITUDE around: no attitude claimed


def test_nearest_shot_takes_the_flash() -> None:
    cc = CameraCrossCheck()
    cc.add_shot(CameraShot("CAMERA_FEEDBACK", 1, _t(10.0)))
    cc.add_shot(CameraShot("CAMERA_FEEDBACK", 2, _t(10.9)))  # a burst: 0.9 s apart
    cc.add_flash(_t(10.95))
    recs = cc.poll(final=True)
    assert [(r["result"], r["shot_index"]) for r in recs] == [(SHOT_WITHOUT_FLASH, 1), (MATCHED, 2)]


def test_camera_time_boot_and_unix() -> None:
    times = BootTimeMap()
    assert camera_time_gpst(5_000_000, times.gpst_at_boot_ms) is None  # before SYSTEM_TIME
    utc = dt.datetime(2024, 3, 1, 12, 0, 0, tzinfo=dt.UTC)
    usec = int((utc - dt.datetime(1970, 1, 1, tzinfo=dt.UTC)).total_seconds() * 1e6)
    times.update(usec, 60_000, 0)  # SYSTEM_TIME: 60 s after boot it was `utc`
    got = camera_time_gpst(61_500_250, times.gpst_at_boot_ms)
    assert got == GpsTime.from_utc(utc).add_ns(1_500_250_000)
    assert camera_time_gpst(usec + 2_000_000, times.gpst_at_boot_ms) == GpsTime.from_utc(utc).add_ns(2 * 10**9)
