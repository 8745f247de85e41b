"""`python -m hil_sim autopilot` flags reach the stand-in's options (faults included)."""

from __future__ import annotations

from pathlib import Path

from hil_sim.__main__ import build_parser
from hil_sim.autopilot import options_from_args
from tests.autopilot.rtcm_frames import rtcm_frame


def test_fault_flags(tmp_path: Path) -> None:
    rtcm = tmp_path / "x.rtcm3"
    msgs = [rtcm_frame(100, 1), rtcm_frame(360, 2)]
    rtcm.write_bytes(b"junk" + msgs[0] + msgs[1])
    args = build_parser().parse_args([
        "autopilot", "--mavlink1", "--reboot-at", "30", "--reboot-at", "60", "--heartbeat-stop", "10:5",
        "--link-loss", "20:3", "--drop-fragment-rate", "0.2", "--reorder-fragments", "--rtcm", str(rtcm),
        "--rtcm-start", "4", "--system-id", "7", "--arm-at", "12", "--survey", "40", "--no-gcs-heartbeat"])
    o = options_from_args(args)
    assert o.mavlink1 and o.reboot_at_s == (30.0, 60.0) and o.heartbeat_stop == ((10.0, 5.0),)
    assert o.link_loss == ((20.0, 3.0),) and o.drop_fragment_rate == 0.2 and o.reorder_fragments
    assert o.rtcm_messages == tuple(msgs) and o.rtcm_start_s == 4.0  # the junk before the first frame is skipped
    assert (o.system_id, o.arm_at_s, o.survey_s, o.gcs_heartbeat) == (7, 12.0, 40.0, False)
