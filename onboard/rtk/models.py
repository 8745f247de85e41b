"""Atmosphere and weighting models: Saastamoinen troposphere, Klobuchar ionosphere, elevation weights.

Follows RTKLIB rtkcmn.c tropmodel() / ionmodel() and rtkpos.c varerr() (vectorised over satellites).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from onboard.rtk.consts import CLIGHT_M_S

Arr = npt.NDArray[np.float64]

# Klobuchar defaults RTKLIB uses when a navigation file has none (2004/1/1).
KLOBUCHAR_DEFAULT_ALPHA = (0.1118e-07, -0.7451e-08, -0.5961e-07, 0.1192e-06)
KLOBUCHAR_DEFAULT_BETA = (0.1167e06, -0.2294e06, -0.1311e06, 0.1049e07)


def saastamoinen_m(lat_rad: float | Arr, h_m: float | Arr, el_rad: Arr, humidity: float = 0.7) -> Arr:
    """Slant tropospheric delay (m) by Saastamoinen with a standard atmosphere (RTKLIB tropmodel); `lat_rad`
    and `h_m` may be (k, 1) for k receivers, `el_rad` (k, n) (a row each)."""
    el = np.asarray(el_rad, dtype=float)
    if getattr(h_m, "ndim", 0):  # np.ndim without its wrapper (a float or a numpy scalar: 0)
        return _saastamoinen_rows(np.ravel(lat_rad).astype(float), np.ravel(h_m).astype(float), el, humidity)
    out = np.zeros(el.shape)
    if h_m < -100.0 or h_m > 1e4:
        return out
    hgt = max(h_m, 0.0)
    pres = 1013.25 * (1.0 - 2.2557e-5 * hgt) ** 5.2568
    temp = 15.0 - 6.5e-3 * hgt + 273.16
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    z = np.pi / 2.0 - el
    ok = el > 0
    cz = np.cos(z[ok])
    trph = 0.0022768 * pres / (1.0 - 0.00266 * math.cos(2.0 * lat_rad) - 0.00028 * hgt / 1e3) / cz  # libm's cos
    trpw = 0.002277 * (1255.0 / temp + 0.05) * e / cz
    out[ok] = trph + trpw
    return out


def _saastamoinen_rows(lat: Arr, h: Arr, el: Arr, humidity: float) -> Arr:
    """saastamoinen_m of k receivers at once (latitudes, heights (k,), elevations (k, n)): the scalar
    formula's operations in the same order per element (the pressure's power per receiver in Python floats,
    as there), in a few array operations instead of k calls (the SPP batch evaluates every epoch's
    troposphere)."""
    out = np.zeros_like(el)
    inside = ~((h < -100.0) | (h > 1e4))  # the scalar formula's range (a NaN height goes on, as there)
    ok = (el > 0) & inside[:, None]
    if not ok.any():
        return out
    hgt = np.maximum(np.where(inside, h, 0.0), 0.0)  # rows outside stay 0 (no overflow computing them)
    pres = np.array([1013.25 * (1.0 - 2.2557e-5 * x) ** 5.2568 for x in hgt.tolist()])
    temp = 15.0 - 6.5e-3 * hgt + 273.16
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    cz = np.cos(np.pi / 2.0 - el[ok])
    row = np.nonzero(ok)[0]
    trph = (0.0022768 * pres / (1.0 - 0.00266 * np.cos(2.0 * lat) - 0.00028 * hgt / 1e3))[row] / cz
    trpw = (0.002277 * (1255.0 / temp + 0.05) * e)[row] / cz
    out[ok] = trph + trpw
    return out


def klobuchar_m(t_tow_s: float | Arr, lat_rad: float | Arr, lon_rad: float | Arr, az_rad: Arr, el_rad: Arr,
                alpha: tuple[float, ...] | None, beta: tuple[float, ...] | None) -> Arr:
    """L1 ionospheric delay (m) by the broadcast Klobuchar model (IS-GPS-200 20.3.3.5.2.5, RTKLIB ionmodel)."""
    a = alpha if alpha is not None and any(alpha) else KLOBUCHAR_DEFAULT_ALPHA
    b = beta if beta is not None and any(beta) else KLOBUCHAR_DEFAULT_BETA
    az = np.asarray(az_rad, float)
    el = np.asarray(el_rad, float)
    elsc = el / np.pi
    psi = 0.0137 / (elsc + 0.11) - 0.022
    phi = lat_rad / np.pi + psi * np.cos(az)
    phi = np.minimum(np.maximum(phi, -0.416), 0.416)  # np.clip to the bit, without its dispatch overhead
    lam = lon_rad / np.pi + psi * np.sin(az) / np.cos(phi * np.pi)
    phi = phi + 0.064 * np.cos((lam - 1.617) * np.pi)
    tt = 43200.0 * lam + t_tow_s
    tt = tt - np.floor(tt / 86400.0) * 86400.0
    f = 1.0 + 16.0 * (0.53 - elsc) ** 3
    amp = a[0] + phi * (a[1] + phi * (a[2] + phi * a[3]))
    per = b[0] + phi * (b[1] + phi * (b[2] + phi * b[3]))
    amp = np.maximum(amp, 0.0)
    per = np.maximum(per, 72000.0)
    x = 2.0 * np.pi * (tt - 50400.0) / per
    delay = np.where(np.abs(x) < 1.57, 5e-9 + amp * (1.0 + x * x * (-0.5 + x * x / 24.0)), 5e-9)
    return CLIGHT_M_S * f * delay


IONO_SHELL_HEIGHT_M = 350e3
"""Height of the single-layer ionosphere (m), as RTKLIB ionmapf."""
_EARTH_RADIUS_IONO_M = 6380e3


def iono_mapping(el_rad: Arr) -> Arr:
    """Single-layer ionospheric mapping function (slant / vertical delay, RTKLIB ionmapf): 1 at the zenith,
    about 2.7 at 15° elevation."""
    c = _EARTH_RADIUS_IONO_M / (_EARTH_RADIUS_IONO_M + IONO_SHELL_HEIGHT_M) * np.cos(np.asarray(el_rad, float))
    return 1.0 / np.sqrt(1.0 - c * c)


def phase_variance_m2(el_rad: Arr, a_m: float, b_m: float) -> Arr:
    """Zero-difference carrier-phase variance (m²): (a² + b²/sin²el), RTKLIB varerr() without the factor 2."""
    s = np.sin(np.maximum(np.asarray(el_rad, float), np.radians(1.0)))
    return a_m * a_m + (b_m * b_m) / (s * s)


CHI2_1DOF_MEDIAN = 0.4549
"""Median of a χ²(1) variable: a robust mean of squared normalised Gaussian deviations is median / this."""


@dataclass
class CodeScatter:
    """Running estimate of how noisy the code really is against its model, from code minus carrier.

    Single-differenced (rover − base) code minus carrier, per satellite, is free of geometry, clocks and
    troposphere: along a phase arc it is code noise and multipath plus a constant (the ambiguity) and a slow
    ionospheric divergence. Its scatter about an exponentially weighted arc mean (`arc_time_s`), divided by
    the modelled single-difference code variance, is averaged over satellites (median, robust to a code
    outlier or an undetected slip) and over time (`window_s`). Pure.
    """

    arc_time_s: float = 60.0
    window_s: float = 120.0
    mean_m: Arr = field(default_factory=lambda: np.full(32, np.nan))
    count: Arr = field(default_factory=lambda: np.zeros(32))
    ratio: float = float("nan")
    """Smoothed mean of (deviation² / modelled variance); NaN until `epochs` ≥ 1."""
    epochs: int = 0

    def update(self, cmc_m: Arr, model_var_m2: Arr, ok: npt.NDArray[np.bool_],
               restart: npt.NDArray[np.bool_], dt_s: float) -> None:
        """Add one epoch: `cmc_m` SD code − λ·phase per slot (m), `model_var_m2` the SD code variance the
        filter uses, `ok` slots with both, `restart` slots whose phase arc starts afresh (slip, gap)."""
        gone = restart | ~ok
        self.mean_m[gone] = np.nan
        self.count[gone] = 0.0
        fresh = ok & ~np.isfinite(self.mean_m)
        self.mean_m[fresh] = cmc_m[fresh]
        self.count[fresh] = 1.0
        upd = ok & ~fresh
        settled = self.count >= 5
        old = upd & settled  # the arc mean has settled enough to measure against
        w_time = min(1.0, abs(dt_s) / self.arc_time_s) if dt_s else 1.0 / self.arc_time_s
        w = np.maximum(1.0 / (self.count[upd] + 1.0), w_time)
        dev = cmc_m - self.mean_m
        if np.count_nonzero(old) >= 3:
            # deviation from a mean of n samples has variance σ²(1 + w) for weight w (the old slots' w)
            wo = w[settled[upd]]
            r = median_of_few(dev[old] ** 2 / (model_var_m2[old] * (1.0 + wo))) / CHI2_1DOF_MEDIAN
            a = max(1.0 / (self.epochs + 1), min(1.0, abs(dt_s) / self.window_s) if dt_s else 0.0)
            self.ratio = r if self.epochs == 0 else self.ratio + a * (r - self.ratio)
            self.epochs += 1
        self.mean_m[upd] += w * dev[upd]
        self.count[upd] += 1.0


@dataclass
class ChannelCodeBias:
    """Per-slot single-difference (rover − base) code bias (m) of GLONASS's FDMA channels, learned at fixed
    epochs, where the position is known to centimetres and a channel's code residual is its bias plus noise.

    Two receivers' (and antennas') code group delays differ from one FDMA frequency to the next by up to
    metres, even between two units of one receiver type; the receiver clock's part common to the channels
    cancels in the double differences, so each bias is kept relative to the median over the channels of an
    epoch (a datum the calibrated channels hold steady as satellites come and go). Running mean over at most
    `window` samples per slot. Pure."""

    bias_m: Arr
    count: npt.NDArray[np.int64]

    @classmethod
    def empty(cls, n: int) -> ChannelCodeBias:
        return cls(np.zeros(n), np.zeros(n, np.int64))

    def learn(self, resid_m: Arr, use: npt.NDArray[np.bool_], window: int) -> None:
        """Add one fixed epoch: `resid_m` SD code − modelled SD range at the fixed position per slot (m),
        `use` the slots to learn from (at least 3, else nothing is learned)."""
        if np.count_nonzero(use) < 3:
            return
        common = median_of_few(resid_m[use] - self.bias_m[use])
        n = np.minimum(self.count[use] + 1, window)
        self.bias_m[use] += (resid_m[use] - common - self.bias_m[use]) / n
        self.count[use] += 1

    def correction_m(self, min_count: int) -> Arr:
        """The bias to take off each slot's SD code (m): 0 for a slot learned at fewer than `min_count` epochs."""
        return np.where(self.count >= min_count, self.bias_m, 0.0)


def median_of_few(a: Arr) -> float:
    """np.median of a short, finite, non-empty 1-D array, to the bit (mean of the middle two when even),
    without its generic-reduction overhead and its import of numpy.ma (per-epoch hot paths)."""
    v = sorted(a.tolist())
    h = len(v) // 2
    return v[h] if len(v) % 2 else (v[h - 1] + v[h]) / 2.0
