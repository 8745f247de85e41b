"""Atmosphere and weighting models: Saastamoinen troposphere, Klobuchar ionosphere, elevation weights.

Follows RTKLIB rtkcmn.c tropmodel() / ionmodel() and rtkpos.c varerr() (vectorised over satellites).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from onboard.rtk.consts import CLIGHT_M_S

Arr = npt.NDArray[np.float64]

# Klobuchar defaults RTKLIB uses when a navigation file has none (2004/1/1).
KLOBUCHAR_DEFAULT_ALPHA = (0.1118e-07, -0.7451e-08, -0.5961e-07, 0.1192e-06)
KLOBUCHAR_DEFAULT_BETA = (0.1167e06, -0.2294e06, -0.1311e06, 0.1049e07)


def saastamoinen_m(lat_rad: float, h_m: float, el_rad: Arr, humidity: float = 0.7) -> Arr:
    """Slant tropospheric delay (m) by Saastamoinen with a standard atmosphere (RTKLIB tropmodel)."""
    el = np.asarray(el_rad, dtype=float)
    out = np.zeros_like(el)
    if h_m < -100.0 or h_m > 1e4:
        return out
    hgt = max(h_m, 0.0)
    pres = 1013.25 * (1.0 - 2.2557e-5 * hgt) ** 5.2568
    temp = 15.0 - 6.5e-3 * hgt + 273.16
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    z = np.pi / 2.0 - el
    ok = el > 0
    cz = np.cos(z[ok])
    trph = 0.0022768 * pres / (1.0 - 0.00266 * np.cos(2.0 * lat_rad) - 0.00028 * hgt / 1e3) / cz
    trpw = 0.002277 * (1255.0 / temp + 0.05) * e / cz
    out[ok] = trph + trpw
    return out


def klobuchar_m(t_tow_s: float, lat_rad: float, lon_rad: float, az_rad: Arr, el_rad: Arr,
                alpha: tuple[float, ...] | None, beta: tuple[float, ...] | None) -> Arr:
    """L1 ionospheric delay (m) by the broadcast Klobuchar model (IS-GPS-200 20.3.3.5.2.5, RTKLIB ionmodel)."""
    a = alpha if alpha is not None and any(alpha) else KLOBUCHAR_DEFAULT_ALPHA
    b = beta if beta is not None and any(beta) else KLOBUCHAR_DEFAULT_BETA
    az = np.asarray(az_rad, float)
    el = np.asarray(el_rad, float)
    elsc = el / np.pi
    psi = 0.0137 / (elsc + 0.11) - 0.022
    phi = lat_rad / np.pi + psi * np.cos(az)
    phi = np.clip(phi, -0.416, 0.416)
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


def phase_variance_m2(el_rad: Arr, a_m: float, b_m: float) -> Arr:
    """Zero-difference carrier-phase variance (m²): (a² + b²/sin²el), RTKLIB varerr() without the factor 2."""
    s = np.sin(np.maximum(np.asarray(el_rad, float), np.radians(1.0)))
    return a_m * a_m + (b_m * b_m) / (s * s)
