"""Typed inputs shared by the decoders, the RTK engine, the RINEX writer and the simulator.

Everything downstream of the parsing boundary sees these, never pyubx2/pyrtcm attribute names.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from onboard.gnsstime import GpsTime

# u-blox gnssId values (RXM-RAWX); RXM-RAW carries GPS (1–32) and SBAS (120–158) only.
GNSS_GPS = 0
GNSS_SBAS = 1
GNSS_GALILEO = 2
GNSS_BEIDOU = 3
GNSS_QZSS = 5
GNSS_GLONASS = 6

SYSTEM_LETTER = {GNSS_GPS: "G", GNSS_SBAS: "S", GNSS_GALILEO: "E", GNSS_BEIDOU: "C", GNSS_QZSS: "J",
                 GNSS_GLONASS: "R"}
"""u-blox gnssId → RINEX 3 system letter."""

FCN_NONE = -128
"""`ObsEpoch.glo_fcn` where there is no GLONASS frequency channel: another system, or a channel not known."""

LLI_SLIP = 0x01
"""RINEX LLI bit 0: lost lock between the previous and this observation (possible cycle slip)."""
LLI_HALF_CYCLE = 0x02
"""RINEX LLI bit 1: half-cycle ambiguity possible (phase not yet resolved to a full cycle)."""


@dataclass(frozen=True)
class ObsEpoch:
    """Raw single-frequency (L1) observations of one receiver epoch.

    `time` is the receiver time tag (receiver clock, not yet corrected: u-blox tags sit at …999 ms or
    …992 ms). Arrays are all shape (n,), one entry per tracked signal:
    `gnss_id` u-blox gnssId, `sv_id` satellite number within it (GPS PRN 1–32, SBAS 120–158),
    `pr_m` pseudorange (m), `cp_cyc` carrier phase (cycles of the signal's own carrier: a GLONASS FDMA phase
    is in cycles of 1602 + 0.5625·k MHz; NaN when invalid), `dop_hz` Doppler (Hz),
    `cn0_dbhz` carrier-to-noise density (dB-Hz), `lock_ms` lock time (ms, NaN when the receiver has none,
    e.g. RXM-RAW), `lli` RINEX loss-of-lock bits (LLI_SLIP | LLI_HALF_CYCLE), `half_cyc_sub` 1 where the
    receiver already subtracted a half cycle (RXM-RAWX trkStat bit 3), `pr_std_m`, `cp_std_cyc` receiver
    precision estimates (NaN where unknown). `clock_reset` is True when the receiver reported a clock reset
    (RXM-RAWX recStat bit 1); `leap_s` the GPS−UTC leap seconds it reported (None if unknown).

    Multi-GNSS (optional: empty arrays on GPS-only paths, which never read them): `glo_fcn` GLONASS frequency
    channel number k (−7…+6; carrier 1602 + 0.5625·k MHz) per entry, FCN_NONE for other systems and unknown
    channels; `signal` RINEX 3 band + attribute of the tracked signal ("1C" GPS/GLONASS/QZSS L1 C/A or
    Galileo E1C, "1B" E1B, "1X" E1B+C, "2I" BeiDou B1I, "1Z" QZSS L1S …), "" where unknown. A u-blox M8
    (RXM-RAWX version 0) reports no signal id: its L1 signals are "1C", Galileo "1X" (E1 B+C, as RTKLIB) and
    BeiDou "2I".
    Times of every system are GPS time (receiver time tag); sv_id is the number within the system (QZSS 1–10,
    not PRN 193–202; SBAS keeps its PRN 120–158).
    """

    time: GpsTime
    gnss_id: npt.NDArray[np.int8]
    sv_id: npt.NDArray[np.int16]
    pr_m: npt.NDArray[np.float64]
    cp_cyc: npt.NDArray[np.float64]
    dop_hz: npt.NDArray[np.float64]
    cn0_dbhz: npt.NDArray[np.float64]
    lock_ms: npt.NDArray[np.float64]
    lli: npt.NDArray[np.uint8]
    half_cyc_sub: npt.NDArray[np.uint8] = field(default_factory=lambda: np.zeros(0, np.uint8))
    pr_std_m: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    cp_std_cyc: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    clock_reset: bool = False
    leap_s: int | None = None
    glo_fcn: npt.NDArray[np.int8] = field(default_factory=lambda: np.zeros(0, np.int8))
    signal: npt.NDArray[np.str_] = field(default_factory=lambda: np.zeros(0, "<U2"))

    def __len__(self) -> int:
        return int(self.sv_id.shape[0])

    def gps_only(self) -> ObsEpoch:
        """The same epoch restricted to GPS satellites (gnssId 0, PRN 1–32)."""
        g: ObsEpoch | bool | None = self.__dict__.get("_gps")  # the reader, the pairing, the batch, the engine ask
        if isinstance(g, ObsEpoch):
            return g
        if g is True:
            return self
        keep = (self.gnss_id == GNSS_GPS) & (self.sv_id >= 1) & (self.sv_id <= 32)
        # frozen: the epoch itself is its GPS part (GPS-only files, every engine epoch), else kept once made
        # (True stands for the epoch itself: no reference cycle)
        if keep.all():
            object.__setattr__(self, "_gps", True)
            return self
        gps = self.select(keep)
        object.__setattr__(self, "_gps", gps)
        return gps

    def select(self, keep: npt.NDArray[np.bool_]) -> ObsEpoch:
        """The same epoch keeping only the entries where `keep` is True."""

        def pick(a: np.ndarray) -> np.ndarray:
            return a[keep] if a.shape[0] == keep.shape[0] else a

        return ObsEpoch(
            time=self.time, gnss_id=pick(self.gnss_id), sv_id=pick(self.sv_id), pr_m=pick(self.pr_m),
            cp_cyc=pick(self.cp_cyc), dop_hz=pick(self.dop_hz), cn0_dbhz=pick(self.cn0_dbhz),
            lock_ms=pick(self.lock_ms), lli=pick(self.lli), half_cyc_sub=pick(self.half_cyc_sub),
            pr_std_m=pick(self.pr_std_m), cp_std_cyc=pick(self.cp_std_cyc),
            clock_reset=self.clock_reset, leap_s=self.leap_s, glo_fcn=pick(self.glo_fcn), signal=pick(self.signal),
        )

    def system(self, gnss_id: int) -> ObsEpoch:
        """The same epoch restricted to one system's entries (u-blox gnssId)."""
        return self.select(self.gnss_id == gnss_id)

    def systems(self) -> frozenset[int]:
        """The u-blox gnssIds present in this epoch."""
        return frozenset(np.unique(self.gnss_id).tolist())


@dataclass(frozen=True)
class Ephemeris:
    """Keplerian broadcast ephemeris and clock of one satellite: GPS LNAV (IS-GPS-200 subframes 1–3) by
    default; also Galileo I/NAV or F/NAV, BeiDou D1/D2 and QZSS LNAV, told apart by `gnss_id` (u-blox gnssId).

    Angles in radians (semicircles converted at the boundary), rates in rad/s, harmonic corrections in
    m or rad, clock terms in s, s/s, s/s². `toe`/`toc` are instants on the GPS time scale with the full GPS
    week (a Galileo or BeiDou toe/toc broadcast in GST/BDT is converted: onboard.gnsstime), `week` the GPS
    week of `toe`. `prn` is the u-blox svId (QZSS 1–10 = PRN 193–202). For the other systems: `iode`/`iodc`
    hold Galileo IODnav (both) or BeiDou AODE/AODC; `ura_index` the Galileo SISA index or BeiDou URAI;
    `health` Galileo's RINEX SV health word (E5b HS << 7 | E5b DVS << 6 | E1-B HS << 1 | E1-B DVS, as RTKLIB's
    svh) or BeiDou SatH1; `code_on_l2` the Galileo RINEX data-source bits (RTKLIB's eph.code);
    `tgd_s` Galileo BGD(E1,E5a) or BeiDou TGD1 (B1I), `tgd2_s` Galileo BGD(E1,E5b) or BeiDou TGD2.
    Only GPS ones go into the engine's EphemerisStore today (keyed by PRN).
    """
    prn: int
    week: int
    toe: GpsTime
    toc: GpsTime
    iode: int
    iodc: int
    sqrt_a: float
    e: float
    i0_rad: float
    omega0_rad: float
    omega_rad: float
    m0_rad: float
    delta_n_rad_s: float
    omega_dot_rad_s: float
    idot_rad_s: float
    cuc_rad: float
    cus_rad: float
    crc_m: float
    crs_m: float
    cic_rad: float
    cis_rad: float
    af0_s: float
    af1_s_s: float
    af2_s_s2: float
    tgd_s: float
    ura_index: int = 0
    health: int = 0
    fit_interval_h: float = 4.0
    code_on_l2: int = 1
    l2p_flag: int = 0
    gnss_id: int = GNSS_GPS
    tgd2_s: float = 0.0

    @property
    def toe_s(self) -> float:
        """Time of ephemeris, seconds of week."""
        return self.toe.tow_s

    @property
    def toc_s(self) -> float:
        """Time of clock, seconds of week."""
        return self.toc.tow_s


@dataclass(frozen=True)
class GlonassEphemeris:
    """GLONASS broadcast ephemeris (immediate data of strings 1–4, GLONASS ICD 5.1): a state vector at `toe`.

    `slot` orbital slot 1–24 (u-blox svId, RINEX Rnn), `channel` frequency channel k (−7 … +6),
    `toe` the instant tb on the GPS time scale (GLONASS time = UTC(SU) + 3 h converted with the leap seconds),
    `tof` the message frame time tk on the GPS time scale, `pos_m`/`vel_m_s`/`acc_m_s2` the PZ-90 position,
    velocity and luni-solar acceleration at tb (m, m/s, m/s²; PZ-90.11 is taken as WGS 84, as RTKLIB does:
    they agree to a few centimetres), `tau_n_s` the satellite clock offset τn (s; satellite time = GLONASS
    time − τn + γn·(t − tb)), `gamma_n` the relative frequency offset γn (s/s), `delta_tau_n_s` Δτn (L2 − L1
    delay, s), `health` 0 when healthy (bit 0: Bn's MSB, what RTKLIB and RINEX call health; bit 1: the
    GLONASS-M ln flag of string 3, when decoded from strings), `age_days` En, `iode` the 7-bit
    tb index (tb in 15 min units, RTKLIB's iode for GLONASS), `ft` the accuracy index FT (15 when unknown).
    """

    slot: int
    channel: int
    toe: GpsTime
    tof: GpsTime
    pos_m: tuple[float, float, float]
    vel_m_s: tuple[float, float, float]
    acc_m_s2: tuple[float, float, float]
    tau_n_s: float
    gamma_n: float
    delta_tau_n_s: float = 0.0
    health: int = 0
    age_days: int = 0
    iode: int = 0
    ft: int = 15


@dataclass(frozen=True)
class CameraMark:
    """One TIM-TM2 report (or GPIO edge) mapped to GPS time.

    `channel` EXTINT index (0 flash, 1 trigger where wired); `edge` "falling"/"rising"; `count` the
    receiver's rising-edge counter; `time` the edge in GPS time (None when the receiver said it was not valid);
    `acc_est_ns` accuracy estimate; `time_base` 0 receiver, 1 GNSS, 2 UTC; `source` "tim-tm2" or "gpio".
    """

    channel: int
    edge: str
    count: int
    time: GpsTime | None
    acc_est_ns: int
    time_base: int
    valid: bool
    source: str = "tim-tm2"


Q_NONE = 0
Q_FIX = 1
Q_FLOAT = 2
Q_SINGLE = 5
"""Solution quality flags, RTKLIB's .pos `Q` column (1 fixed, 2 float, 5 single point, 0 none: no position)."""


class BasePositionRejected(ValueError):
    """The given base position is contradicted by the base's own single-point solution by more than the
    bound (RtkOptions.max_base_spp_offset_m): every output position would carry the error. A data rule: the
    command lines answer it with exit 3."""

    def __init__(self, offset_m: float, bound_m: float, epochs: int) -> None:
        super().__init__(f"base position {offset_m:.1f} m from the base's own single-point position (median of "
                         f"{epochs} epochs): more than {bound_m:g} m; check the base position")
        self.offset_m = offset_m
        """3D distance (m) between the given position and the median single-point position."""
        self.bound_m = bound_m
        self.epochs = epochs


@dataclass(frozen=True)
class Solution:
    """One epoch's position solution (the RTK engine's output, one per rover epoch).

    `time` GPS time of the solution (receiver time tag minus the estimated receiver clock bias, as RTKLIB),
    `pos_ecef_m` (3,) rover antenna L1 phase centre, `vel_ecef_m_s` (3,) (NaN when not estimated),
    `q` Q_FIX/Q_FLOAT/Q_SINGLE/Q_NONE, `ns` satellites used (a Q_NONE solution has no position: NaN position,
    velocity and covariances, ns 0; never read it as a position), `cov_pos_m2` (3,3) ECEF position covariance,
    `cov_vel_m2_s2` (3,3) velocity covariance, `age_s` age of the base data (rover − base time, s),
    `ratio` the ambiguity ratio-test value (0 when no search ran), `fix_id` the pass's integer-set lineage of a
    fix (fixes with one id rest on one set of integers, held or re-fixed, satellites joining and leaving; -1 when
    not fixed or not known).
    """

    time: GpsTime
    pos_ecef_m: npt.NDArray[np.float64]
    vel_ecef_m_s: npt.NDArray[np.float64]
    q: int
    ns: int
    cov_pos_m2: npt.NDArray[np.float64]
    cov_vel_m2_s2: npt.NDArray[np.float64]
    age_s: float = 0.0
    ratio: float = 0.0
    fix_id: int = -1
