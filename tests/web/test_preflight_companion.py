"""The flight companion's pre-flight lines: autopilot link, base corrections, camera cross-check, upload queue,
disk minutes, and the go/no-go line naming the first fault (pure checks, then the API on odd files)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from onboard.recorder.status import RTK_STATUS_NAME, write_status
from onboard.web.app import create_app
from onboard.web.checks import FAIL, OK, WARN, blocks, describe_base_stream, headline, preflight_checks
from tests.web.test_preflight import _healthy, _rtk_fixed


def autopilot_ok() -> dict[str, Any]:
    """autopilot.json of a healthy link on the ground (keys of onboard.autopilot.feature.LinkStatus)."""
    return {
        "link": "serial:/dev/ttyAMA1@921600", "link_open": True, "link_error": None, "link_up": True,
        "heartbeat_age_s": 0.4, "autopilot": {"system_id": 1, "component_id": 1, "type": 2, "autopilot": 3},
        "mavlink_version": 2, "armed": False, "mode": "LOITER", "custom_mode": 5, "system_status": 3,
        "landed_state": "on_ground", "flown": False, "packets": 900, "packets_lost": 0, "packet_loss": 0.0,
        "bad_bytes": 0, "battery": {"voltage_v": 16.4, "current_a": 0.8, "remaining_pct": 97},
        "prearm_ok": True, "gps": {"fix_type": 6, "satellites": 17, "hdop": 0.7, "h_acc_m": 0.02, "v_acc_m": 0.03},
        "attitude": {"roll_deg": 0.1, "pitch_deg": -0.2, "yaw_deg": 91.0}, "position": None, "time_synced": True,
        "camera_feedback": 0, "last_camera_feedback": None,
        "camera_check": {"shots": 0, "flashes": 1, "matched": 0, "shots_without_flash": 0,
                         "flashes_without_shot": 1, "untimed_shots": 0, "last_delay_ms": None, "tolerance_ms": 500.0},
        "rtcm": {"fragments": 0, "messages": 0, "dropped": 0, "bytes": 0}, "tlog_bytes": 120_000,
    }


UPLOAD_OK = {"queued": 2, "uploading": None, "done": 5, "last_result": "flight-0005 uploaded", "last_error": None,
             "last_success_wall_ns": 1_700_000_000 * 10**9, "bytes_sent": 42_000_000}


def _checks(ap: dict[str, Any] | None = None, upload: dict[str, Any] | None = None, rtk: Any = None,
            **status: Any) -> dict[str, tuple[str, str]]:
    now = time.time_ns()
    snap = _healthy(now).to_json()
    snap.update(status)
    return {c.name: (c.level, c.detail) for c in preflight_checks(snap, now, None, rtk, ap, upload, None)}


def test_a_healthy_companion_is_go() -> None:
    now = time.time_ns()
    checks = preflight_checks(_healthy(now).to_json(), now, None, _rtk_fixed().to_json(), autopilot_ok(), UPLOAD_OK,
                              "mavlink")
    line = headline(checks)
    assert line == {"level": OK, "verdict": "READY TO FLY", "fault": ""}, checks
    got = {c.name: c.detail for c in checks}
    assert "heartbeat 0.4 s ago, 0.0 % packets lost; disarmed, LOITER, on ground" == got["autopilot link"]
    assert got["autopilot GPS"] == "RTK fixed, 17 satellites, ±0.02 m horizontal"
    assert got["base corrections"] == "MAVLink GPS_RTCM_DATA (ground station inject), 0.8 s old"
    assert got["upload"] == "2 flights waiting, 5 uploaded, 42.0 MB sent; last: flight-0005 uploaded"
    assert got["battery"] == "16.40 V, 97 %"


def test_autopilot_faults_are_named_no_gos() -> None:
    lost = {**autopilot_ok(), "link_up": False, "heartbeat_age_s": 7.3}
    assert _checks(lost)["autopilot link"] == (
        FAIL, "autopilot link lost: last heartbeat 7 s ago on serial:/dev/ttyAMA1@921600")
    closed = {**autopilot_ok(), "link_open": False, "link_error": "device disappeared", "heartbeat_age_s": None}
    assert _checks(closed)["autopilot link"] == (FAIL, "serial:/dev/ttyAMA1@921600 closed: device disappeared")
    silent = {**autopilot_ok(), "heartbeat_age_s": None, "link_up": False}
    assert _checks(silent)["autopilot link"][0] == FAIL
    assert _checks({**autopilot_ok(), "prearm_ok": False})["autopilot pre-arm"][0] == FAIL
    assert _checks({**autopilot_ok(), "packet_loss": 0.12})["autopilot link"][0] == WARN
    assert _checks({**autopilot_ok(), "battery": {"voltage_v": 14.1, "remaining_pct": 12}})["battery"][0] == WARN
    assert _checks({**autopilot_ok(), "gps": {"fix_type": 1, "satellites": 3}})["autopilot GPS"] == (
        WARN, "no fix, 3 satellites")
    # no autopilot.json: no autopilot line at all (no link configured)
    assert not any(k.startswith("autopilot") for k in _checks(None))


def test_wrong_kind_values_are_named_no_gos() -> None:
    """check_snapshot-style: a value of the wrong kind in autopilot.json or upload.json names file and key."""
    level, detail = _checks({**autopilot_ok(), "heartbeat_age_s": "soon"})["autopilot link"]
    assert level == FAIL and "autopilot.json: heartbeat_age_s must be a number, got 'soon'" in detail
    level, detail = _checks({**autopilot_ok(), "gps": {"fix_type": 6.5}})["autopilot GPS"]
    assert level == FAIL and "gps.fix_type must be a whole number, got 6.5" in detail
    level, detail = _checks({**autopilot_ok(), "battery": "full"})["battery"]
    assert level == FAIL and "battery.voltage_v is inside 'full'" in detail
    level, detail = _checks(upload={**UPLOAD_OK, "queued": "two"})["upload"]
    assert level == FAIL and "upload.json: queued must be a whole number or a list, got 'two'" in detail
    level, detail = _checks(upload={**UPLOAD_OK, "bytes_sent": True})["upload"]
    assert level == FAIL and "bytes_sent must be a whole number, got True" in detail
    rows = dict(blocks(None, None, {**autopilot_ok(), "armed": "yes"}, None, None)["autopilot"])
    assert rows["armed"] == "unreadable: must be true or false, got 'yes'" and rows["mode"] == "LOITER"


def test_upload_queue() -> None:
    assert _checks()["upload"] == (OK, "no automatic upload configured")
    failing = {**UPLOAD_OK, "queued": ["flight-0006", "flight-0007"], "uploading": "flight-0006",
               "last_error": "connection refused"}
    assert _checks(upload=failing)["upload"] == (
        WARN, ("2 flights waiting, uploading flight-0006, 5 uploaded, 42.0 MB sent; last attempt failed: "
               "connection refused"))


def test_camera_cross_check_line() -> None:
    assert _checks(autopilot_ok())["camera cross-check"] == (OK, "no autopilot camera trigger yet (1 flash marks)")
    agree = {**autopilot_ok(), "camera_check": {"shots": 12, "flashes": 12, "matched": 12, "shots_without_flash": 0,
                                                 "flashes_without_shot": 0, "last_delay_ms": 84.2}}
    assert _checks(agree)["camera cross-check"] == (
        OK, "12 triggers and flash marks agree, last trigger → flash delay 84 ms")
    off = {**agree, "camera_check": {**agree["camera_check"], "matched": 10, "shots_without_flash": 2}}
    level, detail = _checks(off)["camera cross-check"]
    assert level == WARN and detail.startswith("2 autopilot images without a flash mark, 0 flash marks")


def test_disk_minutes_left() -> None:
    now = time.time_ns()
    # 100 s recorded at 20 kB/s (receiver) + tlog: 2 MB + 120 kB; 1 GB usable above the floor
    base = {"started_wall_ns": now - 100 * 10**9, "bytes_recorded": 2_000_000, "disk_free_bytes": 1_200_000_000,
            "disk_floor_bytes": 200_000_000}
    level, detail = _checks(autopilot_ok(), **base)["disk"]
    assert level == OK and "≈ 786 min of recording left" in detail  # 1e9 / (2.12e6 / 100) / 60
    level, detail = _checks(autopilot_ok(), **{**base, "bytes_recorded": 2_000_000_000 // 10})["disk"]
    assert level == FAIL and "≈ 8 min" in detail
    assert "not measured yet" in _checks(**{**base, "started_wall_ns": now - 2 * 10**9})["disk"][1]


def test_base_source_never_shows_credentials() -> None:
    assert describe_base_stream("ntrip://surveyor:s3cret@caster.example:2101/MOUNT1", None) == \
        "NTRIP caster.example:2101/MOUNT1"
    assert describe_base_stream("serial:/dev/ttyUSB0@57600", None) == "radio /dev/ttyUSB0@57600"
    assert describe_base_stream("tcp://10.0.0.2:5000", None) == "TCP 10.0.0.2:5000"
    assert describe_base_stream(None, {"rtcm": {"messages": 3}}) == "MAVLink GPS_RTCM_DATA"
    stopped = {**_rtk_fixed().to_json(), "age_s": 41.0, "q": 2}
    level, detail = _checks(rtk=stopped)["base corrections"]
    assert level == FAIL and "base corrections stopped 41 s ago (source the base stream; no-go after 10 s)" == detail


def test_headline_names_the_first_blocking_fault() -> None:
    now = time.time_ns()
    lost = {**autopilot_ok(), "link_up": False, "heartbeat_age_s": 9.0}
    checks = preflight_checks(_healthy(now).to_json(), now, None, {**_rtk_fixed().to_json(), "age_s": 50.0}, lost)
    line = headline(checks)
    assert line["level"] == FAIL and line["verdict"] == "DO NOT FLY"
    assert line["fault"].startswith("autopilot link: autopilot link lost: last heartbeat 9 s ago")
    checks = preflight_checks(_healthy(now).to_json(), now, None, {**_rtk_fixed().to_json(), "age_s": 50.0},
                              autopilot_ok())
    assert headline(checks)["fault"].startswith("base corrections: base corrections stopped")


def test_api_on_torn_and_foreign_companion_files(tmp_path: Path) -> None:
    status_path = tmp_path / "status.json"
    write_status(status_path, _healthy(time.time_ns()))
    client = TestClient(create_app(status_path, base_stream="ntrip://u:pw@caster:2101/M"))
    body = client.get("/api/preflight").json()
    # rtk.base_stream is set but rtk.json is not written yet: a no-go naming the (credential-free) source
    assert body["headline"]["fault"] == ("base corrections: real-time RTK configured (NTRIP caster:2101/M) but not "
                                         "reporting: no rtk.json")
    assert body["blocks"]["upload"] == [["upload", "no automatic upload configured"]]
    status_path.with_name("autopilot.json").write_text('{"link_up": tr')
    status_path.with_name("upload.json").write_text("[1]")
    write_status(status_path.with_name(RTK_STATUS_NAME), _rtk_fixed().to_json())
    r = client.get("/api/preflight")
    assert r.status_code == 200
    body = r.json()
    levels = {c["name"]: (c["level"], c["detail"]) for c in body["checks"]}
    assert levels["autopilot link"][0] == FAIL and "autopilot.json" in levels["autopilot link"][1]
    assert levels["upload"] == (FAIL, "upload status unreadable: upload.json is not a JSON object of ours")
    assert dict(body["blocks"]["base corrections"])["source"] == "NTRIP caster:2101/M"
    assert "pw" not in json.dumps(body["blocks"]) and "pw" not in json.dumps(body["checks"])


def test_stopped_base_corrections_are_a_no_go_with_rtk_configured() -> None:
    """Real-time RTK configured (rtk.json present, or `rtk.base_stream` known): no base, a closed source or
    corrections older than the timeout are a no-go naming them; the recorder's timeout (rtk.json) wins over the
    page's default; at the timeout itself still go. Without real-time RTK there is no base line at all."""
    now = time.time_ns()
    snap = _healthy(now).to_json()

    def base(rtk: dict[str, Any] | None, stream: str | None = "mavlink") -> tuple[str, str] | None:
        checks = preflight_checks(snap, now, None, rtk, autopilot_ok(), None, stream)
        line = headline(checks)
        got = {c.name: (c.level, c.detail) for c in checks}.get("base corrections")
        if got is not None and got[0] == FAIL:
            assert line["level"] == FAIL and line["fault"] == f"base corrections: {got[1]}"
        return got

    fixed = _rtk_fixed().to_json()
    assert base({**fixed, "age_s": 10.0}) == (OK, "MAVLink GPS_RTCM_DATA (ground station inject), 10.0 s old")
    assert base({**fixed, "age_s": 10.5}) == (
        FAIL, "base corrections stopped 10 s ago (source MAVLink GPS_RTCM_DATA (ground station inject); no-go after 10 s)")
    assert base({**fixed, "age_s": 25.0, "preflight_base_timeout_s": 30.0})[0] == OK  # type: ignore[index]
    assert base({**fixed, "age_s": 4.0, "preflight_base_timeout_s": 3.0})[0] == FAIL  # type: ignore[index]
    assert base({**fixed, "base_epochs": 0, "age_s": None}) == (
        FAIL, "none yet from MAVLink GPS_RTCM_DATA (ground station inject): is the base station on?")
    assert base({**fixed, "radio_open": False, "radio_error": "gone"}) == (
        FAIL, "MAVLink GPS_RTCM_DATA (ground station inject) closed: gone")
    assert base(None) == (FAIL, ("real-time RTK configured (MAVLink GPS_RTCM_DATA (ground station inject)) but not "
                                 "reporting: no rtk.json"))
    assert base(None, stream=None) is None and base(None, stream="") is None
