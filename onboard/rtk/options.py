"""RTK engine options: one frozen dataclass (units in field names) and the TOML key → field table."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

AR_MODES = ("fix-and-hold", "continuous", "instantaneous", "off")


@dataclass(frozen=True)
class RtkOptions:
    """Options of the L1 relative-positioning engine (defaults: RTKLIB demo5-like, tuned for L1 drones).

    Noise terms follow RTKLIB prcopt_t: phase σ = a + b/sin(el) per zero-difference (m), code σ = that ×
    `code_phase_ratio`. Process noises are spectral densities (per √s).
    """

    systems: str = "G"
    """Constellations used, as RINEX letters (G GPS, R GLONASS, E Galileo, C BeiDou, J QZSS): "G" is the
    LEA-6T's GPS L1, "GREJ" the M8T's. Double differences are formed within each constellation, and every
    constellation used has its ambiguities fixed: GLONASS as RTKLIB demo5's gloarmode=on, which assumes both
    receivers of one type (their inter-frequency biases cancel); with a base of another type leave R out.
    Why no float-only constellation: its float ambiguities absorb the error of a wrong integer set of the
    others and hide it from every residual test (docs/rtk-defaults.md)."""
    elmask_deg: float = 15.0
    ar_elmask_deg: float = 15.0
    hold_elmask_deg: float = 15.0
    """Elevation mask (deg) of the hold (RTKLIB elmaskhold): only fixed satellites at or above it are constrained
    to their integers. At or below ar_elmask_deg it holds every fixed satellite."""
    ar_mode: str = "fix-and-hold"
    ratio_threshold: float = 3.0
    min_success_rate: float = 0.99
    """Bootstrapped ILS success rate a fix needs besides the ratio test (rejects fixes of ambiguities the
    float solution has not yet determined, e.g. single-epoch code-only geometry); see consistent_fix_span_s."""
    confirm_fix_span_s: float = 30.0
    """A first fix on a partial set (nothing held or validated, no known start) needs the same integer set
    winning the ratio test for this long (s), scaled by the code's measured quality (`code_variance_scale`,
    ≤ 1) but never under confirm_fix_span_min_s. Why: a float built on correlated code multipath is metres off
    with σ ≈ 1 m in its first seconds and can pass the ratio test with a wrong set; the span must outlast the
    multipath's correlation time, which geodetic code hardly has. Full sets: see full_set_confirm_epochs."""
    confirm_fix_span_min_s: float = 10.0
    """Floor of the partial-set confirmation span (s) for the cleanest code."""
    confirm_fix_span_per_km_s: float = 6.0
    """Added to the partial-set confirmation span per km of baseline (s/km) once the code scatter has been
    measured u-blox-like (code_variance_scale ≥ 0.5). Why: L1 double differences keep the differential
    ionosphere (millimetres per km per satellite), a few hundredths of a cycle that keep the float of noisy,
    correlated code consistently off for minutes."""
    consistent_fix_span_s: float = 60.0
    """Below min_success_rate a fix on a partial set is still accepted when the same integer set has passed the
    ratio test at every epoch over this span (s). Why: the bootstrapped success rate is a lower bound that can
    stay under the threshold for minutes on sparse (30 s) epochs while the ratio test is right; geometry needs
    time, not epochs. Never shorter than the span a set above the success rate needs (confirm_fix_span_s with
    its per-km part)."""
    settled_fix_span_s: float = 60.0
    """A first-fix candidate that has won the ratio test with the same integer set at every epoch for this long
    (s) is no longer rejected for lying far from the float position (the Mahalanobis check; its fixed
    residuals must still fit). Why: a float built on correlated u-blox code multipath stays too confident after
    its error shrinks and would reject the right set for minutes; the span outlasts the multipath's
    correlation time. 0 disables."""
    settled_fix_span_moving_s: float = 30.0
    """settled_fix_span_s while the rover moves (Doppler speed above takeoff_speed_m_s, s): a winning epoch in
    motion counts settled_fix_span_s / this as much. Why: a moving antenna's code multipath decorrelates in
    seconds against tens of seconds static, and the float's bias with it."""
    revalidated_skips_float_check: bool = True
    """A fix that re-fixes the last validated integers (no set held, at least min_fix_sats satellites of that set
    tracked without a slip since) is not rejected for lying far from the float position (the Mahalanobis check;
    its residuals must still fit). Why: after a hold is released the float of a static rover is known to
    millimetres yet off by the centimetre multipath the hold kept out, and rejects the validated integers until
    they settle (M8P static with the RAWX base, GPS+GLONASS: 86 s unfixed)."""
    float_fix_gate_scale: float = 6.0
    """The float's position covariance is multiplied by this in the float-fix consistency test (the
    Mahalanobis distance of the fixed from the float position, against χ²(3) at 99.9 %) when the code has been
    measured u-blox-like (code_variance_scale ≥ 0.5) and the integer set has at least float_fix_gate_min_dd
    double differences. Why: u-blox code multipath under trees is correlated over tens of seconds, and two
    units' GLONASS code differs by metres per channel until the biases are learned, so the float's covariance
    is too small along the directions it leaves loose and rejects the right set for minutes; a set of many
    double differences is refuted by its own fixed phase residuals instead. 1 disables."""
    float_fix_gate_min_dd: int = 10
    """Fewest double differences (beyond the three position unknowns, seven redundant) a fix needs for
    float_fix_gate_scale. Why: the fewer double differences, the less the fixed solution's own phase residuals
    can refute a wrong set, and the more the float's verdict is needed (a 5-DD GPS set 80 cm off fits them)."""
    combined_handover: bool = True
    """Combined post-processing hands the forward pass's fixes to the backward pass: where a run of forward
    fixes starts in time and the backward pass holds nothing, the backward float is pinned to the forward fix,
    fixes at once and carries that hold on into the epochs before, where the forward pass was still
    confirming its first fix or re-fixing after slips. Why: under trees each direction loses its hold at the
    slips and needs minutes to confirm a new first fix, minutes the other direction crossed fixed (M8P walk,
    GPS+GLONASS: 53 -> 61 % fixed; docs/rtk-defaults.md)."""
    combined_contest_distance_m: float = 0.10
    """Combined post-processing: two integer hypotheses (one pass's lineage of a held set, Solution.fix_id)
    whose fixes lie more than this (m, 3D) apart at most of the epochs both passes are fixed refute each other,
    and each is reported float at all its epochs where the other pass has no fix agreeing with it, not only
    where the two meet; so is a hypothesis held over less than handover_min_run_s, which also refutes nothing,
    and a fix next to an epoch where the two passes dispute its hypothesis (0 disables all four). Why: one held
    set is right or wrong as a whole; hil_sim GPS alone under trees held wrong sets for 63-327 s in one pass
    while the other, right there, had no fix over part of them (M8T seeds 1-24: 119 wrong combined epochs). Not
    the 5 cm at which two fixes are combined, and not at a single epoch: right sets under trees stray beyond
    5 cm at a few epochs (M8P walk: 5.0-6.0 cm; hil_sim: up to 21 cm; docs/rtk-defaults.md)."""
    handover_sigma_m: float = 0.01
    """σ (m, per ECEF axis) added to the handed-over fix's own covariance when it pins the other pass. Why: a
    fixed position carries centimetre multipath its covariance does not hold; 1 cm keeps the pinned double
    differences within a fraction of a cycle (λ 19 cm)."""
    handover_min_run_s: float = 5.0
    """Shortest run of consecutive forward fixes (s) whose first epoch pins the backward pass (see
    combined_handover). Why: an isolated fix has not been borne out by the epochs after it."""
    confirm_across_set_changes: bool = True
    """A first-fix candidate keeps its confirmation spans (first win, settled fraction; not its count of
    consecutive wins, which full_set_confirm_epochs reads of one and the same set) when the next winning set
    differs only by satellites joining, leaving or a new reference, its integers equal the candidate's on every
    satellite both hold (at least min_fix_sats; up to one constant per constellation, the reference). Why:
    under trees satellites come and go every few seconds, and a confirmation that restarts with each of them
    never reaches its span while the same integers keep winning (M8P walk, GPS+GLONASS: runs of 36 epochs at
    most, first fix 400 s; with it, 162 s)."""
    full_set_confirm_epochs: int = 2
    """A first fix on the full candidate set (no satellite dropped by partial AR) needs the same integer set
    winning the ratio test at this many consecutive epochs instead of over confirm_fix_span_s (and, below
    min_success_rate, over confirm_fix_span_s instead of consistent_fix_span_s). Why: a partial set is the
    survivor of several ratio tests, which inflates the chance that a biased float passes one by luck; the
    full set is one test on every ambiguity."""
    full_set_min_dd: int = 7
    """With measured u-blox-like code, a full set counts as full (full_set_confirm_epochs) only with at least
    this many double differences; a smaller one waits the spans of a partial set. Why: GPS alone under trees
    (hil_sim harsh, M8T, the C/N0 deviation as attenuation) fixed full sets of 6-7 double differences on a
    float 1.3-1.6 m off after two winning epochs."""
    min_success_rate_minimal_set: float = 0.999
    """Success rate a fix resting on the bare minimum of double differences (`min_fix_sats` satellites, nothing held)
    needs, besides twice the ratio."""
    strict_partial_drop_sats: int = 4
    """A first fix (nothing held) found after partial AR has dropped this many satellites needs the
    minimal-set gates too (twice the ratio, min_success_rate_minimal_set). Why: every drop is one more integer
    set tried on the same biased float, and the survivor rests on the satellites that happened to fit."""
    min_lock_epochs: int = 1
    """A satellite joins AR once its phase has been tracked for more than this many epochs. Why: a fix needs
    the float to have seen the phase at least twice, never a single epoch of code. The known take-off point
    start is exempt (its ambiguities come from the surveyed position, not the code)."""
    min_fix_sats: int = 5
    """Fewest satellites (the reference and min_fix_sats − 1 double differences) a (partial) fix may rest on
    (RTKLIB demo5 minfixsats); also the fewest held satellites a fault exclusion may leave, and the fewest a
    candidate must share with the last validated set to count as a re-fix of it."""
    stuck_float_s: float = 60.0
    """Nothing held, the float ambiguities of the full set determined to a small fraction of a cycle
    (bootstrapped success rate ≥ stuck_float_success_rate) yet near no integer set (ratio < stuck_float_ratio)
    for this long (s): the ambiguities restart from the code (0 disables). Why: such a float carries an error
    its covariance does not know (slips it absorbed, e.g. undetected ones in a cold start) and will not fix
    right. Not while the ionosphere states are in use: their prior leaves a right float near no integer set
    for minutes, and a restart only loses that progress."""
    stuck_float_success_rate: float = 0.9999
    stuck_float_ratio: float = 2.0
    min_hold_epochs: int = 5
    partial_ar: bool = True
    exclude_half_cycle: bool = False
    """Drop phase flagged with an unresolved half cycle (LLI bit 1) from the filter, not only from AR."""
    max_partial_drop: int = 6
    partial_agrees_with_full: bool = True
    """A first fix on a partial set (nothing held, validated or known) must agree with the full candidate set's
    best integers on the satellites they share. Why: when the survivor of partial AR differs from the full
    set's best on satellites both contain, the data hold two rival hypotheses, and the survivor wins only
    because the satellites that contradict it were left out."""
    phase_sigma_a_m: float = 0.003
    phase_sigma_b_m: float = 0.003
    code_phase_ratio: float = 300.0
    code_scatter_reference: float = 0.1
    """Single-differenced code-minus-carrier scatter (its variance over the modelled code variance, white part)
    at and above which code_phase_ratio holds; code scattering less gets proportionally less variance (0
    disables), i.e. the code variance is kept at ≥ 10× the measured white scatter. Why: code_phase_ratio is set
    for u-blox code; geodetic receivers scatter an order of magnitude less, and their float should lean on
    their code accordingly, while multipath correlated over tens of seconds must not average out."""
    code_cn0_ref_dbhz: float = 42.0
    """C/N0 (dB-Hz) below which a signal's code variance grows as 10^((this − C/N0)/10), on each receiver's
    side of the single difference, for code measured u-blox-like (code_variance_scale ≥ 0.5; 0 disables;
    an unknown C/N0 counts as strong). Why: under trees the weak, diffracted signals carry most of the code
    error, and it is biased (the float followed it metres up), so it does not average out."""
    glonass_code_bias_min_epochs: int = 60
    """Fixed epochs after which a GLONASS channel's learned code bias (rover − base, relative to the other
    channels) is taken off its code (0 disables learning and use). Why: the two receivers' code delays differ
    by channel by metres (M8P walk: R08 −4.1 m, R09/R10 −1.2 m); the float, held on them, stays metres off
    once a hold is lost."""
    glonass_code_bias_window_epochs: int = 300
    """Samples in the running mean of each channel's bias (it follows a slow change over this many fixed
    epochs)."""
    code_variance_min_scale: float = 1.0 / 9.0
    """Floor of that variance factor: the code keeps at least (code_phase_ratio / 3) × the phase σ
    (RTKLIB 2.4.3's ratio of 100), since its multipath is correlated in time and does not average out."""
    static_code_correlation_s: float = 17.0
    """Correlation time (s) of a static antenna's code multipath: while the rover is held static (standstill
    or static_start) its code variance is multiplied by this over the epoch interval (≥ 1; see
    static_code_factor). Why: a standstill's code adds about one independent sample per correlation time, not
    one per epoch; weighting every epoch as independent leaves the float metres off with a decimetre σ after a
    minute on the ground. Moving, the multipath decorrelates within seconds and the code keeps its weight.
    0 disables."""
    code_scatter_min_epochs: int = 30
    """Epochs of code-minus-carrier statistics before the code variance is scaled (starts as modelled)."""
    doppler_sigma_m_s: float = 0.1
    use_doppler: bool = True
    initial_bias_sigma_cyc: float = 30.0 / 0.19029367279836487
    bias_process_noise_cyc: float = 1e-4
    bias_process_noise_cyc_per_km: float = 0.5e-3
    """Ambiguity random walk per km of baseline (cycles/√s/km), added to bias_process_noise_cyc in quadrature.
    Why: L1 double differences drift with the differential ionosphere/troposphere, which grows with the
    baseline; modelled as zero, that drift read through the slow satellite motion biases the float. More is
    not free: it hands the float to the code, whose u-blox multipath is correlated. Where the ionosphere is
    estimated (iono_sigma_m_per_km, iono_min_baseline_km) only for code measured geodetic
    (code_variance_scale < 0.5), which can follow the drift the constant ionosphere states do not."""
    iono_sigma_m_per_km: float = 0.0005
    """Prior σ of each satellite's single-differenced (rover − base) vertical L1 ionospheric delay per km of
    baseline (m/km), estimated as a filter state (x[38 + prn − 1]) mapped to the slant by the single-layer
    obliquity, entering code with + and phase with − (the ionosphere-weighted model of Odijk; RTKLIB
    ionoopt=EST's udion). Why: with L1 alone phase cannot tell the ionosphere from the ambiguity; the prior is
    what bounds it, and the ratio test, the fixed solution and its residuals stop carrying the differential
    ionosphere as if it were zero. With these states u-blox-like code gets no per-km ambiguity random walk
    (which hands its float to correlated code multipath); code measured geodetic keeps it. 0 disables.
    Only from iono_min_baseline_km to iono_max_baseline_km."""
    iono_process_noise_m_per_km: float = 0.0
    """Random walk of those vertical ionosphere states per km of baseline (m/√s/km); 0: constant over a
    flight, which the L1 ambiguities then hold apart from the ionosphere."""
    iono_min_baseline_km: float = 4.5
    """The ionosphere states start from this baseline (km) and are dropped (folded into the ambiguities) below
    3/4 of it, re-evaluated each epoch. Why: on shorter baselines the per-km ambiguity walk does better, and
    they are then processed exactly as without the states."""
    iono_max_baseline_km: float = 7.5
    """Nor beyond this baseline (km; dropped above 1.1 times it). Why: beyond it the states let held wrong sets
    through where the filter without them fixes little but nothing wrong."""
    max_first_fix_baseline_km: float = 6.0
    """No first fix (nothing held or validated, no known take-off point) beyond this baseline (km; 0: no limit).
    Why: with L1 alone the differential ionosphere (millimetres per km per satellite) cannot be told from the
    ambiguities; the longer the baseline, the more often a set that fits the ionosphere-biased float as well as
    the right one wins, and a right set's fixed position carries the ionosphere too. A fix held from a shorter
    baseline or seeded from a surveyed take-off point is kept as the rover flies out. The pre-flight page
    names this cause when the rover floats beyond it."""
    accel_h_sigma_m_s2: float = 3.0
    accel_v_sigma_m_s2: float = 1.0
    initial_pos_sigma_m: float = 30.0
    initial_vel_sigma_m_s: float = 10.0
    hold_sigma_cyc: float = 0.001
    max_outage_epochs: int = 5
    slip_threshold_cyc: float = 2.0
    """Doppler-predicted phase jump beyond which a slip is declared (cycles, scaled with the gap), while no
    fix is held. Why this size: a false slip only restarts a converging float, while a lower threshold that
    catches 2-cycle slips also cost a wrong held fix."""
    slip_threshold_held_cyc: float = 0.85
    """The same while a fix is held (cycles): below one cycle so that a 1-cycle slip without LLI (1.0 ± the
    Doppler's ~0.1 cycle over 1 s) is caught before the hold absorbs it. Not before the first fix: the Doppler
    misses the phase by up to a cycle across steps of acceleration, and false slips restart converging floats."""
    fault_exclusion_margin: float = 2.0
    """Under a hold, when leaving out either of several satellites makes the rest fit, the best exclusion must
    have a post-fit phase χ² this many times smaller than the next, else the hold is released."""
    slip_outlier_factor: float = 6.0
    """While a fix is held, the Doppler slip threshold drops to this many robust standard deviations (1.4826 ×
    the median absolute clock-removed prediction error) of the other satellites at this epoch, when that is below
    slip_threshold_held_cyc (never under slip_threshold_min_cyc; needs 5 satellites not flagged; 0 disables).
    Why: the fixed threshold must allow for manoeuvres, where the Doppler misses the phase by up to a cycle on
    every satellite; a quiet epoch shows a smaller slip."""
    slip_threshold_min_cyc: float = 0.5
    """Floor of that adaptive threshold (cycles): half a cycle, the smallest jump a receiver makes."""
    tdcp_slip_test: bool = True
    """While a fix is held, the rover's slips are judged by its time-differenced phase (onboard.rtk.tdcp_slips:
    the displacement and clock fitted to every satellite's phase change, a slipped satellite left as a residual)
    instead of the Doppler prediction, wherever six satellites the Doppler test clears, or more, decide it (its
    suspects are judged against their fit); LLI always counts. Why: the Doppler, read once per epoch, misses the
    antenna motion between epochs (a walker's steps, a drone's vibration and turns) by decimetres, and a burst
    of its false slips leaves the hold on a few satellites whose fixed position is 10-20 cm off (M8P walk under
    trees, GPS+GLONASS). Not before a fix: there its false alarms only restart floats that correlated code has
    misled, and clearing them or adding the small slips it misses exposed wrong first fixes of small full sets
    (docs/rtk-defaults.md)."""
    tdcp_slip_threshold_cyc: float = 0.35
    """Deletion residual (cycles) beyond which the time-differenced phase test declares a slip: above the
    phase noise and multipath change of one epoch (99th percentile 0.17 cycle on the M8P static set, 0.88 under
    trees with the real slips), below the half cycle of the smallest receiver jump."""
    tdcp_float_slip_threshold_cyc: float = 1.5
    """Before a fix, the time-differenced phase test (as tdcp_slip_test) adds the slips beyond this deletion
    residual (cycles) to the Doppler's flags; the Doppler's own flags stay (0 disables). Why: the Doppler's
    2-cycle threshold before a fix lets 2-cycle slips through, and a float that absorbs one fits no integer
    set until it is restarted (hil_sim GPS+GLONASS, undetected slips: 67 % of a flight's airborne epochs
    unfixed); above the 0.88-cycle 99th percentile of the phase test's residuals under trees, so that it does
    not restart floats that the real sets fix."""
    outlier_gate_sigma: float = 6.0
    """Innovation gate of the float update (innovation σ from H·P·Hᵀ + R): a row beyond it is an outlier, the
    worst one is removed and the update re-run."""
    phase_outlier_floor_m: float = 0.05
    """A phase innovation below this (m, a quarter of a cycle) is never an outlier, however small its σ (a
    held state's covariance is millimetres, a centimetre of unmodelled atmosphere is not a slip)."""
    max_outlier_passes: int = 4
    """Passes of the float update's outlier removal per epoch (one outlier removed per pass). When every pass
    finds one the epoch has no measurement update (RtkState.rejected_updates counts these)."""
    validation_sigma_factor: float = 4.0
    max_fix_sigma_m: float = 0.06
    """A fixed solution whose 3D σ (from the fixed covariance) exceeds this is reported as float: with too
    few or badly placed satellites even correct integers do not give a centimetre position."""
    max_age_s: float = 30.0
    base_rate_window_s: float = 20.0
    """Span (s) of base epochs over which each satellite's correction rate (base phase − modelled range) is
    fitted to carry the last base epoch across a radio gap. Why: 3 mm/sin(el) phase noise gives a slope good to
    ~0.4 mm/s over 20 s, short enough for the curvature of the atmosphere's drift."""
    base_age_sigma_m_s: float = 0.0005
    """Growth (m/s) of the phase σ of an aged base epoch after it is carried forward (RTKLIB demo5's sclkstab
    term, smaller since the rate is removed). Why: lets the hold's residual check and the fix's σ widen with
    the age instead of releasing a good fix late in a gap."""
    resume_hold_after_gap: bool = True
    """A hold released while the base was carried forward (a radio gap) is tried again, integers as they were, at
    the first new base epoch: fixed and held at once when every fixed phase residual fits, without the ratio test
    and the float-fix check. Why: the carried base's drift, not the integers, made the held set misfit, and the
    float it left behind needs 15-30 s of fresh data to win the ratio test again (gr-2012 radio gaps)."""
    base_extrapolate_min_age_s: float = 5.0
    """Base epochs older than this (s) are carried forward along the correction rate, from this age on (the
    correction grows from zero, it does not jump by rate × age when carrying starts). Younger ones (1 Hz base,
    a few lost epochs) are used raw. Why: the atmosphere moves about a centimetre in 5 s, less than the rate's
    own noise adds on a multipath-laden u-blox base, while longer gaps need the rate."""
    base_rate_skill_min: float = 0.5
    """While a set is held, a satellite whose correction rate (base_rate_window_s) predicted the base's own last
    base_extrapolate_min_age_s seconds this well (skill 1 − SSE(rate)/SSE(hold): the straight line fitted to the
    epochs before them against holding the last of those; 1 a perfect prediction, 0 no better than holding) is
    carried forward from the first second of a gap instead of from base_extrapolate_min_age_s. ≥ 1: never. Why:
    under a fast ionosphere (solar maximum) a satellite's base correction can drift 6 mm/s, 3 cm before carrying
    starts, enough to release a held set (hil_sim gr-2012, 20-s gap); the multipath of a u-blox base does not
    continue its trend, and is carried as before."""
    pair_tolerance_s: float = 0.025
    max_base_spp_offset_m: float = 30.0
    """Post-processing refuses a base position farther than this (m, 3D) from the median of the base's own
    single-point solutions (BasePositionRejected): a single point scatters a few metres (u-blox or geodetic
    code, broadcast orbits and atmosphere), so 30 m is no scatter but a wrong or mistyped position, which
    would shift every output by its error with centimetre σ. 0 disables."""
    static_start: bool = False
    """Hold the rover static (no process noise) until its Doppler speed exceeds takeoff_speed_m_s."""
    takeoff_speed_m_s: float = 0.5
    standstill: bool = True
    """Detect a rover standing still and hold it static (no position process noise, zero velocity) until it
    moves (see onboard.rtk.standstill): the displacement from time-differenced phase over standstill_window_s
    passes a χ² test against zero for standstill_min_s. Motion (the test failing, or a Doppler speed above
    takeoff_speed_m_s) ends it at once, before the epoch's update."""
    standstill_window_s: float = 10.0
    """Window (s) of the displacement test; with sparser epochs the previous epoch is the window's start."""
    standstill_min_s: float = 10.0
    """Time (s) without motion before the static hold starts."""
    standstill_max_sigma_m: float = 0.05
    """The static hold starts only on a displacement known this well (3D σ, m): weaker geometry cannot tell
    a standstill from a slow drift."""
    init_pos_sigma_m: float = 0.005
    """σ given to a known take-off position (Daakir 2015 known-point initialisation)."""
    spp_max_gdop: float = 100.0
    """SPP geometry limit; higher than RTKLIB's 30 since the relative filter only needs a rough position."""
    spp_outlier_m: float = 60.0

    @property
    def elmask_rad(self) -> float:
        return math.radians(self.elmask_deg)

    def __post_init__(self) -> None:
        if self.ar_mode not in AR_MODES:
            raise ValueError(f"ar_mode must be one of {AR_MODES}, not {self.ar_mode!r}")
        if not 0.0 <= self.elmask_deg < 90.0:
            raise ValueError(f"elmask_deg out of range: {self.elmask_deg}")
        if not self.systems or set(self.systems) - set("GRECJ"):
            raise ValueError(f"systems must be letters of G, R, E, C, J, not {self.systems!r}")
        if self.ratio_threshold < 1.0:
            raise ValueError("ratio_threshold must be ≥ 1")
        if not self.float_fix_gate_scale >= 1.0:
            raise ValueError(f"float_fix_gate_scale must be ≥ 1 (1 disables), not {self.float_fix_gate_scale}")
        if self.float_fix_gate_min_dd < 0:
            raise ValueError(f"float_fix_gate_min_dd must be ≥ 0, not {self.float_fix_gate_min_dd}")
        if not (math.isfinite(self.handover_sigma_m) and self.handover_sigma_m > 0.0):
            raise ValueError(f"handover_sigma_m must be a positive number of metres, not {self.handover_sigma_m}")
        if not (math.isfinite(self.handover_min_run_s) and self.handover_min_run_s >= 0.0):
            raise ValueError(f"handover_min_run_s must be ≥ 0 s, not {self.handover_min_run_s}")
        if not (math.isfinite(self.combined_contest_distance_m) and self.combined_contest_distance_m >= 0.0):
            raise ValueError("combined_contest_distance_m must be ≥ 0 m (0 disables), not "
                             f"{self.combined_contest_distance_m}")
        if self.glonass_code_bias_min_epochs < 0 or self.glonass_code_bias_window_epochs < 1:
            raise ValueError("glonass_code_bias_min_epochs must be ≥ 0 (0 disables) and "
                             "glonass_code_bias_window_epochs ≥ 1")
        if math.isnan(self.base_rate_skill_min):
            raise ValueError("base_rate_skill_min must be a number (≥ 1 never carries early)")
        if not 0.0 <= self.code_cn0_ref_dbhz <= 70.0:  # also refuses NaN
            raise ValueError(f"code_cn0_ref_dbhz must be 0 (off) to 70 dB-Hz, not {self.code_cn0_ref_dbhz}")


# TOML key → (field, converter). Keys carry RTKLIB-like names; units convert here, at the boundary.
TOML_KEYS: dict[str, tuple[str, Any]] = {
    "systems": ("systems", str),
    "elevation_mask_deg": ("elmask_deg", float),
    "ar_elevation_mask_deg": ("ar_elmask_deg", float),
    "ar_mode": ("ar_mode", str),
    "ratio_threshold": ("ratio_threshold", float),
    "min_lock_epochs": ("min_lock_epochs", int),
    "min_fix_sats": ("min_fix_sats", int),
    "min_hold_epochs": ("min_hold_epochs", int),
    "partial_ar": ("partial_ar", bool),
    "phase_sigma_mm": ("phase_sigma_a_m", lambda v: float(v) / 1000.0),
    "phase_sigma_el_mm": ("phase_sigma_b_m", lambda v: float(v) / 1000.0),
    "code_phase_ratio": ("code_phase_ratio", float),
    "code_cn0_ref_dbhz": ("code_cn0_ref_dbhz", float),
    "glonass_code_bias_min_epochs": ("glonass_code_bias_min_epochs", int),
    "glonass_code_bias_window_epochs": ("glonass_code_bias_window_epochs", int),
    "accel_h_sigma_m_s2": ("accel_h_sigma_m_s2", float),
    "accel_v_sigma_m_s2": ("accel_v_sigma_m_s2", float),
    "max_age_s": ("max_age_s", float),
    "resume_hold_after_gap": ("resume_hold_after_gap", bool),
    "max_outage_epochs": ("max_outage_epochs", int),
    "static_start": ("static_start", bool),
    "takeoff_speed_m_s": ("takeoff_speed_m_s", float),
    "tdcp_slip_test": ("tdcp_slip_test", bool),
    "tdcp_slip_threshold_cyc": ("tdcp_slip_threshold_cyc", float),
    "tdcp_float_slip_threshold_cyc": ("tdcp_float_slip_threshold_cyc", float),
    "confirm_across_set_changes": ("confirm_across_set_changes", bool),
    "float_fix_gate_scale": ("float_fix_gate_scale", float),
    "float_fix_gate_min_dd": ("float_fix_gate_min_dd", int),
    "combined_handover": ("combined_handover", bool),
    "combined_contest_distance_m": ("combined_contest_distance_m", float),
    "handover_sigma_m": ("handover_sigma_m", float),
    "handover_min_run_s": ("handover_min_run_s", float),
    "standstill": ("standstill", bool),
    "standstill_window_s": ("standstill_window_s", float),
    "standstill_min_s": ("standstill_min_s", float),
    "static_code_correlation_s": ("static_code_correlation_s", float),
    "base_rate_skill_min": ("base_rate_skill_min", float),
    "use_doppler": ("use_doppler", bool),
    "max_first_fix_baseline_km": ("max_first_fix_baseline_km", float),
}


def options_from_mapping(values: Mapping[str, Any], base: RtkOptions | None = None) -> RtkOptions:
    """Options from a parsed TOML table; unknown keys raise ValueError naming the key."""
    changes: dict[str, Any] = {}
    for key, value in values.items():
        if key not in TOML_KEYS:
            raise ValueError(f"unknown RTK option {key!r} (known: {', '.join(sorted(TOML_KEYS))})")
        name, conv = TOML_KEYS[key]
        changes[name] = conv(value)
    return replace(base or RtkOptions(), **changes)


def option_names() -> list[str]:
    """Field names of RtkOptions (for help texts)."""
    return [f.name for f in fields(RtkOptions)]
