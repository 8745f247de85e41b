"""Cycle slips of one receiver from its time-differenced carrier phase (pure).

Between two consecutive epochs, each satellite's phase change (m) minus the change of its modelled range (the
satellite's motion and clock, both from the ephemeris, seen from one receiver position) leaves the receiver's
own displacement projected on the line of sight and its clock change, common to all satellites in metres:
y_k = −e_k·Δx + c·Δt_r + noise. Fitting those four unknowns by least squares leaves residuals of millimetres for
satellites tracked without a slip, whatever the receiver did in between, and a slipped satellite stands out by
its cycles. The Doppler prediction of the phase, the other test, cannot tell a slip from motion it does not
sample: the antenna of a walker swings at the step frequency and the Doppler, read once a second, misses
decimetres of it (M8P walk under trees, GPS+GLONASS: six of twelve held satellites flagged at the first steps,
none of which slipped).

The satellite with the largest normalised residual (Baarda's w-test) is flagged when its deletion residual
(its residual against the fit without it: the slip's size) is beyond the threshold, and the fit repeated
without it, while at least `min_sats` remain; with fewer, the test cannot isolate a slip and says so (None).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from onboard.rtk.linsolve import LinAlgError, inv

Arr = npt.NDArray[np.float64]

MIN_SATS = 6
"""Four unknowns (displacement, clock) and two redundant satellites: one slip can be both seen and isolated."""


def tdcp_slips(y_m: Arr, los: Arr, lam_m: Arr, usable: npt.NDArray[np.bool_], threshold_cyc: float,
               suspects: npt.NDArray[np.bool_] | None = None, min_sats: int = MIN_SATS
               ) -> npt.NDArray[np.bool_] | None:
    """Slip flags per slot from time-differenced phase, or None when the test cannot decide.

    `y_m` per slot: phase change λ·Δφ (m) minus the modelled range change between the two epochs, `los` unit
    lines of sight (one row per slot, receiver → satellite), `lam_m` each slot's wavelength (m), `usable` the
    slots to test (phase at both epochs, no loss-of-lock flag, an ephemeris at both), `threshold_cyc` the size
    (cycles of the slot's own wavelength) beyond which a satellite has slipped. `suspects` (e.g. the Doppler
    test's flags) are left out of the fit and each judged against the fit of the others: several slips at
    once then cannot hide one another. None when fewer than `min_sats` usable satellites that are no suspects
    remain, at the start or after the flagged ones are removed: the suspects' verdict is not this test's.
    """
    usable = usable & np.isfinite(y_m)
    flags = np.zeros(y_m.shape[0], bool)
    trusted = usable if suspects is None else usable & ~suspects
    fit = _isolate(y_m, los, lam_m, trusted.nonzero()[0], threshold_cyc, min_sats, flags)
    if fit is None:
        return None
    judged = (usable & ~trusted).nonzero()[0]
    if judged.size:
        flags[judged] = np.abs(y_m[judged] - _design(los, judged) @ fit) / lam_m[judged] > threshold_cyc
    return flags


def _design(los: Arr, k: npt.NDArray[np.int64]) -> Arr:
    """Rows (−e, 1) of the slots `k`: displacement (m) and clock change (m) as unknowns."""
    h = np.empty((k.size, 4))
    np.negative(los[k], out=h[:, :3])
    h[:, 3] = 1.0
    return h


def _isolate(y_m: Arr, los: Arr, lam_m: Arr, k: npt.NDArray[np.int64], threshold_cyc: float, min_sats: int,
             flags: npt.NDArray[np.bool_]) -> Arr | None:
    """Flag (in `flags`) the slipped satellites among slots `k` one at a time; the fit (displacement, clock
    change; m) of those left, None when fewer than `min_sats` are (or the geometry is singular)."""
    if k.size < min_sats:
        return None
    h, yk, lam = _design(los, k), y_m[k], lam_m[k]
    while True:
        try:
            n_inv = inv(h.T @ h)
        except LinAlgError:
            return None
        coef = n_inv @ (h.T @ yk)
        r = np.abs(yk - h @ coef)
        free = np.maximum(1.0 - np.einsum("ij,ij->i", h @ n_inv, h), 1e-9)  # 1 − leverage, > 0 with ≥ 5 rows
        # the suspect: the largest residual over its own σ (Baarda's w-test: a slip elsewhere inflates the
        # deletion residual of a satellite alone in its direction, not this); its size: the residual it
        # would have against the fit of the others
        worst = int((r / np.sqrt(free) / lam).argmax())
        if r[worst] / free[worst] / lam[worst] <= threshold_cyc:
            return coef
        flags[k[worst]] = True
        keep = np.arange(k.size) != worst
        k, h, yk, lam = k[keep], h[keep], yk[keep], lam[keep]
        if k.size < min_sats:
            return None
