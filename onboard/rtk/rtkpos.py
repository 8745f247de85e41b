"""L1 relative positioning (GPS, and GLONASS/Galileo/BeiDou/QZSS with RtkOptions.systems): Kalman filter on
double differences within each constellation, MLAMBDA, fix-and-hold.

Follows RTKLIB rtkpos.c relpos(): time update of the rover position/velocity (udpos) and of the
single-difference ambiguities (udbias, with slip detection), zero-difference residuals (zdres), double
differences with an elevation-weighted covariance (ddres), integer resolution with a ratio test and partial
fixing (resamb_lambda), validation of the fix (valpos) and hold (holdamb). Additions over RTKLIB:
between-satellite Doppler differences constrain the velocity; every fix is checked against the float
solution (Mahalanobis distance) and post-fit residuals; a held fix that stops fitting is released; a fix
must rest on at least `min_fix_sats` satellites; known-point initialisation
(Daakir et al. 2015 eq. 2) and a static mode until take-off.

State vector: x[0:3] rover position (ECEF m), x[3:6] velocity (m/s), x[6+slot] SD ambiguity of each satellite
slot (rover − base, cycles of its own carrier; slots: onboard.rtk.slots, GPS `prn` at slot prn − 1), and, while the
baseline is in the band of RtkOptions.iono_min/max_baseline_km, x[6+n+slot] the SD vertical GPS-L1 ionospheric
delay of the slot's satellite (rover − base, m; see _udion), n the number of slots (32 for GPS alone). Pure: no
I/O, no clock.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

from onboard.gnsstime import GpsTime
from onboard.rtk.consts import CLIGHT_M_S, LAMBDA_L1_M, OMEGA_E_RAD_S
from onboard.rtk.ephemeris import EphemerisStore, SatState, geometric_range, satellite_states_batch
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation
from onboard.rtk.linsolve import LinAlgError, solve
from onboard.rtk.mlambda import LambdaError, LambdaResult, mlambda
from onboard.rtk.models import (
    ChannelCodeBias,
    CodeScatter,
    iono_mapping,
    median_of_few,
    phase_variance_m2,
    saastamoinen_m,
)
from onboard.rtk.navstore import BroadcastNavigation
from onboard.rtk.options import RtkOptions
from onboard.rtk.pntpos import SppSolution, _norm, pntpos, pntpos_batch, sat_az_el
from onboard.rtk.slots import (
    SlotLayout,
    lambda_ratio_to_gps,
    satellite_states_layout,
    screen_observations,
    slot_arrays,
    slot_layout,
    wavelengths,
)
from onboard.rtk.standstill import StandstillMonitor
from onboard.rtk.tdcp_slips import MIN_SATS as TDCP_MIN_SATS
from onboard.rtk.tdcp_slips import tdcp_slips
from onboard.rtk.types import LLI_HALF_CYCLE, LLI_SLIP, Q_FIX, Q_FLOAT, Q_NONE, Q_SINGLE, ObsEpoch, Solution

log = logging.getLogger(__name__)

Arr = npt.NDArray[np.float64]
NSAT = 32
NX0 = 6
NXI = NX0 + NSAT
"""Size of the state without ionosphere states, and index of the first one (see _udion)."""
NX = NXI + NSAT
"""Size of the state with them: the arrays grow to it only while they are in use (smaller arrays otherwise)."""
_CHI2_3DOF_999 = 16.27
RATIO_CAP = 999.9
"""Largest AR ratio reported (RTKLIB's .pos column): LAMBDA stops searching once the ratio provably exceeds it."""
_NO_TIME_NS = np.iinfo(np.int64).min
_PRNS = np.arange(1, NSAT + 1, dtype=np.int16)
_PRNS.flags.writeable = False  # shared by every epoch's SatState
_ROWS = np.arange(3 * 200)  # row indices of the DD system (phase + code + Doppler rows of every slot at most)
_ROWS.flags.writeable = False
_LAM_GPS = np.full(NSAT, LAMBDA_L1_M)
_LAM_GPS.flags.writeable = False
GPS_LAYOUT = slot_layout("G")

SPP_SIGMA_PER_GDOP_M = 1.5
"""σ (m per axis) of a single-point solution per unit of GDOP: a user range error of 1.5 m, u-blox L1 code in
the open (RTKLIB reports SPP covariances from its own weighted fit; this is the .pos σ of Q=5 rows)."""
SPP_VEL_VAR_M2_S2 = 0.01
"""Variance (m²/s²) per axis reported with a single-point Doppler velocity: 0.1 m/s, the order of an L1 Doppler
velocity's error."""
MIN_PHASE_DD_TO_ISOLATE = 5
"""Fewest phase double differences among which one outlier can be told from the rest: with fewer (or with
several rows out) every ambiguity restarts instead of the worst one (a single bad row shifts the others)."""
MIN_DD_REFERENCE_SLIP = 3
"""Fewest phase double differences that must all misfit at once, under a hold, for the reference satellite to be
taken as the one that slipped (with two, either satellite could be the one)."""
RELEASE_AMB_SIGMA_CYC = 0.5
"""σ (cycles) added to every ambiguity when a held set is released: half a cycle, enough to let them move to
another integer, small enough to keep what the float knows."""
FIX_TRIES = 2
"""Integer searches per epoch: the first, and one retry on a reduced set after a rejected fix (see _resolve)."""
SLIP_TEST_MAX_GAP_S = 30.0
"""Longest gap (s) across which a phase is compared with its previous one for a slip (the rover's Doppler
prediction, the base's phase − range): beyond it the atmosphere and the clocks move too much for a cycle to be
told apart, and the satellite counts as not bridged."""
DOPPLER_MIN_ELEVATION_RAD = 0.1
"""Elevation floor (rad, ~5.7°) of the Doppler σ / sin(el) weighting: bounded near the horizon, below any mask."""
BASE_SLIP_CYC = 0.5
"""Base geometry-residual slip threshold (cycles) between consecutive base epochs, plus BASE_SLIP_CYC_PER_S per
second of gap: half a cycle, since a 1-cycle base slip reads 1.0 ± millimetres and slipped under 1.0."""
BASE_HISTORY_JUMP_CYC = 1.0
"""A jump of the base's phase − range beyond this (cycles, plus BASE_SLIP_CYC_PER_S per second) voids the
slot's correction history (the rate fit must not straddle a slip; looser than the slip test it follows)."""
BASE_SLIP_CYC_PER_S = 0.05
"""Growth (cycles/s) of the base thresholds with the gap: atmosphere and orbit changes grow with it."""
HALF_CYCLE_STEP_CYC = 0.25
"""A half-cycle flag clearing with a phase step beyond this (cycles, Doppler-predicted, clock removed) is a slip:
a ½-cycle correction reads 0.5, noise a few hundredths."""
HALF_CYCLE_MAX_GAP_S = 2.0
"""Longest epoch interval (s) over which that step is judged (the Doppler prediction degrades with the gap)."""
KNOWN_AMB_SIGMA_CYC = 0.05
"""σ (cycles) of an ambiguity seeded from a known rover position besides the position's own σ/λ: the phase noise
and residual models of one epoch."""
SPP_RESET_DISTANCE_M = 100.0
"""A filter position this far (m) from the single-point solution is restarted on it (RTKLIB udpos's reset)."""
SPP_RESET_VAR_M2 = 1e4
"""Likewise a position variance above this (m², a 100 m σ): the filter no longer knows where it is."""
KNOWN_VEL_VAR_M2_S2 = 1e-8
"""Variance (m²/s²) of a velocity known to be zero (static start, zero-velocity update at a standstill)."""
GEODETIC_CODE_SCALE = 0.5
"""Code variance scale (code_variance_scale) under which the code counts as geodetic rather than u-blox-like: the
per-km confirmation span and the ionosphere states' per-km walk depend on it."""
MAD_TO_SIGMA = 1.4826
"""Median absolute deviation to standard deviation of a normal distribution."""


class NavData(Protocol):
    """What the engine needs from navigation data: an ephemeris store and Klobuchar coefficients."""

    store: EphemerisStore
    iono: tuple | None


@dataclass
class Nav:
    """Navigation data for the engine: GPS ephemerides, optional Klobuchar (alpha, beta) and, for the other
    constellations (RtkOptions.systems), their broadcast ephemerides."""

    store: EphemerisStore
    iono: tuple | None = None
    broadcast: BroadcastNavigation | None = None


@dataclass
class _Receiver:
    """Per-epoch zero-difference data of one receiver on the engine's slots (32 GPS ones, or those of
    RtkState.layout; NaN where absent)."""

    pr_m: Arr
    cp_cyc: Arr
    dop_hz: Arr
    lli: npt.NDArray[np.uint8]
    sats: SatState  # aligned with the slots
    has: npt.NDArray[np.bool_]
    lam: Arr = field(default_factory=lambda: _LAM_GPS)
    """Carrier wavelength per slot (m): the unit of its phase (GLONASS: its frequency channel's)."""
    cn0_dbhz: Arr | None = None
    """C/N0 per slot (dB-Hz; NaN, or 0 as RTCM MSM sends it, where unknown), None when the source has none."""
    memo: dict[tuple[object, ...], tuple[Arr, ...]] = field(default_factory=dict)
    """What was already computed for this epoch, by (what, its inputs): geometry by receiver position bytes (the
    base epoch serves several rover epochs from the same known position, and the rover's is asked for again at
    the same predicted position), the base's correction rate by history (_extrapolated_base). Read-only."""


class PendingFix(NamedTuple):
    """A first-fix candidate under confirmation: the integer set that has won the ratio test at consecutive
    epochs without a held set to lean on (see RtkOptions.confirm_fix_span_s, settled_fix_span_s)."""

    key: tuple[int, tuple[int, ...], tuple[int, ...]]
    """(reference slot, other slots, their DD integers in cycles): the set's identity."""
    since: GpsTime
    """Its first win of the current run."""
    wins: int
    """Consecutive epochs it has won."""
    last_win: GpsTime
    """Its latest win."""
    settled_fraction: float
    """How far it has settled: wins weighted by time over settled_fix_span_s (static) or settled_fix_span_moving_s
    (moving); 1 = settled."""
    slot_ints: Arr
    """Its integers per slot (_slot_integers): how a set with a satellite more or less is told the same
    (RtkOptions.confirm_across_set_changes)."""


_NO_F: Arr = np.zeros(0)
_NO_F.flags.writeable = False
_NO_B: npt.NDArray[np.bool_] = np.zeros(0, bool)
_NO_B.flags.writeable = False


class EpochContext:
    """Per-epoch scratch of rtk_pos (what RTKLIB relpos() keeps on its stack), filled by its stages in order and
    dropped with the epoch; RtkState keeps what persists. Slot arrays are (32,), one entry per GPS PRN."""

    time: GpsTime
    """The rover epoch's time tag (receiver time)."""
    rov: _Receiver
    spp: SppSolution
    """The rover's single-point solution at this epoch."""
    t_sol: GpsTime
    """Solution time: the time tag minus the receiver clock bias (as RTKLIB)."""
    moving: bool
    """The rover's Doppler speed exceeds takeoff_speed_m_s (its code multipath decorrelates)."""
    bas: _Receiver | None
    """The base epoch's slot data, carried forward along the correction rate once aged (see _extrapolated_base)."""
    base_pos: Arr
    """Base antenna position (ECEF m)."""
    age_s: float
    """Age of the base data (rover − base time, s)."""
    dt_s: float
    """Time since the previous processed epoch (s, negative processed backward)."""
    baseline_m: float
    """Rover–base distance (m) at the previous epoch's position (the partial-fix confirmation grows with it)."""
    base_age_var_m2: float
    """Variance (m²) of the carried-forward base phase (atmosphere/clock drift the correction rate does not
    follow): (base_age_sigma_m_s · age)², added to every single difference; 0 for raw base data."""
    static_code_factor: float
    """Factor on the code variance while the rover is held static (see static_code_factor)."""
    rng_b: Arr
    """Base modelled range per slot (m): geometric + Sagnac − satellite clock + troposphere."""
    rng_r: Arr
    """Rover modelled range per slot at the predicted position (m)."""
    los_r: Arr
    """Rover line-of-sight unit vectors (32, 3)."""
    el: Arr
    """Rover elevation per slot (rad)."""
    trop_r: Arr
    """Rover troposphere delay per slot (m), evaluated once per epoch."""
    base_zb_cyc: Arr
    """Base phase − modelled range per slot (cycles): the base-side slip test and correction history."""
    common: npt.NDArray[np.bool_]
    """Slots seen by both receivers above the mask and used by the single-point solution (their code is used)."""
    half: npt.NDArray[np.bool_]
    """Slots with an unresolved half cycle on either receiver (never used for AR)."""
    phase_ok: npt.NDArray[np.bool_]
    """Common slots with phase on both receivers (the satellite selection of the phase)."""
    code_ok: npt.NDArray[np.bool_]
    """Slots whose code enters the update (common minus code outliers)."""
    use_phase: npt.NDArray[np.bool_]
    """Slots whose phase enters the update (phase_ok minus outliers and misfits)."""
    x_prior: Arr
    p_prior: Arr
    """The state before the accepted measurement update (fault exclusion re-runs the update from it)."""
    dd: _DD | None
    """The double-difference system of the last outlier pass."""
    ns: int
    """Satellites whose phase is used."""
    anchored: bool
    """The float was pinned this epoch to the other pass's fix (see _apply_anchor): its integers need no
    confirmation."""

    __slots__ = (  # noqa: RUF023 (in the order of the stages that fill them)
        "time", "rov", "spp", "t_sol", "moving", "bas", "base_pos", "age_s", "dt_s", "baseline_m",
        "base_age_var_m2", "static_code_factor", "rng_b", "rng_r", "los_r", "el", "trop_r",
        "base_zb_cyc", "common", "half", "phase_ok", "code_ok", "use_phase", "x_prior", "p_prior", "dd",
        "ns", "anchored",
    )

    def __init__(self, time: GpsTime, rov: _Receiver, spp: SppSolution, t_sol: GpsTime) -> None:
        self.time = time
        self.rov = rov
        self.spp = spp
        self.t_sol = t_sol
        self.moving = False
        self.bas = None
        self.base_pos = _NO_F
        self.age_s = 0.0
        self.dt_s = 0.0
        self.baseline_m = 0.0
        self.base_age_var_m2 = 0.0
        self.static_code_factor = 1.0
        self.rng_b = _NO_F
        self.rng_r = _NO_F
        self.los_r = _NO_F
        self.el = _NO_F
        self.trop_r = _NO_F
        self.base_zb_cyc = _NO_F
        self.common = _NO_B
        self.half = _NO_B
        self.phase_ok = _NO_B
        self.code_ok = _NO_B
        self.use_phase = _NO_B
        self.x_prior = _NO_F
        self.p_prior = _NO_F
        self.dd = None
        self.ns = 0
        self.anchored = False


@dataclass
class RtkState:
    """Filter state (RTKLIB rtk_t): estimates, covariance, per-satellite counters. Mutated by rtk_pos()."""

    options: RtkOptions
    layout: SlotLayout = GPS_LAYOUT
    """The satellite slots (onboard.rtk.slots) of options.systems: every per-slot array below has layout.n
    entries (32, PRN − 1, for GPS alone)."""
    ns: int = NSAT
    """layout.n: the number of slots."""
    nxi: int = NXI
    """NX0 + ns: the size of the state without ionosphere states and the index of the first one."""
    x: Arr = field(default_factory=lambda: np.zeros(NXI))
    p: Arr = field(default_factory=lambda: np.zeros((NXI, NXI)))
    initialized: bool = False
    time: GpsTime | None = None
    lock: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(NSAT, np.int64))
    outage: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(NSAT, np.int64))
    half_cycle: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(NSAT, bool))
    prev_cp_r: Arr = field(default_factory=lambda: np.full(NSAT, np.nan))
    prev_dop_r: Arr = field(default_factory=lambda: np.full(NSAT, np.nan))
    prev_time_r: GpsTime | None = None
    prev_sat_pos_r: Arr = field(default_factory=lambda: np.zeros((NSAT, 3)))
    """Per slot, its satellite's ECEF position (m) at the rover epoch of prev_cp_r (the time-differenced phase
    test's other end)."""
    prev_sat_clk_r: Arr = field(default_factory=lambda: np.zeros(NSAT))
    """Per slot, its satellite's clock bias (s) then."""
    prev_sat_ok_r: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(NSAT, bool))
    """Per slot, whether an ephemeris gave that position and clock."""
    prev_phase_r: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(NSAT, bool))
    """Slots with rover phase at the previous rover epoch (a gap without a Doppler bridge is a slip)."""
    last_t_r_ns: npt.NDArray[np.int64] = field(default_factory=lambda: np.full(NSAT, _NO_TIME_NS, np.int64))
    """Per slot, the rover time (ns since the GPS epoch) of its last phase + Doppler; _NO_TIME_NS = never."""
    prev_zb: Arr = field(default_factory=lambda: np.full(NSAT, np.nan))
    prev_time_b: GpsTime | None = None
    fix_count: int = 0
    held_prns: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(NSAT, bool))
    known_amb: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(NSAT, bool))
    """Ambiguities seeded from the surveyed take-off point (exempt from the lock wait before AR)."""
    validated_int: Arr = field(default_factory=lambda: np.full(NSAT, np.nan))
    """Integer SD-ambiguity offsets (cycles, relative to one member) of the last held set, NaN off it; a slot
    leaves it on any reset (slip, outage, outlier), so the rest stays tracked without a slip since validation.
    Survives the release of a hold, whose misfitting satellites are reset."""
    gap_int: Arr = field(default_factory=lambda: np.full(NSAT, np.nan))
    """validated_int as it was when a hold was released on a base carried forward (a radio gap), NaN elsewhere;
    slots leave it on a reset as they leave validated_int (see RtkOptions.resume_hold_after_gap)."""
    gap_base_time: GpsTime | None = None
    """The base epoch of that release: the set is tried again at the first epoch paired with a newer one. None
    when no such try is due."""
    lineage_int: Arr = field(default_factory=lambda: np.full(NSAT, np.nan))
    """The last fix's integers (as validated_int, NaN off it and on any reset since): a fix equal to them on the
    satellites both hold continues their lineage (Solution.fix_id)."""
    lineage_id: int = -1
    """Solution.fix_id of that lineage (-1 before the first fix); ids count from 0 in each run of the filter."""
    static: bool = False
    init_pos_ecef_m: Arr | None = None
    fail_count: int = 0
    slips: int = 0
    base_cache: tuple[GpsTime, _Receiver] | None = None
    base_hist: list[tuple[GpsTime, Arr]] = field(default_factory=list)
    """Recent base epochs (time, phase − modelled range in cycles per slot, NaN after a base slip), oldest
    first: the per-satellite correction rate that bridges a radio gap (see _extrapolated_base)."""
    last_ratio: float = 0.0
    clock_bias_m: float = 0.0
    pending_fix: PendingFix | None = None
    """The first-fix candidate under confirmation (an integer set winning the ratio test without a held set to
    lean on), None without one."""
    stuck_since: GpsTime | None = None
    """Start of the current run of epochs whose float ambiguities were determined yet near no integer set
    (see the option stuck_float_s), None outside one."""
    float_restarts: int = 0
    """Times the float ambiguities were restarted for that (stuck_float_s)."""
    pending_slip: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(NSAT, bool))
    """Rover slips detected while no base data was usable, applied at the next relative epoch."""
    code_scatter: CodeScatter = field(default_factory=CodeScatter)
    code_var_scale: float = 1.0
    """Factor on the modelled code variance from the measured code scatter (see code_variance_scale)."""
    channel_code_bias: ChannelCodeBias | None = None
    """The GLONASS channels' SD code biases learned at fixed epochs (glonass_code_bias_min_epochs), None
    without GLONASS or with the learning off."""
    standstill: StandstillMonitor = field(default_factory=StandstillMonitor)
    iono_on: bool = False
    """The per-satellite ionosphere states are in use (see _udion)."""
    rejected_updates: int = 0
    """Epochs whose every outlier pass found an outlier, so that they had no measurement update (their solution
    is the time update's: see _float_update)."""
    pairs_memo: dict[tuple[bytes, bytes], tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]] = field(
        default_factory=dict, repr=False, compare=False)
    """_dd_pairs' results by (slots, elevations) bytes: a cache, no state of the filter."""
    lambda_z: dict[tuple[bytes, bytes], Arr] = field(default_factory=dict, repr=False, compare=False)
    """The last decorrelating Z of each DD ambiguity set (others, references as bytes), where the next reduction
    of that set starts (mlambda's z_start): same integers and ratio, the success rate of that reduced basis."""


def rtk_init(options: RtkOptions, init_pos_ecef_m: Arr | None = None) -> RtkState:
    """A fresh engine state. `init_pos_ecef_m` = surveyed take-off antenna position (known-point start, ECEF
    m); ValueError when it is not three finite coordinates."""
    if init_pos_ecef_m is not None:
        init = np.asarray(init_pos_ecef_m, float)
        if init.shape != (3,) or not np.all(np.isfinite(init)):
            raise ValueError(f"take-off position {init_pos_ecef_m!r}: must be three finite ECEF coordinates in "
                             "metres")
    st = RtkState(options=options, standstill=StandstillMonitor(window_s=options.standstill_window_s))
    layout = slot_layout(options.systems)
    if layout.n != NSAT or not layout.gps_only:
        n = layout.n
        st.layout, st.ns, st.nxi = layout, n, NX0 + n
        st.x, st.p = np.zeros(NX0 + n), np.zeros((NX0 + n, NX0 + n))
        for name in ("lock", "outage", "half_cycle", "prev_cp_r", "prev_dop_r", "prev_phase_r", "last_t_r_ns",
                     "prev_zb", "held_prns", "known_amb", "validated_int", "gap_int", "lineage_int", "pending_slip",
                     "prev_sat_clk_r", "prev_sat_ok_r"):
            old = getattr(st, name)
            setattr(st, name, np.full(n, old[0], old.dtype))
        st.prev_sat_pos_r = np.zeros((n, 3))
        st.code_scatter = CodeScatter(mean_m=np.full(n, np.nan), count=np.zeros(n))
        if "R" in layout.systems and options.glonass_code_bias_min_epochs > 0:
            st.channel_code_bias = ChannelCodeBias.empty(n)
    st.static = options.static_start
    st.init_pos_ecef_m = None if init_pos_ecef_m is None else np.asarray(init_pos_ecef_m, float)
    return st


def _slot_arrays(epochs: list[ObsEpoch]) -> tuple[Arr, Arr, Arr, npt.NDArray[np.uint8], Arr]:
    """The epochs' GPS pseudoranges (m), phases (cycles), Dopplers (Hz) (NaN where absent), LLI bits (0
    where absent) and C/N0 (dB-Hz, NaN where absent) on the 32 PRN slots, one row per epoch, scattered in one
    assignment each."""
    gps = [e.gps_only() for e in epochs]
    shape = (len(gps), NSAT)
    pr, cp, dop, cn0 = (np.full(shape, np.nan) for _ in range(4))
    lli = np.zeros(shape, np.uint8)
    if len(gps) == 1:  # one live epoch: no concatenation
        g = gps[0]
        at: tuple[npt.NDArray[np.int64] | int, npt.NDArray[np.int64]] = (0, g.sv_id.astype(int) - 1)
        pr[at], cp[at], dop[at], lli[at], cn0[at] = g.pr_m, g.cp_cyc, g.dop_hz, g.lli, g.cn0_dbhz
    elif gps:
        rows = np.repeat(np.arange(len(gps)), [len(g) for g in gps])
        at = (rows, np.concatenate([g.sv_id for g in gps]).astype(int) - 1)
        pr[at] = np.concatenate([g.pr_m for g in gps])
        cp[at] = np.concatenate([g.cp_cyc for g in gps])
        dop[at] = np.concatenate([g.dop_hz for g in gps])
        lli[at] = np.concatenate([g.lli for g in gps])
        cn0[at] = np.concatenate([g.cn0_dbhz for g in gps])
    screen_observations(pr, cp, dop, cn0)
    return pr, cp, dop, lli, cn0


def epoch_receivers(epochs: list[ObsEpoch], store: EphemerisStore, pos_ecef_m: Arr | None = None,
                    layout: SlotLayout = GPS_LAYOUT, broadcast: BroadcastNavigation | None = None
                    ) -> list[_Receiver]:
    """What _slots gives for each epoch (slot arrays, satellite states), for rtk_pos's `receivers` when the
    epochs are known ahead (post-processing): the scatter and satposs of every epoch in one batch.

    `pos_ecef_m`: the receiver's fixed, known position (the base), where every epoch's modelled range is then
    evaluated in one batch too (see _model_range_rows). Each receiver's arrays are rows of the batch's, its
    own (rtk_pos may blank a Doppler of its rover epoch)."""
    if not epochs:
        return []
    if layout.gps_only:
        pr, cp, dop, lli, cn0 = _slot_arrays(epochs)
        sats = satellite_states_batch(store, _PRNS, [e.time.total_ns for e in epochs], pr)
        has = np.isfinite(pr) & np.array([s.ok for s in sats])
        out = [_Receiver(pr[k], cp[k], dop[k], lli[k], sats[k], has[k], cn0_dbhz=cn0[k]) for k in range(len(epochs))]
    else:
        out = _layout_receivers(epochs, store, layout, broadcast)
    if pos_ecef_m is not None:
        _model_range_rows(out, np.asarray(pos_ecef_m, float))
    return out


def epoch_spp(epochs: list[ObsEpoch], rcvs: list[_Receiver], nav: NavData, o: RtkOptions) -> list[SppSolution]:
    """Single-point solutions of every epoch in one batch (pntpos_batch), for rtk_pos's `spp` when the epochs
    are known ahead (post-processing), from their receivers (epoch_receivers). All start from the first
    solvable epoch's solution, as rtk_pos starts each epoch's from the filter position: the same start for a
    receiver within kilometres (a survey site, a drone flight); the solution does not depend on it (sub-mm),
    the point where the atmosphere is evaluated moves by the rover's distance from it (re-evaluated past
    50 m)."""
    if not epochs:
        return []
    layout = slot_layout(o.systems)
    if layout.gps_only:
        prs = np.array([r.pr_m for r in rcvs])
        group = lam = None
        ng = 1
    else:  # a slot without usable data (a GLONASS one without its channel) is left out
        prs = np.array([np.where(r.has, r.pr_m, np.nan) for r in rcvs])
        group, ng = layout.group, len(layout.systems)
        lam = rcvs[0].lam if all(r.lam is rcvs[0].lam or np.array_equal(r.lam, rcvs[0].lam, equal_nan=True)
                                 for r in rcvs) else None
        if lam is None:  # the channels changed along the epochs: one batch per wavelength set
            return [epoch_spp([e], [r], nav, o)[0] for e, r in zip(epochs, rcvs, strict=True)]
    dops = np.array([r.dop_hz for r in rcvs])
    sats = [r.sats for r in rcvs]
    tows = np.array([e.time.tow_s for e in epochs])
    x0 = None
    for k in range(min(len(epochs), 10)):  # a start point: the first epoch with a cold-start solution
        first = pntpos_batch(prs[k:k + 1], sats[k:k + 1], tows[k:k + 1], o.elmask_rad, dops[k:k + 1], nav.iono,
                             outlier_m=o.spp_outlier_m, max_gdop=o.spp_max_gdop, clock_group=group, lam_m=lam)[0]
        if first.ok:
            x0 = np.tile(np.append(first.pos_ecef_m, [first.clock_bias_m] * ng), (len(epochs), 1))
            break
    return pntpos_batch(prs, sats, tows, o.elmask_rad, dops, nav.iono, x0=x0, outlier_m=o.spp_outlier_m,
                        max_gdop=o.spp_max_gdop, clock_group=group, lam_m=lam)


def _layout_receivers(epochs: list[ObsEpoch], store: EphemerisStore, layout: SlotLayout,
                      broadcast: BroadcastNavigation | None) -> list[_Receiver]:
    """epoch_receivers on a multi-constellation layout: slot arrays, satellite states, the slots' wavelengths
    (a GLONASS slot without a known frequency channel has no usable data)."""
    pr, cp, dop, lli, cn0 = slot_arrays(layout, epochs)
    sats = satellite_states_layout(layout, store, broadcast, [e.time.total_ns for e in epochs], pr)
    # a satellite's frequency channel does not change over a session: one wavelength array for all epochs
    lam = wavelengths(layout, epochs, broadcast)
    lam.flags.writeable = False
    out = []
    for k in range(len(epochs)):
        has = np.isfinite(pr[k]) & sats[k].ok & np.isfinite(lam)
        out.append(_Receiver(pr[k], cp[k], dop[k], lli[k], sats[k], has, lam, cn0[k]))
    return out


def _slots(obs: ObsEpoch, store: EphemerisStore, layout: SlotLayout = GPS_LAYOUT,
           broadcast: BroadcastNavigation | None = None) -> _Receiver:
    """Scatter an epoch onto the slots and compute satellite states at its own time tag (satposs): the
    real-time path's epoch_receivers of one epoch."""
    if not layout.gps_only:
        return _layout_receivers([obs], store, layout, broadcast)[0]
    pr, cp, dop, lli, cn0 = (a[0] for a in _slot_arrays([obs]))
    # straight onto the 32 slots: a batch of one leaves slots without a pseudorange zero and not ok
    sats = satellite_states_batch(store, _PRNS, [obs.time.total_ns], pr.reshape(1, NSAT))[0]
    return _Receiver(pr, cp, dop, lli, sats, np.isfinite(pr) & sats.ok, cn0_dbhz=cn0)


def _geometry(rcv: _Receiver, pos_ecef_m: Arr) -> tuple[Arr, Arr]:
    """geometric_range() of the receiver's satellites from `pos_ecef_m`: range with Sagnac, LOS (memoised)."""
    key = ("geo", pos_ecef_m.tobytes())
    hit = rcv.memo.get(key)
    if hit is None:
        # no errstate: empty slots hold zero satellite positions, whose range from a receiver off the Earth's
        # centre is finite (the context cost ~2 µs, three times per epoch; no FP warning on any real set, the
        # benchmarks and hil_sim run with numpy errors raising)
        hit = geometric_range(rcv.sats.pos_m, pos_ecef_m)
        for a in hit:
            a.flags.writeable = False
        rcv.memo[key] = hit
    return hit[0], hit[1]


def _model_range_m(rcv: _Receiver, pos_ecef_m: Arr) -> tuple[Arr, Arr, Arr, Arr]:
    """Modelled range (geometric + Sagnac − sat clock + dry/wet troposphere), LOS, az, el for every slot."""
    key = ("model", pos_ecef_m.tobytes())
    hit = rcv.memo.get(key)
    if hit is None:
        r, e = _geometry(rcv, pos_ecef_m)
        rng, az, el = _model_from_geometry(r, e, rcv.sats.clock_s, pos_ecef_m)
        hit = (rng, e, az, el)
        for a in hit:
            a.flags.writeable = False
        rcv.memo[key] = hit
    return hit[0], hit[1], hit[2], hit[3]


def _model_from_geometry(r: Arr, e: Arr, clock_s: Arr, pos_ecef_m: Arr) -> tuple[Arr, Arr, Arr]:
    """Modelled range (m), azimuth and elevation (rad) from geometric_range()'s range `r` and LOS `e` of the
    satellites seen from one position: one slot row (32,) / (32, 3), or several epochs' (k, 32) / (k, 32, 3)."""
    llh = ecef_to_llh(pos_ecef_m)
    az, el = sat_az_el(pos_ecef_m, e.reshape(-1, 3), llh)  # empty slots: finite LOS (see _geometry)
    az, el = az.reshape(r.shape), el.reshape(r.shape)
    lat, _, h = llh
    return r - CLIGHT_M_S * clock_s + saastamoinen_m(lat, h, el), az, el


def _model_range_rows(rcvs: list[_Receiver], pos_ecef_m: Arr) -> None:
    """Memoise _model_range_m (and _geometry) of every receiver at one fixed position (the base's) from a
    batch over all of them: the same operations per element as the per-epoch call, in array operations."""
    sat_pos = np.array([rc.sats.pos_m for rc in rcvs])
    with np.errstate(invalid="ignore", divide="ignore"):
        r, e = geometric_range(sat_pos, pos_ecef_m)
    model, az, el = _model_from_geometry(r, e, np.array([rc.sats.clock_s for rc in rcvs]), pos_ecef_m)
    for a in (r, e, model, az, el):
        a.flags.writeable = False  # and so every row
    pos_key = pos_ecef_m.tobytes()
    for k, rc in enumerate(rcvs):
        rc.memo[("geo", pos_key)] = (r[k], e[k])
        rc.memo[("model", pos_key)] = (model[k], e[k], az[k], el[k])


def _sd_obs_m(rov: _Receiver, bas: _Receiver) -> tuple[Arr, Arr]:
    """Single-differenced (rover − base) phase λ·(φ_r − φ_b) and code ρ_r − ρ_b (m) per slot, memoised on the
    rover epoch for its base epoch (the slip, standstill and code-scatter tests and every _ddres call of the
    epoch difference the same observations). Read-only."""
    key = ("sd_obs", id(bas))  # one base epoch per rover epoch, alive while it is processed
    hit = rov.memo.get(key)
    if hit is None:
        hit = (rov.lam * (rov.cp_cyc - bas.cp_cyc), rov.pr_m - bas.pr_m)
        for a in hit:
            a.flags.writeable = False
        rov.memo[key] = hit
    return hit[0], hit[1]


def _range_with_trop_m(rcv: _Receiver, pos_ecef_m: Arr, trop_m: Arr) -> tuple[Arr, Arr]:
    """As _model_range_m with the troposphere already evaluated this epoch (it changes negligibly with
    the millimetre-to-metre position updates inside one epoch): modelled range and LOS."""
    r, e = _geometry(rcv, pos_ecef_m)
    return r - CLIGHT_M_S * rcv.sats.clock_s + trop_m, e


def _solution(t: GpsTime, pos: Arr, vel: Arr, q: int, ns: int, cov: Arr, covv: Arr, age: float,
              ratio: float, fix_id: int = -1) -> Solution:
    return Solution(time=t, pos_ecef_m=np.array(pos, float), vel_ecef_m_s=np.array(vel, float), q=q, ns=ns,
                    cov_pos_m2=np.array(cov, float), cov_vel_m2_s2=np.array(covv, float), age_s=age,
                    ratio=min(ratio, RATIO_CAP), fix_id=fix_id)


def _in_use(st: RtkState, first: int = NX0) -> npt.NDArray[np.bool_]:
    """Per PRN slot, whether its state in the block starting at `first` (ambiguities at NX0, ionosphere at
    NXI) is in use: a state out of use has zero variance. A view-derived array, not a copy to keep."""
    return st.p.diagonal()[first:first + st.ns] > 0


def _reset_amb(st: RtkState, k: npt.NDArray[np.int64]) -> None:
    """Forget the ambiguities of slots `k` (they are re-initialised from phase − code when next seen)."""
    j = NX0 + np.asarray(k, int)
    st.x[j] = 0.0
    st.p[j, :] = 0.0
    st.p[:, j] = 0.0
    st.lock[k] = 0
    st.held_prns[k] = False
    st.known_amb[k] = False
    st.validated_int[k] = np.nan
    st.gap_int[k] = np.nan
    st.lineage_int[k] = np.nan


def _process_noise(st: RtkState, dt: float, pos: Arr) -> Arr:
    """Velocity random walk (white acceleration) noise for pos/vel over dt, ENU σ rotated to ECEF."""
    o = st.options
    lat, lon, _ = ecef_to_llh(pos)
    rot = enu_rotation(lat, lon)
    # Rᵀ·diag(σ²)·R with the diagonal product as a column scaling (the same numbers: one term per entry)
    sig2 = np.array([o.accel_h_sigma_m_s2**2, o.accel_h_sigma_m_s2**2, o.accel_v_sigma_m_s2**2])
    qa = (rot.T * sig2) @ rot
    adt = abs(dt)
    q = np.empty((NX0, NX0))
    q[:3, :3] = qa * adt**3 / 3.0
    q[:3, 3:] = q[3:, :3] = qa * dt * adt / 2.0  # negative when propagating backward in time
    q[3:, 3:] = qa * adt
    return q


@functools.lru_cache(maxsize=8)
def _transition(dt: float) -> Arr:
    """Constant-velocity transition matrix of pos/vel over dt (s), read-only (the epoch interval repeats)."""
    f = np.eye(NX0)
    f[:3, 3:] = np.eye(3) * dt
    f.flags.writeable = False
    return f


def _udstate(st: RtkState, dt: float, spp_pos: Arr, spp_vel: Arr, base_pos: Arr | None = None) -> None:
    """Time update of position/velocity (RTKLIB udpos with dynamics) and ambiguity noise (random walk,
    growing with the baseline to `base_pos` ECEF m, see RtkOptions.bias_process_noise_cyc_per_km)."""
    o = st.options
    if not st.initialized:
        st.x[:] = 0.0
        st.p[:] = 0.0
        if st.init_pos_ecef_m is not None:
            st.x[:3] = st.init_pos_ecef_m
            st.p[:3, :3] = np.eye(3) * o.init_pos_sigma_m**2
        else:
            st.x[:3] = spp_pos
            st.p[:3, :3] = np.eye(3) * o.initial_pos_sigma_m**2
        vel = spp_vel if np.all(np.isfinite(spp_vel)) else np.zeros(3)
        if st.static:
            vel = np.zeros(3)
        st.x[3:6] = vel
        st.p[3:6, 3:6] = np.eye(3) * (KNOWN_VEL_VAR_M2_S2 if st.static else o.initial_vel_sigma_m_s**2)
        st.initialized = True
        return
    f = _transition(dt)
    st.x[:NX0] = f @ st.x[:NX0]
    st.p[:NX0, :] = f @ st.p[:NX0, :]
    st.p[:, :NX0] = st.p[:, :NX0] @ f.T
    if not st.static:
        st.p[:NX0, :NX0] += _process_noise(st, dt, st.x[:3])
    # a filter that drifted far from the SPP solution is restarted on it (RTKLIB udpos's reset)
    if _norm(st.x[:3] - spp_pos) > SPP_RESET_DISTANCE_M or st.p[0, 0] > SPP_RESET_VAR_M2:
        log.info("position state reset to SPP (%.1f m off)", np.linalg.norm(st.x[:3] - spp_pos))
        st.x[:3] = spp_pos
        st.p[:3, :] = 0.0
        st.p[:, :3] = 0.0
        st.p[:3, :3] = np.eye(3) * o.initial_pos_sigma_m**2
    # with the ionosphere estimated (st.iono_on, last epoch's verdict) the per-km random walk is left to
    # geodetic code, which can follow the drift it stands for (see RtkOptions.iono_sigma_m_per_km)
    per_km = None if st.iono_on and not _geodetic_code(st) else base_pos
    nx = st.p.shape[0]
    amb_var = st.p.ravel()[NX0 * (nx + 1) : st.nxi * (nx + 1) : nx + 1]  # the ambiguities' variances, a view
    amb_var[amb_var > 0] += bias_process_noise_cyc2_s(o, st.x[:3], per_km) * abs(dt)


def _watch_standstill(st: RtkState, ctx: EpochContext, valid: npt.NDArray[np.bool_]) -> int:
    """Start or end the static hold from the time-differenced phase displacement (see onboard.rtk.standstill),
    after this epoch's time update: motion re-opens the position at once, before the measurement update.
    Held static and not moving by Doppler, a failed test that one satellite's slip explains restarts that
    satellite's ambiguity instead (a slip too small for the Doppler test before a fix is held, e.g. 1 cycle
    against its 2): the slot is returned, −1 for none."""
    o = st.options
    rov, bas, t, dt = ctx.rov, ctx.bas, ctx.time, ctx.dt_s
    assert bas is not None
    sd = _sd_obs_m(rov, bas)[0] - (ctx.rng_r - ctx.rng_b)
    var = _var_sd_m2(o, rov, ctx.el)
    t_ns = t.total_ns
    disp = st.standstill.update(t_ns, sd, st.x[:3], ctx.los_r, var, st.lock, valid,
                                exclude_one=st.static and not ctx.moving)
    slipped = st.standstill.slipped_slot
    if slipped >= 0:
        log.info("%s: %s slipped while standing (%.2f m over %.0f s without it): its ambiguity restarts", t,
                 st.layout.letter(slipped), float(np.linalg.norm(disp.d_m)) if disp is not None else float("nan"),
                 disp.span_s if disp is not None else 0.0)
        _reset_amb(st, np.array([slipped]))
        st.slips += 1
    if st.static:
        if disp is not None and st.standstill.still_since_ns is None:
            log.info("%s: motion detected (%.3f m over %.0f s, χ² %.0f), leaving static mode", t,
                     float(np.linalg.norm(disp.d_m)), disp.span_s, disp.chi2)
            _leave_static(st, dt)
    elif (o.standstill and disp is not None and disp.sigma_m <= o.standstill_max_sigma_m
          and st.standstill.still_for_s(t_ns) >= o.standstill_min_s):
        log.info("%s: standstill for %.0f s, static hold", t, st.standstill.still_for_s(t_ns))
        st.static = True
        # zero-velocity update: the velocity is known now, and stays so without process noise
        h = np.zeros((3, st.x.size))
        h[:, 3:6] = np.eye(3)
        st.x, st.p = _kf_update(st.x, st.p, -st.x[3:6], h, np.eye(3) * KNOWN_VEL_VAR_M2_S2)
    return slipped


def _leave_static(st: RtkState, dt: float) -> None:
    """End the static hold: the velocity unknown again, the position given this epoch's process noise."""
    o = st.options
    st.static = False
    st.p[3:6, :] = 0.0
    st.p[:, 3:6] = 0.0
    st.p[3:6, 3:6] = np.eye(3) * o.initial_vel_sigma_m_s**2
    st.p[:NX0, :NX0] += _process_noise(st, dt, st.x[:3])


def bias_process_noise_cyc2_s(o: RtkOptions, rover_pos: Arr, base_pos: Arr | None) -> float:
    """Spectral density (cycles²/s) of the SD ambiguity random walk: a floor plus a part proportional to the
    baseline (km), which stands for the differential ionosphere/troposphere drifting the L1 phase over minutes
    (RTKLIB udion scales its ionosphere process noise with the baseline the same way); the floor alone
    without `base_pos` (and while the ionosphere states are estimated)."""
    q = o.bias_process_noise_cyc**2
    if base_pos is None or o.bias_process_noise_cyc_per_km <= 0.0:
        return q
    bl_km = _norm(np.asarray(rover_pos, float) - np.asarray(base_pos, float)) / 1000.0
    return q + (o.bias_process_noise_cyc_per_km * bl_km) ** 2


def _detect_slips(st: RtkState, rov: _Receiver, base: _Receiver, base_zb: Arr, t_r: GpsTime,
                  t_b: GpsTime, common: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """Cycle-slip flags per slot: LLI (RTKLIB detslp_ll), Doppler-predicted rover phase (detslp_dop,
    clock-common part removed), and the base's geometry residual (static known base: phase − range
    jumps between its epochs, clock-common part removed)."""
    slip = _rover_slips(st, rov, t_r, common) | (((base.lli & LLI_SLIP) != 0) & common)
    # base: phase − geometric range (known static base), differenced in time
    if st.prev_time_b is not None and t_b != st.prev_time_b:
        dtb = abs(t_b.diff_s(st.prev_time_b))
        if dtb <= SLIP_TEST_MAX_GAP_S:
            d = base_zb - st.prev_zb
            ok = np.isfinite(d) & common
            if np.count_nonzero(ok) >= 3:
                d = d - median_of_few(d[ok])
                # cycles: atmosphere/orbit changes grow with the gap (see BASE_SLIP_CYC)
                thr = BASE_SLIP_CYC + BASE_SLIP_CYC_PER_S * dtb
                slip |= ok & (np.abs(d) > thr)
    return slip


def _rover_slips(st: RtkState, rov: _Receiver, t_r: GpsTime, common: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """Rover-side slip flags among `common` slots: LLI, Doppler-predicted phase from each satellite's last
    phase, and phase gaps the Doppler cannot bridge. Needs no base data (also run while the base is missing)."""
    o = st.options
    slip = ((rov.lli & LLI_SLIP) != 0) & common
    # Doppler-predicted phase on the rover, from each satellite's last phase (across short gaps)
    bridged = np.zeros(st.ns, bool)  # phase continuity checked against the Doppler
    if st.prev_time_r is not None:
        seen = st.last_t_r_ns != _NO_TIME_NS
        dt_all = np.where(seen, (t_r.total_ns - np.where(seen, st.last_t_r_ns, 0)) / 1e9, np.nan)
        if np.count_nonzero(np.isfinite(dt_all)):
            dop_avg = np.where(np.isfinite(st.prev_dop_r), 0.5 * (rov.dop_hz + st.prev_dop_r), rov.dop_hz)
            d = (rov.cp_cyc - st.prev_cp_r) + dop_avg * dt_all  # RINEX: phase follows range, Doppler = −rate
            if not st.layout.gps_only:
                # in GPS L1 cycles: the receiver clock, removed below, is common in metres, not in cycles
                d = d * lambda_ratio_to_gps(rov.lam)
            d[~(np.abs(dt_all) <= SLIP_TEST_MAX_GAP_S)] = np.nan
            ok = np.isfinite(d) & common
            if np.count_nonzero(ok) >= 2:
                # the receiver-clock part is common to all satellites: take it from those not flagged,
                # a burst of flagged slips would otherwise corrupt it
                # the clock part grows with the time since each satellite's last phase (a drift the
                # Doppler holds and the phase does not): removed as a rate, so a satellite back from a gap
                # is compared over its own interval
                clean = ok & ~slip
                rate = d / np.where(ok, dt_all, 1.0)
                d = d - median_of_few(rate[clean] if np.count_nonzero(clean) >= 2 else rate[ok]) * dt_all
                # a held set absorbs a missed slip (wrong fixes): tighter then; before a fix a false alarm
                # only restarts a float
                held = np.count_nonzero(st.held_prns) > 0
                thr_cyc = o.slip_threshold_held_cyc if held else o.slip_threshold_cyc
                if held and np.count_nonzero(clean) >= 5 and o.slip_outlier_factor > 0:
                    # a quiet epoch (the Doppler follows every other satellite's phase closely) shows a slip
                    # well under the fixed threshold: a robust spread of the others sets a lower one
                    spread = MAD_TO_SIGMA * median_of_few(np.abs(d[clean]))
                    thr_cyc = min(thr_cyc, max(o.slip_threshold_min_cyc, o.slip_outlier_factor * spread))
                thr = thr_cyc * np.maximum(1.0, np.abs(dt_all))  # NaN (never seen) only where not ok
                by_doppler = ok & (np.abs(d) > thr)
                if held and o.tdcp_slip_test:
                    # where the phase itself decides (six satellites the Doppler clears, or more), the Doppler's
                    # motion-blind verdict gives way: its suspects are judged against the others' fit
                    tested, by_phase = _tdcp_slips(st, rov, t_r, common & ~slip, by_doppler,
                                                   o.tdcp_slip_threshold_cyc)
                    by_doppler = np.where(tested, by_phase, by_doppler)
                elif not held and o.tdcp_float_slip_threshold_cyc > 0:
                    # before a fix the phase test only adds the whole-cycle slips under the Doppler's threshold
                    # (a float that absorbs one fits no integer set for minutes); the Doppler's false alarms
                    # stay, since clearing them exposed wrong first fixes (docs/rtk-defaults.md)
                    tested, by_phase = _tdcp_slips(st, rov, t_r, common & ~slip, by_doppler,
                                                   o.tdcp_float_slip_threshold_cyc)
                    by_doppler |= tested & by_phase
                slip |= by_doppler
                bridged = ok
        # a phase gap the Doppler could not bridge: receivers do not always flag a loss of lock inside the
        # gap (the Septentrio rover of GEONET 3034 comes back a whole cycle off with LLI 0), so the continuity
        # of such phase is unknown and its ambiguity starts afresh
        amb_on = _in_use(st)
        slip |= common & ~st.prev_phase_r & amb_on & ~bridged
    return slip



def _remember_base(st: RtkState, base: _Receiver, t_b: GpsTime, base_zb_cyc: Arr) -> None:
    """Add a new base epoch to the correction history (forward time only; a base slip voids the slot's past)."""
    o = st.options
    hist = st.base_hist
    if hist and (t_b <= hist[-1][0] or t_b.diff_s(hist[-1][0]) > o.max_age_s):
        hist.clear()  # backward processing or a long outage: start a new history
    zb = base_zb_cyc.copy()
    if hist:
        t_l, z_l = hist[-1]
        dtb = t_b.diff_s(t_l)
        d = zb - z_l
        ok = np.isfinite(d)
        jump = ((base.lli & LLI_SLIP) != 0) & np.isfinite(zb)
        if np.count_nonzero(ok) >= 3:
            d = d - median_of_few(d[ok])  # the base clock is common to every satellite
            jump |= ok & (np.abs(d) > BASE_HISTORY_JUMP_CYC + BASE_SLIP_CYC_PER_S * dtb)
        for _t, z in hist:
            z[jump] = np.nan
    hist.append((t_b, zb))
    while len(hist) > 1 and t_b.diff_s(hist[0][0]) > o.base_rate_window_s:
        hist.pop(0)


def _extrapolated_base(st: RtkState, base: _Receiver, age_s: float) -> _Receiver:
    """Base phase carried forward over `age_s` (rover − base time, s) along each satellite's correction rate.

    During a radio gap the rover's epochs are differenced with the last base epoch: the geometry is evaluated
    at each receiver's own time and the base clock cancels, but what the base observes and the model does
    not (ionosphere, satellite clock and orbit errors) changes with the age: centimetres to decimetres over
    20 s at low elevation. Its rate, measured on the base's own phase − modelled range over
    the last `base_rate_window_s` (the common base-clock drift removed), carries it forward as RTCM 2's
    range-rate corrections did. Slots without a clean history keep the raw phase.
    """
    o = st.options
    hist = st.base_hist
    if age_s <= 0.0 or len(hist) < 3:
        return base
    held = o.base_rate_skill_min < 1.0 and bool(st.held_prns.any())
    if age_s < o.base_extrapolate_min_age_s and not held:
        return base
    # the rate depends on the history alone, which changes only with a new base epoch: the rover epochs of one
    # base epoch (a radio gap) share it, memoised on that base epoch's receiver
    key = ("rate", len(hist), hist[0][0].total_ns, hist[-1][0].total_ns)
    rate = base.memo.get(key)
    if rate is None:
        rate = base.memo[key] = _correction_rate(o, hist, base.cp_cyc)
    if not rate:
        return base
    ok, slope, skill = rate
    early = held & (skill >= o.base_rate_skill_min)
    if age_s < o.base_extrapolate_min_age_s and not early.any():
        return base
    cp = base.cp_cyc.copy()
    # from the age where carrying starts, so the correction does not jump when it starts (a jump of rate ×
    # min age released a good hold on the M8P RAWX base); the drift before that stays, as for raw data. Under a
    # hold, a rate that predicted the base's own last seconds is carried from the gap's start (base_rate_skill_min)
    step = np.where(early, slope * age_s, slope * max(age_s - o.base_extrapolate_min_age_s, 0.0))
    # the history is in GPS L1 cycles (see _udbias_epoch): each slot's own
    cp[ok] += step if st.layout.gps_only else step / lambda_ratio_to_gps(base.lam)[ok]
    return _Receiver(base.pr_m, cp, base.dop_hz, base.lli, base.sats, base.has, base.lam, base.cn0_dbhz)


def _correction_rate(o: RtkOptions, hist: list[tuple[GpsTime, Arr]], base_cp_cyc: Arr) -> tuple[Arr, ...]:
    """(slots, their rate in cycles/s, its skill) of the base's phase − modelled range over the history `hist`
    (see _extrapolated_base), the common base-clock drift removed; () when the history cannot tell (too short,
    too few clean slots). The skill (per slot, ≤ 1; −inf where the history is too short to tell) is
    1 − SSE(line)/SSE(hold) of the base's last base_extrapolate_min_age_s seconds against the straight line
    fitted to the epochs before them, and against holding the last of those: near 1 for an atmosphere drifting
    steadily, 0 or less for multipath that does not continue its trend."""
    t_n = hist[-1][0]
    tk = np.array([t.diff_s(t_n) for t, _ in hist])  # ≤ 0, newest last
    if -tk[0] < 0.5 * o.base_rate_window_s:
        return ()
    z = np.array([zk for _, zk in hist]) - hist[-1][1]  # relative to the newest epoch
    fin = np.isfinite(z)
    keep = fin.sum(axis=1) >= 3
    if np.count_nonzero(keep) < 3:
        return ()
    z, tk = z[keep], tk[keep]
    if -tk[0] < 0.5 * o.base_rate_window_s:
        return ()
    z = z - np.array([median_of_few(row[np.isfinite(row)]) for row in z])[:, None]  # the base clock, common
    ok = np.all(np.isfinite(z), axis=0) & np.isfinite(base_cp_cyc)
    if np.count_nonzero(ok) < 2:
        return ()
    # least-squares slope over the window (a quadratic amplifies a u-blox base's noise: docs/rtk-defaults.md)
    slope, _ = _line_fit(z[:, ok], tk)
    skill = _rate_skill(z[:, ok], tk, o.base_extrapolate_min_age_s)
    for a in (ok, slope, skill):
        a.flags.writeable = False
    return ok, slope, skill


def _line_fit(z: Arr, tk: Arr) -> tuple[Arr, Arr]:
    """Least-squares straight line through each column of `z` (epochs × slots) over the times `tk` (s): its
    slope (per s) and its value at the mean time."""
    tc = tk - tk.mean()
    z_mean = z.mean(axis=0)
    return tc @ (z - z_mean) / (tc @ tc), z_mean


def _rate_skill(z: Arr, tk: Arr, recent_s: float) -> Arr:
    """Per column of `z` (epochs × slots, at times `tk` s, newest last): 1 − SSE(line)/SSE(hold) over the epochs
    of the last `recent_s` seconds, the line fitted to the epochs before them and the hold their last value;
    −inf per column when fewer than 3 epochs precede or fewer than 2 follow."""
    older = tk <= tk[-1] - recent_s
    if np.count_nonzero(older) < 3 or np.count_nonzero(~older) < 2:
        return np.full(z.shape[1], -np.inf)
    zo, to = z[older], tk[older]
    slope, zo_mean = _line_fit(zo, to)
    zn = z[~older]
    sse_line = ((zn - zo_mean - np.outer(tk[~older] - to.mean(), slope)) ** 2).sum(axis=0)
    sse_hold = ((zn - zo[-1]) ** 2).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sse_hold > 0.0, 1.0 - sse_line / sse_hold, -np.inf)


def _tdcp_slips(st: RtkState, rov: _Receiver, t_r: GpsTime, usable: npt.NDArray[np.bool_],
                suspects: npt.NDArray[np.bool_], threshold_cyc: float
                ) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """(slots the time-differenced phase test judged, their slip flags): the phase change since the previous
    rover epoch of each `usable` slot seen there, against its satellite's motion and clock from the ephemeris
    (onboard.rtk.tdcp_slips; `suspects` judged against the others' fit). Nothing judged when the test cannot
    decide."""
    none = np.zeros(st.ns, bool)
    prev = st.prev_time_r
    if prev is None or abs(t_r.diff_s(prev)) > SLIP_TEST_MAX_GAP_S:
        return none, none
    k = usable & (st.last_t_r_ns == prev.total_ns) & rov.sats.ok & st.prev_sat_ok_r & np.isfinite(rov.cp_cyc)
    if np.count_nonzero(k) < TDCP_MIN_SATS:
        return none, none
    # both epochs' ranges from one receiver position: the receiver's displacement is one of the unknowns
    pos = st.x[:3]
    r_now, los = _geometry(rov, pos)
    j = k.nonzero()[0]
    y = np.full(st.ns, np.nan)
    r_prev = geometric_range(st.prev_sat_pos_r[j], pos)[0]
    y[j] = rov.lam[j] * (rov.cp_cyc[j] - st.prev_cp_r[j]) - (r_now[j] - r_prev) \
        + CLIGHT_M_S * (rov.sats.clock_s[j] - st.prev_sat_clk_r[j])
    flags = tdcp_slips(y, los, rov.lam, k, threshold_cyc, suspects)
    if flags is None:
        return none, none
    return k, flags


def _remember_rover(st: RtkState, rov: _Receiver, t_r: GpsTime) -> None:
    """Keep this rover epoch's phase/Doppler (and the satellites' positions and clocks, for the time-differenced
    phase test) for the next epoch's slip tests."""
    have = np.isfinite(rov.cp_cyc) & np.isfinite(rov.dop_hz)
    st.prev_cp_r[have] = rov.cp_cyc[have]
    st.prev_dop_r[have] = rov.dop_hz[have]
    st.prev_sat_pos_r[have] = rov.sats.pos_m[have]
    st.prev_sat_clk_r[have] = rov.sats.clock_s[have]
    st.prev_sat_ok_r[have] = rov.sats.ok[have]
    st.last_t_r_ns[have] = t_r.total_ns
    st.prev_time_r = t_r
    st.prev_phase_r = np.isfinite(rov.cp_cyc)


def _udbias(st: RtkState, rov: _Receiver, base: _Receiver, rng_r: Arr, rng_b: Arr,
            valid_phase: npt.NDArray[np.bool_], slip: npt.NDArray[np.bool_], count_lock: bool = True,
            t_r: GpsTime | None = None) -> None:
    """Ambiguity bookkeeping (RTKLIB udbias): reset on slip or long outage, initialise new ones.

    `t_r` the rover epoch (its Doppler bridges the half-cycle step test below; None skips that test).
    New SD ambiguities come from phase − code; with a known rover position (take-off point) from phase −
    modelled range instead (Daakir et al. 2015 eq. 2), which lets the first epoch fix.
    """
    o = st.options
    if count_lock:
        st.outage[~valid_phase] += 1
        # the half-cycle (parity unknown) flag clearing on the rover: a receiver that resolves the half cycle by
        # moving the phase ½ cycle and reports no slip (RXM-RAW has no half-cycle-subtracted bit; RAWX data
        # carry one, which the decoder turns into a slip as RTKLIB does) corrupts the held set with that step.
        # RTKLIB detslp_ll declares a slip at every change of the flag; here only a step the Doppler sees (phase
        # change minus the Doppler-predicted one, receiver clock removed, over HALF_CYCLE_STEP_CYC) is one:
        # receivers also clear the flag without a step (docs/rtk-defaults.md).
        half = (rov.lli & LLI_HALF_CYCLE) != 0
        cleared = valid_phase & st.half_cycle & ~half
        st.half_cycle = half & valid_phase
        if np.count_nonzero(cleared) and st.prev_time_r is not None and t_r is not None:
            dt_r = t_r.diff_s(st.prev_time_r)
            step = (rov.cp_cyc - st.prev_cp_r) + 0.5 * (rov.dop_hz + st.prev_dop_r) * dt_r
            ok = np.isfinite(step) & valid_phase
            if ok.sum() >= 3 and 0.0 < dt_r <= HALF_CYCLE_MAX_GAP_S:
                step = step - median_of_few(step[ok & ~cleared] if (ok & ~cleared).sum() >= 2 else step[ok])
                slip = slip | (cleared & ok & (np.abs(step) > HALF_CYCLE_STEP_CYC))
    lost = (st.outage > o.max_outage_epochs) & _in_use(st)
    reset = (lost | (slip & valid_phase)).nonzero()[0]
    if reset.size:
        st.slips += int(np.count_nonzero(slip & valid_phase))
        _reset_amb(st, reset)
    st.outage[valid_phase] = 0
    new = valid_phase & ~_in_use(st)
    if np.count_nonzero(new):
        lam = rov.lam
        if st.init_pos_ecef_m is not None and st.fix_count == 0 and st.p[0, 0] <= (2 * o.init_pos_sigma_m) ** 2:
            sd = (lam * (rov.cp_cyc - base.cp_cyc) - (rng_r - rng_b)) / lam
            # phase − modelled range keeps the receivers' clock difference (0.5 ms = 150 km on hil_sim), which
            # phase − code removes: take it out (the median over satellites of code − range, common to all, so
            # the double differences keep the surveyed precision), or a satellite re-initialised from code
            # after a slip never fits the others again
            clk = (rov.pr_m - base.pr_m) - (rng_r - rng_b)
            if np.any(new & np.isfinite(clk)):
                sd = sd - median_of_few(clk[new & np.isfinite(clk)]) / lam
            var = (KNOWN_AMB_SIGMA_CYC + o.init_pos_sigma_m / lam) ** 2
            st.known_amb[new] = True
        else:
            sd = (lam * (rov.cp_cyc - base.cp_cyc) - (rov.pr_m - base.pr_m)) / lam
            var = o.initial_bias_sigma_cyc**2
        k = new.nonzero()[0]
        st.x[NX0 + k] = sd[k]
        st.p[NX0 + k, NX0 + k] = var[k] if np.ndim(var) else var
    if count_lock:
        st.lock[valid_phase] += 1
        st.lock[~valid_phase] = 0


def static_code_factor(o: RtkOptions, static: bool, dt_s: float) -> float:
    """Factor on the code variance of an epoch of a rover held static, `dt_s` after the previous one: the
    epochs per code-multipath correlation time (static_code_correlation_s / |dt_s|, ≥ 1); 1 when moving.

    A static antenna's code multipath repeats itself for tens of seconds; weighting every epoch as independent
    code makes the float as confident after 60 s on the ground as after 60 independent samples, when it holds
    a few. Moving, the multipath decorrelates within seconds and the code keeps its weight."""
    if not static or dt_s == 0.0 or o.static_code_correlation_s <= 0.0:
        return 1.0
    return max(1.0, o.static_code_correlation_s / abs(dt_s))  # processed backward, dt < 0


def code_variance_scale(st: RtkState, rov: _Receiver, base: _Receiver, phase_ok: npt.NDArray[np.bool_],
                        slip: npt.NDArray[np.bool_], el: Arr, dt: float) -> float:
    """Factor (≤ 1) on the modelled code variance, from the single-differenced code-minus-carrier scatter.

    `code_phase_ratio` is set for u-blox code, whose multipath is correlated over tens of seconds; geodetic
    receivers (GEONET Trimble, Septentrio) scatter an order of magnitude less, and weighting their code as
    u-blox code leaves the float to the slow geometry change of the phase, which centimetres of differential
    ionosphere or multipath bias by decimetres. Receivers scattering less than `code_scatter_reference` get
    proportionally less code variance, never below `code_variance_min_scale`.
    """
    o = st.options
    sd_phase, sd_code = _sd_obs_m(rov, base)
    cmc = sd_code - sd_phase
    ok = phase_ok & np.isfinite(cmc)
    var_code = _var_sd_m2(o, rov, el) * o.code_phase_ratio**2
    st.code_scatter.update(np.where(ok, cmc, 0.0), var_code, ok, slip, dt)
    cs = st.code_scatter
    if o.code_scatter_reference <= 0.0 or cs.epochs < o.code_scatter_min_epochs or not np.isfinite(cs.ratio):
        return 1.0
    return float(min(max(cs.ratio / o.code_scatter_reference, o.code_variance_min_scale), 1.0))


def _slant_iono_m(st: RtkState, x: Arr, el: Arr, lam: Arr | None = None) -> tuple[Arr, Arr]:
    """(slant SD ionospheric delay (m) per slot at state `x`, the mapping function): 0 where no state. The
    states are the delays at GPS L1: a slot on another carrier (wavelength `lam`, m) scales them by
    (f_L1 / f)², which the mapping returned includes."""
    mf = iono_mapping(el)
    if lam is not None and not st.layout.gps_only:
        mf = mf * lambda_ratio_to_gps(lam) ** 2
    return mf * x[st.nxi:st.nxi + st.ns], mf


def _geodetic_code(st: RtkState) -> bool:
    """The code has been measured far cleaner than u-blox code (code_variance_scale < 0.5, the threshold of
    confirm_fix_span_per_km_s)."""
    return st.code_scatter.epochs >= st.options.code_scatter_min_epochs and st.code_var_scale < GEODETIC_CODE_SCALE


def _ublox_code(st: RtkState) -> bool:
    """The code has been measured u-blox-like (code_variance_scale ≥ 0.5; the other side of _geodetic_code)."""
    return st.code_scatter.epochs >= st.options.code_scatter_min_epochs and st.code_var_scale >= GEODETIC_CODE_SCALE


def _drop_iono(st: RtkState, drop: npt.NDArray[np.bool_], el: Arr, lam: Arr | None = None) -> None:
    """Remove the ionosphere states of the `drop` slots, folding each into its ambiguity where both exist
    (N' = N − m(el)·I/λ, the phase then carries the delay as without the states), so that the ambiguities keep
    the ionosphere's estimate and uncertainty instead of losing them."""
    nxi = st.nxi
    k = (drop & _in_use(st, nxi)).nonzero()[0]
    if k.size == 0:
        return
    fold = k[(st.p[NX0 + k, NX0 + k] > 0) & np.isfinite(el[k])]
    if fold.size:
        a = np.eye(st.x.size)
        if lam is None or st.layout.gps_only:
            a[NX0 + fold, nxi + fold] = -iono_mapping(el[fold]) / LAMBDA_L1_M
        else:
            a[NX0 + fold, nxi + fold] = -_slant_iono_m(st, st.x, el, lam)[1][fold] / lam[fold]
        st.x = a @ st.x
        st.p = a @ st.p @ a.T
    j = nxi + k
    st.x[j] = 0.0
    st.p[j, :] = 0.0
    st.p[:, j] = 0.0


def _udion(st: RtkState, seen: npt.NDArray[np.bool_], base_pos: Arr, dt: float, el: Arr,
           lam: Arr | None = None) -> None:
    """Time update of the SD ionosphere states (RTKLIB udion): on long baselines only, started at 0 with a
    prior σ growing with the baseline for every satellite `seen` (its code used), a random walk likewise,
    dropped after max_outage_epochs without phase. They exist between iono_min_baseline_km and
    iono_max_baseline_km (dropped below 3/4 of the first, above 1.1 times the second; the state arrays grow
    from NXI to NX for them and shrink back); see _drop_iono. `el` the
    satellites' elevations (rad) this epoch."""
    o = st.options
    bl_km = _norm(st.x[:3] - base_pos) / 1000.0
    # a little hysteresis: a rover flying about a threshold does not drop and restart them every few seconds
    lo, hi = (0.75 * o.iono_min_baseline_km, 1.1 * o.iono_max_baseline_km) if st.iono_on else \
        (o.iono_min_baseline_km, o.iono_max_baseline_km)
    on = o.iono_sigma_m_per_km > 0.0 and lo <= bl_km <= hi
    if not on:
        if st.iono_on:
            _drop_iono(st, np.ones(st.ns, bool), el, lam)
            st.x, st.p = st.x[:st.nxi].copy(), st.p[:st.nxi, :st.nxi].copy()
        st.iono_on = False
        return
    if not st.iono_on:
        nx, nxi = st.nxi + st.ns, st.nxi
        x, p = np.zeros(nx), np.zeros((nx, nx))
        x[:nxi], p[:nxi, :nxi] = st.x, st.p
        st.x, st.p = x, p
    st.iono_on = True
    j = st.nxi + np.arange(st.ns)
    active = _in_use(st, st.nxi)
    lost = active & (st.outage > o.max_outage_epochs)
    if lost.any():
        _drop_iono(st, lost, el, lam)
        active &= ~lost
    if active.any() and o.iono_process_noise_m_per_km > 0.0:
        st.p[j[active], j[active]] += (o.iono_process_noise_m_per_km * bl_km) ** 2 * abs(dt)
    new = seen & ~active
    if new.any():
        k = j[new]
        st.x[k] = 0.0
        st.p[k, k] = (o.iono_sigma_m_per_km * bl_km) ** 2


def _dd_ambiguities(x: Arr, p: Arr, idx: npt.NDArray[np.int64], ref: int) -> tuple[Arr, Arr, Arr, Arr | None]:
    """Double-difference ambiguities (slot i − `ref` for every other slot of `idx`, in slot order) of the state
    (x, p): their values a = D·x (cycles), covariance Qa = (D·P)·Dᵀ, cross-covariance with the position P·Dᵀ
    (3, n) and, while the ionosphere states are in use, with them (32, n), else None.

    D's rows hold one +1 and one −1 (RTKLIB's DD matrix): index arithmetic instead of the dense products, the
    same numbers to the bit (each entry of those products is one difference; the other terms add exact zeros).
    """
    jo = NX0 + idx[idx != ref]
    jr = NX0 + ref
    a = x.take(jo) - x[jr]
    p_o = p.take(jo, 0)  # rows of the other ambiguities
    qa = (p_o.take(jo, 1) - p[jr].take(jo)) - (p_o[:, jr] - p[jr, jr])[:, None]
    qba = p[:3].take(jo, 1) - p[:3, jr][:, None]
    qia = p[NXI:NX].take(jo, 1) - p[NXI:NX, jr][:, None] if p.shape[0] == NX else None
    return a, qa, qba, qia


def _dd_ambiguities_multi(x: Arr, p: Arr, others: npt.NDArray[np.int64], refs: npt.NDArray[np.int64], nsat: int
                          ) -> tuple[Arr, Arr, Arr, Arr | None]:
    """_dd_ambiguities with a reference per row (`refs`, one per constellation): rows `others` − `refs`; `nsat`
    the number of slots (the ionosphere block, when present, follows the ambiguities)."""
    jo, jr = NX0 + others, NX0 + refs
    a = x.take(jo) - x.take(jr)
    p_o, p_r = p.take(jo, 0), p.take(jr, 0)
    qa = (p_o.take(jo, 1) - p_r.take(jo, 1)) - (p_o.take(jr, 1) - p_r.take(jr, 1))
    qba = p[:3].take(jo, 1) - p[:3].take(jr, 1)
    nxi = NX0 + nsat
    qia = p[nxi:nxi + nsat].take(jo, 1) - p[nxi:nxi + nsat].take(jr, 1) if p.shape[0] == nxi + nsat else None
    return a, qa, qba, qia


def _dd_ambiguities_of(st: RtkState, idx: npt.NDArray[np.int64], others: npt.NDArray[np.int64],
                       refs: npt.NDArray[np.int64]) -> tuple[Arr, Arr, Arr, Arr | None]:
    """The filter state's DD ambiguities of slots `idx` paired as (`others`, `refs`) (_dd_pairs): _dd_ambiguities
    with GPS alone (one reference), else _dd_ambiguities_multi."""
    if st.layout.gps_only:
        return _dd_ambiguities(st.x, st.p, idx, int(refs[0]))
    return _dd_ambiguities_multi(st.x, st.p, others, refs, st.ns)


def _conditioned_on(st: RtkState, a: Arr, qa: Arr, qba: Arr, qia: Arr | None, ints: Arr
                    ) -> tuple[Arr, Arr, Arr | None] | None:
    """The float conditioned on integers `ints` of its DD ambiguities (a, Qa and the cross-covariances Qba, Qia
    of _dd_ambiguities): position (ECEF m), its covariance (m²) and, while in use, the ionosphere states (m);
    None when Qa is singular."""
    try:
        gain = solve(qa, qba.T).T
    except LinAlgError:
        return None
    pos = st.x[:3] - gain @ (a - ints)
    cov = st.p[:3, :3] - gain @ qba.T
    iono = None
    if st.iono_on and qia is not None:
        iono = st.x[st.nxi:st.nxi + st.ns] - qia @ solve(qa, a - ints)
    return pos, cov, iono


def _dd_ambiguities_without(dd: tuple[Arr, Arr, Arr, Arr | None], k: int) -> tuple[Arr, Arr, Arr, Arr | None]:
    """_dd_ambiguities' result for the same reference with the `k`-th other slot left out: its entries are
    each one difference of the state's, so a principal subset of the larger set's, to the bit."""
    a, qa, qba, qia = dd
    keep = np.ones(a.size, bool)
    keep[k] = False
    return (a[keep], qa.compress(keep, 0).compress(keep, 1), qba.compress(keep, 1),
            None if qia is None else qia.compress(keep, 1))


@dataclass
class _DD:
    """Double-difference system of one epoch: innovations v, design H (on the full state), covariance R."""

    v: Arr
    h: Arr
    r: Arr
    kind: npt.NDArray[np.int8]  # 0 phase, 1 code, 2 doppler
    slot: npt.NDArray[np.int64]  # the non-reference satellite of each row
    ref_phase: int


def _var_sd_m2(o: RtkOptions, rov: _Receiver, el: Arr) -> Arr:
    """Single-difference phase variance (m²) per slot, 2·phase_variance_m2(el), memoised on the rover epoch:
    the same elevations serve the code scatter, the standstill test and every _ddres call of the epoch.
    Read-only."""
    key = ("var_sd", el.tobytes())
    hit = rov.memo.get(key)
    if hit is None:
        var_sd = 2.0 * phase_variance_m2(el, o.phase_sigma_a_m, o.phase_sigma_b_m)
        var_sd.flags.writeable = False
        hit = rov.memo[key] = (var_sd,)
    return hit[0]


def _code_cn0_factor(cn0_ref_dbhz: float, rov: _Receiver, bas: _Receiver) -> Arr:
    """Factor on each slot's SD code variance for a weak signal: the mean over the two receivers of
    max(1, 10^((cn0_ref_dbhz − C/N0)/10)), 1 for a receiver whose C/N0 is unknown (code_cn0_ref_dbhz).
    Memoised on the rover epoch for its base epoch. Read-only."""
    key = ("cn0", id(bas), cn0_ref_dbhz)
    hit = rov.memo.get(key)
    if hit is None:
        f = (_cn0_inflation(cn0_ref_dbhz, rov.cn0_dbhz, rov.pr_m.shape[0])
             + _cn0_inflation(cn0_ref_dbhz, bas.cn0_dbhz, rov.pr_m.shape[0])) / 2.0
        f.flags.writeable = False
        hit = rov.memo[key] = (f,)
    return hit[0]


def _weak_signals(cn0_ref_dbhz: float, cn0_dbhz: Arr | None, n: int) -> npt.NDArray[np.bool_]:
    """Slots whose C/N0 is known and below `cn0_ref_dbhz`; unknown (NaN, ≤ 0 as RTCM MSM sends it, or no array)
    counts as strong."""
    if cn0_dbhz is None:
        return np.zeros(n, bool)
    return np.isfinite(cn0_dbhz) & (cn0_dbhz > 0.0) & (cn0_dbhz < cn0_ref_dbhz)


def _cn0_inflation(cn0_ref_dbhz: float, cn0_dbhz: Arr | None, n: int) -> Arr:
    """max(1, 10^((cn0_ref_dbhz − C/N0)/10)) per slot: 1 but for _weak_signals."""
    weak = _weak_signals(cn0_ref_dbhz, cn0_dbhz, n)
    if cn0_dbhz is None or not weak.any():
        return np.ones(n)
    return np.where(weak, 10.0 ** ((cn0_ref_dbhz - np.where(weak, cn0_dbhz, cn0_ref_dbhz)) / 10.0), 1.0)


def _reference_slot(idx: npt.NDArray[np.int64], el: Arr) -> int:
    """The reference satellite of a double-difference set among slots `idx`: the highest (elevation `el`,
    rad), as RTKLIB's. One place: the filter's rows, the residual checks and partial fixing must agree on it."""
    return int(idx[el[idx].argmax()])


def _dd_pairs(st: RtkState, idx: npt.NDArray[np.int64], el: Arr) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Double-difference pairs among slots `idx`: within each constellation (DD group) its highest satellite
    (_reference_slot) is the reference of the others, as RTKLIB's per-system references. (the other slots in
    slot order, the reference of each); a constellation with one satellite gives none. Read-only arrays,
    memoised on the state by (idx, el): an epoch asks for the same sets several times (filter passes, residual
    checks, fix tries: 4.4 calls per distinct set on the M8P static GPS+GLONASS set)."""
    key = (idx.tobytes(), el.tobytes())
    hit = st.pairs_memo.get(key)
    if hit is None:
        if len(st.pairs_memo) >= _PAIRS_MEMO_SIZE:
            st.pairs_memo.clear()  # entries of past epochs (their elevations) are not asked for again
        hit = st.pairs_memo[key] = _dd_pairs_of(st.layout, idx, el)
    return hit


_PAIRS_MEMO_SIZE = 64
"""Entries RtkState.pairs_memo holds at most (an epoch uses a handful)."""
_LAMBDA_Z_MEMO_SIZE = 32
"""Ambiguity sets RtkState.lambda_z holds at most (an epoch tries up to max_partial_drop + 1)."""


def _dd_pairs_of(layout: SlotLayout, idx: npt.NDArray[np.int64], el: Arr
                 ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """_dd_pairs computed (read-only arrays)."""
    if layout.gps_only:
        ref = _reference_slot(idx, el)
        others = idx[idx != ref]
        refs = np.full(others.size, ref, np.int64)
    else:
        # per group the first slot of highest elevation, as argmax picks it (a NaN first, as argmax's NaN): a
        # pass over the few slots in Python costs less than a mask per group
        slots, groups, els = idx.tolist(), layout.group[idx].tolist(), el[idx].tolist()
        best: dict[int, tuple[float, int]] = {}
        for s, gv, e in zip(slots, groups, els, strict=True):
            b = best.get(gv)
            if b is None or e > b[0] or (math.isnan(e) and not math.isnan(b[0])):
                best[gv] = (e, s)
        ref_of = [best[gv][1] for gv in groups]
        pairs = [(s, r) for s, r in zip(slots, ref_of, strict=True) if s != r]
        others = np.array([s for s, _ in pairs], np.int64).reshape(-1)
        refs = np.array([r for _, r in pairs], np.int64).reshape(-1)
    others.flags.writeable = False
    refs.flags.writeable = False
    return others, refs


def _sd_terms(st: RtkState, ctx: EpochContext, x: Arr) -> tuple[Arr, Arr, Arr, tuple[Arr, Arr] | None]:
    """Per slot at state `x`: modelled range difference rover − base (m), rover LOS, SD phase variance (m²,
    with this epoch's base-age variance) and the slant ionosphere with its mapping (_slant_iono_m, or None)."""
    rng_r, e = _range_with_trop_m(ctx.rov, x[:3], ctx.trop_r)
    var_sd = _var_sd_m2(st.options, ctx.rov, ctx.el)
    if ctx.base_age_var_m2 > 0.0:
        var_sd = var_sd + ctx.base_age_var_m2
    return rng_r - ctx.rng_b, e, var_sd, _slant_iono_m(st, x, ctx.el, ctx.rov.lam) if st.iono_on else None


def _phase_z(x: Arr, sd_phase: Arr, drng: Arr, ion: tuple[Arr, Arr] | None, lam: Arr = _LAM_GPS) -> Arr:
    """Zero-difference-like phase residual per slot (m): SD phase − modelled range difference − λ·ambiguity
    (`lam` the slots' wavelengths, m)."""
    z = sd_phase - drng - lam * x[NX0:NX0 + lam.shape[0]]
    return z if ion is None else z + ion[0]  # the ionosphere advances the phase


def _phase_fit(st: RtkState, ctx: EpochContext, x: Arr, use: npt.NDArray[np.bool_]
               ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.bool_], npt.NDArray[np.int64]]:
    """The phase rows of _ddres(x, use, no code, jacobian=False) and their _valid_residuals test, without the
    DD system around them (R, H): (the rows' non-reference slots, each row's |v| ≤ validation_sigma_factor·σ,
    each row's reference slot). σ² = the reference's + the slot's SD variance, R's diagonal summed alike."""
    idx = use.nonzero()[0]
    if idx.size < 2:
        return idx[:0], np.zeros(0, bool), idx[:0]
    drng, _, var, ion = _sd_terms(st, ctx, x)
    assert ctx.bas is not None
    z = _phase_z(x, _sd_obs_m(ctx.rov, ctx.bas)[0], drng, ion, ctx.rov.lam)
    others, refs = _dd_pairs(st, idx, ctx.el)
    v = z[others] - z[refs]
    return others, np.abs(v) <= st.options.validation_sigma_factor * np.sqrt(var[refs] + var[others]), refs


def _ddres(st: RtkState, ctx: EpochContext, x: Arr, phase_ok: npt.NDArray[np.bool_], code_ok: npt.NDArray[np.bool_],
           with_doppler: bool, jacobian: bool = True) -> tuple[_DD, Arr]:
    """Double-difference residuals at state `x` (RTKLIB ddres): phase, code, rover Doppler between satellites.
    `jacobian=False` for a residual test alone (_valid_residuals): the design matrix H is left empty,
    shape (nrow, 0)."""
    o = st.options
    rov, base, el = ctx.rov, ctx.bas, ctx.el
    assert base is not None
    drng, e, var_sd, ion = _sd_terms(st, ctx, x)
    # groups (kind, reference slot, other slots, zero-difference residual z, per-slot variance), rows i − ref
    groups: list[tuple[int, int, npt.NDArray[np.int64], Arr, Arr]] = []
    ref_phase = -1
    sd_phase, sd_code = _sd_obs_m(rov, base)
    for kind, ok in ((0, phase_ok), (1, code_ok)):
        idx = ok.nonzero()[0]
        if idx.size < 2:
            continue
        others, refs = _dd_pairs(st, idx, el)
        if others.size == 0:
            continue
        if kind == 0:
            ref_phase = int(refs[0])
            z = _phase_z(x, sd_phase, drng, ion, rov.lam)
            var = var_sd
        else:
            z = sd_code - drng
            if st.channel_code_bias is not None:
                z = z - st.channel_code_bias.correction_m(o.glonass_code_bias_min_epochs)
            if ion is not None:
                z = z - ion[0]  # and delays the code
            var = var_sd * o.code_phase_ratio**2 * st.code_var_scale * ctx.static_code_factor
            if o.code_cn0_ref_dbhz > 0.0 and _ublox_code(st):
                var = var * _code_cn0_factor(o.code_cn0_ref_dbhz, rov, base)
        groups.append((kind, refs, others, z, var))
    if with_doppler:
        idx = (code_ok & np.isfinite(rov.dop_hz)).nonzero()[0]
        if idx.size >= 2:
            # one reference across constellations: the receiver clock drift is common to all in m/s
            ref = _reference_slot(idx, el)
            vs = rov.sats.vel_m_s
            sag = OMEGA_E_RAD_S / CLIGHT_M_S * (vs[:, 1] * x[0] - vs[:, 0] * x[1])
            rate_model = np.einsum("ij,ij->i", e, vs - x[3:6]) + sag - CLIGHT_M_S * rov.sats.drift_s_s
            z = -rov.lam * rov.dop_hz - rate_model
            s2 = (o.doppler_sigma_m_s / np.sin(np.maximum(el, DOPPLER_MIN_ELEVATION_RAD))) ** 2
            others = idx[idx != ref]
            groups.append((2, np.full(others.size, ref, np.int64), others, z, s2))
    if not groups:
        return _DD(np.zeros(0), np.zeros((0, x.size)), np.zeros((0, 0)), np.zeros(0, np.int8), np.zeros(0, np.int64), -1), e
    nrow = sum(g[2].size for g in groups)
    v = np.empty(nrow)
    h = np.zeros((nrow, x.size if jacobian else 0))
    r = np.zeros((nrow, nrow))
    kinds = np.empty(nrow, np.int8)
    slots = np.empty(nrow, np.int64)
    var_other: list[Arr] = []
    k = 0
    lam, nxi = rov.lam, st.nxi
    for kind, refs, others, z, var in groups:
        m = others.size
        rows = slice(k, k + m)
        at = _ROWS[k : k + m]
        v[rows] = z[others] - z[refs]
        if jacobian:
            # position (phase, code) or velocity (Doppler) columns: LOS difference ref − other
            cols = slice(3, 6) if kind == 2 else slice(0, 3)
            h[rows, cols] = e[refs] - e[others]
            if kind == 0:
                h[at, NX0 + others] = lam[others]
                h[at, NX0 + refs] = -lam[refs]
            if ion is not None and kind < 2:
                sign = -1.0 if kind == 0 else 1.0
                h[at, nxi + others] = sign * ion[1][others]
                h[at, nxi + refs] = -sign * ion[1][refs]
        # covariance of rows sharing a reference: var_ref everywhere, var_other + var_ref on the diagonal
        if refs[0] == refs[-1] and (refs == refs[0]).all():
            r[rows, rows] = var[refs[0]]
        else:  # one reference per constellation: rows of different ones are uncorrelated
            r[rows, rows] = np.where(refs[:, None] == refs[None, :], var[refs][:, None], 0.0)
        var_other.append(var[others])
        kinds[rows] = kind
        slots[rows] = others
        k += m
    r.ravel()[:: nrow + 1] += np.concatenate(var_other)  # the diagonal as a strided view: no fancy indexing
    return _DD(v, h, r, kinds, slots, ref_phase), e


def _innovation(p: Arr, h: Arr, r: Arr) -> tuple[npt.NDArray[np.int64], Arr, Arr, Arr]:
    """(active states, P on them, P·Hᵀ, innovation covariance S = H·P·Hᵀ + R) over the active states."""
    act = (p.diagonal() > 0).nonzero()[0]
    pa = p.take(act, 0).take(act, 1)  # p[np.ix_(act, act)] without its indexing overhead
    ha = h.take(act, 1)
    ph = pa @ ha.T
    return act, pa, ph, ha @ ph + r


def _kf_update(x: Arr, p: Arr, v: Arr, h: Arr, r: Arr,
               innov: tuple[npt.NDArray[np.int64], Arr, Arr, Arr] | None = None) -> tuple[Arr, Arr]:
    """Kalman measurement update on the active states only (zero-variance states are left alone).
    `innov` = _innovation(p, h, r) when the caller already has it (gating)."""
    act, pa, ph, s = _innovation(p, h, r) if innov is None else innov
    rows, cols = act[:, None], act[None, :]
    k = solve(s, ph.T).T
    x = x.copy()
    x[act] += k @ v
    pn = pa - k @ ph.T
    p = p.copy()
    p[rows, cols] = 0.5 * (pn + pn.T)
    return x, p


def _exclude_one_phase(st: RtkState, ctx: EpochContext, suspects: npt.NDArray[np.int64]
                       ) -> tuple[int, tuple[Arr, Arr]]:
    """Fault exclusion under a hold: the one satellite whose phase, left out of the update from the prior
    state, lets every other phase double difference fit (post-fit within validation_sigma_factor·σ).

    Every held satellite is tried, and a lone suspect (the one satellite whose own post-fit residual failed)
    too when it is a newcomer not yet held. A lone suspect that is not held and fits is the one. Otherwise the
    exclusion must be unique, or clearly the best: its post-fit phase χ² (vᵀR⁻¹v) at most
    1 / fault_exclusion_margin of the runner-up's. Returns (slot, (x, P) of that update), or (−1, prior) when no
    single exclusion fits, when several fit alike (ambiguous), or when fewer than `min_fix_sats` held
    satellites would remain.
    """
    o = st.options
    x_prior, p_prior, use_phase, code_ok = ctx.x_prior, ctx.p_prior, ctx.use_phase, ctx.code_ok
    found: list[tuple[float, int, tuple[Arr, Arr]]] = []
    held = (use_phase & st.held_prns).nonzero()[0]
    # a lone suspect may also be a newcomer not yet held (its float ambiguity still off by a fraction of a
    # cycle): leaving it out keeps the hold whole
    lone = suspects[use_phase[suspects]] if suspects.size == 1 else suspects[:0]
    for c in np.concatenate([lone, held[~np.isin(held, lone)]]):
        keep = use_phase.copy()
        keep[c] = False
        if int(np.count_nonzero(keep & st.held_prns)) < o.min_fix_sats:
            continue
        dd, _ = _ddres(st, ctx, x_prior, keep, code_ok, o.use_doppler)
        if dd.v.size == 0:
            continue
        x_c, p_c = _kf_update(x_prior, p_prior, dd.v, dd.h, dd.r)
        post, _ = _ddres(st, ctx, x_c, keep, code_ok, False, jacobian=False)
        if np.all(_valid_residuals(post, o.validation_sigma_factor)):
            if lone.size and int(c) == int(lone[0]) and not st.held_prns[c]:
                return int(c), (x_c, p_c)
            rows = post.kind == 0
            v = post.v[rows]
            chi2 = float(v @ solve(post.r[np.ix_(rows, rows)], v)) if v.size else 0.0
            found.append((chi2, int(c), (x_c, p_c)))
    if not found:
        return -1, (x_prior, p_prior)
    found.sort(key=lambda f: f[0])
    # a slip the hold absorbed for an epoch or two (a high-leverage satellite, the Doppler test blind in a
    # manoeuvre) biases the prior: leaving out an innocent satellite may then "fit" too, but leaves the
    # slipped one in, with a larger χ² than the true exclusion
    if len(found) > 1 and found[0][0] * o.fault_exclusion_margin > found[1][0] \
            and not (suspects.size == 1 and found[0][1] == int(suspects[0])):
        # not clearly the best, unless it is the one satellite whose own residual failed: then the data
        # point at it twice (its misfit, and the best fit without it)
        return -1, (x_prior, p_prior)
    return found[0][1], found[0][2]


def _valid_residuals(dd: _DD, factor: float) -> npt.NDArray[np.bool_]:
    """Rows whose |residual| ≤ factor·σ (RTKLIB valpos), σ from the measurement covariance."""
    return np.abs(dd.v) <= factor * np.sqrt(dd.r.diagonal())


@dataclass
class _Fix:
    pos: Arr
    cov: Arr
    ratio: float
    slots: npt.NDArray[np.int64]
    ref: npt.NDArray[np.int64]
    """The reference slot of each of `slots` (one per constellation)."""
    ints: Arr
    nb: int
    settled: bool = False
    """The same integer set has won the ratio test at every epoch for settled_fix_span_s (see the option)."""
    iono: Arr | None = None
    """The ionosphere states (m) conditioned on the integers, when they are in use."""
    revalidated: bool = False
    """No set is held and this one re-fixes the last validated integers on at least min_fix_sats satellites
    tracked without a slip since (see _agrees_with_validated)."""
    resumed: bool = False
    """The set held before a radio gap, tried again on the base's return (_resume_gap_hold): held at once."""


def _slot_integers(ref: int | npt.NDArray[np.int64], others: npt.NDArray[np.int64], ints: Arr,
                   nsat: int = NSAT) -> Arr:
    """Per-slot integers of a DD integer set (cycles): 0 at the reference(s) `ref`, the DD integers at
    `others`, NaN elsewhere (`nsat` slots)."""
    c = np.full(nsat, np.nan)
    c[ref] = 0.0
    c[others] = np.rint(ints)
    return c


def _same_integers(a: Arr, b: Arr, min_common: int, group: npt.NDArray[np.int8] | None = None) -> bool:
    """True when per-slot integer sets `a` and `b` (see _slot_integers) share at least `min_common` satellites
    and are equal on all of them, up to the choice of reference (a constant)."""
    common = np.isfinite(a) & np.isfinite(b)
    if common.sum() < min_common:
        return False
    d = a[common] - b[common]
    if group is None:
        return bool(np.all(d == d[0]))
    # up to one constant per constellation (each has its own reference): each equal to its group's first (a
    # pass over the few satellites: np.unique's sort and index arrays cost more)
    first: dict[int, float] = {}
    return all(first.setdefault(gv, dv) == dv for gv, dv in zip(group[common].tolist(), d.tolist(), strict=True))


def _agrees_with_validated(st: RtkState, ref: int | npt.NDArray[np.int64], others: npt.NDArray[np.int64], ints: Arr,
                           min_common: int) -> bool:
    """True when at least `min_common` satellites of a candidate set belong to the last validated (held) set
    and the candidate's integers equal that set's on all of them: a re-fix of integers already validated and
    tracked without a slip since (e.g. after a hold released for one satellite's misfit, which that satellite's
    reset removed), extended at most by satellites that joined since, as a held set would be."""
    return _same_integers(_slot_integers(ref, others, ints, st.ns), st.validated_int, min_common, _groups(st))


def _groups(st: RtkState) -> npt.NDArray[np.int8] | None:
    """The slots' DD groups (constellations), None for GPS alone (one group)."""
    return None if st.layout.gps_only else st.layout.group


def _resamb_lambda(st: RtkState, ctx: EpochContext, cand: npt.NDArray[np.bool_]) -> _Fix | None:
    """Integer ambiguity resolution on the DD ambiguities of `cand` slots (RTKLIB resamb_LAMBDA) with
    partial fixing: drop the least determined satellite and retry while the ratio test fails; a set needs at
    least min_fix_sats satellites."""
    o = st.options
    el, t = ctx.el, ctx.time
    idx = cand.nonzero()[0]
    best_ratio = 0.0
    seen_candidate = False
    settled = False
    full_set: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], LambdaResult] | None = None
    """The full candidate set's (references, others, search result): its integers are read only when a partial
    survivor must be compared with them (LambdaResult.fixed is computed on first use)."""
    dropped: tuple[tuple[int, ...], tuple[Arr, Arr, Arr, Arr | None], int] | None = None
    """The last try's references, DD ambiguities (a, Qa, Qba, Qia) and position among its others of the slot
    dropped since."""
    for _drop in range(o.max_partial_drop + 1 if o.partial_ar else 1):
        if idx.size < 2:
            break
        others, ref = _dd_pairs(st, idx, el)
        if others.size + 1 < o.min_fix_sats:
            break
        ref_key = tuple(sorted(set(ref.tolist())))  # np.unique's result, without its sort of arrays
        if dropped is not None and dropped[0] == ref_key:
            # a retry keeps the references (the highest satellites, never the one dropped): a subset of the last
            a, qa, qba, qia = _dd_ambiguities_without(dropped[1], dropped[2])
        else:
            a, qa, qba, qia = _dd_ambiguities_of(st, idx, others, ref)
        z_key = (others.tobytes(), ref.tobytes())
        try:
            res = mlambda(a, qa, ratio_cap=RATIO_CAP, z_start=st.lambda_z.get(z_key))
        except LambdaError:
            return None
        if len(st.lambda_z) >= _LAMBDA_Z_MEMO_SIZE and z_key not in st.lambda_z:
            st.lambda_z.clear()  # sets of past epochs' satellites: most are not asked for again
        st.lambda_z[z_key] = res.z_mat
        ratio = res.ratio
        best_ratio = max(best_ratio, ratio)
        if _drop == 0:
            full_set = (ref, others, res)
            # determined to a small fraction of a cycle (success rate ≈ 1), yet near no integer set (low ratio):
            # the float holds something its covariance does not know, e.g. a slip it absorbed (stuck_float_s)
            if o.stuck_float_s > 0.0 and not st.held_prns.any() and not st.iono_on \
                    and res.success_rate >= o.stuck_float_success_rate and ratio < o.stuck_float_ratio:
                if st.stuck_since is None:
                    st.stuck_since = t
            else:
                st.stuck_since = None
        # a fix resting on the bare minimum of double differences (no held set to lean on) must be
        # nearly certain: a stricter success rate and twice the ratio
        strict = (others.size + 1 <= o.min_fix_sats or _drop >= o.strict_partial_drop_sats) \
            and not np.count_nonzero(st.held_prns)
        need_ratio = o.ratio_threshold * (2.0 if strict else 1.0)
        need_sr = max(o.min_success_rate, o.min_success_rate_minimal_set) if strict else o.min_success_rate
        accept = False
        if ratio >= need_ratio and not seen_candidate:
            # the integer set winning the ratio test must keep winning for a while before a first fix (nothing
            # held, no known start): a float biased by correlated code gives a wrong set that satellite motion breaks within seconds. Below the success rate, it must
            # win over consistent_fix_span_s: satellite motion over that span separates position from
            # ambiguities, which a float built on code cannot do in a few epochs.
            #
            # A full set (no satellite dropped) is one ratio test on every ambiguity the float carries, low
            # satellites included; a partial set is the survivor of up to max_partial_drop + 1 tests, which
            # inflates the chance that a code-biased float passes one of them by luck (docs/rtk-defaults.md): a
            # full set needs its win confirmed at full_set_confirm_epochs consecutive epochs (and, below the
            # success rate, over confirm_fix_span_s), a partial one the wall-time spans.
            seen_candidate = True
            # with measured u-blox-like code, a full set of few double differences is no stronger than a partial one
            full = _drop == 0 and (others.size >= o.full_set_min_dd or not _ublox_code(st))
            key = (ref_key, tuple(others.tolist()), tuple(np.rint(res.fixed[:, 0]).astype(int).tolist()))
            slot_ints = _slot_integers(ref, others, res.fixed[:, 0], st.ns)
            pf = st.pending_fix
            if pf is None or (pf.key != key and not (o.confirm_across_set_changes and _same_integers(
                    pf.slot_ints, slot_ints, o.min_fix_sats, _groups(st)))):
                pf = PendingFix(key, t, 0, t, 0.0, slot_ints)
            elif pf.key != key:
                # the same integers with a satellite more or less, or another reference: its time spans go on,
                # its count of consecutive wins (full_set_confirm_epochs: of one and the same set) starts again
                pf = pf._replace(wins=0)
            _, since, wins, last, progress, _ = pf
            if o.settled_fix_span_s > 0:
                # the code multipath the float leans on decorrelates within seconds once the rover moves
                progress += abs(t.diff_s(last)) / (o.settled_fix_span_moving_s if ctx.moving else o.settled_fix_span_s)
            st.pending_fix = PendingFix(key, since, wins + 1, t, progress, slot_ints)
            span = abs(t.diff_s(since))
            settled = o.settled_fix_span_s > 0 and progress >= 1.0 - 1e-9
            # correlated code multipath biases the float for about its correlation time: clean code waits less
            need_span = max(o.confirm_fix_span_min_s, o.confirm_fix_span_s * st.code_var_scale)
            if _ublox_code(st):
                # measured u-blox-like code: the differential ionosphere biases its float for minutes
                need_span += o.confirm_fix_span_per_km_s * ctx.baseline_m / 1000.0
            wins = st.pending_fix.wins
            trusted = bool(np.count_nonzero(st.held_prns) or st.known_amb[idx].all() or ctx.anchored) \
                or _agrees_with_validated(st, ref, others, res.fixed[:, 0], o.min_fix_sats)
            # a survivor contradicting the full set's best integers on the satellites they share: two rival
            # integer hypotheses, the partial one winning only without the satellites that contradict it
            rival = False
            if not full and o.partial_agrees_with_full and full_set is not None:
                full_ref, full_others, full_res = full_set
                rival = not _same_integers(_slot_integers(ref, others, res.fixed[:, 0], st.ns),
                                           _slot_integers(full_ref, full_others, full_res.fixed[:, 0], st.ns), 2,
                                           _groups(st))
            far = o.max_first_fix_baseline_km > 0.0 and ctx.baseline_m > 1000.0 * o.max_first_fix_baseline_km
            if rival or far:
                # no first fix on such data (see the options): only a set already trusted
                accept = trusted and res.success_rate >= need_sr
            elif res.success_rate >= need_sr:
                accept = trusted or span >= need_span or (full and wins >= o.full_set_confirm_epochs)
            elif not strict:
                accept = span >= max(o.consistent_fix_span_s, need_span) or (
                    full and wins >= o.full_set_confirm_epochs and span >= need_span)
        elif ratio >= need_ratio:
            accept = res.success_rate >= need_sr and (bool(st.held_prns.any() or st.known_amb[idx].all()
                                                           or ctx.anchored)
                                                     or _agrees_with_validated(st, ref, others, res.fixed[:, 0], o.min_fix_sats))
        if accept:
            ints = res.fixed[:, 0]
            conditioned = _conditioned_on(st, a, qa, qba, qia, ints)
            if conditioned is None:
                return None
            pos, cov, iono = conditioned
            st.last_ratio = ratio
            revalidated = not st.held_prns.any() and _agrees_with_validated(st, ref, others, ints, o.min_fix_sats)
            return _Fix(pos, cov, ratio, others, ref, ints, others.size, settled, iono, revalidated)
        # partial: drop the least determined DD ambiguity (largest float variance: a satellite just (re)joined,
        # whose ambiguity is still code-level, else mostly the lowest one), not blindly the lowest satellite:
        # one fresh ambiguity would otherwise sink the ratio of a set determined long ago
        k_drop = int(qa.diagonal().argmax())
        dropped = (ref_key, (a, qa, qba, qia), k_drop)
        idx = idx[idx != others[k_drop]]
    st.last_ratio = best_ratio
    if not seen_candidate:
        st.pending_fix = None
    return None


def _fixed_ambiguity_state(x: Arr, fix: _Fix) -> Arr:
    """State with the DD ambiguities of the fix imposed (SD of the reference kept, others = ref + integer)."""
    xf = x.copy()
    xf[:3] = fix.pos
    xf[NX0 + fix.slots] = xf[NX0 + fix.ref] + fix.ints
    if fix.iono is not None:
        xf[NX0 + fix.iono.size:] = fix.iono
    return xf


def _holdamb(st: RtkState, fix: _Fix, el: Arr) -> None:
    """Constrain the float DD ambiguities to the fixed integers (RTKLIB holdamb), for the fixed satellites at
    or above hold_elmask_deg (`el` elevations in rad per slot); nothing is held when none is."""
    o = st.options
    keep = el[fix.slots] >= math.radians(o.hold_elmask_deg)
    slots, ints = fix.slots[keep], fix.ints[keep]
    n = slots.size
    if n == 0:
        return
    h = np.zeros((n, st.x.size))
    h[np.arange(n), NX0 + slots] = 1.0
    h[np.arange(n), NX0 + fix.ref[keep]] = -1.0
    v = ints - h @ st.x
    r = np.eye(n) * o.hold_sigma_cyc**2
    st.x, st.p = _kf_update(st.x, st.p, v, h, r)
    st.held_prns[:] = False
    st.held_prns[slots] = True
    st.held_prns[fix.ref] = True
    st.validated_int[:] = np.nan
    st.validated_int[fix.ref] = 0.0
    st.validated_int[slots] = np.rint(ints)


# The stages of rtk_pos, in order (RTKLIB rtkpos() → relpos()): _start_epoch (satposs, pntpos), _detect_motion,
# _rover_only (no usable base), _select_base, _udstate, _select_satellites (zdres: ranges, elevations, the
# common set), _udbias_epoch (slips, base history, udbias, udion, code weight, standstill), _remember_epoch,
# _float_update (ddres + Kalman update with outlier passes), _check_hold (post-fit residuals under a hold,
# fault exclusion, release), _resolve (resamb_lambda + validation, valpos), _restart_stuck, _epoch_solution
# (holdamb). Each reads and writes the epoch's EpochContext and the persistent RtkState.


def rtk_pos(st: RtkState, rover: ObsEpoch, base: ObsEpoch | None, nav: NavData,
            base_pos_ecef_m: Arr | None, receivers: tuple[_Receiver | None, _Receiver | None] = (None, None),
            spp: SppSolution | None = None, anchor: tuple[Arr, Arr] | None = None) -> Solution:
    """Process one rover epoch (RTKLIB rtkpos()/relpos()); returns the epoch's Solution.

    `base` is the base epoch paired with this rover epoch (latest at or before it, see postpro.pair_epochs);
    `base_pos_ecef_m` the base antenna L1 phase centre. Without base data a single-point solution (Q=5);
    without a single-point solution none (Q=0, NaN position: see Solution).
    `receivers`: the rover's and the base epoch's slot data when already built (epoch_receivers), else None
    (built here); `spp` the rover's single-point solution likewise (epoch_spp). `anchor`: a fixed position of
    this epoch from another pass over the same data (ECEF m, its covariance m²), which pins a float without a
    held set (see _apply_anchor).
    """
    ctx = _start_epoch(st, rover, nav, receivers[0], spp)
    if ctx is None:
        return _no_solution(rover.time)
    _detect_motion(st, ctx)
    if base is None or base_pos_ecef_m is None or abs(rover.time.diff_s(base.time)) > st.options.max_age_s:
        return _rover_only(st, ctx, base, base_pos_ecef_m)
    _select_base(st, ctx, base, nav, receivers[1], base_pos_ecef_m)
    _udstate(st, ctx.dt_s, ctx.spp.pos_ecef_m, ctx.spp.vel_ecef_m_s, ctx.base_pos)
    _select_satellites(st, ctx)
    _udbias_epoch(st, ctx, base.time)
    _remember_epoch(st, ctx, base.time)
    _float_update(st, ctx)
    dd = ctx.dd
    if dd is None or ctx.ns < 2 or not np.count_nonzero(dd.kind == 0):
        # no phase double differences at all: report the filter position as float only if it is constrained
        return _solution(ctx.t_sol, st.x[:3], st.x[3:6], Q_FLOAT if ctx.ns >= 2 else Q_SINGLE, ctx.ns,
                         st.p[:3, :3], st.p[3:6, 3:6], ctx.age_s, 0.0)
    _check_hold(st, ctx)
    if anchor is not None:
        _apply_anchor(st, ctx, *anchor)
    fix = _resolve(st, ctx) if st.options.ar_mode != "off" else None
    _restart_stuck(st, ctx, fix)
    return _epoch_solution(st, ctx, fix)


def _apply_anchor(st: RtkState, ctx: EpochContext, pos_ecef_m: Arr, cov_m2: Arr) -> None:
    """Pin the float to another pass's fixed position of this epoch (a Kalman update of the position, ECEF m,
    with covariance `cov_m2` m²) when nothing is held: the position determines the ambiguities through their
    correlation with it, as a surveyed take-off point does, and the integers that follow need no confirmation
    (ctx.anchored). A held set is left alone: it stays an independent check of the other pass."""
    if st.held_prns.any() or not np.all(np.isfinite(pos_ecef_m)) or not np.all(np.isfinite(cov_m2)):
        return
    h = np.zeros((3, st.x.size))
    h[:, :3] = np.eye(3)
    st.x, st.p = _kf_update(st.x, st.p, pos_ecef_m - st.x[:3], h, cov_m2)
    ctx.anchored = True


def _broadcast(nav: NavData) -> BroadcastNavigation | None:
    """The other constellations' ephemerides of `nav` (Nav.broadcast), None without."""
    return getattr(nav, "broadcast", None)


def _no_solution(t: GpsTime) -> Solution:
    """The epoch without any position (Q_NONE): NaN position, velocity and covariances, no satellite."""
    nan3, nan33 = np.full(3, np.nan), np.full((3, 3), np.nan)
    return Solution(time=t, pos_ecef_m=nan3, vel_ecef_m_s=nan3.copy(), q=Q_NONE, ns=0, cov_pos_m2=nan33,
                    cov_vel_m2_s2=nan33.copy(), age_s=0.0, ratio=0.0)


def _start_epoch(st: RtkState, rover: ObsEpoch, nav: NavData, rov: _Receiver | None, spp: SppSolution | None
                 ) -> EpochContext | None:
    """Satellite states on the rover's slots (satposs) and its single-point solution (pntpos); the epoch's
    context, or None without a single-point solution."""
    o = st.options
    rov = _slots(rover, nav.store, st.layout, _broadcast(nav)) if rov is None else rov
    if spp is None or not st.initialized:
        # the filter starts on this epoch's own solution from a cold start (precomputed ones start elsewhere)
        multi = not st.layout.gps_only
        spp = pntpos(np.where(rov.has, rov.pr_m, np.nan) if multi else rov.pr_m, rov.sats, rover.time.tow_s,
                     o.elmask_rad, rov.dop_hz, nav.iono, x0_ecef_m=st.x[:3] if st.initialized else None,
                     outlier_m=o.spp_outlier_m, max_gdop=o.spp_max_gdop, clock0_m=st.clock_bias_m,
                     clock_group=st.layout.group if multi else None, lam_m=rov.lam if multi else None)
    if not spp.ok:
        log.debug("%s: no single-point solution (%s)", rover.time, spp.message)
        return None
    st.clock_bias_m = spp.clock_bias_m
    return EpochContext(rover.time, rov, spp, rover.time.add_s(-spp.clock_bias_m / CLIGHT_M_S))


def _detect_motion(st: RtkState, ctx: EpochContext) -> None:
    """Whether the rover moves by its Doppler speed (ctx.moving); the static start ends at take-off."""
    o = st.options
    speed = _norm(ctx.spp.vel_ecef_m_s)  # not finite unless every component is
    ctx.moving = math.isfinite(speed) and speed > o.takeoff_speed_m_s
    if st.static and ctx.moving:
        log.info("%s: take-off detected (%.2f m/s), leaving static mode", ctx.time, speed)
        st.static = False
        st.p[3:6, 3:6] = np.eye(3) * o.initial_vel_sigma_m_s**2


def _single(ctx: EpochContext, age_s: float) -> Solution:
    """The epoch's single-point solution (Q_SINGLE), its σ SPP_SIGMA_PER_GDOP_M per unit of GDOP."""
    spp = ctx.spp
    cov = np.eye(3) * (spp.gdop * SPP_SIGMA_PER_GDOP_M) ** 2
    return _solution(ctx.t_sol, spp.pos_ecef_m, spp.vel_ecef_m_s, Q_SINGLE, int(np.count_nonzero(spp.used)), cov,
                     np.eye(3) * SPP_VEL_VAR_M2_S2, age_s, 0.0)


def _rover_only(st: RtkState, ctx: EpochContext, base: ObsEpoch | None, base_pos_ecef_m: Arr | None) -> Solution:
    """An epoch without usable base data (none, or older than max_age_s): the single-point solution."""
    # keep watching the rover's phase, so that a radio gap neither hides a rover slip nor (judged later over the
    # whole gap by a Doppler integration that ignores the manoeuvres) fakes slips on every satellite
    if st.initialized:
        rov = ctx.rov
        rover_ok = rov.has & np.isfinite(rov.cp_cyc)
        st.pending_slip |= _rover_slips(st, rov, ctx.time, rover_ok)
        _remember_rover(st, rov, ctx.time)
    return _single(ctx, 0.0 if base is None or base_pos_ecef_m is None else ctx.time.diff_s(base.time))


def _select_base(st: RtkState, ctx: EpochContext, base: ObsEpoch, nav: NavData, bas: _Receiver | None,
                 base_pos_ecef_m: Arr) -> None:
    """The base epoch's slot data (kept while later rover epochs pair with it), its age, the baseline at the
    previous position and the time since the previous epoch."""
    ctx.age_s = ctx.time.diff_s(base.time)
    if st.base_cache is not None and st.base_cache[0] == base.time:
        ctx.bas = st.base_cache[1]
    else:
        ctx.bas = _slots(base, nav.store, st.layout, _broadcast(nav)) if bas is None else bas
        st.base_cache = (base.time, ctx.bas)
    ctx.base_pos = base_pos = np.asarray(base_pos_ecef_m, float)
    ctx.baseline_m = _norm(st.x[:3] - base_pos) if st.initialized else 0.0
    ctx.dt_s = ctx.time.diff_s(st.time) if st.time is not None else 0.0


def _select_satellites(st: RtkState, ctx: EpochContext) -> None:
    """Zero-difference models (RTKLIB zdres) at the base's known and the rover's predicted position, and the
    satellites the epoch may use: both receivers, above the mask, used by the single-point solution; with phase
    on both (an unresolved half cycle excluded when exclude_half_cycle)."""
    o = st.options
    rov, bas = ctx.rov, ctx.bas
    assert bas is not None
    ctx.rng_b = _model_range_m(bas, ctx.base_pos)[0]
    rng_r, ctx.los_r, _, el = _model_range_m(rov, st.x[:3])
    ctx.rng_r, ctx.el = rng_r, el
    ctx.trop_r = rng_r - _range_with_trop_m(rov, st.x[:3], np.zeros(st.ns))[0]
    common = rov.has & bas.has & (el >= o.elmask_rad) & ctx.spp.used
    half = ((rov.lli & LLI_HALF_CYCLE) != 0) | ((bas.lli & LLI_HALF_CYCLE) != 0)
    # phase with an unresolved half cycle may jump by ½ cycle when the receiver resolves it: not used at all
    ctx.phase_ok = common & np.isfinite(rov.cp_cyc) & np.isfinite(bas.cp_cyc) & ~(half & o.exclude_half_cycle)
    ctx.common, ctx.half = common, half


def _udbias_epoch(st: RtkState, ctx: EpochContext, t_b: GpsTime) -> None:
    """Slips (LLI, Doppler, base geometry), the base correction history and the carried-forward base, the
    ambiguities (udbias) and ionosphere states (udion), the code weight (measured scatter, standstill)."""
    o = st.options
    rov, bas, phase_ok = ctx.rov, ctx.bas, ctx.phase_ok
    assert bas is not None
    # in GPS L1 cycles (the base clock, common in metres, is removed from them; see _extrapolated_base)
    base_zb_cyc = (bas.lam * bas.cp_cyc - ctx.rng_b) / LAMBDA_L1_M
    slip = _detect_slips(st, rov, bas, base_zb_cyc, ctx.time, t_b, phase_ok)
    if np.count_nonzero(st.pending_slip):  # rover slips seen while the base was missing
        gone = (st.pending_slip & ~phase_ok & _in_use(st)).nonzero()[0]
        if gone.size:
            _reset_amb(st, gone)
            st.slips += int(gone.size)
        slip |= st.pending_slip & phase_ok
        st.pending_slip[:] = False
    if st.prev_time_b != t_b:
        _remember_base(st, bas, t_b, base_zb_cyc)
    ctx.base_zb_cyc = base_zb_cyc
    carried = _extrapolated_base(st, bas, ctx.age_s)
    # the variance of what the rate misses; raw base data (young, or no history, e.g. processed backward) as before
    ctx.base_age_var_m2 = (o.base_age_sigma_m_s * ctx.age_s) ** 2 if carried is not bas else 0.0
    ctx.bas = bas = carried
    _udbias(st, rov, bas, ctx.rng_r, ctx.rng_b, phase_ok, slip, t_r=ctx.time)
    _udion(st, ctx.common, ctx.base_pos, ctx.dt_s, ctx.el, rov.lam)
    st.code_var_scale = code_variance_scale(st, rov, bas, phase_ok, slip, ctx.el, ctx.dt_s)
    if o.standstill or st.static:
        slipped = _watch_standstill(st, ctx, phase_ok & ~slip & ~ctx.half)
        if slipped >= 0:
            phase_ok[slipped] = False  # its ambiguity starts again next epoch
    ctx.static_code_factor = static_code_factor(o, st.static, ctx.dt_s)


def _remember_epoch(st: RtkState, ctx: EpochContext, t_b: GpsTime) -> None:
    """Keep this epoch's raw rover phase/Doppler and base geometry residual for the next epoch's slip tests."""
    _remember_rover(st, ctx.rov, ctx.time)
    if st.prev_time_b != t_b:
        st.prev_zb = ctx.base_zb_cyc
        st.prev_time_b = t_b
    st.time = ctx.time


def _float_update(st: RtkState, ctx: EpochContext) -> None:
    """Measurement update of the float solution (RTKLIB ddres + filter, one iteration): innovations gated at
    outlier_gate_sigma; the worst outlier is removed (a phase outlier resets its ambiguity) and the update re-run,
    up to max_outlier_passes passes. When every pass finds an outlier the epoch has no measurement update: the
    state stays at its time update (with the outliers' ambiguities reset), st.rejected_updates counts it."""
    o = st.options
    rov, bas, phase_ok = ctx.rov, ctx.bas, ctx.phase_ok
    assert bas is not None
    ctx.code_ok = code_ok = ctx.common.copy()
    ctx.use_phase = use_phase = phase_ok.copy()
    x_post, p_post = st.x, st.p
    ctx.x_prior, ctx.p_prior = st.x, st.p
    dd = None
    for _pass in range(o.max_outlier_passes):
        dd, _ = _ddres(st, ctx, st.x, use_phase, code_ok, o.use_doppler)
        if dd.v.size == 0:
            break
        # innovation gating with the innovation covariance (the one the update then uses)
        innov = _innovation(st.p, dd.h, dd.r)
        norm = np.abs(dd.v) / np.sqrt(innov[-1].diagonal())
        bad = norm > o.outlier_gate_sigma
        bad &= ~((dd.kind == 0) & (np.abs(dd.v) < o.phase_outlier_floor_m))
        if not np.count_nonzero(bad):
            ctx.x_prior, ctx.p_prior = st.x, st.p
            x_post, p_post = _kf_update(st.x, st.p, dd.v, dd.h, dd.r, innov)
            break
        worst = int(np.argmax(np.where(bad, norm, -1)))
        kind, slot = int(dd.kind[worst]), int(dd.slot[worst])
        if kind == 0:
            # a phase outlier: treat as a slip of that satellite (or of the reference when most rows fail)
            phase_bad = bad & (dd.kind == 0)
            n_phase = int((dd.kind == 0).sum())
            if n_phase < MIN_PHASE_DD_TO_ISOLATE or phase_bad.sum() > 1:
                # too few double differences (or several bad) to tell which satellite slipped: start the
                # ambiguities afresh rather than keep a possibly slipped one (and a wrong hold) alive
                log.debug("%s: phase outliers on %d of %d DDs -> all ambiguities reset", ctx.time,
                          int(phase_bad.sum()), n_phase)
                reset = _in_use(st).nonzero()[0]
                _reset_amb(st, reset)
                st.slips += int(reset.size)
                ctx.use_phase = use_phase = phase_ok & code_ok
                st.fix_count = 0
                _udbias(st, rov, bas, ctx.rng_r, ctx.rng_b, use_phase, np.zeros(st.ns, bool), count_lock=False)
                continue
            log.debug("%s: phase outlier %s (%.2f m) -> ambiguity reset", ctx.time, st.layout.letter(slot), dd.v[worst])
            _reset_amb(st, np.array([slot]))
            use_phase[slot] = False
            st.slips += 1
            st.held_prns[:] = False
        elif kind == 1:
            code_ok[slot] = False
            use_phase[slot] = False
        else:
            rov.dop_hz[slot] = np.nan
    else:
        if o.max_outlier_passes > 0:
            st.rejected_updates += 1
            log.info("%s: an outlier at every one of %d passes: no measurement update this epoch (time update "
                     "only)", ctx.time, o.max_outlier_passes)
    st.x, st.p = x_post, p_post
    ctx.dd = dd
    ctx.ns = int(np.count_nonzero(use_phase))


def _check_hold(st: RtkState, ctx: EpochContext) -> None:
    """Post-fit phase residuals of the float solution under a held set: one satellite that no longer fits is
    excluded (fault exclusion), a set that no longer fits is released (wrong-fix protection)."""
    # it guards a held set (the fault exclusion and the release act only on one), so without one it is not
    # computed (a residual pass per epoch of an unfixed rover)
    use_phase = ctx.use_phase
    bad_phase = rows_post = refs_post = bad_refs = np.zeros(0, np.int64)
    if st.held_prns.any():
        # phase rows alone: only they are judged, each against its own σ (the code rows changed none of them)
        rows_post, ok_post, refs_post = _phase_fit(st, ctx, st.x, use_phase)
        bad_phase, bad_refs = rows_post[~ok_post], refs_post[~ok_post]
    if bad_phase.size:  # only ever found under a hold (above)
        # one satellite slipping under a hold spreads its error over every row through the position: find
        # whether leaving out a single satellite makes the rest fit (fault exclusion) before releasing all
        culprit, fitted = _exclude_one_phase(st, ctx, bad_phase)
        if culprit >= 0:
            log.info("%s: %s no longer fits the held set: its ambiguity alone restarts", ctx.time,
                     st.layout.letter(culprit))
            st.x, st.p = fitted
            st.slips += 1
            _reset_amb(st, np.array([culprit]))
            use_phase[culprit] = False
            bad_phase = bad_phase[:0]
    if bad_phase.size:
        # the held integer set no longer fits: release it (wrong-fix protection)
        log.info("%s: held fix released (%d phase residuals out of bounds)", ctx.time, bad_phase.size)
        st.held_prns[:] = False
        st.fix_count = 0
        if st.options.resume_hold_after_gap and ctx.base_age_var_m2 > 0.0:
            # on a carried base the drift of what it observes, not the integers, is the likelier misfit: the set
            # is tried again on the base's return (_resume_gap_hold)
            st.gap_int = st.validated_int.copy()
            st.gap_base_time = st.prev_time_b
        if bad_phase.size > 1:
            # several misfits point at the set rather than at one satellite: it no longer vouches for a re-fix
            st.validated_int[:] = np.nan
        amb = NX0 + _in_use(st).nonzero()[0]
        st.p[amb, amb] += RELEASE_AMB_SIGMA_CYC**2
        if bad_phase.size >= MIN_DD_REFERENCE_SLIP and (bad_refs == bad_refs[0]).all() \
                and bad_phase.size == np.count_nonzero(refs_post == bad_refs[0]):
            # every DD of a constellation off at once is one satellite, its reference, slipping without LLI:
            # reset it alone (the others stay; see docs/rtk-defaults.md)
            bad_phase = bad_refs[:1]
        if bad_phase.size >= 1:
            st.slips += int(bad_phase.size)
            _reset_amb(st, bad_phase)
            use_phase[bad_phase] = False


def _resolve(st: RtkState, ctx: EpochContext) -> _Fix | None:
    """Integer ambiguity resolution (RTKLIB resamb_LAMBDA) and validation of the fix (valpos): float-fix
    consistency (Mahalanobis distance of the positions) and post-fit phase residuals of the fixed solution;
    a rejected fix gets one more try on a reduced set (FIX_TRIES)."""
    o = st.options
    el, use_phase = ctx.el, ctx.use_phase
    amb_var = st.p.diagonal()[NX0:st.nxi]
    # ambiguities seeded from a surveyed take-off point are known, not guessed from the code: no lock wait
    locked = (st.lock > o.min_lock_epochs) | st.known_amb
    cand = use_phase & (el >= math.radians(o.ar_elmask_deg)) & ~ctx.half & locked & (amb_var > 0)
    fix = _resamb_lambda(st, ctx, cand)
    if st.gap_base_time is not None and st.prev_time_b != st.gap_base_time:
        # the first epoch with new base data since a hold was released in a radio gap: one try of that set
        st.gap_base_time = None
        if fix is None and ctx.base_age_var_m2 == 0.0 and not st.held_prns.any():
            fix = _resume_gap_hold(st, ctx, cand)
    for _try in range(FIX_TRIES):
        if fix is None:
            break
        # validate: float-fix consistency and post-fit residuals of the fixed solution
        dpos = fix.pos - st.x[:3]
        try:
            maha = float(dpos @ solve(st.p[:3, :3], dpos))
        except LinAlgError:
            maha = np.inf
        xf = _fixed_ambiguity_state(st.x, fix)
        use_fix = np.zeros(st.ns, bool)
        use_fix[fix.slots] = True
        use_fix[fix.ref] = True
        fix_rows, valid, _ = _phase_fit(st, ctx, xf, use_fix)
        near_float = maha <= _CHI2_3DOF_999 * _float_fix_gate_scale(st, fix)
        # a re-fix of validated integers need not lie near the float: after a released hold the float of a
        # static rover knows its position to millimetres and carries the centimetre multipath the hold kept out
        if (near_float or fix.settled or (fix.revalidated and o.revalidated_skips_float_check)) \
                and np.count_nonzero(valid) == valid.size:
            break
        log.debug("%s: fix rejected (mahalanobis %.1f, residuals ok %s)", ctx.time, maha, bool(valid.all()))
        # a second look at this epoch: without the one satellite whose phase does not fit the fixed solution
        # (multipath, a half cycle) while the float agrees with the fix, or, with a set held, on the held
        # satellites alone (a newcomer, e.g. G23 on M8P a 0.4 cycle off, pulls a full set away from the held
        # float); RTKLIB only rejects the epoch. A fix that fits nowhere is not retried. The retry is no
        # confirmation: it can only fix a set trusted without one (held or validated), and the first-fix
        # confirmation under way is left as it was.
        fix = None
        retry = None
        if _try == 0 and near_float and int((~valid).sum()) == 1 and valid.sum() >= o.min_fix_sats - 1:
            retry = cand.copy()
            retry[fix_rows[~valid]] = False
        elif _try == 0 and st.held_prns.any() and np.any(cand & ~st.held_prns):
            retry = cand & st.held_prns
        if retry is not None:
            pending = st.pending_fix
            st.pending_fix = None
            fix = _resamb_lambda(st, ctx, retry)
            st.pending_fix = pending
    return fix


def _resume_gap_hold(st: RtkState, ctx: EpochContext, cand: npt.NDArray[np.bool_]) -> _Fix | None:
    """The fix of the integers held before a radio gap (RtkState.gap_int) on the `cand` slots still tracked
    without a slip, None when fewer than min_fix_sats satellites are left. The caller validates its phase
    residuals; as a revalidated set it skips the float-fix check (the float drifted with the carried base)."""
    o = st.options
    idx = (cand & np.isfinite(st.gap_int)).nonzero()[0]
    if idx.size < o.min_fix_sats:
        return None
    others, ref = _dd_pairs(st, idx, ctx.el)
    if others.size + 1 < o.min_fix_sats:
        return None
    a, qa, qba, qia = _dd_ambiguities_of(st, idx, others, ref)
    ints = st.gap_int[others] - st.gap_int[ref]
    conditioned = _conditioned_on(st, a, qa, qba, qia, ints)
    if conditioned is None:
        return None
    pos, cov, iono = conditioned
    log.debug("%s: the set held before the radio gap tried again (%d satellites)", ctx.time, idx.size)
    return _Fix(pos, cov, st.last_ratio, others, ref, ints, others.size, iono=iono, revalidated=True, resumed=True)


def _float_fix_gate_scale(st: RtkState, fix: _Fix) -> float:
    """Factor on the float's position covariance in the float-fix consistency test (float_fix_gate_scale):
    measured u-blox-like code and a set of at least float_fix_gate_min_dd double differences, else 1."""
    o = st.options
    return o.float_fix_gate_scale if _ublox_code(st) and fix.slots.size >= o.float_fix_gate_min_dd else 1.0


def _restart_stuck(st: RtkState, ctx: EpochContext, fix: _Fix | None) -> None:
    """Restart the float ambiguities when they have been determined yet near no integer set for
    stuck_float_s (see the option)."""
    if fix is None and st.stuck_since is not None and abs(ctx.time.diff_s(st.stuck_since)) >= st.options.stuck_float_s:
        log.info("%s: float ambiguities determined yet fitting no integer set for %.0f s: restarted", ctx.time,
                 abs(ctx.time.diff_s(st.stuck_since)))
        _reset_amb(st, _in_use(st).nonzero()[0])
        st.stuck_since = None
        st.pending_fix = None
        st.float_restarts += 1


def _learn_channel_code_bias(st: RtkState, ctx: EpochContext, pos_ecef_m: Arr) -> None:
    """One fixed epoch's GLONASS SD code residuals at the fixed position (ECEF m) into the channel biases:
    the strong signals' (C/N0 at or above code_cn0_ref_dbhz where known), whose code multipath is small next
    to the biases."""
    assert st.channel_code_bias is not None and ctx.bas is not None
    o = st.options
    x = st.x.copy()
    x[:3] = pos_ecef_m
    drng, _, _, ion = _sd_terms(st, ctx, x)
    resid = _sd_obs_m(ctx.rov, ctx.bas)[1] - drng
    if ion is not None:
        resid = resid - ion[0]
    use = ctx.code_ok & (st.layout.group == st.layout.systems.index("R")) & np.isfinite(resid)
    if o.code_cn0_ref_dbhz > 0.0:
        use &= ~_weak_signals(o.code_cn0_ref_dbhz, ctx.rov.cn0_dbhz, st.ns)
    st.channel_code_bias.learn(resid, use, o.glonass_code_bias_window_epochs)


def _epoch_solution(st: RtkState, ctx: EpochContext, fix: _Fix | None) -> Solution:
    """The epoch's solution: the float one without a fix; else the fixed one (reported float when its σ exceeds
    max_fix_sigma_m), then the hold (holdamb) or, instantaneous AR, the ambiguities forgotten."""
    o = st.options
    if fix is None:
        st.fix_count = 0
        st.fail_count += 1
        return _solution(ctx.t_sol, st.x[:3], st.x[3:6], Q_FLOAT, ctx.ns, st.p[:3, :3], st.p[3:6, 3:6], ctx.age_s,
                         st.last_ratio)
    st.fix_count += 1
    st.fail_count = 0
    if st.init_pos_ecef_m is not None:
        st.init_pos_ecef_m = None  # the known point only seeds the first fix
    weak = math.sqrt(max(float(fix.cov.trace()), 0.0)) > o.max_fix_sigma_m
    ints = _slot_integers(fix.ref, fix.slots, fix.ints, st.ns)
    if st.lineage_id < 0 or not _same_integers(ints, st.lineage_int, 2, _groups(st)):
        st.lineage_id += 1  # another integer hypothesis than the last fix's
    st.lineage_int = ints
    sol = _solution(ctx.t_sol, fix.pos, st.x[3:6], Q_FLOAT if weak else Q_FIX, ctx.ns, fix.cov, st.p[3:6, 3:6],
                    ctx.age_s, fix.ratio, -1 if weak else st.lineage_id)
    if st.channel_code_bias is not None and not weak and st.fix_count >= o.min_hold_epochs:
        _learn_channel_code_bias(st, ctx, fix.pos)
    if o.ar_mode == "fix-and-hold" and (st.fix_count >= o.min_hold_epochs or fix.resumed):
        _holdamb(st, fix, ctx.el)
    elif o.ar_mode == "instantaneous":
        _reset_amb(st, np.arange(st.ns))
    return sol
