"""Base station, MSM modes: one MSM per constellation per epoch (multiple-message bit on all but the last), the
rover's EpochAssembler rebuilding the epoch, the observations back within the MSM resolution (synthetic epochs,
and the real RXM-RAWX of u-blox logs), the per-second budget (observations first, never exceeded by the
others, deferrals counted, MSM7 → MSM4 when the observations do not fit) and the ephemeris rotation."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from pyrtcm import RTCMReader

from onboard.base.cli import OBS_MESSAGES as CLI_OBS_MESSAGES
from onboard.base.schedule import EphemerisRotation, SecondBudget
from onboard.base.station import OBS_MESSAGES, BaseCore, BaseOptions
from onboard.gnsstime import GpsTime
from onboard.receiver.base_epochs import collect_rtcm
from onboard.receiver.decode import decode_rxm_rawx, iter_file_bytes
from onboard.receiver.framing import Protocol, StreamFramer, iter_frames
from onboard.rtk.consts import CLIGHT_M_S, l1_wavelength_m
from onboard.rtk.types import (
    FCN_NONE,
    GNSS_BEIDOU,
    GNSS_GALILEO,
    GNSS_GLONASS,
    GNSS_GPS,
    GNSS_QZSS,
    Ephemeris,
    ObsEpoch,
)
from tests.conftest import shared_file

T0 = GpsTime.from_week_tow_s(2300, 345_600.0)
POS = (3774089.2120, -601661.6157, 5089321.2474)
SYSTEMS = {GNSS_GPS: ("1C", 8), GNSS_GLONASS: ("1C", 7), GNSS_GALILEO: ("1X", 6), GNSS_QZSS: ("1C", 2),
           GNSS_BEIDOU: ("2I", 6)}
"""gnssId → (signal, satellites) of the synthetic epoch."""


def synthetic_epoch(t: GpsTime, systems: dict[int, tuple[str, int]] = SYSTEMS, seed: int = 0) -> ObsEpoch:
    """One L1 epoch of `systems` (pseudorange 20–26 Mm, phase = range in cycles + a few cycles, Doppler, C/N0,
    lock times growing with `t`; GLONASS channels −3…+3)."""
    rng = np.random.default_rng(seed)
    rows = []
    for g, (sig, n) in systems.items():
        for k in range(n):
            sv = k + 1
            fcn = k - 3 if g == GNSS_GLONASS else FCN_NONE
            lam = l1_wavelength_m(g, fcn if g == GNSS_GLONASS else None)
            pr = 20e6 + 6e6 * rng.random() + 100.0 * t.diff_s(T0)
            rows.append((g, sv, pr, pr / lam + rng.integers(-20, 20), -500.0 + 100 * k, 30.0 + 2 * k,
                         1000.0 * (t.diff_s(T0) + 100), fcn, sig))
    cols = list(zip(*rows))
    n = len(rows)
    return ObsEpoch(time=t, gnss_id=np.array(cols[0], np.int8), sv_id=np.array(cols[1], np.int16),
                    pr_m=np.array(cols[2]), cp_cyc=np.array(cols[3]), dop_hz=np.array(cols[4]),
                    cn0_dbhz=np.array(cols[5]), lock_ms=np.array(cols[6]), lli=np.zeros(n, np.uint8),
                    glo_fcn=np.array(cols[7], np.int8), signal=np.array(cols[8], "<U2"))


def _numbers(frames: list[tuple[str, bytes]]) -> list[int]:
    return [(f[3] << 4) | (f[4] >> 4) for _, f in frames]


def _df393(frame: bytes) -> int:
    return int(RTCMReader.parse(frame).DF393)


def test_cli_and_station_offer_the_same_observation_messages() -> None:
    assert CLI_OBS_MESSAGES == OBS_MESSAGES
    assert BaseOptions(position_ecef_m=POS).msm_kind == 4 and BaseOptions(position_ecef_m=POS,
                                                                          obs_message="1004").msm_kind is None


@pytest.mark.parametrize("kind", [4, 5, 7])
def test_one_msm_per_constellation_multiple_message_bit_and_reassembly(kind: int) -> None:
    core = BaseCore(BaseOptions(station_id=33, obs_message=f"msm{kind}", position_ecef_m=POS,
                                radio_budget_bytes_s=5000.0))
    stream = b""
    epochs = [synthetic_epoch(T0.add_s(k), seed=k) for k in range(5)]
    for ep in epochs:
        frames = core.on_item(ep)
        obs = [f for kind_, f in frames if kind_ == "obs"]
        nums = [(f[3] << 4) | (f[4] >> 4) for f in obs]
        assert nums == [1070 + kind, 1080 + kind, 1090 + kind, 1110 + kind, 1120 + kind]
        assert [_df393(f) for f in obs] == [1, 1, 1, 1, 0]
        stream += b"".join(f for _, f in frames)
    col = collect_rtcm([stream], T0, glo_fcn={k + 1: k - 3 for k in range(7)})
    assert [e.time for e in col.gnss_epochs] == [ep.time for ep in epochs]
    for got, ep in zip(col.gnss_epochs, epochs, strict=True):
        assert got.complete and got.messages == tuple(nums) and got.systems == set(SYSTEMS)
        o = got.obs
        assert sorted(zip(o.gnss_id.tolist(), o.sv_id.tolist())) == sorted(zip(ep.gnss_id.tolist(),
                                                                             ep.sv_id.tolist()))
        at = {(g, s): i for i, (g, s) in enumerate(zip(ep.gnss_id.tolist(), ep.sv_id.tolist()))}
        pr_res_m = (2**-24 if kind != 7 else 2**-29) * CLIGHT_M_S / 1000
        cp_res_m = (2**-29 if kind != 7 else 2**-31) * CLIGHT_M_S / 1000
        for j, key in enumerate(zip(o.gnss_id.tolist(), o.sv_id.tolist())):
            i = at[key]
            lam = l1_wavelength_m(key[0], int(ep.glo_fcn[i]) if key[0] == GNSS_GLONASS else None)
            assert abs(o.pr_m[j] - ep.pr_m[i]) <= pr_res_m / 2 + 1e-6, key
            assert abs(o.cp_cyc[j] - ep.cp_cyc[i]) * lam <= cp_res_m / 2 + 1e-6, key
            assert str(o.signal[j]) == str(ep.signal[i])
            if kind != 4:
                assert abs(o.dop_hz[j] - ep.dop_hz[i]) * lam <= 0.0001, key
    assert col.base_position is not None and col.glonass_biases is not None and col.glonass_biases.aligned


def test_budget_holds_every_second_defers_and_counts() -> None:
    budget = SecondBudget(100.0)
    sent = budget.offer(10.2, [("obs", b"o" * 60)], [("position", b"p" * 30), ("ephemeris", b"e" * 20)])
    assert [k for k, _ in sent] == ["obs", "position"] and budget.counts.deferred == {"ephemeris": 1}
    sent = budget.offer(10.6, [], [("ephemeris", b"e" * 10), ("ephemeris", b"e" * 20)])  # 10 B left this second
    assert [len(f) for _, f in sent] == [10] and budget.counts.deferred == {"ephemeris": 2}
    sent = budget.offer(11.0, [("obs", b"o" * 150)], [("position", b"p" * 1)])  # obs alone over: sent, counted
    assert [k for k, _ in sent] == ["obs"] and budget.counts.over_budget_s == 1
    assert budget.left_bytes(11.5) == -50 and budget.left_bytes(12.0) == 100
    assert budget.counts.sent_bytes == 60 + 30 + 10 + 150 and budget.counts.sent == {"obs": 2, "position": 1,
                                                                                     "ephemeris": 1}


def test_rotation_new_issue_first_then_longest_waiting_after_the_interval() -> None:
    rot = EphemerisRotation(30.0)
    issues = {"G01": 1, "G02": 1, "R03": 1}
    assert rot.due(0.0, issues) == ["G01", "G02", "R03"]
    rot.sent("G01", 1, 0.0)
    rot.sent("R03", 1, 5.0)
    assert rot.due(10.0, issues) == ["G02"]
    rot.sent("G02", 1, 10.0)
    assert rot.due(29.0, issues) == []
    assert rot.due(36.0, issues) == ["G01", "R03"]
    assert rot.due(36.0, {**issues, "R03": 2}) == ["R03", "G01"]  # a new issue before a repeat


def _gps_ephemeris(prn: int, iode: int) -> Ephemeris:
    return Ephemeris(prn=prn, week=T0.week, toe=T0, toc=T0, iode=iode, iodc=iode, sqrt_a=5153.6, e=0.01,
                     i0_rad=0.95, omega0_rad=1.0, omega_rad=0.5, m0_rad=0.1, delta_n_rad_s=4e-9,
                     omega_dot_rad_s=-8e-9, idot_rad_s=1e-10, cuc_rad=1e-6, cus_rad=1e-6, crc_m=200.0, crs_m=20.0,
                     cic_rad=1e-7, cis_rad=1e-7, af0_s=1e-4, af1_s_s=1e-12, af2_s_s2=0.0, tgd_s=-1e-8)


def test_core_never_exceeds_the_budget_sends_every_ephemeris_and_a_new_issue_at_once() -> None:
    gps = {GNSS_GPS: ("1C", 8), GNSS_GLONASS: ("1C", 7)}
    budget = 400.0
    core = BaseCore(BaseOptions(obs_message="msm4", position_ecef_m=POS, radio_budget_bytes_s=budget,
                                ephemeris_interval_s=20.0, receiver_descriptor="u-blox LEA-M8T"))
    for prn in range(1, 9):
        core.on_item(_gps_ephemeris(prn, 10))
    per_second: dict[int, int] = {}
    eph_at: dict[int, list[float]] = {}
    for k in range(60):
        t = T0.add_s(k)
        if k == 30:
            core.on_item(_gps_ephemeris(5, 11))
        frames = core.on_item(synthetic_epoch(t, gps, seed=k))
        per_second[k] = sum(len(f) for _, f in frames)
        for num, (_, f) in zip(_numbers(frames), frames, strict=True):
            if num == 1019:
                eph_at.setdefault(int(RTCMReader.parse(f).DF009), []).append(k)
    assert max(per_second.values()) <= budget
    c = core.counts()
    assert c["sent"]["obs"] == 120 and c["deferred"].get("ephemeris", 0) > 0 and c["over_budget_s"] == 0
    assert sorted(eph_at) == list(range(1, 9))
    first = {prn: ks[0] for prn, ks in eph_at.items()}
    assert max(first.values()) <= 8  # ~150 B of observations a second leave room for 3 of 67 B
    assert all(ks[1] - ks[0] >= 20 for prn, ks in eph_at.items() if prn != 5 and len(ks) > 1)
    assert 30 in eph_at[5] or 31 in eph_at[5]  # the new issue went out at once
    assert c["sent"]["position"] == 6 and c["sent"]["descriptor"] == 6 and c["sent"]["glonass_bias"] == 6


def test_observations_over_the_budget_fall_back_to_msm4_then_are_sent_and_reported(caplog) -> None:
    ep = synthetic_epoch(T0)
    sizes = {}
    for kind in (4, 7):
        frames = BaseCore(BaseOptions(obs_message=f"msm{kind}", position_ecef_m=POS,
                                      radio_budget_bytes_s=1e6)).on_item(ep)
        sizes[kind] = sum(len(f) for k, f in frames if k == "obs")
    position_b = 27
    squeezed = BaseCore(BaseOptions(obs_message="msm7", position_ecef_m=POS,
                                    radio_budget_bytes_s=sizes[4] + position_b + 5))
    frames = squeezed.on_item(ep)
    assert [n % 10 for n, (k, _) in zip(_numbers(frames), frames, strict=True) if k == "obs"] == [4] * 5
    assert "position" in [k for k, _ in frames] and squeezed.obs_downgraded == {"msm4": 1}
    # observations alone over the budget: sent every epoch as MSM4; the position only when never sent yet and
    # then once a whole interval overdue (10 s late), over the budget; the rest deferred, everything counted
    tiny = BaseCore(BaseOptions(obs_message="msm7", position_ecef_m=POS, radio_budget_bytes_s=sizes[4] // 2))
    position_at = []
    for k in range(25):
        frames = tiny.on_item(synthetic_epoch(T0.add_s(k)))
        assert [kind for kind, _ in frames if kind != "position"] == ["obs"] * 5
        position_at += [k for kind, _ in frames if kind == "position"]
    c = tiny.counts()
    assert position_at == [0, 20] and c["deferred"]["position"] == 10
    assert c["over_budget_s"] == 25 and c["obs_downgraded"] == {"msm4": 25} and tiny.over_budget
    assert "over the radio budget" in caplog.text
    assert sizes[7] > sizes[4]


def test_a_half_cycle_is_flagged_not_withheld_and_slips_reset_the_lock() -> None:
    """MSM flags an unresolved half cycle (DF420) instead of withholding the phase as 1004 must; a slip at a
    receiver without lock times (RXM-RAW: NaN) restarts the lock time the base synthesises, which the rover
    decodes as a slip."""
    core = BaseCore(BaseOptions(obs_message="msm4", position_ecef_m=POS))
    stream = b""
    for k in range(4):
        ep = synthetic_epoch(T0.add_s(k), {GNSS_GPS: ("1C", 5)})
        lli = np.zeros(len(ep), np.uint8)
        lli[1] = 2 if k == 1 else 0  # half cycle unresolved at k = 1
        lli[2] = 1 if k == 2 else 0  # a slip at k = 2
        ep = replace(ep, lli=lli, lock_ms=np.full(len(ep), np.nan))
        stream += b"".join(f for _, f in core.on_item(ep))
    col = collect_rtcm([stream], T0)
    half = [int(e.obs.lli[1]) for e in col.gnss_epochs]
    assert half[1] & 2 and math.isfinite(col.gnss_epochs[1].obs.cp_cyc[1])
    assert [int(e.obs.lli[2]) & 1 for e in col.gnss_epochs] == [0, 0, 1, 0]


M8P_ROVER = "gnss/ublox-m8p-galway-2018/raw/rover-20181004-1237.ubx.gz"
F9_LOG = "ubx/pygnssutils_pygpsdata_testobsnavdata.log"


@pytest.mark.shared_data
@pytest.mark.parametrize(("rel", "n_epochs", "systems"), [
    (M8P_ROVER, 120, {GNSS_GPS, GNSS_GLONASS}),
    (F9_LOG, 75, {GNSS_GPS, GNSS_GLONASS, GNSS_GALILEO, GNSS_BEIDOU}),
])
def test_real_rawx_through_the_base_back_equal_within_msm7_resolution(rel: str, n_epochs: int,
                                                                      systems: set[int]) -> None:
    """Real RXM-RAWX (M8P: GPS + GLONASS; F9: + Galileo + BeiDou, L1-band signals kept) → BaseCore MSM7 (with
    the SFRBX navigation decoded alongside) → the rover's collector: every L1 cell of every epoch, pseudorange
    within 1 mm, phase within 1 mm up to the whole cycles an MSM may move it by, and the ephemerides arrive."""
    framer = StreamFramer(frozenset({Protocol.UBX}))
    frames = [f for chunk in iter_file_bytes(shared_file(rel)) for f in framer.feed(chunk)]
    core = BaseCore(BaseOptions(obs_message="msm7", position_ecef_m=POS, radio_budget_bytes_s=5000.0))
    sent_epochs: list[ObsEpoch] = []
    stream = b""
    for f in frames:
        if (f.msg_class, f.msg_id) != (0x02, 0x15):
            core.on_frame(f, 0.0)
            continue
        ep = decode_rxm_rawx(f.payload)
        if ep is None:
            continue
        out = core.on_item(ep)
        if out:
            sent_epochs.append(ep)
            stream += b"".join(x for _, x in out)
        if len(sent_epochs) == n_epochs:
            break
    col = collect_rtcm([stream], sent_epochs[0].time)
    assert len(col.gnss_epochs) == n_epochs and all(e.complete for e in col.gnss_epochs)
    shift: dict[tuple[int, int], float] = {}
    l1 = {GNSS_GPS: "1C", GNSS_GLONASS: "1C", GNSS_GALILEO: "1C", GNSS_QZSS: "1C", GNSS_BEIDOU: "2I"}
    n_cells = 0
    for got, ep in zip(col.gnss_epochs, sent_epochs, strict=True):
        assert got.time == ep.time and got.systems == systems
        at = {(int(g), int(s)): i for i, (g, s) in enumerate(zip(got.obs.gnss_id, got.obs.sv_id))}
        for i in range(len(ep)):
            g, sv = int(ep.gnss_id[i]), int(ep.sv_id[i])
            if g not in l1 or not math.isfinite(ep.pr_m[i]) or not str(ep.signal[i]).startswith(l1[g][0]):
                continue
            j = at[(g, sv)]
            if str(got.obs.signal[j]) != str(ep.signal[i]):
                continue  # another L1 signal of the same satellite was sent
            n_cells += 1
            assert abs(got.obs.pr_m[j] - ep.pr_m[i]) < 1e-3
            if math.isfinite(ep.cp_cyc[i]) and math.isfinite(got.obs.cp_cyc[j]):
                lam = l1_wavelength_m(g, int(ep.glo_fcn[i]) if g == GNSS_GLONASS else None)
                d = float(got.obs.cp_cyc[j] - ep.cp_cyc[i])
                whole = shift.setdefault((g, sv), round(d))
                if abs(d - whole) * lam > 1e-3:  # a new arc may take a new shift
                    whole = shift[(g, sv)] = round(d)
                assert abs(d - whole) * lam < 1e-3
    assert n_cells > 10 * n_epochs
    eph_messages = {f.msg_id for f in iter_frames(stream) if f.msg_id in (1019, 1020, 1042, 1044, 1046)}
    assert eph_messages >= {1019, 1020}


def test_base_section_of_the_configuration_and_its_flags(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """[base] keys reach BaseOptions, the command line overrides them, the shipped defaults are BaseOptions'
    own, and bad values are refused naming the key."""
    from onboard.__main__ import build_parser
    from onboard.base.cli import base_options, base_overrides
    from onboard.errors import ConfigFileError
    from onboard.recorder.settings import BASE_OBSERVATIONS, default_config_path, load_settings

    assert BASE_OBSERVATIONS == OBS_MESSAGES
    argv = ["base", "--port", "/dev/null", "--radio", "/dev/null", "--position=" + ",".join(map(str, POS))]
    shipped = base_options(load_settings(default_config_path(), environ={}), build_parser().parse_args(argv))
    defaults = BaseOptions(position_ecef_m=POS, receiver_descriptor="u-blox")
    assert shipped == defaults
    cfg = tmp_path / "c.toml"
    cfg.write_text('[receiver]\nmodel = "m8t"\n[base]\nobservations = "msm7"\nbudget_bytes_s = 700.0\n'
                   "ephemeris_interval_s = 60.0\nglonass_bias_interval_s = 5.0\n")
    args = build_parser().parse_args([*argv, "--budget", "650", "--position-interval", "20"])
    opts = base_options(load_settings(cfg, environ={}, overrides=base_overrides(args)), args)
    assert (opts.obs_message, opts.radio_budget_bytes_s, opts.ephemeris_interval_s, opts.glonass_bias_interval_s,
            opts.position_interval_s, opts.receiver_descriptor) == ("msm7", 650.0, 60.0, 5.0, 20.0, "u-blox LEA-M8T")
    for text, message in (('[base]\nobservations = "msm6"\n', "base.observations"),
                          ("[base]\nbudget_bytes_s = 0\n", "base.budget_bytes_s 0"),
                          ('[base]\nreceiver_descriptor = "' + "x" * 32 + '"\n', "31 ASCII")):
        cfg.write_text(text)
        with pytest.raises(ConfigFileError, match=message):
            load_settings(cfg, environ={})
