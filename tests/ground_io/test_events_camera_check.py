"""The ground importer reads the onboard camera cross-check: typed records, and the autopilot's attitude on
each mark as a prior (the exporters are unchanged)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ground.io.errors import FormatError
from ground.io.events import AutopilotAttitude, camera_checks_from_records, read_marks_jsonl
from onboard.autopilot.camera import Attitude, CameraCrossCheck, CameraShot
from onboard.gnsstime import GpsTime
from onboard.rtk.types import CameraMark
from onboard.timepulse.marks import PairingOptions, mark_record, pair_marks, pairing_record

T0 = GpsTime.from_week_tow_s(2300, 345600.0)


def _t(s: float) -> GpsTime:
    return T0.add_ns(round(s * 1e9))


def _flight_log(tmp_path: Path) -> Path:
    """events.jsonl as the recorder writes it: flash marks, their pairings, and the link's camera_check records
    (3 autopilot shots; the second lost its flash; one extra flash before the mission)."""
    flashes = [CameraMark(0, "falling", 10 + k, t, 20, 1, True) for k, t in enumerate([_t(3.0), _t(10.07),
                                                                                         _t(15.09)])]
    cc = CameraCrossCheck()
    for s in range(80):
        cc.add_attitude(Attitude(_t(s * 0.25), 2.0, -1.0 + 0.01 * s, 90.0 + 0.5 * s))
    for k, s in enumerate((10.0, 12.5, 15.0)):
        cc.add_shot(CameraShot("CAMERA_FEEDBACK", k + 1, _t(s)))
    for f in flashes:
        assert f.time is not None
        cc.add_flash(f.time, f.count)
    records = [mark_record(f) for f in flashes]
    records += [pairing_record(p) for p in pair_marks(flashes, PairingOptions(trigger_measured=False))]
    records += cc.poll(final=True)
    path = tmp_path / "events.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    return path


def test_marks_carry_the_autopilot_attitude(tmp_path: Path) -> None:
    marks = read_marks_jsonl(_flight_log(tmp_path))
    assert len(marks) == 3
    # a flash without an autopilot shot still has the autopilot's attitude at its time (ATTITUDE at 3 s)
    assert marks[0].autopilot_attitude == AutopilotAttitude(2.0, -0.88, 96.0)
    att = marks[1].autopilot_attitude
    assert isinstance(att, AutopilotAttitude)
    # ATTITUDE at 10.07 s: pitch -1 + 0.01·40.28, yaw 90 + 0.5·40.28
    assert att.roll_deg == pytest.approx(2.0) and att.pitch_deg == pytest.approx(-0.5972, abs=1e-4)
    assert att.yaw_deg == pytest.approx(110.14, abs=1e-4)


def test_camera_check_records_are_typed(tmp_path: Path) -> None:
    from onboard.logger.events import read_events

    checks = camera_checks_from_records(read_events(_flight_log(tmp_path)).records)
    assert [c.result for c in checks] == ["flash_without_shot", "matched", "shot_without_flash", "matched"]
    matched = checks[1]
    assert matched.shot_index == 1 and matched.delay_s == pytest.approx(0.07) and matched.flash_count == 11
    assert matched.shot_time == _t(10.0) and matched.exposure_time == _t(10.07)
    assert checks[2].flash_time is None and checks[2].exposure_time == _t(12.5)


def test_a_malformed_camera_check_is_a_format_error(tmp_path: Path) -> None:
    path = _flight_log(tmp_path)
    lines = path.read_text().splitlines()
    bad = json.loads(lines[-1])
    bad["roll_deg"] = "level"
    path.write_text("\n".join([*lines[:-1], json.dumps(bad)]) + "\n")
    with pytest.raises(FormatError, match="roll_deg must be int or float, got 'level'"):
        read_marks_jsonl(path)
