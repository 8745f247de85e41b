"""The simulated GNSS world: real broadcast orbits, faithful L1 signal physics, u-blox-like receivers.

API used by the receiver emulator (names are a contract):

- ``Scenario`` (hil_sim.scenario) with ``Scenario.default(model="m8t"|"lea6t", **overrides)``;
- ``World(scenario)``: raises ``onboard.errors.InputError`` with the path when the navigation file is missing
  or holds no usable GPS ephemeris for the scenario time;
- ``world.observe(receiver, t_rx_nominal) -> ObsEpoch``: `receiver` "rover" | "base"; `t_rx_nominal` the epoch
  on the receiver's nominal grid (e.g. every 200 ms on the whole second); the returned epoch's `time` is the
  receiver's tag (its clock model, see below). Observations come in time order per receiver (LLI and
  clock-reset flags refer to the previous call for that receiver);
- ``world.ephemerides() -> list[Ephemeris]``: the set being broadcast (one per healthy PRN, toe nearest the
  scenario middle; the same set is the truth orbit, plus the orbit error below);
- ``world.iono_params() -> (alpha, beta)`` Klobuchar coefficients from the navigation file header;
- ``world.trajectory`` (hil_sim.flight.Trajectory), ``world.camera_events(t0, t1) -> list[CameraEvent]``;
- ``world.truth(t) -> dict`` antenna/camera positions, attitude, armed flag, receiver clock biases;
- ``world.epoch_timing(receiver, t_rx_nominal)`` and ``world.components(receiver, t_rx_nominal)`` expose the
  exact measurement instant and every term of the observation equations for tests.

Observation equations (GPS L1 C/A, λ = c/1575.42 MHz, RINEX sign convention: phase has the sign of range,
Doppler = −range rate/λ, positive when approaching) for receiver r and satellite s at the true reception
time t (GPS time):

    pr  = ρ + c·(b_r − dt_s) + T + I + MP_code + ε_code
    cp  = (ρ + c·(b_r − dt_s) + T − I + MP_phase + ε_phase)/λ + N (+ ½ during an unresolved half cycle)
    dop = −(ρ̇ + c·(ḃ_r − ḋt_s) + d(T − I)/dt)/λ + ε_dop

- ρ: geometric range from the antenna to the satellite at transmission time t − ρ/c (light-time iteration),
  satellite position rotated by the Earth's rotation during the travel time (exact Sagnac rotation).
  Satellite truth = broadcast ephemeris + orbit error (3-D Gauss–Markov, σ `orbit_sigma_m` per axis,
  τ `orbit_tau_s` = 1 h): common to both receivers.
- dt_s: broadcast clock (af0, af1, af2 at transmission time, relativistic eccentricity term) − TGD, plus a
  satellite clock error (Gauss–Markov, σ `sat_clock_sigma_m` = 0.3 m, τ 1 h), common to both receivers.
- T: Saastamoinen with a standard atmosphere at each antenna's height (onboard.rtk.models.saastamoinen_m),
  plus a zenith residual (Gauss–Markov σ 2 cm, τ 30 min, common) mapped with 1/sin(el).
- I: Klobuchar with the file's α/β at each antenna (onboard.rtk.models.klobuchar_m) × (1 + model error,
  Gauss–Markov per satellite σ 20 %, τ 30 min, common) + a differential gradient: per satellite a random
  horizontal direction, magnitude `iono_gradient_mm_per_km` (1 mm/km) of slant delay per km of horizontal
  rover–base separation × the Klobuchar obliquity factor. Code delayed, phase advanced.
- Receiver errors, per receiver and satellite: white code σ 0.15 m, phase σ 1 mm, Doppler σ 0.05 Hz, each
  ÷ sin(el); first-order Gauss–Markov multipath, code σ 0.5 m, phase σ 1 mm (÷ sin(el)), τ 30 s
  (process sampled every 1 s, linearly interpolated); while the rover moves faster than MOVING_SPEED_M_S its
  code multipath is another process, τ `mp_tau_moving_s` (a moving antenna's reflections decorrelate faster);
  C/N0 = 35 + 15·sin(el) dB-Hz + 1 dB white noise.
  These defaults are measured on real u-blox data (`bench/error_stats.py`, see ErrorModel's fields).
- Carrier phase ambiguity N: a random integer (±500 cycles, i.e. phase starts near code/λ as u-blox's
  does) per arc; a new arc when the satellite rises above the receiver mask (5°) or after a cycle slip with
  loss of lock (Poisson, `slip_lli_rate_per_h` per satellite; LLI bit 0 on the next epoch, lock time reset).
  Undetected slips (Poisson, `slip_undetected_rate_per_h`) add ±1…3 cycles with no flag and no lock reset.
  For `half_cycle_resolve_s` after each acquisition the phase may be off by ½ cycle (probability
  `half_cycle_probability`): LLI bit 1 is set then; afterwards the receiver corrects it and reports
  `half_cyc_sub` = 1 (RXM-RAWX trkStat bit 3) for arcs where it subtracted the half cycle.
- Receiver clock: local oscillator offset β(t) = bias0 + drift·(t − start) + a random walk of the drift
  (σ `clock_drift_rw_s_s_per_sqrt_s`). The receiver measures when its oscillator reads the nominal epoch +
  `tag_offset_ms` and steps its own time by 1 ms whenever |β − J·1 ms| exceeds `clock_jump_threshold_s`
  (J the step count). Tag = nominal + offset − J ms; b_r = tag − t (the quantity in the equations). At a step
  the tag moves by 1 ms (…999 → …998 ms on a LEA-6T) while the measurement instant does not, so b_r, the
  pseudorange (by c·1 ms = 299 792.458 m) and the phase (by exactly 1 575 420 cycles, an integer, no slip)
  all jump together, as on real u-blox RXM-RAW/RAWX; the RAWX `clock_reset` flag marks the epoch after it.

Other constellations (`Scenario.systems`, e.g. "GREJ"; worlds in hil_sim.scenario.MULTI_WORLDS): the same
equations per satellite on its own carrier (hil_sim.constellations: Galileo E1/QZSS L1 1575.42 MHz, BeiDou B1I,
GLONASS 1602 + 0.5625·k MHz with k from its ephemeris; λ, Doppler and the ionosphere ×(f_L1/f)² follow), the
satellites from the engine's own models (onboard.rtk.navstore.satellite_state: GLONASS state-vector integration,
Galileo/QZSS/BeiDou Kepler, L1-band group delay). GLONASS code and phase carry the receiver type's
inter-frequency biases (ReceiverModel.ifb_type; identical for two receivers of one type). The LEA-6T tracks GPS
only. Epochs then fill `glo_fcn` and `signal`. A GPS-only scenario ("G") keeps its historical random layout
and reproduces bit for bit.

`Scenario.rover_environment` (e.g. HARSH, fitted to a real walk under trees, docs/hil-sim-error-model.md)
adds, for the rover only, blockage by elevation/azimuth with reacquisition arcs, receiver-wide and independent
LLI slips, slips without LLI, C/N0-driven noise in place of the 1/sin(el) law, and a code error per arc (drawn
at each acquisition or slip: a constant plus a part decaying over the arc's first seconds).

The common slowly varying errors (orbit, satellite clock, ionosphere model error, troposphere residual) are
Gauss–Markov samples every `SMOOTH_DT_S` (300 s) joined by cubic splines: their σ and τ as stated, their rates
continuous (a rover epoch differenced with a 20-s-old base epoch sees them drift smoothly, as real ones do).

Everything random is drawn from `np.random.default_rng` seeded by (scenario seed, purpose, receiver,
satellite, epoch): a scenario reproduces exactly, in any order of calls (except the LLI/clock-reset flags,
which compare with the previous call). `ErrorModel.noise_free()` removes every random error.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline
from scipy.signal import lfilter

from hil_sim.camera import CameraEvent, camera_events
from hil_sim.constellations import (
    SIGNAL_CODE,
    SatelliteLayout,
    carrier_hz,
    glonass_ifb,
    parse_systems,
    read_navigation,
    sat_of,
    select_broadcast,
)
from hil_sim.flight import Trajectory
from hil_sim.scenario import ReceiverModel, RoverEnvironment, Scenario
from onboard.errors import InputError
from onboard.gnsstime import NS_PER_S, GpsTime, leap_seconds_at_utc
from onboard.rtk.consts import CLIGHT_M_S, FREQ_L1_HZ, GLO_FCN_MAX, GLO_FCN_MIN, OMEGA_E_RAD_S
from onboard.rtk.ephemeris import eph_position, eph_position_velocity
from onboard.rtk.geodesy import ecef_to_llh, enu_rotation
from onboard.rtk.glonass import glonass_position
from onboard.rtk.models import klobuchar_m, saastamoinen_m
from onboard.rtk.navstore import AnyEphemeris, BroadcastNavigation, satellite_state
from onboard.rtk.types import FCN_NONE, GNSS_GLONASS, GNSS_GPS, LLI_HALF_CYCLE, LLI_SLIP, Ephemeris, ObsEpoch

log = logging.getLogger(__name__)

Vec = npt.NDArray[np.float64]
RECEIVERS = ("rover", "base")
MARGIN_S = 300.0
"""Span simulated before the start and after the end of the scenario (s); observations outside raise."""
SLOW_DT_S = 10.0
FAST_DT_S = 1.0
SMOOTH_DT_S = 300.0
"""Knot spacing of the common slowly varying errors (orbit, satellite clock, ionosphere model error,
troposphere residual): Gauss–Markov samples every 300 s joined by a cubic spline. Linear interpolation of
10-s samples gave them random rates changing every 10 s (slant ionosphere 1-2 cm/s ≈ 6-12 TECU/min, storm
level; satellite clocks 3 cm in 20 s where GPS clocks drift millimetres); 60-s knots still bent by 5-8 cm
over 20 s. Harmless while base and rover observe at the same instant (the errors cancel); unphysical once a
rover epoch is differenced with an older base epoch (radio gaps), where real broadcast-model errors drift
smoothly (travelling ionospheric disturbances: ≤ 1 TECU over 10-60 min, millimetres of curvature in 20 s)."""
AMBIGUITY_RANGE_CYC = 500
MOVING_SPEED_M_S = 0.5
"""Rover speed above which its code multipath follows the moving-antenna process (ErrorModel.mp_tau_moving_s)."""

# Purposes of the random streams (part of every seed so streams never overlap).
_P_ORBIT, _P_SATCLK, _P_IONO, _P_TROPO, _P_GRAD, _P_MP, _P_CLOCK, _P_TRACK, _P_EPOCH, _P_IFB, _P_BLOCK, _P_CN0, _P_ARC = (
    range(1, 14))


def _sat_position(eph: AnyEphemeris, t: GpsTime) -> Vec:
    """Broadcast satellite position (ECEF of the instant `t`), either ephemeris kind."""
    if isinstance(eph, Ephemeris):
        return eph_position(eph, t)[0]
    return glonass_position(eph, t)[0]


class OutsideSimulatedSpan(ValueError):
    """A time outside [start − MARGIN_S, start + duration_s + MARGIN_S] was asked for: the scenario has ended
    (or not begun). The emulator should stop or be built with a longer `Scenario.duration_s`."""


def _rng(*key: int) -> np.random.Generator:
    return np.random.default_rng([k & 0xFFFFFFFF for k in key])


def _gauss_markov(rng: np.random.Generator, n: int, cols: int, dt_s: float, tau_s: float) -> Vec:
    """(n, cols) samples of a stationary unit-variance first-order Gauss–Markov process every `dt_s`."""
    phi = math.exp(-dt_s / tau_s)
    x0 = rng.standard_normal(cols)
    w = rng.standard_normal((n, cols)) * math.sqrt(1.0 - phi * phi)
    w[0] = x0
    return np.asarray(lfilter([1.0], [1.0, -phi], w, axis=0))


class _Grid:
    """Uniform time grid from `t0_ns` with step `dt_s`; linear interpolation of sampled processes."""

    def __init__(self, t0_ns: int, dt_s: float, n: int) -> None:
        self.t0_ns = t0_ns
        self.dt_ns = round(dt_s * NS_PER_S)
        self.dt_s = dt_s
        self.n = n

    def locate(self, t: GpsTime) -> tuple[int, float]:
        x = (t.total_ns - self.t0_ns) / self.dt_ns
        if x < 0 or x > self.n - 1:
            raise OutsideSimulatedSpan(f"time {t} is outside the simulated span; extend Scenario.duration_s")
        i = min(int(x), self.n - 2)
        return i, x - i

    def interp(self, values: Vec, t: GpsTime) -> Vec:
        i, f = self.locate(t)
        return np.asarray(values[i] * (1.0 - f) + values[i + 1] * f)

    def time(self, i: int) -> GpsTime:
        return GpsTime.from_total_ns(self.t0_ns + i * self.dt_ns)


class _SplineGrid(_Grid):
    """A knot grid whose sampled processes are joined by cubic splines (continuous rates)."""

    def spline(self, values: Vec) -> CubicSpline:
        """The spline through (n, cols) samples at the knots, over knot index."""
        return CubicSpline(np.arange(self.n, dtype=float), values, axis=0)

    def at(self, spline: CubicSpline, t: GpsTime) -> Vec:
        """The spline's (cols,) values at time `t`."""
        i, f = self.locate(t)
        return np.asarray(spline(i + f))


@dataclass(frozen=True)
class EpochTiming:
    """When an epoch is measured: `t_rx_nominal` requested, `tag` the receiver's time tag, `t_true` the GPS
    time of the measurement, `clock_bias_s` = tag − t_true exactly, `clock_drift_s_s`, `jumps` the 1-ms
    steps taken so far (signed)."""

    t_rx_nominal: GpsTime
    tag: GpsTime
    t_true: GpsTime
    clock_bias_s: float
    clock_drift_s_s: float
    jumps: int


@dataclass
class _Track:
    """Tracking history of one satellite at one receiver: acquisitions, slips, ambiguities (all ns times).

    `resets_ns` sorted acquisition instants (arc starts and LLI slips) with `reset_lli` (True for slips),
    `reset_n_cyc` the ambiguity drawn at each, `reset_half` whether a half cycle is pending after it;
    `arc_ends_ns` instants where tracking stops (setting); `jumps_ns`/`jumps_cyc` undetected slips.
    """

    resets_ns: list[int]
    reset_lli: list[bool]
    reset_n_cyc: list[int]
    reset_half: list[bool]
    jumps_ns: list[int]
    jumps_cyc: list[int]


class _Clock:
    """A receiver clock on the fast grid: oscillator offset β, its drift, the 1-ms step count J."""

    def __init__(self, model: ReceiverModel, grid: _Grid, start_ns: int, rw: float, rng: np.random.Generator) -> None:
        self.model = model
        self.grid = grid
        n = grid.n
        drift = model.clock_drift_s_s + np.cumsum(rng.standard_normal(n) * rw * math.sqrt(grid.dt_s))
        beta = np.concatenate(([0.0], np.cumsum(drift[:-1] * grid.dt_s)))
        k0 = (start_ns - grid.t0_ns) / grid.dt_ns
        beta += model.clock_bias0_s - np.interp(k0, np.arange(n), beta)
        self.beta = beta
        self.drift = drift
        thr = model.clock_jump_threshold_s
        jumps = np.zeros(n, dtype=np.int64)
        j = 0
        for k in range(n):
            while beta[k] - j * 1e-3 > thr:
                j += 1
            while beta[k] - j * 1e-3 < -thr:
                j -= 1
            jumps[k] = j
        self.jumps = jumps

    def beta_at(self, t: GpsTime) -> float:
        return float(self.grid.interp(self.beta, t))

    def timing(self, t_nom: GpsTime) -> EpochTiming:
        local = t_nom.add_ns(self.model.tag_offset_ms * 1_000_000)
        t = local
        for _ in range(3):
            t = local.add_s(-self.beta_at(t))
        i, _ = self.grid.locate(t)
        j = int(self.jumps[i])
        tag = local.add_ns(-j * 1_000_000)
        return EpochTiming(t_nom, tag, t, tag.diff_ns(t) / NS_PER_S, float(self.drift[i]), j)


PLL_NOISE_BANDWIDTH_HZ = 15.0
"""Carrier loop noise bandwidth assumed for the receiver's own phase-precision estimate (cpStdev), Hz."""
PLL_PREDETECTION_S = 0.001
"""Coherent integration time of the carrier loop (one C/A code period), s."""


def pll_thermal_sigma_cyc(cn0_dbhz: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The carrier-phase σ a receiver reports for itself (u-blox cpStdev): PLL thermal jitter from C/N0, cycles.

    σ = √(B_n / (C/N0) · (1 + 1 / (2·T·C/N0))) / 2π (Kaplan & Hegarty, eq. 5.9). Receivers report their
    tracking noise, not multipath: about 0.003 cycles at 45 dB-Hz, 0.012 at 35 dB-Hz, 0.024 at 30 dB-Hz — so
    RTKLIB's cpStdev validity rule (≤ 0.020 cycles) drops only weak signals, as on a real M8T.
    """
    cn0 = 10.0 ** (np.asarray(cn0_dbhz, dtype=float) / 10.0)
    var_rad2 = PLL_NOISE_BANDWIDTH_HZ / cn0 * (1.0 + 1.0 / (2.0 * PLL_PREDETECTION_S * cn0))
    return np.sqrt(var_rad2) / (2.0 * np.pi)


class World:
    """GNSS physics of one scenario (see module docstring). Pure computation after construction."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        sc = scenario
        em = sc.errors
        nav_path = Path(sc.nav_path)
        if not nav_path.is_file():
            raise InputError(
                f"navigation file {nav_path} not found: the simulator needs real broadcast orbits "
                "(Scenario.nav_path; default hil_sim/data/broadcast-nav-20100701/brdc1820.10n, shipped with the package)"
            )
        systems = parse_systems(sc.systems)
        all_ephs, self._alpha, self._beta = read_navigation([nav_path, *sc.extra_nav_paths])
        self.start = sc.start
        self.end = sc.start.add_s(sc.duration_s)
        mid = sc.start.add_s(sc.duration_s / 2)
        best = select_broadcast(all_ephs, systems, mid, sc.duration_s, MARGIN_S)
        if not any(g == GNSS_GPS for g, _ in best) and systems == (GNSS_GPS,):
            raise InputError(f"{nav_path}: no healthy GPS ephemeris valid over the scenario ({sc.start}, "
                             f"{sc.duration_s} s)")
        if not best:
            raise InputError(f"{nav_path}: no healthy ephemeris of {sc.systems} valid over the scenario "
                             f"({sc.start}, {sc.duration_s} s)")
        self.layout = SatelliteLayout(gps_only=systems == (GNSS_GPS,))
        n_cols = self.layout.n_cols
        self._n_cols = n_cols
        self._eph: dict[int, AnyEphemeris] = {self.layout.column(*k): e for k, e in best.items()}
        self.cols = sorted(self._eph)
        """Columns of the simulated satellites (hil_sim.constellations.SatelliteLayout)."""
        self._sat = {c: sat_of(e) for c, e in self._eph.items()}
        self.prns = sorted(sv for g, sv in best if g == GNSS_GPS)
        """GPS PRNs with a broadcast ephemeris (the GPS part of `cols`)."""
        self._freq_hz = np.full(n_cols, FREQ_L1_HZ)
        self._glo_fcn = np.full(n_cols, FCN_NONE, dtype=np.int8)
        for c, e in self._eph.items():
            self._freq_hz[c] = carrier_hz(e)
            if self._sat[c][0] == GNSS_GLONASS:
                self._glo_fcn[c] = e.channel  # type: ignore[union-attr]
        self._lambda_m = CLIGHT_M_S / self._freq_hz
        self._leap_s = leap_seconds_at_utc(sc.start.to_gpst_datetime())
        self.trajectory = Trajectory(sc.flight, sc.start, sc.site_lat_deg, sc.site_lon_deg, sc.site_h_m)
        self.base_ecef_m = self.trajectory.enu_to_ecef(np.asarray(sc.base_offset_enu_m, dtype=float))
        self._base_enu_m = np.asarray(sc.base_offset_enu_m, dtype=float)
        self._r_ecef_to_enu = enu_rotation(self.trajectory.lat_rad, self.trajectory.lon_rad)

        t0_ns = sc.start.total_ns - round(MARGIN_S * NS_PER_S)
        span_s = sc.duration_s + 2 * MARGIN_S
        self._slow = _Grid(t0_ns, SLOW_DT_S, math.ceil(span_s / SLOW_DT_S) + 2)
        self._fast = _Grid(t0_ns, FAST_DT_S, math.ceil(span_s / FAST_DT_S) + 2)
        seed = sc.seed
        nf = self._fast.n
        self._smooth = _SplineGrid(t0_ns, SMOOTH_DT_S, math.ceil(span_s / SMOOTH_DT_S) + 4)
        nk = self._smooth.n
        self._orbit_err = self._smooth.spline(em.orbit_sigma_m * _gauss_markov(
            _rng(seed, _P_ORBIT), nk, 3 * n_cols, SMOOTH_DT_S, em.orbit_tau_s))
        self._satclk_err_m = self._smooth.spline(em.sat_clock_sigma_m * _gauss_markov(
            _rng(seed, _P_SATCLK), nk, n_cols, SMOOTH_DT_S, em.sat_clock_tau_s))
        self._iono_err = self._smooth.spline(em.iono_model_error_fraction * _gauss_markov(
            _rng(seed, _P_IONO), nk, n_cols, SMOOTH_DT_S, em.iono_model_error_tau_s))
        self._tropo_res_m = self._smooth.spline(em.tropo_residual_zenith_sigma_m * _gauss_markov(
            _rng(seed, _P_TROPO), nk, 1, SMOOTH_DT_S, em.tropo_residual_tau_s))
        ang = _rng(seed, _P_GRAD).uniform(0.0, 2 * math.pi, n_cols)
        self._iono_grad_enu = em.iono_gradient_mm_per_km * 1e-6 * np.stack([np.sin(ang), np.cos(ang)], axis=1)
        models = {"rover": sc.rover_receiver, "base": sc.base_receiver}
        self._mp_code: dict[str, Vec] = {}
        self._mp_phase: dict[str, Vec] = {}
        self._clock: dict[str, _Clock] = {}
        self._tracks: dict[str, list[_Track | None]] = {}
        self._blocked: dict[str, npt.NDArray[np.bool_]] = {}
        self._model = models
        # the moving rover's code multipath: its own process (new reflection geometry at every metre)
        self._mp_code_moving = _gauss_markov(_rng(seed, _P_MP, 0, 2), nf, n_cols, FAST_DT_S, em.mp_tau_moving_s)
        # the rover's C/N0 deviation when it is the signal's own attenuation (RoverEnvironment.cn0_tau_s), dB
        env = sc.rover_environment
        self._cn0_dev_db: Vec | None = None
        if env is not None and env.cn0_tau_s:
            parts = [_gauss_markov(_rng(seed, _P_CN0, k), nf, n_cols, FAST_DT_S, tau) for k, tau in enumerate(env.cn0_tau_s)]
            self._cn0_dev_db = env.cn0_sigma_dbhz * np.sum(parts, axis=0) / math.sqrt(len(parts))
        for r_idx, rcv in enumerate(RECEIVERS):
            self._mp_code[rcv] = _gauss_markov(_rng(seed, _P_MP, r_idx, 0), nf, n_cols, FAST_DT_S, em.mp_tau_s)
            self._mp_phase[rcv] = _gauss_markov(_rng(seed, _P_MP, r_idx, 1), nf, n_cols, FAST_DT_S, em.mp_tau_s)
            same_clock = rcv == "base" and sc.base_receiver == sc.rover_receiver
            self._clock[rcv] = _Clock(models[rcv], self._fast, sc.start.total_ns, em.clock_drift_rw_s_s_per_sqrt_s,
                                      _rng(seed, _P_CLOCK, 0 if same_clock else r_idx))
            self._tracks[rcv] = self._build_tracks(r_idx, rcv)
        # GLONASS inter-frequency biases per receiver type (identical for two receivers of one type), and each
        # unit's own code delay per channel (not: the two M8Ps of the real sets differ by metres on some channels)
        self._code_ifb_m: dict[str, Vec] = {}
        self._phase_ifb_m: dict[str, Vec] = {}
        glo = self._glo_fcn != FCN_NONE
        for r_idx, rcv in enumerate(RECEIVERS):
            code, phase = np.zeros(n_cols), np.zeros(n_cols)
            if glo.any():
                code[glo], phase[glo] = glonass_ifb(models[rcv].ifb_type, self._glo_fcn[glo], (seed, _P_IFB))
                unit = _rng(seed, _P_IFB, r_idx, 1).standard_normal(GLO_FCN_MAX - GLO_FCN_MIN + 1)
                code[glo] += em.glonass_unit_code_sigma_m * unit[self._glo_fcn[glo] - GLO_FCN_MIN]
            self._code_ifb_m[rcv], self._phase_ifb_m[rcv] = code, phase
        self._last_obs: dict[str, tuple[int, int] | None] = {"rover": None, "base": None}
        self._arc_draws: dict[tuple[int, int], tuple[float, float]] = {}
        """The rover's per-arc code error draws (persistent, at acquisition) by (column, reset index)."""

    # ------------------------------------------------------------------------------- public queries
    def ephemerides(self) -> list[Ephemeris]:
        """The GPS broadcast ephemerides (one per healthy PRN) valid over the whole scenario."""
        return [e for c in self.cols if isinstance(e := self._eph[c], Ephemeris) and e.gnss_id == GNSS_GPS]

    def broadcast_navigation(self) -> BroadcastNavigation:
        """Every system's broadcast set (the truth orbits) for the engine (`Nav.broadcast`)."""
        return BroadcastNavigation(self._eph[c] for c in self.cols)

    def glonass_channels(self) -> dict[int, int]:
        """GLONASS slot → frequency channel k of the simulated satellites."""
        return {sv: int(self._glo_fcn[c]) for c, (g, sv) in self._sat.items() if g == GNSS_GLONASS}

    def satellites(self) -> list[tuple[int, int]]:
        """(gnssId, svId) of every simulated satellite, in column order."""
        return [self._sat[c] for c in self.cols]

    def iono_params(self) -> tuple[tuple[float, ...] | None, tuple[float, ...] | None]:
        """Klobuchar (α, β) of the navigation file header (None when absent)."""
        return self._alpha, self._beta

    def camera_events(self, t0: GpsTime, t1: GpsTime) -> list[CameraEvent]:
        """Camera trigger pulses in [t0, t1) with their flashes (pulses before valid time suppressed)."""
        valid_from = self.start.add_s(self.scenario.camera.valid_after_s)
        return camera_events(self.scenario.camera, t0, t1, valid_from, self.scenario.seed)

    def receiver_position_ecef_m(self, receiver: str, t: GpsTime) -> Vec:
        """Antenna phase centre of `receiver` at GPS time `t` (ECEF m)."""
        if receiver == "base":
            return self.base_ecef_m.copy()
        if receiver == "rover":
            return self.trajectory.position_ecef_m(t)
        raise ValueError(f"unknown receiver {receiver!r} (expected 'rover' or 'base')")

    def epoch_timing(self, receiver: str, t_rx_nominal: GpsTime) -> EpochTiming:
        """Measurement instant, tag and clock state of `receiver` for the nominal epoch `t_rx_nominal`."""
        if receiver not in RECEIVERS:
            raise ValueError(f"unknown receiver {receiver!r} (expected 'rover' or 'base')")
        return self._clock[receiver].timing(t_rx_nominal)

    def truth(self, t: GpsTime) -> dict[str, Any]:
        """Ground truth at GPS time `t`: rover antenna/camera (ECEF m), velocity, attitude, armed flag, base
        antenna, receiver clock biases (β − J·1 ms, s) and 1-ms step counts."""
        st = self.trajectory.state(t)
        out: dict[str, Any] = {
            "time": t, "antenna_ecef_m": st.pos_ecef_m, "antenna_vel_ecef_m_s": st.vel_ecef_m_s,
            "antenna_enu_m": st.pos_enu_m, "camera_ecef_m": st.camera_ecef_m, "camera_enu_m": st.camera_enu_m,
            "r_cam_to_enu": st.r_cam_to_enu, "roll_deg": math.degrees(st.roll_rad),
            "pitch_deg": math.degrees(st.pitch_rad), "yaw_deg": math.degrees(st.yaw_rad), "armed": st.armed,
            "phase": st.phase, "line_index": st.line_index, "rover_ecef_m": st.pos_ecef_m,
            "rover_vel_ecef_m_s": st.vel_ecef_m_s, "base_ecef_m": self.base_ecef_m.copy(),
            "base_vel_ecef_m_s": np.zeros(3),
            "enu_origin_ecef_m": self.trajectory.origin_ecef_m.copy(),
            "lever_arm_cam_m": np.asarray(self.scenario.flight.lever_arm_cam_m, dtype=float),
        }
        for rcv in RECEIVERS:
            clk = self._clock[rcv]
            i, _ = self._fast.locate(t)
            out[f"{rcv}_clock_bias_s"] = clk.beta_at(t) - int(clk.jumps[i]) * 1e-3
            out[f"{rcv}_clock_drift_s_s"] = float(clk.drift[i])
            out[f"{rcv}_clock_jumps"] = int(clk.jumps[i])
        return out

    def observe(self, receiver: str, t_rx_nominal: GpsTime) -> ObsEpoch:
        """The L1 observables `receiver` reports for its nominal epoch `t_rx_nominal` (time = its tag)."""
        return self._simulate(receiver, t_rx_nominal)[0]

    def observe_detailed(self, receiver: str, t_rx_nominal: GpsTime) -> tuple[ObsEpoch, dict[str, Any]]:
        """`observe` and `components` in one computation (for tests and truth logging)."""
        return self._simulate(receiver, t_rx_nominal)

    def components(self, receiver: str, t_rx_nominal: GpsTime) -> dict[str, Any]:
        """Every term of the observation equations for one epoch (arrays aligned with the epoch's sv_id)."""
        return self._simulate(receiver, t_rx_nominal, update_state=False)[1]

    # ------------------------------------------------------------------------------------ internals
    def _geometry(self, col: int, t: GpsTime, rcv_ecef: Vec, rcv_vel: Vec) -> dict[str, Any]:
        """Light-time solution for a receiver at `rcv_ecef` (ECEF m, moving at `rcv_vel`) at GPS time t:
        range (m), range rate (m/s), satellite position/velocity rotated into the ECEF frame of reception,
        satellite clock (s, incl. relativity, −TGD and the clock error) and drift (s/s)."""
        eph = self._eph[col]
        orbit_err = self._smooth.at(self._orbit_err, t)[3 * col:3 * col + 3]
        clk_err_s = float(self._smooth.at(self._satclk_err_m, t)[col]) / CLIGHT_M_S
        tau = 0.075
        rot = np.eye(3)
        pos_r = np.zeros(3)
        rho = 0.0
        for _ in range(3):  # converges to < 1e-12 s: the first guess is within ~10 ms
            pos = _sat_position(eph, t.add_s(-tau))
            th = OMEGA_E_RAD_S * tau
            c, s = math.cos(th), math.sin(th)
            rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
            pos_r = rot @ (pos + orbit_err)
            rho = float(np.linalg.norm(pos_r - rcv_ecef))
            tau = rho / CLIGHT_M_S
        t_tx = t.add_s(-tau)
        if isinstance(eph, Ephemeris) and eph.gnss_id == GNSS_GPS:
            pos, vel, clk, drift = eph_position_velocity(eph, t_tx)
            clk -= eph.tgd_s
        else:  # the engine's model of every other system (GLONASS state vector, Galileo/QZSS/BeiDou Kepler)
            st = satellite_state(eph, t_tx)
            pos, vel, clk, drift = st.pos_m, st.vel_m_s, st.clock_s, st.drift_s_s
        pos_r = rot @ (pos + orbit_err)
        rho = float(np.linalg.norm(pos_r - rcv_ecef))
        los = (pos_r - rcv_ecef) / rho
        vel_r = rot @ vel
        e_vs = float(los @ vel_r)
        rho_dot = (e_vs - float(los @ rcv_vel)) / (1.0 + e_vs / CLIGHT_M_S)
        return {"rho_m": rho, "rho_dot_m_s": rho_dot, "sat_pos_m": pos_r, "sat_vel_m_s": vel_r,
                "sat_clock_s": clk + clk_err_s, "sat_drift_s_s": drift, "los": los, "t_tx": t_tx}

    def _delays(self, t: GpsTime, lat: float, lon: float, h: float, az: Vec, el: Vec, d_enu: Vec,
                col: npt.NDArray[np.int_]) -> tuple[Vec, Vec, Vec, Vec]:
        """(troposphere, ionosphere, Saastamoinen part, Klobuchar part) slant delays (m); the ionosphere on
        each satellite's own carrier (Klobuchar's L1 delay × (f_L1/f)²)."""
        sin_el = np.sin(np.maximum(el, math.radians(1.0)))
        tropo_model = saastamoinen_m(lat, h, el)
        tropo = tropo_model + float(self._smooth.at(self._tropo_res_m, t)[0]) / sin_el
        iono_model = klobuchar_m(t.tow_s, lat, lon, az, el, self._alpha, self._beta)
        obliquity = 1.0 + 16.0 * (0.53 - el / math.pi) ** 3
        grad = self._iono_grad_enu[col] @ d_enu[:2] if col.size else np.zeros(0)
        iono = iono_model * (1.0 + self._smooth.at(self._iono_err, t)[col]) + grad * obliquity
        scale = (FREQ_L1_HZ / self._freq_hz[col]) ** 2
        return tropo, iono * scale, tropo_model, iono_model * scale

    def _elevation_grid(self, receiver: str) -> tuple[Vec, Vec]:
        """Elevation and azimuth (rad) of every column (NaN without ephemeris) at the slow grid's instants."""
        g = self._slow
        el = np.full((g.n, self._n_cols), np.nan)
        az = np.full((g.n, self._n_cols), np.nan)
        for k in range(g.n):
            t = g.time(k)
            rcv = self._position_clamped(receiver, t)
            lat, lon, _ = ecef_to_llh(rcv)
            r = enu_rotation(lat, lon)
            for col in self.cols:
                enu = r @ (_sat_position(self._eph[col], t.add_s(-0.075)) - rcv)
                el[k, col] = math.atan2(enu[2], math.hypot(enu[0], enu[1]))
                az[k, col] = math.atan2(enu[0], enu[1]) % (2 * math.pi)
        return el, az

    def _blockage(self, r_idx: int, col: int, el: Vec, az: Vec, env: RoverEnvironment) -> npt.NDArray[np.bool_]:
        """Blocked flag of one satellite on the fast grid: a two-state chain whose unavailability follows the
        environment's elevation bands × azimuth factors (RoverEnvironment), mean outage `outage_mean_s`."""
        f = self._fast
        x = np.arange(f.n) * f.dt_s / self._slow.dt_s
        el_f = np.interp(x, np.arange(self._slow.n), el)
        az_f = az[np.minimum(np.floor(x).astype(int), self._slow.n - 1)]
        band = np.searchsorted(np.asarray(env.el_bands_deg), np.degrees(el_f), side="right") - 1
        u = np.where(band >= 0, np.asarray(env.unavailability)[np.maximum(band, 0)], 0.0)
        sector = (np.nan_to_num(np.degrees(az_f)) // (360.0 / len(env.az_factor))).astype(int) % len(env.az_factor)
        u = np.clip(u * np.asarray(env.az_factor)[sector], 0.0, 0.95)
        p_unblock = min(1.0, f.dt_s / env.outage_mean_s)
        p_block = np.minimum(1.0, p_unblock * u / np.maximum(1.0 - u, 1e-9))
        draw = _rng(self.scenario.seed, _P_BLOCK, r_idx, col + 1).random(f.n)
        blocked = np.zeros(f.n, bool)
        state = False
        for k in range(f.n):
            state = draw[k] >= p_unblock if state else draw[k] < p_block[k]
            blocked[k] = state
        return blocked

    def _position_clamped(self, receiver: str, t: GpsTime) -> Vec:
        return self.receiver_position_ecef_m(receiver, t)

    def _build_tracks(self, r_idx: int, receiver: str) -> list[_Track | None]:
        """Acquisitions, slips and ambiguities of every satellite at `receiver` over the simulated span."""
        em = self.scenario.errors
        mask = math.radians(self._model[receiver].elevation_mask_deg)
        el, az = self._elevation_grid(receiver)
        env = self.scenario.rover_environment if receiver == "rover" else None
        lli_rate = env.lli_slips_per_h if env else em.slip_lli_rate_per_h
        und_rate = env.unflagged_slips_per_h if env else em.slip_undetected_rate_per_h
        common_ns: list[int] = []
        if env is not None:
            rc = _rng(self.scenario.seed, _P_BLOCK, r_idx, 0)
            span = (self._slow.n - 1) * self._slow.dt_ns
            n_common = rc.poisson(env.common_slip_events_per_h * span / 3.6e12)
            common_ns = sorted(int(x) for x in self._slow.t0_ns + rc.uniform(0, span, n_common))
            self._blocked[receiver] = np.zeros((self._fast.n, self._n_cols), bool)
        if receiver == "rover":
            self._el_grid_rover = el
        else:
            self._el_grid_base = el
        g = self._slow
        span_ns = (g.n - 1) * g.dt_ns
        tracks: list[_Track | None] = [None] * self._n_cols
        for col in self.cols:
            rng = _rng(self.scenario.seed, _P_TRACK, r_idx, col + 1)
            e = el[:, col] - mask
            resets: list[tuple[int, bool]] = []
            if e[0] >= 0:
                resets.append((g.t0_ns, False))
            for k in range(1, g.n):
                if e[k - 1] < 0 <= e[k]:
                    frac = -e[k - 1] / (e[k] - e[k - 1])
                    resets.append((g.t0_ns + round((k - 1 + frac) * g.dt_ns), False))
            span_h = span_ns / 3.6e12
            n_lli = rng.poisson(lli_rate * span_h)
            n_und = rng.poisson(und_rate * span_h)
            lli_t = sorted(int(x) for x in g.t0_ns + rng.uniform(0, span_ns, n_lli))
            und_t = sorted(int(x) for x in g.t0_ns + rng.uniform(0, span_ns, n_und))
            resets += [(t, True) for t in lli_t]
            if env is not None:  # receiver-wide slips and the reacquisitions after each blockage
                blocked = self._blockage(r_idx, col, el[:, col], az[:, col], env)
                self._blocked[receiver][:, col] = blocked
                ends = np.flatnonzero(blocked[:-1] & ~blocked[1:]) + 1
                resets += [(t, True) for t in common_ns]
                # reacquired half a step before the first unblocked sample: the first epoch seen again is the new arc
                resets += [(self._fast.t0_ns + int(k) * self._fast.dt_ns - self._fast.dt_ns // 2, True) for k in ends]
            resets.sort()
            mag = rng.integers(1, max(1, em.slip_undetected_max_cyc) + 1, n_und)
            sign = rng.choice(np.array([-1, 1]), n_und)
            tracks[col] = _Track(
                resets_ns=[t for t, _ in resets], reset_lli=[lli for _, lli in resets],
                reset_n_cyc=[int(x) for x in rng.integers(-AMBIGUITY_RANGE_CYC, AMBIGUITY_RANGE_CYC + 1, len(resets))],
                reset_half=[bool(x) for x in rng.random(len(resets)) < em.half_cycle_probability],
                jumps_ns=und_t, jumps_cyc=[int(a * b) for a, b in zip(mag, sign)],
            )
        return tracks

    def _tracked(self, receiver: str, col: int, t: GpsTime) -> bool:
        el = self._el_grid_rover if receiver == "rover" else self._el_grid_base
        mask = math.radians(self._model[receiver].elevation_mask_deg)
        blocked = self._blocked.get(receiver)
        if blocked is not None:
            i, f = self._fast.locate(t)
            if blocked[i + (f >= 0.5), col]:
                return False
        return bool(self._slow.interp(el[:, col], t) >= mask)

    def _arc_code_m(self, env: RoverEnvironment, r_idx: int, col: Vec, arc: list[int], age_s: Vec, scale: Vec) -> Vec:
        """The rover's code error of each satellite's current arc (m): a constant drawn at its acquisition (or
        slip; `arc` its index in the track, `age_s` the time since) plus a part decaying from it over
        acq_code_tau_s, both at σ env.*_ref_m × `scale` (the C/N0 law of this epoch, without GLONASS's chip
        factor). See RoverEnvironment.arc_code_sigma_ref_m."""
        out = np.zeros(col.size)
        seed = self.scenario.seed
        for i, (c, k) in enumerate(zip(col.tolist(), arc, strict=True)):
            draw = self._arc_draws.get((c, k))
            if draw is None:
                z = _rng(seed, _P_ARC, r_idx, c, k).standard_normal(2)
                draw = self._arc_draws[(c, k)] = (float(z[0]), float(z[1]))
            out[i] = scale[i] * (env.arc_code_sigma_ref_m * draw[0] + env.acq_code_sigma_ref_m * draw[1]
                                 * math.exp(-max(float(age_s[i]), 0.0) / env.acq_code_tau_s))
        return out

    def _simulate(self, receiver: str, t_nom: GpsTime, update_state: bool = True) -> tuple[ObsEpoch, dict[str, Any]]:
        if receiver not in RECEIVERS:
            raise ValueError(f"unknown receiver {receiver!r} (expected 'rover' or 'base')")
        sc = self.scenario
        em = sc.errors
        model = self._model[receiver]
        r_idx = RECEIVERS.index(receiver)
        timing = self._clock[receiver].timing(t_nom)
        t = timing.t_true
        self._slow.locate(t)  # raises outside the simulated span
        if receiver == "rover":
            st = self.trajectory.state(t)
            rcv, rcv_vel, rcv_enu = st.pos_ecef_m, st.vel_ecef_m_s, st.pos_enu_m
        else:
            rcv, rcv_vel, rcv_enu = self.base_ecef_m, np.zeros(3), self._base_enu_m
        lat, lon, h = ecef_to_llh(rcv)
        r_enu = enu_rotation(lat, lon)
        d_enu = rcv_enu - self._base_enu_m  # horizontal separation from the base drives the iono gradient

        # Per-epoch white noise, fixed layout over all columns so it does not depend on the visible set.
        noise = _rng(sc.seed, _P_EPOCH, r_idx, t_nom.total_ns, t_nom.total_ns >> 32).standard_normal(
            (4, self._n_cols))
        prev = self._last_obs[receiver]
        prev_ns = prev[0] if prev is not None and prev[0] < t.total_ns else t.total_ns - NS_PER_S
        prev_jumps = prev[1] if prev is not None else timing.jumps

        rows: list[dict[str, Any]] = []
        for c in self.cols:
            if not model.tracks(self._sat[c][0]) or not self._tracked(receiver, c, t):
                continue
            geo = self._geometry(c, t, rcv, rcv_vel)
            enu = r_enu @ (geo["sat_pos_m"] - rcv)
            el_s = math.atan2(enu[2], math.hypot(enu[0], enu[1]))
            az_s = math.atan2(enu[0], enu[1]) % (2 * math.pi)
            rows.append({"col": c, "el": el_s, "az": az_s, **geo})
        if len(rows) > model.max_sats:
            rows = sorted(sorted(rows, key=lambda r: -r["el"])[: model.max_sats], key=lambda r: r["col"])
        n = len(rows)
        col = np.array([r["col"] for r in rows], dtype=int)
        gnss_arr = np.array([self._sat[c][0] for c in col], dtype=np.int8)
        prn_arr = np.array([self._sat[c][1] for c in col], dtype=np.int16)
        lam = self._lambda_m[col]
        el = np.array([r["el"] for r in rows])
        az = np.array([r["az"] for r in rows])
        rho = np.array([r["rho_m"] for r in rows])
        rho_dot = np.array([r["rho_dot_m_s"] for r in rows])
        dts = np.array([r["sat_clock_s"] for r in rows])
        dts_dot = np.array([r["sat_drift_s_s"] for r in rows])
        sin_el = np.sin(np.maximum(el, math.radians(1.0)))

        tropo, iono, tropo_model, iono_model = self._delays(t, lat, lon, h, az, el, d_enu, col)
        # Rate of the atmospheric terms (phase rate = Doppler): central difference along the motion of the
        # line of sight (elevation rate from the relative velocity) and of the receiver.
        los = np.array([r["los"] for r in rows]).reshape(n, 3)
        v_rel = np.array([r["sat_vel_m_s"] for r in rows]).reshape(n, 3) - rcv_vel
        up = r_enu[2]
        de_dt = (v_rel - los * np.sum(los * v_rel, axis=1)[:, None]) / rho[:, None]
        el_rate = (de_dt @ up) / np.maximum(np.cos(el), 1e-6)
        vel_enu = r_enu @ rcv_vel
        h_step = 0.5
        tp, ip, _, _ = self._delays(t.add_s(h_step), lat, lon, h + vel_enu[2] * h_step, az,
                                    el + el_rate * h_step, d_enu + vel_enu * h_step, col)
        tm, im, _, _ = self._delays(t.add_s(-h_step), lat, lon, h - vel_enu[2] * h_step, az,
                                    el - el_rate * h_step, d_enu - vel_enu * h_step, col)
        atmo_rate = ((tp - ip) - (tm - im)) / (2 * h_step)

        moving = receiver == "rover" and float(np.linalg.norm(rcv_vel)) > MOVING_SPEED_M_S
        mp_src = self._mp_code_moving if moving else self._mp_code[receiver]
        env = sc.rover_environment if receiver == "rover" else None
        mp_phase = em.mp_phase_sigma_zenith_m / sin_el * self._fast.interp(self._mp_phase[receiver], t)[col]
        eps_dop = em.doppler_sigma_zenith_hz / sin_el * noise[2, col]
        if env is None:
            mp_code = em.mp_code_sigma_zenith_m / sin_el * self._fast.interp(mp_src, t)[col]
            eps_code = em.code_sigma_zenith_m / sin_el * noise[0, col]
            eps_phase = em.phase_sigma_zenith_m / sin_el * noise[1, col]
            cn0 = em.cn0_horizon_dbhz + (em.cn0_zenith_dbhz - em.cn0_horizon_dbhz) * np.sin(np.maximum(el, 0.0))
            cn0 = cn0 + em.cn0_sigma_dbhz * noise[3, col]
            pr_std = np.hypot(em.code_sigma_zenith_m, em.mp_code_sigma_zenith_m) / sin_el
            half_ns = round(em.half_cycle_resolve_s * NS_PER_S)
        else:  # C/N0 drives the noise (RoverEnvironment)
            cn0_model = env.cn0_horizon_dbhz + (env.cn0_zenith_dbhz - env.cn0_horizon_dbhz) * np.sin(np.maximum(el, 0.0))
            if self._cn0_dev_db is not None:  # an attenuated signal: weaker, and noisier with it
                cn0_model = cn0_model + self._fast.interp(self._cn0_dev_db, t)[col]
            scale = 10.0 ** ((env.cn0_ref_dbhz - cn0_model) / 20.0)
            code_scale = scale * np.where(gnss_arr == GNSS_GLONASS, env.glonass_code_factor, 1.0)
            tot = math.hypot(em.code_sigma_zenith_m, em.mp_code_sigma_zenith_m)
            w_frac, m_frac = (em.code_sigma_zenith_m / tot, em.mp_code_sigma_zenith_m / tot) if tot else (0.0, 0.0)
            mp_code = env.code_sigma_ref_m * m_frac * code_scale * self._fast.interp(mp_src, t)[col]
            eps_code = env.code_sigma_ref_m * w_frac * code_scale * noise[0, col]
            eps_phase = env.phase_sigma_ref_m * scale * noise[1, col]
            cn0 = cn0_model if self._cn0_dev_db is not None else cn0_model + env.cn0_sigma_dbhz * noise[3, col]
            pr_std = env.code_sigma_ref_m * code_scale
            half_ns = round(env.half_cycle_resolve_s * NS_PER_S)

        b = timing.clock_bias_s
        clocks_m = CLIGHT_M_S * (b - dts)
        amb = np.zeros(n)
        half = np.zeros(n)
        lock_ms = np.zeros(n)
        lli = np.zeros(n, dtype=np.uint8)
        half_sub = np.zeros(n, dtype=np.uint8)
        tracks = self._tracks[receiver]
        arc_index: list[int] = []
        for i, c in enumerate(col):
            tr = tracks[int(c)]
            assert tr is not None
            k = int(np.searchsorted(tr.resets_ns, t.total_ns, side="right")) - 1
            k = max(k, 0)
            arc_index.append(k)
            t_reset = tr.resets_ns[k]
            jumps = sum(c for tj, c in zip(tr.jumps_ns, tr.jumps_cyc) if t_reset < tj <= t.total_ns)
            amb[i] = tr.reset_n_cyc[k] + jumps
            age_ns = t.total_ns - t_reset
            lock_ms[i] = age_ns / 1e6
            if age_ns < half_ns:
                lli[i] |= LLI_HALF_CYCLE
                half[i] = 0.5 if tr.reset_half[k] else 0.0
            elif tr.reset_half[k]:
                half_sub[i] = 1
            if tr.reset_lli[k] and prev_ns < t_reset <= t.total_ns:
                lli[i] |= LLI_SLIP

        code_ifb = self._code_ifb_m[receiver][col]
        phase_ifb = self._phase_ifb_m[receiver][col]
        arc_code = np.zeros(n)
        if env is not None and (env.arc_code_sigma_ref_m > 0.0 or env.acq_code_sigma_ref_m > 0.0):
            arc_code = self._arc_code_m(env, r_idx, col, arc_index, lock_ms / 1e3, scale)
        pr = rho + clocks_m + tropo + iono + mp_code + eps_code + code_ifb + arc_code
        cp = (rho + clocks_m + tropo - iono + mp_phase + eps_phase + phase_ifb) / lam + amb + half
        dop = -(rho_dot + CLIGHT_M_S * (timing.clock_drift_s_s - dts_dot) + atmo_rate) / lam + eps_dop
        cp_std = pll_thermal_sigma_cyc(cn0)
        clock_reset = timing.jumps != prev_jumps
        if update_state:
            self._last_obs[receiver] = (t.total_ns, timing.jumps)
        multi: dict[str, Any] = {} if self.layout.gps_only else {
            "glo_fcn": self._glo_fcn[col].copy(),
            "signal": np.array([SIGNAL_CODE[int(g)] for g in gnss_arr], dtype="<U2")}
        epoch = ObsEpoch(
            time=timing.tag, gnss_id=gnss_arr, sv_id=prn_arr, pr_m=pr, cp_cyc=cp,
            dop_hz=dop, cn0_dbhz=cn0, lock_ms=lock_ms, lli=lli, half_cyc_sub=half_sub, pr_std_m=pr_std,
            cp_std_cyc=cp_std, clock_reset=bool(clock_reset), leap_s=self._leap_s, **multi,
        )
        details = {
            "timing": timing, "receiver_ecef_m": rcv, "receiver_vel_ecef_m_s": rcv_vel, "sv_id": prn_arr,
            "el_rad": el, "az_rad": az, "rho_m": rho, "rho_dot_m_s": rho_dot, "sat_clock_s": dts,
            "sat_drift_s_s": dts_dot, "sat_pos_m": np.array([r["sat_pos_m"] for r in rows]).reshape(n, 3),
            "t_tx": [r["t_tx"] for r in rows], "tropo_m": tropo, "tropo_model_m": tropo_model,
            "iono_m": iono, "iono_model_m": iono_model, "mp_code_m": mp_code, "mp_phase_m": mp_phase,
            "eps_code_m": eps_code, "eps_phase_m": eps_phase, "eps_dop_hz": eps_dop, "ambiguity_cyc": amb,
            "half_cycle_cyc": half, "clock_bias_s": b, "freq_l1_hz": FREQ_L1_HZ, "gnss_id": gnss_arr,
            "freq_hz": self._freq_hz[col], "lambda_m": lam, "code_ifb_m": code_ifb, "phase_ifb_m": phase_ifb,
            "arc_code_m": arc_code,
        }
        return epoch, details
