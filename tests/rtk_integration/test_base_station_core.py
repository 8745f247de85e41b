"""Base-station core: the radio budget's priorities, the message schedule, survey-in (pure parts)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from pyrtcm import RTCMReader

from onboard.base.station import BaseCore, BaseOptions, CorrectionScheduler, SurveyIn, spp_position
from onboard.formats.rinex_nav import read_rinex_nav
from onboard.formats.rinex_obs import read_rinex_obs
from onboard.gnsstime import GpsTime
from onboard.receiver.framing import iter_frames
from onboard.rtk.ephemeris import EphemerisStore
from tests.conftest import shared_file

GEONET = "gnss/geonet-0759-3040-20050402/"
BASE_3040 = (-3978241.958, 3382840.234, 3649900.853)


def _base_data():
    obs = read_rinex_obs(shared_file(GEONET + "30400920.05o.gz"))
    nav = read_rinex_nav(shared_file(GEONET + "30400920.05n.gz"))
    return [e.gps_only() for e in obs.epochs], nav


def test_scheduler_never_drops_observations_and_drops_ephemerides_before_position() -> None:
    sch = CorrectionScheduler(budget_bytes_s=200.0, burst_bytes=200)
    sent = sch.offer(0.0, [("ephemeris", b"e" * 67), ("obs", b"o" * 150), ("position", b"p" * 27)])
    # 200 B of credit: obs (150) first, then the position (27); the 67 B ephemeris does not fit
    assert [k for k, _ in sent] == ["obs", "position"] and sch.counts.deferred == {"ephemeris": 1}
    sent = sch.offer(0.1, [("obs", b"o" * 300), ("position", b"p" * 27)])  # obs over budget: sent anyway
    assert [k for k, _ in sent] == ["obs"] and sch.credit_bytes < 0
    sent = sch.offer(1.0, [("ephemeris", b"e" * 67)])  # the debt is paid back before anything optional
    assert sent == [] and sch.counts.deferred == {"ephemeris": 2, "position": 1}
    sent = sch.offer(3.0, [("ephemeris", b"e" * 67)])
    assert [k for k, _ in sent] == ["ephemeris"]


def test_core_sends_1004_every_epoch_1006_every_10_s_1019_every_30_s_within_budget() -> None:
    epochs, nav = _base_data()  # 30 s epochs; resample the schedule at 1 Hz by shifting the tags
    ep0 = epochs[0]
    core = BaseCore(BaseOptions(station_id=3040, position_ecef_m=BASE_3040, radio_budget_bytes_s=600.0,
                                obs_message="1004"))
    for e in nav.ephemerides:
        core.on_item(e)
    sent: list[tuple[float, list[int], int]] = []
    for k in range(120):
        ep = replace(ep0, time=ep0.time.add_s(k))
        frames = core.on_item(ep)
        nums = [int(RTCMReader.parse(f).identity) for _, f in frames]
        sent.append((float(k), nums, sum(len(f) for _, f in frames)))
    assert all(nums.count(1004) == 1 for _, nums, _ in sent)
    pos_times = [t for t, nums, _ in sent if 1006 in nums]
    assert pos_times == [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0, 110.0]
    n_sats = len(ep0)
    eph_times = [t for t, nums, _ in sent for n in nums if n == 1019]
    # every observed satellite's ephemeris, 4 rounds in 120 s (the burst lets the first round go at once)
    assert len(eph_times) == 4 * n_sats
    total = sum(b for _, _, b in sent)
    assert total <= 600.0 * 119 + 1024


def test_tight_budget_keeps_every_observation_and_position_sheds_ephemerides() -> None:
    epochs, nav = _base_data()
    ep0 = epochs[0]
    obs_size = len(BaseCore(BaseOptions(position_ecef_m=BASE_3040, obs_message="1004")).on_item(ep0)[0][1])
    # the observations plus 10 B/s: room for 1006 (27 B) every 10 s, not for 1019 (67 B) per satellite per 30 s
    core = BaseCore(BaseOptions(position_ecef_m=BASE_3040, radio_budget_bytes_s=obs_size + 10.0,
                                radio_burst_bytes=300, obs_message="1004"))
    for e in nav.ephemerides:
        core.on_item(e)
    count = {1004: 0, 1006: 0, 1019: 0}
    for k in range(300):
        for _, f in core.on_item(replace(ep0, time=ep0.time.add_s(k))):
            count[int(RTCMReader.parse(f).identity)] += 1
    assert count[1004] == 300
    assert count[1006] >= 25  # the position keeps its 10 s schedule out of the ~20-40 B/s left
    assert count[1019] < 5 * len(ep0) and core.scheduler.counts.deferred.get("ephemeris", 0) > 0


def test_corrections_decode_back_to_the_epoch_and_position() -> None:
    epochs, _nav = _base_data()
    core = BaseCore(BaseOptions(station_id=12, position_ecef_m=BASE_3040, obs_message="1002"))
    frames = core.on_item(epochs[3])
    msgs = [RTCMReader.parse(f) for _, f in frames]
    obs = next(m for m in msgs if m.identity == "1002")
    assert obs.DF003 == 12 and obs.DF004 == epochs[3].time.tow_ns // 1_000_000 and obs.DF006 == len(epochs[3])
    pos = next(m for m in msgs if m.identity == "1006")
    assert (pos.DF025, pos.DF026, pos.DF027) == pytest.approx(BASE_3040, abs=1e-4)
    assert [f.msg_id for f in iter_frames(b"".join(f for _, f in frames))] == [1002, 1006]


def test_survey_in_is_the_mean_of_spp_over_the_duration_and_gates_sending() -> None:
    epochs, nav = _base_data()
    store = EphemerisStore(nav.ephemerides)
    single = spp_position(epochs[0], store)
    assert single is not None and np.linalg.norm(single - BASE_3040) < 15.0
    core = BaseCore(BaseOptions(survey_in_s=300.0))
    for e in nav.ephemerides:
        core.on_item(e)
    sent_at = []
    for k, ep in enumerate(epochs[:20]):  # 30 s epochs: done after the 11th (300 s after the first)
        if core.on_item(ep):
            sent_at.append(k)
    assert sent_at[0] == 10 and sent_at == list(range(10, 20))
    assert core.position is not None
    assert np.linalg.norm(np.array(core.position.arp_ecef_m) - BASE_3040) < 10.0


def test_survey_in_without_ephemerides_sends_nothing_and_bad_options_are_refused() -> None:
    epochs, _ = _base_data()
    core = BaseCore(BaseOptions(survey_in_s=10.0))
    assert all(core.on_item(ep) == [] for ep in epochs[:5]) and core.position is None
    s = SurveyIn(0.0)
    t = GpsTime.from_week_tow_s(1316, 0.0)
    assert s.add(t, np.zeros(3)) is None  # one fix is no mean
    with pytest.raises(ValueError, match="survey-in"):
        BaseOptions()
    with pytest.raises(ValueError, match="msm4, msm5, msm7, 1004, 1002"):
        BaseOptions(position_ecef_m=BASE_3040, obs_message="1077")


def test_cli_registers_base_and_refuses_a_missing_or_bad_position(capsys) -> None:
    from onboard.__main__ import build_parser, main

    args = build_parser().parse_args(["base", "--port", "/dev/null", "--radio", "/dev/null",
                                      "--position=-3978241.958,3382840.234,3649900.853", "--budget", "300"])
    assert args.position == pytest.approx(BASE_3040) and args.budget == 300.0 and args.message is None
    # main() returns the usage error's exit code (2) instead of raising SystemExit
    assert main(["base", "--port", "/dev/null", "--radio", "/dev/null"]) == 2  # neither --position nor --survey-in
    assert main(["base", "--port", "x", "--radio", "y", "--position", "1,2"]) == 2
    assert main(["base", "--port", "x", "--radio", "y", "--survey-in", "0"]) == 2
    assert "survey-in" in capsys.readouterr().err


def _third_satellite_through_1004(lli_at, lock_ms_at):  # type: ignore[no-untyped-def]
    """40 one-second epochs of the GEONET base through BaseCore (1004) and back through RtcmDecoder, the third
    satellite's LLI (`lli_at(k)`) and every lock time (`lock_ms_at(k)`, NaN = none, as RXM-RAW) set per epoch k:
    (k, decoded epoch, row of that satellite) per decoded epoch, and its PRN."""
    from onboard.receiver.framing import StreamFramer
    from onboard.receiver.rtcm import RtcmDecoder

    epochs, _ = _base_data()
    ep0 = epochs[0]
    prn = int(ep0.sv_id[2])
    core = BaseCore(BaseOptions(position_ecef_m=BASE_3040, obs_message="1004"))
    dec = RtcmDecoder()
    decoded = []
    for k in range(40):
        lli = np.zeros(len(ep0), np.uint8)
        lli[2] = lli_at(k)
        ep = replace(ep0, time=ep0.time.add_s(k), lock_ms=np.full(len(ep0), lock_ms_at(k)), lli=lli)
        for f in StreamFramer().feed(b"".join(f for _, f in core.on_item(ep))):
            out = dec.decode(f, ep0.time)
            if out is not None and hasattr(out, "sv_id"):
                decoded.append((k, out, int(np.flatnonzero(out.sv_id == prn)[0])))
    return decoded


def test_a_slip_at_an_rxm_raw_base_reaches_the_rover_as_a_lock_time_reset() -> None:
    from onboard.rtk.types import LLI_SLIP

    # 1 Hz, no lock times (as RXM-RAW); the receiver flags a slip on the satellite at k = 25
    decoded = _third_satellite_through_1004(lambda k: LLI_SLIP if k == 25 else 0, lambda k: np.nan)
    slips = [k for k, out, j in decoded if out.lli[j] & LLI_SLIP]
    assert slips == [25]
    assert all(np.all(out.lli[np.arange(len(out)) != j] & LLI_SLIP == 0) for _, out, j in decoded)


@pytest.mark.parametrize("receiver_lock", [False, True], ids=["rxm-raw", "rxm-rawx"])
def test_an_unresolved_half_cycle_at_the_base_is_withheld_and_its_resolution_starts_a_new_arc(
        receiver_lock: bool) -> None:
    """1004 cannot flag a half cycle: phase flagged unresolved (LLI bit 1) is not sent, and when the flag clears
    (the receiver may move the phase half a cycle then) the lock time restarts, so the rover sees a new arc.
    hil_sim seed 10 (undetected slips): sent as it was, a base half-cycle arc ended in 10 wrong rover fixes."""
    from onboard.rtk.types import LLI_HALF_CYCLE, LLI_SLIP

    # the receiver flags an unresolved half cycle on the satellite at k = 10-19, resolved at 20
    decoded = _third_satellite_through_1004(lambda k: LLI_HALF_CYCLE if 10 <= k < 20 else 0,
                                            lambda k: 600_000.0 + 1000.0 * k if receiver_lock else np.nan)
    assert [bool(np.isfinite(out.cp_cyc[j])) for _, out, j in decoded] == [not 10 <= k < 20 for k in range(40)]
    assert [k for k, out, j in decoded if out.lli[j] & LLI_SLIP] == [20]
    for _, out, j in decoded:
        others = np.arange(len(out)) != j
        assert np.all(np.isfinite(out.cp_cyc[others])) and np.all(out.lli[others] & LLI_SLIP == 0)


def test_radio_sender_drops_when_the_radio_is_stuck_and_logs_only_what_it_queued(tmp_path) -> None:
    import threading

    from onboard.base.station import RadioSender
    from onboard.errors import LinkLost
    from tests.daemon.helpers import wait_until

    gate = threading.Event()

    class StuckRadio:
        def __init__(self) -> None:
            self.written = bytearray()

        def read(self, max_bytes: int) -> bytes:
            return b""

        def write(self, data: bytes) -> int:
            gate.wait(5)  # a radio whose buffer is full: writes block
            self.written += data
            return len(data)

        def close(self) -> None:
            pass

    radio = StuckRadio()
    opens = {"n": 0}

    def open_radio() -> StuckRadio:
        opens["n"] += 1
        if opens["n"] == 1:
            raise LinkLost("not plugged yet")
        return radio

    sender = RadioSender(open_radio, tmp_path / "tx.rtcm3", max_queue=4, reopen_s=0.01)
    sender.start()
    results = [sender.send(bytes([k]) * 10) for k in range(20)]  # never blocks the caller
    wait_until(lambda: sender.radio_open, 5, "radio open")
    gate.set()
    sender.stop()
    assert results.count(False) == sender.frames_dropped > 0
    logged = (tmp_path / "tx.rtcm3").read_bytes()
    assert len(logged) == 10 * results.count(True) and bytes(radio.written) == logged


def test_a_5_hz_base_is_decimated_to_1_hz_and_an_impossible_budget_is_flagged(caplog) -> None:
    epochs, _nav = _base_data()
    ep0 = epochs[0]
    core = BaseCore(BaseOptions(position_ecef_m=BASE_3040, radio_budget_bytes_s=300.0))
    sent = [core.on_item(replace(ep0, time=ep0.time.add_s(k * 0.2))) for k in range(50)]  # 10 s at 5 Hz
    obs_at = [k for k, frames in enumerate(sent) if any(kind == "obs" for kind, _ in frames)]
    assert obs_at == list(range(0, 50, 5)) and not core.over_budget
    assert sum(1 for frames in sent for kind, _ in frames if kind == "position") == 1
    tight = BaseCore(BaseOptions(position_ecef_m=BASE_3040, radio_budget_bytes_s=50.0, obs_interval_s=0.0))
    for k in range(5):
        tight.on_item(replace(ep0, time=ep0.time.add_s(k)))
    assert tight.over_budget and "over the radio budget" in caplog.text
