"""Scenario description of the simulated world: options as frozen dataclasses, units in every name.

A `Scenario` is data only (no I/O): start time, site, base placement, navigation file path, the error model,
the flight and camera plans and the two receivers' models. `Scenario.default(model, **overrides)` gives the
standard survey flight on 2010-07-01 (GPS week 1590, the day of the real broadcast orbits in
`hil_sim/data/broadcast-nav-20100701/brdc1820.10n`, shipped with the package) at 13:00 GPST over Zurich, when 9 GPS satellites are
above 15° (10 above the 5° receiver mask).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

from onboard.gnsstime import GpsTime

DATA_DIR = Path(__file__).resolve().parent / "data"
"""Broadcast orbits shipped with the simulator (provenance and licence in data/NOTICE.md)."""
DEFAULT_NAV_PATH = DATA_DIR / "broadcast-nav-20100701" / "brdc1820.10n"
"""The real GPS broadcast orbits of 2010-07-01 (RTKLIB test data, BSD 2-Clause), the default world's sky."""
DEFAULT_START = GpsTime(1590, 392_400 * 1_000_000_000)
"""2010-07-01 13:00:00 GPST (Thursday of GPS week 1590)."""


@dataclass(frozen=True)
class MultiWorld:
    """A multi-constellation sky: shipped navigation files (data/NOTICE.md), the systems they hold, a start
    time on their day and a site where those systems are in view."""

    nav_paths: tuple[Path, ...]
    systems: str
    start: GpsTime
    site_lat_deg: float
    site_lon_deg: float
    site_h_m: float
    iono_model_error_tau_s: float | None = None
    """The sky's own ErrorModel.iono_model_error_tau_s (None: the default), fitted to real dual-frequency data
    of that day and place (docs/hil-sim-error-model.md, "The ionosphere's rate")."""


MULTI_WORLDS: dict[str, MultiWorld] = {
    "gr-2012": MultiWorld(
        tuple(DATA_DIR / "broadcast-nav-20121031" / f"brdc3050.12{x}" for x in "ngq"), "GR",
        GpsTime(1712, (259_200 + 2 * 3600) * 1_000_000_000), 35.68, 139.77, 40.0),
    "gej-2021": MultiWorld(
        (DATA_DIR / "geonet-3034-sept-20210922" / "SEPT2650.21P.gz",), "GEJ",
        GpsTime(2176, (259_200 + 6 * 3600 + 1800) * 1_000_000_000), 35.342, 139.522, 60.0,
        iono_model_error_tau_s=45_000.0),
}
"""2012-10-31 02:00 GPST (GPS + GLONASS FDMA, RTKLIB test data, BSD-2) over Tokyo (QZS-1's file is read too but
it broadcast itself unhealthy all that day: systems "GRJ" simulates no QZSS there); 2021-09-22 06:30 GPST
(GPS + Galileo + 4 QZSS, cssrlib-data, MIT) over Fujisawa, where those files were recorded."""


@dataclass(frozen=True)
class ErrorModel:
    """Error budget of the simulated observables (all 1σ; `*_zenith_*` values are scaled by 1/sin(el)).

    Receiver errors (independent per receiver and satellite): white code/phase/Doppler noise, first-order
    Gauss–Markov multipath on code and phase. Common errors (same for base and rover): broadcast orbit error
    (3-D, per axis), satellite clock error, ionosphere model error (fraction of the Klobuchar delay),
    zenith troposphere residual after Saastamoinen. Differential: ionospheric gradient (slant delay change
    per km of horizontal base–rover separation, random direction per satellite). Tracking events: cycle slips
    with LLI (new ambiguity, lock time reset) and without (integer jump only), half-cycle ambiguity after
    acquisition. A receiver unit's own GLONASS code delay per frequency channel. `noise_free()` switches all of
    these off (ambiguities stay random integers).
    """

    code_sigma_zenith_m: float = 0.15
    """White (epoch-to-epoch independent) code noise. Measured by `bench/error_stats.py` (code minus carrier,
    detrended per arc, autocovariance): u-blox M8P static 0.16 m zenith-equivalent of a 0.51 m total, i.e.
    about 10 % of the code variance is white (C(1 s)/C(0) = 0.96); the u-blox RXM-RAW logs (2008 LEA-4T era,
    NEO-6P) 0.93-0.99, no resolvable white part. Was 0.5 m (half the variance white: C(1 s)/C(0) ≈ 0.5),
    which made the simulated code 2-3× noisier in short-term scatter than a real u-blox."""
    phase_sigma_zenith_m: float = 0.001
    """White carrier-phase noise. Measured (`bench/error_stats.py`, DD phase minus DD range at the reference
    coordinates): M8P/M8P 0.33 m 1.46 mm one-way zenith-equivalent in all (white 0.8 mm, correlated 0.9 mm);
    M8P/GLW1 197 m 1.56 mm. Was 3 mm (3.1 mm in all with the multipath below, twice the measured)."""
    doppler_sigma_zenith_hz: float = 0.05
    mp_code_sigma_zenith_m: float = 0.5
    """Code multipath (first-order Gauss–Markov, `mp_tau_s`). Measured: M8P static 0.48 m (the estimator
    returns 0.46 m for this model's 0.5 m), u-blox 2008 RXM-RAW 0.42 m, NEO-6P 0.9 m (patch antenna)."""
    mp_phase_sigma_zenith_m: float = 0.001
    """Phase multipath. Measured: M8P/M8P 0.9 mm correlated part (τ ≈ 13 s estimated; the estimator returns
    0.7 mm for 0.8 mm on hil_sim). With 1 mm white and 1 mm here hil_sim's one-way total is 1.3 mm against
    the measured 1.46 (M8P/M8P) and 1.56 mm (M8P/GLW1)."""
    mp_tau_s: float = 30.0
    """Multipath correlation time, static antenna. The estimator (arc polynomial removed) returns 17 s both
    for this model's 30 s and for the real M8P static rover (17.2 s), i.e. the real value is about 30 s."""
    mp_tau_moving_s: float = 8.0
    """Code multipath correlation time of the rover while it moves (> 0.5 m/s; same σ). Measured
    (`bench/error_stats.py`): the M8P walking rover (20181004-1532, ~1 m/s) decorrelates in 5.1 s
    (C(10 s)/C(0) = 0.15) where the same receiver static gives 17.2 s (0.53) through the same estimator; this
    τ reproduces the walking figures on the simulated flight. A drone at 5-10 m/s decorrelates its
    reflections faster still: the walking figure is the conservative one we can measure."""
    cn0_zenith_dbhz: float = 50.0
    cn0_horizon_dbhz: float = 35.0
    cn0_sigma_dbhz: float = 1.0
    orbit_sigma_m: float = 0.3
    orbit_tau_s: float = 3600.0
    sat_clock_sigma_m: float = 0.3
    sat_clock_tau_s: float = 3600.0
    iono_model_error_fraction: float = 0.2
    iono_model_error_tau_s: float = 1800.0
    """Correlation time of the fraction above; with it σ sets the ionosphere's rate, which a rover differenced
    with an aged base epoch (radio gaps) sees. 1800 s: between two satellites 69-102 mm RMS change in 20 s on
    the gr-2012 sky (seeds 1-8), 59 mm in the real GMSD MSM7 stream (L1−L2 phase, 2012-10-14, Japan). A
    MultiWorld can carry its own (docs/hil-sim-error-model.md)."""
    iono_gradient_mm_per_km: float = 1.0
    tropo_residual_zenith_sigma_m: float = 0.02
    tropo_residual_tau_s: float = 1800.0
    slip_lli_rate_per_h: float = 0.1
    slip_undetected_rate_per_h: float = 0.02
    slip_undetected_max_cyc: int = 3
    half_cycle_probability: float = 0.5
    half_cycle_resolve_s: float = 2.0
    clock_drift_rw_s_s_per_sqrt_s: float = 2e-12
    glonass_unit_code_sigma_m: float = 1.0
    """σ (m) of each receiver unit's own code delay per GLONASS frequency channel (its antenna and front end),
    constant, drawn per receiver: two units of one type do not cancel it (hil_sim.constellations.glonass_ifb
    holds the type's part, which does). Fitted to the channel biases our engine learns between the two M8Ps of
    the Galway sets (docs/hil-sim-error-model.md)."""

    @classmethod
    def noise_free(cls) -> ErrorModel:
        """Every random error, event and residual at zero (deterministic modelled delays remain)."""
        return cls(
            code_sigma_zenith_m=0.0, phase_sigma_zenith_m=0.0, doppler_sigma_zenith_hz=0.0,
            mp_code_sigma_zenith_m=0.0, mp_phase_sigma_zenith_m=0.0, cn0_sigma_dbhz=0.0, orbit_sigma_m=0.0,
            sat_clock_sigma_m=0.0, iono_model_error_fraction=0.0, iono_gradient_mm_per_km=0.0,
            tropo_residual_zenith_sigma_m=0.0, slip_lli_rate_per_h=0.0, slip_undetected_rate_per_h=0.0,
            half_cycle_probability=0.0, clock_drift_rw_s_s_per_sqrt_s=0.0, glonass_unit_code_sigma_m=0.0,
        )


@dataclass(frozen=True)
class RoverEnvironment:
    """A hard place for the rover's antenna (e.g. walking under trees): blockage, slips and C/N0-driven noise.

    Replaces, for the rover only, the ErrorModel's slip rates, half-cycle time, C/N0 model and the 1/sin(el)
    noise law; the base stays in the open sky. Blockage: a two-state (tracked/blocked) process per satellite
    on the 1-s grid with the unavailability `unavailability` per elevation band `el_bands_deg` (lower edges,
    the last band to 90°) × the relative factor of its 45° azimuth sector (`az_factor`, 8 values from north,
    clockwise), mean outage `outage_mean_s`; each reacquisition is a new arc (new ambiguity, lock time reset,
    LLI). Slips: independent LLI slips `lli_slips_per_h` per satellite, receiver-wide events (every satellite
    slips at once) `common_slip_events_per_h`, slips without LLI `unflagged_slips_per_h` (±1…3 cycles).
    Noise: code (white and multipath, split as in the ErrorModel) of total σ `code_sigma_ref_m` and white
    phase `phase_sigma_ref_m` at `cn0_ref_dbhz`, scaled by 10^((ref − C/N0)/20) (thermal noise ∝ 1/√(C/N0),
    what the measured code RMS per C/N0 bin follows); GLONASS code × `glonass_code_factor` (its C/A chip is
    twice as long). C/N0 = `cn0_horizon_dbhz` + (`cn0_zenith_dbhz` − horizon)·sin(el) + N(0, `cn0_sigma_dbhz`),
    the deviation correlated over `cn0_tau_s`.
    `HARSH` holds the values fitted to the real M8P walk (hil_sim.obs_stats.fit_environment;
    docs/hil-sim-error-model.md).
    """

    el_bands_deg: tuple[float, ...] = (10.0, 20.0, 30.0, 45.0, 60.0)
    unavailability: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    az_factor: tuple[float, ...] = (1.0,) * 8
    outage_mean_s: float = 3.0
    lli_slips_per_h: float = 0.0
    common_slip_events_per_h: float = 0.0
    unflagged_slips_per_h: float = 0.0
    half_cycle_resolve_s: float = 2.0
    cn0_horizon_dbhz: float = 35.0
    cn0_zenith_dbhz: float = 50.0
    cn0_sigma_dbhz: float = 1.0
    cn0_tau_s: tuple[float, ...] = ()
    """Correlation times (s) of the C/N0 deviation from the law, each an equal share of its variance. ():
    white, the receiver's estimate scattering about the law, the noise following the law. Otherwise the
    deviation is the signal's own attenuation (foliage, the walker's body) and the noise follows it."""
    cn0_ref_dbhz: float = 45.0
    code_sigma_ref_m: float = 0.5
    phase_sigma_ref_m: float = 0.001
    glonass_code_factor: float = 1.0
    arc_code_sigma_ref_m: float = 0.0
    """σ (m, at cn0_ref_dbhz, scaled by the same C/N0 law) of a code error drawn at each acquisition or slip and
    kept for the whole arc: the slow part of a real rover's code under trees, which its own code minus carrier
    cannot see (docs/hil-sim-error-model.md). 0: none."""
    acq_code_sigma_ref_m: float = 0.0
    """σ (m, likewise) of a further code error at acquisition that decays over `acq_code_tau_s` (s): the real
    walk's first 30 s of an arc are 1.2-1.6 times worse than the rest. 0: none."""
    acq_code_tau_s: float = 15.0


HARSH = RoverEnvironment(
    el_bands_deg=(10.0, 20.0, 30.0, 45.0, 60.0), unavailability=(0.100, 0.066, 0.010, 0.009, 0.007),
    az_factor=(0.30, 0.57, 0.92, 3.47, 0.40, 1.33, 0.28, 0.72), outage_mean_s=2.7, lli_slips_per_h=38.1,
    common_slip_events_per_h=4.6, unflagged_slips_per_h=2.6, half_cycle_resolve_s=2.9, cn0_horizon_dbhz=34.6,
    cn0_zenith_dbhz=51.1, cn0_sigma_dbhz=3.5, cn0_tau_s=(5.0, 90.0), cn0_ref_dbhz=45.0, code_sigma_ref_m=0.85,
    phase_sigma_ref_m=0.0018, glonass_code_factor=2.6, arc_code_sigma_ref_m=1.2, acq_code_sigma_ref_m=2.5,
    acq_code_tau_s=15.0,
)
"""The u-blox M8P walking a river trail under trees (Galway 2018, set 20181004-1532, GPS + GLONASS, 10° mask):
`hil_sim.obs_stats.fit_environment` of its RINEX (bench/error_stats.py --harsh prints the fit and the
simulated statistics beside the real ones). Phase σ: not measurable there (no truth for a moving antenna): the
static M8P's 1 mm zenith (C/N0 ≈ 50 dB-Hz) carried to 45 dB-Hz by the same 10^(Δ/20) law. Code σ: 0.85 m
and GLONASS × 2.6 in, because the estimator (a quadratic removed per arc takes some multipath with it, the
per-arc error's decay adds some) returns 0.80 m and × 2.0 on the simulated flight, the walk's 0.79 m and × 2.43
(seed 5). The per-arc code error (arc_code_sigma_ref_m, acq_code_sigma_ref_m) is the one part not seen by the
rover-only estimator: set from the walk's code residuals at the M8P's own RTK fixes, per arc
(docs/hil-sim-error-model.md)."""


@dataclass(frozen=True)
class ReceiverModel:
    """A u-blox receiver's clock and tracking behaviour.

    The local oscillator runs with offset `clock_bias0_s` + `clock_drift_s_s`·(t − start) (+ a random walk of
    the drift); the receiver measures on its own nominal grid shifted by `tag_offset_ms` (LEA-6T −1 → tags at
    …999 ms, M8T −8 → …992 ms) and steps its time by 1 ms whenever |bias| exceeds `clock_jump_threshold_s`
    (tags then move to …998 / …993 ms …). `elevation_mask_deg` is the receiver's tracking mask.
    """

    kind: str = "m8t"
    tag_offset_ms: int = -8
    clock_bias0_s: float = -0.35e-3
    clock_drift_s_s: float = -0.25e-6
    clock_jump_threshold_s: float = 0.5e-3
    elevation_mask_deg: float = 5.0
    max_sats: int = 16
    ifb_type: str = "ublox-m8"
    """GLONASS inter-frequency bias type (hil_sim.constellations.IFB_TYPES): "ublox-m8" or "other"."""

    @classmethod
    def lea6t(cls, **overrides: object) -> ReceiverModel:
        """LEA-6T (RXM-RAW): tags …999 ms; bias kept within ±1 ms by 1-ms steps (one step after ~10 min)."""
        base = cls(kind="lea6t", tag_offset_ms=-1, clock_bias0_s=0.62e-3, clock_drift_s_s=0.65e-6,
                   clock_jump_threshold_s=1.0e-3, max_sats=16)
        return dataclasses.replace(base, **overrides)  # type: ignore[arg-type]

    @classmethod
    def m8t(cls, **overrides: object) -> ReceiverModel:
        """NEO/LEA-M8T (RXM-RAWX): free-running clock, tags …992 ms, an occasional 1-ms step."""
        return dataclasses.replace(cls(), **overrides)  # type: ignore[arg-type]

    def tracks(self, gnss_id: int) -> bool:
        """Whether this receiver tracks the system: the LEA-6T GPS only, the M8T every simulated one (CFG-GNSS
        chooses among them in the receiver emulator)."""
        return self.kind != "lea6t" or gnss_id == 0

    @classmethod
    def for_kind(cls, kind: str, **overrides: object) -> ReceiverModel:
        """The model named "lea6t" or "m8t"."""
        if kind == "lea6t":
            return cls.lea6t(**overrides)
        if kind == "m8t":
            return cls.m8t(**overrides)
        raise ValueError(f"unknown receiver model {kind!r} (expected 'lea6t' or 'm8t')")


@dataclass(frozen=True)
class FlightPlan:
    """The rover's flight: static on the ground, vertical climb, parallel survey lines joined by half-circle
    turns, optional descent and landing. Distances in metres (ENU about the takeoff point), speeds m/s.

    `line_speeds_m_s` cycles over the lines (a different speed per line). `fly=False` keeps the rover static
    for the whole scenario (zero-baseline and static tests).
    """

    fly: bool = True
    static_s: float = 60.0
    climb_rate_m_s: float = 2.5
    survey_height_m: float = 60.0
    line_length_m: float = 300.0
    line_spacing_m: float = 30.0
    n_lines: int = 6
    line_azimuth_deg: float = 30.0
    line_speeds_m_s: tuple[float, ...] = (4.0, 4.6, 5.0, 4.3, 4.8, 4.2)
    accel_m_s2: float = 1.5
    land: bool = True
    descent_rate_m_s: float = 1.5
    wobble_amplitude_deg: float = 2.8
    lever_arm_cam_m: tuple[float, float, float] = (0.01, -0.05, -0.18)


@dataclass(frozen=True)
class CameraPlan:
    """TimePulse → camera → flash chain (see hil_sim.camera).

    Pulses every `period_s` on the GPS-time grid at `phase_offset_s` past the grid (not on the second);
    pulses before `valid_after_s` (scenario-relative: the receiver has no valid time yet) are suppressed.
    The shutter fires `shutter_delay_mean_s` ± `shutter_jitter_sigma_s` after the pulse; the flash mark is
    the hot-shoe falling edge at exposure. `missed_flash_probability` drops a flash; `bounce_probability`
    adds a second edge `bounce_delay_max_s` or less after it.
    """

    period_s: float = 2.0
    phase_offset_s: float = 0.3217
    shutter_delay_mean_s: float = 0.064
    shutter_jitter_sigma_s: float = 0.0002
    valid_after_s: float = 30.0
    missed_flash_probability: float = 0.0
    bounce_probability: float = 0.0
    bounce_delay_max_s: float = 0.003
    trigger_routed: bool = True


@dataclass(frozen=True)
class Scenario:
    """Everything that defines one simulated flight; the World is a pure function of it (and `seed`).

    `site_*` is the rover antenna at takeoff (WGS 84), the ENU origin of the flight. `base_offset_enu_m` is
    the base antenna relative to it (e.g. (800, −600, 2) for a 1 km baseline). `nav_path` is the RINEX
    navigation file whose orbits/clocks/Klobuchar coefficients are the truth.
    """

    start: GpsTime = DEFAULT_START
    duration_s: float = 900.0
    seed: int = 1
    site_lat_deg: float = 47.40
    site_lon_deg: float = 8.50
    site_h_m: float = 500.0
    base_offset_enu_m: tuple[float, float, float] = (800.0, -600.0, 2.0)
    nav_path: Path = DEFAULT_NAV_PATH
    extra_nav_paths: tuple[Path, ...] = ()
    systems: str = "G"
    errors: ErrorModel = field(default_factory=ErrorModel)
    flight: FlightPlan = field(default_factory=FlightPlan)
    camera: CameraPlan = field(default_factory=CameraPlan)
    rover_environment: RoverEnvironment | None = None
    """None: the rover sees the open sky of the ErrorModel; else its hard environment (e.g. HARSH)."""
    rover_receiver: ReceiverModel = field(default_factory=ReceiverModel.m8t)
    base_receiver: ReceiverModel = field(default_factory=lambda: ReceiverModel.m8t(
        clock_bias0_s=0.21e-3, clock_drift_s_s=0.12e-6))

    @classmethod
    def default(cls, model: str = "m8t", **overrides: object) -> Scenario:
        """The standard survey flight with both receivers of `model` ("m8t" or "lea6t"); fields overridable."""
        rover = ReceiverModel.for_kind(model)
        base = ReceiverModel.for_kind(model, clock_bias0_s=0.21e-3, clock_drift_s_s=0.12e-6)
        if model == "lea6t":
            base = ReceiverModel.for_kind(model, clock_bias0_s=-0.4e-3, clock_drift_s_s=-0.3e-6)
        values: dict[str, object] = {"rover_receiver": rover, "base_receiver": base}
        values.update(overrides)
        if "nav_path" in values:
            values["nav_path"] = Path(str(values["nav_path"]))
        if "extra_nav_paths" in values:
            values["extra_nav_paths"] = tuple(Path(str(p)) for p in values["extra_nav_paths"])  # type: ignore[attr-defined]
        return cls(**values)  # type: ignore[arg-type]

    @classmethod
    def multi(cls, world: str = "gr-2012", model: str = "m8t", systems: str | None = None,
              **overrides: object) -> Scenario:
        """The standard flight in a multi-constellation world (MULTI_WORLDS): its navigation files, day, hour
        and site; `systems` a subset of the world's (default: all it has); fields overridable."""
        if world not in MULTI_WORLDS:
            raise ValueError(f"unknown world {world!r} (expected one of {sorted(MULTI_WORLDS)})")
        w = MULTI_WORLDS[world]
        values: dict[str, object] = {
            "nav_path": w.nav_paths[0], "extra_nav_paths": w.nav_paths[1:], "systems": systems or w.systems,
            "start": w.start, "site_lat_deg": w.site_lat_deg, "site_lon_deg": w.site_lon_deg,
            "site_h_m": w.site_h_m}
        if w.iono_model_error_tau_s is not None:
            values["errors"] = ErrorModel(iono_model_error_tau_s=w.iono_model_error_tau_s)
        if model == "m8t":  # 32 tracking channels: a multi-constellation sky fills more than 16
            values["rover_receiver"] = ReceiverModel.m8t(max_sats=32)
            values["base_receiver"] = ReceiverModel.m8t(clock_bias0_s=0.21e-3, clock_drift_s_s=0.12e-6, max_sats=32)
        values.update(overrides)
        return cls.default(model, **values)

    @staticmethod
    def base_offset_for(baseline_m: float, azimuth_deg: float = 127.0, up_m: float = 2.0) -> tuple[float, float, float]:
        """`base_offset_enu_m` for a horizontal baseline of `baseline_m` towards `azimuth_deg` (from north)."""
        az = math.radians(azimuth_deg)
        return (baseline_m * math.sin(az), baseline_m * math.cos(az), up_m)

    @property
    def baseline_m(self) -> float:
        """Length of the base offset from the takeoff point (m)."""
        e, n, u = self.base_offset_enu_m
        return float((e * e + n * n + u * u) ** 0.5)
