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

    elmask_deg: float = 15.0
    ar_elmask_deg: float = 15.0
    hold_elmask_deg: float = 15.0
    ar_mode: str = "fix-and-hold"
    ratio_threshold: float = 3.0
    min_success_rate: float = 0.99
    """Bootstrapped ILS success rate a fix needs besides the ratio test (rejects fixes of ambiguities the
    float solution has not yet determined, e.g. single-epoch code-only geometry); see consistent_fix_span_s."""
    confirm_fix_span_s: float = 30.0
    """A first fix on a partial set (nothing held or validated, no known start) needs the same integer set
    winning the ratio test for this long (s), scaled by the code's measured quality (`code_variance_scale`,
    ≤ 1) but never under confirm_fix_span_min_s. Floats built on correlated code multipath are metres off with
    σ ≈ 1 m in their first seconds: hil_sim's real-time chain fixed one 4 m off (ratio 3.0) for 1.5 s; M8P/GLW1
    processed backward, a set 3.4 m off won for 5 s; a hil_sim flight at 5 km (u-blox-like code multipath,
    τ = 30 s) fixed a set 1.6 m off after 10 s of wins and held it (141 wrong epochs). The span must outlast
    the multipath's correlation time, which geodetic code (GEONET Trimble, Septentrio, scale ≈ 0.2) hardly
    has: Septentrio fixes 71.7 % with 10 s, 1.4 % with 30 s; M8P and GLW1 lose nothing at 30 s (97.8 / 99.1 %).
    Full sets: see full_set_confirm_epochs."""
    confirm_fix_span_min_s: float = 10.0
    confirm_fix_span_per_km_s: float = 6.0
    """Added to the partial-set confirmation span per km of baseline (s/km) once the code scatter has been
    measured u-blox-like (code_variance_scale ≥ 0.5): the L1 double differences keep the differential
    ionosphere (hil_sim: 1 mm/km of slant delay per satellite, quiet to moderate days' 1-4 mm/km), a few
    hundredths of a cycle that keep the float of noisy, correlated code consistently off for minutes. hil_sim
    5 km seed 7 (calibrated): a partial set 1.5 m off won the ratio test (3.1-3.5) for 30 s and was fixed
    (3 wrong epochs); 60 s at 5 km: 0 wrong, 5 km seeds 1-8 0 wrong. Geodetic code (GEONET, Septentrio: scale
    ≈ 0.1-0.2, or not yet measured) keeps confirm_fix_span_s, which 60 s there would cost (92.5 / 71.1 %)."""
    """Floor of the partial-set confirmation span (s) for the cleanest code."""
    consistent_fix_span_s: float = 60.0
    """Below min_success_rate a fix on a partial set is still accepted when the same integer set has passed the
    ratio test at every epoch over this span (s). GEONET 0759/3040 (30 s epochs): the bootstrapped rate, a lower bound, stays
    under 0.99 for 510 s while RTKLIB's ratio test is right from the second epoch; hil_sim at 1 Hz: a ratio
    of 3 on a float metres off (correlated code) after 7 s is wrong. Geometry needs time, not epochs. Never
    shorter than the span a set above the success rate needs (confirm_fix_span_s with its per-km part): hil_sim
    7 km seed 26, a partial set (ratio 3.1, success rate 0.94) was fixed 28 cm off after 60 s of wins where one
    above the rate would have needed 72 s."""
    settled_fix_span_s: float = 60.0
    """A first-fix candidate that has won the ratio test with the same integer set at every epoch for this long
    (s) is no longer rejected for lying far from the float position (the Mahalanobis check; its fixed
    residuals must still fit). u-blox code multipath is correlated over ~30 s static (bench/error_stats.py):
    a float built on it at 1 Hz is metres off with a decimetre σ, and stays too confident after its error
    shrinks. hil_sim seed 3 (calibrated error model): the right set won from 25 s on (ratio 3 → 20, fix 3-18 mm
    off) while the float, 2.9 → 0.6 m off, rejected it at every epoch (Mahalanobis 26-76): no fix in 600 s;
    first fix at 82 s with 60 here, 52 s with 30 (seed 2: 126 / 96 s). As confirm_fix_span_s, the span
    outlasts the code multipath's correlation time. hil_sim seeds 1-8, nominal and 5 km: 0 wrong with 30.
    60, not 30: on the M8P walk under trees (no truth) 30 fixed 45 epochs (1040-1095, the walker standing)
    whose sets had won for 30-55 s: 79-82 cm from the M8P's own RTK and 41-42 cm from demo5's fix there, so
    at least two of the three are wrong and ours, rejected by its own float, is the likeliest; 60 fixes none
    of them. The other real sets are unchanged either way (every candidate there is near its float). 0
    disables."""
    settled_fix_span_moving_s: float = 30.0
    """settled_fix_span_s while the rover moves (Doppler speed above takeoff_speed_m_s): a winning epoch in
    motion counts settled_fix_span_s / this as much, since a moving antenna's code multipath decorrelates in
    ~5 s (walking M8P, bench/error_stats.py) against ~30 s static, and the float's bias with it. hil_sim
    nominal cold starts (m8t, airborne fixed, first fix): seed 2 87.9 → 93.4 % (125 → 96 s), seed 3 96.0 →
    98.1 %, seed 7 90.2 → 95.1 %; 5 km seeds 2/7 83.2/71.6 → 88.8/77.3 %; seeds 1-8 nominal and 5 km 0 wrong
    with 20, 30 and 40. Not 20: the M8P walk under trees then fixes two of the 45 suspect standing epochs
    (1052-1053, see settled_fix_span_s), whose set had won partly while walking; 25 and 30 fix none. The
    real static sets never move (unchanged); Septentrio moving and the walk are unchanged with 30."""
    full_set_confirm_epochs: int = 2
    """A first fix on the full candidate set (no satellite dropped by partial AR) needs the same integer set
    winning the ratio test at this many consecutive epochs instead of over confirm_fix_span_s (and, below
    min_success_rate, over confirm_fix_span_s instead of consistent_fix_span_s). Every wrong candidate seen on
    the real sets (M8P/GLW1 backward 1.9-2.1 m off) and the hil_sim flight (2.5 m off) was a partial set, the
    survivor of several ratio tests; no full-set candidate in 131 was wrong. M8P forward first fix 32 → 23 s,
    GEONET 0759/3040 90 → 60 s (the second winning epoch)."""
    min_success_rate_minimal_set: float = 0.999
    """Success rate a fix resting on the bare minimum of double differences (`min_amb_dd`, nothing held)
    needs, besides twice the ratio."""
    strict_partial_drop_sats: int = 4
    """A first fix (nothing held) found after partial AR has dropped this many satellites needs the
    minimal-set gates too (twice the ratio, min_success_rate_minimal_set): every drop is one more integer
    set tried on the same biased float, and the survivor rests on the satellites that happened to fit. M8P
    processed backward (or forward from its last 150 s): float 0.78 m off (σ ≈ 0.2 m per axis, code
    multipath), full set ratio 2.6, the set left after 4 drops won 10 s at ratio 3.5, success rate 0.994,
    and was 0.69 m wrong. 2 or 3 here cost M8P forward 3 points."""
    min_lock_epochs: int = 1
    """A satellite joins AR once its phase has been tracked for more than this many epochs: a fix needs the
    float to have seen the phase at least twice, never a single epoch of code (the Septentrio rover of
    GEONET 3034 and RTKLIB 2.4.3 fix wrongly, 1.1 m off, at the first epoch with ratio 3.1). The known
    take-off point start is exempt (its ambiguities come from the surveyed position, not the code)."""
    min_fix_sats: int = 4
    stuck_float_s: float = 60.0
    """Nothing held, the float ambiguities of the full set determined to a small fraction of a cycle (bootstrapped
    success rate ≥ stuck_float_success_rate) yet near no integer set (ratio < stuck_float_ratio) for this long
    (s): the float carries an error its covariance does not know (slips it absorbed, e.g. undetected ones in a
    cold start), and it will not fix right; its ambiguities restart from the code (0 disables). Not while
    the ionosphere states are in use: their prior leaves a right float near no integer set for minutes, and a
    restart only loses that progress (hil_sim 5 km seed 29: 58.2 → 37.6 % with it). hil_sim M8T, undetected
    slips 2/h, seeds 1-8 at other hours of the orbits' day (bench/rtk_sim.py --start-hour): 19:00 (6
    satellites) seed 1 had fixed a set 1.59 m off after 180 s of such a float and held it (217 wrong epochs)
    → 0 wrong, mean airborne fixed 58.9 → 62.9 %; 10:00 69.4 → 78.0 % (seeds 1/4: 0.8/0.2 → 63.1/6.2 %);
    nominal 07:00 92.4 → 92.8 %; the 13:00 matrix (seeds 1-16, nominal, slips, gaps, 5 km) unchanged. Real
    sets (`onboard rtk`): fix counts unchanged except the M8P walk under trees processed backward, 21 → 4 fixed
    epochs (no truth; the 3 with an M8P RTK reference agree with it to 0.6-1.2 cm either way); restarts move
    the walk's float positions by up to 23 cm and M8P lossy combined by up to 2.4 mm."""
    stuck_float_success_rate: float = 0.9999
    stuck_float_ratio: float = 2.0
    min_hold_epochs: int = 5
    min_amb_dd: int = 4
    """Fewest double-difference ambiguities a (partial) fix may rest on."""
    partial_ar: bool = True
    exclude_half_cycle: bool = False
    """Drop phase flagged with an unresolved half cycle (LLI bit 1) from the filter, not only from AR."""
    max_partial_drop: int = 6
    partial_agrees_with_full: bool = True
    """A first fix on a partial set (nothing held, validated or known) must agree with the full candidate set's
    best integers on the satellites they share. Partial AR drops the least determined satellites until a set
    passes the ratio test; when the survivor's integers differ from the full set's best on satellites both
    contain, the data hold two rival hypotheses, and the survivor wins only because the satellites that
    contradict it were left out. hil_sim 5 km, seeds 17 and 29 (the same sky as every seed, other draws of the
    errors): a 6-satellite survivor with PRN 11, 14 and 25 one cycle off the full set's best won at ratio 6-9
    for 60 s on a float 10 cm from the truth, was fixed 35-43 cm off and held to the end (514 and 356 wrong
    epochs); seed 14 at 8 km the same (433). The right partial fixes seen (seed 8 at 5 km: ratio 5, 60 s) agree
    with their full set. Seeds 17-32 (the 16 after those the engine was tuned on), wrong epochs before /
    after: M8T 5 km 870 / 0 (airborne fixed, mean 90.3 / 89.7 %), 6 km 858 / 0, LEA-6T 5 km 869 / 0; seeds
    1-16 and every real set (forward, backward, combined) unchanged."""
    phase_sigma_a_m: float = 0.003
    phase_sigma_b_m: float = 0.003
    code_phase_ratio: float = 300.0
    code_scatter_reference: float = 0.1
    """Single-differenced code-minus-carrier scatter (its variance over the modelled code variance, white part)
    at and above which code_phase_ratio holds; code scattering less gets proportionally less variance (0
    disables). I.e. the code variance is kept at ≥ 10× the measured white scatter, for multipath correlated
    over tens of seconds. Measured with the defaults: u-blox M8P/M8P 0.10-0.25, M8P/GLW1 0.06-0.15, hil_sim
    0.3-0.5 (all left as they were), GEONET Trimble/Trimble 0.011, Septentrio/Trimble 0.019 (scaled to ~0.2,
    a code/phase ratio of ~130). Septentrio fix ratio with 0.05/0.07/0.1/0.15: 19/21/57/43 %, 0 wrong."""
    code_variance_min_scale: float = 1.0 / 9.0
    """Floor of that variance factor: the code keeps at least (code_phase_ratio / 3) × the phase σ
    (RTKLIB 2.4.3's ratio of 100), since its multipath is correlated in time and does not average out."""
    static_code_correlation_s: float = 17.0
    """Correlation time (s) of a static antenna's code multipath: while the rover is held static (standstill
    or static_start) its code variance is multiplied by this over the epoch interval (≥ 1; see
    static_code_factor), so that a standstill's code adds about one independent sample per correlation time
    instead of one per epoch. 17 s is what bench/error_stats.py measures on the static M8P rover (hil_sim's
    static process: 16 s by the same estimator); moving, the multipath decorrelates in ~5 s and the code keeps
    its weight. 0 disables. Without it 60 s on the ground left hil_sim floats 2-3 m off with a σ of 0.45 m,
    and the flight's decorrelated code then took up to minutes to outweigh them. Measured, 0 → 17 (forward,
    M8T seeds 1-16, airborne fixed min / median / mean, 0 wrong either way): nominal 93.4 / 100 / 98.7 → 100 /
    100 / 100 % (first fix, median 9 s, worst 35 s; was 96 s); undetected slips 87.5 / 100 / 98.0 → 100 % on
    every seed; radio gaps 100 % on every seed; 5 km 71.3 / 94.6 / 90.7 → 87.7 / 100 / 97.6 % (seed 1 98.5 →
    97.0 %, its float at take-off had been a lucky 0.9 m); LEA-6T nominal 99.8 % on every seed, 5 km 87.5 /
    99.8 / 97.4 %. 5, 7, 9, 15 and 30 s gave the same within a seed or two (5: nominal seed 2 99.1 %, the M8P
    walk 4 fixes). Real data, forward (backward): M8P static with the RAWX base 97.4 → 96.3 %, lossy RTCM as
    RINEX 97.8 → 97.2 % (91.8 → 89.5), the raw RTCM3 stream 97.9 → 96.3 %, first fix 21 → 41 s (87.0 →
    88.8), GLW1 99.1 % either way (97.2 → 94.4), Septentrio 80.3 → 80.0 % (57.5 → 56.7), GEONET (30 s epochs,
    factor 1) unchanged; combined 99.7-100 % as before. The M8P walk under trees (stop-and-go, no truth) fixes
    no epoch forward (176 before, 119 of them more than 10 cm from the M8P's own RTK), 21 backward as before.
    Those real starts were already right at 21 s: this costs them 20 s of waiting, for a cold start that on
    hil_sim's u-blox base and rover no longer depends on the draw."""
    code_scatter_min_epochs: int = 30
    """Epochs of code-minus-carrier statistics before the code variance is scaled (starts as modelled)."""
    doppler_sigma_m_s: float = 0.1
    use_doppler: bool = True
    initial_bias_sigma_cyc: float = 30.0 / 0.19029367279836487
    bias_process_noise_cyc: float = 1e-4
    bias_process_noise_cyc_per_km: float = 0.5e-3
    """Ambiguity random walk per km of baseline (cycles/√s/km), added to bias_process_noise_cyc in quadrature:
    L1 double differences drift with the differential ionosphere/troposphere, which grows with the baseline.
    Measured at the reference coordinates: GEONET 3034/Septentrio (5.3 km, 2021) 0.0053 cycle/√s (1.0e-3/km),
    GEONET 0759/3040 (3.3 km, 2005) 0.0009 (0.3e-3/km). Modelled as white noise (0 here), that drift read
    through the slow satellite motion put the Septentrio float 0.3-0.5 m off with a 4-10 cm σ: no fix in 360
    epochs. More is not free: it hands the float to the code, whose u-blox multipath is correlated (hil_sim at
    5 km, main 79 % fixed: 81 % with 0.3-0.6e-3, 0 % with ≥ 1e-3/km, float 2 m off). Septentrio fixed with
    0.3/0.4/0.5/0.6/1.0/1.5/2.0e-3: 28/21/31/30/21/57/58 % (0 wrong each; the AR gates make it lumpy).
    Where the ionosphere is estimated (iono_sigma_m_per_km, iono_min_baseline_km) only for code measured
    geodetic (code_variance_scale < 0.5), which can follow the drift the constant ionosphere states do not."""
    iono_sigma_m_per_km: float = 0.0005
    """Prior σ of each satellite's single-differenced (rover − base) vertical L1 ionospheric delay per km of
    baseline (m/km), estimated as a filter state (x[38 + prn − 1]) mapped to the slant by the single-layer
    obliquity, entering code with + and phase with − (the ionosphere-weighted model of Odijk; RTKLIB
    ionoopt=EST's udion). With L1 alone phase cannot tell the ionosphere from the ambiguity: the prior is what
    bounds it, and the ratio test, the fixed solution and its residuals stop carrying the differential
    ionosphere as if it were zero. With these states u-blox-like code gets no per-km ambiguity random walk
    (which hands its float to correlated code multipath); code measured geodetic keeps it. 0 disables.
    Only from iono_min_baseline_km to iono_max_baseline_km.
    hil_sim 5 km (1 mm/km slant gradient per satellite, i.e. a ~0.7 mm/km vertical σ), M8T, air fix % seeds
    1-8 / 9-16, 0 wrong everywhere unless noted:
    without (per-km walk 0.5e-3): 93.8 83.2 0 99.8 99.2 67.3 71.6 85.6 / 80.2 82.8 100 100 100 57.7 (314 wrong,
    40 cm) 54.8 67.5; 0.0004: 97.5 81.1 56.3 100 99.6 90.0 72.2 85.1 / 96.4 100 100 100 100 86.2 97.5 80.3;
    0.0005: 98.5 81.1 29.1 100 98.9 94.5 71.6 84.3 / 94.9 100 100 100 89.4 86.4 94.7 79.8; 0.0006: seed 3
    0 %; more weakens the ambiguities further (0.001: seed 3 0 %, seed 1 84 %) and lets biased floats fix:
    0.001 with confirm_fix_span_per_km_s ≤ 3 a partial set 40 cm off (seed 2), 0.002 with 6 wrong sets 6-19
    cm off (seeds 1, 8). GEONET 3034/Septentrio (5.3 km) forward / backward / combined 71.7 / 40.3 / 100 →
    80.3 / 57.5 / 100 % (without the walk for geodetic code: 82.2 / 0 / 82.2 %, its float 0.5-0.75 m off with
    a 0.1 m σ backward); GEONET 0759/3040 (3.3 km) 98.3 / 93.3 / 100 % with or without.
    What the gradient costs at 5 km (hil_sim M8T seeds 33-48, airborne fixed mean, first fixes): 86.3 %, 42-373 s
    as simulated; without the gradient 98.8 %, 31-165 s with these states, 100 %, 9-49 s without them and the
    per-km walk. A prior of this size weakens the single-epoch geometry as much as the phase noise (seed 34 at
    8 s: success rate 0.87 against 0.99 without the states), which is right while the gradient is there."""
    iono_process_noise_m_per_km: float = 0.0
    """Random walk of those vertical ionosphere states per km of baseline (m/√s/km). 0.2e-3 (the Septentrio
    drift measured at bias_process_noise_cyc_per_km) broke the 30 s GEONET 0759/3040 hold: 98.3 → 20.8 %;
    hil_sim 5 km seeds 1-8 with 0.03e-3: seed 3 29 → 0 %, with 0.1e-3 seed 1 98.5 → 0 % (its ionosphere is
    constant)."""
    iono_min_baseline_km: float = 4.5
    """The ionosphere states start from this baseline (km) and are dropped (folded into the ambiguities) below
    3/4 of it, re-evaluated each epoch: shorter baselines are processed exactly as without them (hil_sim
    nominal, 1.0 km; GEONET 0759/3040, 3.3 km). hil_sim M8T seeds 1-8 air fix % without / with the states
    from 3.5 km: 3.5 km 100 84.7 87.3 100 100 100 76.6 94.0 / 100 81.1 69.9 100 99.6 96.0 73.5 88.3; 4 km 99.8
    84.1 0 100 100 100 73.7 93.0 / 100 81.1 68.4 100 99.6 97.7 72.6 90.5 (3 km: worse as well): below ~4.5 km
    the per-km ambiguity walk does better but on an outlier seed; 0 wrong everywhere."""
    iono_max_baseline_km: float = 7.5
    """Nor beyond this baseline (km; dropped above 1.1 times it). hil_sim M8T seeds 1-8 without / with: 6 km
    80.7 48.0 0 95.1 99.1 62.8 52.4 83.0 / 97.9 80.9 0 96.0 98.1 87.3 64.1 83.6 %; 7 km 0.2 16.6 0 93.2 98.9 0
    47.1 80.3 / 92.6 80.9 0 94.5 97.5 67.3 62.9 80.5 %, seeds 9-16 67.3 0 100 100 88.8 53.9 (294 wrong, 40 cm)
    0 21.6 / 50.1 68.1 100 100 87.3 33.6 60.5 74.3 %, 0 wrong with them; 8.5 km seed 1: a
    5-satellite set 20-24 cm off won for 88 s (ratio 3 → 8) on a float 0.35-0.45 m off and was held (165 wrong
    epochs; 10 km: seed 8 9 wrong, 9-10 cm), where without them 8.5-10 km fix little but nothing wrong."""
    max_first_fix_baseline_km: float = 6.0
    """No first fix (nothing held or validated, no known take-off point) beyond this baseline (km; 0: no limit).
    With L1 alone the differential ionosphere (millimetres per km per satellite) cannot be told from the
    ambiguities; the longer the baseline, the more often a set that fits the ionosphere-biased float as well as
    the right one wins, and a right set's fixed position carries the ionosphere too. hil_sim M8T cold starts,
    seeds 1-16 / 17-32, wrong epochs without any limit: 8 km 433 / 929, 10 km 85 / 1114, 20 km 1200 / 1126
    (sets 0.3-1.6 m off, held to the end). With partial_agrees_with_full a limit of 7.5 km still let seed 14
    fix at 7.4 km 10-11 cm off (5 epochs: right integers, a partial set's position, σ 4.5 cm), 7 km seed 1 at
    6.9 km 16 cm off; 6 km: 0 wrong on seeds 1-32 at 5, 6, 6.5, 7, 10 and 20 km. With stuck_float_s too, no
    limit still fixes wrong sets at 8 km (seeds 3, 8, 10, 14, 15 of 1-16) and 20 km (3, 7, 12). A fix held
    from a shorter baseline or seeded from a surveyed take-off point is kept as the rover flies out (hil_sim
    with the known take-off point: 10 km 100 % fixed, 0.7 cm 3D RMS; 20 km 100 %, 1.1 cm). The real sets
    (≤ 5.3 km) are unchanged. The pre-flight page names this cause when the rover floats beyond it."""
    accel_h_sigma_m_s2: float = 3.0
    accel_v_sigma_m_s2: float = 1.0
    initial_pos_sigma_m: float = 30.0
    initial_vel_sigma_m_s: float = 10.0
    hold_sigma_cyc: float = 0.001
    max_outage_epochs: int = 5
    slip_threshold_cyc: float = 2.0
    """Doppler-predicted phase jump beyond which a slip is declared (cycles, scaled with the gap), while no
    fix is held. 1.5 was tried (hil_sim M8T, undetected slips 2/h): it catches the 2-cycle slips a cold start
    otherwise absorbs (seed 18: 94.0 → 100 %; 10:00 sky 78.0 → 88.9 %, 19:00 62.9 → 78.5 %, seeds 1-8), but at
    19:00 seed 5 (6 satellites) then fixed a set 1.05 m off and held it (423 wrong epochs)."""
    slip_threshold_held_cyc: float = 0.85
    """The same while a fix is held: below one cycle so that a 1-cycle slip without LLI (1.0 ± the Doppler's
    ~0.1 cycle over 1 s) is caught before the hold absorbs it. With 2.0, hil_sim seed 6 (undetected slips
    2/h) held a rover PRN 17 +1-cycle slip at 331 s to the end, 18 cm off (268 wrong epochs, on main too; 0
    with 0.85). Not before the first fix: the Doppler misses the phase by up to a cycle across hil_sim's
    steps of acceleration, and the false slips restarted converging floats (seeds 2 and 7: first fix 96 →
    120 s, 93 → 117 s with 0.85 throughout). Real sets fix the same with 0.7-2.0 forward; M8P static
    processed backward loses 1.7 points with 0.7 throughout (81.9 → 80.2 %), none with 0.85."""
    fault_exclusion_margin: float = 2.0
    """Under a hold, when leaving out either of several satellites makes the rest fit, the best exclusion must
    have a post-fit phase χ² this many times smaller than the next, else the hold is released."""
    slip_outlier_factor: float = 6.0
    """While a fix is held, the Doppler slip threshold drops to this many robust standard deviations (1.4826 ×
    the median absolute clock-removed prediction error) of the other satellites at this epoch, when that is below
    slip_threshold_held_cyc (never under slip_threshold_min_cyc; needs 5 satellites not flagged; 0 disables).
    The fixed threshold must allow for manoeuvres, where the Doppler misses the phase by up to a cycle on
    every satellite; a quiet epoch shows a smaller slip. hil_sim seed 15, undetected slips: a -1 cycle rover
    slip seen as 0.83 cycle (under 0.85) pulled the held position 22 cm for 2 epochs; caught with 6. Seeds
    1-16, nominal / gaps / 5 km / undetected slips (M8T; LEA-6T undetected slips): no other change; real sets
    and the M8P walk unchanged in every direction."""
    slip_threshold_min_cyc: float = 0.5
    """Floor of that adaptive threshold (cycles): half a cycle, the smallest jump a receiver makes."""
    max_innovation_phase_m: float = 0.5
    max_innovation_code_m: float = 30.0
    validation_sigma_factor: float = 4.0
    max_fix_sigma_m: float = 0.06
    """A fixed solution whose 3D σ (from the fixed covariance) exceeds this is reported as float: with too
    few or badly placed satellites even correct integers do not give a centimetre position."""
    max_age_s: float = 30.0
    base_rate_window_s: float = 20.0
    """Span (s) of base epochs over which each satellite's correction rate (base phase − modelled range) is
    fitted to carry the last base epoch across a radio gap: 3 mm/sin(el) phase noise gives a slope good to
    ~0.4 mm/s over 20 s (10 s: ~1 mm/s, 5 cm misses after a 20 s gap on hil_sim), short enough for the
    curvature of the atmosphere's drift. M8P static with its lossy base: 94.3 % fixed with 10, 20 or 30 s."""
    base_age_sigma_m_s: float = 0.0005
    """Growth (m/s) of the phase σ of an aged base epoch after it is carried forward (RTKLIB demo5's sclkstab
    term, smaller since the rate is removed): hil_sim leaves < 0.5 cm after 20 s; real data are rougher. Lets
    the hold's residual check and the fix's σ widen with the age instead of releasing a good fix at 25 s."""
    base_extrapolate_min_age_s: float = 5.0
    """Base epochs older than this (s) are carried forward along the correction rate, from this age on (the
    correction grows from zero, it does not jump by rate × age when carrying starts). Younger ones (1 Hz base,
    a few lost epochs) are used raw: the atmosphere moves about a centimetre in 5 s, less than the rate's own
    noise adds on a multipath-laden u-blox base. M8P static, forward, RAWX base / raw lossy RTCM3 stream / its
    RINEX: 97.4 / 97.9 / 97.8 % fixed from 5 s, 96.3 / 97.3 / 97.8 % from 2.5 s; carrying the whole age from
    5 s released a good hold (51 % on the RAWX base). hil_sim's 5–20 s gaps need it (never carrying: 37.8 %
    airborne fixed, 2 wrong; from 5 s: 100 %, 1.8 cm, 0 wrong)."""
    pair_tolerance_s: float = 0.025
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
    max_iterations: int = 2
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
        if self.ratio_threshold < 1.0:
            raise ValueError("ratio_threshold must be ≥ 1")


# TOML key → (field, converter). Keys carry RTKLIB-like names; units convert here, at the boundary.
TOML_KEYS: dict[str, tuple[str, Any]] = {
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
    "accel_h_sigma_m_s2": ("accel_h_sigma_m_s2", float),
    "accel_v_sigma_m_s2": ("accel_v_sigma_m_s2", float),
    "max_age_s": ("max_age_s", float),
    "max_outage_epochs": ("max_outage_epochs", int),
    "static_start": ("static_start", bool),
    "takeoff_speed_m_s": ("takeoff_speed_m_s", float),
    "standstill": ("standstill", bool),
    "standstill_window_s": ("standstill_window_s", float),
    "standstill_min_s": ("standstill_min_s", float),
    "static_code_correlation_s": ("static_code_correlation_s", float),
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
