"""Standstill detection from time-differenced carrier phase (pure).

A survey drone stands on the ground for minutes before take-off and after landing, and a static receiver's
solution is better for knowing it: with no position process noise every epoch adds to the same point, which
is what carries a fix through a stretch of poor geometry (GEONET 0759/3040: its last six epochs have five
satellites at PDOP 23-37, where an epoch-by-epoch position with the right integers is 8-18 cm off). u-blox
receivers do the same in their navigation filter ("static hold", CFG-NAV5 staticHoldThresh).

The evidence is the rover's displacement over a sliding window, from single-differenced (rover − base) phase
minus modelled range at both ends: time-differencing removes the ambiguity, double-differencing the
receiver clocks, so a satellite tracked without a slip across the window measures the displacement along its
line of sight to millimetres whatever the state of the ambiguities and the sampling interval. The window's
ends only enter: the noise does not grow with the window, and a slow creep adds up inside it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from onboard.rtk.consts import LAMBDA_L1_M
from onboard.rtk.linsolve import LinAlgError, inv

Arr = npt.NDArray[np.float64]

CHI2_3DOF_999 = 16.266
"""0.999 quantile of χ²(3): a displacement test failing it is motion, not noise."""


@dataclass(frozen=True)
class Displacement:
    """Rover displacement over the window (ECEF m) with its covariance (m²), from `n_sats` satellites."""

    d_m: Arr
    cov_m2: Arr
    info_m2: Arr
    """Inverse of the covariance (1/m²)."""
    span_s: float
    n_sats: int

    @functools.cached_property
    def chi2(self) -> float:
        """Mahalanobis square of the displacement against zero (static hypothesis); computed once (a standing
        rover's update reads it twice)."""
        return float(self.d_m @ self.info_m2 @ self.d_m)

    @property
    def sigma_m(self) -> float:
        """3D standard deviation (m): √trace of the covariance."""
        return math.sqrt(max(float(self.cov_m2.trace()), 0.0))


def tdcp_displacement(sd_then_m: Arr, pos_then_m: Arr, sd_now_m: Arr, pos_now_m: Arr, los_now: Arr,
                      var_sd_m2: Arr, usable: npt.NDArray[np.bool_], min_sats: int = 5,
                      span_s: float = 0.0) -> Displacement | None:
    """Displacement (ECEF m) of the rover between two epochs from time-differenced double differences.

    `sd_*_m` per satellite slot: λ(φ_rover − φ_base) − (modelled rover range from `pos_*_m` − base range);
    `los_now` unit lines of sight (rover → satellite, one row per slot), `var_sd_m2` the single-difference
    phase variance of one epoch, `usable` the slots tracked without a slip from one epoch to the other, `span_s`
    the time between them (s, reported with the displacement). With fewer than `min_sats` (one redundant)
    satellites, None.
    """
    k = (usable & np.isfinite(sd_then_m) & np.isfinite(sd_now_m)).nonzero()[0]
    if k.size < min_sats:
        return None
    # λφ − ρ(x_a) = −e·(x − x_a) + ambiguity + clocks: the time difference keeps −e·(Δx − Δx_a) + Δclocks
    y = sd_now_m[k] - sd_then_m[k]
    e = los_now[k]
    var = 2.0 * var_sd_m2[k]
    ref = int(var.argmin())  # the best-determined satellite (highest) as reference
    others = np.arange(k.size) != ref
    dd_y = y[others] - y[ref]
    a = -(e[others] - e[ref])
    # weights of the DD rows: the inverse of diag(var_others) + var_ref·11ᵀ (Sherman-Morrison, no m×m inverse)
    inv_d = 1.0 / var[others]
    g = var[ref] / (1.0 + var[ref] * float(inv_d.sum()))
    aw = a.T * inv_d
    aw1 = aw.sum(axis=1)
    normal = aw @ a - g * (aw1[:, None] * aw1[None, :])  # np.outer's product without its wrapper
    rhs = aw @ dd_y - g * aw1 * float(inv_d @ dd_y)
    try:
        cov_u = inv(normal)
    except LinAlgError:
        return None
    u = cov_u @ rhs
    return Displacement(u + (np.asarray(pos_now_m) - np.asarray(pos_then_m)), cov_u, normal, span_s, int(k.size))


SLIP_MIN_M = 0.4 * LAMBDA_L1_M
"""Smallest time-differenced phase misfit (m) read as a slip by the one-satellite exclusion: 0.4 L1 cycle,
below the half cycle a receiver's phase jumps by, above the few millimetres of phase noise."""


def tdcp_misfit_m(sd_then_m: Arr, pos_then_m: Arr, sd_now_m: Arr, pos_now_m: Arr, los_now: Arr,
                  var_sd_m2: Arr, usable: npt.NDArray[np.bool_], slot: int, disp: Displacement) -> float:
    """Time-differenced DD phase misfit (m) of satellite `slot` against the displacement `disp` solved from the
    `usable` satellites without it (same reference choice as tdcp_displacement)."""
    k = np.flatnonzero(usable & np.isfinite(sd_then_m) & np.isfinite(sd_now_m))
    ref = int(k[np.argmin(var_sd_m2[k])])
    y = sd_now_m - sd_then_m
    u = disp.d_m - (np.asarray(pos_now_m) - np.asarray(pos_then_m))
    return float((y[slot] - y[ref]) + (los_now[slot] - los_now[ref]) @ u)


@dataclass
class StandstillMonitor:
    """Sliding-window standstill test over a rover's relative epochs (pure; one `update` per epoch)."""

    window_s: float = 10.0
    max_anchor_age_s: float = 120.0
    """Sparse data (30 s epochs): the previous epoch still serves as the window's start up to this age."""
    epochs: int = 0
    hist: list[tuple[int, int, Arr, Arr, npt.NDArray[np.int64]]] = field(default_factory=list)
    """(time ns, epoch number, SD phase − range per slot (m), position used (ECEF m), lock counts), oldest first."""
    still_since_ns: int | None = None
    """Start of the current run of windows that passed the test (ns), None while moving or unknown."""
    slipped_slot: int = -1
    """The slot the last update found slipped by the one-satellite exclusion, −1 for none."""

    def update(self, t_ns: int, sd_m: Arr, pos_m: Arr, los: Arr, var_sd_m2: Arr,
               lock: npt.NDArray[np.int64], valid: npt.NDArray[np.bool_],
               exclude_one: bool = False) -> Displacement | None:
        """Add an epoch and return the displacement since the window's start (None when it cannot be told).

        `lock` the per-slot count of consecutive epochs with phase (reset to 0 by a slip), after this epoch's
        bookkeeping: a slot is continuous over the window when its count grew by the number of epochs since.
        `exclude_one` (a rover believed standing): when the test fails, and leaving out exactly one satellite
        makes the rest pass while that satellite misfits by SLIP_MIN_M or more, that satellite slipped
        (`slipped_slot`) and the displacement without it stands.
        """
        self.slipped_slot = -1
        self.epochs += 1
        hist = self.hist
        if hist and (t_ns == hist[-1][0] or abs(t_ns - hist[-1][0]) / 1e9 > self.max_anchor_age_s):
            hist.clear()  # a repeated epoch or a long gap: start afresh (time runs backward in a backward pass)
            self.still_since_ns = None
        anchor = None
        for entry in hist:
            if abs(t_ns - entry[0]) / 1e9 <= self.window_s:
                anchor = entry
                break
        if anchor is None and hist:
            anchor = hist[-1]
        disp = None
        if anchor is not None:
            t_a, ep_a, sd_a, pos_a, lock_a = anchor
            continuous = valid & (lock - lock_a == self.epochs - ep_a)
            disp = tdcp_displacement(sd_a, pos_a, sd_m, pos_m, los, var_sd_m2, continuous,
                                     span_s=abs(t_ns - t_a) / 1e9)
            if exclude_one and disp is not None and disp.chi2 > CHI2_3DOF_999:
                disp = self._exclude_one_slip(sd_a, pos_a, sd_m, pos_m, los, var_sd_m2, continuous, disp)
        hist.append((t_ns, self.epochs, np.where(valid, sd_m, np.nan), np.array(pos_m, float), lock.copy()))
        # keep the newest entry older than the window (the next anchor) and everything inside it
        while len(hist) > 2 and abs(t_ns - hist[1][0]) / 1e9 > self.window_s:
            hist.pop(0)
        if disp is None or disp.chi2 > CHI2_3DOF_999:
            self.still_since_ns = None
        elif self.still_since_ns is None:
            self.still_since_ns = anchor[0] if anchor is not None else t_ns
        return disp

    def _exclude_one_slip(self, sd_a: Arr, pos_a: Arr, sd_m: Arr, pos_m: Arr, los: Arr, var_sd_m2: Arr,
                          continuous: npt.NDArray[np.bool_], disp: Displacement) -> Displacement:
        """The displacement without the one satellite whose slip explains a failed test (sets slipped_slot),
        else `disp` unchanged: motion moves every line of sight, a slip one."""
        found: list[tuple[int, Displacement]] = []
        for j in np.flatnonzero(continuous & np.isfinite(sd_a) & np.isfinite(sd_m)):
            rest = continuous.copy()
            rest[j] = False
            d = tdcp_displacement(sd_a, pos_a, sd_m, pos_m, los, var_sd_m2, rest, span_s=disp.span_s)
            if d is not None and d.chi2 <= CHI2_3DOF_999 and \
                    abs(tdcp_misfit_m(sd_a, pos_a, sd_m, pos_m, los, var_sd_m2, rest, int(j), d)) >= SLIP_MIN_M:
                found.append((int(j), d))
        if len(found) != 1:
            return disp
        self.slipped_slot = found[0][0]
        return found[0][1]

    def still_for_s(self, t_ns: int) -> float:
        """How long (s) the windows up to `t_ns` have shown no motion; 0 when the last one did or was unknown."""
        return 0.0 if self.still_since_ns is None else abs(t_ns - self.still_since_ns) / 1e9
